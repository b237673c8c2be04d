"""Continuation in the friction coefficient at a fixed load.

:func:`trace_friction_path` follows the solutions of (1)-(3) at the load f(alpha) (alpha fixed)
as the friction coefficient F runs from F_start to F_end.  A system with one coefficient per
node is scaled by one factor: node i has F phi_i, phi = the system's friction vector over its
largest entry (:func:`cfcontact.rational.friction_pattern`), so F is the largest node
coefficient.

Along a branch (states fixed) the load data w are fixed and F enters only through the slipping
nodes' rows (lam_t = +-F phi lam_n): the multipliers are rational in F (:mod:`cfcontact.rational`:
affine in the p slipping nodes' tangential forces mu, which solve (I + F H) mu = F h).

* ``method="exact"``: the next transition of a branch is the first root, in the direction of
  travel, of one of its constraints: every root is a real generalized eigenvalue of a pencil of
  size p + 1 (:meth:`RationalBranch.pencil_roots`), polished on the rational function itself
  with its sign change bracketed (:func:`~cfcontact.rational.polish_root`: to rounding, far
  below 1e-10 relative in F).  No step halving.  The crossing at the root -- which state comes
  next, forward or back in F (a *fold in F*), degenerate points where several constraints
  vanish -- is decided by the exact method's lexicographic rule (:mod:`cfcontact.exact`) on
  the branches' values and F-derivatives there.
* ``method="seed"``: the predictor-corrector of [JL-PF] with F as the parameter (DirNeu on the
  branch at F + s h, accepted when it is consistent with its states; failures at h_min are
  transitions, branching by the smallest indicator).  The reference the exact method is
  compared with; its transition points are known to within h_min.

Both return a :class:`FrictionPath`: a :class:`~cfcontact.solution_path.SolutionPath` whose
parameter is F (``path.alphas`` are F values, transitions and folds are in F,
``solutions_at(F)``, ``multiplicity_intervals``, save/load, plots), each branch stored in its
exact rational form.  Only the condensed backend (:class:`~cfcontact.condensed.CondensedSolver`)
is supported.
"""

from __future__ import annotations

import logging
import math
import time
from typing import Optional

import numpy as np

from cfcontact.errors import ConvergenceError, InputError, SingularSystemError
from cfcontact.exact import (
    OPEN,
    SLIP_M,
    SLIP_P,
    STICK,
    _Context,
    _digest,
    _not_a_solution,
    _reach_start,
    _resolve,
    _Unresolved,
    canonical_codes,
    node_kinds,
    sets_from_codes,
)
from cfcontact.jsonio import jsonable
from cfcontact.options import AlphaSpan, PathOptions
from cfcontact.rational import RationalBranch, friction_pattern, mu_at, polish_root, solver_at
from cfcontact.solution_path import SET_NAMES, Branch, PathEvent, PathPoint, SolutionPath, Transition
from cfcontact.ssnm import STATE_NAMES, Solution, verify
from cfcontact.stepper import Stepper, check_monitor

log = logging.getLogger(__name__)

__all__ = ["trace_friction_path", "FrictionPath", "FrictionStepper", "SeedFrictionStepper", "load_path",
           "friction_system", "worst_residual_friction", "FRICTION_METHODS"]

FRICTION_METHODS = ("exact", "seed")
#: A root of the constraint a branch was entered by within this (relative) of the entry is the
#: entry itself seen from the new branch (the two sides locate one root to ~1e-12 relative).
ENTRY_RTOL = 1e-9


def friction_system(system, F: float, pattern=None):
    """``system`` with node friction F phi (phi = :func:`~cfcontact.rational.friction_pattern`)."""
    phi = friction_pattern(system) if pattern is None else pattern
    return system.with_friction(float(F) * phi if np.any(phi != phi[0]) else float(F) * float(phi[0]))


