"""Semi-smooth Newton layer: inactive sets, the generalized Jacobian J(Z), DirNeu, SSNM.

Notation follows the path-following paper [JL-PF] (Section 3) and the theory page
(docs/theory.md).  With y = (u, lam_n, lam_t) and the system's initial gap g (:attr:`ContactSystem.gap`, zero by default)::

    I_nu  = { i : lam_n,i + rho ((N u)_i - g_i) < 0 }            (open nodes)
    I_t^+ = { i : lam_t,i + rho (T u)_i - F lam_n,i > 0 }         (slip +)
    I_t^- = { i : lam_t,i + rho (T u)_i + F lam_n,i < 0 }         (slip -)

and ``dirneu(Z, f)`` solves J(Z) y = (f, r_g, 0) with J of docs/theory.md (5), r_g = -rho g on the
closed nodes (A_nu: (N u)_i = g_i) and 0 on the open ones: DirNeu is affine in f (linear when
g = 0), and along f(alpha) with Z fixed y(alpha) is still affine because g is constant.  J is
assembled as one PETSc AIJ matrix: the displacement rows are distributed as the
rows of K, the 2m multiplier rows live on the last rank, so the global order is
(u, lam_n, lam_t).  It is factored by a direct solver (MUMPS where PETSc has it)
through a KSP whose options can be overridden with the prefix
``SolverOptions.prefix`` (default ``cfcontact_``), e.g. ``-cfcontact_pc_factor_mat_solver_type superlu_dist``.
This layer never imports dolfinx: it sees only a :class:`~cfcontact.system.ContactSystem`.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from dataclasses import dataclass
from typing import Optional

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc

from cfcontact import linalg
from cfcontact.errors import ConvergenceError, InputError, SingularSystemError
from cfcontact.system import ContactSystem

log = logging.getLogger(__name__)

STATE_NAMES = ("open", "stick", "slip+", "slip-")


# --------------------------------------------------------------------------- sets
def canonical_key(nu, tp, tm, frictionless) -> bytes:
    """:meth:`InactiveSets.canonical_key` of the sets given as boolean arrays, no object formed
    (``frictionless``: F == 0 per node): a tangentially free node that is open or frictionless
    counts as I_t^+ alone; the bytes are :meth:`InactiveSets.key` of that form."""
    free = nu | frictionless
    return np.packbits(np.concatenate((nu, tp | (free & tm), tm & ~free))).tobytes() + nu.size.to_bytes(4, "little")


@dataclass(frozen=True, eq=False)
class InactiveSets:
    """Inactive sets Z = {I_nu; I_t^+; I_t^-} as boolean arrays of length m."""

    nu: np.ndarray
    tp: np.ndarray
    tm: np.ndarray

    def __post_init__(self):
        for name in ("nu", "tp", "tm"):
            arr = np.asarray(getattr(self, name), dtype=bool).copy()
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def m(self) -> int:
        return self.nu.size

    @property
    def it(self) -> np.ndarray:
        """I_t = I_t^+ u I_t^-."""
        return self.tp | self.tm

    def key(self) -> bytes:
        """Exact identity of the three sets (hashable)."""
        return np.packbits(np.concatenate([self.nu, self.tp, self.tm])).tobytes() + self.m.to_bytes(4, "little")

    def canonical_key(self, friction) -> bytes:
        """Identity up to changes that cannot alter DirNeu's solution.

        For an open node (lam_n = 0) or a node with F = 0, the rows of I_t^+, I_t^- and
        both all give lam_t = 0, so only "tangentially free or not" matters there.
        """
        F = np.broadcast_to(np.asarray(friction, dtype=float), (self.m,))
        return canonical_key(self.nu, self.tp, self.tm, F == 0.0)

    def equivalent(self, other: "InactiveSets", friction) -> bool:
        return self.canonical_key(friction) == other.canonical_key(friction)

    def __eq__(self, other):
        return isinstance(other, InactiveSets) and self.key() == other.key()

    def __hash__(self):
        return hash(self.key())

    def states(self) -> list:
        """Per-node state: 'open', 'stick', 'slip+' or 'slip-'."""
        out = []
        for i in range(self.m):
            if self.nu[i]:
                out.append("open")
            elif self.tp[i] and not self.tm[i]:
                out.append("slip+")
            elif self.tm[i] and not self.tp[i]:
                out.append("slip-")
            elif not self.tp[i] and not self.tm[i]:
                out.append("stick")
            else:
                out.append("slip+-")
        return out

    def state_codes(self) -> np.ndarray:
        """Per-node integer code: 0 open, 1 stick, 2 slip+, 3 slip- (index into STATE_NAMES)."""
        codes = np.where(self.nu, 0, np.where(self.tp, 2, np.where(self.tm, 3, 1)))
        return codes.astype(np.int8)

    @classmethod
    def from_states(cls, states) -> "InactiveSets":
        """Sets from per-node states ('open', 'stick', 'slip+', 'slip-' or codes 0-3).

        An open node is put in I_t^+ (tangentially free: lam_t = F lam_n = 0)."""
        if isinstance(states, np.ndarray) and states.dtype.kind in "iu":
            codes = states.astype(int)
        else:
            codes = np.array([STATE_NAMES.index(s) if isinstance(s, str) else int(s) for s in states], dtype=int)
        if np.any((codes < 0) | (codes > 3)):
            raise InputError(f"node states must be in {STATE_NAMES} or 0..3, got {list(states)}")
        return cls(nu=codes == 0, tp=(codes == 0) | (codes == 2), tm=codes == 3)

    @classmethod
    def from_rows(cls, table: np.ndarray) -> "InactiveSets":
        """Sets from the rows (nu, tp, tm) of a 3 x m boolean array that the caller gives away (a
        fresh array, e.g. a table lookup): made read-only and used as is, without the copies of
        the constructor (the exact method forms one per branch)."""
        if table.dtype != bool or table.ndim != 2 or table.shape[0] != 3:
            raise InputError(f"from_rows needs a 3 x m boolean array, got {table.dtype} {table.shape}")
        table.setflags(write=False)
        sets = cls.__new__(cls)
        for name, row in zip(("nu", "tp", "tm"), table):
            object.__setattr__(sets, name, row)
        return sets

    @classmethod
    def all_stick(cls, m) -> "InactiveSets":
        z = np.zeros(m, dtype=bool)
        return cls(z, z, z)

    def to_dict(self) -> dict:
        return {"nu": np.flatnonzero(self.nu).tolist(), "tp": np.flatnonzero(self.tp).tolist(),
                "tm": np.flatnonzero(self.tm).tolist(), "m": self.m}

    @classmethod
    def from_dict(cls, d) -> "InactiveSets":
        m = int(d["m"])
        arrs = []
        for k in ("nu", "tp", "tm"):
            a = np.zeros(m, dtype=bool)
            a[np.asarray(d[k], dtype=int)] = True
            arrs.append(a)
        return cls(*arrs)

    def __repr__(self):
        return (f"InactiveSets(I_nu={np.flatnonzero(self.nu).tolist()}, "
                f"I_t+={np.flatnonzero(self.tp).tolist()}, I_t-={np.flatnonzero(self.tm).tolist()})")


def indicators(system: ContactSystem, y: np.ndarray):
    """The three indicator vectors of (11)-(13) / (17) at y:

    ``lam_n + rho (N u - g)``, ``lam_t + rho T u - F lam_n``, ``lam_t + rho T u + F lam_n``."""
    n, m = system.n, system.m
    y = np.asarray(y)
    u, ln, lt = y[:n], y[n:n + m], y[n + m:]
    N, T = system.contact_maps()
    F = system.friction_vector
    a = ln + system.rho * (N @ u - system.gap)
    b = lt + system.rho * (T @ u)
    return a, b - F * ln, b + F * ln


def inactive_sets(system: ContactSystem, y) -> InactiveSets:
    """Inactive sets Z(y) of [JL-PF]'s Section 3."""
    if isinstance(y, Solution):
        y = y.y
    a, bp, bm = indicators(system, y)
    return InactiveSets(a < 0, bp > 0, bm < 0)


