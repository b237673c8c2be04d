"""Path following along f(alpha) = (1 - alpha) f1 + alpha f2: the dispatcher.

:func:`trace_path` validates a request once (:func:`cfcontact.start.check_request`), picks the
DirNeu backend (:func:`select_solver`) and the method's stepper (:func:`path_stepper`), and runs
it:

* ``method="seed"``: the predictor-corrector of [JL-PF] (:class:`cfcontact.seed.SeedStepper`);
* ``method="exact"``: the exact piecewise-affine continuation of :mod:`cfcontact.exact`
  (:class:`cfcontact.exact.ExactStepper`).

Both return a :class:`~cfcontact.solution_path.SolutionPath` (the result model, in
:mod:`cfcontact.solution_path`).  The names of the result model, the options and the start
logic are re-exported here for code written against the single ``path`` module.
"""

from __future__ import annotations

import warnings
from typing import Callable, Optional

from cfcontact.backend import CONDENSED_MAX_M, auto_backend, machine_memory, select_solver
from cfcontact.errors import IgnoredOptionWarning, InputError
from cfcontact.options import BACKENDS, METHODS, AlphaSpan, PathOptions, check_method, unused_options
from cfcontact.solution_path import (
    BATCH_LIMIT,
    FORMAT_VERSION,
    SET_NAMES,
    Branch,
    PathEvent,
    PathPoint,
    SolutionPath,
    Transition,
)
from cfcontact.start import START_RHO_FACTORS, branch_endpoints, check_request, resume_parts, start_point
from cfcontact.stepper import check_monitor
from cfcontact.system import ContactSystem

__all__ = ["trace_path", "path_stepper", "select_solver", "auto_backend", "machine_memory", "CONDENSED_MAX_M",
           "BACKENDS", "METHODS", "PathOptions", "AlphaSpan", "SolutionPath", "Branch", "Transition", "PathEvent",
           "PathPoint", "SET_NAMES", "FORMAT_VERSION", "BATCH_LIMIT", "START_RHO_FACTORS", "start_point",
           "branch_endpoints", "resume_parts"]


def path_stepper(system: ContactSystem, span: AlphaSpan, options: PathOptions, method: str = "seed", y0=None,
                 solver=None, resume=None, monitor=None):
    """The stepper of ``method`` for a validated request (see :func:`trace_path`).  K is checked
    first (:meth:`~cfcontact.system.ContactSystem.check_positive_definite`: not positive definite
    or singular, from the inertia of its Cholesky factorization)."""
    system.check_positive_definite()
    if method == "exact":
        from cfcontact.exact import ExactStepper

        return ExactStepper(system, span, options, solver, y0=y0, resume=resume, monitor=monitor)
    from cfcontact.seed import SeedStepper

    check_monitor(monitor)  # (the seed method's start: SSNM, else the exact method's homotopy start)
    return SeedStepper(system, span, options, solver, y0=y0, resume=resume, monitor=monitor)


def check_resume_method(resume, method):
    """InputError when ``resume`` holds a path traced by another method."""
    if isinstance(resume, dict) and isinstance(resume.get("path"), SolutionPath) and resume["path"].method != method:
        raise InputError(f"cannot resume a {resume['path'].method!r} path with method {method!r}")


def trace_path(system: ContactSystem, alpha_start: float = 0.0, alpha_end: float = 1.0, method: str = "seed",
               y0=None, options: Optional[PathOptions] = None, solver=None, resume=None, backend: str = "auto",
               callback: Optional[Callable] = None, monitor: Optional[Callable] = None, **overrides) -> SolutionPath:
    """Follow the solution path of (4) along f(alpha) from alpha_start towards alpha_end.

    Parameters
    ----------
    method : "seed" ([JL-PF]'s Section 4) or "exact" (exact piecewise-affine continuation)
    solver : a DirNeu backend object (overrides ``backend``)
    backend : "full" (PETSc :class:`~cfcontact.ssnm.DirNeuSolver`: one factorization of J(Z) per
        branch), "condensed" (:class:`~cfcontact.condensed.CondensedSolver`: K factored once,
        dense systems in the contact unknowns) or "auto" (default: condensed for the exact method
        while its dense data fit the machine's memory, :func:`auto_backend`, full otherwise; the
        seed method uses full, as in [JL-PF])
    y0 : start solution or guess (Solution or flat vector); SSNM at alpha_start is run from it
    options : PathOptions; keyword arguments override its fields (e.g. ``h_min=1e-6``,
        ``tie_rtol=1e-9``); one the method does not use (``tree=True`` with "seed") is ignored with
        an :class:`~cfcontact.IgnoredOptionWarning`
    callback : called with each accepted :class:`~cfcontact.solution_path.PathPoint`; a truthy
        return stops the run (status "stopped by callback")
    monitor : called during a long start, before the path's first point (the exact method's
        homotopy start when SSNM does not converge at alpha_start; the seed method takes that
        start too), with a
        :class:`~cfcontact.StartProgress` after each of its transitions; a truthy
        return abandons the run: :class:`~cfcontact.errors.StartInterrupted` (nothing to resume)
    resume : continue a run stopped by its callback instead of starting anew: a dict
        ``{"path": SolutionPath, "state": path.resume_state}`` (the stopped run's path, possibly
        saved and loaded, and the state it left in ``path.resume_state``: for "seed" the loop
        state -- step h, step count, cycle detector --, for "exact" the branch being followed --
        sets, orientation, entry alpha -- and the cycle detector).  The method must be the
        path's.  New points are appended to that path; the result equals an uninterrupted run.
    """
    check_method(method)
    opts, span = check_request(system, alpha_start, alpha_end, options, **overrides)
    for note in unused_options(method, overrides):
        warnings.warn(note, IgnoredOptionWarning, stacklevel=2)
    check_resume_method(resume, method)
    if callback is not None and not callable(callback):  # (the monitor is checked where it is used)
        raise InputError(f"callback must be a function of a PathPoint (or None), got {callback!r}")
    system.check_positive_definite()  # before any backend factors K (cached: path_stepper checks again for free)
    solver = solver if solver is not None else select_solver(system, method, backend)
    return path_stepper(system, span, opts, method, y0, solver, resume, monitor).run(callback)
