"""Exact piecewise-affine path following (no step sizes).

On a branch with inactive sets Z fixed, y(alpha) = (1 - alpha) Y1 + alpha Y2 exactly, with
Y1 = DirNeu(Z, f1), Y2 = DirNeu(Z, f2).  The three indicator vectors of (17)

    a = lam_n + rho N u,   bp = lam_t + rho T u - F lam_n,   bm = lam_t + rho T u + F lam_n

are linear in y, hence affine in alpha along the branch.  Z is consistent (Remark 3.1) as long
as every indicator keeps the sign Z requires.  Per node state (``ssnm.STATE_NAMES``) the
required signs ("constraints" c >= 0, closed) are

    open   : -a >= 0                         (lam_n = lam_t = 0; the sign of T u is irrelevant)
    stick  :  a >= 0, -bp >= 0, bm >= 0
    slip+  :  a >= 0,  bp >= 0              (bm = bp + 2 F a >= 0 follows)
    slip-  :  a >= 0, -bm >= 0              (bp = bm - 2 F a <= 0 follows)
    F = 0  : slip+ and slip- coincide (tangentially free: a >= 0 only)

The branch is left at the first root (in the orientation s) of a constraint that decreases
(ratio test).  At that transition point y*, the states of the nodes whose constraints vanish
("involved" nodes) are re-decided: a state is admissible at y* iff its constraints hold at y*
(closed signs) -- which is equivalent to y* = DirNeu(Z', f(alpha*)), so every admissible
candidate Z' continues y continuously.  A candidate branch y'(alpha) (2 solves) continues the
path in the direction d = +-1 iff each of its constraints is either positive at alpha* or
vanishes there with d * slope > 0 (or vanishes identically).  This is decided from values and
slopes only, with a relative tolerance ``tie_rtol`` on the indicator scale for "vanishes";
there is no step size.  Exactly one continuation: a "transversal" transition (d = s) or a
"fold" (d = -s).  Several: a branch point (a ``PathEvent("branch_point")`` lists every
alternative; :func:`follow_alternative` follows another one later, the path being a tree of
branches linked by ``Branch.parent`` / ``Branch.origin``).  None: ``PathEvent("dead_end")`` and
status "stuck".  Revisiting the same (Z, s, alpha): ``PathEvent("cycling")``.

Cost: two solves per candidate branch (one factorization of J(Z) with the default PETSc
backend; with :class:`cfcontact.condensed.CondensedSolver` one factorization of K in total and
dense 2m x 2m solves per branch).
"""

from __future__ import annotations

import itertools
import logging
import math
import time
from typing import Optional

import numpy as np

from cfcontact.errors import ConvergenceError, InputError, SingularSystemError
from cfcontact.options import TIE_RTOL, AlphaSpan, PathOptions
from cfcontact.solution_path import SET_NAMES, PathEvent, PathPoint, SolutionPath, Transition
from cfcontact.ssnm import STATE_NAMES, InactiveSets, Solution, get_solver, indicators
from cfcontact.start import branch_endpoints, check_request, resume_parts, start_point
from cfcontact.system import ContactSystem

log = logging.getLogger(__name__)

#: TIE_RTOL (from :mod:`cfcontact.options`, the default of ``PathOptions.tie_rtol``): the relative
#: tolerance deciding that an indicator "vanishes" (relative to the largest indicator magnitude of
#: the branch) or that a slope is zero.
#: Constraints whose roots lie further apart than this (times 1 + |alpha|) are separate
#: transitions even when their values at a transition point are within the tolerance.
ALPHA_WINDOW = 1e-9
#: At most this many candidate set combinations are examined at one transition point.
MAX_CANDIDATES = 4096
#: When SSNM cannot find the start solution, problems with at most this many contact nodes are
#: started from a solution found by enumeration (:mod:`cfcontact.enumerate`).
START_ENUMERATION_MAX_NODES = 8

OPEN, STICK, SLIP_P, SLIP_M = 0, 1, 2, 3
# constraints per state: (indicator 0=a, 1=bp, 2=bm ; sign) meaning sign * indicator >= 0
_CONS = {
    (OPEN, False): ((0, -1.0),),
    (STICK, False): ((0, 1.0), (1, -1.0), (2, 1.0)),
    (SLIP_P, False): ((0, 1.0), (1, 1.0)),
    (SLIP_M, False): ((0, 1.0), (2, -1.0)),
    # F = 0 at the node: tangentially free (slip+ == slip-), stick only with lam_t = 0
    (OPEN, True): ((0, -1.0),),
    (STICK, True): ((0, 1.0), (1, -1.0), (2, 1.0)),
    (SLIP_P, True): ((0, 1.0),),
    (SLIP_M, True): ((0, 1.0),),
}


