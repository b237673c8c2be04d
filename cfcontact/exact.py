"""Exact piecewise-affine path following, degenerate points resolved by a lexicographic rule.

On a branch with inactive sets Z fixed, y(alpha) is affine in alpha.  A branch is represented by
its point and slope at a reference alpha (its entry point): y(alpha) = y_ref + (alpha - alpha_ref)
y', so it keeps full accuracy near its own alpha range whatever its values at alpha = 0 and 1.
The three indicator vectors of (17)

    a = lam_n + rho (N u - g),   bp = lam_t + rho T u - F lam_n,   bm = lam_t + rho T u + F lam_n

are linear in y, hence affine along the branch.  Per node state the branch is consistent while
its *constraints* (c >= 0) hold:

    open   : -a >= 0                       (lam_n = lam_t = 0; the sign of T u is irrelevant)
    stick  : -bp >= 0, bm >= 0             (a = lam_n >= 0 follows: bm - bp = 2 F a, F > 0)
    slip+  :  a >= 0,  bp >= 0             (bm = bp + 2 F a >= 0 follows)
    slip-  :  a >= 0, -bm >= 0             (bp = bm - 2 F a <= 0 follows)
    F = 0  : open (-a >= 0) or tangentially free (a >= 0); "free" is coded as slip+.

Each constraint is one side of a facet between two states of its node (the *pivot* table: a
constraint of stick on bp leads to slip+, a of slip+- to open, bp of slip+ to stick, ...; a of
an open node to slip+ or slip- by the sign of T u).  The path leaves a branch at the first root
of a decreasing constraint (ratio test), crosses that facet, and continues on the new branch in
the direction in which the crossed constraint grows again: forward ("transversal") or back
("fold").  With all sets regular this is a complementary-pivoting scheme: the solution path is a
1-manifold, each branch is entered at most once, and a run ends only by leaving the alpha range
(or by closing a loop, a genuine closed curve of solutions).

Degenerate points (several constraints vanish at one alpha: symmetric problems, regular meshes
under uniform loads) are resolved by rule, without enumerating state combinations: the load is
perturbed symbolically, f(alpha) + sum_j eps^j e_j with fixed random load vectors e_j, which
orders every tie (Lemke's lexicographic rule).  A tie between roots -- decided with a tolerance
derived from the data's own rounding, never merging roots that rounding can separate -- is
broken by comparing the constraints' responses to e_1, e_2, ... (one extra solve per branch at
a degenerate point); one pivot at a time, each new branch checked by its indicators, until a
branch leaves the point with positive length.  The other continuations of a degenerate point
(a *branch point*) are found by the opposite perturbation and, at points involving few nodes,
by enumerating the nodes' admissible states; they are recorded as a ``PathEvent("branch_point")``
and can be followed (:func:`follow_alternative`, ``trace_exact(..., tree=True)``).

Start: the inactive sets of SSNM's solution at alpha_start (SSNM in the multipliers with the
condensed backend); when SSNM does not converge (at large F it can cycle), the start is reached
by the exact method itself along a homotopy from data whose only solution is "every node open"
(a separating gap with the tangential data held), which provably ends at alpha_start.

Cost: one dense factorization and two solves (three at degenerate points) of the reduced
system per branch with :class:`cfcontact.condensed.CondensedSolver` (K factored once), or two
sparse J(Z) solves per branch with the full PETSc backend.
"""

from __future__ import annotations

import hashlib
import itertools
import logging
import math
import time
from typing import Optional

import numpy as np

from cfcontact import native
from cfcontact.backend import select_solver
from cfcontact.errors import ConvergenceError, InputError, SingularSystemError, StartInterrupted
from cfcontact.jsonio import jsonable
from cfcontact.options import ALPHA_LIMIT, TIE_RTOL, AlphaSpan, PathOptions
from cfcontact.solution_path import SET_NAMES, PathEvent, PathPoint, SolutionPath, Transition
from cfcontact.ssnm import STATE_NAMES, InactiveSets, Solution, canonical_codes, indicators
from cfcontact.start import START_RHO_FACTORS, check_request, resume_parts, start_point
from cfcontact.stepper import StartProgress, Stepper, check_monitor, stop_only
from cfcontact.system import PERTURBATION_COLUMNS as SYSTEM_PERTURBATION_COLUMNS
from cfcontact.system import ContactSystem

log = logging.getLogger(__name__)

#: TIE_RTOL (:mod:`cfcontact.options`, the default of ``PathOptions.tie_rtol``): the relative
#: tolerance (on the local size of the indicators and their rates: the multipliers and rho times
#: the data at the branch's reference point) under which an indicator value or rate counts as
#: zero, on top of its rounding error measured by iterative refinement (condensed backend; the
#: full backend, which measures none, uses FULL_BACKEND_RTOL_FACTOR times it).  Roots of two
#: constraints are one point only when they lie within the uncertainty that this gives each of
#: them: a few hundred units of rounding, never a fixed share of the scale.
FULL_BACKEND_RTOL_FACTOR = 100.0
#: Safety factor on the rounding error of an indicator measured by one step of iterative refinement
#: (condensed backend): an indicator within that many times its measured error counts as zero.
ERROR_FACTOR = 16.0
#: Rounding of the data w = B K^-1 f - (g; 0) of the condensed backend, in units of the largest row:
#: its solves are accurate in norm, so every row that reads w (an open node's gap, a slipping or
#: open node's slip) carries at least this many units of the largest abs(w_i) (of abs(w2 - w1)
#: in its rate) on top of its own size (``_CondensedData._data_scale``).  The centre node of the
#: symmetric obstacle case (demos/cases/obstacle.toml) has a tangential row of -1e-19 against a
#: largest row of 0.16 where the exact value is 0: a root that it alone separates by 1e-17 in
#: alpha from the node's closing is the same point.
DATA_ULPS = 16.0
_EPS = float(np.finfo(float).eps)
#: Number of symbolic-perturbation load vectors computed at first (more when a tie survives them;
#: cfcontact.system.PERTURBATION_COLUMNS, where the loads are defined).
PERTURBATION_COLUMNS = SYSTEM_PERTURBATION_COLUMNS
#: A degenerate point's intermediate branches come from rank-2 updates of one model of the point
#: (:class:`cfcontact.condensed.PointModel`) from its this-many-th pivot on; the first ones are
#: solved afresh (a point with few pivots does not repay the model) ...
POINT_MODEL_MIN_PIVOTS = 3
#: ... on systems with at least this many multipliers (2m); below, a fresh solve per pivot costs
#: no more than an update's bookkeeping (measured: equal at m = 48, the model 3x faster at m = 96).
POINT_MODEL_MIN_SIZE = 160
#: A degenerate point with at least this many nodes near a vanishing indicator is crossed on its
#: tableau (:class:`cfcontact.condensed.PointTableau`, :func:`_tableau_walk`): a rank-one or
#: rank-two update of a small array per pivot instead of a solve; at fewer nodes a solve per pivot
#: costs no more.  (Its stat ``tableau_updates`` counts those updates, also of a walk that then
#: starts over with a solve per pivot.)
TABLEAU_MIN_NODES = 8
#: The leaving branch formed afresh must have the rates that the tableau gave it within this share
#: of their size (else the walk starts over with a solve per pivot).
TABLEAU_RTOL = 1e-8
#: Units in the last place of alpha's scale, max(|alpha|, 1), within which two roots count as one
#: transition point: alpha is rounded, and so is the load (1 - alpha) f1 + alpha f2 it weighs,
#: whose rounding is that of its larger weight; a steep constraint's value carries its rate times
#: that.  (In units of alpha itself, a half punch lifting off at alpha = 0.05, where every contact
#: force vanishes at once, was crossed as 23 transitions spread over 900 ulps of 0.05.)
ALPHA_ULPS = 4.0
#: Degenerate points whose vanishing constraints involve at most this many nodes are
#: cross-checked by enumerating the nodes' admissible states (all continuations, branch points).
ENUMERATION_CHECK_NODES = 2
#: Degenerate points crossing at most this many nodes are also crossed by the opposite
#: perturbation, which finds a second continuation where there is one (a branch point).
ALTERNATIVES_MAX_NODES = 6
#: Kept for compatibility (the number of state combinations the enumeration cross-check tries).
MAX_CANDIDATES = 4 ** ENUMERATION_CHECK_NODES
#: Iterations of SSNM (in the multipliers, from 0) before the exact method starts by its homotopy.
START_SSNM_ITERATIONS = 25
#: The start is an apex of the solution set when the contact data at alpha_start vanish to within
#: this many units of their larger end's rounding (no load that moves a contact node, no gap):
#: every solution there is zero and the problem is positively homogeneous from it.
APEX_ULPS = DATA_ULPS
#: A transition point where the data are smaller than this share of their scale, near an alpha
#: where they vanish, is that apex: there the roots are ordered by the rounding of data (and of
#: branch values) hundreds of times larger than the data themselves (a load reversed through zero
#: at alpha = 1/3: a single root 190 ulps before the apex, then 17 tied ones 1 ulp before it).
APEX_RTOL = 1e-10
#: Cross an apex met along the path by its ray (:func:`_apex_crossing`); False leaves it to the
#: lexicographic rule (benchmark Part D measures that rule on such points of m nodes).
APEX_RULE = True
#: Take ordinary transitions through the compiled step (:class:`cfcontact.native.OrdinaryStep`,
#: where the branch kernel forms the branches): the same path as the general form, faster.
ORDINARY_COMPILED = True
#: Walk a degenerate point's tableau in one compiled call (PointTableau.walk): the same pivots.
TABLEAU_COMPILED = True
#: When neither SSNM nor the homotopy can start a path, problems with at most this many contact
#: nodes are started from a solution found by enumeration (:mod:`cfcontact.enumerate`).
START_ENUMERATION_MAX_NODES = 8
#: Under MPI the displacements of a path are formed at its end when they take at most this many
#: doubles per rank (2 GiB); a larger path stays lazy (see _form_under_mpi).
FORM_AT_END_LIMIT = 2 ** 28
#: Transition cap of the homotopy start (independent of the path's max_transitions).
HOMOTOPY_MAX_TRANSITIONS = 1000000
#: How far below t = 0 the homotopy from the frictionless solution may go after a fold (it can
#: turn again and reach t = 1); 0.0 gives up at its first return to t = 0.
FRICTIONLESS_T_MIN = -ALPHA_LIMIT
#: A path that ends "cycling" or "stuck" goes back to its latest branch point with an untried
#: alternative and follows that one, at most this many times (see _backtrack).
MAX_BACKTRACKS = 16
#: The statuses a path backtracks from: a numerical inconsistency or a point it cannot cross,
#: not a property of the problem (a closed curve of solutions) nor a limit the user set.
BACKTRACK_FROM = ("cycling", "stuck")

OPEN, STICK, SLIP_P, SLIP_M = 0, 1, 2, 3
_A, _BP, _BM = 0, 1, 2

# Node kinds: 0 = F > 0, 1 = F = 0 (open or tangentially free, "free" coded slip+), 2 = a node
# without tangential unknown (its row of T vanishes, e.g. on a symmetry plane: open or closed with
# lam_t = 0, "closed" coded stick).
# _CONS_SIGN[state, kind, indicator] = sign s of the constraint s * indicator >= 0 (0: none)
_CONS_SIGN = np.zeros((4, 3, 3))
for _st, _k, _ind, _sg in ((OPEN, 0, _A, -1), (STICK, 0, _BP, -1), (STICK, 0, _BM, 1), (SLIP_P, 0, _A, 1),
                           (SLIP_P, 0, _BP, 1), (SLIP_M, 0, _A, 1), (SLIP_M, 0, _BM, -1),
                           (OPEN, 1, _A, -1), (SLIP_P, 1, _A, 1), (OPEN, 2, _A, -1), (STICK, 2, _A, 1)):
    _CONS_SIGN[_st, _k, _ind] = _sg
# _PIVOT[state, kind, indicator]: the state across the facet of that constraint (-1: an open
# node closing with F > 0 slips in the direction of its T u; -2: no such constraint)
_PIVOT = np.full((4, 3, 3), -2, dtype=np.int8)
for _st, _k, _ind, _to in ((OPEN, 0, _A, -1), (STICK, 0, _BP, SLIP_P), (STICK, 0, _BM, SLIP_M),
                           (SLIP_P, 0, _A, OPEN), (SLIP_P, 0, _BP, STICK), (SLIP_M, 0, _A, OPEN),
                           (SLIP_M, 0, _BM, STICK), (OPEN, 1, _A, SLIP_P), (SLIP_P, 1, _A, OPEN),
                           (OPEN, 2, _A, STICK), (STICK, 2, _A, OPEN)):
    _PIVOT[_st, _k, _ind] = _to
# membership (I_nu, I_t+, I_t-) of each state code; an open node is tangentially free (I_t+)
_SETS_OF_CODE = np.array([[True, True, False], [False, False, False], [False, True, False], [False, False, True]])
_CODE_SETS = np.ascontiguousarray(_SETS_OF_CODE.T)  # (nu, tp, tm) rows by code: 3 x 4


def _canon(system, sets) -> np.ndarray:
    """:func:`canonical_codes` of sets of ``system``."""
    return canonical_codes(sets, system.friction, system.no_tangent)


def node_kinds(system, friction=None) -> np.ndarray:
    """Per node: 0 (F > 0), 1 (F = 0), 2 (no tangential unknown): the second index of the tables.
    ``friction``: per-node coefficients to use instead of the system's (a path in F passes its
    pattern phi: kind 1 where phi = 0, no friction at any F)."""
    F = system.friction_vector if friction is None else np.asarray(friction)
    return np.where(np.asarray(system.no_tangent, dtype=bool), 2, np.where(F == 0.0, 1, 0)).astype(np.intp)


def sets_from_codes(codes) -> InactiveSets:
    return InactiveSets.from_rows(_CODE_SETS.take(np.asarray(codes), axis=1))  # (3 x m, a fresh array)


def state_constraints(codes, F0) -> tuple:
    """(flat indicator index ind*m + node, sign, node) of every constraint of the states ``codes``
    (node by node, each node's constraints in the order of the indicators)."""
    codes = np.asarray(codes)
    m = codes.size
    table = _CONS_SIGN[codes, np.asarray(F0, dtype=np.intp)]  # m x 3
    nodes, ind = table.nonzero()
    return ind * m + nodes, table[nodes, ind], nodes


def _digest(key: bytes) -> bytes:
    return hashlib.blake2b(key, digest_size=16).digest()


class _Unresolved(Exception):
    """A degenerate point the lexicographic rule could not resolve (kind, message, data)."""

    def __init__(self, kind, message, data=None):
        super().__init__(message)
        self.kind, self.data = kind, data or {}


def _alpha_ulp(alpha) -> float:
    """One unit in the last place of alpha's scale (see ALPHA_ULPS)."""
    return math.ulp(max(abs(float(alpha)), 1.0))  # (np.spacing's value for x >= 1, without its overhead)


def _alpha_rounding(alpha, dc):
    """What a constraint's value at alpha can be off by because alpha itself is rounded (a
    transition point is known to a few units in the last place of its scale): ALPHA_ULPS of them
    times its rate.
    Two roots within that of each other cannot be ordered by their values: they are tied, and the
    lexicographic rule orders them."""
    return ALPHA_ULPS * _alpha_ulp(alpha) * np.abs(dc)


