"""The seed's path following (its Section 4) as a stepper.

On an oriented branch (inactive sets Z, orientation s) the predictor-corrector takes
y_pred = DirNeu(Z, f(alpha + s h)) and accepts the step iff SSNM returns the predictor after one
iteration (``is_fixed_point``); the step grows by c_p after a success and shrinks by c_s after
a failure, within [h_min, h_max].  A failure at h_min runs the branching algorithm: the
branching indicator (17) picks the set change (18); the branch continues transversally if
DirNeu with the new sets is a fixed point at alpha + s h_fail, otherwise it is a fold.  When
the indicator's minimizer is misleading, further candidates are tried (:func:`_branching`).

:class:`SeedStepper` holds the loop state (branch, alpha, y, step h, step count, cycle
detector) between accepted points, so its :attr:`~SeedStepper.resume_state` is always current:
a checkpoint is a save of the live path and that state.
"""

from __future__ import annotations

import logging
from typing import Optional

import numpy as np

from cfcontact.errors import ConvergenceError, InputError, SingularSystemError
from cfcontact.options import AlphaSpan, PathOptions
from cfcontact.solution_path import SET_NAMES, PathEvent, PathPoint, SolutionPath, Transition
from cfcontact.ssnm import InactiveSets, Solution, get_solver, indicators, is_fixed_point
from cfcontact.start import (branch_endpoints, consistent_up_to_ties, failed_start, indicator_ties, oriented_start,
                             resume_parts, start_point)
from cfcontact.stepper import Stepper

log = logging.getLogger(__name__)