def canonical_codes(sets: InactiveSets, friction) -> np.ndarray:
    """Per-node state codes (0 open, 1 stick, 2 slip+, 3 slip-) with the canonical choices:
    an open node is tangentially free, a node with F = 0 that is tangentially free is slip+."""
    F = np.broadcast_to(np.asarray(friction, dtype=float), (sets.m,))
    codes = sets.state_codes().astype(np.int8)  # tp & tm -> 2 (slip+)
    codes = np.where((codes == SLIP_M) & (F == 0.0), SLIP_P, codes)
    return codes.astype(np.int8)


# membership (I_nu, I_t+, I_t-) of each state code; an open node is tangentially free (I_t+)
_SETS_OF_CODE = np.array([[True, True, False], [False, False, False], [False, True, False], [False, False, True]])


def sets_from_codes(codes) -> InactiveSets:
    table = _SETS_OF_CODE[np.asarray(codes)]  # m x 3
    return InactiveSets(table[:, 0], table[:, 1], table[:, 2])


# _CONS as a table: _CONS_SIGN[state, F == 0, indicator] = sign of that constraint (0: none)
_CONS_SIGN = np.zeros((4, 2, 3))
for (_st, _f0), _cs in _CONS.items():
    for _ind, _sg in _cs:
        _CONS_SIGN[_st, int(_f0), _ind] = _sg


def state_constraints(codes, F0) -> tuple:
    """(flat indicator index ind*m + node, sign, node) of every constraint of the states ``codes``
    (node by node, each node's constraints in the order of the indicators)."""
    codes = np.asarray(codes)
    m = codes.size
    table = _CONS_SIGN[codes, np.asarray(F0, dtype=np.intp)]  # m x 3
    nodes, ind = table.nonzero()
    return ind * m + nodes, table[nodes, ind], nodes


class _Line:
    """One candidate branch: sets, y(alpha) = (1-alpha) Y1 + alpha Y2, its constraints.

    The multipliers (lam_n, lam_t) at alpha = 0 and 1 and the indicators are always at hand;
    the whole Y1, Y2 (with u) are formed when first needed (with the condensed backend that
    costs O(n m), so only branches the path takes pay it)."""

    def __init__(self, codes, sets, lam1, lam2, g1, g2, cidx, csgn, cnode, full, source=None):
        self.codes, self._sets = codes, sets  # sets: None = formed from codes when first needed
        self.key = codes.tobytes()  # identity of the line (its canonical state codes, _Context.key)
        self.source = source  # backend forming u on demand (lazy branches of the path), or None
        self.lam1, self.lam2 = lam1, lam2
        self.g1, self.g2 = g1, g2
        self.c1, self.c2 = csgn * g1[cidx], csgn * g2[cidx]  # constraint values at alpha = 0 and 1
        self.slopes = self.c2 - self.c1
        self.cidx, self.cnode = cidx, cnode
        self.gmax1 = float(np.abs(g1).max()) if g1.size else 0.0
        self.gmax2 = float(np.abs(g2).max()) if g2.size else 0.0
        self._full = full
        self._Y = None

    @property
    def sets(self) -> InactiveSets:
        if self._sets is None:
            self._sets = sets_from_codes(self.codes)
        return self._sets

    @property
    def Y1(self):
        if self._Y is None:
            self._Y = self._full()
        return self._Y[0]

    @property
    def Y2(self):
        if self._Y is None:
            self._Y = self._full()
        return self._Y[1]

    def y(self, alpha):
        return (1.0 - alpha) * self.Y1 + alpha * self.Y2

    def lam(self, alpha):
        return (1.0 - alpha) * self.lam1 + alpha * self.lam2

    def indicators(self, alpha):
        return (1.0 - alpha) * self.g1 + alpha * self.g2

    def values(self, alpha):
        return (1.0 - alpha) * self.c1 + alpha * self.c2

    def tol_v(self, alpha, rtol):
        return rtol * (abs(1.0 - alpha) * self.gmax1 + abs(alpha) * self.gmax2) + 1e-300

    def tol_s(self, rtol):
        return rtol * (self.gmax1 + self.gmax2) + 1e-300


