"""Which DirNeu backend a run uses: :func:`select_solver` (``backend="auto"``: the condensed
solver for the exact method while its dense data fit the machine, the PETSc one otherwise),
shared by :func:`cfcontact.path.trace_path` and the exact method's own entry points
(:func:`cfcontact.exact.trace_exact` and the stepper it runs, :func:`cfcontact.exact.trace_tree`,
:func:`cfcontact.exact.follow_alternative`)."""

from __future__ import annotations

import os
from typing import Optional

from cfcontact.options import check_backend, check_method
from cfcontact.ssnm import get_solver
from cfcontact.system import ContactSystem

__all__ = ["select_solver", "auto_backend", "machine_memory", "CONDENSED_MAX_M", "CONDENSED_BYTES_PER_ENTRY",
           "CONDENSED_MEMORY_SHARE"]

#: ``backend="auto"`` uses the condensed solver for the exact method up to this many contact
#: nodes on any machine (its dense matrices are (2m)^2: 128 MB at m = 2000), ...
CONDENSED_MAX_M = 2000
#: ... and beyond that while CONDENSED_BYTES_PER_ENTRY bytes per entry of (2m)^2 -- S, the kept
#: factorization of the branches' systems with its updates, the dense LU cache -- fit in
#: CONDENSED_MEMORY_SHARE of the machine's memory (benchmark Part C: the m = 4000 strips peak at
#: 2.7-4.1 GiB in all, 43-69 bytes per entry; on 24 GiB this admits m <= 7100).  The full
#: backend refactors J(Z) per branch: 3x the time per transition at m = 4000.
CONDENSED_BYTES_PER_ENTRY = 64
CONDENSED_MEMORY_SHARE = 0.5


def machine_memory() -> Optional[int]:
    """Bytes of physical memory (None where the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def auto_backend(method: str, m: int, memory: Optional[int] = None) -> str:
    """The backend ``backend="auto"`` picks for ``method`` on a system of m contact nodes, on a
    machine with ``memory`` bytes (default: :func:`machine_memory`): "condensed" for the exact
    method while its dense data fit (CONDENSED_MAX_M, CONDENSED_BYTES_PER_ENTRY), else "full"."""
    check_method(method)
    if method != "exact":
        return "full"
    if m <= CONDENSED_MAX_M:
        return "condensed"
    memory = machine_memory() if memory is None else memory
    fits = memory is not None and CONDENSED_BYTES_PER_ENTRY * (2.0 * m) ** 2 <= CONDENSED_MEMORY_SHARE * memory
    return "condensed" if fits else "full"


def select_solver(system: ContactSystem, method: str = "exact", backend: str = "auto"):
    """The system's cached DirNeu backend for ``method`` (see :func:`trace_path`'s ``backend``)."""
    check_backend(backend)
    if backend == "auto":
        backend = auto_backend(method, system.m)
    if backend == "condensed":
        from cfcontact.condensed import get_condensed_solver

        return get_condensed_solver(system)
    return get_solver(system)
