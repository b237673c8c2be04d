"""Where a path starts: the checks of a request (:func:`check_request`, once per entry point), the
start solution (SSNM with restarts), the end points of a branch, and the checks of a ``resume``
argument.  Shared by the seed and exact methods."""

from __future__ import annotations

import logging

from typing import Optional

from cfcontact.errors import ConvergenceError, InputError
from cfcontact.options import AlphaSpan, PathOptions
from cfcontact.solution_path import SolutionPath
from cfcontact.ssnm import InactiveSets, Solution, get_solver, ssnm
from cfcontact.system import ContactSystem

log = logging.getLogger(__name__)


def check_request(system, alpha_start, alpha_end, options: Optional[PathOptions] = None,
                  **overrides) -> tuple:
    """(options, span) of a path request, validated: the entry points (``trace_path``,
    ``trace_exact``, ``follow_alternative``) call this once and pass the results down unchecked.
    ``overrides`` replace fields of ``options`` (InputError names unknown ones)."""
    if not isinstance(system, ContactSystem):
        raise InputError(f"system must be a ContactSystem, got {type(system).__name__}")
    opts = PathOptions.with_overrides(options, **overrides)
    return opts, AlphaSpan.of(alpha_start, alpha_end, opts)


#: Factors of rho tried by :func:`start_point` when SSNM fails with the system's own rho.
START_RHO_FACTORS = (0.01, 100.0, 0.1, 10.0, 0.001, 1000.0)


def start_point(system, alpha, y0, opts, solver) -> Solution:
    """SSNM at alpha from y0.  Without y0 SSNM starts from 0 and, should that fail (SSNM is only
    locally convergent, and at large F it can cycle), from the frictionless solution (a convex
    problem where SSNM is robust), from the solution with every node open (u = K^-1 f), and
    with other augmentation parameters rho (START_RHO_FACTORS): SSNM's convergence depends on
    rho, the solutions of (1)-(3) do not.  The first that converges is returned, with its sets
    taken for the system's own rho; ConvergenceError of the first attempt when none does."""
    tol, max_iter = opts.tol, opts.max_iter
    try:
        return ssnm(system, alpha, y0=y0, tol=tol, max_iter=max_iter, solver=solver)
    except ConvergenceError as first:
        if y0 is not None:
            raise
        failure = first

    def attempts():
        yield "from the frictionless solution", lambda: ssnm(
            system, alpha, y0=ssnm(system.with_friction(0.0), alpha, tol=tol, max_iter=max_iter).y,
            tol=tol, max_iter=max_iter, solver=solver)
        open_sets = InactiveSets.from_states(["open"] * system.m)
        yield "from the open solution", lambda: ssnm(
            system, alpha, y0=(solver or get_solver(system)).solve(open_sets, system.load(alpha)),
            tol=tol, max_iter=max_iter, solver=solver)
        for factor in START_RHO_FACTORS:
            yield f"with rho x {factor:g}", lambda factor=factor: Solution.from_y(
                system, ssnm(system.with_rho(system.rho * factor), alpha, tol=tol, max_iter=max_iter).y, alpha)

    for what, attempt in attempts():
        log.info("SSNM from 0 failed at alpha=%g; trying %s", alpha, what)
        try:
            return attempt()
        except ConvergenceError:
            continue
    raise failure


def branch_endpoints(system, solver, sets):
    """(Y1, Y2) = (DirNeu(Z, f1), DirNeu(Z, f2)): y(alpha) = (1 - alpha) Y1 + alpha Y2 on the branch."""
    f1, f2 = system.loads_numpy()
    return solver.solve(sets, f1), solver.solve(sets, f2)


def resume_parts(system, alpha_start, alpha_end, resume, method):
    """(path, state) of a ``resume`` argument, checked against the system, the alpha range and
    the method (InputError naming what does not match)."""
    usage = "resume must be a dict {'path': SolutionPath, 'state': path.resume_state}"
    try:
        path, state = resume["path"], resume["state"]
    except (TypeError, KeyError):
        raise InputError(usage) from None
    if not isinstance(path, SolutionPath) or not isinstance(state, dict):
        raise InputError(usage)
    if path.method != method or not path.branches or not path._alphas:
        raise InputError(f"cannot resume from {path!r}: not a started {method} path")
    if (path.n, path.m) != (system.n, system.m):
        raise InputError(f"cannot resume: the path has n={path.n}, m={path.m}, the system n={system.n}, m={system.m}")
    saved = getattr(path, "system_checksum", None)
    if saved is not None and saved != system.checksum():
        raise InputError(f"cannot resume: the path belongs to another system (checksum {saved[:12]}..., this system "
                         f"{system.checksum()[:12]}...)")
    if (path.alpha_start, path.alpha_end) != (float(alpha_start), float(alpha_end)):
        raise InputError(f"cannot resume: the path runs from {path.alpha_start} to {path.alpha_end}, "
                         f"not from {alpha_start} to {alpha_end}")
    return path, state