class _Line:
    """One branch (sets fixed): multipliers, indicators and constraints, affine in alpha.

    Reference form: at alpha_ref the multipliers ``lam`` and indicators ``g`` (3m), their rates
    ``dlam`` and ``dg`` per unit alpha; the constraints' values ``c`` and rates ``dc`` at alpha_ref.
    ``tol_v`` and ``tol_s``: what counts as zero for a value at alpha_ref and for a rate."""

    __slots__ = ("codes", "key", "alpha", "lam", "dlam", "g", "dg", "cidx", "csgn", "cnode", "c", "dc",
                 "tol_v", "tol_s", "scale", "ind_tv", "ind_ts", "P", "_sets", "_Y", "_full", "source", "vertex",
                 "inputs")

    def __init__(self, codes, key, alpha, lam, dlam, g, dg, scale_v, scale_s, rtol, F0_index, full=None,
                 source=None, eg=None, tol=None, floor=None):
        self.codes, self.key, self.alpha = codes, key, float(alpha)
        self.lam, self.dlam, self.g, self.dg = lam, dlam, g, dg
        self.cidx, self.csgn, self.cnode = state_constraints(codes, F0_index)
        self.c = self.csgn * g[self.cidx]
        self.dc = self.csgn * dg[self.cidx]
        self.scale = float(scale_v.max()) if np.ndim(scale_v) else float(scale_v)
        # what counts as zero for each indicator value / rate: the local size times rtol, plus the
        # measured rounding error (eg: 3m x 2, from iterative refinement) times a safety factor,
        # plus the data's rounding (floor: (values, rates), 3m each, see DATA_ULPS); ``tol``: given
        # (ind_tv, ind_ts) instead (an intermediate branch of a point: the point's)
        if tol is not None:
            self.ind_tv, self.ind_ts = tol
        else:
            self.ind_tv = rtol * scale_v + 1e-300
            self.ind_ts = rtol * scale_s + 1e-300
            if eg is not None:
                self.ind_tv = self.ind_tv + ERROR_FACTOR * eg[:, 0]
                self.ind_ts = self.ind_ts + ERROR_FACTOR * eg[:, 1]
            if floor is not None:
                self.ind_tv = self.ind_tv + floor[0]
                self.ind_ts = self.ind_ts + floor[1]
        tv, ts = self.ind_tv, self.ind_ts
        self.tol_v = (tv[self.cidx] if np.ndim(tv) else np.full(self.cidx.size, tv)) + _alpha_rounding(self.alpha,
                                                                                                       self.dc)
        self.tol_s = ts[self.cidx] if np.ndim(ts) else np.full(self.cidx.size, ts)
        self.P = None  # indicator responses to the perturbation loads (3m x J), when needed
        self.vertex = False  # an intermediate branch of a degenerate point (Context.vertex_line)
        self._sets = None
        self._Y = None  # (Y_ref, dY) with u, when formed
        self._full = full
        self.source = source  # backend forming u on demand (lazy branches of the path), or None
        # the addresses of its arrays for the compiled ordinary step (native.OrdinaryStep.inputs),
        # None until asked for (and again once its values move: _shift)
        self.inputs = None

    @classmethod
    def compiled(cls, codes, key, alpha, lam, dlam, g, dg, cons, full, source, inputs=None) -> "_Line":
        """The branch from its tolerances and constraints formed by the compiled kernel
        (:func:`cfcontact.native.line_constraints`: the same arithmetic as :meth:`__init__`'s);
        ``inputs``: the addresses of its arrays where the kernel formed them in its own buffers."""
        ln = cls.__new__(cls)
        ln.codes, ln.key, ln.alpha = codes, key, float(alpha)
        ln.lam, ln.dlam, ln.g, ln.dg = lam, dlam, g, dg
        (ln.ind_tv, ln.ind_ts, ln.cidx, ln.csgn, ln.cnode, ln.c, ln.dc, ln.tol_v, ln.tol_s, ln.scale) = cons
        ln.P, ln.vertex, ln._sets, ln._Y, ln._full, ln.source = None, False, None, None, full, source
        ln.inputs = inputs
        return ln

    @property
    def sets(self) -> InactiveSets:
        if self._sets is None:
            self._sets = sets_from_codes(self.codes)
        return self._sets

    def values(self, alpha):
        return self.c + (alpha - self.alpha) * self.dc

    def lam_at(self, alpha):
        return self.lam + (alpha - self.alpha) * self.dlam

    def ind_at(self, alpha):
        return self.g + (alpha - self.alpha) * self.dg

    def ind_tol(self, alpha):
        """What counts as zero for each indicator at alpha (scalar or 3m)."""
        return self.ind_tv + abs(alpha - self.alpha) * self.ind_ts

    def endpoints(self):
        """(lam1, lam2, g1, g2): multipliers and indicators at alpha = 0 and 1 (storage form)."""
        a = self.alpha
        return (self.lam - a * self.dlam, self.lam + (1.0 - a) * self.dlam,
                self.g - a * self.dg, self.g + (1.0 - a) * self.dg)

    def Y(self):
        """(Y_ref, dY) = (y(alpha_ref), y') with displacements (formed once)."""
        if self._Y is None:
            self._Y = self._full()
        return self._Y

    def position(self, node, ind):
        """Index in the constraint list of node's constraint on indicator ``ind`` (or -1)."""
        j = (self.cidx == ind * self.codes.size + node).nonzero()[0]  # (the flat index names the node)
        return int(j[0]) if j.size else -1


# ------------------------------------------------------------------ backends
class _CondensedData:
    """Branch data from the condensed backend: multipliers and indicators in O(m^2) per branch."""

    def __init__(self, solver, W, loads=None):
        self.solver = solver
        self.w1, self.w2 = np.array(W[:, 0]), np.array(W[:, 1])
        # the loads (f1, f2) whose data W are: with them a branch whose data's rounding can reach
        # its multipliers is corrected against K (condensed.POLISH_RTOL); None (a homotopy's data)
        self.loads = loads
        # ... given to the corrections by their exact coefficients when they are the solver's own
        # path loads (condensed.PathLoads: no rounding of f(alpha) in B u)
        own = solver.system.loads_numpy() if loads is not None else None
        self.path_loads = None
        if own is not None and all(np.array_equal(a, b) for a, b in zip(own, loads)):
            from cfcontact.condensed import PathLoads

            self.path_loads = PathLoads
        self.dw = self.w2 - self.w1
        self.rho = solver.system.rho
        self.WE = None  # perturbation data B K^-1 E (2m x J)
        # sqrt(S_ii): |S_ij| <= sqrt(S_ii S_jj) (S = B K^-1 B^T is positive semidefinite) bounds the
        # terms of (S lam)_i row by row in O(m) (see line)
        self.sqrt_diag = np.sqrt(np.maximum(np.diagonal(solver.S), 0.0))
        self.dw_max = np.abs(self.dw).max(initial=0.0)
        # where the data vanish (an apex), or None
        self.w_scale = max(np.abs(self.w1).max(initial=0.0), np.abs(self.w2).max(initial=0.0))
        self.apex = affine_zero(self.w1, self.w2)
        m = self.dw.size // 2
        self._rows3 = np.concatenate([np.arange(m), m + np.arange(m), m + np.arange(m)])
        self._request = None  # what the compiled branch kernel needs to form a branch's constraints too
        self._stepper = None  # the compiled ordinary transition (ordinary_step)

    def _data_scale(self, w, w_max, lam) -> np.ndarray:
        """Per row i of B u (2m), the size of the terms that w_i - (S lam)_i sums: |w_i| plus the
        bound sqrt(S_ii) sum_j sqrt(S_jj) |lam_j| of sum_j |S_ij lam_j|, at most w_max (the size
        every free row was given before).  The rounding of w_i - (S lam)_i is a few units
        of |w_i| + sum_j |S_ij lam_j| (measured on the m = 4000 strip: at most 2.3 units); on a
        slender body the rows near a clamp are a hundredth of the free end's.  With the largest
        row's size for all, an open node near the clamp had an uncertainty in alpha of 1.7e-5,
        which spanned its neighbour's root: the two were taken as one point, the rule closed the
        neighbour first, and the path later came back to the node's real root inside a branch it
        had traversed ("cycling")."""
        r = np.abs(w)
        r += self.sqrt_diag * (self.sqrt_diag @ np.abs(lam))
        return np.minimum(r, w_max, out=r)

    def make_line(self, codes, key, alpha, rtol, kinds) -> _Line:
        """The branch of the state ``codes`` referenced at alpha (``kinds``: the node kinds of
        the tables, int64; ``rtol``: the run's relative tolerance)."""
        W = np.empty((self.dw.size, 2))
        w = W[:, 0]
        np.multiply(self.w1, 1.0 - alpha, out=w)
        w += alpha * self.w2
        W[:, 1] = self.dw
        true = None
        if self.loads is not None:  # (the loads of W's columns: f(alpha) and the rate f2 - f1)
            f1, f2, own = self.loads[0], self.loads[1], self.path_loads
            # (formed only if the branch is corrected against K: most never are)
            true = ((lambda: own([alpha], rates=1)) if own else
                    (lambda: np.column_stack([(1.0 - alpha) * f1 + alpha * f2, f2 - f1])), (True, False))
        L, G, Eg, cons = self.solver.branch_data(W, key, codes, refine=True, true=true,
                                                 line=(self._line_request(rtol, kinds), ALPHA_ULPS * _alpha_ulp(alpha)))
        # each indicator's own scale: the multipliers', plus rho times the data's for those that
        # read a free row of B u (an open node's gap, a slipping or open node's slip); the others'
        # B u rows are equations of the branch, exactly zero (CondensedSolver._ind); and the data's
        # rounding on the free rows (DATA_ULPS units of the data's largest entry)
        imposed = self.solver.imposed_rows(codes)
        lam, dlam = L[:, 0], L[:, 1]
        g, dg = G[:, 0], G[:, 1]
        solver = self.solver
        full = self._full(lam, dlam, alpha, imposed)
        if cons is not None:  # (formed by the compiled kernel with the branch)
            return _Line.compiled(codes, key, alpha, lam, dlam, g, dg, cons[0], full, solver, cons[1])
        if Eg is None:
            rtol = FULL_BACKEND_RTOL_FACTOR * rtol
        rho = self.rho
        unit = DATA_ULPS * _EPS * rho
        compiled = native.line_scales(W, L, self.sqrt_diag, imposed, rho, unit) if self.sqrt_diag.size else None
        if compiled is not None:
            cons = native.line_constraints(compiled, codes, kinds, _CONS_SIGN, G, Eg, rtol, ERROR_FACTOR,
                                           ALPHA_ULPS * _alpha_ulp(alpha))
            return _Line.compiled(codes, key, alpha, lam, dlam, g, dg, cons, full, solver)
        else:
            w_max = np.abs(w).max(initial=0.0)
            dv, ds = self._data_scale(w, w_max, lam), self._data_scale(self.dw, self.dw_max, dlam)
            dv[imposed] = 0.0
            ds[imposed] = 0.0
            rows3 = self._rows3  # indicator -> its row of B u (a: N u, bp and bm: T u)
            scale_v = np.abs(lam).max(initial=0.0) + rho * dv.take(rows3)
            scale_s = np.abs(dlam).max(initial=0.0) + rho * ds.take(rows3)
            free = (~imposed).take(rows3)
            floor = ((unit * w_max) * free, (unit * self.dw_max) * free)
        return _Line(codes, key, alpha, lam, dlam, g, dg, scale_v, scale_s, rtol, kinds, full, solver, Eg, floor=floor)

    def _full(self, lam, dlam, alpha, imposed):
        """The function that forms a branch's (Y_ref, dY) with displacements when asked."""
        solver = self.solver

        def full():  # u_ref = K^-1 (f(alpha) - B^T lam), u' = (u(alpha+1) - u(alpha)) [f affine]
            U = solver.displacements(np.column_stack([lam, lam + dlam]), [alpha, alpha + 1.0], imposed, (True, False))
            return np.concatenate([U[:, 0], lam]), np.concatenate([U[:, 1] - U[:, 0], dlam])

        return full

    def _line_request(self, rtol, kinds):
        """What the compiled kernel needs to form a branch's constraints with it (kept per rtol and
        node kinds)."""
        request = self._request
        if request is None or request.rtol != rtol or request.kinds_given is not kinds:
            request = self._request = native.LineRequest(self.sqrt_diag, kinds, _CONS_SIGN, DATA_ULPS * _EPS * self.rho,
                                                         rtol, ERROR_FACTOR)
        return request

    def ordinary_step(self, ln: _Line, s: int, alpha0: float, bound: float, rtol: float, kinds, lines) -> tuple:
        """An ordinary transition of the branch ln (direction s, from alpha0) in one compiled call
        (:class:`cfcontact.native.OrdinaryStep`): (1, None) when the path ends before ``bound``,
        (0, (alpha*, its uncertainty, j, node, indicator, e, d, next line)) for an ordinary
        transition, (2, None) for anything the general form must decide -- also where the kernel
        is not used here, where the next branch is known already (its factorization kept, or its
        line in ``lines``, the run's cache by (codes, alpha): the general form uses those) or
        where it needs a correction against K."""
        solver = self.solver
        kernel = solver.branch_kernel()
        if kernel is None:
            return 2, None
        request = self._line_request(rtol, kinds)
        stepper = self._stepper
        if stepper is None or stepper.kernel is not kernel or stepper.request is not request:
            stepper = self._stepper = native.OrdinaryStep(kernel, request, _PIVOT, self.w1, self.w2, self.dw,
                                                          solver.no_tangent)
        inputs = ln.inputs
        if inputs is None:
            inputs = ln.inputs = native.OrdinaryStep.inputs(ln.c, ln.dc, ln.tol_v, ln.tol_s, ln.cidx, ln.cnode, ln.g,
                                                            ln.dg, ln.ind_tv, ln.ind_ts, ln.codes)
            if inputs is None:
                return 2, None
        status, r = stepper(inputs, ln.alpha, s, alpha0, bound, ALPHA_ULPS, self.rho)
        if status:
            return status, None
        a_star, a_err, j, node, ind, old, new, e, d, codes, imposed, W, entry, L, G, E, cons, new_inputs = r
        if APEX_RULE and self.apex is not None and abs(self.apex - a_star) <= max(
                a_err, ALPHA_ULPS * _alpha_ulp(a_star), APEX_RTOL * self.w_scale / self.dw_max):
            return 2, None  # (possibly an apex: _apex_crossing decides)
        raw = codes.tobytes()
        key = b"exact:" + raw
        if (solver.has_factorization(key) or (raw, a_star) in lines
                or (self.loads is not None and solver.needs_true(W, G, L))):
            return 2, None
        solver.adopt_factorization(key, entry)
        lam, dlam = L[:, 0], L[:, 1]
        nxt = _Line.compiled(codes, key, a_star, lam, dlam, G[:, 0], G[:, 1], cons,
                             self._full(lam, dlam, a_star, imposed), solver, new_inputs)
        return 0, (a_star, a_err, j, node, ind, e, d, nxt)

    def _rate_columns(self, J):
        """The right-hand sides of an intermediate branch of a degenerate point: the rates' w2 - w1
        and the first J perturbation loads' data (2m x (1 + J))."""
        return self.dw[:, None] if not J else np.column_stack([self.dw, self.WE[:, :J]])

    def rates(self, codes, key, J=0):
        """(lam', g', P): the rates of the branch of ``codes`` (one column: w2 - w1) and, with J > 0,
        the indicators' responses to the first J perturbation loads (3m x J; else None)."""
        L, G = self.solver.branch_data(self._rate_columns(J), key, codes, plain=True)
        return L[:, 0], G[:, 0], (G[:, 1:] if J else None)

    def point_rates(self, point, codes, at, J):
        """(lam', g', P) of the branch of ``codes`` through the degenerate point of ``at`` from the
        point's :class:`~cfcontact.condensed.PointModel` (built at the first call, updated one
        pivot at a time after), or None when the model cannot answer (a fresh solve then does).
        ``point``: the point's record [at, calls, model]; P: the indicators' responses to the
        first J perturbation loads."""
        from cfcontact.condensed import PointModel

        model = point[2]
        if model is False:
            return None
        if model is None:
            m = self.dw.size // 2
            zero = np.abs(at.g) <= at.ind_tv + _alpha_rounding(at.alpha, at.dg)  # vanishing at the point
            nodes = np.union1d(np.flatnonzero(zero) % m, np.flatnonzero(codes != at.codes))
            try:
                model = PointModel(self.solver, codes, self._rate_columns(J), nodes)
            except SingularSystemError:
                point[2] = False
                return None
            point[2] = model
            X, SX = model.solution()
        else:
            res = model.move_to(codes)
            if res is None:
                return None
            X, SX = res
        G = self.solver._ind(X, model.W, SX, self.solver.imposed_rows(codes))
        return X[:, 0], G[:, 0], G[:, 1:]

    def perturbation(self, line, E_loads):
        """Indicator responses (3m x J) of the branch to the perturbation loads."""
        if self.WE is None or self.WE.shape[1] < E_loads.shape[1]:
            solver = self.solver
            # B K^-1 E: the data less their constant part -(g; 0) (a system with a gap), which
            # load_data_many includes (the data of the zero load, without a solve)
            zero = solver._gap_shifted(np.zeros(self.dw.size))
            self.WE = solver.load_data_many([E_loads[:, j] for j in range(E_loads.shape[1])]) - zero[:, None]
        WE = self.WE[:, :E_loads.shape[1]]
        _, G = self.solver.branch_data(WE, line.key, line.codes, plain=line.vertex)
        return G


