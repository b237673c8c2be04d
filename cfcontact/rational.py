"""A branch of the solution set as an exact function of the friction coefficient.

On a branch the per-node states are fixed (state codes as in :mod:`cfcontact.exact`: 0 open,
1 stick, 2 slip+, 3 slip-).  In the condensed form (:mod:`cfcontact.condensed`: S = B K^-1 B^T,
w = B K^-1 f - (g; 0)) its multipliers solve the reduced system

    M(F) x = W[rows],     M(F) = M0 + F R D E^T,

with x = lam[rows] (lam_n of the closed nodes, lam_t of the sticking ones), M0 = S[rows, rows]
(a principal submatrix of the SPD S: SPD), R = S[rows, m + slip], D = diag(phi_i s_i) of the
slipping nodes (friction F phi_i, slip sign s_i) and E^T x = x at the slipping nodes' lam_n.
Friction enters only through the p slipping nodes, a rank-p term.  With mu = lam_t[slip] (the
slipping nodes' tangential forces) the system splits exactly (Woodbury):

    x = X0 t - Z mu,   (I + F H) mu = F h t,     Z = M0^-1 R, X0 = M0^-1 W[rows],
                                                 H = D Z[pos], h = D X0[pos],

so lam, the indicators (17) and every constraint are affine in (t, mu) with coefficients affine
in F: ``ind = C0 t + CL mu + F (E0 t + EL mu)``.  The columns of W are the load data w the
branch is evaluated for, t their weights: one column (a fixed load: t = 1), or two, (w(alpha_r),
w') along a load path (t = (1, alpha - alpha_r)).

Roots in F are generalized eigenvalues of small pencils (size p + c), exact up to rounding:

* one constraint at a fixed load: c_j(F) = 0 iff F is an eigenvalue of
  [[I, 0], [CL_j, C0_j]] + F [[H, -h], [EL_j, E0_j]] (its determinant is c_j(F) det M(F) / det M0);
* two constraints along a load path vanishing at one alpha (a coincidence of two transition
  points, where a path changes its structure): the same with two border rows and t = (1, tau);
* det M(F) = 0 (the branch is singular there: it becomes vertical in alpha): F = -1/eig(H).

Each candidate root is then polished on the rational function itself (direct solves with M(F)),
with its sign change bracketed and checked (:func:`polish_root`).

Only NumPy/SciPy; no PETSc.  :func:`solver_at` makes a :class:`~cfcontact.condensed.CondensedSolver`
for another friction coefficient that shares the factorization of K and S.
"""

from __future__ import annotations

import copy
import math
from collections import OrderedDict
from typing import Optional

import numpy as np
import scipy.linalg as sla
from scipy.optimize import brentq

from cfcontact.exact import OPEN, SLIP_P, STICK, state_constraints

_getrf, _getrs = sla.lapack.dgetrf, sla.lapack.dgetrs
_ggev = sla.lapack.dggev

#: Relative half-width of the first bracket tried around a candidate root (grown x 30 up to
#: BRACKET_MAX until the function changes sign; no sign change: no crossing, the candidate is dropped).
BRACKET_START = 1e-10
BRACKET_MAX = 1e-4
#: Candidates with |Im F| <= IMAG_RTOL |F| count as real (a pair of nearly double real roots
#: comes out as a complex pair; the sign test decides).
IMAG_RTOL = 1e-6


def friction_pattern(system) -> np.ndarray:
    """phi with the system's node friction = F phi: its friction vector over its largest entry
    (ones when frictionless).  A path over F scales every node's coefficient by one factor."""
    Fv = system.friction_vector
    top = float(Fv.max(initial=0.0))
    return Fv / top if top > 0 else np.ones(system.m)


def solver_at(solver, system_F):
    """A :class:`~cfcontact.condensed.CondensedSolver` of ``system_F`` (the same K, N, T and loads
    with other friction) sharing ``solver``'s factorization of K, S and its cache of load data:
    a shallow copy with the friction, a fresh cache of reduced factorizations and fresh counters.
    Do not :meth:`destroy` it (the PETSc objects are the original's)."""
    from cfcontact.condensed import CondensedStats

    v = copy.copy(solver)
    v.system = system_F
    v.F = system_F.friction_vector
    v._F0 = v.F == 0.0
    v._lu = OrderedDict()
    v.stats = CondensedStats()
    v.timings = dict(solver.timings)
    return v