def canonical_codes(sets: InactiveSets, friction, no_tangent=None) -> np.ndarray:
    """Per-node state codes (0 open, 1 stick, 2 slip+, 3 slip-) with the canonical choices: an open
    node is tangentially free, a node with F = 0 is open or free (coded slip+; its stick state
    gives the same solution when consistent, lam_t = 0), and a node without tangential unknown
    (``no_tangent``) is open or closed (coded stick, lam_t = 0)."""
    F = np.broadcast_to(np.asarray(friction, dtype=float), (sets.m,))
    codes = sets.state_codes()  # tp & tm -> 2 (slip+)
    closed = codes != 0
    codes = np.where(closed & (F == 0.0), 2, codes)
    if no_tangent is not None:
        codes = np.where(closed & np.asarray(no_tangent, dtype=bool), 1, codes)
    return codes.astype(np.int8)


# ----------------------------------------------------------------------- results
@dataclass(eq=False)
class Solution:
    """A solution (or iterate) y = (u, lam_n, lam_t) at load parameter alpha."""

    u: np.ndarray
    lam_n: np.ndarray
    lam_t: np.ndarray
    alpha: float
    sets: InactiveSets
    iterations: int = 0

    @property
    def y(self) -> np.ndarray:
        return np.concatenate([self.u, self.lam_n, self.lam_t])

    def states(self) -> list:
        return self.sets.states()

    @classmethod
    def from_y(cls, system, y, alpha, sets=None, iterations=0) -> "Solution":
        n, m = system.n, system.m
        y = np.asarray(y, dtype=float)
        sets = inactive_sets(system, y) if sets is None else sets
        return cls(y[:n].copy(), y[n:n + m].copy(), y[n + m:].copy(), float(alpha), sets, iterations)