class _FullData:
    """Branch data from the full PETSc backend (J(Z) factored per branch): the reference."""

    def __init__(self, system, solver):
        self.system, self.solver = system, solver
        self.f1, self.f2 = system.loads_numpy()
        self.df = self.f2 - self.f1
        self.n = system.n

    def _ind(self, y):
        return np.concatenate(indicators(self.system, y))

    def line(self, codes, key, alpha):
        sets = sets_from_codes(codes)
        f = (1.0 - alpha) * self.f1 + alpha * self.f2
        Y = self.solver.solve(sets, f)
        Yp = self.solver.solve(sets, f + self.df)  # y(alpha + 1): y' without assuming linearity in f
        dY = Yp - Y
        g = self._ind(Y)
        dg = self._ind(Yp) - g
        n, rho = self.n, self.system.rho
        scale_v = np.abs(Y[n:]).max(initial=0.0) + rho * np.abs(self.system.contact_maps()[0] @ Y[:n]).max(
            initial=0.0) + np.abs(g).max(initial=0.0)
        scale_s = np.abs(dY[n:]).max(initial=0.0) + np.abs(dg).max(initial=0.0)
        return Y[n:], dY[n:], g, dg, scale_v, scale_s, (lambda: (Y, dY)), None, None, None

    def perturbation(self, line, E_loads):
        sets = line.sets
        f = (1.0 - line.alpha) * self.f1 + line.alpha * self.f2
        Y0 = line.Y()[0]
        g0 = self._ind(Y0)
        cols = [self._ind(self.solver.solve(sets, f + E_loads[:, j])) - g0 for j in range(E_loads.shape[1])]
        return np.column_stack(cols)


# ------------------------------------------------------------------ context
class _Context:
    """What one run needs: system, backend, options, alpha range, caches, visited branches."""

    fast = False  # (see __init__; subclasses with other data do not take the compiled step)

    def __init__(self, system, solver, opts, lo, hi, rtol, W=None, callback=None):
        self.system, self.solver, self.opts, self.callback = system, solver, opts, callback
        self.lo, self.hi, self.rtol = lo, hi, rtol
        self.Fv = system.friction_vector
        self.F0 = self.Fv == 0.0
        self.F0_index = node_kinds(system)  # the node kind of each node (second index of the tables)
        self._kinds = np.ascontiguousarray(self.F0_index, dtype=np.int64)
        self.m = system.m
        self.f1, self.f2 = system.loads_numpy()
        if hasattr(solver, "branch_data"):
            if W is None:
                W = solver.load_data_many([self.f1, self.f2])
                self.data = _CondensedData(solver, W, (self.f1, self.f2))
            else:
                self.data = _CondensedData(solver, W)
            self.condensed = True
        else:
            self.data = _FullData(system, solver)
            self.condensed = False
        self.visited: dict = {}  # digest of canonical codes -> (orientation, alpha) of its first entry
        self._lines: dict = {}  # (key, alpha) -> _Line, for the current transition point
        # ordinary transitions in one compiled call (_ordinary_transition): condensed data
        self.fast = type(self.data) is _CondensedData and ORDINARY_COMPILED
        self.E = None  # perturbation loads (n x J)
        self._point = None  # the degenerate point being crossed: [its first branch, pivots so far, model]
        self.stats = {"degenerate_points": 0, "pivots": 0, "max_vanishing": 0, "branch_points": 0,
                      "perturbation_solves": 0, "homotopy_transitions": 0, "start_pivots": 0, "point_updates": 0,
                      "tableau_updates": 0, "revisited_vertices": 0}

    def line(self, codes, alpha) -> _Line:
        codes = np.asarray(codes, dtype=np.int8)
        key = codes.tobytes()
        ck = (key, float(alpha))
        ln = self._lines.get(ck)
        if ln is not None:
            return ln
        make = getattr(self.data, "make_line", None)
        if make is not None:
            ln = make(codes, b"exact:" + key, alpha, self.rtol, self._kinds)
        else:
            lam, dlam, g, dg, sv, ss, full, source, eg, floor = self.data.line(codes, b"exact:" + key, alpha)
            rtol = self.rtol if eg is not None else FULL_BACKEND_RTOL_FACTOR * self.rtol
            ln = _Line(codes, b"exact:" + key, alpha, lam, dlam, g, dg, sv, ss, rtol, self.F0_index, full, source, eg,
                       floor=floor)
        if len(self._lines) > 64:
            self._lines.clear()
        self._lines[ck] = ln
        return ln

    def vertex_line(self, codes, alpha, at: _Line) -> _Line:
        """The branch of ``codes`` through the point of the branch ``at`` (referenced at alpha): an
        intermediate branch of a degenerate point.  Its indicators there are those of the point
        (they depend on y only), so only its rates are solved for (condensed backend; the full
        backend forms a line as usual).  Not for the path: the branch that leaves the point is
        formed by :meth:`line`."""
        if not self.condensed:
            return self.line(codes, alpha)
        codes = np.asarray(codes, dtype=np.int8)
        key = codes.tobytes()
        ck = (key, float(alpha), "vertex")
        ln = self._lines.get(ck)
        if ln is not None:
            return ln
        res = self._point_rates(codes, at)
        if res is not None:
            dlam, dg, P = res
        elif self.data.WE is not None:  # the perturbation responses with the rates, in one solve
            dlam, dg, P = self.data.rates(codes, b"exact:" + key, PERTURBATION_COLUMNS)
        else:
            dlam, dg, P = self.data.rates(codes, b"exact:" + key)
        # the point's own precision, the rates' of the point's branch
        ln = _Line(codes, b"exact:" + key, alpha, at.lam, dlam, at.g, dg, at.scale, 0.0, self.rtol, self.F0_index,
                   None, at.source, tol=(at.ind_tv, at.ind_ts))
        ln.P = P
        ln.vertex = True
        self._lines[ck] = ln
        return ln

    def _point_rates(self, codes, at: _Line):
        """(lam', g', P) of a vertex line from the point's model once the point has needed
        POINT_MODEL_MIN_PIVOTS of them, else None."""
        pt = self._point
        if pt is None or pt[0] is not at:
            pt = self._point = [at, 0, None]
        pt[1] += 1
        if pt[1] < POINT_MODEL_MIN_PIVOTS or 2 * self.m < POINT_MODEL_MIN_SIZE:
            return None
        self.perturbation_rows(at, PERTURBATION_COLUMNS)  # the perturbation loads' data
        res = self.data.point_rates(pt, codes, at, PERTURBATION_COLUMNS)
        if res is not None:
            self.stats["point_updates"] += 1
        return res

    def perturbation_rows(self, ln: _Line, J: int) -> np.ndarray:
        """The constraints' responses to the first J perturbation loads (k x J)."""
        if ln.P is None or ln.P.shape[1] < J:
            if self.E is None or self.E.shape[1] < J:
                self.E = self.system.perturbation_loads(J)
            ln.P = self.data.perturbation(ln, self.E[:, :J])
            self.stats["perturbation_solves"] += J
        return ln.csgn[:, None] * ln.P[ln.cidx, :J]

    def indicator_perturbation(self, ln: _Line, flat_index: int, J: int) -> np.ndarray:
        self.perturbation_rows(ln, J)
        return ln.P[flat_index, :J]


# ------------------------------------------------------------------ lexicographic helpers
def _lex_argmin(rows, rtol=1e-9):
    """Index of the lexicographically smallest row (k x J), or None if the first J columns tie."""
    cand = np.arange(rows.shape[0])
    for j in range(rows.shape[1]):
        col = rows[cand, j]
        lo = col.min()
        tol = rtol * max(np.abs(col).max(), 1e-300)
        cand = cand[col <= lo + tol]
        if cand.size == 1:
            return int(cand[0])
    return None


def _lex_sign(vec, rtol=1e-9, scale=None):
    """Sign of the first component of vec that is not zero (relative to ``scale``), 0 if none."""
    sc = np.abs(vec).max(initial=0.0) if scale is None else scale
    for v in vec:
        if abs(v) > rtol * max(sc, 1e-300):
            return 1 if v > 0 else -1
    return 0


def _lexmin_with_more_columns(ctx, compute, k):
    """compute(J) -> rows (k x J); the lexicographic argmin, adding perturbation columns until the
    rows differ (at most 2m + 1 columns: the rows are linearly independent in exact arithmetic)."""
    J = PERTURBATION_COLUMNS
    limit = 2 * ctx.m + 1
    while True:
        rows = compute(J)
        i = _lex_argmin(rows)
        if i is not None:
            return i
        if J >= limit:
            return 0  # unresolvable within rounding: any choice is as good
        J = min(limit, 4 * J)


# ------------------------------------------------------------------ ratio test
def _exit(ctx: _Context, ln: _Line, alpha0: float, s: int):
    """First alpha from alpha0 (on ln, direction s) where a decreasing constraint vanishes.

    Returns (alpha*, tied constraint positions, uncertainty of alpha*) or (None, None, None) when
    none vanishes before the end of the alpha range.  Roots that lie within their rounding
    uncertainty of the first one are tied (the same point); every other root is a later, separate
    transition."""
    bound = ctx.hi if s > 0 else ctx.lo
    out = native.first_root(ln.c, ln.dc, ln.tol_v, ln.tol_s, s, alpha0, ln.alpha, bound, ALPHA_ULPS)
    if out is not False:  # (the same arithmetic compiled)
        return out
    sdc = s * ln.dc
    dec = (sdc < -ln.tol_s).nonzero()[0]
    if not dec.size:
        return None, None, None
    rate = -sdc[dec]
    t = (ln.c[dec] + (alpha0 - ln.alpha) * ln.dc[dec]) / rate  # distance from alpha0
    np.maximum(t, 0.0, out=t)
    j = int(t.argmin())
    a_star = alpha0 + s * float(t[j])
    if s * (a_star - bound) >= 0:
        return None, None, None
    # uncertainty of each root: its data's, and the rounding of alpha itself near a_star
    err = (ln.tol_v[dec] + abs(a_star - ln.alpha) * ln.tol_s[dec]) / rate + ALPHA_ULPS * _alpha_ulp(a_star)
    if s * (bound - a_star) <= err[j]:
        # the root is the end of the range within its own uncertainty: the path ends there (a
        # load path from or to f = 0 has every constraint of its last branch vanish at alpha = 0,
        # rounded to either side; taken as transitions, they cascaded through 1e-82, 1e-150, ...,
        # each point the rounding of its branch's entry, no solution at its own size)
        return None, None, None
    tied = dec[(t - t[j]) <= err + err[j]]
    return a_star, tied, float(err[j])


def _recenter(ctx: _Context, ln: _Line, s: int, a_star: float, alpha_from: float):
    """(line, alpha*, tied, uncertainty): ln evaluated afresh at its transition point alpha* (values
    extrapolated from its entry carry the rounding of its rates times the distance), the point
    corrected to the first root as seen from there, and the constraints that vanish there within
    their own rounding.  Used when several roots tie on ln: it keeps roots apart that the
    extrapolation could not separate."""
    lc = ln
    for _ in range(4):
        lc = ctx.line(ln.codes, a_star)
        sdc = s * lc.dc
        dec = (sdc < -lc.tol_s).nonzero()[0]
        if not dec.size:
            return ln, a_star, np.zeros(0, dtype=np.intp), 0.0
        rate = -sdc[dec]
        t = lc.c[dec] / rate  # distance of each root from alpha* (negative: behind)
        unc = lc.tol_v[dec] / rate
        j = int(t.argmin())
        moved = a_star + s * float(t[j])
        if abs(t[j]) > unc[j] and s * (moved - alpha_from) >= 0 and ctx.lo <= moved <= ctx.hi:
            a_star = moved  # the first root lies measurably elsewhere: look again from there
            continue
        tied = dec[np.abs(t - t[j]) <= unc + unc[j]]
        return lc, a_star, tied, float(unc[j])
    return lc, a_star, dec[np.abs(t - t[j]) <= unc + unc[j]], float(unc[j])


# ------------------------------------------------------------------ pivoting
def _resolve(ctx: _Context, ln: _Line, s: int, a_star: float, tied, sign: int = 1, start: bool = False):
    """Cross the transition point a_star of branch (ln, s), whose constraints ``tied`` vanish there,
    one facet at a time by the lexicographic rule of the perturbation sign * eps.

    Returns (line, direction, pivots, e): the branch leaving the point with positive length and the
    position of the constraint by which it was entered.  ``start``:
    ln is the start branch at a_star = alpha_start (the point itself is not perturbed).
    Raises _Unresolved."""
    m = ctx.m
    cur, d = ln, s
    visited = {(cur.key, d)}
    pivots = []
    # the first leaving constraint: the lexicographically first root on ln
    if len(tied) == 1:
        k = int(tied[0])
    else:
        rates = np.abs(cur.dc[tied])
        k = int(tied[_lexmin_with_more_columns(
            ctx, lambda J: sign * ctx.perturbation_rows(cur, J)[tied] / rates[:, None], len(tied))])

    def offset_leaving(line, k):
        """delta(J): the lexicographic offset of the point where ``line`` leaves through k."""
        if start:
            return lambda J: np.zeros(J)
        return lambda J: -(sign * ctx.perturbation_rows(line, J)[k]) / line.dc[k]

    def offset_entering(line, e):
        """delta(J): the lexicographic offset of the vertex where ``line`` is entered through e."""
        return lambda J: -(sign * ctx.perturbation_rows(line, J)[e]) / line.dc[e]

    delta = offset_leaving(cur, k)  # offset of the vertex we are at, as a function of J
    first = None  # the first branch across the point, formed in full: the point's values
    repair = False  # is k a constant constraint that is negative in the perturbation (not a root)?
    for _ in range(max(64, 8 * m)):
        node = int(cur.cnode[k])
        ind = int(cur.cidx[k]) // m
        old = int(cur.codes[node])
        new = int(_PIVOT[old, ctx.F0_index[node], ind])
        if new == -2:
            raise _Unresolved("degenerate", f"no facet for constraint {SET_NAMES[ind]} of node {node} ({STATE_NAMES[old]})")
        if new == -1:  # an open node closes: it slips in the direction of its T u (bp = bm = rho T u here)
            b = float(cur.g[m + node] + (a_star - cur.alpha) * cur.dg[m + node])
            btol = cur.ind_tol(a_star)
            if abs(b) > (btol if np.isscalar(btol) else btol[m + node]):
                new = SLIP_P if b > 0 else SLIP_M
            else:
                J = PERTURBATION_COLUMNS
                while True:
                    Pb = sign * ctx.indicator_perturbation(cur, m + node, J)
                    sg = _lex_sign(cur.dg[m + node] * delta(J) + Pb)
                    if sg or J > 2 * m:
                        break
                    J *= 4
                new = SLIP_P if sg >= 0 else SLIP_M
        codes = cur.codes.copy()
        codes[node] = new
        try:
            nxt = ctx.line(codes, a_star) if first is None else ctx.vertex_line(codes, a_star, first)
            if first is None:
                first = nxt
        except SingularSystemError as exc:
            raise _Unresolved("singular", f"the branch across the facet is singular: {exc}",
                              {"node": node, "from": STATE_NAMES[old], "to": STATE_NAMES[new]}) from None
        e = nxt.position(node, ind)
        de = float(nxt.dc[e]) if e >= 0 else 0.0
        if e >= 0 and abs(de) > nxt.tol_s[e]:
            d = 1 if de > 0 else -1
            delta = offset_entering(nxt, e)
        elif not repair or e < 0:
            raise _Unresolved("singular", f"the branch across the facet of node {node} ({STATE_NAMES[old]} -> "
                              f"{STATE_NAMES[new]}) does not move alpha (rate {de:.3g})",
                              {"node": node, "from": STATE_NAMES[old], "to": STATE_NAMES[new]})
        # else: a constant constraint crossed at the same vertex (two codes of nearly one line):
        # orientation and vertex offset stay
        pivots.append({"node": node, "set": SET_NAMES[ind], "from": STATE_NAMES[old], "to": STATE_NAMES[new],
                       "orientation": d})
        if (nxt.key, d) in visited:
            raise _Unresolved("cycling", "the lexicographic pivots return to a branch already crossed at this point",
                              {"pivots": pivots})
        visited.add((nxt.key, d))
        ctx.stats["pivots"] += 1
        # constraints of nxt that vanish at a_star (its reference point) and do not grow in d
        zero = np.abs(nxt.c) <= nxt.tol_v
        if e >= 0:
            zero[e] = False
        if not zero.any():  # (an ordinary transition: one pivot)
            return _full_exit(ctx, nxt, a_star), d, pivots, e
        rate = d * nxt.dc
        cand = zero & (rate <= nxt.tol_s)
        if not cand.any():
            return _full_exit(ctx, nxt, a_star), d, pivots, e
        if nxt is first and not repair and type(ctx.data) is _CondensedData:
            out = _tableau_walk(ctx, first, d, e, sign, a_star, pivots, visited)
            if out is not None:
                return out
        dec = cand & (rate < -nxt.tol_s)
        flat = (cand & ~dec).nonzero()[0]
        repair = False
        if flat.size:
            # constant (within rounding) and zero: the perturbation decides whether it holds here
            J = PERTURBATION_COLUMNS
            P = sign * ctx.perturbation_rows(nxt, J)
            v = nxt.dc[flat, None] * delta(J)[None, :] + P[flat]
            neg = [i for i in range(flat.size) if _lex_sign(v[i]) < 0]
            if neg:
                k = int(flat[neg[_lex_argmin(v[neg]) or 0]])
                repair = True
                cur = nxt
                continue
        D = dec.nonzero()[0]
        if not D.size:
            return _full_exit(ctx, nxt, a_star), d, pivots, e
        if D.size == 1:
            k = int(D[0])
        else:
            rates = np.abs(nxt.dc[D])

            def rows(J, nxt=nxt, D=D, rates=rates, delta=delta):
                P = sign * ctx.perturbation_rows(nxt, J)
                return (nxt.dc[D, None] * delta(J)[None, :] + P[D]) / rates[:, None]

            k = int(D[_lexmin_with_more_columns(ctx, rows, D.size)])
        cur = nxt
    raise _Unresolved("degenerate", f"more than {max(64, 8 * m)} pivots at one point", {"pivots": pivots})