# ====================================================================== result
class FrictionPath(SolutionPath):
    """A solution path over the friction coefficient F at the fixed load f(alpha).

    The parameter of the base class is F: ``alphas``, ``alpha_start``/``alpha_end``, the
    transitions' ``alpha`` and ``solutions_at(F)`` are in F.  ``load_alpha`` is the load and
    ``pattern`` the friction pattern phi (node friction F phi; also ``friction``).  Each branch
    is stored in its exact form: lam(F) = lam0 + L mu(F), g(F) = lam + rho B u = gam0 + GamL mu(F),
    u(F) = u0 + U mu(F), (I + F H) mu(F) = F h (mu: the slipping nodes' tangential forces)."""

    FORMAT = "cfcontact-friction-path"
    parameter = "friction"

    def __init__(self, *args, load_alpha: float = 0.0, pattern=None, **kwargs):
        super().__init__(*args, **kwargs)
        self.load_alpha = float(load_alpha)
        self.pattern = np.ones(self.m) if pattern is None else np.asarray(pattern, dtype=float)
        self._fb: dict = {}  # branch -> exact form (lam0, L, gam0, GamL, H, h)
        self._fu: dict = {}  # branch -> (u0, U) once formed
        self._source: dict = {}  # branch -> the backend that forms its points' u directly (not after a load)

    @classmethod
    def for_friction(cls, system, method, F_start, F_end, alpha, options=None, pattern=None) -> "FrictionPath":
        phi = friction_pattern(system) if pattern is None else pattern
        p = cls.for_system(system, method, F_start, F_end, {**(options or {}), "parameter": "friction",
                                                              "alpha": float(alpha)})
        p.load_alpha, p.pattern, p.friction = float(alpha), phi, phi
        return p

    def friction_at(self, F) -> np.ndarray:
        """The node friction coefficients at F."""
        return float(F) * self.pattern

    # ------------------------------------------------------------- building
    def add_friction_branch(self, sets, orientation, form: dict, source=None, origin=None, parent=None,
                            F_enter=float("nan")) -> Branch:
        """Append a branch in its exact form (:meth:`RationalBranch.affine_in_mu`); ``source``: the
        condensed solver forming u when it is needed."""
        b = Branch(len(self.branches), sets, int(orientation), origin=origin, parent=parent, alpha_enter=F_enter)
        self.branches.append(b)
        self._fb[b.index] = form
        if source is not None:
            self._pending[b.index] = source
            self._source[b.index] = source
        return b

    def add_point(self, branch: Branch, alpha, y=None) -> int:
        self._alphas.append(float(alpha))
        self._ys.append(None if y is None else np.asarray(y, dtype=float))
        self._point_branch.append(branch.index)
        branch.points.append(len(self._alphas) - 1)
        return len(self._alphas) - 1

    # ------------------------------------------------------------- evaluation
    def _mu(self, b, F):
        fb = self._fb[b]
        return mu_at(fb["H"], fb["h"], float(F))

    def branch_lam(self, branch, alpha):
        b = branch.index if isinstance(branch, Branch) else int(branch)
        fb = self._fb[b]
        return fb["lam0"] + fb["L"] @ self._mu(b, alpha)

    def _branch_indicators(self, b, alpha):
        fb = self._fb[b]
        mu = self._mu(b, alpha)
        lam_n = (fb["lam0"] + fb["L"] @ mu)[:self.m]
        g = fb["gam0"] + fb["GamL"] @ mu
        Fl = self.friction_at(alpha) * lam_n
        m = self.m
        return g[:m], g[m:] - Fl, g[m:] + Fl

    def branch_y(self, branch, alpha) -> np.ndarray:
        """y on a branch at F: u from one solve of the multipliers there, u = K^-1 (f - B^T lam(F)),
        made to satisfy the rows the branch's states impose, while its backend is at hand; else
        (a loaded path) from the branch's form u0 + U mu(F).  (The form loses digits as mu grows:
        a point at F = 0.99 of an inclined non-matching pair 2.7e-9 from (1)-(3) against 1e-13.)"""
        b = branch.index if isinstance(branch, Branch) else int(branch)
        src = self._source.get(b)
        if src is not None:
            lam = self.branch_lam(b, alpha)
            u = src.displacements(lam[:, None], [self.load_alpha], src.imposed_of_sets(self.branches[b].sets))
            return np.concatenate([u[:, 0], lam])
        if b not in self._fu:
            self.form([b])
        fb, (u0, U) = self._fb[b], self._fu[b]
        mu = self._mu(b, alpha)
        return np.concatenate([u0 + U @ mu, fb["lam0"] + fb["L"] @ mu])

    def form(self, branches=None):
        """Form u0, U of the branches (default: all) whose displacements are not formed yet: one
        multi-right-hand-side solve per backend (u at lam0 and at lam0 + s L e_i, s a force scale)."""
        by_source: dict = {}  # every pending branch (a batch is cheap: p + 1 columns a branch)
        for b in sorted(self._pending):
            by_source.setdefault(id(self._pending[b]), (self._pending[b], []))[1].append(b)
        for source, bs in by_source.values():
            cols, where, imposed, points = [], [], [], []
            for b in bs:
                fb = self._fb[b]
                s = max(float(np.abs(fb["lam0"]).max(initial=0.0)), float(np.abs(fb["L"]).max(initial=0.0)), 1e-300)
                where.append((b, len(cols), fb["L"].shape[1], s))
                cols.append(fb["lam0"])
                cols.extend(fb["lam0"] + s * fb["L"][:, i] for i in range(fb["L"].shape[1]))
                # the branch's imposed rows hold for every column (S_I L = 0: they hold at every F)
                imposed.extend([source.imposed_of_sets(self.branches[b].sets)] * (1 + fb["L"].shape[1]))
                points.extend([True] + [False] * fb["L"].shape[1])
            U = source.displacements(np.column_stack(cols), [self.load_alpha] * len(cols), np.column_stack(imposed),
                                     points)
            for b, c0, p, s in where:
                u0 = U[:, c0]
                self._fu[b] = (u0.copy(), (U[:, c0 + 1:c0 + 1 + p] - u0[:, None]) / s)
                del self._pending[b]

    def iter_points(self, batch: int = 256, indices=None):
        order = range(len(self._alphas)) if indices is None else [int(i) for i in indices]
        for i in order:
            yield self._alphas[i], self._ys[i]

    def summary(self) -> dict:
        return {**super().summary(), "parameter": "friction", "load_alpha": self.load_alpha}

    def __repr__(self):
        return "FrictionPath" + super().__repr__().removeprefix("SolutionPath") + f"[alpha={self.load_alpha:g}]"

    # ------------------------------------------------------------- save / load
    def _branch_arrays(self) -> dict:
        B = len(self.branches)
        if not B:
            return {}
        fbs = [self._fb[b.index] for b in self.branches]
        ps = np.array([fb["h"].size for fb in fbs], dtype=int)
        cat = (lambda key, rows: np.concatenate([fb[key] for fb in fbs], axis=1) if ps.sum()
               else np.zeros((rows, 0)))
        return {"fb_p": ps, "fb_lam0": np.stack([fb["lam0"] for fb in fbs]),
                "fb_gam0": np.stack([fb["gam0"] for fb in fbs]), "fb_h": np.concatenate([fb["h"] for fb in fbs]),
                "fb_H": np.concatenate([fb["H"].ravel() for fb in fbs]), "fb_L": cat("L", 2 * self.m),
                "fb_GamL": cat("GamL", 2 * self.m), "fb_u0": np.stack([self._fu[b.index][0] for b in self.branches]),
                "fb_U": (np.concatenate([self._fu[b.index][1] for b in self.branches], axis=1) if ps.sum()
                         else np.zeros((self.n, 0)))}

    def _set_branch_arrays(self, arrays):
        ps = arrays.get("fb_p", np.zeros(0, dtype=int))
        off, offH = np.concatenate([[0], np.cumsum(ps)]), np.concatenate([[0], np.cumsum(ps ** 2)])
        for b in self.branches:
            i, p = b.index, int(ps[b.index])
            sl = slice(off[i], off[i + 1])
            self._fb[i] = {"lam0": arrays["fb_lam0"][i], "gam0": arrays["fb_gam0"][i], "h": arrays["fb_h"][sl],
                           "H": arrays["fb_H"][offH[i]:offH[i + 1]].reshape(p, p), "L": arrays["fb_L"][:, sl],
                           "GamL": arrays["fb_GamL"][:, sl]}
            self._fu[i] = (arrays["fb_u0"][i], arrays["fb_U"][:, sl])

    @classmethod
    def load(cls, path) -> "FrictionPath":
        p = super().load(path)
        p.load_alpha = float(p.options.get("alpha", 0.0))
        p.pattern = np.broadcast_to(np.asarray(p.friction, dtype=float), (p.m,)).copy()
        return p