# ------------------------------------------------------------------------ solver
@dataclass
class SolverOptions:
    """Options of the linear-solver layer.

    prefix: PETSc options prefix of the KSP (``-<prefix>pc_factor_mat_solver_type`` etc.).
    solver_type: factorization package; None picks MUMPS when PETSc has it, else PETSc's LU
        (serial) or SuperLU_dist.
    cache: how many factorizations of J(Z) to keep (one per inactive-set combination).
    updates: condensed backend, exact method: solve neighbouring branches by updates of one kept
        factorization (True), by a fresh factorization each (False), or decide by size (None).
    refine: condensed backend: iterative refinement of the solves with K that form w and u
        (and a correction of S to match), with residuals in double-double arithmetic (True),
        none (False), or where a probe solve at set-up shows that K's condition number costs
        digits (None; slender bodies, see ``condensed.REFINE_RTOL``).
    """

    prefix: str = "cfcontact_"
    solver_type: Optional[str] = None
    cache: int = 4
    updates: Optional[bool] = None
    refine: Optional[bool] = None


@dataclass
class SolverStats:
    """Work counters (the benchmarks read them)."""

    factorizations: int = 0
    linear_solves: int = 0
    ssnm_iterations: int = 0

    def as_dict(self) -> dict:
        return {"factorizations": self.factorizations, "linear_solves": self.linear_solves,
                "ssnm_iterations": self.ssnm_iterations}


def _default_solver_type(comm_size):
    if PETSc.Sys.hasExternalPackage("mumps"):
        return "mumps"
    if comm_size == 1:
        return "petsc"
    if PETSc.Sys.hasExternalPackage("superlu_dist"):
        return "superlu_dist"
    raise SingularSystemError("no parallel direct solver (MUMPS or SuperLU_dist) in this PETSc build")