def _tableau_walk(ctx: _Context, first: _Line, d: int, e: int, sign: int, a_star: float, pivots: list, visited: set):
    """The rest of :func:`_resolve`'s walk from its first pivot (the branch ``first``, entered in
    direction d through its constraint e), on the point's :class:`~cfcontact.condensed.PointTableau`.

    The same rule and the same decisions as the loop of :func:`_resolve`, with the rates and
    perturbation responses of the point's nodes from the tableau's rank-2 updates instead of a
    solve per intermediate branch (and nothing of the other nodes, which the walk never needs).
    Returns (line, d, pivots, e) as :func:`_resolve`, the leaving branch formed afresh and
    checked: none of its constraints that vanish at the point decreases in d, and its rates at the
    point's nodes are the tableau's.  Returns None where the loop of :func:`_resolve` must go on
    instead (its case is not one the walk handles: a constraint constant along the branch, a tie
    that needs more perturbation columns, a near-singular update, a failed check); ``pivots`` and
    ``visited`` are then as they were."""
    from cfcontact.condensed import PointTableau

    m = ctx.m
    g = first.g
    tv = np.broadcast_to(first.ind_tv, (3 * m,))
    near = np.abs(g) <= 4.0 * tv + 256.0 * _alpha_rounding(a_star, first.dg)
    nodes = np.unique(np.flatnonzero(near) % m)
    if nodes.size < TABLEAU_MIN_NODES:
        return None
    J = PERTURBATION_COLUMNS
    ctx.perturbation_rows(first, J)  # the perturbation loads' data
    try:
        tab = PointTableau(ctx.solver, first.codes, ctx.data._rate_columns(J), nodes)
    except SingularSystemError:
        return None
    n_piv, added, n_stats = len(pivots), [], ctx.stats["pivots"]

    def give_up():
        del pivots[n_piv:]
        visited.difference_update(added)
        ctx.stats["pivots"] = n_stats
        return None

    kind = ctx.F0_index[nodes]
    codes = first.codes.copy()
    loc = codes[nodes].astype(np.intp)  # the nodes' states
    # the nodes' indicators, node by node (flat index 3 j + i: indicator i of node j): the point's
    # values (the same on every branch through it) and what counts as zero
    flat = (np.arange(3)[None, :] * m + nodes[:, None]).ravel()
    absg = np.abs(g[flat])
    tvf = tv[flat]
    tsf = np.broadcast_to(first.ind_ts, (3 * m,))[flat]
    spacing = ALPHA_ULPS * _alpha_ulp(a_star)
    sg = _CONS_SIGN[loc, kind].ravel()  # the constraints of the nodes' states, 0: none
    lidx = {int(i): j for j, i in enumerate(nodes)}
    je = lidx.get(int(first.cnode[e]))
    if je is None:
        return give_up()
    fe = 3 * je + int(first.cidx[e]) // m  # the constraint the branch was entered by
    ind = tab.indicators()
    delta = -(sign * sg[fe] * ind[fe, 1:]) / (sg[fe] * ind[fe, 0])  # the vertex's lexicographic offset
    # the loop below in one compiled call (PointTableau.walk: the same decisions, the same bits)
    walked = _compiled_walk(tab, ind, codes, loc, sg, kind, nodes, g, absg, tvf, tsf, spacing, sign, d, fe, delta,
                            visited, first.codes, m) if TABLEAU_COMPILED else None
    if walked is not None and walked[0] == 3:  # (more states than it had room for: the loop below,
        try:                                   # on a fresh tableau; the walk changed only its own)
            tab = PointTableau(ctx.solver, first.codes, ctx.data._rate_columns(J), nodes)
        except SingularSystemError:
            return None
        walked = None
        ind = tab.indicators()
    if walked is not None:
        status, done, d, fe, codes, ind = walked
        if status:
            return give_up()
        for j, c, old, new, dd in done.tolist():
            pivots.append({"node": int(nodes[j]), "set": SET_NAMES[c], "from": STATE_NAMES[old], "to": STATE_NAMES[new],
                           "orientation": dd})
        ctx.stats["pivots"] += len(done)
        ctx.stats["tableau_updates"] += len(done)
    for _ in (range(max(64, 8 * m)) if walked is None else ()):
        dc = sg * ind[:, 0]
        rate = d * dc
        cand = (absg <= tvf + spacing * np.abs(dc)) & (rate <= tsf) & (sg != 0.0)
        cand[fe] = False
        D = cand.nonzero()[0]
        if not D.size:
            break
        rD = rate[D]
        if (rD >= -tsf[D]).any():
            return give_up()  # a constant constraint: the perturbation decides (the loop of _resolve)
        if D.size == 1:
            f = int(D[0])
        else:
            # the lexicographic offsets of the roots, (dc delta + P) / |dc| (first column first)
            dD, sD = dc[D], sign * sg[D]
            col = (dD * delta[0] + sD * ind[D, 1]) / -rD
            i = int(col.argmin())
            if (col <= col[i] + 1e-9 * np.abs(col).max()).sum() > 1:  # a tie in the first column
                rows = (dD[:, None] * delta + sD[:, None] * ind[D, 1:]) / np.abs(dD)[:, None]
                i = _lex_argmin(rows)
                if i is None:
                    return give_up()  # tied in the first perturbation columns: more of them
            f = int(D[i])
        j, c = divmod(f, 3)
        node, old = int(nodes[j]), int(loc[j])
        new = int(_PIVOT[old, kind[j], c])
        if new == -2:
            return give_up()
        if new == -1:  # an open node closes: it slips in the direction of its T u
            fb = 3 * j + _BP
            b = float(g[m + node])
            if abs(b) > tvf[fb]:
                new = SLIP_P if b > 0 else SLIP_M
            else:
                sgn = _lex_sign(ind[fb, 0] * delta + sign * ind[fb, 1:])
                if not sgn:
                    return give_up()
                new = SLIP_P if sgn > 0 else SLIP_M
        if not tab.change(j, old, new):
            return give_up()
        loc[j] = new
        codes[node] = new
        sg[3 * j:3 * j + 3] = _CONS_SIGN[new, kind[j]]
        ind = tab.indicators()
        de = sg[f] * ind[f, 0]
        if not sg[f] or not abs(de) > tsf[f]:
            return give_up()
        d = 1 if de > 0 else -1
        delta = -(sign * sg[f] * ind[f, 1:]) / de
        fe = f
        pivots.append({"node": node, "set": SET_NAMES[c], "from": STATE_NAMES[old], "to": STATE_NAMES[new],
                       "orientation": d})
        key = (b"exact:" + codes.tobytes(), d)
        if key in visited:
            return give_up()  # the loop of _resolve reports it
        visited.add(key)
        added.append(key)
        ctx.stats["pivots"] += 1
        ctx.stats["tableau_updates"] += 1
    else:
        if walked is None:
            return give_up()
    # the leaving branch afresh: it must leave the point (no vanishing constraint decreasing in d)
    # with the rates the tableau gave it
    try:
        out = ctx.line(codes, a_star)
    except SingularSystemError:
        return give_up()
    je, ie = divmod(fe, 3)
    e_out = out.position(int(nodes[je]), ie)
    zero = np.abs(out.c) <= out.tol_v
    if e_out >= 0:
        zero[e_out] = False
    rates = out.dg[flat]
    scale = np.abs(rates).max(initial=0.0) + 1e-300
    if (e_out < 0 or (zero & (d * out.dc < -out.tol_s)).any()
            or np.abs(rates - ind[:, 0]).max(initial=0.0) > TABLEAU_RTOL * scale):
        return give_up()
    return out, d, pivots, e_out


def _compiled_walk(tab, ind, codes, loc, sg, kind, nodes, g, absg, tvf, tsf, spacing, sign, d, fe, delta, visited,
                   base_codes, m):
    """:func:`_tableau_walk`'s loop by :meth:`~cfcontact.condensed.PointTableau.walk`: (status, pivots
    (j, indicator, old, new, d per pivot), d, fe, codes, indicators) after it -- status 0 through, 1
    given up, 3 start again without it (the tableau has changed) -- or None where it is not
    available (the loop in Python then).  The visited branches of the walk differ from
    ``base_codes`` at the point's nodes only, so their states there are what is compared; those
    that differ elsewhere can never be reached.  The caller's arrays are left as they are (the walk
    works on copies), so that its loop can start again from them."""
    others = np.ones(m, dtype=bool)
    others[nodes] = False
    states = []
    for key, dv in visited:
        vc = np.frombuffer(key[len(b"exact:"):], dtype=np.int8) if key.startswith(b"exact:") else None
        if vc is None or vc.size != m:
            return None
        if np.array_equal(vc[others], base_codes[others]):
            states.append((vc[nodes], dv))
    H = np.array(ind, dtype=np.float64, order="C")
    loc8 = np.array(loc, dtype=np.int8)
    sgc = np.array(sg, dtype=np.float64)
    dl = np.array(delta, dtype=np.float64)
    res = tab.walk(H, loc8, sgc, np.ascontiguousarray(kind, dtype=np.int64), np.ascontiguousarray(g[m + nodes]),
                   np.ascontiguousarray(absg), np.ascontiguousarray(tvf), np.ascontiguousarray(tsf), spacing, sign, d, fe,
                   dl, _PIVOT, _CONS_SIGN, states, max(64, 8 * m))
    if res is None:
        return None
    status, done, d, fe = res
    if status:
        return status, None, d, fe, None, None
    out = codes.copy()
    out[nodes] = loc8
    return 0, done, d, fe, out, H


def _full_exit(ctx, ln: _Line, alpha) -> _Line:
    """The branch leaving a degenerate point, formed in full (an intermediate one has only rates)."""
    return ctx.line(ln.codes, alpha) if ln.vertex else ln


def _admissible_states(ctx: _Context, g_star: np.ndarray, node: int, tol: float) -> list:
    """States of ``node`` whose (closed) constraints hold at the indicator values g_star (3m)."""
    m = ctx.m
    kind = int(ctx.F0_index[node])
    g = (float(g_star[node]), float(g_star[m + node]), float(g_star[2 * m + node]))
    out = []
    for st in ((OPEN, STICK, SLIP_P, SLIP_M), (OPEN, SLIP_P), (OPEN, STICK))[kind]:
        signs = _CONS_SIGN[st, kind]
        if all(signs[i] * g[i] >= -tol for i in range(3) if signs[i]):
            out.append(st)
    return out


def _directions(ln: _Line, a_tol: float = 0.0) -> tuple:
    """(valid for d = +1, valid for d = -1): is ln consistent on [alpha_ref, alpha_ref + d eps] for
    some eps > 0 (from its values and rates at its reference point)?  ``a_tol``: the reference
    point is known only to within this much in alpha (each value's tolerance grows by its rate
    times a_tol)."""
    tol_v = ln.tol_v + np.abs(ln.dc) * a_tol if a_tol else ln.tol_v
    neg = ln.c < -tol_v
    if neg.any():
        return False, False
    zero = ln.c <= tol_v
    if not zero.any():
        return True, True
    dz, tz = ln.dc[zero], ln.tol_s[zero]
    return bool((dz >= -tz).all()), bool((dz <= tz).all())


def _same_line(a: _Line, b: _Line, rtol=1e-9) -> bool:
    """Same y(alpha) near the common point (the multipliers determine u for a given load)."""
    sc = max(np.abs(a.lam).max(initial=0), np.abs(a.dlam).max(initial=0), 1e-300)
    return bool(np.abs(a.lam_at(b.alpha) - b.lam).max(initial=0) <= rtol * sc
                and np.abs(a.dlam - b.dlam).max(initial=0) <= rtol * max(sc, np.abs(b.dlam).max(initial=0)))


def _enumerated_continuations(ctx: _Context, ln: _Line, s: int, a_star: float, nodes, a_tol: float = 0.0,
                              extra=(), admit=None) -> list:
    """Every (line, direction) continuing (ln, s) at a_star found by trying the admissible states of
    ``nodes`` (the cross-check of small degenerate points), and the state codes ``extra``.
    ``a_tol``: a_star is known only to within this much in alpha (a vertex reached a second time,
    :func:`_revisited_vertex`): the indicators, multipliers and constraints may miss it by that
    much times their rates.  ``admit(codes, d)``: which candidates may be kept at all (d=None:
    asked before the candidate's line is solved)."""
    g_star = ln.ind_at(a_star)
    tol = np.broadcast_to(ln.ind_tol(a_star), (3 * ctx.m,))
    m = ctx.m
    dg = np.abs(ln.dg)
    choices = [_admissible_states(ctx, g_star, i, max(tol[i], tol[m + i], tol[2 * m + i])
                                  + a_tol * max(dg[i], dg[m + i], dg[2 * m + i])) for i in nodes]
    candidates = {}
    for cb in itertools.product(*choices):
        codes = ln.codes.copy()
        codes[nodes] = cb
        candidates.setdefault(codes.tobytes(), codes)
    for codes in extra:
        candidates.setdefault(codes.tobytes(), codes)
    lam_star = ln.lam_at(a_star)
    lsc = max(np.abs(lam_star).max(initial=0), ln.scale, 1e-300)
    out = []
    for codes in candidates.values():
        if np.array_equal(codes, ln.codes) or (admit is not None and not admit(codes, None)):
            continue
        try:
            cand = ctx.line(codes, a_star)
        except SingularSystemError:
            continue
        if np.abs(cand.lam - lam_star).max(initial=0) > 1e-6 * lsc + a_tol * np.abs(cand.dlam).max(initial=0):
            continue  # does not pass through the transition point
        fwd, bwd = _directions(cand, a_tol)
        for d, ok in ((s, fwd if s > 0 else bwd), (-s, bwd if s > 0 else fwd)):
            if not ok or (admit is not None and not admit(codes, d)):
                continue
            if d == -s and _same_line(cand, ln):
                continue  # the incoming branch itself
            if any(dd == d and _same_line(cand, other) for other, dd in out):
                continue
            out.append((cand, d))
    return out


# ---------------------------------------------------------------------- driver
def _add_branch(path, ln: _Line, s: int, **kw):
    """Add ln to the path: lazily (multipliers, indicators; u formed on demand) with a backend that
    forms displacements in batches, else with its end points Y1, Y2."""
    if ln.source is not None and ln._Y is None:
        return path.add_branch(ln.sets, s, None, None, multipliers=(ln.lam, ln.dlam), indicators=(ln.g, ln.dg),
                               source=ln.source, reference=ln.alpha, **kw)
    Yr, dY = ln.Y()
    return path.add_branch(ln.sets, s, Yr, dY, reference=ln.alpha, **kw)


def _imposed_count(code: int, kind: int) -> int:
    """How many of a node's two rows of B u its state imposes as equations (the condensed
    backend's imposed_rows): N u = g when closed, T u = 0 when sticking with a tangential
    unknown (kind 2 has none)."""
    return (code != OPEN) + (code == STICK and kind != 2)


def _precise_side(ctx, old: _Line, new: _Line) -> Optional[str]:
    """Which of two branches meeting at a transition point locates the point's displacements to
    the multipliers' precision ("old", "new"; None: neither, or the nodes disagree).  A node's
    gap N u - g and slip T u are exactly zero where its state imposes them (closed, sticking):
    there the condensed data's cancellation w - S lam (of the size of w, which on a slender body
    is thousands of times the contact displacements) does not enter.  So a node that becomes
    closed or sticking is located by the new branch, one that opens or starts slipping by the
    old one, whose vanishing indicator was a multiplier (lam_n, or lam_t -+ F lam_n)."""
    if not ctx.condensed:
        return None
    changed = (old.codes != new.codes).nonzero()[0]  # (usually one node)
    if changed.size == 1:  # (the same count for one node, from its states and kind)
        i = int(changed[0])
        kind = int(ctx.F0_index[i])
        gain = _imposed_count(int(new.codes[i]), kind) - _imposed_count(int(old.codes[i]), kind)
        more, less = gain > 0, gain < 0
    else:
        imposed = ctx.data.solver.imposed_rows  # (cached per state: both branches' were just asked for)
        before, after = imposed(old.codes), imposed(new.codes)
        m = old.codes.size
        gain = (after[changed].astype(int) + after[m + changed]) - (before[changed].astype(int) + before[m + changed])
        more, less = bool((gain > 0).any()), bool((gain < 0).any())
    if more == less:
        return None
    return "new" if more else "old"


