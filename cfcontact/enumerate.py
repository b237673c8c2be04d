"""Every solution at one alpha by trying every nodal state combination ([JL-PF]'s Remark 3.2).

Per contact node the states are open / stick / slip+ / slip- (an open node is tangentially
free, lam_t = 0, so its tangential sign is irrelevant; a node with F = 0 has only open / free;
a node without tangential DOFs, :attr:`ContactSystem.no_tangent`, only open / stick with
lam_t = 0).  The system's initial gap enters through w (:meth:`CondensedSolver.load_data`).
Every solution y of (4) is DirNeu(Z, f) for the canonical form of its own sets Z(y) (Remark
3.1), so trying the 4^m combinations finds all of them.  Each combination is solved in the
condensed form (:mod:`cfcontact.condensed`): with S = B K^-1 B^T and w = B K^-1 f(alpha)
(one factorization of K for the whole enumeration) DirNeu(Z, f) is a dense 2m x 2m system in
lam = (lam_n, lam_t); the systems are solved in vectorized batches.  A combination is kept when
its solution is consistent with it (Remark 3.1, the indicator signs; ties at transition points
are accepted up to a relative slack, the force conditions against the forces), then it must
satisfy (1)-(3) (``verify(...).ok(1e-8)``); equal solutions (equal multipliers) are reported
once.  Cost: 4^m dense solves of size 2m; refused (a clear
:class:`~cfcontact.errors.EnumerationTooLarge`) for m > ``max_nodes`` (default 10: about 1e6
combinations, some seconds).
"""

from __future__ import annotations

import contextlib
import functools
import logging

import numpy as np
from threadpoolctl import ThreadpoolController

from cfcontact.errors import EnumerationTooLarge, InputError
from cfcontact.ssnm import InactiveSets, Solution, verify
from cfcontact.system import ContactSystem, check_alpha

log = logging.getLogger(__name__)

DEFAULT_MAX_NODES = 10
CHUNK = 16384
SLACK = 1e-9
#: ... of each node's own scale: the force conditions (lam_n >= 0 at a closed node, the cone at
#: a sticking one) up to this share of the largest force (a model whose open nodes' rho |B u| is
#: 1e6 times its loads kept a node with lam_n of -2 times the largest force), the gap and slip
#: conditions up to SLACK of their own row's terms
FORCE_SLACK = 1e-7


def _combos(radices, c0, c1):
    """Mixed-radix digits of the integers c0..c1-1 (node 0 varies slowest)."""
    idx = np.arange(c0, c1, dtype=np.int64)
    out = np.empty((idx.size, len(radices)), dtype=np.int64)
    for j in range(len(radices) - 1, -1, -1):
        out[:, j] = idx % radices[j]
        idx //= radices[j]
    return out