def load_path(dirname):
    """A saved path, whichever its parameter: :class:`FrictionPath` or :class:`SolutionPath`."""
    import json
    import os

    try:
        with open(os.path.join(os.fspath(dirname), "path.json")) as fh:
            fmt = json.load(fh).get("format")
    except (OSError, ValueError, AttributeError):
        fmt = None
    return (FrictionPath if fmt == FrictionPath.FORMAT else SolutionPath).load(dirname)


def worst_residual_friction(system, path: FrictionPath, solver=None) -> float:
    """Worst relative violation of (1)-(3) over the stored points of a friction path, each point
    checked with the friction of its F and the path's load."""
    f = system.load(path.load_alpha)
    worst = 0.0
    for F, y in path.iter_points():
        sysF = friction_system(system, F, path.pattern)
        worst = max(worst, verify(sysF, y, path.load_alpha, f=f, solver=solver).worst())
    return worst


# ====================================================================== shared set-up
class _FData:
    """Branch data in F at the fixed load for the exact method's crossing rule (the interface of
    the exact module's backends: ``line`` and ``perturbation``), and the rational branches."""

    def __init__(self, system, solver, alpha, pattern):
        self.system, self.solver = system, solver
        self.S, self.rho = solver.S, system.rho
        self.phi = pattern
        self.F0_index = node_kinds(system, pattern)
        self.w = solver.load_data(system.load(alpha))
        self.W = self.w[:, None]
        self._branches: dict = {}
        self.WE = None

    def branch(self, codes) -> RationalBranch:
        codes = np.asarray(codes, dtype=np.int8)
        key = codes.tobytes()
        rb = self._branches.get(key)
        if rb is None:
            if len(self._branches) > 256:
                self._branches.clear()
            rb = self._branches[key] = RationalBranch(self.S, self.rho, codes, self.phi, self.F0_index)
        return rb

    def line(self, codes, key, F):
        try:
            lam, dlam, g, dg, err = self.branch(codes).tangent(F, self.w)
        except np.linalg.LinAlgError as exc:
            raise SingularSystemError(f"the branch {[STATE_NAMES[c] for c in codes]} is singular at F = {F!r}: "
                                      f"{exc}") from None
        scale_v = np.abs(lam).max(initial=0.0) + self.rho * np.abs(self.w).max(initial=0.0)
        scale_s = np.abs(dlam).max(initial=0.0) + np.abs(dg).max(initial=0.0)
        return lam, dlam, g, dg, scale_v, scale_s, None, None, err, None

    def perturbation(self, line, E_loads):
        if self.WE is None or self.WE.shape[1] < E_loads.shape[1]:
            zero = self.solver.load_data_many([np.zeros(self.solver.n)])[:, 0]
            self.WE = self.solver.load_data_many([E_loads[:, j] for j in range(E_loads.shape[1])]) - zero[:, None]
        return self.branch(line.codes).solve(line.alpha, self.WE[:, :E_loads.shape[1]])[1]