class DirNeuSolver:
    """Solves the Dirichlet-Neumann problems (9) J(Z) y = (f, 0, 0) of one system.

    Factorizations of J(Z) are cached per inactive-set combination (least recently used
    dropped first), so the solves of one branch for several loads share one factorization.
    """

    def __init__(self, system: ContactSystem, options: Optional[SolverOptions] = None):
        self.system = system
        self.options = options or SolverOptions()
        self.stats = SolverStats()
        self.comm = system.comm
        self.rank, self.size = self.comm.Get_rank(), self.comm.Get_size()
        self.n, self.m = system.n, system.m
        self.r0, self.r1 = system.K.getOwnershipRange()
        self.last = self.rank == self.size - 1
        m = self.m
        self.K_local = linalg.local_csr(system.K)
        N, T = system.contact_maps()
        self.N, self.T = N, T
        self.no_tangent = system.no_tangent
        #: right-hand side of the normal rows of closed nodes: -rho (N u)_i = -rho g_i
        self._gap_rhs = -system.rho * system.gap if system.has_gap else None
        B = sp.vstack([N, T]).tocsc()
        BT_local = B[:, self.r0:self.r1].T.tocsr()
        self.upper = sp.hstack([self.K_local, BT_local]).tocsr()
        self.upper.sort_indices()
        self.local_rows = (self.r1 - self.r0) + (2 * m if self.last else 0)
        self.solver_type = self.options.solver_type or _default_solver_type(self.size)
        self._ksps: "OrderedDict[bytes, tuple]" = OrderedDict()

    # -- assembly of J(Z)
    def jacobian_lower(self, Z: InactiveSets) -> sp.csr_matrix:
        """The 2m multiplier rows of J(Z) (docs/theory.md (5)) as a SciPy matrix (2m x (n+2m))."""
        m, rho = self.m, self.system.rho
        F = self.system.friction_vector
        A_nu = (~Z.nu).astype(float)
        A_t = (~Z.it).astype(float)
        rows_n = sp.hstack([sp.diags(A_nu) @ (-rho * self.N), sp.diags(Z.nu.astype(float)), sp.csr_matrix((m, m))])
        sgn = Z.tp.astype(float) - Z.tm.astype(float)
        # a sticking node without tangential DOFs (zero row of T) has the row lam_t,i = 0 instead of 0 = 0
        lt_diag = (Z.it | (~Z.it & self.no_tangent)).astype(float)
        rows_t = sp.hstack([sp.diags(A_t) @ (-rho * self.T), sp.diags(-F * sgn), sp.diags(lt_diag)])
        lower = sp.vstack([rows_n, rows_t]).tocsr()
        lower.eliminate_zeros()
        return lower

    def jacobian(self, Z: InactiveSets) -> PETSc.Mat:
        """J(Z) as a distributed PETSc AIJ matrix."""
        n, m = self.n, self.m
        size = n + 2 * m
        local = sp.vstack([self.upper, self.jacobian_lower(Z)]).tocsr() if self.last else self.upper
        local.sort_indices()
        J = PETSc.Mat().createAIJ(
            size=((self.local_rows, size), (self.local_rows, size)),
            csr=(local.indptr.astype(PETSc.IntType), local.indices.astype(PETSc.IntType),
                 local.data.astype(PETSc.ScalarType)),
            comm=self.comm,
        )
        J.assemble()
        return J

    def _ksp(self, Z: InactiveSets):
        key = Z.canonical_key(self.system.friction)
        if key in self._ksps:
            self._ksps.move_to_end(key)
            return self._ksps[key]
        J = self.jacobian(Z)
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOperators(J)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("lu")
        if self.solver_type != "petsc":
            pc.setFactorSolverType(self.solver_type)
        ksp.setOptionsPrefix(self.options.prefix)
        ksp.setFromOptions()
        try:
            ksp.setUp()
        except PETSc.Error as exc:
            raise SingularSystemError(
                f"factorization of J(Z) failed for {Z!r} (is K singular? every body needs a Dirichlet "
                f"condition): PETSc error {exc.ierr}") from exc
        self.stats.factorizations += 1
        x, b = J.createVecs()
        self._ksps[key] = (ksp, J, x, b)
        while len(self._ksps) > max(1, self.options.cache):
            old = self._ksps.popitem(last=False)[1]
            for obj in old:
                obj.destroy()
        return self._ksps[key]

    def solve(self, Z: InactiveSets, f) -> np.ndarray:
        """y = DirNeu(Z, f) as a whole NumPy vector (u, lam_n, lam_t) on every rank.

        ``f`` is a NumPy array of length n (whole, on every rank).  The normal rows of the closed
        nodes read (N u)_i = g_i (the system's gap): DirNeu is affine in f."""
        f = np.asarray(f, dtype=float)
        if f.shape != (self.n,):
            raise InputError(f"load vector has shape {f.shape}, expected ({self.n},)")
        ksp, J, x, b = self._ksp(Z)
        arr = b.getArray()
        nloc = self.r1 - self.r0
        arr[:nloc] = f[self.r0:self.r1]
        arr[nloc:] = 0.0
        if self.last and self._gap_rhs is not None:
            arr[nloc:nloc + self.m] = np.where(Z.nu, 0.0, self._gap_rhs)
        try:
            ksp.solve(b, x)
        except PETSc.Error as exc:
            raise SingularSystemError(f"DirNeu solve failed for {Z!r}: PETSc error {exc.ierr}") from exc
        self.stats.linear_solves += 1
        reason = ksp.getConvergedReason()
        local = np.array(x.getArray(readonly=True), copy=True)
        y = linalg.concat_ranks(self.comm, local)
        if reason < 0 or not np.all(np.isfinite(y)):
            raise SingularSystemError(
                f"DirNeu(Z) could not be solved (KSP reason {reason}); J(Z) is singular for {Z!r} — "
                f"is K singular (a body without Dirichlet condition)?")
        return y

    def K_times(self, u: np.ndarray) -> np.ndarray:
        """K u as a whole vector (for residual checks)."""
        local = self.K_local @ u
        return linalg.concat_ranks(self.comm, local)

    def destroy(self):
        for objs in self._ksps.values():
            for obj in objs:
                obj.destroy()
        self._ksps.clear()