def enumerate_solutions(system: ContactSystem, alpha: float = 0.0, max_nodes: int = DEFAULT_MAX_NODES,
                        solver=None, f=None) -> list:
    """Every solution of (1)-(3) at f(alpha) (or at the load ``f``), as a list of :class:`Solution`.

    Refuses (EnumerationTooLarge) when the number m of contact nodes exceeds ``max_nodes``
    (4^m combinations are tried).  ``solver``: a :class:`~cfcontact.condensed.CondensedSolver`
    of the system (default: the system's cached one).
    """
    from cfcontact.condensed import CondensedSolver, get_condensed_solver

    m, n = system.m, system.n
    if m > int(max_nodes):
        raise EnumerationTooLarge(
            f"enumerating all solutions tries 4^m state combinations; m = {m} contact nodes exceeds the limit "
            f"max_nodes = {int(max_nodes)} (4^{m} = {4.0 ** m:.3g} combinations); raise max_nodes to force it")
    alpha = check_alpha(alpha)
    system.check_positive_definite()  # (cached) with an indefinite K "no solution" would be no answer
    solver = solver if isinstance(solver, CondensedSolver) else get_condensed_solver(system)
    fvec = system.load(alpha) if f is None else np.asarray(f, dtype=float)
    if fvec.shape != (n,):
        raise InputError(f"load vector has length {fvec.size}, expected n = {n}")
    w = solver.load_data(fvec)
    # the size of w's own terms: at a transition point a difference of them vanishes (an open node
    # touching its foundation: B K^-1 f(alpha) = g), and what rounding leaves there is judged
    # against them, not against w
    gap = np.concatenate([system.gap, np.zeros(m)]) if system.has_gap else np.zeros(2 * m)
    w_terms = np.abs(w) + np.abs(gap)
    if f is None:
        W = solver.load_data_many(list(system.loads_numpy())) + gap[:, None]  # B K^-1 (f1, f2)
        w_terms = np.maximum(w_terms, abs(1.0 - alpha) * np.abs(W[:, 0]) + abs(alpha) * np.abs(W[:, 1]) + np.abs(gap))
    S = solver.S
    F = system.friction_vector
    rho = system.rho
    F0 = F == 0.0
    no_t = system.no_tangent
    states = [np.array([0, 1]) if no_t[i] else np.array([0, 2]) if F0[i] else np.array([0, 1, 2, 3])
              for i in range(m)]
    radices = [len(s) for s in states]
    total = int(np.prod(radices)) if m else 1
    I2 = np.eye(2 * m)
    idx = np.arange(m)
    found, ys, top = [], [], 0.0  # ys: the multipliers found; top: the largest of them
    for c0 in range(0, total, CHUNK):
        digits = _combos(radices, c0, min(total, c0 + CHUNK))
        codes = np.stack([states[i][digits[:, i]] for i in range(m)], axis=1) if m else np.zeros((1, 0), int)
        nu = codes == 0
        tp = (codes == 0) | (codes == 2)
        tm = codes == 3
        it = tp | tm
        act = np.concatenate([~nu, ~it & ~no_t], axis=1)  # rows taken from S (else lam = 0 rows)
        M = np.where(act[:, :, None], S[None], I2[None])
        sgn = tp.astype(float) - tm.astype(float)
        M[:, m + idx, idx] = np.where(it, -F * sgn, M[:, m + idx, idx])
        r = np.where(act, w[None], 0.0)
        lam, ok = _batched_solve(M, r)
        Bu = w[None] - lam @ S.T
        a = lam[:, :m] + rho * Bu[:, :m]
        b = lam[:, m:] + rho * Bu[:, m:]
        bp, bm = b - F * lam[:, :m], b + F * lam[:, :m]
        scale = np.maximum(np.abs(np.concatenate([a, bp, bm], axis=1)).max(axis=1, initial=0), 1e-300)
        tol = SLACK * scale[:, None]
        # each node's conditions at its own scale, not at that of the largest indicator (a node
        # pulled 1e12 away from its foundation made a neighbour's lam_n = -1 and a slip against
        # its force look like rounding): a closed node's a and a sticking node's b+- are forces
        # (lam_n >= 0, |lam_t| <= F lam_n), judged against the forces; an open node's gap and a
        # slipping node's slip against the terms of their own row of rho (w - S lam), w's own
        # terms included, whose rounding also bounds a force condition's imposed row
        terms = rho * (w_terms[None] + np.abs(lam) @ np.abs(S).T)
        tn, tt = terms[:, :m], terms[:, m:]
        eps64 = 64.0 * np.finfo(float).eps
        force = FORCE_SLACK * np.abs(lam).max(axis=1, initial=0.0)[:, None]
        cons = np.where(nu, a <= np.minimum(tol, SLACK * tn), a >= -np.minimum(tol, force + eps64 * tn))
        stick = codes == 1
        tol_f = np.minimum(tol, force + eps64 * tt)
        cons &= np.where(stick, (bp <= tol_f) & (bm >= -tol_f), True)
        tol_s = np.minimum(tol, SLACK * tt)
        cons &= np.where((codes == 2) & ~F0, bp >= -tol_s, True)
        cons &= np.where(codes == 3, bm <= tol_s, True)
        good = np.flatnonzero(ok & np.all(cons, axis=1))
        for k in good:
            y = np.concatenate([solver.displacement(fvec, lam[k], solver.imposed_rows(codes[k].astype(np.int8))), lam[k]])
            if not np.all(np.isfinite(y)):
                continue
            if not verify(system, y, alpha, f=fvec, solver=solver).ok(1e-8):
                log.debug("combination %s consistent but fails verify; dropped", codes[k])
                continue
            # one solution per multipliers (they determine u), compared at their own scale: against
            # y's, a body that moves far (u of 1e12) merged the three solutions of a node into one
            lk = lam[k]
            top = max(top, float(np.abs(lk).max(initial=0.0)))
            if any(np.abs(lk - z).max() <= SLACK * max(np.abs(lk).max(initial=0.0), np.abs(z).max(initial=0.0))
                   + 1e3 * np.finfo(float).eps * top for z in ys):
                continue
            ys.append(lk)
            Z = InactiveSets.from_states(codes[k])
            found.append(Solution.from_y(system, y, alpha, sets=Z))
    return found


@functools.lru_cache(maxsize=None)
def _blas_controller():
    """threadpoolctl's view of the BLAS libraries loaded now (found once, when first needed)."""
    return ThreadpoolController()


@contextlib.contextmanager
def single_threaded_blas():
    """Run BLAS single-threaded inside the block (batched tiny solves are much faster so)."""
    with _blas_controller().limit(limits=1, user_api="blas"):
        yield


def _batched_solve(M, r):
    with single_threaded_blas():
        return _batched_solve_(M, r)


def _batched_solve_(M, r):
    """Solve M[k] x = r[k] for every k; singular systems give ok[k] = False."""
    ok = np.ones(M.shape[0], dtype=bool)
    if M.shape[1] == 0:
        return np.zeros((M.shape[0], 0)), ok
    try:
        x = np.linalg.solve(M, r[..., None])[..., 0]
        return x, ok & np.all(np.isfinite(x), axis=1)
    except np.linalg.LinAlgError:
        out = np.zeros_like(r)
        for k in range(M.shape[0]):
            try:
                out[k] = np.linalg.solve(M[k], r[k])
            except np.linalg.LinAlgError:
                ok[k] = False
        return out, ok & np.all(np.isfinite(out), axis=1)