class _FContext(_Context):
    """The exact method's run context (:class:`cfcontact.exact._Context`) with F as the parameter:
    its ``line`` gives a branch's values and F-derivatives at F (what the lexicographic crossing
    rule needs), its perturbation rows the responses at that F."""

    def __init__(self, system, solver, opts, lo, hi, rtol, alpha, pattern):
        self.system, self.solver, self.opts, self.callback = system, solver, opts, None
        self.lo, self.hi, self.rtol = lo, hi, rtol
        self.Fv = pattern
        self.F0 = pattern == 0.0
        # the node kinds of the exact method's tables (F = 0; no tangential unknown)
        self.F0_index = node_kinds(system, pattern)
        self.m = system.m
        self.f1, self.f2 = system.loads_numpy()
        self.data = _FData(system, solver, alpha, pattern)
        self.condensed = True
        self.visited: dict = {}
        self._lines: dict = {}
        self.E = None
        self.stats = {"degenerate_points": 0, "pivots": 0, "max_vanishing": 0, "branch_points": 0,
                      "perturbation_solves": 0, "homotopy_transitions": 0, "start_pivots": 0, "root_candidates": 0}

    def vertex_line(self, codes, alpha, at):
        """The intermediate branches of a degenerate point are formed in full here (their values
        and F-derivatives at F)."""
        return self.line(codes, alpha)


def _check_request(system, alpha, F_start, F_end, options, method, solver):
    from cfcontact.condensed import CondensedSolver, get_condensed_solver
    from cfcontact.system import ContactSystem

    if not isinstance(system, ContactSystem):
        raise InputError(f"system must be a ContactSystem, got {type(system).__name__}")
    if method not in FRICTION_METHODS:
        raise InputError(f"unknown method {method!r} for a friction path; valid: "
                         f"{', '.join(map(repr, FRICTION_METHODS))}")
    try:
        a, F0, F1 = float(alpha), float(F_start), float(F_end)
    except (TypeError, ValueError):
        raise InputError(f"alpha, F_start and F_end must be numbers, got {alpha!r}, {F_start!r}, {F_end!r}") from None
    if not all(map(math.isfinite, (a, F0, F1))) or F0 == F1 or min(F0, F1) < 0:
        raise InputError(f"the friction range must be two different finite numbers >= 0, got F_start={F_start!r}, "
                         f"F_end={F_end!r} (alpha={alpha!r})")
    opts = options if isinstance(options, PathOptions) else PathOptions.with_overrides(None, **(options or {}))
    system.check_positive_definite()  # (cached) before the solver factors K
    if solver is None:
        solver = get_condensed_solver(system)
    elif not isinstance(solver, CondensedSolver):
        raise InputError("friction paths need the condensed backend (a CondensedSolver)")
    return a, AlphaSpan(F0, F1, min(F0, F1), max(F0, F1)), opts, solver


def _start_codes(system, solver, alpha, F, pattern, opts, monitor=None) -> tuple:
    """(codes, how): the state codes of a solution at the load f(alpha) with friction F pattern:
    SSNM in the multipliers, else the exact method's homotopy from the frictionless solution or
    from the all-open state, else enumeration (small problems).  At F = 0 a closed node with
    friction slips in the direction of its T u (stick when T u = 0): the states of F = 0+.  A
    closed node without tangential unknown sticks.  ``monitor``: as for
    :func:`cfcontact.exact.trace_exact` (the homotopy start's progress)."""
    sysF = friction_system(system, F, pattern)
    view = solver_at(solver, sysF)
    f = system.load(alpha)
    sets, how = view.ssnm_sets(f, opts.tol, opts.max_iter), "ssnm"
    if sets is None:
        ctx = _Context(sysF, view, opts, alpha, alpha + 1.0, float(opts.tie_rtol))
        sets, how, _ = _reach_start(ctx, alpha, monitor)
    if sets is None and system.m <= 8:
        from cfcontact.enumerate import enumerate_solutions

        sols = enumerate_solutions(sysF, alpha, solver=view)
        sets, how = (sols[0].sets if sols else None), "enumeration"
    if sets is None:
        raise ConvergenceError(f"no start solution found at alpha={alpha}, F={F}")
    codes = canonical_codes(sets, sysF.friction_vector)
    kinds = node_kinds(system, pattern)
    # a closed node without tangential unknown sticks (lam_t = 0), as in the condensed backend's codes
    codes = np.where((codes != OPEN) & (kinds == 2), STICK, codes).astype(np.int8)
    if F == 0.0:
        rb = RationalBranch(solver.S, system.rho, codes, pattern, kinds)
        _, ind, err = rb.solve(0.0, solver.load_data(f)[:, None])
        m = system.m
        gt, tol = ind[m:2 * m, 0], 1e3 * err[m:2 * m, 0] + 1e-13 * np.abs(ind).max(initial=0.0)
        free = (codes != OPEN) & (kinds == 0)
        codes = np.where(free, np.where(gt > tol, SLIP_P, np.where(gt < -tol, SLIP_M, STICK)), codes).astype(np.int8)
    return codes, how