class _Context:
    def __init__(self, system, solver, opts, lo, hi, rtol, callback=None):
        self.system, self.solver, self.opts, self.callback = system, solver, opts, callback
        self.lo, self.hi, self.rtol = lo, hi, rtol
        self.Fv = system.friction_vector
        self.F0 = self.Fv == 0.0
        self.F0_index = self.F0.astype(np.intp)  # second index of _CONS_SIGN
        self.m = system.m
        self.f1, self.f2 = system.loads_numpy()
        self.visited: dict = {}
        self.lines: dict = {}  # canonical key -> _Line (re-used at branch points / alternatives)
        self._W = None  # condensed backend: (w1, w2) = B K^-1 (f1, f2)

    def prepare_loads(self):
        """Condensed backend: w1, w2 = B K^-1 (f1, f2) in one two-column solve."""
        if self._W is None and hasattr(self.solver, "load_data_many"):
            self._W = self.solver.load_data_many([self.f1, self.f2])

    def _condensed_indicators(self, lam, w):
        m, rho = self.m, self.system.rho
        Bu = w - self.solver.S @ lam
        b = lam[m:] + rho * Bu[m:]
        return np.concatenate([lam[:m] + rho * Bu[:m], b - self.Fv * lam[:m], b + self.Fv * lam[:m]])

    def key(self, codes):
        return np.asarray(codes, dtype=np.int8).tobytes()

    def line(self, codes) -> _Line:
        codes = np.asarray(codes, dtype=np.int8)
        k = codes.tobytes()  # = self.key(codes)
        ln = self.lines.get(k)
        if ln is not None:
            return ln
        system, solver, n = self.system, self.solver, self.system.n
        cidx, csgn, cnode = state_constraints(codes, self.F0_index)
        if hasattr(solver, "branch_data"):
            # condensed backend: both loads with one LU and no u (formed on demand by the path);
            # the sets are passed as their codes (InactiveSets formed only for branches taken)
            if self._W is None:
                self.prepare_loads()
            L, G = solver.branch_data(self._W, b"exact:" + k, codes)
            lam1, lam2, g1, g2 = L[:, 0], L[:, 1], G[:, 0], G[:, 1]

            def full(lam1=lam1, lam2=lam2):
                U = solver.displacements(np.column_stack([lam1, lam2]), [0.0, 1.0])
                return np.concatenate([U[:, 0], lam1]), np.concatenate([U[:, 1], lam2])

            ln = _Line(codes, None, lam1, lam2, g1, g2, cidx, csgn, cnode, full, source=solver)
        elif hasattr(solver, "multipliers") and hasattr(solver, "load_data"):
            # condensed backend: multipliers and indicators in O(m^2), u only when needed
            sets = sets_from_codes(codes)
            w1, w2 = solver.load_data(self.f1), solver.load_data(self.f2)
            lam1, lam2 = solver.multipliers(sets, w1), solver.multipliers(sets, w2)
            g1, g2 = self._condensed_indicators(lam1, w1), self._condensed_indicators(lam2, w2)

            def full(lam1=lam1, lam2=lam2):
                return (np.concatenate([solver.displacement(self.f1, lam1), lam1]),
                        np.concatenate([solver.displacement(self.f2, lam2), lam2]))

            ln = _Line(codes, sets, lam1, lam2, g1, g2, cidx, csgn, cnode, full,
                       source=solver if hasattr(solver, "displacements") else None)
        else:
            sets = sets_from_codes(codes)
            Y1, Y2 = branch_endpoints(system, solver, sets)
            g1 = np.concatenate(indicators(system, Y1))
            g2 = np.concatenate(indicators(system, Y2))
            ln = _Line(codes, sets, Y1[n:], Y2[n:], g1, g2, cidx, csgn, cnode, lambda: (Y1, Y2))
        if len(self.lines) > 256:
            self.lines.clear()
        self.lines[k] = ln
        return ln


# ------------------------------------------------------------------ ratio test
def _exit(ctx: _Context, ln: _Line, alpha0: float, s: int):
    """First alpha (from alpha0 in direction s) where a decreasing constraint of ln vanishes.

    Returns (alpha_exit, vanishing constraint positions: a sorted list) or (None, None) when no
    constraint vanishes before the end of the alpha range."""
    sl = ln.slopes
    tol_s = ln.tol_s(ctx.rtol)
    dec = ((sl < -tol_s) if s > 0 else (sl > tol_s)).nonzero()[0]  # s * slope < -tol_s
    if not dec.size:
        return None, None
    c1, c2 = ln.c1[dec], ln.c2[dec]
    roots = c1 / (c1 - c2)
    dist = np.maximum((roots - alpha0) if s > 0 else (alpha0 - roots), 0.0)  # s * (roots - alpha0), >= 0
    j = int(dist.argmin())
    dj = float(dist[j])
    a_star = alpha0 + s * dj if dj == 0.0 else float(roots[j])
    bound = ctx.hi if s > 0 else ctx.lo
    if s * (a_star - bound) >= 0:
        return None, None
    vals = ln.values(a_star)
    vanish = (np.abs(vals) <= ln.tol_v(a_star, ctx.rtol)).nonzero()[0].tolist()
    first = int(dec[j])
    if first not in vanish:
        vanish = sorted(vanish + [first])
    return float(a_star), vanish