class SeedStepper(Stepper):
    """One run of the seed method ([JL-PF]'s predictor-corrector); see :class:`cfcontact.stepper.Stepper`.

    ``resume``: ``{"path": SolutionPath, "state": resume state}`` of a stopped or checkpointed
    run (the path possibly saved and loaded); new points are appended to that path.
    """

    method = "seed"

    def __init__(self, system, span: AlphaSpan, options: PathOptions, solver=None, y0=None, resume=None,
                 monitor=None):
        self.system, self.span, self.opts = system, span, options
        self.solver = solver or get_solver(system)
        self.f1, self.f2 = system.loads_numpy()
        if resume is None:
            self._start_clock()
            self.path = SolutionPath.for_system(system, "seed", span.start, span.end, options.to_dict())
            start = self._start_point(span.start, y0, monitor)
            start = oriented_start(system, start, span, options, self.solver,  # a degenerate start: its sets
                                   reach=lambda a: self._sets_at(a, monitor))
            self.Z, self.s, self.alpha, self.y = start.sets, span.direction, span.start, start.y
            self.branch = self.path.add_branch(self.Z, self.s, *branch_endpoints(system, self.solver, self.Z),
                                               alpha_enter=self.alpha)
            self.path.add_point(self.branch, self.alpha, self.y)
            self.h, self.steps, self.last_seen, self.done = options.h0, 0, {}, False
            self._pending_point = 0  # the start point is the first accepted point
        else:  # continue exactly after the last accepted point of the stopped run
            path, state = resume_parts(system, span.start, span.end, resume, "seed")
            self._start_clock(path.stats)
            self.start = {k: path.stats[k] for k in ("start", "homotopy_transitions") if k in path.stats}
            self.path = path
            try:
                self.h, self.steps = float(state["h"]), int(state["steps"])
                self.last_seen = {(bytes.fromhex(k), int(sg), int(r)): int(c)
                                  for k, sg, r, c in state.get("last_seen", [])}
                self.done = state.get("done", False)
            except (KeyError, TypeError, ValueError) as exc:
                raise InputError(f"cannot resume: incomplete or invalid resume state ({exc!r})") from None
            if not (np.isfinite(self.h) and self.h > 0) or self.steps < 0 or not isinstance(self.done, bool):
                raise InputError(f"cannot resume: invalid resume state (h = {self.h!r}, steps = {self.steps!r}, done = "
                                 f"{self.done!r}; expected h > 0, steps >= 0, done true or false)")
            if self.done and path._alphas[-1] not in (span.lo, span.hi):
                raise InputError(f"cannot resume: the resume state says the run ended, but its path ends at alpha = "
                                 f"{path._alphas[-1]!r}, inside the range [{span.lo!r}, {span.hi!r}]")
            self.branch = path.branches[-1]
            self.Z, self.s = self.branch.sets, self.branch.orientation
            self.alpha, self.y = path._alphas[-1], path._ys[-1]
            path.status = "running"

    def _start_point(self, alpha, y0, monitor=None) -> Solution:
        """SSNM's solution at alpha (:func:`start_point`: with its restarts); where SSNM does not
        converge (at large F it can cycle from every start it is given), the solution the exact
        method reaches in the condensed multipliers (:func:`cfcontact.exact.reach_start`; ``monitor``
        sees its homotopy), solved with this run's backend and checked (an event "start_reached"
        says how)."""
        system, path = self.system, self.path
        try:
            start = start_point(system, alpha, y0, self.opts, self.solver)
            self.start = {"start": "ssnm"}
            return start
        except (ConvergenceError, SingularSystemError) as exc:
            if y0 is not None or not failed_start(exc):
                raise
            failure = exc
        from cfcontact.exact import reach_start

        sets, how, n = reach_start(system, alpha, path, self.opts, monitor)
        y = self.solver.solve(sets, system.load(alpha))
        if not _fixed_point(system, y, sets):
            raise ConvergenceError(f"{failure}; the start the exact method reached ({how}) is not a fixed point "
                                   f"with this backend") from failure
        self.start = {"start": how, "homotopy_transitions": n}
        path.events.append(PathEvent("start_reached", alpha, f"SSNM did not converge at alpha_start; the start "
                                     f"was reached by the exact method ({how}, {n} transition(s))", None,
                                     {"how": how, "transitions": n}))
        return Solution.from_y(system, y, alpha, sets)

    def _sets_at(self, alpha, monitor=None) -> InactiveSets:
        """Sets of a solution at alpha: :func:`start_point` (SSNM with its restarts), else the exact
        method's :func:`~cfcontact.exact.reach_start`; ConvergenceError when neither finds one."""
        try:
            return start_point(self.system, alpha, None, self.opts, self.solver).sets
        except (ConvergenceError, SingularSystemError) as exc:
            if not failed_start(exc):
                raise
            from cfcontact.exact import reach_start

            return reach_start(self.system, alpha, self.path, self.opts, monitor)[0]

    # ------------------------------------------------------------- stepper interface
    @property
    def resume_state(self) -> dict:
        """The loop state after the last accepted point: step h, step count, whether that point
        ended the run, and the cycle detector."""
        return {"h": self.h, "steps": self.steps, "done": bool(self.done),
                "last_seen": [[k.hex(), sg, r, c] for (k, sg, r), c in self.last_seen.items()]}

    def point(self, index: int) -> PathPoint:
        path = self.path
        sol = Solution.from_y(self.system, path._ys[index], path._alphas[index], sets=self.Z)
        return PathPoint(index, path._alphas[index], self.branch.index, sol, path)

    def stop(self) -> SolutionPath:
        return self._finish("stopped by callback", done=self.done)

    def _update_stats(self):
        self.branch.alpha_exit = self.alpha
        super()._update_stats()
        self.path.stats.update(self.start)

    def _finish(self, status, done=False) -> SolutionPath:
        self.finished = True
        self.branch.alpha_exit = self.alpha
        self.path.status = status
        self._update_stats()
        self.done = done  # the state for trace_path(resume=...): had the run ended at its last point?
        self.path.resume_state = self.resume_state
        log.info("seed path: %s", self.path)
        return self.path

    def _step(self) -> Optional[int]:
        system, solver, opts, path = self.system, self.solver, self.opts, self.path
        lo, hi, f1, f2 = self.span.lo, self.span.hi, self.f1, self.f2
        while True:
            self.steps += 1
            alpha, s, Z, h = self.alpha, self.s, self.Z, self.h
            if self.steps > opts.max_steps:
                path.events.append(PathEvent("max_steps", alpha, f"step cap {opts.max_steps} reached",
                                             self.branch.index))
                self._finish("max_steps")
                return None
            a_new = alpha + s * h
            clipped = False
            if a_new >= hi or a_new <= lo:
                a_new = min(max(a_new, lo), hi)
                clipped = True
            step = abs(a_new - alpha)
            y_pred = solver.solve(Z, (1.0 - a_new) * f1 + a_new * f2) if step > 0 else self.y
            # (a step may end on a tie: at the end of the span -- a zero load there, say -- or on a branch
            # where a node sits exactly on its boundary; see _fixed_point)
            if step > 0 and _fixed_point(system, y_pred, Z):
                self.alpha, self.y = a_new, y_pred
                idx = path.add_point(self.branch, a_new, y_pred)
                self.h = min(opts.c_p * h, opts.h_max)
                self.done = clipped
                return idx
            if h > opts.h_min and step > 0:
                self.h = max(opts.c_s * h, opts.h_min)
                continue
            idx = self._transition(step if step > 0 else h)
            if idx is _UNVERIFIED:
                continue  # no point stored: the new branch's first accepted step is
            return idx

    def _transition(self, h_fail) -> Optional[int]:
        """The branching algorithm at the last point (alpha, y) of the branch; index of the first
        point on the new branch, or None when the run ends here."""
        system, solver, opts, path = self.system, self.solver, self.opts, self.path
        alpha, s, Z, y, branch = self.alpha, self.s, self.Z, self.y, self.branch
        lo, hi = self.span.lo, self.span.hi
        if len(path.transitions) >= opts.max_transitions:
            path.events.append(PathEvent("max_transitions", alpha, f"transition cap {opts.max_transitions} reached",
                                         branch.index))
            self._finish("max_transitions")
            return None
        choice = _branching(system, solver, y, Z, alpha, s, h_fail, lo, hi)
        if choice is None:
            path.events.append(PathEvent("no_indicator", alpha, "no set change available at the branch end",
                                         branch.index))
            self._finish("stuck")
            return None
        a1 = alpha + s * h_fail
        if not choice[7]:
            choice = self._through_apex(alpha, a1) or choice
        tkind, node, kind, Z_new, s_new, a_next, y_next, verified, changes = choice
        if not verified:
            path.events.append(PathEvent(
                "unverified_transition", alpha,
                "no candidate set change gives a solution on either side; the seed's rule (a fold) was applied "
                "with the smallest indicator", branch.index, {"node": node, "set": kind}))
        key = (Z_new.canonical_key(system.friction), s_new, round(a_next / max(opts.h_min, 1e-300)))
        self.last_seen[key] = self.last_seen.get(key, 0) + 1
        if self.last_seen[key] > 2:
            path.events.append(PathEvent("cycling", alpha, "the branching algorithm returns to the same branch at "
                                         "the same alpha; the transition cannot be resolved by the seed's indicator",
                                         branch.index, {"node": node, "set": kind}))
            self._finish("cycling")
            return None
        branch.alpha_exit = alpha
        tr = Transition(len(path.transitions), alpha, tkind, node, kind, branch.index, len(path.branches),
                        bracket=(min(alpha, a1), max(alpha, a1)),
                        changes=changes)
        path.transitions.append(tr)
        log.info("alpha=%.8g %s transition: node %d set %s", alpha, tkind, node, kind)
        self.branch = path.add_branch(Z_new, s_new, *branch_endpoints(system, solver, Z_new), origin=tr.index,
                                      parent=branch.index, alpha_enter=alpha)
        self.Z, self.s, self.alpha, self.y = Z_new, s_new, a_next, y_next
        if not verified:
            # the seed's rule was applied, but its point is no solution: it is not stored (the
            # predictor-corrector goes on from it; its accepted steps are verified)
            return _UNVERIFIED
        idx = path.add_point(self.branch, a_next, y_next)
        self.done = tkind == "transversal" and (a_next >= hi or a_next <= lo)
        return idx

    def _through_apex(self, alpha, a1):
        """A transversal continuation through an apex between alpha and a1, or None.

        Where the load vanishes between the two (f(alpha*) = 0 to APEX_ULPS of rounding: a load
        reversed through zero) and no gap is open, every multiplier and indicator vanishes at
        alpha*, and no single or double set change continues the path.  Beyond alpha* the problem is
        positively homogeneous: the sets of a solution at a1 (SSNM with its restarts, else the
        exact method's homotopies) are those of the ray that leaves the apex."""
        from cfcontact.exact import affine_zero

        system, solver = self.system, self.solver
        if np.any(np.asarray(system.gap) != 0.0):
            return None
        a_star = affine_zero(self.f1, self.f2)
        if a_star is None or not (min(alpha, a1) <= a_star <= max(alpha, a1)):
            return None
        try:
            Z1 = self._sets_at(a1)
        except ConvergenceError:
            return None
        y1 = solver.solve(Z1, (1.0 - a1) * self.f1 + a1 * self.f2)
        if not _fixed_point(system, y1, Z1):
            return None
        changes = _set_changes(system, self.Z, Z1)
        if not changes:
            return None
        log.info("alpha=%.8g: the load vanishes at alpha=%.12g (an apex); %d node(s) change state there", alpha,
                 a_star, len({c["node"] for c in changes}))
        return ("transversal", changes[0]["node"], changes[0]["set"], Z1, self.s, a1, y1, True, changes)


