"""The (alpha, F) plane of a load path: multiplicity map, fold curves, cusps, critical friction.

**Multiplicity map** (:func:`multiplicity_map`): for every friction coefficient F of a grid, the
exact alpha-path (:func:`cfcontact.exact.trace_exact`, one per F, all sharing one factorization of
K and S through :func:`cfcontact.rational.solver_at`) and its exact multiplicity intervals
(:meth:`~cfcontact.solution_path.SolutionPath.multiplicity_intervals`): the number of solutions
*on the traced path* at every grid alpha, with no sampling in alpha.  0 means the path does not
reach that alpha (it can turn back and leave the range at its start after an odd number of folds).

**Structure sweep in F** (:func:`fold_curves`, :func:`critical_friction_path`).  At a friction F
the alpha-path is a chain of branches Z_0, ..., Z_K (state codes, orientation) joined at
transitions, each the root in alpha of one constraint of the branch it leaves.  On a branch the
indicators are affine in alpha with coefficients rational in F (:mod:`cfcontact.rational`), so
every transition point alpha_j(F) is an exact rational function of F, and the chain stays the
path of the nearby F until an *event*: a constraint of a branch vanishes at one of its end points
(two transitions meet: another node's transition crosses, or a branch shrinks to zero length --
e.g. where it becomes singular, det M(F) = 0: a cusp, where a pair of folds is born), an end
point reaches the alpha range's bound, or the start point lies on a facet.  Each event is a root
in F of a rational function: a real eigenvalue of a pencil of size p + 2 (two constraints
vanishing at one alpha) or p + 1 (one constraint at a fixed alpha), or a root of det M(F); the
nearest one on each side of a probe friction is polished with a certified sign change
(:func:`cfcontact.rational.polish_root`).  The sweep traces the path at a probe F, finds the
interval [F_a, F_b] around it on which that chain is the path, and continues just past F_b
(probing closer where the next chain's own interval shows an event in between), until the F
range is covered by such intervals.  So:

* the fold curves are exact: on each interval a fold is the rational function alpha_j(F) of its
  transition, evaluated at any F to rounding (plots draw polylines through exact points); pieces
  are joined across events where their alpha agree, and a pair of fold pieces ending at one
  point is a cusp;
* the critical friction of the path (the smallest F at which it has a fold) is the lower end of
  the first interval whose chain has a fold: an event root, polished to rounding, bracketed by a
  probe without folds below and one with folds above (``tests``).

Limits (see docs/friction.md): the chain is followed from the start solution SSNM finds at
alpha_start; where several solutions exist there, a probe can start elsewhere (reported in
``notes``); the completeness of the events rests on the eigenvalue computations (each found
event is verified, a missed one is not).
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from cfcontact.errors import CfcontactError, InputError
from cfcontact.exact import canonical_codes, node_kinds, trace_exact
from cfcontact.jsonio import jsonable
from cfcontact.options import PathOptions
from cfcontact.rational import RationalBranch, friction_pattern, polish_root, solver_at
from cfcontact.solution_path import SET_NAMES

log = logging.getLogger(__name__)

__all__ = ["multiplicity_map", "fold_curves", "critical_friction_path", "FrictionMap", "FoldCurves",
           "PathCriticalFriction", "MAP_FORMAT"]

MAP_FORMAT = "cfcontact-friction-map"
#: A probe just past an event F_e sits at F_e + PROBE_STEP (|F_e| + width of the F range) (or halfway
#: to the next event when that is closer).
PROBE_STEP = 1e-7
#: Two fold pieces meeting at an event are one curve when their alpha agree within this (relative to
#: the alpha range); ends of two pieces at one point within it form a cusp.
JOIN_RTOL = 1e-7
#: The upper event of one chain and the lower event of the next are one event when they agree within
#: this (relative to max(|F|, 1e-3 x the F range)): an event where two transition points cross at
#: nearly the same rate is known only to about 1e-10 relative (seen on the main demo).
EVENT_RTOL = 1e-9
#: At most this many probes per sweep (each traces one alpha-path).
MAX_PROBES = 20000


def _paths_setup(system, solver, options):
    from cfcontact.condensed import CondensedSolver, get_condensed_solver

    system.check_positive_definite()  # (once: the rows' systems share what it found, ContactSystem._same_K)
    if solver is None:
        solver = get_condensed_solver(system)
    elif not isinstance(solver, CondensedSolver):
        raise InputError("friction maps need the condensed backend (a CondensedSolver)")
    opts = options if isinstance(options, PathOptions) else PathOptions.with_overrides(None, **(options or {}))
    return solver, opts, friction_pattern(system)


def _system_at(system, F, phi):
    return system.with_friction(float(F) * phi if np.any(phi != phi[0]) else float(F) * float(phi[0]))


def _check_alpha_range(alpha_range):
    """InputError unless ``alpha_range`` is (alpha_start, alpha_end), two different finite numbers."""
    try:
        a0, a1 = (float(a) for a in alpha_range)
    except (TypeError, ValueError):
        raise InputError(f"alpha_range must be (alpha_start, alpha_end), got {alpha_range!r}") from None
    if not (math.isfinite(a0) and math.isfinite(a1) and a0 != a1):
        raise InputError(f"alpha_range must be two different finite numbers (start, end), got ({a0}, {a1})")


def _check_range(name, lo, hi):
    lo, hi = float(lo), float(hi)
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise InputError(f"{name} must be an interval (lo, hi) with lo < hi, got ({lo}, {hi})")
    return lo, hi


# ====================================================================== starts
class _Starts:
    """Where every alpha-path starts: at the load f(alpha_start), the solution connected to the
    frictionless one (unique) by continuation in F -- the first pass over F of the exact friction
    path from F = 0 to ``F_max`` (:func:`cfcontact.friction.trace_friction_path`).  Where that path
    does not reach F (it turned back, or stopped), SSNM's start.  Deterministic, and the same for
    the map and the fold curves; SSNM alone can pick different solutions at neighbouring F where
    alpha_start has several."""

    def __init__(self, system, solver, alpha_start, F_max, opts, mode="continued"):
        from cfcontact.friction import trace_friction_path

        self.path, self.extents, self.time = None, [], 0.0
        if mode not in ("continued", "ssnm"):
            raise InputError(f"start must be 'continued' or 'ssnm', got {mode!r}")
        if mode == "continued" and F_max > 0:
            t0 = time.perf_counter()
            try:
                self.path = trace_friction_path(system, alpha_start, 0.0, F_max, options=opts, solver=solver)
                self.extents = [(min(b.alpha_enter, b.alpha_exit), max(b.alpha_enter, b.alpha_exit), b.sets)
                                for b in self.path.branches]
            except CfcontactError as exc:
                log.info("no friction path at alpha_start (%s): SSNM starts", exc)
            self.time = time.perf_counter() - t0

    def sets_at(self, F):
        """The start sets at F, or None (SSNM)."""
        for lo, hi, sets in self.extents:
            if lo <= F <= hi:
                return sets
        return None


def _trace_at(system, F, phi, a0, a1, opts, solver, starts: _Starts):
    """The exact alpha-path at friction F from the start of ``starts`` (SSNM's when it has none
    or when its start is not consistent there)."""
    sysF = _system_at(system, F, phi)
    view = solver_at(solver, sysF)
    sets = starts.sets_at(F)
    if sets is not None:
        try:
            return trace_exact(sysF, a0, a1, options=opts, solver=view, start_sets=sets)
        except InputError:
            pass
    return trace_exact(sysF, a0, a1, options=opts, solver=view)


# ====================================================================== multiplicity map
@dataclass
class FrictionMap:
    """Solution counts on the traced alpha-paths: ``counts[i, j]`` at (frictions[i], alphas[j])
    (-1: the path at frictions[i] could not be traced, see ``status[i]``).

    ``intervals[i]``: the exact multiplicity intervals [(alpha_lo, alpha_hi, k)] of the path at
    frictions[i]; ``folds[i]``: its fold alphas; ``status[i]``: its status.  ``timings``: "trace"
    (the sum of the alpha-paths), "count" (the counting), "total"."""

    alphas: np.ndarray
    frictions: np.ndarray
    counts: np.ndarray
    alpha_start: float
    alpha_end: float
    intervals: list = field(default_factory=list)
    folds: list = field(default_factory=list)
    status: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return jsonable({"format": MAP_FORMAT, "version": 1, "alpha_start": self.alpha_start,
                         "alpha_end": self.alpha_end, "alphas": self.alphas, "frictions": self.frictions,
                         "counts": self.counts, "intervals": self.intervals, "folds": self.folds,
                         "status": self.status, "timings": self.timings})


def _count(path, alphas) -> tuple:
    """(intervals, counts at ``alphas``) of an exact alpha-path: between two consecutive branch
    ends the number of solutions is the number of branches spanning that interval (the exact
    method's branches are consistent on their whole extent and pairwise distinct there); a grid
    alpha at a branch end gets the interval to its right.  The same numbers as
    :meth:`SolutionPath.multiplicity_intervals` (a test checks it), without its per-interval
    consistency checks."""
    ext = np.array([path.branch_extent(b) for b in path.branches], dtype=float).reshape(-1, 2)
    ext = ext[np.isfinite(ext).all(axis=1) & (ext[:, 1] > ext[:, 0])]
    ends = np.unique(ext.ravel())
    if ends.size < 2:
        return [], np.zeros(alphas.size, dtype=np.int16)
    mids = 0.5 * (ends[:-1] + ends[1:])
    k = ((mids[None, :] > ext[:, :1]) & (mids[None, :] < ext[:, 1:])).sum(axis=0)
    j = np.searchsorted(ends, alphas, side="right") - 1
    inside = (j >= 0) & (j < k.size) | (alphas == ends[-1])
    counts = np.where(inside, k[np.clip(j, 0, k.size - 1)], 0).astype(np.int16)
    iv = []
    for a, b, c in zip(ends[:-1], ends[1:], k):
        if iv and iv[-1][2] == c:
            iv[-1][1] = float(b)
        else:
            iv.append([float(a), float(b), int(c)])
    return iv, counts


def multiplicity_map(system, alphas, frictions, alpha_start: float = 0.0, alpha_end: float = 1.0, solver=None,
                     options=None, start: str = "continued") -> FrictionMap:
    """The number of solutions of the exact alpha-path from ``alpha_start`` to ``alpha_end`` at
    every grid point (alphas x frictions): one :func:`~cfcontact.exact.trace_exact` per F (K
    factored once for all), counted from its exact multiplicity intervals (a grid alpha at a
    transition point takes the interval to its right).

    ``start``: "continued" (default) -- every path starts from the solution at alpha_start
    connected to the frictionless one by continuation in F (one friction path at alpha_start,
    see :class:`_Starts`; the fold curves use the same) -- or "ssnm" (SSNM's start, as
    ``trace_exact`` alone)."""
    solver, opts, phi = _paths_setup(system, solver, options)
    alphas = np.asarray(alphas, dtype=float).ravel()
    frictions = np.asarray(frictions, dtype=float).ravel()
    for name, x in (("alphas", alphas), ("frictions", frictions)):
        bad = x[~np.isfinite(x) | ((x < 0) if name == "frictions" else False)]
        if not x.size or bad.size:
            raise InputError(f"alphas and frictions must be non-empty arrays of finite numbers (frictions >= 0): "
                             f"{name} {'is empty' if not x.size else f'has {bad[0]!r}'}")
    counts = np.zeros((frictions.size, alphas.size), dtype=np.int16)
    res = FrictionMap(alphas, frictions, counts, float(alpha_start), float(alpha_end))
    t_trace = t_count = 0.0
    t_all = time.perf_counter()
    starts = _Starts(system, solver, alpha_start, float(frictions.max()), opts, start)
    for i, F in enumerate(frictions):
        t0 = time.perf_counter()
        try:
            path = _trace_at(system, F, phi, alpha_start, alpha_end, opts, solver, starts)
        except CfcontactError as exc:  # e.g. a singular start branch exactly at a cusp's F
            t_trace += time.perf_counter() - t0
            counts[i] = -1
            res.intervals.append([])
            res.folds.append([])
            res.status.append(f"failed: {exc}")
            continue
        t1 = time.perf_counter()
        iv, counts[i] = _count(path, alphas)
        if path.status != "completed":  # (stuck or cycling: what lies beyond where it stopped is unknown)
            counts[i] = -1
        t_count += time.perf_counter() - t1
        t_trace += t1 - t0
        res.intervals.append(iv)
        res.folds.append([float(t.alpha) for t in path.folds])
        res.status.append(path.status)
    res.timings = {"trace": t_trace, "count": t_count, "start_path": starts.time, "total": time.perf_counter() - t_all}
    return res


# ====================================================================== structures
class _Link:
    """One branch of a chain: its rational form, orientation, reference alpha and load data
    W = (w(alpha_ref), w'), the positions of its entry and exit constraints (-1: none)."""

    __slots__ = ("rb", "s", "alpha_ref", "W", "e_in", "e_out", "changed")

    def __init__(self, rb, s, alpha_ref, W):
        self.rb, self.s, self.alpha_ref, self.W = rb, s, alpha_ref, W
        self.e_in = self.e_out = -1
        self.changed = np.zeros(0, dtype=int)


class _Chain:
    """The alpha-path at a probe friction as a chain of branches (see the module docstring)."""

    def __init__(self, F, links, trans, path):
        self.F, self.links, self.trans, self.path = F, links, trans, path
        self.folds = [j for j, t in enumerate(trans) if t["kind"] == "fold"]

    def alpha(self, j, F) -> float:
        """The alpha of transition j at F (the root of the exit constraint of link j).  Where the
        branch is singular (a cusp: det M(F) = 0, the root is the limit of a ratio of two poles)
        it is evaluated at F (1 + d), d = 1e-12, 1e-10, ... up to 1e-8, the first that works)."""
        ln = self.links[j]
        rb, e = ln.rb, ln.e_out
        for d in (0.0, 1e-12, 1e-10, 1e-8):
            try:
                ind = rb.solve(F + d * max(abs(F), 1e-3), ln.W)[1][rb.cidx[e]] * rb.csgn[e]
            except np.linalg.LinAlgError:
                continue
            return float(ln.alpha_ref - ind[0] / ind[1])
        return float("nan")


class _Sweep:
    """Probes, chains and their events (see the module docstring)."""

    def __init__(self, system, alpha_start, alpha_end, solver=None, options=None, F_max=0.0, start="continued"):
        self.system = system
        self.solver, self.opts, self.phi = _paths_setup(system, solver, options)
        self.starts = _Starts(system, self.solver, float(alpha_start), float(F_max), self.opts, start)
        self.F0_index = node_kinds(system, self.phi)
        self.a0, self.a1 = float(alpha_start), float(alpha_end)
        self.lo, self.hi = min(self.a0, self.a1), max(self.a0, self.a1)
        W = self.solver.load_data_many(list(system.loads_numpy()))
        self.w1, self.dw = W[:, 0].copy(), W[:, 1] - W[:, 0]
        self._rb: dict = {}
        self.probes: list = []  # (F, number of folds, [F_a, F_b])
        self.notes: list = []
        self.times = {"trace": 0.0, "events": 0.0}
        self.n_pencils = 0
        self.stopped_at = None  # the F where the sweep stopped before the end of its range (see notes)

    def w(self, a):
        return self.w1 + a * self.dw

    def rb(self, codes) -> RationalBranch:
        key = codes.tobytes()
        r = self._rb.get(key)
        if r is None:
            if len(self._rb) > 4096:
                self._rb.clear()
            r = self._rb[key] = RationalBranch(self.solver.S, self.system.rho, codes, self.phi, self.F0_index)
        return r

    def chain(self, F) -> Optional[_Chain]:
        """The chain of the path traced at F, or None when it is degenerate there (a degenerate
        transition, a branch point, a path that does not complete)."""
        t0 = time.perf_counter()
        try:
            path = _trace_at(self.system, F, self.phi, self.a0, self.a1, self.opts, self.solver, self.starts)
        except CfcontactError:  # e.g. a singular branch exactly at an event
            return None
        finally:
            self.times["trace"] += time.perf_counter() - t0
        if path.status != "completed" or any(t.pivots or len(t.changes) != 1 for t in path.transitions) \
                or any(e.kind == "branch_point" for e in path.events):
            return None
        Fv = F * self.phi
        links = []
        for b in path.branches:
            codes = canonical_codes(b.sets, Fv)
            a_ref = float(b.alpha_enter)
            links.append(_Link(self.rb(codes), b.orientation, a_ref, np.column_stack([self.w(a_ref), self.dw])))
        trans = []
        for j, t in enumerate(path.transitions):
            ind = SET_NAMES.index(t.set)
            a, b = links[j], links[j + 1]
            a.e_out, b.e_in = a.rb.position(t.node, ind), b.rb.position(t.node, ind)
            if a.e_out < 0 or b.e_in < 0:
                return None
            b.changed = np.flatnonzero(np.isin(b.rb.cnode, np.flatnonzero(a.rb.codes != b.rb.codes)))
            trans.append({"kind": t.kind, "node": int(t.node), "set": t.set, "alpha": float(t.alpha)})
        ch = _Chain(F, links, trans, path)
        for j, t in enumerate(trans):  # the rational form must give the traced transitions
            if abs(ch.alpha(j, F) - t["alpha"]) > 1e-7 * (1.0 + abs(t["alpha"])):
                self.notes.append(f"F={F!r}: transition {j} at alpha={t['alpha']!r} is not reproduced by its "
                                  f"rational form ({ch.alpha(j, F)!r}); probe skipped")
                return None
        return ch

    # ------------------------------------------------------------ events
    def _candidates(self, ch: _Chain, lo, hi) -> list:
        """[(F, fun)]: every candidate event of the chain in [lo, hi] with the scalar function whose
        sign change certifies it."""
        out = []
        last = len(ch.links) - 1
        for j, ln in enumerate(ch.links):
            rb, W = ln.rb, ln.W
            cidx, csgn = rb.cidx, rb.csgn

            def at_point(q, e, rb=rb, W=W):
                def fun(F):  # constraint q where constraint e vanishes
                    ind = rb.solve(F, W)[1]
                    Aq, Bq = rb.csgn[q] * ind[rb.cidx[q]]
                    Ae, Be = rb.csgn[e] * ind[rb.cidx[e]]
                    return float(Aq - Ae * Bq / Be)
                return fun

            def at_alpha(q, a, rb=rb):
                wa = self.w(a)[:, None]

                def fun(F):  # constraint q at the fixed alpha a
                    return float(rb.csgn[q] * rb.solve(F, wa)[1][rb.cidx[q], 0])
                return fun, wa

            pairs = []
            if ln.e_out >= 0:
                pairs += [(q, ln.e_out) for q in range(cidx.size) if q != ln.e_out]
            if ln.e_in >= 0:
                pairs += [(q, ln.e_in) for q in ln.changed if q != ln.e_in]
            if pairs:
                self.n_pencils += len(pairs)
                qe = np.asarray(pairs, dtype=int)
                roots = rb.pencil_roots_many(W, cidx[qe], csgn[qe], lo, hi, sigma=ch.F)
                for (q, e), rs in zip(pairs, roots):
                    out.extend((float(r), at_point(q, e)) for r in rs)
            bound = self.hi if ln.s > 0 else self.lo
            singles = {}
            if j == 0:
                singles[self.a0] = list(range(cidx.size))
            if j == last:
                singles.setdefault(bound, []).extend(range(cidx.size))
            elif ln.e_out >= 0:
                singles.setdefault(bound, []).append(ln.e_out)
            for a, qs in singles.items():
                qs = np.asarray(sorted(set(qs)), dtype=int)
                self.n_pencils += qs.size
                wa = self.w(a)[:, None]
                roots = rb.pencil_roots_many(wa, cidx[qs][:, None], csgn[qs][:, None], lo, hi, sigma=ch.F)
                for q, rs in zip(qs, roots):
                    fun = at_alpha(q, a)[0]
                    out.extend((float(r), fun) for r in rs)
            if rb.p:
                H = rb.woodbury(np.zeros((2 * rb.m, 1)))["H"]
                I = np.eye(rb.p)
                for r in rb.poles(lo, hi):
                    out.append((float(r), lambda F, H=H, I=I: float(np.linalg.det(I + F * H))))
        return out

    def events_around(self, ch: _Chain, Fp, a, b):
        """(F_a, F_b): the nearest verified events below and above the probe Fp within [a, b] (a or
        b when there is none); None when an event lies at Fp itself (a degenerate probe)."""
        t0 = time.perf_counter()
        scale = max(abs(a), abs(b), b - a, 1e-300)
        tiny = 1e-12 * scale
        cands = self._candidates(ch, a, b)
        near = [(r, f) for r, f in cands if abs(r - Fp) <= tiny]
        for r, f in near:
            if polish_root(f, r, a, b, scale) is not None:
                self.times["events"] += time.perf_counter() - t0
                return None
        up = sorted(((r, f) for r, f in cands if r > Fp + tiny), key=lambda x: x[0])
        down = sorted(((r, f) for r, f in cands if r < Fp - tiny), key=lambda x: -x[0])
        hi_e, lo_e = b, a
        for r, f in up:
            if r >= hi_e:
                break
            res = polish_root(f, r, Fp, b, scale)
            if res is not None and Fp + tiny < res[0] < hi_e:
                hi_e = res[0]
                break
        for r, f in down:
            if r <= lo_e:
                break
            res = polish_root(f, r, a, Fp, scale)
            if res is not None and lo_e < res[0] < Fp - tiny:
                lo_e = res[0]
                break
        self.times["events"] += time.perf_counter() - t0
        return lo_e, hi_e

    def probe(self, F, a, b, limit=None, step=None):
        """(chain, F_a, F_b) of a probe at F in [a, b], nudged upwards (at most 8 times, staying
        below ``limit``) while the path there is degenerate; None when no such probe works."""
        limit = b if limit is None else limit
        step = max(PROBE_STEP * (abs(F) + (b - a)), 1e-15) if step is None else step
        for _ in range(8):
            if not a <= F <= limit:
                return None
            ch = self.chain(F)
            if ch is not None:
                ev = self.events_around(ch, F, a, b)
                if ev is not None:
                    self.probes.append((F, len(ch.folds), list(ev)))
                    return ch, ev[0], ev[1]
            F = F + step if F + step < limit else 0.5 * (F + limit)
            step *= 4.0
        return None

    def sweep(self, F_lo, F_hi, stop_at_fold=False) -> list:
        """[(F_a, F_b, chain)]: intervals covering [F_lo, F_hi] in increasing F, on each of which the
        chain is the alpha-path (stops after the first interval with a fold if ``stop_at_fold``).
        A gap between two events too narrow to be probed (the alpha-path there has transitions
        closer than the exact method separates: it resolves them as one degenerate point) is an
        interval with chain None (see ``notes``)."""
        out = []
        a, at_event = F_lo, False
        width = F_hi - F_lo
        pending = None  # (chain, F_a, F_b) of a probe above a gap still to be probed
        for _ in range(MAX_PROBES):
            if a >= F_hi:
                break
            if pending is None:
                F = a if not (at_event or a == 0.0) else a + min(PROBE_STEP * (abs(a) + width), 0.5 * (F_hi - a))
                got = self.probe(F, a, F_hi)
                if got is None:
                    self.notes.append(f"no usable probe in [{a!r}, {F_hi!r}] (degenerate paths); the sweep stops")
                    self.stopped_at = a
                    break
            else:  # probe the gap [a, F_a) below the chain found above it
                gap = pending[1] - a
                got = self.probe(a + 0.5 * gap, a, F_hi, limit=pending[1], step=0.05 * gap)
                if got is None or got[1] < a:
                    self.notes.append(f"events at F = {a!r} and {pending[1]!r} (a gap of {gap:.3g}) lie too close "
                                      f"for the alpha-paths between them to be traced apart; the gap is skipped")
                    out.append((a, pending[1], None))
                    got, a = pending, pending[1]
                pending = None
            ch, lo_e, hi_e = got
            if lo_e > a + EVENT_RTOL * max(abs(a), 1e-3 * width):
                pending = got  # another chain lies between a and lo_e
                continue
            out.append((a, hi_e, ch))
            if stop_at_fold and ch.folds:
                break
            a, at_event = hi_e, True
        else:
            self.notes.append(f"probe cap {MAX_PROBES} reached")
            self.stopped_at = a
        return out


# ====================================================================== results
@dataclass
class PathCriticalFriction:
    """The smallest F at which the exact alpha-path has a fold.

    ``friction``: the event root (inf when no fold in the range; ``F_lo`` when the path folds
    already there, ``below_range`` then True); ``alpha``, ``node``, ``set``: the fold(s) there (the
    first); ``folds``: every fold of the chain at that F as (alpha, node, set); ``bracket``: the
    probes (F, folds) just below and above, between which the chain changes only at ``friction``;
    ``tests``: every probe of the sweep (F, folds, [F_a, F_b] of its chain); ``stopped_at``: the F
    at which the sweep stopped before the end of the range (None: it covered the range), see
    ``notes``: with ``friction`` inf, no fold was found below it and above it nothing is known."""

    friction: float
    alpha: float = float("nan")
    node: int = -1
    set: str = ""
    folds: list = field(default_factory=list)
    bracket: tuple = ()
    below_range: bool = False
    uncertainty: float = 0.0
    stopped_at: Optional[float] = None
    tests: list = field(default_factory=list)
    notes: list = field(default_factory=list)
    time: float = 0.0

    def to_dict(self) -> dict:
        return jsonable({"friction": self.friction, "alpha": self.alpha, "node": self.node, "set": self.set,
                         "folds": self.folds, "bracket": list(self.bracket), "below_range": self.below_range,
                         "uncertainty": self.uncertainty, "stopped_at": self.stopped_at,
                         "tests": self.tests, "notes": self.notes, "time": self.time})

    def __str__(self):
        if not np.isfinite(self.friction):
            if self.stopped_at is not None:
                why = next((n for n in self.notes if "the sweep stops" in n or "probe cap" in n), "see notes")
                return (f"no fold found for F up to {self.stopped_at:.12g}, where the sweep stopped before the end "
                        f"of the friction range ({why}): above it unknown")
            return "no fold in the friction range"
        return (f"F = {self.friction:.12g}{' (already at the range start)' if self.below_range else ''}: fold at "
                f"alpha = {self.alpha:.10g}, node {self.node} ({self.set})")


def _critical_from(intervals, F_lo, sweep) -> PathCriticalFriction:
    res = PathCriticalFriction(math.inf, tests=[list(p) for p in sweep.probes], notes=list(sweep.notes),
                               stopped_at=sweep.stopped_at)
    for k, (a, b, ch) in enumerate(intervals):
        if ch is None or not ch.folds:
            continue
        res.friction = a
        res.below_range = k == 0 and a == F_lo
        res.folds = [(ch.alpha(j, a), ch.trans[j]["node"], ch.trans[j]["set"]) for j in ch.folds]
        res.alpha, res.node, res.set = res.folds[0]
        above = (ch.F, len(ch.folds))
        below = ()
        if k and intervals[k - 1][2] is None:  # an unresolved gap of events just below
            res.uncertainty = a - intervals[k - 1][0]
            if k > 1 and intervals[k - 2][2] is not None:
                below = (intervals[k - 2][2].F, len(intervals[k - 2][2].folds))
        elif k:
            below = (intervals[k - 1][2].F, len(intervals[k - 1][2].folds))
        res.bracket = (below, above)
        break
    return res


def critical_friction_path(system, alpha_range=(0.0, 1.0), F_max: float = 100.0, F_min: float = 0.0,
                           solver=None, options=None, start: str = "continued") -> PathCriticalFriction:
    """The smallest F in [F_min, F_max] at which the exact alpha-path over ``alpha_range`` (from
    its first entry to its second) has a fold, with the fold's alpha and node: the sweep of the
    module docstring, stopped at the first chain with a fold.  The value is an event root
    (an eigenvalue polished with a certified sign change), far below 1e-8 relative."""
    F_min, F_max = _check_range("the friction range", F_min, F_max)
    if F_min < 0:
        raise InputError(f"friction coefficients are >= 0, got F_min = {F_min}")
    _check_alpha_range(alpha_range)
    t0 = time.perf_counter()
    sw = _Sweep(system, alpha_range[0], alpha_range[1], solver, options, F_max, start)
    intervals = sw.sweep(F_min, F_max, stop_at_fold=True)
    res = _critical_from(intervals, F_min, sw)
    res.time = time.perf_counter() - t0
    return res


@dataclass
class FoldPiece:
    """One piece of a fold curve: the fold of transition ``j`` of a chain, alpha(F) exact on [F_a, F_b]."""

    F_a: float
    F_b: float
    chain: _Chain = field(repr=False)
    j: int
    node: int
    set: str

    def alpha(self, F) -> float:
        return self.chain.alpha(self.j, float(F))


@dataclass
class FoldCurve:
    """A fold curve: pieces joined end to end in increasing F; ``start``/``end``: how it begins and
    ends ("cusp", "boundary" (alpha range), "range" (F range), "open": the path stops passing
    through it, e.g. it turns back before)."""

    pieces: list
    start: str = "open"
    end: str = "open"

    @property
    def F_range(self):
        return self.pieces[0].F_a, self.pieces[-1].F_b

    def alpha(self, F) -> Optional[float]:
        for p in self.pieces:
            if p.F_a <= F <= p.F_b:
                return p.alpha(F)
        return None

    def sample(self, per_piece: int = 24) -> np.ndarray:
        """(k, 2) points (alpha, F) on the curve, each evaluated exactly (for drawing)."""
        pts = []
        for p in self.pieces:
            t = 0.5 - 0.5 * np.cos(np.linspace(0.0, np.pi, max(2, per_piece)))
            for F in p.F_a + t * (p.F_b - p.F_a):
                pts.append((p.alpha(F), F))
        return np.asarray(pts, dtype=float).reshape(-1, 2)


@dataclass
class FoldCurves:
    """The fold curves of the alpha-path over a friction range (:func:`fold_curves`).

    ``curves``: :class:`FoldCurve` list; ``cusps``: (alpha, F) where two fold pieces meet and end;
    ``critical``: the :class:`PathCriticalFriction` of the same sweep; ``intervals``: (F_a, F_b,
    number of folds, transitions) of every chain; ``timings``: "trace" (the probes' paths),
    "events", "total"; ``probes``: how many alpha-paths were traced."""

    curves: list
    cusps: list
    critical: PathCriticalFriction
    alpha_start: float
    alpha_end: float
    F_range: tuple
    intervals: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)
    probes: int = 0
    notes: list = field(default_factory=list)

    def alphas_at(self, F) -> list:
        """The fold alphas of every curve at F (exact)."""
        return sorted(a for c in self.curves if (a := c.alpha(F)) is not None)

    def to_dict(self, points: bool = False) -> dict:
        """JSON data; ``points``: also each curve's exactly evaluated (alpha, F) points (:meth:`FoldCurve.sample`;
        :func:`save_map` puts them in map.npz instead)."""
        return jsonable({
            "alpha_start": self.alpha_start, "alpha_end": self.alpha_end, "F_range": list(self.F_range),
            "curves": [{"start": c.start, "end": c.end, "F_range": list(c.F_range),
                        "pieces": [{"F_a": p.F_a, "F_b": p.F_b, "node": p.node, "set": p.set,
                                    "alpha_a": p.ends[0], "alpha_b": p.ends[1]} for p in c.pieces],
                        **({"points_alpha_F": c.sample()} if points else {})} for c in self.curves],
            "cusps": self.cusps, "critical": self.critical.to_dict(), "intervals": self.intervals,
            "timings": self.timings, "probes": self.probes, "notes": self.notes})


def _pieces(intervals, alpha_tol) -> list:
    """Every fold of every chain as a :class:`FoldPiece` on its interval, with its end values;
    a piece equal to one already there (the same fold of a chain from another start, inside its
    F range) is dropped."""
    out = []
    for a, b, ch in intervals:
        if ch is None:
            continue
        for j in ch.folds:
            p = FoldPiece(a, b, ch, j, ch.trans[j]["node"], ch.trans[j]["set"])
            p.ends = (p.alpha(a), p.alpha(b))
            mid = 0.5 * (a + b)
            if any(q.F_a <= a and b <= q.F_b and (q.node, q.set) == (p.node, p.set)
                   and abs(q.alpha(mid) - p.alpha(mid)) <= alpha_tol for q in out):
                continue
            out.append(p)
    return out


def _join(pieces, alpha_tol, F_tol, a_lo, a_hi, F_lo, F_hi):
    """Curves: pieces joined end to start where they meet (F within F_tol, alpha within alpha_tol;
    the same node and set preferred), each to one in a later F interval; cusps: two unjoined ends
    (or starts) at one point."""
    order = sorted(range(len(pieces)), key=lambda i: (pieces[i].F_a, pieces[i].ends[0]))
    succ, pred = {}, {}
    for i in sorted(range(len(pieces)), key=lambda i: (pieces[i].F_b, pieces[i].ends[1])):
        p = pieces[i]
        best = None
        for k in order:
            q = pieces[k]
            if k in pred or q.F_a <= p.F_a or abs(q.F_a - p.F_b) > F_tol or abs(q.ends[0] - p.ends[1]) > alpha_tol:
                continue  # (a successor lies in a later interval: in one narrower than F_tol two pieces would
                # join each other's ends into a cycle, and no curve would start)
            key = (0 if (q.node, q.set) == (p.node, p.set) else 1, abs(q.ends[0] - p.ends[1]))
            if best is None or key < best[0]:
                best = (key, k)
        if best is not None:
            succ[i], pred[best[1]] = best[1], i
    cusps, cusp_end, cusp_start = [], set(), set()
    for group, side, F_of, mark in (([i for i in range(len(pieces)) if i not in succ], 1, "F_b", cusp_end),
                                    ([i for i in range(len(pieces)) if i not in pred], 0, "F_a", cusp_start)):
        for x in group:
            for y in group:
                px, py = pieces[x], pieces[y]
                if x < y and x not in mark and y not in mark and abs(getattr(px, F_of) - getattr(py, F_of)) <= F_tol \
                        and abs(px.ends[side] - py.ends[side]) <= alpha_tol:
                    mark |= {x, y}
                    cusps.append((0.5 * (px.ends[side] + py.ends[side]), getattr(px, F_of)))

    def kind(i, side):
        p = pieces[i]
        if i in (cusp_start if side == 0 else cusp_end):
            return "cusp"
        F = p.F_a if side == 0 else p.F_b
        if (side == 0 and F <= F_lo + F_tol) or (side == 1 and F >= F_hi - F_tol):
            return "range"
        return "boundary" if min(abs(p.ends[side] - a_lo), abs(p.ends[side] - a_hi)) <= alpha_tol else "open"

    curves = []
    for i in order:
        if i in pred:
            continue
        chain = [i]
        while chain[-1] in succ and len(chain) <= len(pieces):
            chain.append(succ[chain[-1]])
        curves.append(FoldCurve([pieces[k] for k in chain], start=kind(chain[0], 0), end=kind(chain[-1], 1)))
    cusps.sort(key=lambda c: (c[1], c[0]))
    return curves, cusps


def _same_chain(x: _Chain, y: _Chain) -> bool:
    return len(x.links) == len(y.links) and all(
        a.rb is b.rb and a.s == b.s for a, b in zip(x.links, y.links))


def fold_curves(system, F_range=(0.0, 30.0), alpha_range=(0.0, 1.0), frictions=None, solver=None,
                options=None, start: str = "continued") -> FoldCurves:
    """Every fold of the exact alpha-path over ``alpha_range`` followed through ``F_range`` as
    curves in the (alpha, F) plane, exact piece by piece (the sweep of the module docstring),
    with the cusps where pairs of folds are born and the path's critical friction.

    ``frictions``: more probe frictions (e.g. the rows of a :func:`multiplicity_map`).  Where the
    start alpha has several solutions, SSNM's choice of the start can change from one F to
    another: the path traced at such a friction is then another chain than the sweep's; its
    folds are added on their own exact interval (``notes`` says where)."""
    F_lo, F_hi = _check_range("the friction range", *F_range)
    if F_lo < 0:
        raise InputError(f"friction coefficients are >= 0, got {F_lo}")
    _check_alpha_range(alpha_range)
    t0 = time.perf_counter()
    sw = _Sweep(system, alpha_range[0], alpha_range[1], solver, options, F_hi, start)
    intervals = sw.sweep(F_lo, F_hi)
    extra = []
    for F in sorted(float(F) for F in np.ravel(frictions if frictions is not None else [])):
        if not F_lo < F < F_hi:
            continue
        have = [ch for a, b, ch in intervals + extra if ch is not None and a <= F <= b]
        ch = sw.chain(F)
        if ch is None or any(_same_chain(ch, h) for h in have):
            continue
        ev = sw.events_around(ch, F, F_lo, F_hi)
        if ev is not None:
            sw.probes.append((F, len(ch.folds), list(ev)))
            extra.append((ev[0], ev[1], ch))
            sw.notes.append(f"F = {F!r}: the path starts on another branch than the sweep's chain there (several "
                            f"solutions at alpha_start); its chain, on [{ev[0]!r}, {ev[1]!r}], is added")
    tol = JOIN_RTOL * (sw.hi - sw.lo)
    F_tol = 2 * EVENT_RTOL * max(abs(F_lo), abs(F_hi), 1.0)
    curves, cusps = _join(_pieces(intervals + extra, tol), tol, F_tol, sw.lo, sw.hi, F_lo, F_hi)
    crit = _critical_from(intervals, F_lo, sw)
    total = time.perf_counter() - t0
    crit.time = total
    return FoldCurves(curves, cusps, crit, sw.a0, sw.a1, (F_lo, F_hi),
                      intervals=[(a, b, None, None) if ch is None else (a, b, len(ch.folds), len(ch.trans))
                                 for a, b, ch in intervals + extra],
                      timings={"trace": sw.times["trace"], "events": sw.times["events"], "total": total},
                      probes=len(sw.probes), notes=list(sw.notes))


# ====================================================================== files
def save_map(folder, fmap: FrictionMap, curves: Optional[FoldCurves] = None, marks=(), extra=None) -> list:
    """Write ``map.json`` (strict JSON: the map, each path's intervals and folds, the curves' pieces
    with their end points, cusps, the critical friction) and ``map.npz`` (alphas, frictions, counts,
    ``curve_<i>``: each curve's exactly evaluated (alpha, F) points, ``cusps``) into ``folder``;
    returns the file names."""
    os.makedirs(folder, exist_ok=True)
    data = {**fmap.to_dict(), "marks": list(map(float, marks)), **(extra or {})}
    arrays = {"alphas": fmap.alphas, "frictions": fmap.frictions, "counts": fmap.counts}
    if curves is not None:
        data["fold_curves"] = curves.to_dict()
        for i, c in enumerate(curves.curves):
            arrays[f"curve_{i}"] = c.sample()
        arrays["cusps"] = np.asarray(curves.cusps, dtype=float).reshape(-1, 2)
    with open(os.path.join(folder, "map.json"), "w") as fh:
        json.dump(jsonable(data), fh, indent=1)
    np.savez_compressed(os.path.join(folder, "map.npz"), **arrays)
    return ["map.json", "map.npz"]