def _admissible_states(ctx: _Context, g_star: np.ndarray, node: int, tol: float) -> list:
    """States of ``node`` whose (closed) constraints hold at the indicator values g_star (3m)."""
    m = ctx.m
    f0 = bool(ctx.F0[node])
    g = (float(g_star[node]), float(g_star[m + node]), float(g_star[2 * m + node]))  # a, bp, bm
    out = []
    for st in (OPEN, STICK, SLIP_P, SLIP_M):
        if st == SLIP_M and f0:
            continue  # same as slip+ (free) when F = 0
        for ind, sg in _CONS[(st, f0)]:
            if not sg * g[ind] >= -tol:
                break
        else:  # every constraint holds
            out.append(st)
    return out


def _valid_directions(ctx: _Context, ln: _Line, alpha: float) -> tuple:
    """(valid for d = +1, valid for d = -1): is the branch ln consistent on [alpha, alpha + d*eps]
    for some eps > 0?  Decided from values and slopes: every constraint must be positive at alpha
    or vanish there and not decrease in the direction d."""
    vals = ln.values(alpha)
    tv = ln.tol_v(alpha, ctx.rtol)
    window = ALPHA_WINDOW * (1.0 + abs(alpha))
    # The constraints that vanish at alpha, up to rounding, decide by their slopes: a value within
    # tv, or -- for a steep constraint -- a value whose own root lies within the alpha window.  A
    # steep constraint (e.g. rho N u of a node that just opened, on a stiff/soft bimaterial model)
    # evaluated at the transition alpha of another line misses zero by its slope times the
    # rounding error of that alpha, with either sign (it differed between Debian 12 and 13).
    # Negative values beyond that are violations.
    reach = tv + np.abs(ln.slopes) * window
    zero = (vals <= reach).nonzero()[0]
    if not zero.size:
        return True, True
    vz, sz, rz = vals[zero], ln.slopes[zero], reach[zero]
    if (vz < -rz).any():
        return False, False
    vz, sz = vz.tolist(), sz.tolist()
    ts = ln.tol_s(ctx.rtol)
    valid = [True, True]
    # few constraints vanish at once: plain floats are cheaper than array operations here
    for v, sl in zip(vz, sz):
        for k, d in enumerate((1, -1)):
            dsl = d * sl
            if v < -tv:  # negative: valid in direction d only if it turns positive within the window
                if not (dsl > ts and -v <= dsl * window + tv):
                    valid[k] = False
                continue
            # A positive value that reaches zero only beyond the alpha window ahead is a separate,
            # later transition (a near-tie on a fine mesh: the value tolerance is relative to the
            # largest indicator), not a constraint vanishing here; within the window it vanishes.
            ahead = v > 0.0 and dsl < -ts and v > -dsl * window
            if not (ahead or dsl > ts or abs(dsl) <= ts):
                valid[k] = False
    return valid[0], valid[1]


def _same_line(a: _Line, b: _Line, rtol=1e-10) -> bool:
    """Same y(alpha) (the multipliers determine u for a given load)."""
    sc = max(np.abs(a.lam1).max(initial=0), np.abs(a.lam2).max(initial=0), 1e-300)
    return bool(np.abs(a.lam1 - b.lam1).max(initial=0) <= rtol * sc
                and np.abs(a.lam2 - b.lam2).max(initial=0) <= rtol * sc)


def _continuations(ctx: _Context, ln: _Line, alpha: float, s: int, vanish) -> tuple:
    """Every (line, direction) continuing the path at the transition point alpha of branch (ln, s)."""
    lam_star = ln.lam(alpha)
    g_star = ln.indicators(alpha)  # indicators are linear in y
    tol = ln.tol_v(alpha, ctx.rtol)
    nodes = sorted(set(ln.cnode[vanish].tolist()))
    choices = [_admissible_states(ctx, g_star, i, tol) for i in nodes]
    total = math.prod(len(c) for c in choices) if choices else 0
    info = {"nodes": nodes, "admissible": {i: [STATE_NAMES[c] for c in ch] for i, ch in zip(nodes, choices)},
            "candidates": total}
    if total > MAX_CANDIDATES:
        return None, info
    current = ln.codes[nodes].tolist()  # the states of ln at these nodes
    combos = list(itertools.product(*choices))
    # fewest changed nodes first (deterministic preference)
    combos.sort(key=lambda cb: sum(c != o for c, o in zip(cb, current)))
    out = []
    lsc = max(np.abs(lam_star).max(initial=0), ln.tol_v(alpha, 1.0), 1e-300)
    for cb in combos:
        if list(cb) == current:
            continue  # ln itself
        codes = ln.codes.copy()
        codes[nodes] = cb
        try:
            cand = ctx.line(codes)
        except SingularSystemError as exc:
            log.info("alpha=%.12g: candidate %s skipped: %s", alpha, sets_from_codes(codes), exc)
            continue
        if np.abs(cand.lam(alpha) - lam_star).max(initial=0) > 1e-6 * lsc:
            log.info("alpha=%.12g: candidate %s does not pass through the transition point; skipped",
                     alpha, cand.sets)
            continue
        valid = _valid_directions(ctx, cand, alpha)
        for d in (s, -s):
            if not valid[0 if d > 0 else 1]:
                continue
            if d == -s and _same_line(cand, ln):
                continue  # the incoming branch itself (equivalent sets)
            if any(dd == d and _same_line(cand, other) for other, dd in out):
                continue
            out.append((cand, d))
    return out, info


