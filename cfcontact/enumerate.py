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
are accepted up to a relative slack), then it must satisfy (1)-(3) (``verify(...).ok(1e-8)``);
equal solutions are reported once.  Cost: 4^m dense solves of size 2m; refused (a clear
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
    found, ys = [], []
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
        cons = np.where(nu, a <= tol, a >= -tol)
        stick = codes == 1
        cons &= np.where(stick, (bp <= tol) & (bm >= -tol), True)
        cons &= np.where((codes == 2) & ~F0, bp >= -tol, True)
        cons &= np.where(codes == 3, bm <= tol, True)
        good = np.flatnonzero(ok & np.all(cons, axis=1))
        for k in good:
            y = np.concatenate([solver.displacement(fvec, lam[k], solver.imposed_rows(codes[k].astype(np.int8))), lam[k]])
            if not np.all(np.isfinite(y)):
                continue
            if not verify(system, y, alpha, f=fvec, solver=solver).ok(1e-8):
                log.debug("combination %s consistent but fails verify; dropped", codes[k])
                continue
            sc = max(np.abs(y).max(initial=0), 1e-300)
            if any(np.abs(y - z).max() <= SLACK * max(sc, np.abs(z).max(initial=0)) for z in ys):
                continue
            ys.append(y)
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