# ====================================================================== steppers
class _FStepper(Stepper):
    """What the two steppers in F share: branches entered in their exact form, the callback's
    points (the accepted-point bookkeeping is :meth:`Stepper.advance`'s)."""

    def _add(self, codes, s, F, origin, parent) -> int:
        """Enter the branch of ``codes`` at F in direction s; index of its entry point."""
        rb = self.data.branch(codes)
        self.branch = self.path.add_friction_branch(sets_from_codes(codes), s, rb.affine_in_mu(self.data.w),
                                                    self.solver, origin=origin, parent=parent, F_enter=F)
        self.codes, self.s, self.F = np.asarray(codes, dtype=np.int8), s, F
        return self.path.add_point(self.branch, F)

    def point(self, index: int) -> PathPoint:
        path = self.path
        b = path._point_branch[index]
        sol = Solution.from_y(self.system, path._ys[index], path._alphas[index], sets=path.branches[b].sets)
        return PathPoint(index, path._alphas[index], b, sol, path)


class FrictionStepper(_FStepper):
    """The exact continuation in F (see the module docstring) as a stepper: one transition per
    accepted point; ``resume`` and ``monitor`` as for :class:`cfcontact.exact.ExactStepper`."""

    method = "exact"
    _start_stuck = False  # the start point is degenerate and the rule could not leave it: the run ends there

    def __init__(self, system, alpha, span: AlphaSpan, options: PathOptions, solver, pattern=None, resume=None,
                 monitor=None):
        self.system, self.span, self.opts, self.solver = system, span, options, solver
        self.alpha = float(alpha)
        self.pattern = friction_pattern(system) if pattern is None else np.asarray(pattern, dtype=float)
        self.ctx = _FContext(system, solver, options, span.lo, span.hi, float(options.tie_rtol), self.alpha,
                             self.pattern)
        self.data = self.ctx.data
        if resume is None:
            self._start_clock()
            self.path = FrictionPath.for_friction(system, "exact", span.start, span.end, self.alpha,
                                                  options.to_dict(), self.pattern)
            codes, how = _start_codes(system, solver, self.alpha, span.start, self.pattern, options, monitor)
            self.start = how
            s = 1 if span.end > span.start else -1
            codes, s = self._leave_start(codes, span.start, s)
            self._enter(codes, s, span.start, None, None)
            self.n_trans0 = 0
            self.start_key = (_digest(codes.tobytes()), s)
            self._pending_point = 0
        else:
            path, state = resume["path"], resume["state"]
            if not isinstance(path, FrictionPath) or path.method != "exact" or not path.branches:
                raise InputError("resume needs a started exact FrictionPath and its resume_state")
            self._start_clock(path.stats)
            self.path, self.start = path, path.stats.get("start")
            for k in self.ctx.stats:
                self.ctx.stats[k] = int(path.stats.get(k, 0))
            try:
                self.branch = path.branches[int(state["branch"])]
                self.codes = np.asarray(state["codes"], dtype=np.int8)
                self.s, self.F = int(state["orientation"]), float(state["F"])
                self.n_trans0 = int(state["transitions0"])
                for k, sg, a in state["visited"]:
                    self.ctx.visited.setdefault((bytes.fromhex(k), int(sg)), []).append(float(a))
                first = path.branches[0]
                self.start_key = (_digest(canonical_codes(first.sets, self.pattern).tobytes()), first.orientation)
            except (KeyError, IndexError, TypeError, ValueError) as exc:
                raise InputError(f"cannot resume: incomplete or invalid resume state ({exc!r})") from None
            path.status, path.resume_state = "running", None
            self.branch.alpha_exit = float("nan")
            self.at_entry = set(int(j) for j in state.get("entry_zero", []))

    # ------------------------------------------------------------- walk
    def _leave_start(self, codes, F, s):
        ctx = self.ctx
        ln = ctx.line(codes, F)
        if _not_a_solution(ln):
            raise ConvergenceError(f"the start states are not consistent at F={F} (alpha={self.alpha})")
        dec = ((np.abs(ln.c) <= ln.tol_v) & (s * ln.dc < -ln.tol_s)).nonzero()[0]
        if not dec.size:
            return codes, s
        try:
            nxt, d, pivots, _ = _resolve(ctx, ln, s, F, dec, start=True)
        except _Unresolved as exc:
            # the start branch's vanishing constraints decrease in the direction of travel: it is no
            # solution beyond the start point (its entry roots would be skipped), so the run ends there
            self.path.events.append(PathEvent("start_degenerate", F, f"the start point is a degenerate point the "
                                              f"lexicographic rule could not leave ({exc}); the path stops there",
                                              None, jsonable(exc.data)))
            self._start_stuck = True
            return codes, s
        ctx.stats["start_pivots"] = len(pivots)
        return nxt.codes.copy(), d

    def _enter(self, codes, s, F, origin, parent, e_in=-1):
        index = self._add(codes, s, F, origin, parent)
        self._entry_zero(e_in)
        self.ctx.visited.setdefault((_digest(self.codes.tobytes()), s), []).append(F)
        return index

    def _entry_zero(self, e_in=-1):
        """The constraints vanishing at the entry of the current branch (their roots there are the
        entry itself, located by the two sides to ~1e-12 relative only)."""
        ln = self.ctx.line(self.codes, self.F)
        zero = np.abs(ln.c) <= ln.tol_v
        if e_in >= 0:
            zero[e_in] = True
        self.at_entry = set(np.flatnonzero(zero).tolist())

    def _exit(self):
        """(F*, position of the vanishing constraint) of the first root in the direction of travel,
        ("pole", F) when the branch becomes singular before any constraint vanishes, or None."""
        ctx, s, F0 = self.ctx, self.s, self.F
        rb = ctx.data.branch(self.codes)
        bound = ctx.hi if s > 0 else ctx.lo
        lo, hi = (F0, bound) if s > 0 else (bound, F0)
        scale = max(abs(F0), abs(bound), 1.0)
        W = ctx.data.W
        cands = []
        roots = rb.pencil_roots_many(W, rb.cidx[:, None], rb.csgn[:, None], lo, hi, sigma=0.5 * (lo + hi))
        for j, rs in enumerate(roots):
            cands.extend((s * (r - F0), float(r), j) for r in rs)
        poles = [(s * (r - F0), float(r), -1) for r in rb.poles(lo, hi)]
        ctx.stats["root_candidates"] += len(cands)
        cands.sort()
        tiny = 1e-12 * scale
        for dist, r, j in cands:
            if poles and poles[0][0] < dist - tiny:
                return "pole", poles[0][1]

            def c(F, j=j):
                return float(rb.csgn[j] * rb.solve(F, W)[1][rb.cidx[j], 0])

            res = polish_root(c, r, lo, hi, scale)
            if res is None:
                continue
            root = res[0]
            if s * (root - F0) <= (ENTRY_RTOL * scale if j in self.at_entry else tiny):
                continue  # the root the branch was entered by (or one behind it)
            if c(F0 + 0.5 * (root - F0)) < 0:
                continue  # the constraint does not decrease through this root (it was negative before)
            return root, j
        if poles:
            return "pole", poles[0][1]
        return None

    def _precise_side(self, ln, j, nxt, e, F_star) -> float:
        """The transition point from its more precise side: the root of the entering constraint e
        on the new branch when its uncertainty (rounding of the value over the rate) is smaller
        than that of the root found on the old branch (constraint j) and the two agree within the
        latter (a steep branch entered through a flat constraint locates the point better)."""
        if e is None or e < 0:
            return F_star
        unc_old = float(ln.tol_v[j]) / max(abs(float(ln.dc[j])), 1e-300)
        unc_new = float(nxt.tol_v[e]) / max(abs(float(nxt.dc[e])), 1e-300)
        if not unc_new < unc_old:
            return F_star
        rb, W = self.ctx.data.branch(nxt.codes), self.ctx.data.W

        def c(F):
            return float(rb.csgn[e] * rb.solve(F, W)[1][rb.cidx[e], 0])

        res = polish_root(c, F_star, self.ctx.lo, self.ctx.hi, max(abs(F_star), 1.0))
        if res is None or abs(res[0] - F_star) > 4.0 * unc_old:
            return F_star
        return res[0]

    def _step(self) -> Optional[int]:
        ctx, path, s = self.ctx, self.path, self.s
        if self._start_stuck:
            self.branch.alpha_exit = self.F
            self._finish("stuck")
            return None
        found = self._exit()
        if found is None:
            F_end = ctx.hi if s > 0 else ctx.lo
            self.branch.alpha_exit = F_end
            self.done = True
            return path.add_point(self.branch, F_end)
        if found[0] == "pole":
            Fp = found[1]
            self.branch.alpha_exit = Fp
            path.events.append(PathEvent("unbounded", Fp, f"the branch becomes singular at F = {Fp!r} before any of "
                                         f"its constraints vanishes: its multipliers grow without bound",
                                         self.branch.index))
            self._finish("stuck")
            return None
        F_star, j = found
        if len(path.transitions) - self.n_trans0 >= self.opts.max_transitions:
            self.branch.alpha_exit = F_star
            path.add_point(self.branch, F_star)
            path.events.append(PathEvent("max_transitions", F_star, f"transition cap {self.opts.max_transitions} "
                                         f"reached", self.branch.index))
            self._finish("max_transitions")
            return None
        ln = ctx.line(self.codes, F_star)
        zero = (np.abs(ln.c) <= ln.tol_v) & (s * ln.dc < ln.tol_s)
        zero[j] = True
        tied = zero.nonzero()[0]
        try:
            nxt, d, pivots, e_in = _resolve(ctx, ln, s, F_star, tied)
        except _Unresolved as exc:
            self.branch.alpha_exit = F_star
            path.add_point(self.branch, F_star)
            path.events.append(PathEvent("dead_end" if exc.kind in ("singular", "cycling") else "degenerate", F_star,
                                         f"the transition point could not be crossed: {exc}", self.branch.index,
                                         jsonable({"reason": exc.kind, **exc.data})))
            self._finish("stuck")
            return None
        F_star = self._precise_side(ln, j, nxt, e_in, F_star)
        m = self.system.m
        if len(tied) > 1 or len(pivots) > 1:
            ctx.stats["degenerate_points"] += 1
            ctx.stats["max_vanishing"] = max(ctx.stats["max_vanishing"], len(tied))
        node, ind = int(ln.cnode[j]), int(ln.cidx[j]) // m
        changes = [{"node": int(i), "set": SET_NAMES[ind] if i == node else None,
                    "from": STATE_NAMES[int(self.codes[i])], "to": STATE_NAMES[int(nxt.codes[i])]}
                   for i in np.flatnonzero(nxt.codes != self.codes)]
        tr = Transition(len(path.transitions), F_star, "transversal" if d == s else "fold", node, SET_NAMES[ind],
                        self.branch.index, len(path.branches), bracket=(F_star, F_star), changes=changes,
                        pivots=[dict(p) for p in pivots] if len(pivots) > 1 else [])
        self.branch.alpha_exit = F_star
        path.add_point(self.branch, F_star)
        # a branch may be entered again at another F (it is rational in F, not affine): only a
        # second entry at the same point is a loop
        key = (_digest(nxt.codes.tobytes()), d)
        tol = 1e-10 * max(abs(F_star), 1.0)
        seen = next((F for F in ctx.visited.get(key, ()) if abs(F - F_star) <= tol), None)
        if seen is not None:
            closed = key == self.start_key
            kind = "closed_loop" if closed else "cycling"
            path.events.append(PathEvent(kind, F_star, "the path returns to its first branch" if closed else
                                         f"branch {sets_from_codes(nxt.codes)} is entered a second time (first at "
                                         f"F={seen!r})", self.branch.index, jsonable({"transition": tr.to_dict()})))
            self._finish(kind)
            return None
        path.transitions.append(tr)
        log.info("F=%.12g %s transition: %s", F_star, tr.kind, changes)
        return self._enter(nxt.codes.copy(), d, F_star, tr.index, self.branch.index, e_in)

    # ------------------------------------------------------------- stepper interface
    @property
    def resume_state(self) -> dict:
        return {"branch": int(self.branch.index), "codes": [int(c) for c in self.codes], "orientation": int(self.s),
                "F": float(self.F), "transitions0": int(self.n_trans0), "entry_zero": sorted(self.at_entry),
                "visited": [[k.hex(), int(sg), float(F)] for (k, sg), Fs in self.ctx.visited.items() for F in Fs]}

    def stop(self):
        if self.done:
            return self._finish("completed")
        self.branch.alpha_exit = self.F
        return self._finish("stopped by callback")

    def _update_stats(self):
        super()._update_stats()
        self.path.stats.update(self.ctx.stats)
        if self.start is not None:
            self.path.stats["start"] = self.start

    def _finish(self, status):
        self.finished = True
        self.path.status = status
        self._update_stats()
        self.path.resume_state = self.resume_state if status == "stopped by callback" else None
        log.info("friction path: %s", self.path)
        return self.path


