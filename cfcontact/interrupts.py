"""Ctrl-C around the libraries that change its handling (gmsh) or misreport it (dolfinx 0.9).

Imported by the FEM layer (:mod:`cfcontact.compat`) and the application (:mod:`cfcontact.case`);
it imports nothing heavy itself.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading


def python_sigint():
    """Put Python's Ctrl-C handling back where gmsh removed it.  gmsh 4.8 sets SIGINT to SIG_DFL
    when it is imported (until ``gmsh.finalize``), later versions in ``gmsh.initialize`` unless
    ``interruptible=False``: a Ctrl-C would kill the process without a word.  With Python's
    handler it raises KeyboardInterrupt once gmsh's C code returns (main thread only)."""
    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGINT) is signal.SIG_DFL:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def import_gmsh():
    """The gmsh module, importable from any thread.  gmsh 4.8 sets SIGINT's handler when it is
    imported, and Python sets handlers in the main thread only: imported first by another thread
    (a model built by a worker thread), ``import gmsh`` failed ("signal only works in main
    thread").  There that one step is left out (Python's handler stays, where
    :func:`python_sigint` would put it back anyway); calls of the main thread meanwhile go
    through."""
    if "gmsh" in sys.modules or threading.current_thread() is threading.main_thread():
        import gmsh

        return gmsh
    real = signal.signal

    def main_thread_only(signum, handler):
        if threading.current_thread() is threading.main_thread():
            return real(signum, handler)
        return signal.getsignal(signum)

    with _GMSH_IMPORT:
        signal.signal = main_thread_only
        try:
            import gmsh
        finally:
            signal.signal = real
    return gmsh


_GMSH_IMPORT = threading.Lock()


def caused_by_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` is a KeyboardInterrupt or was raised from one (its ``__cause__`` or
    ``__context__`` chain holds one): a Ctrl-C that Python or a library turned into another
    exception.  Python 3.11 wraps any exception raised in ``__set_name__`` in a RuntimeError
    ("Error calling __set_name__ ..."), so a Ctrl-C that lands while a class body of a module
    being imported runs (pyparsing's ``Regex``, which matplotlib imports when a run's plots are
    written) reaches the program as that RuntimeError."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


@contextlib.contextmanager
def sigint_deferred():
    """Context: a Ctrl-C while heavy libraries are imported is raised after them, at a clean point.

    A KeyboardInterrupt raised inside an import can be misreported: dolfinx 0.9 checks its
    dependencies on import and turns any exception while importing basix into an ImportError
    ("basix is broken").  Meanwhile Python's handler only records the Ctrl-C; when the block ends
    the previous handler is back (Python's own where an import set SIG_DFL, as gmsh 4.8 does) and
    the recorded Ctrl-C is raised as KeyboardInterrupt.  Main thread only (elsewhere: no effect)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught = []
    old = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler if old in (signal.SIG_DFL, None) else old)
    if caught:
        raise KeyboardInterrupt