def _meeting_point(ctx, old: _Line, new: _Line, alpha) -> tuple:
    """(exit, entry): the (lam, g) to store as the old branch's exit and as the new branch's
    entry at their transition point (None: keep the branch's own): the point of the side that
    locates it precisely (:func:`_precise_side`) for both.  (Making the other side's multiplier
    equations exact there as well, e.g. an opening node's lam_n of -1e-4 set to 0, was tried and
    dropped: the change moves u at the neighbouring nodes through S, and a sticking node next to
    a fold at F = 30 then slipped by 4.5 / rho, a residual of 1e-7.)

    At an apex (the data vanish at alpha, no gap) both are zero: the one solution of zero data
    (lam^T S lam = -lam^T B u <= 0 by the complementarity conditions), which neither branch's
    values there, the rounding of its larger ends, can give."""
    if ctx.condensed and ctx.data.apex is not None and alpha == ctx.data.apex and _is_apex(ctx, alpha):
        zero = (np.zeros_like(new.lam), np.zeros_like(new.g))
        return zero, zero
    side = _precise_side(ctx, old, new)
    if side == "new":
        return (new.lam_at(alpha), new.ind_at(alpha)), None
    if side == "old":  # the old branch's own solve (its stored entry may be its predecessor's exit:
        point = (old.lam_at(alpha), old.ind_at(alpha))  # no chains of extrapolations)
        return point, point
    return None, None