# ====================================================================== seed stepper
class SeedFrictionStepper(_FStepper):
    """The seed's predictor-corrector with F as the parameter (the reference of the exact method).

    On a branch (states fixed) it steps F -> F + s h, evaluates the branch there (DirNeu in the
    condensed multipliers) and accepts the step when the result is consistent with its states
    (SSNM would return it after one iteration); h grows by c_p after a success and shrinks by
    c_s after a failure within [h_min, h_max].  At h_min the constraints of the branch are ranked
    by their value at the last point (the branching indicator (17)) and the facet of the first
    that gives a consistent branch is crossed: transversally if the new branch is consistent at
    F + s h_fail, else as a fold if it is consistent at F."""

    method = "seed"

    def __init__(self, system, alpha, span: AlphaSpan, options: PathOptions, solver, pattern=None, monitor=None):
        self.system, self.span, self.opts, self.solver = system, span, options, solver
        self.alpha = float(alpha)
        self.pattern = friction_pattern(system) if pattern is None else np.asarray(pattern, dtype=float)
        self.data = _FData(system, solver, self.alpha, self.pattern)
        self._start_clock()
        self.path = FrictionPath.for_friction(system, "seed", span.start, span.end, self.alpha, options.to_dict(),
                                              self.pattern)
        codes, self.start = _start_codes(system, solver, self.alpha, span.start, self.pattern, options, monitor)
        self.s = 1 if span.end > span.start else -1
        self.h, self.steps = options.h0, 0
        self._add(codes, self.s, span.start, None, None)
        self._pending_point = 0
        self.seen: dict = {}

    def _consistent(self, codes, F) -> bool:
        rb = self.data.branch(codes)
        try:
            lam, ind, err = rb.solve(F, self.data.W)
        except np.linalg.LinAlgError:
            return False
        # SSNM's sets of the result are its states iff every constraint holds (Remark 3.1; the
        # sets of (17) use strict signs, rounding aside)
        c = rb.csgn * ind[rb.cidx, 0]
        return bool(np.all(c >= -1e-15 * max(np.abs(ind).max(initial=0.0), 1e-300)))

    def _step(self) -> Optional[int]:
        opts, lo, hi = self.opts, self.span.lo, self.span.hi
        while True:
            self.steps += 1
            if self.steps > opts.max_steps:
                self.path.events.append(PathEvent("max_steps", self.F, f"step cap {opts.max_steps} reached",
                                                  self.branch.index))
                self._finish("max_steps")
                return None
            F_new = min(max(self.F + self.s * self.h, lo), hi)
            clipped = F_new in (lo, hi)
            step = abs(F_new - self.F)
            if step > 0 and self._consistent(self.codes, F_new):
                self.F = F_new
                self.h = min(opts.c_p * self.h, opts.h_max)
                self.done = clipped
                self.branch.alpha_exit = F_new
                return self.path.add_point(self.branch, F_new)
            if self.h > opts.h_min and step > 0:
                self.h = max(opts.c_s * self.h, opts.h_min)
                continue
            return self._transition(step if step > 0 else self.h)

    def _transition(self, h_fail):
        from cfcontact.exact import _PIVOT

        path, F, s, m = self.path, self.F, self.s, self.system.m
        if len(path.transitions) >= self.opts.max_transitions:
            path.events.append(PathEvent("max_transitions", F, "transition cap reached", self.branch.index))
            self._finish("max_transitions")
            return None
        rb = self.data.branch(self.codes)
        ind = rb.solve(F, self.data.W)[1][:, 0]
        F1 = min(max(F + s * h_fail, self.span.lo), self.span.hi)
        # the branching indicator (17): the smallest constraint at the last point, among those
        # the failed step violates first
        failed = rb.csgn * rb.solve(F1, self.data.W)[1][rb.cidx, 0] < 0 if F1 != F else np.zeros(rb.cidx.size, bool)
        order = np.lexsort((np.abs(ind[rb.cidx]), ~failed))
        choice = None
        for j in order[:8]:
            node, k = int(rb.cnode[j]), int(rb.cidx[j]) // m
            new = int(_PIVOT[self.codes[node], int(self.data.F0_index[node]), k])
            if new == -1:
                new = SLIP_P if ind[m + node] >= 0 else SLIP_M
            if new < 0:
                continue
            codes = self.codes.copy()
            codes[node] = new
            if F1 != F and self._consistent(codes, F1):
                choice = ("transversal", node, k, codes, s)
            elif self._consistent(codes, F):
                choice = ("fold", node, k, codes, -s)
            if choice:
                break
        if choice is None:
            path.events.append(PathEvent("no_indicator", F, "no facet of the branch gives a consistent branch",
                                         self.branch.index))
            self._finish("stuck")
            return None
        kind, node, k, codes, s_new = choice
        key = (codes.tobytes(), s_new, round(F / max(self.opts.h_min, 1e-300)))
        self.seen[key] = self.seen.get(key, 0) + 1
        if self.seen[key] > 2:
            path.events.append(PathEvent("cycling", F, "the branching returns to the same branch", self.branch.index))
            self._finish("cycling")
            return None
        self.branch.alpha_exit = F
        tr = Transition(len(path.transitions), F, kind, node, SET_NAMES[k], self.branch.index, len(path.branches),
                        bracket=(min(F, F1), max(F, F1)),
                        changes=[{"node": node, "set": SET_NAMES[k], "from": STATE_NAMES[int(self.codes[node])],
                                  "to": STATE_NAMES[int(codes[node])]}])
        path.transitions.append(tr)
        F_next = F1 if kind == "transversal" else F
        idx = self._add(codes, s_new, F_next, tr.index, self.branch.index)
        self.done = kind == "transversal" and F_next in (self.span.lo, self.span.hi)
        return idx

    @property
    def resume_state(self) -> dict:
        return {}

    def stop(self):
        return self._finish("stopped by callback")

    def _finish(self, status):
        self.finished = True
        self.path.status = status
        self._update_stats()
        self.path.stats["start"] = self.start
        return self.path