class RationalBranch:
    """The branch of state ``codes`` as a function of F (see the module docstring).

    ``S``, ``rho``: the condensed data; ``phi``: the friction pattern (node friction F phi_i);
    ``F0_index``: the node kinds of the exact method's constraint table
    (:func:`cfcontact.exact.node_kinds` of phi): 1 for nodes without friction at any F (phi_i = 0),
    2 for nodes without tangential unknown (their T row is zero: lam_t = 0 and no equation
    (T u)_i = 0 however they are coded)."""

    def __init__(self, S, rho, codes, phi, F0_index):
        codes = np.asarray(codes, dtype=np.int8)
        m = codes.size
        self.S, self.rho, self.codes, self.m, self.phi = S, float(rho), codes, m, np.asarray(phi, dtype=float)
        closed = np.flatnonzero(codes != OPEN)
        self.rows = np.concatenate([closed, m + np.flatnonzero((codes == STICK) & (np.asarray(F0_index) != 2))])
        self.slip = np.flatnonzero(codes >= SLIP_P)
        self.pos = np.searchsorted(closed, self.slip)
        self.D = self.phi[self.slip] * np.where(codes[self.slip] == SLIP_P, 1.0, -1.0)
        Sr = S.take(self.rows, axis=0)
        self.M0 = Sr.take(self.rows, axis=1)
        self.R = Sr.take(m + self.slip, axis=1)
        self.cidx, self.csgn, self.cnode = state_constraints(codes, F0_index)
        self._wood: dict = {}
        self._chol = None

    def position(self, node: int, ind: int) -> int:
        """Index in the constraint list of the constraint of ``node`` on indicator ``ind`` (0 a,
        1 bp, 2 bm), or -1."""
        j = np.flatnonzero(self.cidx == ind * self.m + node)
        return int(j[0]) if j.size else -1

    @property
    def k(self) -> int:
        return self.rows.size

    @property
    def p(self) -> int:
        return self.slip.size

    # ------------------------------------------------------------ direct evaluation
    def matrix(self, F: float) -> np.ndarray:
        M = self.M0.copy()
        if self.p:
            M[:, self.pos] += (F * self.R) * self.D
        return M

    def _lam(self, F, X):
        """Full multipliers (2m x c) from the reduced unknowns X (k x c)."""
        lam = np.zeros((2 * self.m, X.shape[1]))
        lam[self.rows] = X
        if self.p:
            lam[self.m + self.slip] = (F * self.D)[:, None] * X[self.pos]
        return lam

    def indicators(self, F, lam, W) -> np.ndarray:
        """(a, bp, bm) stacked (3m x c) of the multipliers ``lam`` for the load data W."""
        m = self.m
        g = lam + self.rho * (W - self.S @ lam)
        Fl = (F * self.phi)[:, None] * lam[:m]
        return np.concatenate((g[:m], g[m:] - Fl, g[m:] + Fl))

    def solve(self, F: float, W: np.ndarray, refine: bool = True):
        """(lam, ind, err): multipliers (2m x c) and indicators (3m x c) at F for the columns of W
        (one LU of M(F), one step of iterative refinement), and err = the indicators' change by
        that step (an estimate of their rounding error)."""
        W = np.asarray(W, dtype=float).reshape(2 * self.m, -1)
        if not self.k:
            lam = np.zeros((2 * self.m, W.shape[1]))
            return lam, self.indicators(F, lam, W), np.zeros((3 * self.m, W.shape[1]))
        M = self.matrix(F)
        lu, piv, info = _getrf(M)
        if info != 0 or not np.all(np.isfinite(lu)):
            raise np.linalg.LinAlgError(f"M(F) is singular at F = {F!r}")
        b = W.take(self.rows, axis=0)
        X = _getrs(lu, piv, b)[0]
        err = np.zeros((3 * self.m, W.shape[1]))
        if refine:
            dX = _getrs(lu, piv, b - M @ X)[0]
            X = X + dX
            err = np.abs(self.indicators(F, self._lam(F, dX), np.zeros_like(W)))
        lam = self._lam(F, X)
        return lam, self.indicators(F, lam, W), err

    def tangent(self, F: float, w: np.ndarray):
        """(lam, dlam, ind, dind, err) at F for the fixed load data w: values and derivatives in F
        (dx/dF = -M(F)^-1 R D x[pos]); err (3m x 2): rounding estimates of ind and dind."""
        w = np.asarray(w, dtype=float).reshape(-1)
        m = self.m
        lam, ind, err = self.solve(F, w[:, None])
        lam, ind = lam[:, 0], ind[:, 0]
        dlam = np.zeros(2 * m)
        if self.p:
            X = lam[self.rows]
            M = self.matrix(F)
            rhs = -self.R @ (self.D * X[self.pos])
            lu, piv, _ = _getrf(M)
            dX = _getrs(lu, piv, rhs)[0]
            dX = dX + _getrs(lu, piv, rhs - M @ dX)[0]
            dlam[self.rows] = dX
            dlam[m + self.slip] = self.D * (X[self.pos] + F * dX[self.pos])
        dg = dlam - self.rho * (self.S @ dlam)
        dFl = self.phi * (lam[:m] + F * dlam[:m])
        dind = np.concatenate((dg[:m], dg[m:] - dFl, dg[m:] + dFl))
        derr = np.abs(dind) * 1e-13 + err[:, 0] / max(abs(F), 1.0)
        return lam, dlam, ind, dind, np.column_stack([err[:, 0], derr])

    # ------------------------------------------------------------ rational form
    def woodbury(self, W: np.ndarray) -> dict:
        """The exact affine form in (t, mu) for the load data W (2m x c), cached per W:
        {"H", "h", "C0", "CL", "E0", "EL", "lam0", "L", "gam0", "GamL"} (see the module docstring)."""
        W = np.asarray(W, dtype=float).reshape(2 * self.m, -1)
        key = W.tobytes()
        hit = self._wood.get(key)
        if hit is not None:
            return hit
        m, p, c = self.m, self.p, W.shape[1]
        if self.k:
            if self._chol is None:
                self._chol = sla.cho_factor(self.M0, check_finite=False)
            X0 = sla.cho_solve(self._chol, W.take(self.rows, axis=0), check_finite=False)
            Z = sla.cho_solve(self._chol, self.R, check_finite=False) if p else np.zeros((self.k, 0))
        else:
            X0, Z = np.zeros((0, c)), np.zeros((0, 0))
        H = self.D[:, None] * Z[self.pos] if p else np.zeros((0, 0))
        h = self.D[:, None] * X0[self.pos] if p else np.zeros((0, c))
        lam0 = np.zeros((2 * m, c))
        lam0[self.rows] = X0
        L = np.zeros((2 * m, p))
        L[self.rows] = -Z
        L[m + self.slip, np.arange(p)] = 1.0
        gam0 = lam0 - self.rho * (self.S @ lam0) + self.rho * W
        GamL = L - self.rho * (self.S @ L)
        phi = self.phi[:, None]
        out = {"H": H, "h": h, "lam0": lam0, "L": L, "gam0": gam0, "GamL": GamL,
               "C0": np.concatenate((gam0[:m], gam0[m:], gam0[m:])),
               "CL": np.concatenate((GamL[:m], GamL[m:], GamL[m:])),
               "E0": np.concatenate((np.zeros((m, c)), -phi * lam0[:m], phi * lam0[:m])),
               "EL": np.concatenate((np.zeros((m, p)), -phi * L[:m], phi * L[:m]))}
        if len(self._wood) > 8:
            self._wood.clear()
        self._wood[key] = out
        return out

    def pencil(self, W, flats, signs) -> tuple:
        """(A, B): the pencil A + F B whose eigenvalues F are where the constraints (flat
        indicator indices ``flats``, signs ``signs``; as many as W has columns) vanish together."""
        wd = self.woodbury(W)
        p, c = self.p, np.asarray(W).reshape(2 * self.m, -1).shape[1]
        flats = np.asarray(flats, dtype=int)
        sg = np.asarray(signs, dtype=float)[:, None]
        A = np.zeros((p + c, p + c))
        B = np.zeros((p + c, p + c))
        A[:p, :p] = np.eye(p)
        B[:p, :p] = wd["H"]
        B[:p, p:] = -wd["h"]
        A[p:, :p] = sg * wd["CL"][flats]
        A[p:, p:] = sg * wd["C0"][flats]
        B[p:, :p] = sg * wd["EL"][flats]
        B[p:, p:] = sg * wd["E0"][flats]
        return A, B

    def pencil_roots(self, W, flats, signs, lo=-math.inf, hi=math.inf) -> np.ndarray:
        """Real eigenvalues F in [lo, hi] of :meth:`pencil` (sorted)."""
        A, B = self.pencil(W, flats, signs)
        # row scaling (the eigenvalues do not change): every row of [A B] of unit size
        s = np.maximum(np.abs(A).max(axis=1), np.abs(B).max(axis=1))
        s[s == 0] = 1.0
        return _real_eigs(A / s[:, None], -B / s[:, None], lo, hi)

    def pencil_roots_many(self, W, flats, signs, lo=-math.inf, hi=math.inf, sigma=0.0) -> list:
        """:meth:`pencil_roots` for many constraint sets at once (``flats``, ``signs``: N x c), one
        batched computation: the eigenvalues mu of (A + sigma B)^-1 B give F = sigma - 1/mu (sigma:
        a friction where no pencil is singular, e.g. one where the branch is consistent and the
        constraints do not vanish; a pencil singular there is solved alone by QZ)."""
        flats = np.asarray(flats, dtype=int).reshape(len(flats), -1)
        N, c = flats.shape
        if not N:
            return []
        p = self.p
        # the batch's arrays (A, B, the solve, its operand; ~5 of N (p + c)^2 doubles) within
        # PENCIL_BATCH_BYTES: a long interface with many slipping nodes (m = 1000, p ~ 900, N ~ 2000
        # constraints) would otherwise need tens of GB at once
        chunk = max(1, int(PENCIL_BATCH_BYTES // (5 * 8 * (p + c) ** 2)))
        if N > chunk:
            signs = np.asarray(signs, dtype=float).reshape(N, c)
            out = []
            for i in range(0, N, chunk):
                out.extend(self.pencil_roots_many(W, flats[i:i + chunk], signs[i:i + chunk], lo, hi, sigma))
            return out
        wd = self.woodbury(W)
        sg = np.asarray(signs, dtype=float).reshape(N, c)[:, :, None]
        A = np.zeros((N, p + c, p + c))
        B = np.zeros((N, p + c, p + c))
        A[:, :p, :p] = np.eye(p)
        B[:, :p, :p] = wd["H"]
        B[:, :p, p:] = -wd["h"]
        A[:, p:, :p] = sg * wd["CL"][flats]
        A[:, p:, p:] = sg * wd["C0"][flats]
        B[:, p:, :p] = sg * wd["EL"][flats]
        B[:, p:, p:] = sg * wd["E0"][flats]
        scale = np.maximum(np.abs(A).max(axis=2), np.abs(B).max(axis=2))
        scale[scale == 0] = 1.0
        A /= scale[:, :, None]
        B /= scale[:, :, None]
        try:
            X = np.linalg.solve(A + sigma * B, B)
            ok = np.all(np.isfinite(X), axis=(1, 2))
        except np.linalg.LinAlgError:
            X, ok = None, np.zeros(N, dtype=bool)
        out = [None] * N
        if X is not None and ok.any():
            mu = np.linalg.eigvals(X[ok])  # (k, p + c); mu = 0: F = infinity
            amu = np.abs(mu)
            keep = amu > 1e-14 * np.maximum(amu.max(axis=1, keepdims=True), 1e-300)
            with np.errstate(divide="ignore", invalid="ignore"):
                F = sigma - 1.0 / np.where(keep, mu, 1.0)
            keep &= np.abs(F.imag) <= IMAG_RTOL * np.maximum(np.abs(F.real), 1e-300)
            Fr = F.real
            keep &= (Fr >= lo) & (Fr <= hi)
            Fs = np.sort(np.where(keep, Fr, np.inf), axis=1)
            for i, row, k in zip(np.flatnonzero(ok), Fs, keep.sum(axis=1)):
                out[i] = row[:k]
        for i in np.flatnonzero(~ok):
            out[i] = _real_eigs(A[i], -B[i], lo, hi)
        return out

    def poles(self, lo=-math.inf, hi=math.inf) -> np.ndarray:
        """F in [lo, hi] where det M(F) = 0 (F = -1/eig(H)), sorted."""
        if not self.p:
            return np.zeros(0)
        H = self.woodbury(np.zeros((2 * self.m, 1)))["H"]
        ev = np.linalg.eigvals(H)
        ev = ev[np.abs(ev.imag) <= IMAG_RTOL * np.abs(ev) + 1e-300]
        ev = ev.real[ev.real != 0.0]
        F = -1.0 / ev
        return np.sort(F[(F >= lo) & (F <= hi)])

    def det_sign(self, F: float) -> float:
        """Sign of det M(F) / det M0 = det(I + F H) (+1, -1, or 0)."""
        if not self.p:
            return 1.0
        H = self.woodbury(np.zeros((2 * self.m, 1)))["H"]
        return float(np.linalg.slogdet(np.eye(self.p) + F * H)[0])

    def affine_in_mu(self, w) -> dict:
        """The branch at the fixed load w in its exact stored form: lam(F) = lam0 + L mu(F),
        g(F) = gam0 + GamL mu(F) (g = lam + rho B u), (I + F H) mu(F) = F h.  Arrays:
        {"lam0" (2m), "L" (2m x p), "gam0" (2m), "GamL" (2m x p), "H" (p x p), "h" (p)}."""
        wd = self.woodbury(np.asarray(w, dtype=float).reshape(-1, 1))
        return {"lam0": wd["lam0"][:, 0].copy(), "L": wd["L"].copy(), "gam0": wd["gam0"][:, 0].copy(),
                "GamL": wd["GamL"].copy(), "H": wd["H"].copy(), "h": wd["h"][:, 0].copy()}


def mu_at(H, h, F) -> np.ndarray:
    """The slipping nodes' tangential forces mu(F): (I + F H) mu = F h."""
    p = h.size
    if not p:
        return np.zeros(0)
    return np.linalg.solve(np.eye(p) + F * H, F * h)


#: Memory for one batch of :meth:`RationalBranch.pencil_roots_many` (bytes): larger batches are
#: split (the same eigenvalues, each pencil being solved on its own either way).
PENCIL_BATCH_BYTES = 256 * 2 ** 20


def _real_eigs(A, B, lo, hi) -> np.ndarray:
    """Real generalized eigenvalues of (A, B) (A z = F B z) in [lo, hi], sorted."""
    if A.shape[0] == 0:
        return np.zeros(0)
    ar, ai, beta, _, _, _, info = _ggev(A, B, compute_vl=0, compute_vr=0, overwrite_a=0, overwrite_b=0)
    if info != 0:
        ev = sla.eigvals(A, B, check_finite=False)
        ar, ai, beta = ev.real, ev.imag, np.ones_like(ev.real)
    ok = np.abs(beta) > 1e-14 * np.hypot(ar, ai)
    F = ar[ok] / beta[ok]
    Fi = ai[ok] / beta[ok]
    F = F[np.abs(Fi) <= IMAG_RTOL * np.maximum(np.abs(F), 1e-300)]
    return np.sort(F[(F >= lo) & (F <= hi)])


def polish_root(fun, F0: float, lo: float, hi: float, scale: float = 1.0) -> Optional[tuple]:
    """The root of ``fun`` (a scalar function of F) near the candidate F0 within [lo, hi], to
    rounding: a bracket [F0 - d, F0 + d] with a sign change is found (d from BRACKET_START to
    BRACKET_MAX relative to max(|F0|, scale)) and Brent's method narrows it.  Returns
    (root, (a, fa), (b, fb)) with the bracket that certifies it, or None (no sign change near F0:
    a touching zero or a spurious candidate)."""
    ref = max(abs(F0), scale, 1e-300)
    d = BRACKET_START * ref
    try:
        with np.errstate(all="ignore"):
            f0 = fun(F0)
    except (np.linalg.LinAlgError, ZeroDivisionError):
        f0 = float("nan")
    if f0 == 0.0:
        return F0, (F0, 0.0), (F0, 0.0)
    while d <= BRACKET_MAX * ref:
        a, b = max(lo, F0 - d), min(hi, F0 + d)
        try:
            with np.errstate(all="ignore"):
                fa, fb = fun(a), fun(b)
        except (np.linalg.LinAlgError, ZeroDivisionError):
            return None
        if np.isfinite(fa) and np.isfinite(fb):
            if fa == 0.0:
                return a, (a, fa), (a, fa)
            if fb == 0.0:
                return b, (b, fb), (b, fb)
            if (fa < 0) != (fb < 0):
                if np.isfinite(f0) and f0 != 0.0:  # keep the half that holds the sign change
                    if (fa < 0) != (f0 < 0):
                        b, fb = F0, f0
                    else:
                        a, fa = F0, f0
                try:
                    with np.errstate(all="ignore"):
                        r = float(brentq(fun, a, b, xtol=1e-15 * ref, rtol=8.9e-16, maxiter=200))
                        if not abs(fun(r)) <= max(abs(fa), abs(fb)):
                            return None  # a pole, not a root
                except (ValueError, RuntimeError, ZeroDivisionError, np.linalg.LinAlgError):
                    return None
                return r, (a, float(fa)), (b, float(fb))
        if a == lo and b == hi:
            return None
        d *= 30.0
    return None