def _set_changes(system, Z0, Z1) -> list:
    """[{"node", "set"}] of the nodes whose state differs between Z0 and Z1 (canonical states),
    each named by the first set that differs (nu, tp, tm)."""
    from cfcontact.exact import canonical_codes

    c0 = canonical_codes(Z0, system.friction, system.no_tangent)
    c1 = canonical_codes(Z1, system.friction, system.no_tangent)
    out = []
    for i in np.flatnonzero(c0 != c1):
        i = int(i)
        pairs = (("nu", Z0.nu, Z1.nu), ("tp", Z0.tp, Z1.tp), ("tm", Z0.tm, Z1.tm))
        kind = next((k for k, a, b in pairs if a[i] != b[i]), "nu")
        out.append({"node": i, "set": kind})
    return out


#: _transition's answer when the new branch's first point could not be verified (none is stored).
_UNVERIFIED = object()


# ------------------------------------------------------------------ branching
def _ranked_toggles(system, y, sets, limit=8, order=None):
    """Non-trivial single toggles ordered by |indicator| (rule (17)), at most ``limit``; or in the
    given ``order`` (indices into the stacked indicators (a, bp, bm), 3m).

    Toggles that cannot change DirNeu's solution (the tangential set of an open node, or of a
    node with F = 0 between I_t^+ and I_t^-) are skipped, and so are the tangential toggles of
    a node without tangential unknown (``system.no_tangent``: its lam_t enters no equation).
    Returns [(value, node, kind, Z_new)].
    """
    a, bp, bm = indicators(system, y)
    no_tangent = system.no_tangent
    free = sets.nu & ~no_tangent
    if np.any(free):
        # The tangential sets of an open node do not change DirNeu's solution, so they go stale
        # along a branch (T u may change sign).  Refresh them from y, so that closing the node
        # (toggling I_nu) starts it slipping in the direction of its current T u.  (A node
        # without tangential unknown sticks in every consistent set: lam_t = 0 = T u.)
        tm = np.where(free, bm < 0, sets.tm)
        sets = InactiveSets(sets.nu, np.where(free, ~tm, sets.tp), tm)
    _, tp_tie, tm_tie = indicator_ties(system, y)
    vals = np.concatenate([np.abs(a), np.abs(bp), np.abs(bm)])
    out = []
    for k in (np.argsort(vals, kind="stable") if order is None else order):
        kind, i = SET_NAMES[k // system.m], int(k % system.m)
        if kind != "nu" and (no_tangent[i] or sets.nu[i]):
            continue
        new = _toggled(sets, i, kind, no_tangent)
        if not new.equivalent(sets, system.friction):
            out.append((float(vals[k]), i, kind, new))
            if kind == "nu" and sets.nu[i] and (tp_tie[i] or tm_tie[i]):
                # closing a node whose T u vanishes (e.g. a rigid approach): no slip direction is
                # decided, so sticking is a candidate too
                other = np.arange(system.m) != i
                out.append((float(vals[k]), i, kind, InactiveSets(new.nu, new.tp & other, new.tm & other)))
            if len(out) >= limit:
                break
    return out


def _branching(system, solver, y, Z, alpha, s, h_fail, lo, hi):
    """The seed's branching algorithm, made robust.

    First the seed's own choice (the minimizer of (17)): transversal if DirNeu(Z_new) at
    alpha + s h_fail is a fixed point, else a fold if DirNeu(Z_new) at alpha is one.  When
    neither holds (two indicators vanish within one step, or the minimizer is misleading),
    the indicators that change sign over the failed step (nearest root first), the next
    candidates of (17) and pairs of the first ones are tried the same way, keeping only
    continuations that join the old branch continuously.  Returns
    (kind, node, set, Z_new, s_new, alpha_next, y_next, verified, changes) or None.
    """
    f1, f2 = system.loads_numpy()
    load = lambda a: (1.0 - a) * f1 + a * f2  # noqa: E731
    singles = _ranked_toggles(system, y, Z)
    if not singles:
        return None
    a1 = alpha + s * h_fail
    y_old_1 = solver.solve(Z, load(a1)) if lo <= a1 <= hi else None
    if y_old_1 is not None:
        # After the seed's own choice, the indicators that change sign over the failed step (on the
        # old branch), nearest root first: the constraint the step could not cross.  Rule (17)
        # compares indicators of different kinds by size (a multiplier against rho times a slip),
        # and on soft bodies a slipping node's indicator can be thousands of times the closed
        # nodes' lam_n a step before its root, which left it out of the first eight.
        first = (singles[0][1], singles[0][2])
        extra = [c for c in _crossing_toggles(system, y, y_old_1, Z) if (c[1], c[2]) != first]
        taken = {(c[1], c[2]) for c in extra}
        singles = singles[:1] + extra + [c for c in singles[1:] if (c[1], c[2]) not in taken]
    cands = [(c[3], [(c[1], c[2])]) for c in singles]
    top = singles[:4]
    for i in range(len(top)):
        for j in range(i + 1, len(top)):
            if top[i][1] == top[j][1] and top[i][2] == top[j][2]:
                continue
            Zp = _toggled(top[i][3], top[j][1], top[j][2], system.no_tangent)
            cands.append((Zp, [(top[i][1], top[i][2]), (top[j][1], top[j][2])]))
    for Zn, changes in cands:
        node, kind = changes[0]
        y1 = solver.solve(Zn, load(a1)) if lo <= a1 <= hi else None
        # continuity with the old branch: the two affine branches meet at the transition (also
        # for the seed's own choice: at a near-tie the minimizer of (17) can be a node whose
        # toggle leads onto another branch that is consistent at alpha + s h_fail -- back onto
        # the branch the path came from, say -- a jump the fixed-point test does not see)
        y2 = solver.solve(Zn, load(alpha))
        jump = np.linalg.norm(y2 - y)
        scale = np.linalg.norm(y) + 1e-300
        if y1 is not None and y_old_1 is not None:
            slope_gap = np.linalg.norm((y1 - y2) - (y_old_1 - y)) / max(h_fail, 1e-300) * h_fail
            if jump > 2.0 * slope_gap + 1e-9 * scale:
                continue
        if y1 is not None and _fixed_point(system, y1, Zn):
            return ("transversal", node, kind, Zn, s, a1, y1, True, [{"node": n, "set": k} for n, k in changes])
        if is_fixed_point(system, y2, Zn):  # strict: a tied node's toggle would pass vacuously
            return ("fold", node, kind, Zn, -s, alpha, y2, True, [{"node": n, "set": k} for n, k in changes])
    Zn, changes = cands[0]
    node, kind = changes[0]
    return ("fold", node, kind, Zn, -s, alpha, solver.solve(Zn, load(alpha)), False,
            [{"node": node, "set": kind}])


def _crossing_toggles(system, y0, y1, sets, limit=4):
    """The toggles of the indicators that change sign between y0 and y1 (two points of one
    branch), ordered by where their linear interpolation vanishes (nearest y0 first), at most
    ``limit``; filtered as :func:`_ranked_toggles`."""
    g0 = np.concatenate(indicators(system, y0))
    g1 = np.concatenate(indicators(system, y1))
    k = np.flatnonzero((g0 != 0.0) & (np.sign(g0) != np.sign(g1)))
    if not k.size:
        return []
    t = g0[k] / (g0[k] - g1[k])
    return _ranked_toggles(system, y0, sets, limit=limit, order=k[np.argsort(t, kind="stable")])


def _fixed_point(system, y, Z) -> bool:
    """Remark 3.1's test (Z(y) = Z), where an indicator that vanishes at y (:func:`indicator_ties`)
    may take either side.  A node can sit exactly on a boundary for a whole branch: a contact node
    clamped on one side whose other side is unloaded once every node is open has N u = g and
    lam = 0 there for every alpha.  The strict test puts it in the active set, so no candidate of the
    branching algorithm passed and the seed's fold rule turned the path back at a transversal
    transition.  (A step that ends at a clipped end of the span needs the same closure: the load
    may vanish there.  A generic point has no tie, and the strict test is tried first.)  Not for a
    fold's test at the branch end: there a toggle of a tied node changes nothing and would pass."""
    return is_fixed_point(system, y, Z) or consistent_up_to_ties(system, y, Z)


def _toggled(sets: InactiveSets, i: int, kind: str, no_tangent) -> InactiveSets:
    """:func:`toggle`, except that a sticking node that opens is freed tangentially (put in I_t^+).
    Rule (18) alone leaves it sticking: DirNeu then imposes T u = 0 at a node with lam_n = 0, and
    its reaction lam_t is not 0, so the candidate is no solution (|lam_t| > F lam_n = 0) unless
    lam_t vanishes by chance.  A node that opens from sticking is a degenerate point (lam_t -> 0
    with lam_n), typical of a node whose force stays zero (a clamped end of the interface); the
    branching algorithm found no candidate there and applied its fold rule."""
    new = toggle(sets, i, kind)
    if kind == "nu" and new.nu[i] and not (new.tp[i] or new.tm[i] or no_tangent[i]):
        tp = new.tp.copy()
        tp[i] = True
        new = InactiveSets(new.nu, tp, new.tm)
    return new


def toggle(sets: InactiveSets, i: int, kind: str) -> InactiveSets:
    """Move node i between the active and inactive set named by kind (rule (18))."""
    nu, tp, tm = sets.nu.copy(), sets.tp.copy(), sets.tm.copy()
    if kind == "nu":
        nu[i] = not nu[i]
    elif kind == "tp":
        tp[i] = not tp[i]
    elif kind == "tm":
        tm[i] = not tm[i]
    else:
        raise ValueError(kind)
    return InactiveSets(nu, tp, tm)
