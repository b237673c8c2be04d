"""Condensed DirNeu backend: one factorization of K, then dense 2m x 2m solves.

With B = [N; T] (2m x n) and lam = (lam_n, lam_t), equation (1) gives u = K^-1 (f - B^T lam), so

    B u = w - S lam,    S = B K^-1 B^T (2m x 2m, dense),   w = B K^-1 f.

DirNeu(Z, f) (method.md (9)) is then the dense system M(Z) lam = r(Z, w) with, per node i,

    normal row     : A_nu: (S lam)_i = w_i            I_nu: lam_n,i = 0
    tangential row : A_t : (S lam)_{m+i} = w_{m+i}    I_t : lam_t,i - F (1_{I_t+} - 1_{I_t-}) lam_n,i = 0

followed by u = K^-1 f - (K^-1 B^T) lam.  :class:`CondensedSolver` factors K once (PETSc KSP,
MUMPS when available; works under MPI), forms K^-1 B^T with one multi-right-hand-side solve
(``MatMatSolve`` on a dense matrix of 2m columns), keeps S and (when it fits in memory) the
columns K^-1 B^T, caches K^-1 f and w for the loads seen (f1, f2), and LU-factors M(Z) per
inactive-set combination (dense, cached).  It has the interface of
:class:`cfcontact.ssnm.DirNeuSolver` (``solve(Z, f)``, ``stats``, ``K_times``), so
``ssnm(..., solver=CondensedSolver(system))`` and ``trace_path(..., solver=...)`` use it.
Cost: O(n m) memory for K^-1 B^T; it pays off for small m (tens to a few hundred nodes).
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from dataclasses import dataclass
from typing import Optional

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from petsc4py import PETSc

from cfcontact import linalg
from cfcontact.errors import InputError, SingularSystemError
from cfcontact.ssnm import InactiveSets, SolverOptions, SolverStats, _default_solver_type
from cfcontact.system import ContactSystem

log = logging.getLogger(__name__)

#: Form K^-1 B^T (n x 2m doubles) for S in one multi-RHS solve when it has at most this many
#: entries per rank; otherwise in column blocks of at most this many entries.
STORE_LIMIT = 50_000_000


@dataclass
class CondensedStats(SolverStats):
    """SolverStats plus the dense work: factorizations / linear_solves count sparse work on K
    (one solve per right-hand side, the 2m columns of K^-1 B^T included)."""

    dense_factorizations: int = 0
    dense_solves: int = 0

    def as_dict(self) -> dict:
        d = super().as_dict()
        d.update(dense_factorizations=self.dense_factorizations, dense_solves=self.dense_solves)
        return d


class CondensedSolver:
    """DirNeu(Z, f) through the condensed 2m x 2m system (see the module docstring).

    Parameters
    ----------
    system : ContactSystem
    options : SolverOptions (prefix: the KSP of K uses ``<prefix>K_``; solver_type; cache =
        how many dense LU factorizations of M(Z) to keep, at least 64)
    store_columns : form all of K^-1 B^T at once when forming S (default: when it has at most
        STORE_LIMIT entries per rank), else in column blocks.  It is never kept: u is always
        K^-1 (f - B^T lam) by one sparse solve, since K^-1 f - (K^-1 B^T) lam loses accuracy
        (contact forces nearly cancel the load; relative residual 4e-8 measured at n = 1.2e5).
    """

    def __init__(self, system: ContactSystem, options: Optional[SolverOptions] = None,
                 store_columns: Optional[bool] = None):
        self.system = system
        self.options = options or SolverOptions()
        self.stats = CondensedStats()
        self.comm = system.comm
        self.rank, self.size = self.comm.Get_rank(), self.comm.Get_size()
        self.n, self.m = system.n, system.m
        self.r0, self.r1 = system.K.getOwnershipRange()
        m = self.m
        self.nloc = self.r1 - self.r0
        self.K_local = linalg.local_csr(system.K)
        N, T = system.contact_maps()
        self.B = sp.vstack([N, T]).tocsr()
        self.B_local = self.B[:, self.r0:self.r1].tocsr()  # 2m x nloc
        self.F = system.friction_vector
        self.solver_type = self.options.solver_type or _default_solver_type(self.size)
        self._lu: "OrderedDict[bytes, tuple]" = OrderedDict()
        self._loads: list = []  # [(f, w)]
        # ---- factor K
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOperators(system.K)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("lu")
        if self.solver_type != "petsc":
            pc.setFactorSolverType(self.solver_type)
        ksp.setOptionsPrefix(self.options.prefix + "K_")
        ksp.setFromOptions()
        if self.solver_type == "mumps" and not PETSc.Options().hasName(self.options.prefix + "K_mat_mumps_icntl_14"):
            # MUMPS' default workspace estimate (ICNTL(14) = 20%) is too small for dense couplings
            pc.setFactorSetUpSolverType()
            pc.getFactorMatrix().setMumpsIcntl(14, 100)
        try:
            ksp.setUp()
        except PETSc.Error as exc:
            raise SingularSystemError(f"factorization of K failed (is K singular? every body needs a Dirichlet "
                                      f"condition): PETSc error {exc.ierr}") from exc
        self.stats.factorizations += 1
        self.ksp = ksp
        self._x, self._b = system.K.createVecs()
        # ---- K^-1 B^T and S
        self.store = (self.nloc * 2 * m <= STORE_LIMIT) if store_columns is None else bool(store_columns)
        self.S = self._schur()

    # ----------------------------------------------------------- K solves
    def _ksolve(self, rhs_local: np.ndarray) -> np.ndarray:
        self._b.getArray()[:] = rhs_local
        try:
            self.ksp.solve(self._b, self._x)
        except PETSc.Error as exc:
            raise SingularSystemError(f"solve with K failed: PETSc error {exc.ierr}") from exc
        if self.ksp.getConvergedReason() < 0:
            raise SingularSystemError(f"solve with K failed (KSP reason {self.ksp.getConvergedReason()}); "
                                      f"is K singular?")
        self.stats.linear_solves += 1
        return np.array(self._x.getArray(readonly=True), copy=True)

    def _ksolve_dense(self, rhs: np.ndarray) -> np.ndarray:
        """K^-1 applied to the columns of ``rhs`` (local rows, nloc x k): one multi-RHS solve (MatMatSolve)."""
        k = rhs.shape[1]
        try:
            Bm = PETSc.Mat().createDense(((self.nloc, self.n), (PETSc.DECIDE, k)), comm=self.comm)
            Bm.setUp()
            Bm.getDenseArray()[:] = rhs
            Bm.assemble()
            Xm = Bm.duplicate()
            self.ksp.getPC().getFactorMatrix().matSolve(Bm, Xm)
            X = np.array(Xm.getDenseArray(), copy=True).reshape(self.nloc, k)
            Bm.destroy()
            Xm.destroy()
            self.stats.linear_solves += k
            return X
        except PETSc.Error as exc:  # fall back to one solve per column
            log.info("MatMatSolve unavailable (PETSc error %s); solving %d columns one by one", exc.ierr, k)
            return np.column_stack([self._ksolve(rhs[:, j]) for j in range(k)]) if k else np.zeros((self.nloc, 0))

    def _kinv_columns(self, cols) -> np.ndarray:
        """Local rows of K^-1 B^T[:, cols] (nloc x len(cols))."""
        return self._ksolve_dense(np.asfortranarray(self.B_local[cols, :].T.toarray()))

    def _allreduce(self, a: np.ndarray) -> np.ndarray:
        if self.size == 1:
            return a
        out = np.empty_like(a)
        from mpi4py import MPI

        self.comm.Allreduce(np.ascontiguousarray(a), out, op=MPI.SUM)
        return out

    def _schur(self) -> np.ndarray:
        m2 = 2 * self.m
        if self.store:
            block = m2
        else:
            block = max(1, int(STORE_LIMIT // max(self.nloc, 1)))
            if self.size > 1:
                from mpi4py import MPI

                block = self.comm.allreduce(block, op=MPI.MIN)
        S = np.zeros((m2, m2))
        for c0 in range(0, m2, block):
            cols = np.arange(c0, min(m2, c0 + block))
            S[:, cols] = self.B_local @ self._kinv_columns(cols)
        S = self._allreduce(np.ascontiguousarray(S))
        return 0.5 * (S + S.T)

    # ---------------------------------------------------------------- loads
    def load_data(self, f: np.ndarray) -> np.ndarray:
        """w = B K^-1 f (cached for the last few loads)."""
        for g, w in self._loads:
            if g is f or np.array_equal(g, f):
                return w
        w = self._allreduce(self.B_local @ self._ksolve(f[self.r0:self.r1]))
        self._loads.append((np.array(f, copy=True), w))
        if len(self._loads) > 4:
            self._loads.pop(0)
        return w

    # ------------------------------------------------------------ dense part
    def matrix(self, Z: InactiveSets) -> np.ndarray:
        """M(Z) (2m x 2m) of the condensed DirNeu system."""
        m = self.m
        M = np.zeros((2 * m, 2 * m))
        idx = np.arange(m)
        act_n, act_t = ~Z.nu, ~Z.it
        M[:m][act_n] = self.S[:m][act_n]
        M[idx[Z.nu], idx[Z.nu]] = 1.0
        M[m:][act_t] = self.S[m:][act_t]
        it = np.flatnonzero(Z.it)
        M[m + it, m + it] = 1.0
        sgn = Z.tp.astype(float) - Z.tm.astype(float)
        M[m + it, it] = -self.F[it] * sgn[it]
        return M

    def rhs(self, Z: InactiveSets, w: np.ndarray) -> np.ndarray:
        m = self.m
        r = np.zeros(2 * m)
        r[:m] = np.where(Z.nu, 0.0, w[:m])
        r[m:] = np.where(Z.it, 0.0, w[m:])
        return r

    def _factor(self, Z: InactiveSets):
        key = Z.canonical_key(self.system.friction)
        if key in self._lu:
            self._lu.move_to_end(key)
            return self._lu[key]
        M = self.matrix(Z)
        lu, piv = sla.lu_factor(M, check_finite=False) if M.size else (M, np.zeros(0, dtype=np.int32))
        d = np.abs(np.diag(lu))
        if d.size and (not np.all(np.isfinite(d)) or d.min() <= 1e-14 * max(d.max(), 1e-300)):
            raise SingularSystemError(f"DirNeu(Z) is singular (condensed matrix) for {Z!r}")
        self.stats.dense_factorizations += 1
        self._lu[key] = (lu, piv)
        while len(self._lu) > max(64, self.options.cache):
            self._lu.popitem(last=False)
        return self._lu[key]

    def multipliers(self, Z: InactiveSets, w: np.ndarray) -> np.ndarray:
        """lam = (lam_n, lam_t) of DirNeu(Z, f) from w = B K^-1 f."""
        if self.m == 0:
            return np.zeros(0)
        lu = self._factor(Z)
        self.stats.dense_solves += 1
        return sla.lu_solve(lu, self.rhs(Z, w), check_finite=False)

    def displacement(self, f: np.ndarray, lam: np.ndarray) -> np.ndarray:
        """u = K^-1 (f - B^T lam), whole on every rank (one sparse solve)."""
        u_loc = self._ksolve(f[self.r0:self.r1] - self.B_local.T @ lam)
        return linalg.concat_ranks(self.comm, u_loc)

    # ------------------------------------------------------------ interface
    def solve(self, Z: InactiveSets, f) -> np.ndarray:
        """y = DirNeu(Z, f) = (u, lam_n, lam_t) as a whole NumPy vector on every rank."""
        f = np.asarray(f, dtype=float)
        if f.shape != (self.n,):
            raise InputError(f"load vector has shape {f.shape}, expected ({self.n},)")
        if not isinstance(Z, InactiveSets) or Z.m != self.m:
            raise InputError(f"Z must be InactiveSets of length m = {self.m}, got {Z!r}")
        w = self.load_data(f)
        lam = self.multipliers(Z, w)
        u = self.displacement(f, lam)
        y = np.concatenate([u, lam])
        if not np.all(np.isfinite(y)):
            raise SingularSystemError(f"DirNeu(Z) could not be solved for {Z!r} (non-finite result)")
        return y

    def K_times(self, u: np.ndarray) -> np.ndarray:
        """K u as a whole vector (for residual checks)."""
        local = self.K_local @ u
        return linalg.concat_ranks(self.comm, local)

    def destroy(self):
        for obj in (self.ksp, self._x, self._b):
            obj.destroy()
        self._lu.clear()
        self._loads.clear()


def get_condensed_solver(system: ContactSystem, options: Optional[SolverOptions] = None) -> CondensedSolver:
    """The system's condensed solver (created once and kept on the system; new one if options given)."""
    cache = system._cache
    if options is not None or "condensed" not in cache:
        cache["condensed"] = CondensedSolver(system, options)
    return cache["condensed"]