# ====================================================================== entry point
def friction_stepper(system, alpha, F_start, F_end, method="exact", options=None, solver=None, resume=None,
                     monitor=None):
    """The stepper of a friction path (validated request): :class:`FrictionStepper` or
    :class:`SeedFrictionStepper`."""
    a, span, opts, solver = _check_request(system, alpha, F_start, F_end, options, method, solver)
    check_monitor(monitor)
    if method == "seed":
        if resume is not None:
            raise InputError("the seed method in F cannot resume (trace it again)")
        return SeedFrictionStepper(system, a, span, opts, solver, monitor=monitor)
    return FrictionStepper(system, a, span, opts, solver, resume=resume, monitor=monitor)


def trace_friction_path(system, alpha: float, F_start: float, F_end: float, method: str = "exact",
                        options: Optional[PathOptions] = None, solver=None, callback=None, resume=None,
                        monitor=None, **overrides) -> FrictionPath:
    """Follow the solutions at the load f(alpha) as the friction coefficient runs from F_start to
    F_end (see the module docstring).

    ``method``: "exact" (transitions as exact roots in F) or "seed" (predictor-corrector in F,
    the reference); ``options``: PathOptions (``max_transitions``, ``tie_rtol``, ``tol`` and
    ``max_iter`` of the start; the seed's step options in F) or keyword ``overrides``;
    ``solver``: the system's :class:`~cfcontact.condensed.CondensedSolver` (default: its cached
    one); ``callback`` and ``resume`` as for :func:`cfcontact.exact.trace_exact` (exact only);
    ``monitor`` as there (the start's homotopy, both methods).

    Returns a :class:`FrictionPath` (status "completed", "stuck" -- see its events, e.g.
    "unbounded" when a branch becomes singular before any of its constraints vanishes --,
    "closed_loop", "cycling", "max_transitions" or "stopped by callback")."""
    if overrides:
        options = PathOptions.with_overrides(options, **overrides)
    t0 = time.perf_counter()
    stepper = friction_stepper(system, alpha, F_start, F_end, method, options, solver, resume, monitor)
    path = stepper.run(callback)
    log.info("friction path traced in %.3g s", time.perf_counter() - t0)
    return path
