"""PETSc/NumPy glue shared by every layer (no dolfinx here).

Row distribution convention: a global index range ``[0, n)`` is split over the
ranks of a communicator in contiguous blocks, as ``PETSc.DECIDE`` would
(:func:`ownership`).  Matrices and vectors built here follow it; :func:`gather_vec`
and :func:`gather_mat` return whole objects on every rank.
"""

from __future__ import annotations

from typing import Optional

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from cfcontact import native
from cfcontact.errors import SingularSystemError


def ownership(n: int, comm) -> np.ndarray:
    """Block boundaries ``r[0]=0 <= r[1] <= ... <= r[size]=n`` of an ``n``-range over ``comm``."""
    size = comm.Get_size()
    counts = np.full(size, n // size, dtype=np.int64)
    counts[: n % size] += 1
    return np.concatenate([[0], np.cumsum(counts)])


def owner_of(idx: np.ndarray, ranges: np.ndarray) -> np.ndarray:
    """Rank owning each global index."""
    return np.searchsorted(ranges, idx, side="right") - 1


def _redistribute(rows, payload, ranges, comm):
    """Send each (row, *payload) entry to the rank owning ``row``; return the received arrays."""
    size = comm.Get_size()
    rows = np.asarray(rows, dtype=np.int64)
    if size == 1:
        return rows, [np.asarray(p) for p in payload]
    dest = owner_of(rows, ranges)
    order = np.argsort(dest, kind="stable")
    send_counts = np.bincount(dest, minlength=size).astype(np.int64)
    recv_counts = np.empty(size, dtype=np.int64)
    comm.Alltoall(send_counts, recv_counts)
    sdispl = np.concatenate([[0], np.cumsum(send_counts)[:-1]])
    rdispl = np.concatenate([[0], np.cumsum(recv_counts)[:-1]])
    out = []
    for arr in [rows] + [np.asarray(p) for p in payload]:
        arr = np.ascontiguousarray(arr[order])
        recv = np.empty(int(recv_counts.sum()), dtype=arr.dtype)
        mpitype = MPI._typedict[arr.dtype.char]
        comm.Alltoallv([arr, send_counts, sdispl, mpitype], [recv, recv_counts, rdispl, mpitype])
        out.append(recv)
    return out[0], out[1:]


def mat_from_triplets(rows, cols, vals, shape, comm=MPI.COMM_WORLD, row_ranges=None, col_ranges=None):
    """Distributed AIJ matrix from triplets that any rank may hold for any row (duplicates add up)."""
    m, n = int(shape[0]), int(shape[1])
    row_ranges = ownership(m, comm) if row_ranges is None else np.asarray(row_ranges)
    col_ranges = ownership(n, comm) if col_ranges is None else np.asarray(col_ranges)
    r, (c, v) = _redistribute(rows, [np.asarray(cols, dtype=np.int64), np.asarray(vals, dtype=PETSc.ScalarType)], row_ranges, comm)
    rank = comm.Get_rank()
    r0, r1 = int(row_ranges[rank]), int(row_ranges[rank + 1])
    local = sp.csr_matrix((v, (r - r0, c)), shape=(r1 - r0, n))
    local.sum_duplicates()
    local.sort_indices()
    return _mat_from_local_csr(local, (r1 - r0, m), (int(col_ranges[rank + 1] - col_ranges[rank]), n), comm)


def _mat_from_local_csr(local, rsize, csize, comm):
    A = PETSc.Mat().createAIJ(
        size=(rsize, csize),
        csr=(local.indptr.astype(PETSc.IntType), local.indices.astype(PETSc.IntType), local.data.astype(PETSc.ScalarType)),
        comm=comm,
    )
    A.assemble()
    return A


def mat_from_scipy(A, comm=MPI.COMM_WORLD, row_ranges=None, col_ranges=None):
    """Distributed AIJ matrix from a SciPy/NumPy matrix given whole on every rank."""
    A = sp.csr_matrix(A, dtype=PETSc.ScalarType)
    m, n = A.shape
    row_ranges = ownership(m, comm) if row_ranges is None else row_ranges
    col_ranges = ownership(n, comm) if col_ranges is None else col_ranges
    rank = comm.Get_rank()
    local = A[int(row_ranges[rank]): int(row_ranges[rank + 1])]
    local.sort_indices()
    return _mat_from_local_csr(local, (local.shape[0], m), (int(col_ranges[rank + 1] - col_ranges[rank]), n), comm)


def vec_from_numpy(x, comm=MPI.COMM_WORLD, ranges=None):
    """Distributed Vec from an array given whole on every rank."""
    x = np.asarray(x, dtype=PETSc.ScalarType)
    ranges = ownership(x.size, comm) if ranges is None else ranges
    rank = comm.Get_rank()
    v = PETSc.Vec().createMPI((int(ranges[rank + 1] - ranges[rank]), x.size), comm=comm)
    v.getArray()[:] = x[int(ranges[rank]): int(ranges[rank + 1])]
    return v


def vec_from_triplets(idx, vals, n, comm=MPI.COMM_WORLD, ranges=None):
    """Distributed Vec from (index, value) pairs any rank may hold (duplicates add up)."""
    ranges = ownership(n, comm) if ranges is None else np.asarray(ranges)
    r, (v,) = _redistribute(idx, [np.asarray(vals, dtype=PETSc.ScalarType)], ranges, comm)
    rank = comm.Get_rank()
    r0, r1 = int(ranges[rank]), int(ranges[rank + 1])
    local = np.zeros(r1 - r0, dtype=PETSc.ScalarType)
    np.add.at(local, r - r0, v)
    vec = PETSc.Vec().createMPI((r1 - r0, n), comm=comm)
    vec.getArray()[:] = local
    return vec


def concat_ranks(comm, local: np.ndarray) -> np.ndarray:
    """The blocks ``local`` of all ranks, concatenated in rank order, on every rank."""
    if comm.Get_size() == 1:
        return local
    return np.concatenate(comm.allgather(local))


def gather_vec(v) -> np.ndarray:
    """The whole of a distributed Vec as a NumPy array on every rank."""
    return concat_ranks(v.getComm().tompi4py(), np.array(v.getArray(readonly=True), copy=True))


def gather_mat(A) -> sp.csr_matrix:
    """The whole of a distributed AIJ matrix as a SciPy CSR matrix on every rank."""
    comm = A.getComm().tompi4py()
    m, n = A.getSize()
    ai, aj, av = A.getValuesCSR()
    parts = comm.allgather((np.asarray(ai), np.asarray(aj), np.asarray(av)))
    data, indices, indptr = [], [], [np.zeros(1, dtype=np.int64)]
    offset = 0
    for ai_, aj_, av_ in parts:
        data.append(av_)
        indices.append(aj_)
        indptr.append(ai_[1:].astype(np.int64) + offset)
        offset += int(ai_[-1])
    return sp.csr_matrix((np.concatenate(data), np.concatenate(indices), np.concatenate(indptr)), shape=(m, n))


def local_csr(A) -> sp.csr_matrix:
    """The locally owned rows of an AIJ matrix, with global column indices."""
    m, n = A.getSize()
    r0, r1 = A.getOwnershipRange()
    ai, aj, av = A.getValuesCSR()
    return sp.csr_matrix((np.asarray(av).copy(), np.asarray(aj).copy(), np.asarray(ai).copy()), shape=(r1 - r0, n))


def rcm_order(A: sp.spmatrix) -> np.ndarray:
    """The reverse Cuthill-McKee order of the graph of A (symmetric, n x n): int64, new -> old."""
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    return np.asarray(reverse_cuthill_mckee(sp.csr_matrix(A), symmetric_mode=True), dtype=np.int64)


def rcm_envelope(A: sp.spmatrix, perm: Optional[np.ndarray] = None) -> int:
    """The entries of the lower triangle's envelope of A (symmetric, n x n) in reverse
    Cuthill-McKee order (``perm``: that order, :func:`rcm_order`, when the caller has it):
    sum over rows of (row - first column + 1), what a profile (skyline) Cholesky factor of A in
    that order holds.  O(nnz)."""
    A = sp.csr_matrix(A)
    if A.shape[0] == 0:
        return 0
    p = rcm_order(A) if perm is None else perm
    P = A[p][:, p].tocsr()
    first = np.minimum.reduceat(P.indices, P.indptr[:-1]) if P.nnz else np.arange(P.shape[0])
    rows = np.arange(P.shape[0])
    empty = np.diff(P.indptr) == 0
    first = np.where(empty, rows, np.minimum(first, rows))
    return int((rows - first + 1).sum())


#: EnvelopeCholesky.solve works on blocks of at most this many entries (n x columns) at a time
SOLVE_BLOCK_ENTRIES = 4_000_000
#: ... and row-major (native.ENV_ROW_COLS columns as vectors) from this many columns on; fewer two
#: at a time (a strip, n = 24 000: 2 columns 0.54 ms, row-major -- padded to 32 -- 2.4 ms;
#: 8 columns 2.8 and 3.2 ms; 12 columns 4.2 and 3.5 ms; 32 columns, one by one, 14.2 and 5.2 ms)
SOLVE_ROWS_MIN_COLUMNS = 10


class EnvelopeCholesky:
    """K = P^T L D L^T P for a sparse symmetric positive definite K (one rank): P the reverse
    Cuthill-McKee order of K's graph, L unit lower triangular and D diagonal, held in envelope
    (profile) storage -- each row of L from its first non-zero column to the diagonal -- and
    computed by :mod:`cfcontact.native`'s compiled kernels.  For the small and the long thin
    bodies whose RCM envelope is small (:data:`cfcontact.condensed.NATIVE_MAX_DOFS`,
    ``NATIVE_ENVELOPE_PER_DOF``) this is what PETSc's own Cholesky computes, without its
    symbolic phase and per-call set-up: on the two steel blocks (n = 1320, envelope 34 732
    entries, the same as PETSc's factor) 0.3-0.5 ms, its RCM order included, against PETSc's
    1.5-1.7 ms.  Its forward
    substitutions start at each right-hand side's first non-zero row in that order
    (:meth:`forward_gram`: S from B's rows), 32 columns at a time.

    :meth:`factor` returns None without the compiled library (the caller uses PETSc then) and
    raises SingularSystemError when a pivot is not positive (K singular or indefinite)."""

    def __init__(self, lib, perm: np.ndarray, first: np.ndarray, ptr: np.ndarray, v: np.ndarray):
        self._lib = lib
        self.n = perm.size
        self.perm = perm
        self.iperm = np.empty_like(perm)
        self.iperm[perm] = np.arange(self.n)
        self._first, self._ptr, self._v = first, ptr, v
        self._sqrt_d = np.sqrt(v[ptr[1:] - 1])
        self._perm2 = None  # (solve: two columns)
        self._args = (self.n, native.address(first), native.address(ptr), native.address(v))

    @classmethod
    def factor(cls, A: sp.spmatrix, perm: Optional[np.ndarray] = None) -> "EnvelopeCholesky | None":
        """The factor of A in the order ``perm`` (new -> old; default: :func:`rcm_order` of A)."""
        lib = native.library()
        if lib is None:
            return None
        A = sp.csr_matrix(A)
        n = A.shape[0]
        if A.shape != (n, n):
            raise ValueError(f"EnvelopeCholesky needs a square matrix, not {A.shape[0]} x {A.shape[1]}")
        if perm is None:
            perm = rcm_order(A)
        else:  # (a caller's order: checked, since the kernels index by it)
            perm = np.asarray(perm, dtype=np.int64)
            if perm.shape != (n,) or (n and (perm.min() < 0 or perm.max() >= n
                                             or np.bincount(perm, minlength=n).max() > 1)):
                got = f" from {perm.min()} to {perm.max()}" if perm.size else ""
                raise ValueError(f"EnvelopeCholesky: the order must be a permutation of 0 .. {n - 1} (K has {n} "
                                 f"rows), got {perm.size} entries{got}")
        iperm = np.empty(n, dtype=np.int64)
        iperm[perm] = np.arange(n)
        indptr, indices = A.indptr.astype(np.int64), A.indices.astype(np.int64)
        data = np.ascontiguousarray(A.data, dtype=np.float64)
        first, ptr = np.empty(n, dtype=np.int64), np.empty(n + 1, dtype=np.int64)
        a = native.address
        size = lib.cfc_env_pattern(n, a(indptr), a(indices), a(iperm), a(first), a(ptr))
        v = np.zeros(max(size, 1))
        lib.cfc_env_fill(n, a(indptr), a(indices), a(data), a(iperm), a(first), a(ptr), a(v))
        bad = lib.cfc_env_ldlt(n, a(first), a(ptr), a(v))
        if bad:
            dof = int(perm[bad - 1])
            raise SingularSystemError(f"K is singular or not positive definite: its Cholesky factorization broke "
                                      f"down at DOF {dof} (pivot {bad} of {n}); every body needs a Dirichlet "
                                      f"condition")
        return cls(lib, perm, first, ptr, v)

    @property
    def entries(self) -> int:
        """The factor's stored entries (its envelope)."""
        return int(self._ptr[-1])

    def solve(self, b: np.ndarray) -> np.ndarray:
        """K^-1 b (b: n, or n x k; at least SOLVE_ROWS_MIN_COLUMNS columns row-major,
        native.ENV_ROW_COLS at a time, fewer two at a time: :meth:`_solve2`)."""
        b = np.asarray(b, dtype=np.float64)
        if b.ndim == 2 and b.shape[1] >= SOLVE_ROWS_MIN_COLUMNS:
            return self._solve_rows(b)
        if b.ndim == 2 and b.shape[1] == 2:  # (a branch's values and rates)
            return self._solve2(b)
        if b.ndim == 2 and b.shape[1] > 2:  # two at a time
            out = np.empty(b.shape, order="F")
            for c in range(0, b.shape[1] - 1, 2):
                out[:, c:c + 2] = self._solve2(b[:, c:c + 2])
            if b.shape[1] % 2:
                out[:, -1] = self.solve(b[:, -1])
            return out
        X = np.asfortranarray(b[self.perm].reshape(self.n, -1))
        k = X.shape[1]
        self._lib.cfc_env_forward(*self._args, k, native.address(X), max(self.n, 1))
        self._lib.cfc_env_backward(*self._args, k, native.address(X), max(self.n, 1))
        out = np.empty_like(X)
        out[self.perm] = X
        return out.reshape(b.shape)

    def _solve2(self, b: np.ndarray) -> np.ndarray:
        """K^-1 b for two columns (n x 2), interleaved in one pass over the factor each way
        (``cfc_env_solve2``: the bits of two single solves, in 0.54 instead of 0.94 ms a call
        on the n = 24 000 strip, docs/bench.md Part C)."""
        if self._perm2 is None:  # the permutation of the interleaved entries (a 1-D gather: NumPy's
            self._perm2 = (2 * self.perm[:, None] + np.arange(2)).ravel()  # 2-D one of rows is slower)
        X = np.ascontiguousarray(b).reshape(-1)[self._perm2]
        self._lib.cfc_env_solve2(*self._args, native.address(X))
        out = np.empty((self.n, 2))
        out.reshape(-1)[self._perm2] = X
        return out

    def _solve_rows(self, b: np.ndarray) -> np.ndarray:
        """K^-1 b for the columns of b, row-major in blocks of at most about SOLVE_BLOCK_ENTRIES
        entries (a multiple of native.ENV_ROW_COLS columns)."""
        n, k = b.shape
        out = np.empty((n, k), order="F")
        block = native.ENV_ROW_COLS * max(1, SOLVE_BLOCK_ENTRIES // max(n * native.ENV_ROW_COLS, 1))
        for c0 in range(0, k, block):
            kc = min(block, k - c0)
            width = -(-kc // native.ENV_ROW_COLS) * native.ENV_ROW_COLS
            Y = np.zeros((n, width))
            Y[:, :kc] = b[self.perm, c0:c0 + kc]
            self._lib.cfc_env_forward_rowmajor(*self._args, kc, native.address(Y), width, None)
            self._lib.cfc_env_backward_rowmajor(*self._args, kc, native.address(Y), width)
            out[self.perm, c0:c0 + kc] = Y[:, :kc]
        return out

    def forward_gram(self, B: sp.csr_matrix, dense=()) -> tuple:
        """(G, y0): G = Y^T Y for Y = D^-1/2 L^-1 P [B^T, dense...] (k x k; B: k0 x n CSR without
        duplicate entries, ``dense``: full vectors), i.e. [B; dense^T] K^-1 [B^T, dense] -- S, the
        loads' data B K^-1 f, and f^T K^-1 f --, and Y's first column (for :meth:`backward_row`).
        Y is formed row-major, the columns ordered by their first non-zero row in P's order and
        substituted from there on, native.ENV_ROW_COLS at a time (one contiguous piece of each row per
        entry of L: vector operations); G by one symmetric product."""
        n, k0 = self.n, B.shape[0]
        k = k0 + len(dense)
        rows = np.repeat(np.arange(k0), np.diff(B.indptr))
        pos = self.iperm[B.indices]
        start = np.full(k, n, dtype=np.int64)
        np.minimum.at(start, rows, pos)
        start[k0:] = 0
        order = np.argsort(start, kind="stable")
        rank = np.empty(k, dtype=np.int64)
        rank[order] = np.arange(k)
        width = -(-k // native.ENV_ROW_COLS) * native.ENV_ROW_COLS
        Y = np.zeros((n, width))
        Y[pos, rank[rows]] = B.data
        for j, f in enumerate(dense):
            Y[:, rank[k0 + j]] = np.asarray(f, dtype=np.float64)[self.perm]
        start = np.ascontiguousarray(start[order])
        self._lib.cfc_env_forward_rowmajor(*self._args, k, native.address(Y), width, native.address(start))
        Y /= self._sqrt_d[:, None]
        G = Y.T @ Y  # (symmetric: BLAS' syrk)
        return G[np.ix_(rank, rank)], Y[:, rank[0]].copy()

    def backward_row(self, x: np.ndarray) -> np.ndarray:
        """K^-1 b from x = D^-1/2 L^-1 P b (a column of :meth:`forward_gram`'s Y)."""
        y = np.asfortranarray((x * self._sqrt_d).reshape(self.n, 1))
        self._lib.cfc_env_backward(*self._args, 1, native.address(y), max(self.n, 1))
        out = np.empty(self.n)
        out[self.perm] = y[:, 0]
        return out


def inertia(A):
    """(negative, zero, positive) eigenvalue counts of a symmetric AIJ matrix from its LDL^T
    (Cholesky) factorization, or None when this PETSc cannot tell (no MUMPS under MPI).  A
    factorization that meets a zero pivot (PETSc records it and fails the first solve) counts as
    one zero eigenvalue.

    Serial and small (n <= 2000): PETSc's own Cholesky (no pivoting; a negative pivot is counted,
    not refused); otherwise MUMPS' LDL^T with ICNTL(13) = 1 (inertia without ScaLAPACK) and ICNTL(24) = 1
    (null pivots detected)."""
    comm = A.getComm()
    parallel = comm.getSize() > 1 or A.getSize()[0] > 2000  # MUMPS' ordering beyond small K
    if parallel and not PETSc.Sys.hasExternalPackage("mumps"):
        return None
    ksp = PETSc.KSP().create(comm)
    try:
        ksp.setOperators(A)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("cholesky")
        if parallel:
            pc.setFactorSolverType("mumps")
            pc.setFactorSetUpSolverType()
            fm = pc.getFactorMatrix()
            fm.setMumpsIcntl(13, 1)
            fm.setMumpsIcntl(24, 1)
        else:
            pc.setFactorOrdering("rcm")
        try:
            ksp.setUp()
            x, b = A.createVecs()
            b.set(1.0)
            ksp.solve(b, x)
            failed = ksp.getConvergedReason() < 0
            x.destroy()
            b.destroy()
        except PETSc.Error:
            failed = True
        if failed:
            n = A.getSize()[0]
            return (0, 1, n - 1)
        return tuple(int(k) for k in pc.getFactorMatrix().getInertia())
    finally:
        ksp.destroy()


def local_finite_max(A) -> tuple:
    """(all finite?, largest |entry|) of the locally owned entries of an AIJ matrix or a Vec,
    reduced over the communicator (collective)."""
    comm = A.getComm().tompi4py()
    vals = np.asarray(A.getValuesCSR()[2]) if isinstance(A, PETSc.Mat) else np.asarray(A.getArray(readonly=True))
    finite = bool(np.all(np.isfinite(vals)))
    big = float(np.abs(vals[np.isfinite(vals)]).max(initial=0.0))
    if comm.Get_size() > 1:
        finite = comm.allreduce(finite, op=MPI.LAND)
        big = comm.allreduce(big, op=MPI.MAX)
    return finite, big


#: Veltkamp's splitting constant 2^27 + 1: a = hi + lo with hi, lo of 26 bits each, so that the
#: products of the halves are exact in double.
_SPLITTER = 134217729.0


def _split(a: np.ndarray):
    c = _SPLITTER * a
    hi = c - (c - a)
    return hi, a - hi


class ExactResidual:
    """r = b - A x for a sparse A (SciPy CSR: local rows, global columns) with every product and
    sum carried in double-double arithmetic, rounded to double once at the end: the residual of
    iterative refinement.  A solve's error is A's condition number times the rounding unit, and
    a residual formed in double (or in x87 extended precision, whose 64-bit rounding of
    |A| |x| is what a slender body's cancellation b = A x leaves as a floor: 1.5e-13 of B x on a
    20 x 1 strip) limits refinement to about that; with this one the refined x is correct to
    its own rounding (8e-17 on that strip).

    Products split exactly (a x = p + e, p = fl(a x)), sums by Knuth's two-sum, in the row order
    of A's sorted CSR entries.  By the compiled kernel of :mod:`cfcontact.native` when a C
    compiler is there (0.03 s per right-hand side at n = 1e6); else by NumPy, vectorized over the
    rows: A stored in ELLPACK slots (one array per position in a row, rows padded with zeros), so
    the loop is over the longest row (about 18 for P1 elasticity) and each step works on whole
    columns (0.5 s per right-hand side at n = 1e6; memory: four arrays of n x (longest row)).
    Both give the same bits."""

    def __init__(self, A: sp.csr_matrix):
        A = sp.csr_matrix(A)
        if not A.has_sorted_indices:
            A = A.sorted_indices()  # (a copy: the caller's matrix stays as it is)
        self.shape = A.shape
        self._kernel = native.dd_residual_kernel()
        if self._kernel is not None:  # A's rows as they are (cfcontact.native)
            self._csr = (A.indptr.astype(np.int64), A.indices.astype(np.int64), A.data.astype(np.float64))
            return
        n = A.shape[0]
        counts = np.diff(A.indptr)
        width = int(counts.max(initial=0))
        rows = np.repeat(np.arange(n), counts)
        slot = np.arange(A.nnz) - np.repeat(A.indptr[:-1], counts)
        vals = np.zeros((width, n))
        cols = np.zeros((width, n), dtype=np.int32 if A.shape[1] < 2**31 else np.int64)
        vals[slot, rows] = A.data
        cols[slot, rows] = A.indices
        self._slots = [(vals[s], *_split(vals[s]), cols[s]) for s in range(width)]

    @property
    def compiled(self) -> bool:
        """Is the compiled kernel used (else NumPy)?"""
        return self._kernel is not None

    def __call__(self, b: np.ndarray, x: np.ndarray) -> np.ndarray:
        """b - A x (b: local rows, x: all of A's columns; vectors or matrices with the same
        number of columns)."""
        b = np.asarray(b, dtype=float)
        x = np.asarray(x, dtype=float)
        vector = x.ndim == 1
        X = x[:, None] if vector else x
        if self._kernel is not None:
            r = native.dd_residual(self._kernel, *self._csr, b[:, None] if b.ndim == 1 else b, X)
            return r[:, 0] if vector else r
        xh, xl = _split(X)
        s = np.array(b[:, None] if b.ndim == 1 else b, dtype=float, copy=True)  # sum, leading part
        c = np.zeros_like(s)  # the sum's trailing part
        for a, ah, al, j in self._slots:
            a, ah, al = a[:, None], ah[:, None], al[:, None]
            xhj, xlj = xh[j], xl[j]
            p = a * (xhj + xlj)
            e = ((ah * xhj - p) + ah * xlj + al * xhj) + al * xlj  # a x = p + e exactly
            t = s - p  # two-sum: s - p = t + err exactly
            z = t - s
            c += ((s - (t - z)) - (p + z)) - e
            s = t
        r = s + c
        return r[:, 0] if vector else r