def _vanishing(ctx, ln, idx):
    m = ctx.m
    return [{"node": int(ln.cnode[j]), "set": SET_NAMES[int(ln.cidx[j]) // m]} for j in idx]


#: Membership of each state (STATE_NAMES' order) in the sets (nu, tp, tm) (InactiveSets.from_states).
_MEMBERSHIP = ((True, True, False), (False, False, False), (False, True, False), (False, False, True))


def _set_name(a: int, b: int) -> str:
    """The name of a node's change from state code a to b: the first of the sets (nu, tp, tm)
    that it toggles, as the seed method names a change (a node that opens or closes: "nu")."""
    return next(k for k, x, y in zip(SET_NAMES, _MEMBERSHIP[a], _MEMBERSHIP[b]) if x != y)


def _changes(ln, nxt, vanishing):
    """The nodes whose state changes, in the order of their vanishing constraints, each named by
    the first of the sets (nu, tp, tm) that its change toggles, as the seed method names a change.
    Where one constraint of the node vanishes that is its set; where several vanish at once (a
    degenerate point; at an apex every one does) the name does not depend on which the rule
    crossed first (``Transition.pivots`` lists those): a node that opens is named by "nu"."""
    changes, seen = [], set()
    for ch in vanishing:
        i = ch["node"]
        if i in seen or ln.codes[i] == nxt.codes[i]:
            continue
        seen.add(i)
        a, b = int(ln.codes[i]), int(nxt.codes[i])
        changes.append({**ch, "set": _set_name(a, b), "from": STATE_NAMES[a], "to": STATE_NAMES[b]})
    for i in (nxt.codes != ln.codes).nonzero()[0].tolist():
        if i not in seen:
            changes.append({"node": int(i), "set": None, "from": STATE_NAMES[int(ln.codes[i])],
                            "to": STATE_NAMES[int(nxt.codes[i])]})
    return changes


def _shift(ln: _Line, delta: float):
    """Move the reference point of ln by delta along the branch (a small correction)."""
    ln.alpha += delta
    ln.lam = ln.lam + delta * ln.dlam
    ln.g = ln.g + delta * ln.dg
    ln.c = ln.c + delta * ln.dc
    if ln.inputs is not None:  # (its values are new arrays)
        ln.inputs = native.OrdinaryStep.moved(ln.inputs, ln.c, ln.g)
    if ln._Y is not None:
        ln._Y = (ln._Y[0] + delta * ln._Y[1], ln._Y[1])


def _ordinary_transition(ctx: _Context, path, branch, ln: _Line, s: int, alpha_from: float):
    """What :func:`_exit` and :func:`_transition_point` give for an ordinary transition (a single
    constraint vanishes, its facet is decided by its own indicators, the next branch is entered by
    that constraint with a rate and no other of its constraints vanishes there), from one
    compiled call: (alpha*, tied, (line, d, transition)) -- or (None, None) where the path ends
    before the end of the range; None for anything else (the general form then decides)."""
    status, r = ctx.data.ordinary_step(ln, s, alpha_from, ctx.hi if s > 0 else ctx.lo, ctx.rtol, ctx._kinds,
                                       ctx._lines)
    if status == 1:
        return None, None
    if status:
        return None
    a_star, a_err, j, node, ind, e, d, nxt = r
    a_root = a_star
    ctx.stats["pivots"] += 1
    if len(ctx._lines) > 64:  # (cached as Context.line caches it)
        ctx._lines.clear()
    ctx._lines[(nxt.codes.tobytes(), a_star)] = nxt
    # the point from the more precise side, as _transition_point takes it
    de = float(nxt.dc[e])
    delta = -float(nxt.c[e]) / de
    if (float(nxt.tol_v[e]) / abs(de) < a_err and abs(delta) <= 2.0 * a_err
            and s * (a_star + delta - alpha_from) >= 0 and ctx.lo <= a_star + delta <= ctx.hi):
        ctx._lines.pop((nxt.codes.tobytes(), a_star), None)
        _shift(nxt, delta)
        a_star = nxt.alpha
    old, new = int(ln.codes[node]), int(nxt.codes[node])  # (the one node that changes: _changes' record)
    changes = [{"node": node, "set": _set_name(old, new), "from": STATE_NAMES[old], "to": STATE_NAMES[new]}]
    tr = Transition(len(path.transitions), a_star, "transversal" if d == s else "fold", changes[0]["node"],
                    changes[0]["set"], branch.index, len(path.branches), bracket=(a_star, a_star), changes=changes,
                    pivots=[])
    return a_root, np.array([j]), (nxt, d, tr)


def _transition_point(ctx: _Context, path, branch, ln: _Line, s: int, a_star: float, tied, a_err: float,
                      alpha_from: float, start_key=None):
    """Decide the continuation at the transition point a_star (uncertainty a_err, reached on ln from
    alpha_from).  Returns (line, d, transition), or a status ("stuck") after recording an event.

    The point itself is taken from the more precise side: a constraint vanishing there whose rate
    is large locates it better than the one whose root was found on ln (a steep branch entered
    through a flat constraint), so the entry of the new branch is moved onto that root when it
    lies within the first estimate's uncertainty."""
    degenerate = len(tied) > 1
    vanishing = _vanishing(ctx, ln, tied)
    # (the first root near an apex can be a single one)
    apex = _apex_crossing(ctx, path, ln, s, a_star, a_err) if APEX_RULE else None
    if apex is not None:
        nxt, a_star = apex
        ctx.stats["degenerate_points"] += 1
        ctx.stats["max_vanishing"] = max(ctx.stats["max_vanishing"], len(tied))
        changes = _named(_changes(ln, nxt, vanishing))
        return nxt, s, Transition(len(path.transitions), a_star, "transversal", changes[0]["node"], changes[0]["set"],
                                  branch.index, len(path.branches), bracket=(a_star, a_star), changes=changes)
    e = None
    try:
        nxt, d, pivots, e = _resolve(ctx, ln, s, a_star, tied)
    except _Unresolved as exc:
        # the lexicographic rule failed (a singular branch, rounding): the enumeration of small points
        nodes = sorted(set(ln.cnode[tied].tolist()))
        conts = _enumerated_continuations(ctx, ln, s, a_star, nodes) if len(nodes) <= ENUMERATION_CHECK_NODES else []
        if not conts:
            kind = "dead_end" if exc.kind in ("singular", "cycling") else "degenerate"
            path.events.append(PathEvent(kind, a_star, f"the transition point could not be crossed: {exc}",
                                         branch.index, jsonable({"vanishing": vanishing, "reason": exc.kind,
                                                                 **exc.data})))
            return "stuck"
        conts.sort(key=lambda cd: 0 if cd[1] == s else 1)
        nxt, d = conts[0]
        pivots = []
    if len(pivots) > 1:
        degenerate = True
    de = float(nxt.dc[e]) if e is not None else 0.0
    if de != 0.0:  # (a constraint with no rate -- an exact tie for the whole branch -- locates nothing)
        delta = -float(nxt.c[e]) / de
        if (float(nxt.tol_v[e]) / abs(de) < a_err and abs(delta) <= 2.0 * a_err
                and s * (a_star + delta - alpha_from) >= 0 and ctx.lo <= a_star + delta <= ctx.hi):
            ctx._lines.pop((nxt.codes.tobytes(), float(a_star)), None)  # (Context.line's key)
            _shift(nxt, delta)
            a_star = nxt.alpha
    alternatives, choice = [], 0
    if degenerate:
        ctx.stats["degenerate_points"] += 1
        ctx.stats["max_vanishing"] = max(ctx.stats["max_vanishing"], len(tied))
        alternatives = _alternatives(ctx, ln, s, a_star, tied, nxt, d, pivots)
        choice = _untraversed(ctx, alternatives, start_key)
        if choice:
            ctx.stats["revisited_vertices"] += 1
            nxt, d = alternatives[choice]
    kind = "transversal" if d == s else "fold"
    changes = _changes(ln, nxt, vanishing)
    tr = Transition(len(path.transitions), a_star, kind, changes[0]["node"], changes[0]["set"], branch.index,
                    len(path.branches), bracket=(a_star, a_star), changes=changes,
                    pivots=[dict(p) for p in pivots] if degenerate else [])
    if len(alternatives) > 1:
        ctx.stats["branch_points"] += 1
        alts = [{"sets": c.sets.to_dict(), "states": c.sets.states(), "orientation": int(dd),
                 "kind": "transversal" if dd == s else "fold", "alpha": a_star, "chosen": k == choice}
                for k, (c, dd) in enumerate(alternatives)]
        which = ("the one of the lexicographic rule" if not choice else
                 f"alternative {choice}: the rule's own, alternative 0, is a branch the path has traversed "
                 f"(this point is a vertex it reaches a second time)")
        path.events.append(PathEvent("branch_point", a_star, f"{len(alternatives)} branches leave the transition "
                                     f"point; following {which} (see data['alternatives'], "
                                     f"follow_alternative)", branch.index,
                                     {"alternatives": alts, "transition": tr.index, "vanishing": vanishing}))
    return nxt, d, tr


#: A vertex reached a second time (:func:`_revisited_vertex`) is located to within this many times
#: the distance in alpha between its two crossings.  (On Part C's m = 1000 strip at F = 30 the
#: untraversed continuation missed the vertex by 1.01 times that distance: a distance is an
#: estimate of the uncertainty, not a bound.)
REVISIT_SLACK = 2.0


def _revisited_vertex(ctx, path, ln, s, a_star, tr, nxt, d, start_key, vanishing=()):
    """(line, d, transition) leaving the transition point a_star of (ln, s) by a branch the path
    has not traversed, where the rule's continuation ``nxt`` is one it has; or None.

    This is a vertex where more than two branches meet, reached a second time after a loop of
    branches, whose first crossing looked like an ordinary transition: nxt was entered there
    through another node's condition (the constraints of both nodes vanish at the vertex, their
    roots a little apart in rounding).  The continuations are those of the nodes of both
    crossings (and those whose constraints vanish there), each node in every state its indicators
    admit there, and the alternatives recorded where the first crossing was a branch point; those
    whose constraints hold on an open alpha interval from the vertex -- to within the vertex's own
    uncertainty, twice the distance in alpha between its two crossings times each rate -- are kept,
    the branches traversed excluded; the first is taken, the rule's orientation preferred."""
    codes = nxt.codes
    first = next((b for b in reversed(path.branches) if b.origin is not None  # (each set is entered once;
                  and np.array_equal(_canon(ctx.system, b.sets), codes)), None)    # loops are short: from the end)
    nodes = {int(c["node"]) for c in tr.changes if int(c["node"]) >= 0} | {int(i) for i in vanishing}
    if first is not None:
        nodes |= {int(c["node"]) for c in path.transitions[first.origin].changes if int(c["node"]) >= 0}
    nodes = sorted(nodes)
    if not nodes or len(nodes) > ENUMERATION_CHECK_NODES:
        return None
    # the vertex's position in alpha is known to about the distance between its two crossings: a
    # candidate's constraints may miss it by that much (times REVISIT_SLACK), times their rates
    a_tol = REVISIT_SLACK * abs(a_star - first.alpha_enter) if first is not None else 0.0
    # the alternatives recorded where the first crossing was a branch point
    extra = [_canon(ctx.system, InactiveSets.from_dict(a["sets"])) for ev in path.events
             if first is not None and ev.kind == "branch_point" and ev.data.get("transition") == first.origin
             for a in ev.data.get("alternatives", [])]

    def untraversed(codes, dd):  # (dd=None: in some orientation)
        key = _digest(codes.tobytes())
        return key not in ctx.visited or (key == start_key[0] if dd is None else (key, dd) == start_key)

    conts = _enumerated_continuations(ctx, ln, s, a_star, nodes, a_tol, extra, admit=untraversed)
    if not conts and first is not None:
        # the two crossings can lie closer together than the vertex is known: widen by how far
        # rounding can move the roots of the first crossing on the branch it was made from
        wide = REVISIT_SLACK * (abs(a_star - first.alpha_enter) + 2.0 * _crossing_uncertainty(ctx, path, first, nodes))
        if wide > a_tol:
            a_tol = wide
            conts = _enumerated_continuations(ctx, ln, s, a_star, nodes, a_tol, extra, admit=untraversed)
    if not conts:
        return None
    conts.sort(key=lambda cd: cd[1] != d)  # (stable: the enumeration's order otherwise)
    c, dd = conts[0]
    ctx.stats["revisited_vertices"] += 1
    changes = _changes(ln, c, [])
    new = Transition(tr.index, a_star, "transversal" if dd == s else "fold", changes[0]["node"], None,
                     tr.from_branch, tr.to_branch, bracket=tr.bracket, changes=changes, pivots=list(tr.pivots))
    path.events.append(PathEvent("branch_point", a_star, f"a vertex reached a second time: the continuation "
                                 f"of the rule enters branch {first.index if first is not None else '?'} again; "
                                 f"following an untraversed branch of nodes {nodes} (see data['alternatives'], "
                                 f"follow_alternative)", tr.from_branch, jsonable(
                                     {"alternatives": [{"sets": x.sets.to_dict(), "states": x.sets.states(),
                                                        "orientation": int(dx), "kind": "transversal" if dx == s
                                                        else "fold", "alpha": a_star, "chosen": x is c}
                                                       for x, dx in conts],
                                      "transition": tr.index, "revisited": True, "nodes": nodes})))
    return c, dd, new


def _crossing_uncertainty(ctx, path, first, nodes) -> float:
    """How far in alpha rounding can move the roots of the constraints of ``nodes`` that vanish
    at the crossing where branch ``first`` was entered, measured on the branch it was entered
    from: each root's value tolerance over its rate, the largest among the roots that lie within
    twice their own uncertainty of the crossing (0 when there is no such branch or root).

    On an open node near a slender strip's free end a gap's tolerance over its rate is some 1e-8
    in alpha, while the two crossings of a vertex reached a second time were 2.6e-9 apart: the
    untraversed branch from there missed the vertex by 4 times that distance (Part D's m = 1000
    strip at F = 30, a homotopy moving one node's data: "cycling" after 102 069 transitions)."""
    if first.parent is None:
        return 0.0
    parent = path.branches[first.parent]
    try:
        pl = ctx.line(_canon(ctx.system, parent.sets), first.alpha_enter)
    except SingularSystemError:
        return 0.0
    rate = np.abs(pl.dc)
    k = np.isin(pl.cnode, nodes) & (rate > pl.tol_s)
    unc = pl.tol_v[k] / rate[k]
    near = np.abs(pl.c[k]) / rate[k] <= 2.0 * unc
    return float(unc[near].max(initial=0.0))


def _untraversed(ctx, alternatives, start_key) -> int:
    """The alternative to follow at a branch point: the rule's own (0) unless the path has already
    traversed its branch and another alternative's branch is new.  A path through a vertex where
    more than two branches meet may come back to it (a loop of branches from the vertex to itself);
    it must then leave by a branch it has not traversed, as a walk through a graph's vertex of
    degree four leaves by the edges it has not used.  Entering a traversed branch instead is what
    "cycling" reports.  The path's first branch in its first orientation is not avoided: returning
    to it is a closed curve of solutions ("closed_loop")."""
    def seen(k):
        c, dd = alternatives[k]
        key = _digest(c.codes.tobytes())
        return key in ctx.visited and (key, dd) != start_key

    if not seen(0):
        return 0
    return next((k for k in range(1, len(alternatives)) if not seen(k)), 0)


def _alternatives(ctx, ln, s, a_star, tied, nxt, d, pivots) -> list:
    """[(line, d)] of every continuation found at a degenerate point, the rule's own first."""
    out = [(nxt, d)]

    def add(c, dd):
        # an alternative must hold on its own, at the precision of its own line (an order of two
        # roots that only the perturbation decided is no second branch)
        ok = _directions(c)[0 if dd > 0 else 1]
        if ok and not any(dd == d2 and _same_line(c, o) for o, d2 in out):
            out.append((c, dd))

    # the opposite perturbation pairs the rays of the point differently; it applies when no
    # constraint of ln vanishes identically along it (those are positive only under +eps), and is
    # tried at points of at most ALTERNATIVES_MAX_NODES nodes (it costs as much as the point)
    vals = ln.values(a_star)
    zero = np.abs(vals) <= ln.tol_v + abs(a_star - ln.alpha) * ln.tol_s
    zero[tied] = False
    crossed = {p["node"] for p in pivots}
    if not zero.any() and len(crossed) <= ALTERNATIVES_MAX_NODES:
        try:
            c2, d2, _, _ = _resolve(ctx, ln, s, a_star, tied, sign=-1)
            add(c2, d2)
        except _Unresolved:
            pass
    # the nodes of the point: those crossed by the rule, and those with a constraint that still
    # vanishes on the branch it leaves by (nodes tied on ln only within ln's coarser precision are
    # separate, later transitions)
    zero_exit = np.abs(nxt.c) <= nxt.tol_v
    nodes = sorted({p["node"] for p in pivots} | set(nxt.cnode[zero_exit].tolist()))
    if len(nodes) <= ENUMERATION_CHECK_NODES:
        for c, dd in _enumerated_continuations(ctx, ln, s, a_star, nodes):
            add(c, dd)
    return out


class _Walk:
    """Following the path from one branch on, one transition per :meth:`step`, appending to a path.

    State (always current, see :meth:`state`): the branch ``ln`` followed in direction ``s`` since
    ``alpha`` (its entry), its index in the path, the transition count the cap counts from, and the
    branches entered so far (``ctx.visited``)."""

    #: how the transitions are logged: the parameter's name and the logging level (a homotopy start
    #: logs its own parameter t, at DEBUG: its transitions are not the path's)
    parameter, log_level = "alpha", logging.INFO

    def __init__(self, ctx: _Context, path: SolutionPath, ln: _Line, s: int, alpha: float, branch,
                 n_trans0: int, start_key):
        self.ctx, self.path, self.ln, self.s, self.alpha, self.branch = ctx, path, ln, s, alpha, branch
        self.n_trans0, self.start_key = n_trans0, start_key
        self._digested = (None, None)

    @classmethod
    def begin(cls, ctx, path, ln, s, alpha, parent=None, origin=None):
        """A walk entering (ln, s) at alpha: the branch and its entry point are added to the path."""
        branch = _add_branch(path, ln, s, origin=origin, parent=parent, alpha_enter=alpha)
        path.add_point(branch, alpha)
        return cls(ctx, path, ln, s, alpha, branch, len(path.transitions), (_digest(ln.codes.tobytes()), s))

    def state(self) -> dict:
        """What continues the walk (JSON): the branch being followed (its index, canonical state
        codes, orientation, entry alpha -- its entry point is stored in the path), the transition
        count the max_transitions cap counts from, and the branches entered so far."""
        ln = self.ln
        return {"branch": int(self.branch.index), "codes": [int(c) for c in ln.codes], "states": ln.sets.states(),
                "orientation": int(self.s), "alpha": float(self.alpha), "transitions0": int(self.n_trans0),
                "visited": [[k.hex(), int(v[0]), float(v[1])] for k, v in self.ctx.visited.items()]}

    def step(self):
        """("point", index) of the next branch's entry point, ("end", index) of the point where the
        path leaves the alpha range, or ("status", status) when the walk cannot go on."""
        ctx, path, ln, s, branch = self.ctx, self.path, self.ln, self.s, self.branch
        known = self._digested  # (the digest of the branch entered last, when it is ln)
        ctx.visited.setdefault(known[1] if known[0] is ln else _digest(ln.codes.tobytes()), (s, self.alpha))
        fast = (_ordinary_transition(ctx, path, branch, ln, s, self.alpha)
                if ctx.fast and len(path.transitions) - self.n_trans0 < ctx.opts.max_transitions else None)
        if fast is None:
            a_star, tied, a_err = _exit(ctx, ln, self.alpha, s)
        else:
            a_star, tied = fast[:2]
        if a_star is None:
            a_end = ctx.hi if s > 0 else ctx.lo
            branch.alpha_exit = a_end
            if a_end != self.alpha:
                # the end point from a solve of its own, not extrapolated from the entry: where the
                # path ends at a small load (an unloading to f = 0) the entry's rounding would be
                # all there is of the solution there
                end = ctx.line(ln.codes, a_end)
                path.end_branch_at(branch, a_end, end.lam, end.g, y=lambda: end.Y()[0])
            return "end", path.add_point(branch, a_end)
        limit = ctx.opts.max_transitions
        if len(path.transitions) - self.n_trans0 >= limit:
            branch.alpha_exit = a_star
            path.add_point(branch, a_star)
            path.events.append(PathEvent("max_transitions", a_star, f"transition cap {limit} reached (raise "
                                         f"max_transitions to trace further)", branch.index))
            return "status", "max_transitions"
        at = ln
        if fast is not None:
            nxt, d, tr = fast[2]
        else:
            if len(tied) > 1:
                at, a_star, tied, a_err = _recenter(ctx, ln, s, a_star, self.alpha)
                if not tied.size:  # nothing vanishes when looked at closely: go on (rare)
                    at, a_star, tied, a_err = ln, a_star, tied, a_err
            res = _transition_point(ctx, path, branch, at, s, a_star, tied, a_err, self.alpha, self.start_key)
            if isinstance(res, str):
                branch.alpha_exit = a_star
                path.add_point(branch, a_star)
                return "status", res
            nxt, d, tr = res
        a_star = tr.alpha
        key = _digest(nxt.codes.tobytes())
        if key in ctx.visited and (key, d) != self.start_key:
            other = _revisited_vertex(ctx, path, ln, s, a_star, tr, nxt, d, self.start_key, at.cnode[tied])
            if other is not None:
                nxt, d, tr = other
                key = _digest(nxt.codes.tobytes())
        branch.alpha_exit = a_star
        exit_, entry = _meeting_point(ctx, ln, nxt, a_star)
        if exit_ is not None:
            path.end_branch_at(branch, a_star, *exit_)
        path.add_point(branch, a_star)
        seen = ctx.visited.get(key)
        if seen is not None:
            closed = (key, d) == self.start_key
            kind = "closed_loop" if closed else "cycling"
            msg = ("the path returns to its first branch: its solutions form a closed curve" if closed else
                   f"branch {nxt.sets} is entered a second time (first at alpha={seen[1]!r}): a numerical "
                   f"inconsistency")
            path.events.append(PathEvent(kind, a_star, msg, branch.index, jsonable(
                {"sets": nxt.sets.to_dict(), "orientation": d, "first_orientation": seen[0], "first_alpha": seen[1],
                 "transition": tr.to_dict()})))
            return "status", kind
        path.transitions.append(tr)
        log.log(self.log_level, "%s=%.12g %s transition: %s", self.parameter, a_star, tr.kind, tr.changes)
        self.branch = _add_branch(path, nxt, d, origin=tr.index, parent=branch.index, alpha_enter=a_star)
        if entry is not None:
            path.start_branch_at(self.branch, a_star, *entry)
        self.ln, self.s, self.alpha = nxt, d, a_star
        self._digested = (nxt, key)
        return "point", path.add_point(self.branch, a_star)

    def point(self, index) -> PathPoint:
        path, sets, system = self.path, self.ln.sets, self.ctx.system
        return PathPoint(index, path._alphas[index], self.branch.index, path=path,
                         make=lambda: Solution.from_y(system, path._ys[index], path._alphas[index], sets=sets))

    def run(self, callback=None) -> str:
        """Step to the end (or until ``callback`` stops the walk: "stopped by callback")."""
        if callback is not None and callback(self.point(len(self.path._alphas) - 1)):
            return "stopped by callback"
        while True:
            what, value = self.step()
            if what == "status":
                return value
            if callback is not None and callback(self.point(value)) and what == "point":
                return "stopped by callback"
            if what == "end":
                return "completed"


class ExactStepper(Stepper):
    """One run of the exact method (see :class:`cfcontact.stepper.Stepper`): one transition per
    accepted point; its resume state is always current, so a checkpoint is a save.

    ``resume``: ``{"path": SolutionPath, "state": resume state}`` of a stopped or checkpointed run
    (the path possibly saved and loaded); new points are appended to that path.  ``monitor``: sees
    the progress of a homotopy start (run by the constructor) and can abandon it, see
    :func:`trace_exact`."""

    method = "exact"

    def __init__(self, system, span: AlphaSpan, options: PathOptions, solver=None, y0=None, resume=None,
                 start_sets: Optional[InactiveSets] = None, orientation: Optional[int] = None, monitor=None):
        check_monitor(monitor)
        self.system, self.span, self.opts = system, span, options
        self.solver = solver if solver is not None else select_solver(system, "exact")
        self.start = None
        if resume is None:
            self._start_clock()
            self.ctx = _Context(system, self.solver, options, span.lo, span.hi, float(options.tie_rtol))
            self.path = SolutionPath.for_system(system, "exact", span.start, span.end, options.to_dict())
            s = span.direction if orientation is None else orientation
            if isinstance(s, (bool, np.bool_)) or s not in (1, -1):
                raise InputError(f"orientation must be +1 or -1, got {orientation!r}")
            ln, s, self.start = _start(self.ctx, self.path, span.start, int(s), y0, start_sets, monitor)
            self.walk = _Walk.begin(self.ctx, self.path, ln, s, span.start)
            self._pending_point = 0  # the start point is the first accepted point
        else:
            path, state = resume_parts(system, span.start, span.end, resume, "exact")
            try:
                branch = path.branches[int(state["branch"])]
                codes = np.asarray(state["codes"], dtype=np.int8)
                s, alpha, n_trans0 = int(state["orientation"]), float(state["alpha"]), int(state["transitions0"])
                visited = {bytes.fromhex(k): (int(sg), float(a)) for k, sg, a in state["visited"]}
            except (KeyError, IndexError, TypeError, ValueError) as exc:
                raise InputError(f"cannot resume: incomplete or invalid resume state ({exc!r})") from None
            if codes.shape != (system.m,) or branch.orientation != s or branch.alpha_enter != alpha \
                    or not np.array_equal(_canon(system, branch.sets), codes):
                raise InputError(f"cannot resume: the resume state does not match branch {branch.index} of the path")
            tie_rtol = path.options.get("tie_rtol", TIE_RTOL)  # the path's
            if tie_rtol != options.tie_rtol:
                self.opts = options = PathOptions.with_overrides(options, tie_rtol=tie_rtol)
            self._start_clock(path.stats)
            self.start = path.stats.get("start")
            self.ctx = _Context(system, self.solver, options, span.lo, span.hi, float(options.tie_rtol))
            for k in self.ctx.stats:
                self.ctx.stats[k] = int(path.stats.get(k, 0))
            self.ctx.visited = visited
            self.path = path
            first = path.branches[0]
            start_key = (_digest(_canon(system, first.sets).tobytes()), first.orientation)
            self.walk = _Walk(self.ctx, path, self.ctx.line(codes, alpha), s, alpha, branch, n_trans0, start_key)
            path.status, path.resume_state = "running", None
            branch.alpha_exit = float("nan")

    # ------------------------------------------------------------- stepper interface
    @property
    def resume_state(self) -> dict:
        return self.walk.state()

    def point(self, index: int) -> PathPoint:
        return self.walk.point(index)

    def stop(self) -> SolutionPath:
        if self.done:  # the point was the end of the path
            return self._finish("completed")
        self.walk.branch.alpha_exit = self.walk.alpha
        return self._finish("stopped by callback")

    def _update_stats(self):
        super()._update_stats()
        for k, v in self.ctx.stats.items():
            self.path.stats[k] = v
        if self.start is not None:
            self.path.stats["start"] = self.start

    def _finish(self, status) -> SolutionPath:
        self.finished = True
        path = self.path
        tree = self.opts.tree and status in ("completed", "closed_loop", "stuck", "cycling")
        stop = stop_only(self.callback)  # the run's callback stops the tree and the tries, too
        if tree:
            _follow_all(self.system, path, self.opts, self.solver, stop)
        if status in BACKTRACK_FROM:
            status = _backtrack(self.system, path, self.opts, self.solver, status, stop)
        if path.lazy and getattr(self.solver, "size", 1) > 1:
            _form_under_mpi(path, self.solver)
        path.status = status
        self._update_stats()
        if tree:
            path.stats["tree"] = True
            stopped = [e for e in path.events if e.kind == "tree_stopped"]
            if stopped:
                path.stats["untried_alternatives"] = stopped[-1].data["untried"]
        backtracks = sum(1 for e in path.events if e.kind == "backtrack")
        if backtracks:
            path.stats["backtracks"] = backtracks
        path.resume_state = self.walk.state() if status == "stopped by callback" else None
        log.info("exact path: %s", path)
        return path

    def _step(self) -> Optional[int]:
        what, value = self.walk.step()
        if what == "status":
            self._finish(value)
            return None
        if what == "end":
            self.done = True
        return value


def _form_under_mpi(path, solver):
    """Under MPI, form the path's displacements at the end of the run (collective), so that a later
    use on one rank only (saving, plotting) cannot hang -- as long as they fit FORM_AT_END_LIMIT
    doubles per rank.  A larger path stays lazy (at n ~ 1e6 and 1700 branches u would take 14 GB
    per rank): every rank must then use it alike (save, points, iter_points are collective)."""
    n_local = int(getattr(solver, "nloc", path.n)) if solver is not None else path.n
    pending = len(getattr(path, "_pending", ()))
    if 2 * pending * (n_local + 2 * path.m) <= FORM_AT_END_LIMIT:
        path.form()
    else:
        log.info("the path's displacements stay lazy under MPI (%d branches, %d local DOFs): save, points and "
                 "iter_points are collective (call them on every rank)", pending, n_local)


# ---------------------------------------------------------------------- start
def _not_a_solution(ln) -> bool:
    """Does a branch (its constraints' values c at its reference point, their zero tolerance tol_v,
    its indicators g) violate a constraint there beyond rounding (and 1e-8 of its indicators)?  Its
    states are then no solution at that point."""
    return bool(np.any(ln.c < -np.maximum(ln.tol_v, 1e-8 * np.abs(ln.g).max(initial=0.0))))


def _ssnm_start(ctx: _Context, alpha, y0):
    """Sets of SSNM's solution at alpha, or None when SSNM does not converge.  With the condensed
    backend SSNM gets at most START_SSNM_ITERATIONS iterations (it converges in a few when it
    does; at large F it can wander): the homotopy start reaches the solution by rule."""
    system, solver, opts = ctx.system, ctx.solver, ctx.opts
    if y0 is None and hasattr(solver, "ssnm_sets"):
        return solver.ssnm_sets(system.load(alpha), opts.tol, min(opts.max_iter, START_SSNM_ITERATIONS))
    try:
        return start_point(system, alpha, y0, opts, solver).sets
    except ConvergenceError:
        if y0 is not None:
            raise
        return None


def _homotopy_start(ctx: _Context, alpha, monitor=None, n0=0) -> tuple:
    """Sets of a solution at alpha reached by the exact method from data whose only solution is
    every node open (condensed backend only), and the number of transitions it took.

    In the condensed data w (B u = w - S lam), take w_open = (-c, w_t(alpha)): a separating normal
    gap c > max(0, -min w_n, F max|w_t|) with the tangential data held.  For every t <= 0 the data
    (1 - t) w_open + t w(alpha) has the single solution "all open" (an energy argument: lam^T S lam
    <= sum lam_n (w_n + F |w_t|) < 0 unless lam = 0), so the path from t = 0 cannot come back to
    t <= 0 and, its branches being bounded and entered once each, it reaches t = 1.

    ``monitor``: called with a :class:`~cfcontact.StartProgress` after every transition
    of the homotopy (counting from ``n0``: the transitions of an earlier attempt); a truthy answer
    raises :class:`~cfcontact.errors.StartInterrupted`."""
    data, m = ctx.data, ctx.m
    w = (1.0 - alpha) * data.w1 + alpha * data.w2
    Fmax = float(ctx.Fv.max(initial=0.0))
    scale = max(np.abs(w).max(initial=0.0), 1e-300)
    c = 1.1 * max(0.0, -float(w[:m].min(initial=0.0)), Fmax * float(np.abs(w[m:]).max(initial=0.0))) + scale
    w_open = np.concatenate([np.full(m, -c), w[m:]])
    return _homotopy(ctx, alpha, w_open, w, np.zeros(m, dtype=np.int8), "homotopy", monitor, n0)


def _frictionless_start(ctx: _Context, alpha, monitor=None) -> tuple:
    """Sets of a solution at alpha reached by the exact method from the frictionless solution, and
    the number of transitions it took; (None, transitions) when this start cannot be had: SSNM
    does not converge on the frictionless problem, or the homotopy does not reach t = 1.

    The frictionless problem (every F = 0) has one solution lam_f (S is positive definite), which
    SSNM finds where friction makes it wander.  With Z_f its closed nodes, the data w_0 = w(alpha)
    with the tangential data of Z_f replaced by (S lam_f)_t -- the tangential gaps at which every
    closed node sticks with lam_t = 0 -- have lam_f as a solution at every F (a sticking node
    needs |lam_t| = 0 <= F lam_n).  The homotopy (1 - t) w_0 + t w(alpha) moves only those
    tangential data; where friction holds most nodes it takes a few transitions (the all-open
    homotopy of :func:`_homotopy_start`, which always ends, can take thousands).  Unlike that one
    it may turn back (a fold: the data near t = 0 can have several solutions); the walk then goes
    on through t < 0 -- the data (1 - t) w_0 + t w(alpha) are contact data there too -- where it can
    turn again and reach t = 1 (the strip of 60 x 1 at F = 30 of the tests: one fold back at
    t = 0.13, t = 1 after 100 transitions, where the all-open homotopy wanders for more than 10^5).
    It fails when it leaves to t = FRICTIONLESS_T_MIN or ends otherwise."""
    m, solver = ctx.m, ctx.solver
    if not ctx.condensed or not (ctx.Fv > 0.0).any() or not hasattr(solver, "frictionless_solution"):
        return None, 0
    w = (1.0 - alpha) * ctx.data.w1 + alpha * ctx.data.w2
    sol = solver.frictionless_solution(w, ctx.opts.tol, START_SSNM_ITERATIONS)
    if sol is None:
        return None, 0
    lam, Z = sol
    closed = (~Z.nu).nonzero()[0]
    w0 = w.copy()
    w0[m + closed] = solver.S[m + closed] @ lam
    codes = _canon(ctx.system, sets_from_codes(np.where(~Z.nu, STICK, OPEN)))
    return _homotopy(ctx, alpha, w0, w, codes, "frictionless", monitor, t_min=FRICTIONLESS_T_MIN)


def _homotopy(ctx: _Context, alpha, w0, w, codes, stage, monitor=None, n0=0, t_min=0.0) -> tuple:
    """(sets, transitions) of the exact method's walk in t from the solution of state ``codes`` of
    the data w0 at t = 0 to the data w = w(alpha) at t = 1, within t >= t_min; sets = None when the
    walk does not reach t = 1 (it turns back to t_min, or ends otherwise), or the state is no
    solution at t = 0.  ``stage``: the name the monitor sees, with the transitions counted from
    ``n0`` (see :func:`_homotopy_start`)."""
    data = ctx.data
    # the path's own transition cap does not bound its start (the homotopy ends: each branch once)
    hopts = PathOptions.with_overrides(ctx.opts, alpha_min=None, alpha_max=None,
                                       max_transitions=max(int(ctx.opts.max_transitions), HOMOTOPY_MAX_TRANSITIONS))
    hctx = _Context(ctx.system, ctx.solver, hopts, t_min, 1.0, ctx.rtol, W=np.column_stack([w0, w]))
    hctx.E, hctx.data.WE = ctx.E, data.WE
    path = SolutionPath.for_system(ctx.system, "exact", 0.0, 1.0, {})
    ln = hctx.line(codes, 0.0)
    if _not_a_solution(ln):
        return None, 0
    ln, s = _leave_start(hctx, path, codes, 0.0, 1)
    walk = _Walk.begin(hctx, path, ln, s, 0.0)
    walk.parameter, walk.log_level = "homotopy t", logging.DEBUG
    t0 = time.perf_counter()
    seen = []
    kept = [0]

    def watch(point):
        # only the walk's current branch and the one before are read again: the others' values go
        # (a homotopy can take 10^5 transitions, 10 m doubles each)
        for b in range(kept[0], point.branch - 1):
            path.drop_branch_values(b)
        kept[0] = max(kept[0], point.branch - 1)
        if monitor is None:
            return False
        seen[:] = [StartProgress(stage, n0 + len(path.transitions), float(point.alpha), time.perf_counter() - t0)]
        return monitor(seen[0])

    status = walk.run(watch)
    if status == "stopped by callback":
        prog = seen[0]
        raise StartInterrupted(f"the start at alpha={alpha:g} was abandoned by the monitor after {prog.transitions} "
                               f"transition(s) of its homotopy (t = {prog.t:.6g} of 1, {prog.elapsed:.3g} s)", prog)
    for k in ("degenerate_points", "pivots", "perturbation_solves", "point_updates", "tableau_updates"):
        ctx.stats[k] += hctx.stats[k]
    ctx.E, data.WE = hctx.E, hctx.data.WE
    if status != "completed" or walk.s != 1:
        return None, len(path.transitions)
    return walk.ln.sets, len(path.transitions)


def _start(ctx: _Context, path, alpha, s, y0, start_sets, monitor=None):
    """(line, orientation, how) of the start: the branch of the start solution's sets leaving alpha
    in direction s (see :func:`_leave_start`); how = "start_sets", "ssnm", "frictionless",
    "ssnm_rho", "homotopy", "enumeration" or "apex" (:func:`_apex_start`)."""
    system = ctx.system
    if start_sets is not None:
        if not isinstance(start_sets, InactiveSets) or start_sets.m != system.m:
            raise InputError(f"start_sets must be InactiveSets of length m = {system.m}, got {start_sets!r}")
        codes = _canon(system, start_sets)
        ln = ctx.line(codes, alpha)
        if _not_a_solution(ln):
            raise InputError(f"start_sets {start_sets} are not consistent at alpha_start={alpha}: "
                             f"DirNeu(start_sets, f(alpha_start)) is not a solution")
        how = "start_sets"
    else:
        if y0 is None and _is_apex(ctx, alpha):
            ln = _apex_start(ctx, path, alpha, s, monitor)
            if ln is not None:
                return ln, s, "apex"
        start_sets, how = _ssnm_start(ctx, alpha, y0), "ssnm"
        if start_sets is None:
            start_sets, how, _ = reach_start(system, alpha, path, ctx.opts, monitor, ctx)
        codes = _canon(system, start_sets)
    ln, s = _leave_start(ctx, path, codes, alpha, s)
    return ln, s, how


def affine_zero(v1, v2) -> Optional[float]:
    """The alpha where (1 - alpha) v1 + alpha v2 vanishes (its least-squares zero, to APEX_ULPS of
    the larger end's rounding), or None: the apex of affine contact data or loads."""
    d = v2 - v1
    dd = float(d @ d)
    if dd == 0.0:
        return None
    a = -float(v1 @ d) / dd
    scale = max(np.abs(v1).max(initial=0.0), np.abs(v2).max(initial=0.0))
    return a if np.abs(v1 + a * d).max(initial=0.0) <= APEX_ULPS * np.finfo(float).eps * scale else None


def _is_apex(ctx: _Context, alpha) -> bool:
    """Do the contact data vanish at alpha (APEX_ULPS)?  Condensed backend: w(alpha) = B K^-1 f(alpha)
    - (g; 0); full backend: f(alpha) and the gap."""
    eps = np.finfo(float).eps
    if ctx.condensed:
        w1, w2 = ctx.data.w1, ctx.data.w2
    else:
        if np.any(np.asarray(ctx.system.gap) != 0.0):
            return False
        w1, w2 = ctx.f1, ctx.f2
    scale = max(np.abs(w1).max(initial=0.0), np.abs(w2).max(initial=0.0))
    w = (1.0 - alpha) * w1 + alpha * w2
    return scale > 0.0 and float(np.abs(w).max(initial=0.0)) <= APEX_ULPS * eps * scale


def _apex_crossing(ctx: _Context, path, ln: _Line, s, a_star, a_err) -> Optional[tuple]:
    """(line, alpha) of the branch leaving an apex that the path reaches at a_star (a load reversed
    through zero with no gap open: every multiplier and indicator vanishes there), or None.

    As at an apex start (:func:`_apex_start`), the problem beyond it is positively homogeneous, so
    the sets of a solution at alpha + s give the ray that leaves it; the lexicographic rule would
    order all 3m constraints on the rounding of the data (several transitions at one alpha, or a
    dead end at large F)."""
    data = ctx.data
    alpha = data.apex if ctx.condensed else None
    if alpha is None or abs(alpha - a_star) > max(a_err, ALPHA_ULPS * _alpha_ulp(a_star),
                                                  APEX_RTOL * data.w_scale / data.dw_max):
        return None
    nxt = _apex_start(ctx, path, alpha, s, event=False)
    if nxt is None or np.array_equal(nxt.codes, ln.codes):
        return None
    return nxt, alpha


def _named(changes) -> list:
    """``changes`` (:func:`_changes`) with a set for each: where no vanishing constraint named it,
    :func:`_set_name` of its states."""
    return [ch if ch.get("set") is not None else
            {**ch, "set": _set_name(STATE_NAMES.index(ch["from"]), STATE_NAMES.index(ch["to"]))} for ch in changes]


def _apex_start(ctx: _Context, path, alpha, s, monitor=None, event=True) -> Optional[_Line]:
    """The branch leaving an apex (see APEX_ULPS) in direction s, or None when it cannot be had.

    At an apex every multiplier and every indicator vanishes, so the lexicographic rule would have
    to order all 3m constraints at once (at large F it can return to a branch it crossed: a dead
    end).  It needs no rule: the data are (alpha - alpha_start) (w2 - w1), so a solution's sets at
    alpha_start + s (found by SSNM, or by the exact method's homotopies) are those of a ray
    lam(alpha) = |alpha - alpha_start| lam(alpha_start + s) that solves the problem for every
    alpha beyond alpha_start in direction s.  Its branch is checked (no constraint decreasing) and
    referenced at the apex with the values the ray has there: zero.  Where several solutions exist
    at alpha_start + s, each is such a ray from the apex; the path follows the one found (an event
    says so)."""
    probe = alpha + s
    sets = _ssnm_start(ctx, probe, None)
    how = "ssnm"
    if sets is None:
        try:
            sets, how, _ = reach_start(ctx.system, probe, path, ctx.opts, monitor, ctx)
        except ConvergenceError:
            return None
    ln = ctx.line(_canon(ctx.system, sets), alpha)
    if np.any(s * ln.dc < -ln.tol_s):
        return None
    # at the apex the solution is zero: its values there are the rounding of data that vanish (at an
    # alpha that is itself rounded, of the size of the rates times an ulp); the branch is the ray
    ctx._lines.pop((ln.codes.tobytes(), float(alpha)), None)  # (Context.line's key)
    ln.lam, ln.g, ln.c = np.zeros_like(ln.lam), np.zeros_like(ln.g), np.zeros_like(ln.c)
    ln.inputs = None
    if not event:
        return ln
    path.events.append(PathEvent(
        "apex_start", alpha, f"the data vanish at alpha_start = {alpha:g} (no load on the contact, no gap): the "
        f"solution there is zero and the path leaves it on the ray of the solution found at alpha = {probe:g} "
        f"(by {how}); other solutions there, if any, are other rays from the same point", None,
        {"probe_alpha": probe, "found_by": how}))
    log.info("alpha_start=%g is an apex (zero data); leaving it on the ray of the solution at alpha=%g", alpha, probe)
    return ln


def reach_start(system, alpha, path, options: Optional[PathOptions] = None, monitor=None, ctx=None) -> tuple:
    """(sets, how, transitions) of a solution at alpha where SSNM did not converge, reached by the
    exact method in the condensed multipliers (:func:`_reach_start`: from the frictionless solution,
    how = "frictionless", else by SSNM with another rho, "ssnm_rho", else from the all-open state,
    "homotopy"; ``transitions``: the homotopies'), else -- a numerical failure of all of these, on a
    small problem -- by enumeration ("enumeration", an event on ``path``).  ``ctx``: the calling run's context; when its backend
    is not the condensed one (the full PETSc backend, the seed method's), the system's condensed
    solver is formed for the start (K factored, S) and the run goes on with its own backend.
    ConvergenceError when nothing is found."""
    from cfcontact.condensed import get_condensed_solver

    opts = options if options is not None else PathOptions()
    rctx = ctx
    if rctx is None or not rctx.condensed:
        rctx = _Context(system, get_condensed_solver(system), opts, 0.0, 1.0, float(opts.tie_rtol))
    sets, how, transitions = _reach_start(rctx, alpha, monitor)
    if ctx is not None:
        if rctx is not ctx:
            for k, v in rctx.stats.items():
                ctx.stats[k] += v
        ctx.stats["homotopy_transitions"] += transitions  # (an apex crossing may add its own)
    if sets is not None:
        if how != "ssnm_rho":
            log.info("SSNM did not converge at alpha_start=%g; the start was reached by the exact method from the "
                     "%s state (%d transitions)", alpha, "frictionless" if how == "frictionless" else "all-open",
                     transitions)
        return sets, how, transitions
    return _enumeration_start(system, alpha, path), "enumeration", transitions


def _reach_start(ctx: _Context, alpha, monitor=None) -> tuple:
    """(sets, how, transitions) of a start at alpha where SSNM did not converge: reached by the
    exact method from the frictionless solution (how = "frictionless"); else SSNM's solution with
    another augmentation parameter (how = "ssnm_rho", :func:`_rho_start`); else reached by the
    exact method from the all-open state (how = "homotopy", which always ends); transitions
    counts both homotopies' (sets None only when the all-open one did not reach t = 1 either, a
    numerical failure)."""
    sets, n = _frictionless_start(ctx, alpha, monitor)
    if sets is not None:
        return sets, "frictionless", n
    sets = _rho_start(ctx, alpha)
    if sets is not None:
        return sets, "ssnm_rho", n
    sets, more = _homotopy_start(ctx, alpha, monitor, n)
    return sets, "homotopy", n + more


def _rho_start(ctx: _Context, alpha):
    """Sets of SSNM's solution at alpha with the augmentation parameter rho times one of
    START_RHO_FACTORS (in the condensed multipliers, START_SSNM_ITERATIONS each), checked as a
    solution at the system's own rho; None when none converges to one (or the backend is not
    the condensed one).

    The solutions of (1)-(3) do not depend on rho, SSNM's convergence does: a strip of 10 x 1, 8
    cells across, m = 500, random loads at F = 30 -- where SSNM cycles, the frictionless homotopy
    is a closed loop back to its start (13 transitions) and the all-open homotopy took more than
    28 000 transitions without reaching t = 1 -- converges in 20 iterations with rho x 100.  It
    comes after the frictionless homotopy (a start by rule, and the one the tests and the
    benchmark's counts have always seen first) and before the all-open one, which always ends
    but can take that long."""
    solver, system = ctx.solver, ctx.system
    if not ctx.condensed or not hasattr(solver, "ssnm_sets"):
        return None
    f = system.load(alpha)
    iters = min(ctx.opts.max_iter, START_SSNM_ITERATIONS)
    for factor in START_RHO_FACTORS:
        sets = solver.ssnm_sets(f, ctx.opts.tol, iters, rho=system.rho * factor)
        if sets is None:
            continue
        codes = _canon(system, sets)
        ln = ctx.line(codes, alpha)
        if _not_a_solution(ln):
            log.info("SSNM with rho x %g converged at alpha=%g to sets that are no solution at the system's rho",
                     factor, alpha)
            continue
        log.info("SSNM did not converge at alpha=%g; with rho x %g it did", alpha, factor)
        return sets
    return None


def _leave_start(ctx: _Context, path, codes, alpha, s):
    """The branch leaving the start point in direction s: the start sets' branch, or -- when
    constraints of it vanish at alpha_start and decrease -- the branch the lexicographic rule
    reaches from it at alpha_start."""
    ln = ctx.line(codes, alpha)
    zero = np.abs(ln.c) <= ln.tol_v
    dec = (zero & (s * ln.dc < -ln.tol_s)).nonzero()[0]
    if not dec.size:
        return ln, s
    try:
        nxt, d, pivots, _ = _resolve(ctx, ln, s, alpha, dec, start=True)
    except _Unresolved as exc:
        path.events.append(PathEvent("start_degenerate", alpha, f"the start point is a degenerate point the "
                                     f"lexicographic rule could not leave ({exc}); starting on the start "
                                     f"solution's own branch", None, jsonable(exc.data)))
        return ln, s
    ctx.stats["start_pivots"] = len(pivots)
    log.info("constraints of the start branch vanish at alpha_start=%g; %d pivot(s) lead to the branch "
             "leaving it: %s", alpha, len(pivots), pivots)
    return nxt, d


def _enumeration_start(system, alpha, path):
    """Start sets from enumeration (small problems), else the ConvergenceError of SSNM."""
    if system.m > START_ENUMERATION_MAX_NODES:
        raise ConvergenceError(f"SSNM did not converge at alpha={alpha} and the start could not be reached "
                               f"otherwise (m = {system.m})")
    from cfcontact.enumerate import enumerate_solutions

    sols = enumerate_solutions(system, alpha, max_nodes=START_ENUMERATION_MAX_NODES)
    if not sols:
        raise ConvergenceError(f"no solution found at alpha={alpha} (SSNM and enumeration)")
    path.events.append(PathEvent(
        "start_by_enumeration", alpha, f"SSNM did not converge at alpha_start; started from the first of "
        f"{len(sols)} solutions found by enumeration (follow the others with start_sets=...)",
        None, {"solutions": [{"sets": x.sets.to_dict(), "states": x.states()} for x in sols]}))
    return sols[0].sets


# ---------------------------------------------------------------------- entry points
def trace_exact(system: ContactSystem, alpha_start: float = 0.0, alpha_end: float = 1.0, y0=None,
                options: Optional[PathOptions] = None, solver=None, tie_rtol: Optional[float] = None,
                start_sets: Optional[InactiveSets] = None, orientation: Optional[int] = None,
                resume=None, callback=None, tree: bool = False, monitor=None) -> SolutionPath:
    """Exact piecewise-affine continuation of the solution path from alpha_start towards alpha_end.

    Parameters
    ----------
    y0 : start solution or guess for SSNM at alpha_start (ignored with ``start_sets``)
    options : PathOptions (alpha_min/alpha_max, max_transitions, tie_rtol, tol/max_iter of the
        start SSNM are used; the step-size options are not)
    solver : DirNeu backend (default: the one :func:`cfcontact.path.trace_path` picks,
        :func:`cfcontact.backend.select_solver`: the
        :class:`~cfcontact.condensed.CondensedSolver`, one factorization of K in total, while its
        dense data fit the machine, else the PETSc :class:`~cfcontact.ssnm.DirNeuSolver`)
    tie_rtol : relative tolerance (on the local size of the indicators, beyond their measured
        rounding error) under which an indicator value or rate counts as zero (overrides
        ``options.tie_rtol``); ties are settled by the lexicographic rule
    start_sets, orientation : start on the branch of these sets (y = DirNeu(start_sets, f(alpha_start)),
        which must be consistent there) with this orientation (default: towards alpha_end)
    resume : continue a run stopped by its callback instead of starting anew: a dict
        ``{"path": SolutionPath, "state": path.resume_state}``.  The result equals an
        uninterrupted run.  The path's ``tie_rtol`` is used; y0, start_sets and orientation are
        ignored.
    callback : called with each accepted :class:`~cfcontact.solution_path.PathPoint` (the start,
        the entry of every branch, the end); a truthy return stops the run
    tree : also follow every alternative of every branch point (see :func:`trace_tree`; the same
        as ``options.tree``)
    monitor : called with a :class:`~cfcontact.StartProgress` after every transition of
        a homotopy start (when SSNM does not converge at alpha_start, before the path's first
        point); a truthy return abandons the run with
        :class:`~cfcontact.errors.StartInterrupted` (a time limit, a progress display)

    Returns a :class:`SolutionPath` (method "exact"); transitions carry the exact root alpha
    (bracket (alpha, alpha)), every change (``Transition.changes``) and, at degenerate points,
    the single pivots of the rule (``Transition.pivots``).  Status "completed" (alpha range left),
    "stuck" (a point that could not be crossed, see events), "closed_loop" (the path came back to
    its first branch: a closed curve of solutions), "cycling" (a branch entered twice: a numerical
    inconsistency, see events), "max_transitions" or "stopped by callback".  A path that would end
    "cycling" or "stuck" first backtracks to its branch points' untried alternatives (see
    :func:`_backtrack`; ``backtrack`` events, ``path.stats["backtracks"]``).  ``path.stats`` adds
    ``start`` (how the start was found: "ssnm"; where SSNM does not converge, the exact method's
    homotopy from the frictionless solution, "frictionless", SSNM with another augmentation
    parameter, "ssnm_rho", or the homotopy from the all-open state, "homotopy"; "enumeration",
    "start_sets"; "apex" where the contact data vanish at alpha_start,
    see :func:`_apex_start`), ``degenerate_points``, ``pivots``,
    ``max_vanishing``, ``branch_points``, ``homotopy_transitions`` (of the start's homotopies),
    ``point_updates`` (intermediate branches of degenerate points solved by the point's rank-2
    updates, :class:`~cfcontact.condensed.PointModel`) and ``tableau_updates`` (pivots made on a
    point's own tableau, :class:`~cfcontact.condensed.PointTableau`), ``revisited_vertices``
    (branch points reached a second time, left by a branch not yet traversed instead of the
    rule's own).
    """
    overrides = {} if tie_rtol is None else {"tie_rtol": tie_rtol}
    if tree:
        overrides["tree"] = True
    opts, span = check_request(system, alpha_start, alpha_end, options, **overrides)
    if callback is not None and not callable(callback):  # (the monitor is checked where it is used)
        raise InputError(f"callback must be a function of a PathPoint (or None), got {callback!r}")
    system.check_positive_definite()  # (cached) an indefinite K has no path: say so, not "no solution found"
    return ExactStepper(system, span, opts, solver, y0=y0, resume=resume, start_sets=start_sets,
                        orientation=orientation, monitor=monitor).run(callback)


def trace_tree(system: ContactSystem, alpha_start: float = 0.0, alpha_end: float = 1.0, **kwargs) -> SolutionPath:
    """The whole connected tree of branches reachable from the start: :func:`trace_exact` and then
    every alternative of every branch point (:func:`follow_alternative`), those met on the way
    included.  Sub-runs end where they reach a branch already traced ("joined") or come back to
    their own first branch ("closed_loop").  Multiplicity counts (``solutions_at``,
    ``max_multiplicity``) then include every branch of the tree.  Without a ``solver`` the
    backend is the one ``trace_path(..., method="exact")`` picks, as for :func:`trace_exact`
    (:func:`cfcontact.backend.select_solver`: the condensed solver while its dense data fit; on a
    punch with m = 69 the PETSc backend's start alone took 108 s, the condensed one's tree 0.14 s
    after the path's set-up)."""
    method = kwargs.pop("method", "exact")
    if method != "exact":
        raise InputError(f"trace_tree follows the exact method's branch points: method must be 'exact', got {method!r}")
    return trace_exact(system, alpha_start, alpha_end, tree=True, **kwargs)


def follow_alternative(system: ContactSystem, path: SolutionPath, event_index: int, alternative: int,
                       options: Optional[PathOptions] = None, solver=None, tie_rtol: Optional[float] = None,
                       callback=None, _ctx=None) -> dict:
    """Follow another branch leaving a branch point of an exact path.

    ``path.events[event_index]`` must be a "branch_point" event; ``alternative`` indexes its
    ``data["alternatives"]``.  The new branches are appended to ``path`` (a tree: the first new
    branch has ``parent`` = the branch that reached the branch point and ``origin`` = a new
    Transition).  ``path.status`` (the main run's) is unchanged; the sub-run's status ("completed",
    "closed_loop", ...) and its branch indices are returned and stored in
    ``event.data["followed"][str(alternative)]``.  A sub-run stopped by ``callback`` ends there
    (status "stopped by callback"): ``path.resume_state`` keeps the main run's state, so that
    resuming the path continues the main run, not the alternative.  Without a ``solver`` the
    backend is the one ``trace_path(..., method="exact")`` picks
    (:func:`cfcontact.backend.select_solver`).
    """
    for name, value in (("event_index", event_index), ("alternative", alternative)):
        if not isinstance(value, (int, np.integer)) or isinstance(value, bool):
            raise InputError(f"{name} must be an integer, got {value!r}")
    if not (0 <= event_index < len(path.events)) or path.events[event_index].kind != "branch_point":
        raise InputError(f"event {event_index} is not a branch_point event of this path")
    ev = path.events[event_index]
    alts = ev.data["alternatives"]
    if not (0 <= alternative < len(alts)):
        raise InputError(f"alternative {alternative} out of range (0..{len(alts) - 1})")
    alt = alts[alternative]
    t0 = time.perf_counter()
    if _ctx is None:  # a sub-run of its own: it ends when it leaves the alpha range (or loops itself)
        if tie_rtol is None:
            tie_rtol = path.options.get("tie_rtol", TIE_RTOL)
        opts, span = check_request(system, path.alpha_start, path.alpha_end,
                                   options or PathOptions.from_dict(path.options), tie_rtol=tie_rtol)
        ctx = _Context(system, solver or select_solver(system, "exact"), opts, span.lo, span.hi,
                       float(opts.tie_rtol))
    else:  # part of a tree (_follow_all): it ends where it joins a branch of the tree
        ctx = _ctx
    stats0 = ctx.solver.stats.as_dict()
    a = float(alt["alpha"])
    codes = _canon(system, InactiveSets.from_dict(alt["sets"]))
    from_b = path.branches[ev.branch]
    oc = _canon(system, from_b.sets)
    changes = [{"node": int(i), "set": None, "from": STATE_NAMES[int(oc[i])], "to": STATE_NAMES[int(codes[i])]}
               for i in np.flatnonzero(oc != codes)] or [{"node": -1, "set": None}]
    d = int(alt["orientation"])
    first = len(path.branches)
    key = _digest(codes.tobytes())
    if _ctx is not None and key in ctx.visited:
        status = "joined"
    else:
        tr = Transition(len(path.transitions), a, "transversal" if d == from_b.orientation else "fold",
                        changes[0]["node"], changes[0]["set"], from_b.index, len(path.branches), bracket=(a, a),
                        changes=changes)
        path.transitions.append(tr)
        walk = _Walk.begin(ctx, path, ctx.line(codes, a), d, a, parent=from_b.index, origin=tr.index)
        n_events = len(path.events)
        status = walk.run(callback)
        if status == "cycling" and _ctx is not None:
            status = "joined"  # the alternative runs into a branch of the tree
            _joined_event(path, n_events)
        if status == "stopped by callback":
            walk.branch.alpha_exit = walk.alpha
    if path.lazy and getattr(ctx.solver, "size", 1) > 1:
        _form_under_mpi(path, ctx.solver)  # collective (see ExactStepper._finish)
    st = ctx.solver.stats.as_dict()
    result = {"status": status, "branches": list(range(first, len(path.branches))),
              "stats": {**{k: st[k] - stats0.get(k, 0) for k in st}, "wall_time": time.perf_counter() - t0}}
    ev.data.setdefault("followed", {})[str(alternative)] = result
    return result


def _joined_event(path, since: int):
    """In a tree, a sub-run that enters a branch already traced has joined the tree: its walk's
    "cycling" event (recorded from ``since`` on, worded for a path that revisits its own branch: "a
    numerical inconsistency") becomes a "joined" event."""
    for k in range(len(path.events) - 1, since - 1, -1):
        e = path.events[k]
        if e.kind == "cycling":
            first = e.data.get("first_alpha")
            path.events[k] = PathEvent("joined", e.alpha, f"the alternative reaches a branch of the tree (entered "
                                       f"first at alpha={first!r}): it ends there", e.branch, e.data)
            return


def _backtrack(system, path, options, solver, status: str, callback=None) -> str:
    """The status of a path that ended ``status`` (one of BACKTRACK_FROM) after backtracking.

    Depth first: the latest branch point (``branch_point`` event, those found by earlier tries
    included) with an alternative neither chosen nor followed yet has that alternative followed
    (:func:`follow_alternative`, entering no branch the path has already traversed: such a try
    ends "joined").  The first try that leaves the alpha range ends the search and the path is
    "completed"; at most MAX_BACKTRACKS tries.  Every try is a ``backtrack`` event (the branch
    point's event, the alternative, the try's status and branches), counted in
    ``path.stats["backtracks"]``; the branches of failed tries stay in the path (a tree: their
    points are solutions, as a followed alternative's are).  In a tree (``options.tree``) the
    alternatives have all been followed already: the path is "completed" when one of them
    completed, and nothing more is tried.  ``callback`` sees the tries' points; a truthy answer
    ends the try ("stopped by callback") and the backtracking: the path keeps ``status``."""
    if options.tree:
        done = [(i, k) for i, ev in enumerate(path.events) if ev.kind == "branch_point"
                for k, r in ev.data.get("followed", {}).items() if r["status"] == "completed"]
        if done:
            i, k = done[-1]
            path.events.append(PathEvent("backtrack", path.events[i].alpha, f"the path ended {status!r}; alternative "
                                         f"{k} of the branch point of event {i} (followed in the tree) completes it",
                                         path.events[i].branch, {"event": i, "alternative": int(k),
                                                                 "status": "completed", "from": status}))
            return "completed"
        return status
    ctx = _tree_context(system, path, options, solver)
    tries = 0
    while tries < MAX_BACKTRACKS:
        untried = next(((i, k) for i in range(len(path.events) - 1, -1, -1) for k in _untried(path.events[i])), None)
        if untried is None:
            break
        i, k = untried
        tries += 1
        ev = path.events[i]
        res = follow_alternative(system, path, i, k, solver=ctx.solver, callback=callback, _ctx=ctx)
        log.info("exact path ended %r: backtracked to the branch point at alpha=%.12g, alternative %d: %s",
                 status, ev.alpha, k, res["status"])
        path.events.append(PathEvent("backtrack", ev.alpha, f"the path ended {status!r}; followed alternative {k} "
                                     f"of the branch point of event {i}: {res['status']}", ev.branch,
                                     {"event": i, "alternative": k, "status": res["status"], "from": status,
                                      "branches": res["branches"]}))
        if res["status"] == "completed":
            return "completed"
        if res["status"] == "stopped by callback":
            break
    return status


def _tree_context(system, path, options, solver) -> _Context:
    """The run context of sub-runs that grow ``path`` into a tree: every branch of the path counts
    as traversed, so a sub-run that reaches one ends "joined"."""
    span = AlphaSpan.of(path.alpha_start, path.alpha_end, options)
    ctx = _Context(system, solver, options, span.lo, span.hi, float(options.tie_rtol))
    for b in path.branches:
        ctx.visited.setdefault(_digest(_canon(system, b.sets).tobytes()),
                               (b.orientation, b.alpha_enter))
    return ctx


def _untried(ev) -> list:
    """The alternatives of a branch_point event neither chosen nor followed yet (their indices)."""
    if ev.kind != "branch_point":
        return []
    followed = ev.data.get("followed", {})
    return [k for k, alt in enumerate(ev.data["alternatives"]) if not alt["chosen"] and str(k) not in followed]


def _follow_all(system, path, options, solver, callback=None):
    """Follow every alternative of every branch point of ``path`` (also those found on the way).
    ``callback`` sees the sub-runs' points (they cannot be checkpointed: a checkpoint of the main
    run is taken before); a truthy answer stops the sub-run and the tree there: a
    ``tree_stopped`` event, and ``path.stats["untried_alternatives"]`` counts the alternatives
    left (:func:`follow_alternative` follows them one by one)."""
    ctx = _tree_context(system, path, options, solver)
    i = 0
    while i < len(path.events):
        ev = path.events[i]
        for k in _untried(ev):
            res = follow_alternative(system, path, i, k, solver=ctx.solver, callback=callback, _ctx=ctx)
            if res["status"] == "stopped by callback":
                left = sum(len(_untried(e)) for e in path.events)
                path.events.append(PathEvent(
                    "tree_stopped", ev.alpha, f"the callback stopped the tree while it followed alternative {k} of "
                    f"the branch point of event {i}; {left} alternative(s) not followed (follow_alternative "
                    f"follows them)", ev.branch, {"event": i, "alternative": k, "untried": left}))
                return path
        i += 1
    return path
