"""``python -m cfcontact`` and the ``cfcontact`` command: the command line (see :mod:`cfcontact.cli`).

The command line is imported here, inside the interrupt handling, so that a Ctrl-C while the
libraries load prints one line and exits with 130 (no traceback).  The last exit handler
ignores Ctrl-C: after it Python drops its own signal handlers while C libraries still shut
down, and a Ctrl-C there would kill the finished process."""

import atexit
import signal
import sys


def _ignore_sigint():
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _import_gmsh():
    """Import gmsh with Ctrl-C held back: gmsh 4.8 sets SIGINT to SIG_DFL when it is imported, and
    a Ctrl-C between that and the restoring of Python's handler would kill the process without a
    word.  Imported once here, later imports do nothing; a Ctrl-C that arrived meanwhile is
    delivered to Python's handler when it is unblocked.  It must come first: a signal mask holds
    only while this is the process's one thread (numpy's BLAS starts threads that would take the
    signal, with gmsh's SIG_DFL)."""
    try:
        held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    except (AttributeError, OSError, ValueError):  # no signal masks here: import as it is
        held = None
    try:
        import gmsh  # noqa: F401
    except ImportError:  # the commands that need it say so
        pass
    finally:
        if signal.getsignal(signal.SIGINT) is signal.SIG_DFL:
            signal.signal(signal.SIGINT, signal.default_int_handler)
        if held is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, held)


def main() -> int:
    atexit.register(_ignore_sigint)  # registered first: runs last, after MPI's and PETSc's
    try:
        _import_gmsh()
        from cfcontact.cli import main as cli_main
    except KeyboardInterrupt:
        print("cfcontact: interrupted", file=sys.stderr, flush=True)
        return 130
    return cli_main()


if __name__ == "__main__":
    sys.exit(main())
