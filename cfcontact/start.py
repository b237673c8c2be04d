"""Where a path starts: the checks of a request (:func:`check_request`, once per entry point), the
start solution (SSNM with restarts), the end points of a branch, and the checks of a ``resume``
argument.  Shared by the seed and exact methods."""

from __future__ import annotations

import logging
from typing import Optional

import numpy as np

from cfcontact.errors import ConvergenceError, InputError, SingularSystemError
from cfcontact.options import TIE_RTOL, AlphaSpan, PathOptions
from cfcontact.solution_path import SolutionPath
from cfcontact.ssnm import InactiveSets, Solution, get_solver, indicators, is_fixed_point, ssnm
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
    taken for the system's own rho; the first attempt's error (ConvergenceError, or a J(Z) the
    backend could not factor: SingularSystemError, :func:`failed_start`) when none does."""
    tol, max_iter = opts.tol, opts.max_iter
    try:
        return ssnm(system, alpha, y0=y0, tol=tol, max_iter=max_iter, solver=solver)
    except (ConvergenceError, SingularSystemError) as first:
        if y0 is not None or not failed_start(first):
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
        except (ConvergenceError, SingularSystemError) as exc:
            if not failed_start(exc):
                raise
            continue
    raise failure


def failed_start(exc) -> bool:
    """Is ``exc`` a start that failed (SSNM did not converge, or a J(Z) on its way could not be
    factored: at a stiffness ratio of 1e6 MUMPS can find the all-sticking J(Z) singular), after
    which another start is tried, rather than a bad model (K not positive definite)?"""
    return isinstance(exc, ConvergenceError) or (isinstance(exc, SingularSystemError)
                                                 and not isinstance(exc, InputError))


def indicator_ties(system, y, rtol=TIE_RTOL):
    """(a, bp, bm): (m,) bool arrays of the indicators of :func:`cfcontact.ssnm.indicators` that
    vanish at y, within ``rtol`` of the scale of y's multipliers and of rho times its relative
    displacements (as in :func:`cfcontact.ssnm.verify`).  There the sets Z(y) are not decided by
    y: at y = 0 (a zero load) every tangential indicator vanishes, and so does the normal one of a
    node at zero gap.  Nodes without a tangential unknown (``system.no_tangent``) have no
    tangential ties."""
    n = system.n
    y = np.asarray(y, dtype=float)
    N, T = system.contact_maps()
    u = y[:n]
    scale = max(np.abs(y[n:]).max(initial=0.0), system.rho * np.abs(N @ u - system.gap).max(initial=0.0),
                system.rho * np.abs(T @ u).max(initial=0.0))
    tie = rtol * scale
    a, bp, bm = (np.abs(v) <= tie for v in indicators(system, y))
    return a, bp & ~system.no_tangent, bm & ~system.no_tangent


def consistent_up_to_ties(system, y, sets, rtol=TIE_RTOL) -> bool:
    """Whether ``sets`` are Z(y) where y decides them: an indicator that vanishes at y (see
    :func:`indicator_ties`) may take either side.  With y = DirNeu(sets, f(alpha)) this is the
    closure of "the branch of ``sets`` is consistent at alpha"."""
    ties = indicator_ties(system, y, rtol)
    sides = (np.where(sets.nu, -1.0, 1.0), np.where(sets.tp, 1.0, -1.0), np.where(sets.tm, -1.0, 1.0))
    a, bp, bm = (np.where(t, side, v) for t, side, v in zip(ties, sides, indicators(system, y)))
    return InactiveSets(a < 0, bp > 0, bm < 0).equivalent(sets, system.friction)


def oriented_start(system, start: Solution, span: AlphaSpan, opts: PathOptions, solver, reach=None) -> Solution:
    """The start point with the inactive sets of the branch that leaves it towards ``span.end``.

    SSNM's sets at the start are Z(y_start).  Where an indicator vanishes at y_start (a
    degenerate start, :func:`indicator_ties`: typically y = 0 at a zero load, where every state of
    a node at zero gap is consistent and the tangential sets of every node are undecided), Z(y_start)
    need not be the sets of any branch through the start, and the predictor-corrector would
    fail at every step size.  The sets are then decided by the load direction: for h = h0,
    c_s h0, ... down to h_min, the candidates Z(y_start) and the sets of SSNM's solution at
    alpha_start + s h are tried, and the first Z whose DirNeu(Z, f) is a solution at alpha_start +
    s h (a fixed point), passes through the start point and is consistent there up to the ties
    (:func:`consistent_up_to_ties`) is taken: its branch is affine, so it is consistent on the
    whole step [alpha_start, alpha_start + s h].  A non-degenerate start is returned unchanged
    (its sets are consistent on a neighbourhood), as is a degenerate one where no candidate
    qualifies (the stepper's branching algorithm then takes over).  ``reach``: a callable giving
    the sets of a solution at an alpha by other means, asked once where SSNM from y_start does not
    converge (at y = 0 of a zero load with every gap zero -- an apex, where the problem is
    positively homogeneous -- SSNM fails alike at every step size)."""
    if not any(t.any() for t in indicator_ties(system, start.y)):
        return start
    s, alpha0 = span.direction, span.start
    y0 = start.y
    f1, f2 = system.loads_numpy()
    load = lambda a: (1.0 - a) * f1 + a * f2  # noqa: E731
    h = opts.h0
    while True:
        a1 = min(max(alpha0 + s * h, span.lo), span.hi)
        candidates = [start.sets]
        try:
            candidates.append(ssnm(system, a1, y0=y0, tol=opts.tol, max_iter=opts.max_iter, solver=solver).sets)
        except ConvergenceError:
            if reach is not None:
                try:
                    candidates.append(reach(a1))
                except ConvergenceError:
                    pass
                reach = None  # (once)
        for Z in candidates:
            y1 = solver.solve(Z, load(a1))
            if not is_fixed_point(system, y1, Z):
                continue
            y_at = solver.solve(Z, load(alpha0))
            if np.linalg.norm(y_at - y0) <= 1e-8 * max(np.linalg.norm(y1), np.linalg.norm(y0), 1e-300) \
                    and consistent_up_to_ties(system, y_at, Z):
                if Z is not start.sets:
                    log.info("degenerate start at alpha=%g: the sets of the branch towards alpha=%g taken "
                             "(h = %g)", alpha0, span.end, h)
                return Solution.from_y(system, y_at, alpha0, sets=Z, iterations=start.iterations)
        if h <= opts.h_min:
            return start
        h = max(opts.c_s * h, opts.h_min)


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