# ---------------------------------------------------------------------- driver
def _add_branch(path, ln: _Line, s: int, **kw):
    """Add ln to the path: lazily (multipliers, indicators; u formed on demand) with a backend
    that forms displacements in batches, else with its end points Y1, Y2."""
    if ln.source is not None and ln._Y is None:
        return path.add_branch(ln.sets, s, None, None, multipliers=(ln.lam1, ln.lam2), indicators=(ln.g1, ln.g2),
                               source=ln.source, **kw)
    return path.add_branch(ln.sets, s, ln.Y1, ln.Y2, **kw)


def _finish(path, solver, stats0, t0, status, before=None):
    if path.lazy and getattr(solver, "size", 1) > 1:
        path.form()  # collective: form u now, so that a later rank-0-only use (save, plots) cannot hang
    path.status = status
    before = before or {}  # stats of the stopped run a resumed run continues
    st = solver.stats.as_dict()
    path.stats = {k: st[k] - stats0.get(k, 0) + before.get(k, 0) for k in st}
    path.stats["wall_time"] = time.perf_counter() - t0 + before.get("wall_time", 0.0)
    log.info("exact path: %s", path)
    return path


def _run(ctx: _Context, path: SolutionPath, ln: _Line, s: int, alpha: float, y_enter, parent=None, origin=None,
         budget=None, resume_branch=None, n_trans0=None) -> str:
    """Follow the path from (ln, s) entered at alpha; appends to ``path``; returns the status.

    resume_branch: continue on this branch of ``path`` (sets of ln, orientation s, entered at
    alpha, its entry point already stored and passed to the callback) instead of adding one;
    n_trans0: the transition count the ``max_transitions`` budget counts from (default: now).
    When the callback stops the run, ``path.resume_state`` holds what :func:`_resume` needs."""
    system, opts = ctx.system, ctx.opts
    if resume_branch is None:
        branch = _add_branch(path, ln, s, origin=origin, parent=parent, alpha_enter=alpha)
    else:
        branch = resume_branch
    if n_trans0 is None:
        n_trans0 = len(path.transitions)

    def stopped():
        branch.alpha_exit = alpha
        path.resume_state = _resume_state(ctx, branch, ln, s, alpha, n_trans0)
        return "stopped by callback"

    def emit(idx):
        if ctx.callback is None:
            return False
        sol = Solution.from_y(system, path._ys[idx], path._alphas[idx], sets=ln.sets)
        return bool(ctx.callback(PathPoint(idx, path._alphas[idx], branch.index, sol, path)))

    if resume_branch is None:
        idx = path.add_point(branch, alpha, y_enter)
        if emit(idx):
            return stopped()
    while True:
        key = (ln.key, s)
        seen = ctx.visited.setdefault(key, [])
        if any(abs(alpha - a) <= 1e-12 * (1.0 + abs(alpha)) for a in seen):
            path.events.append(PathEvent("cycling", alpha, f"branch {ln.sets} with orientation {s} entered again at "
                                         f"alpha={alpha!r}: the path loops", branch.index,
                                         {"sets": ln.sets.to_dict(), "orientation": s}))
            branch.alpha_exit = alpha
            return "cycling"
        seen.append(alpha)
        a_star, vanish = _exit(ctx, ln, alpha, s)
        if a_star is None:
            a_end = ctx.hi if s > 0 else ctx.lo
            branch.alpha_exit = a_end
            idx = path.add_point(branch, a_end)
            emit(idx)
            return "completed"
        branch.alpha_exit = a_star
        path.add_point(branch, a_star)
        limit = opts.max_transitions if budget is None else budget
        if len(path.transitions) - n_trans0 >= limit:
            path.events.append(PathEvent("max_transitions", a_star, f"transition cap {limit} reached",
                                         branch.index))
            return "max_transitions"
        conts, info = _continuations(ctx, ln, a_star, s, vanish)
        vanishing = [{"node": i, "set": SET_NAMES[c // ctx.m]}
                     for i, c in zip(ln.cnode[vanish].tolist(), ln.cidx[vanish].tolist())]
        if conts is None:
            path.events.append(PathEvent("degenerate", a_star, f"{info['candidates']} candidate set combinations at "
                                         f"nodes {info['nodes']} (limit {MAX_CANDIDATES}); the transition is "
                                         f"too degenerate to resolve", branch.index,
                                         {"vanishing": vanishing, **_jsonable(info)}))
            return "stuck"
        if not conts:
            path.events.append(PathEvent("dead_end", a_star, "no set combination continues the path at this "
                                         "transition point (one-sided consistency fails in both directions)",
                                         branch.index, {"vanishing": vanishing, **_jsonable(info)}))
            return "stuck"
        # prefer keeping the orientation, then folds; order within: fewest changed nodes
        conts.sort(key=lambda cd: 0 if cd[1] == s else 1)
        nxt, d = conts[0]
        kind = "transversal" if d == s else "fold"
        changes = []
        for ch in vanishing:
            i = ch["node"]
            changes.append({**ch, "from": STATE_NAMES[int(ln.codes[i])], "to": STATE_NAMES[int(nxt.codes[i])]})
        changed = {c["node"] for c in changes}
        # state changes at nodes whose own constraint did not vanish
        for i in (nxt.codes != ln.codes).nonzero()[0].tolist():
            if i not in changed:
                changes.append({"node": int(i), "set": None, "from": STATE_NAMES[int(ln.codes[i])],
                                "to": STATE_NAMES[int(nxt.codes[i])]})
        tr = Transition(len(path.transitions), a_star, kind, changes[0]["node"], changes[0]["set"], branch.index,
                        len(path.branches), bracket=(a_star, a_star), changes=changes)
        if len(conts) > 1:
            alts = [{"sets": c.sets.to_dict(), "states": c.sets.states(), "orientation": int(dd),
                     "kind": "transversal" if dd == s else "fold", "alpha": a_star, "chosen": k == 0}
                    for k, (c, dd) in enumerate(conts)]
            path.events.append(PathEvent("branch_point", a_star, f"{len(conts)} branches leave the transition point; "
                                         f"following the first (see data['alternatives'], follow_alternative)",
                                         branch.index, {"alternatives": alts, "transition": tr.index,
                                                        "vanishing": vanishing}))
        path.transitions.append(tr)
        log.info("alpha=%.12g %s transition: %s", a_star, kind, changes)
        parent_idx, ln, s, alpha = branch.index, nxt, d, a_star
        branch = _add_branch(path, ln, s, origin=tr.index, parent=parent_idx, alpha_enter=alpha)
        idx = path.add_point(branch, alpha)
        if emit(idx):
            return stopped()


def _jsonable(info):
    return {"nodes": list(map(int, info["nodes"])), "candidates": int(info["candidates"]),
            "admissible": {str(k): v for k, v in info["admissible"].items()}}


# ---------------------------------------------------------------------- resume
def _resume_state(ctx: _Context, branch, ln: _Line, s: int, alpha: float, n_trans0: int) -> dict:
    """What a stopped run needs to continue (JSON): the branch being followed (its index, canonical
    state codes, orientation, entry alpha -- its entry point is stored in the path), the transition
    count the max_transitions budget counts from, and the cycle detector.  Nothing else is pending:
    the alternatives of branch points are events of the path (follow_alternative)."""
    return {"branch": int(branch.index), "codes": [int(c) for c in ln.codes], "states": ln.sets.states(),
            "orientation": int(s), "alpha": float(alpha), "transitions0": int(n_trans0),
            "visited": [[k.hex(), int(sg), [float(a) for a in al]] for (k, sg), al in ctx.visited.items()]}


def _resume(system, span: AlphaSpan, options: PathOptions, solver, resume, callback=None) -> SolutionPath:
    """Continue an exact run stopped by its callback (see :func:`trace_exact`)."""
    t0 = time.perf_counter()
    path, state = resume_parts(system, span.start, span.end, resume, "exact")
    try:
        branch = path.branches[int(state["branch"])]
        codes = np.asarray(state["codes"], dtype=np.int8)
        s, alpha, n_trans0 = int(state["orientation"]), float(state["alpha"]), int(state["transitions0"])
        visited = {(bytes.fromhex(k), int(sg)): [float(a) for a in al] for k, sg, al in state["visited"]}
    except (KeyError, IndexError, TypeError, ValueError) as exc:
        raise InputError(f"cannot resume: incomplete or invalid resume state ({exc!r})") from None
    if codes.shape != (system.m,) or branch.orientation != s or branch.alpha_enter != alpha \
            or not np.array_equal(canonical_codes(branch.sets, system.friction), codes):
        raise InputError(f"cannot resume: the resume state does not match branch {branch.index} of the path")
    tie_rtol = path.options.get("tie_rtol", TIE_RTOL)  # the path's
    if tie_rtol != options.tie_rtol:
        options = PathOptions.with_overrides(options, tie_rtol=tie_rtol)
    ctx = _prepare(system, span, options, solver, callback)
    ctx.visited = visited
    stats0 = ctx.solver.stats.as_dict()
    before = {k: v for k, v in path.stats.items() if isinstance(v, (int, float))}
    ln = ctx.line(codes)
    path.status, path.resume_state = "running", None
    branch.alpha_exit = float("nan")
    status = _run(ctx, path, ln, s, alpha, None, resume_branch=branch, n_trans0=n_trans0)
    return _finish(path, ctx.solver, stats0, t0, status, before)


def _prepare(system, span: AlphaSpan, opts: PathOptions, solver, callback=None) -> _Context:
    """The run's context (span and options validated by the caller, once)."""
    solver = solver or get_solver(system)
    ctx = _Context(system, solver, opts, span.lo, span.hi, float(opts.tie_rtol), callback)
    ctx.prepare_loads()
    return ctx


def trace_exact(system: ContactSystem, alpha_start: float = 0.0, alpha_end: float = 1.0, y0=None,
                options: Optional[PathOptions] = None, solver=None, tie_rtol: Optional[float] = None,
                start_sets: Optional[InactiveSets] = None, orientation: Optional[int] = None,
                resume=None, callback=None) -> SolutionPath:
    """Exact piecewise-affine continuation of the solution path from alpha_start towards alpha_end.

    Parameters
    ----------
    y0 : start solution or guess for SSNM at alpha_start (ignored with ``start_sets``)
    options : PathOptions (alpha_min/alpha_max, max_transitions, tie_rtol, tol/max_iter of the
        start SSNM are used; the step-size options are not)
    solver : DirNeu backend (default: the system's PETSc :class:`~cfcontact.ssnm.DirNeuSolver`;
        :class:`~cfcontact.condensed.CondensedSolver` for one factorization of K in total)
    tie_rtol : relative tolerance (on the largest indicator magnitude) under which an indicator
        value counts as zero at a transition point (ties) or a slope as zero (overrides
        ``options.tie_rtol``)
    start_sets, orientation : start on the branch of these sets (y = DirNeu(start_sets, f(alpha_start)),
        which must be consistent there) with this orientation (default: towards alpha_end)
    resume : continue a run stopped by its callback instead of starting anew: a dict
        ``{"path": SolutionPath, "state": path.resume_state}`` (the stopped run's path, possibly
        saved and loaded, and the state it left in ``path.resume_state``: the branch being
        followed -- sets, orientation, entry alpha -- the transition budget's start and the
        cycle detector).  The branch is rebuilt from its sets, new points are appended to that
        path, and the result equals an uninterrupted run.  The path's ``tie_rtol`` is used;
        y0, start_sets and orientation are ignored.

    callback : called with each accepted :class:`~cfcontact.solution_path.PathPoint` (the start,
        the entry of every branch, the end); a truthy return stops the run

    Returns a :class:`SolutionPath` (method "exact"); transitions carry the exact root alpha
    (bracket (alpha, alpha)) and every change (``Transition.changes``).  Status "completed"
    (alpha range left), "stuck" (dead end / too degenerate, see events), "cycling",
    "max_transitions" or "stopped by callback".
    """
    overrides = {} if tie_rtol is None else {"tie_rtol": tie_rtol}
    opts, span = check_request(system, alpha_start, alpha_end, options, **overrides)
    return run_exact(system, span, opts, solver, y0=y0, start_sets=start_sets, orientation=orientation,
                     resume=resume, callback=callback)


def run_exact(system: ContactSystem, span: AlphaSpan, opts: PathOptions, solver=None, y0=None,
              start_sets: Optional[InactiveSets] = None, orientation: Optional[int] = None,
              resume=None, callback=None) -> SolutionPath:
    """:func:`trace_exact` with its arguments validated (by :func:`cfcontact.start.check_request`)."""
    if resume is not None:
        return _resume(system, span, opts, solver, resume, callback)
    alpha_start, alpha_end = span.start, span.end
    t0 = time.perf_counter()
    ctx = _prepare(system, span, opts, solver, callback)
    solver = ctx.solver
    stats0 = solver.stats.as_dict()
    s = (1 if alpha_end > alpha_start else -1) if orientation is None else int(orientation)
    if s not in (1, -1):
        raise InputError(f"orientation must be +1 or -1, got {orientation!r}")
    path = SolutionPath.for_system(system, "exact", alpha_start, alpha_end, opts.to_dict())
    alpha = float(alpha_start)
    if start_sets is not None:
        if not isinstance(start_sets, InactiveSets) or start_sets.m != system.m:
            raise InputError(f"start_sets must be InactiveSets of length m = {system.m}, got {start_sets!r}")
        codes = canonical_codes(start_sets, system.friction)
        ln = ctx.line(codes)
        y = None  # the branch's point at alpha (formed lazily with the condensed backend)
        if np.any(ln.values(alpha) < -ln.tol_v(alpha, 1e-8)):
            raise InputError(f"start_sets {start_sets} are not consistent at alpha_start={alpha_start}: "
                             f"DirNeu(start_sets, f(alpha_start)) is not a solution")
    else:
        # condensed backend from 0: only the start's sets are needed (its u is formed on demand)
        start_sets = (solver.ssnm_sets(system.load(alpha), opts.tol, opts.max_iter)
                      if y0 is None and hasattr(solver, "ssnm_sets") else None)
        try:
            if start_sets is None:  # SSNM from y0 (or a failed fast start: start_point's restarts)
                start_sets = start_point(system, alpha, y0, opts, solver).sets
        except ConvergenceError as exc:
            # SSNM is only locally convergent; small problems can be started by enumeration
            if y0 is not None or system.m > START_ENUMERATION_MAX_NODES:
                raise
            from cfcontact.enumerate import enumerate_solutions

            sols = enumerate_solutions(system, alpha, max_nodes=START_ENUMERATION_MAX_NODES)
            if not sols:
                raise
            start_sets = sols[0].sets
            path.events.append(PathEvent(
                "start_by_enumeration", alpha, f"SSNM did not converge at alpha_start ({exc}); started from the "
                f"first of {len(sols)} solutions found by enumeration (follow the others with start_sets=...)",
                None, {"solutions": [{"sets": x.sets.to_dict(), "states": x.states()} for x in sols]}))
        ln = ctx.line(canonical_codes(start_sets, system.friction))
        y = None  # the branch's point at alpha (formed lazily with the condensed backend)
    status = _run(ctx, path, ln, s, alpha, y)
    return _finish(path, solver, stats0, t0, status)


def follow_alternative(system: ContactSystem, path: SolutionPath, event_index: int, alternative: int,
                       options: Optional[PathOptions] = None, solver=None, tie_rtol: Optional[float] = None,
                       callback=None) -> dict:
    """Follow another branch leaving a branch point of an exact path.

    ``path.events[event_index]`` must be a "branch_point" event; ``alternative`` indexes its
    ``data["alternatives"]``.  The new branches are appended to ``path`` (a tree: the first new
    branch has ``parent`` = the branch that reached the branch point and ``origin`` = a new
    Transition).  ``path.status`` (the main run's) is unchanged; the sub-run's status and its
    branch indices are returned and stored in ``event.data["followed"][str(alternative)]``.
    A sub-run stopped by ``callback`` ends there (status "stopped by callback"):
    ``path.resume_state`` keeps the main run's state, so that resuming the path continues the
    main run, not the alternative.
    """
    if not (0 <= event_index < len(path.events)) or path.events[event_index].kind != "branch_point":
        raise InputError(f"event {event_index} is not a branch_point event of this path")
    ev = path.events[event_index]
    alts = ev.data["alternatives"]
    if not (0 <= alternative < len(alts)):
        raise InputError(f"alternative {alternative} out of range (0..{len(alts) - 1})")
    alt = alts[alternative]
    if tie_rtol is None:
        tie_rtol = path.options.get("tie_rtol", TIE_RTOL)
    opts, span = check_request(system, path.alpha_start, path.alpha_end,
                               options or PathOptions.from_dict(path.options), tie_rtol=tie_rtol)
    t0 = time.perf_counter()
    ctx = _prepare(system, span, opts, solver, callback)
    stats0 = ctx.solver.stats.as_dict()
    a = float(alt["alpha"])
    sets = InactiveSets.from_dict(alt["sets"])
    ln = ctx.line(canonical_codes(sets, system.friction))
    from_b = path.branches[ev.branch]
    old = InactiveSets.from_dict(path.branches[ev.branch].sets.to_dict())
    oc, nc = canonical_codes(old, system.friction), ln.codes
    changes = [{"node": int(i), "set": None, "from": STATE_NAMES[int(oc[i])], "to": STATE_NAMES[int(nc[i])]}
               for i in np.flatnonzero(oc != nc)] or [{"node": -1, "set": None}]
    d = int(alt["orientation"])
    tr = Transition(len(path.transitions), a, "transversal" if d == from_b.orientation else "fold",
                    changes[0]["node"], changes[0]["set"], from_b.index, len(path.branches), bracket=(a, a),
                    changes=changes)
    path.transitions.append(tr)
    first = len(path.branches)
    main_resume_state = path.resume_state
    status = _run(ctx, path, ln, d, a, None, parent=from_b.index, origin=tr.index)
    path.resume_state = main_resume_state  # (_run sets it when the callback stops the sub-run)
    if path.lazy and getattr(ctx.solver, "size", 1) > 1:
        path.form()  # collective (see _finish)
    st = ctx.solver.stats.as_dict()
    result = {"status": status, "branches": list(range(first, len(path.branches))),
              "stats": {**{k: st[k] - stats0.get(k, 0) for k in st}, "wall_time": time.perf_counter() - t0}}
    ev.data.setdefault("followed", {})[str(alternative)] = result
    return result
