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


def main() -> int:
    atexit.register(_ignore_sigint)  # registered first: runs last, after MPI's and PETSc's
    try:
        from cfcontact.cli import main as cli_main
    except KeyboardInterrupt:
        print("cfcontact: interrupted", file=sys.stderr, flush=True)
        return 130
    return cli_main()


if __name__ == "__main__":
    sys.exit(main())