def get_solver(system: ContactSystem, options: Optional[SolverOptions] = None) -> DirNeuSolver:
    """The system's DirNeu solver (created once and kept on the system; new one if options given)."""
    cache = system._cache
    if options is not None or "solver" not in cache:
        cache["solver"] = DirNeuSolver(system, options)
    return cache["solver"]


def _load_vector(system, alpha, f):
    if f is None:
        return system.load(alpha)
    f = np.asarray(f, dtype=float)
    if f.shape != (system.n,):
        raise InputError(f"load vector has length {f.size}, expected n = {system.n}")
    return f


def dirneu(system: ContactSystem, Z: InactiveSets, alpha: float = 0.0, f=None, solver=None) -> Solution:
    """DirNeu(Z, f(alpha)) (or DirNeu(Z, f) if ``f`` is given): the solution of (9)."""
    if not isinstance(Z, InactiveSets) or Z.m != system.m:
        raise InputError(f"Z must be InactiveSets of length m = {system.m}, got {Z!r}")
    solver = solver or get_solver(system)
    y = solver.solve(Z, _load_vector(system, alpha, f))
    return Solution.from_y(system, y, alpha)


def _as_y(system, y0, what="y0"):
    size = system.n + 2 * system.m
    if isinstance(y0, Solution):
        return y0.y
    usage = f"{what} must be a Solution or a flat vector (u, lam_n, lam_t) of length n + 2m = {size}"
    try:
        y0 = np.asarray(y0, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{usage}, got {y0!r:.80}") from None
    if y0.shape != (size,):
        raise InputError(f"{usage}, got shape {y0.shape}")
    if not np.all(np.isfinite(y0)):
        raise InputError(f"{what} has non-finite entries (at {np.flatnonzero(~np.isfinite(y0))[:5].tolist()}...)")
    return y0


def ssnm(system: ContactSystem, alpha: float = 0.0, y0=None, tol: float = 1e-9, max_iter: int = 100,
         f=None, solver: Optional[DirNeuSolver] = None) -> Solution:
    """Semi-smooth Newton method (ALGORITHM SSNM of [JL-PF]).

    y^k = DirNeu(Z(y^{k-1}), f), stopped when ||y^k - y^{k-1}|| <= tol ||y^k||.
    The start y0 (a Solution or a flat vector of length n + 2m) defaults to 0, whose
    inactive sets are empty (all nodes in contact and sticking) when there is no gap; with an
    initial gap the nodes with g > 0 are open at y = 0.

    Raises ConvergenceError after ``max_iter`` iterations (e.g. when the iteration cycles).
    """
    if not (tol > 0):
        raise InputError(f"tol must be > 0, got {tol!r}")
    if int(max_iter) < 1:
        raise InputError(f"max_iter must be >= 1, got {max_iter!r}")
    system.check_positive_definite()  # (cached) SSNM would wander on an indefinite K
    solver = solver or get_solver(system)
    fvec = _load_vector(system, alpha, f)
    y_prev = np.zeros(system.n + 2 * system.m) if y0 is None else _as_y(system, y0)
    if hasattr(solver, "ssnm"):  # the condensed backend iterates in the multipliers alone
        return solver.ssnm(fvec, y_prev, tol, max_iter, alpha)
    for k in range(1, int(max_iter) + 1):
        Z = inactive_sets(system, y_prev)
        y = solver.solve(Z, fvec)
        solver.stats.ssnm_iterations += 1
        diff = np.linalg.norm(y - y_prev)
        log.debug("ssnm alpha=%g it=%d |dy|/|y|=%.3e", alpha, k, diff / max(np.linalg.norm(y), 1e-300))
        if diff <= tol * np.linalg.norm(y):
            return Solution.from_y(system, y, alpha, iterations=k)
        y_prev = y
    raise ConvergenceError(f"SSNM did not converge in {max_iter} iterations at alpha={alpha}",
                           iterations=max_iter, last=Solution.from_y(system, y_prev, alpha, iterations=max_iter))


def is_fixed_point(system: ContactSystem, y, Z: InactiveSets) -> bool:
    """Remark 3.1: y = DirNeu(Z, f) is an SSNM fixed point iff Z(y) is (equivalent to) Z."""
    y = y.y if isinstance(y, Solution) else y
    return inactive_sets(system, y).equivalent(Z, system.friction)


# ----------------------------------------------------------------- verification
@dataclass
class Verification:
    """How well y satisfies (1)-(3); every entry is relative (dimensionless).

    equilibrium: ||K u + N^T lam_n + T^T lam_t - f|| / (||K|| ||u|| + ||N^T lam_n + T^T lam_t|| + ||f||)
        (max-norms): the normwise backward error of (1), what a backward-stable solve attains
        (relative to ||f|| alone, an ill-conditioned K -- a slender body -- shows its condition
        number times the rounding, whatever the solver)
    normal, tangential: max-norm of the 2nd / 3rd block of G(y) in (4) over the force scale: the
        largest of |lam|, rho |N u - g|, rho |T u|, the load |f| and, the gap left being a
        difference, rho |N u| and rho |g|
    cone: max (|lam_t| - F lam_n)_+ ; sign: max (-lam_n)_+ and (N u - g)_+ (penetration, times rho)
    slip_direction: worst violation of "stick => T u = 0, slip+- => +-T u >= 0" (times rho)
    """

    equilibrium: float
    normal: float
    tangential: float
    cone: float
    sign: float
    complementarity: float
    slip_direction: float

    def worst(self) -> float:
        return max(self.equilibrium, self.normal, self.tangential, self.cone, self.sign,
                   self.complementarity, self.slip_direction)

    def ok(self, tol: float = 1e-8) -> bool:
        return self.worst() <= tol


def verify(system: ContactSystem, y, alpha: float = 0.0, f=None, solver=None) -> Verification:
    """Check (1)-(3) at y (a Solution or a flat vector), independently of the sets used to get it.
    The normal conditions are those with the system's gap g: N u - g <= 0, lam_n^T (N u - g) = 0."""
    y = _as_y(system, y, "y")
    solver = solver or get_solver(system)
    n, m, rho = system.n, system.m, system.rho
    u, ln, lt = y[:n], y[n:n + m], y[n + m:]
    N, T = system.contact_maps()
    F = system.friction_vector
    fvec = _load_vector(system, alpha, f)
    Ku = solver.K_times(u)
    Blam = N.T @ ln + T.T @ lt
    r = Ku + Blam - fvec
    eq = np.abs(r).max(initial=0.0) / max(system.K_norm() * np.abs(u).max(initial=0.0) + np.abs(Blam).max(initial=0.0)
                                          + np.abs(fvec).max(initial=0.0), 1e-300)
    Nu0 = N @ u
    Nu, Tu = rho * (Nu0 - system.gap), rho * (T @ u)  # Nu: rho times the gap left, N u - g
    # the gap left is a difference: its rounding is that of N u and g, which count in the scale (a
    # punch landing with zero force: every N u - g and lam vanish, N u and g do not); so does the
    # load, the size equilibrium is measured against (a node at zero gap whose multipliers and
    # N u all vanish at its transition: N u = (K^-1 f)_n is then the rounding of u = K^-1 f)
    scale = max(np.abs(ln).max(initial=0), np.abs(lt).max(initial=0), np.abs(Nu).max(initial=0),
                np.abs(Tu).max(initial=0), rho * np.abs(Nu0).max(initial=0),
                rho * np.abs(np.asarray(system.gap, dtype=float)).max(initial=0), np.abs(fvec).max(initial=0), 1e-300)
    g2 = ln - np.maximum(0.0, ln + Nu)
    g = F * ln
    x = lt + Tu
    g3 = lt - (np.maximum(0.0, x + g) - np.maximum(0.0, x - g) - g)
    cone = np.maximum(np.abs(lt) - F * ln, 0.0).max(initial=0) / scale
    sign = max(np.maximum(-ln, 0).max(initial=0), np.maximum(Nu, 0).max(initial=0)) / scale
    compl = np.abs(np.minimum(ln, -Nu)).max(initial=0) / scale
    # slip direction: strictly inside the cone -> T u = 0; on the boundary -> T u has lam_t's sign
    tol_b = 1e-8 * scale
    inside = np.abs(lt) < F * ln - tol_b
    sd = np.where(inside, np.abs(Tu), np.where(lt > 0, np.maximum(-Tu, 0), np.maximum(Tu, 0)))
    sd = np.where((ln > tol_b) & (F > 0), sd, 0.0)  # open nodes or F = 0: T u is free
    return Verification(
        equilibrium=float(eq), normal=float(np.abs(g2).max(initial=0) / scale),
        tangential=float(np.abs(g3).max(initial=0) / scale), cone=float(cone), sign=float(sign),
        complementarity=float(compl), slip_direction=float(sd.max(initial=0) / scale),
    )
