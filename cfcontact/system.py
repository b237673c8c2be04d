"""The contact-system object: the only thing the solver layers see.

A :class:`ContactSystem` holds the discrete problem of docs/theory.md (1)-(4)::

    K u + N^T lam_n + T^T lam_t = f(alpha) = (1 - alpha) f1 + alpha f2
    N u - g <= 0, lam_n >= 0, lam_n^T (N u - g) = 0, Coulomb's law with coefficient F

as PETSc objects (K: n x n AIJ, N and T: m x n AIJ, f1 and f2: Vec) on one MPI
communicator, plus the friction coefficient F, the augmentation parameter rho and the
initial gap g (one value per contact node, fixed in the reference configuration, zero by
default: g > 0 where the bodies are apart, g < 0 an initial interference).  The gap does
not depend on alpha, so every branch of a solution path stays affine in alpha; but the
problem is no longer positively homogeneous in the load (a zero load does not give y = 0).
Dirichlet DOFs are *eliminated*: K holds free DOFs only, so K is SPD when the
bodies are clamped.  It can come from the FEM assembly layer
(:func:`cfcontact.two_blocks`, :func:`cfcontact.assembly.assemble_contact_system`)
or from plain matrices (:meth:`ContactSystem.from_arrays`) for lumped models.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from dataclasses import dataclass, field
from typing import Optional

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from cfcontact import linalg
from cfcontact.errors import InputError, NotPositiveDefiniteError, SingularSystemError

#: Largest magnitude accepted in K, N, T, the loads, rho and the gap: the path multiplies and
#: squares them (indicators, residual norms), which must stay far from overflow (1.8e308).
MAGNITUDE_LIMIT = 1e100
#: K is checked by the inertia of a Cholesky factorization up to this many DOFs (milliseconds
#: to a second); larger K (FEM models, SPD by construction when E > 0 and -1 < nu < 0.5) by
#: the signs of its diagonal only, to spare the path a second factorization of a large K.
INERTIA_MAX_DOFS = 50_000
#: The exact method's perturbation loads (its lexicographic rule at degenerate points, see
#: :meth:`ContactSystem.perturbation_loads`): fixed random vectors from this seed, this many
#: columns to begin with (more where those tie).
PERTURBATION_SEED = 20261201
PERTURBATION_COLUMNS = 2


@dataclass(eq=False)
class ContactGeometry:
    """Plain NumPy description of a FEM model, for pictures and for reading results.

    Attributes
    ----------
    points : (P, 2) float array
        Mesh node coordinates (all bodies, rank-independent numbering).
    cells : (C, k) int array
        Cells as node indices (k = 3 triangles, k = 4 quadrilaterals in VTK order).
    cell_body : (C,) int array
        Body of each cell (1 = upper body Omega^1, 2 = lower body Omega^2).
    dof_node, dof_comp : (n,) int arrays
        Node and component (0 = x, 1 = y) of each free DOF of K.
    contact_nodes : (m, 2) int array
        Node of body 1 and node of body 2 (-1 for a rigid foundation) of each contact pair.
    contact_points, normals, tangents : (m, 2) float arrays
        Coordinates, unit outer normal of body 1 and unit tangent t = (-n_y, n_x).
    material : dict or None
        ``{"E": ..., "nu": ..., "plane": "strain" | "stress"}`` of the model (E and nu numbers, or
        dicts ``{"body1=1": value, ...}`` with one value per body), as in ``ContactSystem.info``;
        set by the assembly layer and saved with a path, so stresses
        (:func:`cfcontact.fields.von_mises`) can be computed from a saved path.  None: unknown.
    tributary : (m,) float array or None
        Length of the contact boundary each contact node stands for (half its adjacent slave
        facets): lam_n / tributary is the contact pressure.  None: unknown.
    prescribed : (k, 4) float array or None
        Non-zero prescribed displacements [node, component, value at alpha = 0, value at
        alpha = 1] (u_D(alpha) = (1 - alpha) u_D^1 + alpha u_D^2), for
        :meth:`displacement_field` at a given alpha.  None: every prescribed DOF is zero.
    obstacle : dict or None
        The rigid obstacle of a single body (``cfcontact.pairing.Line/Circle.to_dict()``), if any.

    Contact nodes: with node-to-segment pairing the contact node of a pair is its slave node
    (``contact_points``); ``contact_nodes`` gives it with the master node of larger weight.
    """

    points: np.ndarray
    cells: np.ndarray
    cell_body: np.ndarray
    dof_node: np.ndarray
    dof_comp: np.ndarray
    contact_nodes: np.ndarray
    contact_points: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    material: Optional[dict] = None
    tributary: Optional[np.ndarray] = None
    prescribed: Optional[np.ndarray] = None
    obstacle: Optional[dict] = None

    _JSON = ("material", "obstacle")  # stored as JSON text by to_dict
    _OPTIONAL = ("material", "tributary", "prescribed", "obstacle")

    def __post_init__(self):
        # to_dict() stores the material and the obstacle as JSON strings (0-d str arrays in an .npz)
        for name in self._JSON:
            value = getattr(self, name)
            if isinstance(value, (str, np.ndarray)):
                text = str(value)
                setattr(self, name, json.loads(text) if text else None)

    def displacement_field(self, u: np.ndarray, alpha: Optional[float] = None) -> np.ndarray:
        """Nodal displacements (P, 2) from a free-DOF vector u: prescribed nodes get 0, or, with
        ``alpha``, their prescribed values u_D(alpha) (:attr:`prescribed`)."""
        U = np.zeros_like(self.points, dtype=float)
        U[self.dof_node, self.dof_comp] = u
        if alpha is not None and self.prescribed is not None and len(self.prescribed):
            tab = np.asarray(self.prescribed, dtype=float).reshape(-1, 4)
            U[tab[:, 0].astype(int), tab[:, 1].astype(int)] = (1.0 - alpha) * tab[:, 2] + alpha * tab[:, 3]
        return U

    def slave_nodes(self) -> np.ndarray:
        """(m,) the slave node of each pair: of its (body 1, body 2) nodes the one at its contact
        point (with node-to-segment pairing the other is the master node of larger weight).  Where
        both lie there (a master node under the slave node), the slave side is the one the other
        pairs show; a matching interface (every pair so) counts as body 1's."""
        nodes = np.asarray(self.contact_nodes, dtype=int).reshape(-1, 2)
        P = np.asarray(self.points, dtype=float)[:, :2]
        at = np.asarray(self.contact_points, dtype=float)[:, :2]
        tol = 1e-9 * max(float(np.ptp(P, axis=0).max(initial=0.0)) if len(P) else 0.0, 1e-300)
        on0 = np.hypot(*(P[nodes[:, 0]] - at).T) <= tol
        on1 = (nodes[:, 1] >= 0) & (np.hypot(*(P[np.maximum(nodes[:, 1], 0)] - at).T) <= tol)
        body2 = np.sum(on1 & ~on0) > np.sum(on0 & ~on1)
        return np.where(on1 & (~on0 | body2), nodes[:, 1], nodes[:, 0])

    def to_dict(self) -> dict:
        """Plain NumPy arrays (for an .npz; no pickling): the material and obstacle as JSON strings;
        optional entries only when known."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name in self._OPTIONAL and value is None:
                continue
            out[f.name] = np.asarray(json.dumps(value)) if f.name in self._JSON else np.asarray(value)
        return out

    @classmethod
    def from_dict(cls, d) -> "ContactGeometry":
        """Inverse of :meth:`to_dict`; the optional entries may be missing (paths saved before them)."""
        kw = {f.name: np.asarray(d[f.name]) for f in dataclasses.fields(cls) if f.name not in cls._OPTIONAL}
        kw.update({name: d[name] for name in cls._OPTIONAL if name in d})
        return cls(**kw)


def default_rho(K: sp.spmatrix, N: sp.spmatrix, T: sp.spmatrix) -> float:
    """Default augmentation parameter: the mean diagonal stiffness at the contact DOFs.

    With rho of the size of a nodal stiffness, rho * (N u)_i is a force of the size
    of lam_n,i, so the tests ``lam + rho * gap`` that define the inactive sets weigh
    both alike ([JL-PF]'s remark: forces ~1e10 while displacements are tiny).
    """
    B = sp.vstack([sp.csr_matrix(N), sp.csr_matrix(T)]).tocsc()
    dofs = np.flatnonzero(np.diff(B.indptr) > 0)
    diag = np.abs(sp.csr_matrix(K).diagonal())
    vals = diag[dofs] if dofs.size else diag
    rho = float(np.mean(vals)) if vals.size else 1.0
    return rho if rho > 0 else 1.0


@dataclass(eq=False)
class ContactSystem:
    """Discrete two-body (or body-foundation) frictional contact problem.

    Attributes
    ----------
    K : PETSc.Mat   (n x n, AIJ, Dirichlet DOFs eliminated)
    N, T : PETSc.Mat   (m x n, AIJ): relative normal / tangential displacement per contact node
    f1, f2 : PETSc.Vec (n): the load path is f(alpha) = (1 - alpha) f1 + alpha f2
    friction : float or (m,) array: Coulomb coefficient F >= 0 (one per node allowed)
    rho : float > 0: augmentation parameter of (4)
    geometry : ContactGeometry or None: mesh data of a FEM model (pictures, reading results)
    info : dict: free-form description (model parameters, timings of assembly...)
    gap : (m,) float array (read-only; None -> zeros): initial normal gap g of each contact node,
        whole on every rank; (N u)_i - g_i <= 0 is non-penetration
    """

    K: PETSc.Mat
    N: PETSc.Mat
    T: PETSc.Mat
    f1: PETSc.Vec
    f2: PETSc.Vec
    friction: object
    rho: float
    geometry: Optional[ContactGeometry] = None
    info: dict = field(default_factory=dict)
    gap: Optional[np.ndarray] = None

    def __post_init__(self):
        n = self.K.getSize()[0]
        m = self.N.getSize()[0]
        if self.K.getSize() != (n, n):
            raise InputError(f"K must be square, got shape {self.K.getSize()}")
        for name in ("N", "T"):
            shape = getattr(self, name).getSize()
            if shape != (m, n):
                raise InputError(f"{name} must have shape (m, n) = ({m}, {n}), got {shape}")
        for name in ("f1", "f2"):
            size = getattr(self, name).getSize()
            if size != n:
                raise InputError(f"load vector {name} has length {size}, expected n = {n} (the size of K)")
        if n == 0:
            raise InputError("K is empty (0 x 0): the system needs at least one displacement DOF")
        for name in ("K", "N", "T", "f1", "f2"):
            finite, big = linalg.local_finite_max(getattr(self, name))
            what = {"K": "the stiffness K", "N": "the normal map N", "T": "the tangential map T",
                    "f1": "the load vector f1", "f2": "the load vector f2"}[name]
            if not finite:
                raise InputError(f"{what} has non-finite entries (inf or nan){_overflow_hint(name)}")
            if big > MAGNITUDE_LIMIT:
                raise InputError(f"{what} has entries up to {big:.3g}, beyond {MAGNITUDE_LIMIT:g}, too close to "
                                 f"overflow in double precision{_overflow_hint(name)}")
        self.friction = _check_friction(self.friction, m)
        try:
            rho = float(self.rho)
        except (TypeError, ValueError):
            raise InputError(f"rho must be a finite positive number, got {self.rho!r}") from None
        if not (np.isfinite(rho) and 0 < rho <= MAGNITUDE_LIMIT):
            raise InputError(f"rho must be a finite positive number (at most {MAGNITUDE_LIMIT:g}), got {self.rho!r}")
        self.rho = rho
        self.gap = _check_gap(self.gap, m)
        if np.abs(self.gap).max(initial=0.0) > MAGNITUDE_LIMIT:
            raise InputError(f"the gap reaches {np.abs(self.gap).max():.3g}, beyond {MAGNITUDE_LIMIT:g}: rescale the units")
        self._cache = {}

    # ------------------------------------------------------------------ basics
    @property
    def comm(self):
        """The mpi4py communicator of the PETSc objects."""
        return self.K.getComm().tompi4py()

    @property
    def n(self) -> int:
        """Number of displacement DOFs (free DOFs of K)."""
        return self.K.getSize()[0]

    @property
    def m(self) -> int:
        """Number of contact nodes."""
        return self.N.getSize()[0]

    @property
    def friction_vector(self) -> np.ndarray:
        """F as an (m,) array."""
        return np.broadcast_to(np.asarray(self.friction, dtype=float), (self.m,)).copy()

    @property
    def has_gap(self) -> bool:
        """True when some initial gap is not zero."""
        return bool(np.any(self.gap != 0.0))

    @property
    def no_tangent(self) -> np.ndarray:
        """(m,) bool: contact nodes whose row of T is zero (every DOF it would touch is prescribed,
        e.g. a node on a symmetry plane through the contact zone).  Such a node has no tangential
        unknown: lam_t,i enters no equation, and DirNeu takes lam_t,i = 0 when it sticks."""
        if "no_tangent" not in self._cache:
            T = self.contact_maps()[1]
            self._cache["no_tangent"] = np.asarray(abs(T).sum(axis=1)).ravel() == 0.0
        return self._cache["no_tangent"]

    def load(self, alpha: float) -> np.ndarray:
        """f(alpha) = (1 - alpha) f1 + alpha f2 as a whole NumPy array (on every rank)."""
        alpha = check_alpha(alpha)
        f1, f2 = self.loads_numpy()
        with np.errstate(over="ignore", invalid="ignore"):  # checked right below
            f = (1.0 - alpha) * f1 + alpha * f2
        if not np.all(np.isfinite(f)):
            raise InputError(f"the load f(alpha) overflows at alpha = {alpha:g} (|f1| <= {np.abs(f1).max():.3g}, "
                             f"|f2| <= {np.abs(f2).max():.3g}); rescale the loads")
        return f

    # ------------------------------------------------------------ checks
    def inertia(self):
        """(negative, zero, positive) eigenvalue counts of K (cached; None when this PETSc cannot
        tell).  Collective: one Cholesky (LDL^T) factorization of K, unless a backend that factored
        K by Cholesky already stored its inertia (:class:`cfcontact.condensed.CondensedSolver`)."""
        if "inertia" not in self._cache:
            self._cache["inertia"] = linalg.inertia(self.K)
        return self._cache["inertia"]

    def record_inertia(self, inertia: tuple):
        """Keep K's inertia as a factorization made elsewhere found it (a backend's Cholesky
        factorization of K with every pivot positive: (0, 0, n)), so that :meth:`inertia` needs
        none of its own.  Must be the same on every rank."""
        neg, zero, pos = (int(k) for k in inertia)
        if min(neg, zero, pos) < 0 or neg + zero + pos != self.n:
            raise InputError(f"an inertia of K counts n = {self.n} eigenvalues, not {inertia!r}")
        self._cache.setdefault("inertia", (neg, zero, pos))

    def _diagonal_signs(self):
        """(non-positive diagonal entries of K, the first of them) over all ranks, cached."""
        if "diagonal_signs" not in self._cache:
            d = np.asarray(self.K.getDiagonal().getArray(readonly=True))
            r0 = self.K.getOwnershipRange()[0]
            bad = np.flatnonzero(d <= 0.0)
            first = int(bad[0]) + r0 if bad.size else -1
            count = self.comm.allreduce(int(bad.size))
            firsts = [f for f in self.comm.allgather(first) if f >= 0]
            self._cache["diagonal_signs"] = (count, (min(firsts) if firsts else -1))
        return self._cache["diagonal_signs"]

    def check_positive_definite(self):
        """Raise :class:`~cfcontact.errors.NotPositiveDefiniteError` when K has negative eigenvalues
        (a sign error, an indefinite matrix) and :class:`~cfcontact.errors.SingularSystemError`
        when it has zero ones (a body without enough Dirichlet conditions); the path methods call
        this before tracing.  Nothing when the inertia is unknown."""
        if self.n > INERTIA_MAX_DOFS:
            count, first = self._diagonal_signs()
            if count:
                raise NotPositiveDefiniteError(f"K is not positive definite: {count} diagonal entr"
                                               f"{'ies are' if count != 1 else 'y is'} <= 0 (the first K[{first}, "
                                               f"{first}]); a stiffness matrix must be symmetric positive definite "
                                               f"on the free DOFs")
            return
        inertia = self.inertia()
        if inertia is None:
            return
        neg, zero, pos = inertia
        if neg:
            raise NotPositiveDefiniteError(f"K is not positive definite ({neg} negative eigenvalue"
                                           f"{'s' if neg != 1 else ''} of {self.n}, from the inertia of its LDL^T "
                                           f"factorization): a stiffness matrix must be symmetric positive definite "
                                           f"on the free DOFs", inertia)
        if zero:
            raise SingularSystemError(f"K is singular (a zero pivot in its Cholesky factorization): a body without "
                                      f"enough Dirichlet conditions (rigid-body motions)?")

    def checksum(self) -> str:
        """SHA-256 (hex) of (n, m, K, N, T, f1, f2, friction, gap, rho): the identity of the system a
        saved path or a checkpoint belongs to.  Cached; collective under MPI (K is hashed in global
        row order on rank 0 and the digest broadcast), the same on every rank."""
        if "checksum" not in self._cache:
            self._cache["checksum"] = _checksum(self)
        return self._cache["checksum"]

    def loads_numpy(self):
        """(f1, f2) as whole NumPy arrays, cached."""
        if "loads" not in self._cache:
            self._cache["loads"] = (linalg.gather_vec(self.f1), linalg.gather_vec(self.f2))
        return self._cache["loads"]

    def perturbation_loads(self, columns: int = PERTURBATION_COLUMNS) -> np.ndarray:
        """The exact method's perturbation loads (n x max(columns, PERTURBATION_COLUMNS)): fixed
        random load vectors (the same in every run: PERTURBATION_SEED), scaled to the larger of
        the path's two loads.  The backend may form their data with its own set-up's solves
        (:class:`~cfcontact.condensed.CondensedSolver`), the exact method asks for them at its
        first degenerate point."""
        if isinstance(columns, bool) or not isinstance(columns, (int, np.integer)) or columns < 1:
            raise InputError(f"perturbation_loads: columns must be a positive integer, got {columns!r}")
        f1, f2 = self.loads_numpy()
        rng = np.random.default_rng(PERTURBATION_SEED)
        scale = max(np.abs(f1).max(initial=0.0), np.abs(f2).max(initial=0.0), 1e-300)
        return scale * rng.standard_normal((self.n, max(int(columns), PERTURBATION_COLUMNS)))

    def K_norm(self) -> float:
        """||K|| (max absolute row sum), cached; collective under MPI."""
        if "K_norm" not in self._cache:
            self._cache["K_norm"] = float(self.K.norm(PETSc.NormType.INFINITY))
        return self._cache["K_norm"]

    def contact_maps(self):
        """(N, T) as whole SciPy CSR matrices on every rank, cached."""
        if "NT" not in self._cache:
            self._cache["NT"] = (linalg.gather_mat(self.N), linalg.gather_mat(self.T))
        return self._cache["NT"]

    def to_scipy(self):
        """(K, N, T, f1, f2): SciPy CSR matrices and NumPy vectors, whole on every rank."""
        N, T = self.contact_maps()
        f1, f2 = self.loads_numpy()
        return linalg.gather_mat(self.K), N.copy(), T.copy(), f1.copy(), f2.copy()

    # ------------------------------------------------------------ variations
    def with_friction(self, friction) -> "ContactSystem":
        """The same system (sharing K, N, T, loads) with another friction coefficient."""
        return self._same_K(ContactSystem(self.K, self.N, self.T, self.f1, self.f2, friction, self.rho, self.geometry,
                                          dict(self.info), self.gap))

    def _same_K(self, other: "ContactSystem") -> "ContactSystem":
        """``other`` (a variation sharing K) with what this system knows of K: its inertia, the
        signs of its diagonal, its norm (a friction map makes a system per row: the check of K
        would factor it again for each)."""
        other._cache.update({k: self._cache[k] for k in ("inertia", "diagonal_signs", "K_norm") if k in self._cache})
        return other

    def with_gap(self, gap) -> "ContactSystem":
        """The same system with another initial gap (an (m,) array, or None for zero)."""
        return self._same_K(ContactSystem(self.K, self.N, self.T, self.f1, self.f2, self.friction, self.rho,
                                          self.geometry, dict(self.info), gap))

    def with_rho(self, rho: float) -> "ContactSystem":
        """The same system with another augmentation parameter rho > 0.  The solutions of (1)-(3)
        do not depend on rho; the convergence of SSNM and the set tests do."""
        if not (np.isfinite(rho) and rho > 0):
            raise InputError(f"rho must be a finite number > 0, got {rho!r}")
        return self._same_K(ContactSystem(self.K, self.N, self.T, self.f1, self.f2, self.friction, float(rho),
                                          self.geometry, dict(self.info), self.gap))

    def with_loads(self, f1, f2) -> "ContactSystem":
        """The same system with other load vectors (NumPy arrays of length n or PETSc Vecs)."""
        vecs = []
        ranges = np.asarray(self.K.getOwnershipRanges())
        for name, f in (("f1", f1), ("f2", f2)):
            if isinstance(f, PETSc.Vec):
                vecs.append(f)
            else:
                f = np.asarray(f, dtype=float)
                if f.shape != (self.n,):
                    raise InputError(f"load vector {name} has shape {f.shape}, expected ({self.n},)")
                vecs.append(linalg.vec_from_numpy(f, self.comm, ranges))
        return self._same_K(ContactSystem(self.K, self.N, self.T, vecs[0], vecs[1], self.friction, self.rho,
                                          self.geometry, dict(self.info), self.gap))

    # ----------------------------------------------------------- constructors
    @classmethod
    def from_arrays(cls, K, N, T, f1, f2, friction, rho=None, comm=None, geometry=None, gap=None) -> "ContactSystem":
        """Build a system from NumPy/SciPy data given whole on every rank.

        Parameters
        ----------
        K : (n, n) SPD matrix (dense or sparse); N, T : (m, n); f1, f2 : (n,)
        friction : F >= 0 (scalar or one per contact node)
        rho : augmentation parameter; default :func:`default_rho`
        comm : mpi4py communicator (default COMM_WORLD)
        gap : (m,) initial gap g, (N u)_i <= g_i (default zero)
        """
        comm = MPI.COMM_WORLD if comm is None else comm
        K = _as_csr("K", K)
        N = _as_csr("N", N)
        T = _as_csr("T", T)
        n = K.shape[0]
        if K.shape != (n, n):
            raise InputError(f"K must be square, got shape {K.shape}")
        if n == 0:
            raise InputError("K is empty (0 x 0): the system needs at least one displacement DOF")
        m = N.shape[0]
        for name, A in (("N", N), ("T", T)):
            if A.shape != (m, n):
                raise InputError(f"{name} must have shape (m, n) = ({m}, {n}) to match K and N, got {A.shape}")
        loads = []
        for name, f in (("f1", f1), ("f2", f2)):
            try:
                f = np.asarray(f, dtype=float)
            except (TypeError, ValueError):
                raise InputError(f"load vector {name} must be n = {n} numbers, got {f!r:.80}") from None
            if f.ndim == 2 and 1 in f.shape:  # a column or a row
                f = f.ravel()
            if f.ndim != 1:
                raise InputError(f"load vector {name} has shape {f.shape}, expected ({n},) (n, the size of K)")
            if f.shape != (n,):
                raise InputError(f"load vector {name} has length {f.size}, expected n = {n} (the size of K)")
            if not np.all(np.isfinite(f)):
                raise InputError(f"load vector {name} has non-finite entries")
            loads.append(f)
        asym = abs(K - K.T).max() if K.nnz else 0.0
        if asym > 1e-10 * max(abs(K).max(), 1e-300):
            raise InputError(f"K must be symmetric; max |K - K^T| = {asym:.3e}")
        N.eliminate_zeros()
        T.eliminate_zeros()
        empty = np.flatnonzero((np.diff(N.indptr) == 0) & (np.diff(T.indptr) == 0))
        if empty.size:
            raise InputError(f"contact nodes {empty.tolist()} have zero rows in both N and T (fully clamped?)")
        no_normal = np.flatnonzero(np.diff(N.indptr) == 0)
        if no_normal.size:
            raise InputError(f"contact nodes {no_normal[:10].tolist()} have a zero row in N: a contact node needs a "
                             "normal direction (a node without a tangential unknown has a zero row in T instead)")
        _check_distinct_rows(N, T)
        _check_friction(friction, m)
        gap = _check_gap(gap, m)
        if rho is None:
            rho = default_rho(K, N, T)
        ranges = linalg.ownership(n, comm)
        return cls(
            K=linalg.mat_from_scipy(K, comm, ranges, ranges),
            N=linalg.mat_from_scipy(N, comm, None, ranges),
            T=linalg.mat_from_scipy(T, comm, None, ranges),
            f1=linalg.vec_from_numpy(loads[0], comm, ranges),
            f2=linalg.vec_from_numpy(loads[1], comm, ranges),
            friction=friction,
            rho=rho,
            geometry=geometry,
            gap=gap,
        )

    def __repr__(self):
        gap = f", gap in [{self.gap.min():.3g}, {self.gap.max():.3g}]" if self.has_gap else ""
        return f"ContactSystem(n={self.n}, m={self.m}, friction={self.friction!r}, rho={self.rho:.4g}{gap})"


def _check_distinct_rows(N, T):
    """InputError naming two contact nodes with the same rows of N and T: the same constraint twice,
    whose multipliers no load decides (every reduced system of the problem would be singular)."""
    B = sp.hstack([N, T], format="csr")
    B.sort_indices()
    seen = {}
    for i in range(B.shape[0]):
        lo, hi = B.indptr[i], B.indptr[i + 1]
        key = (B.indices[lo:hi].tobytes(), B.data[lo:hi].tobytes())
        if key in seen:
            raise InputError(f"contact nodes {seen[key]} and {i} have the same rows of N and T: the same contact "
                             "condition twice (remove one of them)")
        seen[key] = i


def check_alpha(alpha) -> float:
    """The load parameter as a finite float (InputError otherwise)."""
    try:
        value = float(alpha)
    except (TypeError, ValueError):
        raise InputError(f"alpha must be a finite number, got {alpha!r}") from None
    if not np.isfinite(value):
        raise InputError(f"alpha must be a finite number, got {alpha!r}")
    return value


def _overflow_hint(name) -> str:
    if name == "K":
        return "; check E (Young's modulus far outside 1e-6 .. 1e20 in the model's units?)"
    if name in ("f1", "f2"):
        return "; the tractions or body forces are too large: rescale the units"
    return ""


def _checksum(system) -> str:
    comm = system.comm
    ai, aj, av = system.K.getValuesCSR()
    local = (np.diff(np.asarray(ai)).astype(np.int64), np.asarray(aj, dtype=np.int64), np.asarray(av, dtype=float))
    parts = comm.gather(local, root=0) if comm.Get_size() > 1 else [local]
    digest = None
    if comm.Get_rank() == 0:
        h = hashlib.sha256(b"cfcontact-system-1")
        h.update(np.asarray([system.n, system.m], dtype=np.int64).tobytes())
        for k in range(3):  # row lengths, column indices, values of K, each in global row order
            for part in parts:
                h.update(np.ascontiguousarray(part[k]).tobytes())
        N, T = system.contact_maps()
        for A in (N, T):
            A = sp.csr_matrix(A)
            A.sort_indices()
            for arr in (np.diff(A.indptr).astype(np.int64), A.indices.astype(np.int64), A.data.astype(float)):
                h.update(np.ascontiguousarray(arr).tobytes())
        for v in (*system.loads_numpy(), system.friction_vector, np.asarray(system.gap, dtype=float),
                  np.asarray([system.rho])):
            h.update(np.ascontiguousarray(v, dtype=float).tobytes())
        digest = h.hexdigest()
    return comm.bcast(digest, root=0) if comm.Get_size() > 1 else digest


def _as_csr(name, A):
    try:
        if sp.issparse(A):
            A = sp.csr_matrix(A, dtype=float)
        else:
            arr = np.asarray(A, dtype=float)
            if arr.ndim == 1:
                arr = arr[None, :]
            if arr.ndim != 2:
                raise InputError(f"{name} must be a 2-D matrix, got an array of shape {arr.shape}")
            A = sp.csr_matrix(arr)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{name} is not a numeric matrix: {exc}") from exc
    if A.nnz and not np.all(np.isfinite(A.data)):
        raise InputError(f"{name} has non-finite entries")
    return A


def _check_friction(friction, m):
    try:
        arr = np.asarray(friction, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"friction must be a number >= 0 or one number per contact node, got {friction!r}") \
            from None
    if arr.ndim == 0:
        if not np.isfinite(arr) or arr < 0:
            raise InputError(f"friction coefficient F must be a finite number >= 0, got {float(arr)!r}")
        return float(arr)
    if arr.shape != (m,):
        raise InputError(f"friction must be a scalar or one value per contact node (shape ({m},)), got shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr) | (arr < 0))
    if bad.size:
        raise InputError(f"friction coefficients must be finite and >= 0; nodes {bad.tolist()} have {arr[bad].tolist()}")
    return arr.copy()


def _check_gap(gap, m):
    """The initial gap as a read-only (m,) float array (zeros for None)."""
    if gap is None:
        arr = np.zeros(m)
    elif np.ndim(gap) == 0 and not isinstance(gap, str):  # one number for every node
        try:
            arr = np.full(m, float(gap))
        except (TypeError, ValueError):
            raise InputError(f"gap must be a number or one number per contact node, got {gap!r}") from None
        if not np.isfinite(arr).all():
            raise InputError(f"gap must be finite, got {gap!r}")
    else:
        try:
            arr = np.array(gap, dtype=float).reshape(-1) if np.ndim(gap) <= 1 else np.array(gap, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"gap must be one number per contact node, got {gap!r}") from None
        if arr.shape != (m,):
            raise InputError(f"gap must have one value per contact node (shape ({m},)), got shape {arr.shape}")
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise InputError(f"gap must be finite; nodes {bad[:10].tolist()} have {arr[bad[:10]].tolist()}")
    arr.setflags(write=False)
    return arr
