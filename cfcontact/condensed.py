"""Condensed DirNeu backend: one factorization of K, then dense 2m x 2m solves.

With B = [N; T] (2m x n) and lam = (lam_n, lam_t), equation (1) gives u = K^-1 (f - B^T lam), so

    B u = w - S lam,    S = B K^-1 B^T (2m x 2m, dense),   w = B K^-1 f.

With an initial gap g (:attr:`ContactSystem.gap`) :meth:`CondensedSolver.load_data` returns
w = B K^-1 f - (g; 0) instead, so that w - S lam = (N u - g; T u): everything below then holds
with the gap.

DirNeu(Z, f) (docs/theory.md (9)) is then the dense system M(Z) lam = r(Z, w) with, per node i,

    normal row     : A_nu: (S lam)_i = w_i            I_nu: lam_n,i = 0
    tangential row : A_t : (S lam)_{m+i} = w_{m+i}    I_t : lam_t,i - F (1_{I_t+} - 1_{I_t-}) lam_n,i = 0

followed by u = K^-1 (f - B^T lam).  :class:`CondensedSolver` factors K once (on one rank and
for n <= NATIVE_MAX_DOFS or a small RCM envelope (NATIVE_ENVELOPE_PER_DOF) a Cholesky factor in
RCM order -- cfcontact.native's envelope kernels (:class:`cfcontact.linalg.EnvelopeCholesky`,
see ENVELOPE) or PETSc's own --, S = X X^T from the forward substitutions X of B's rows when
they fit; otherwise a PETSc KSP with MUMPS when available, which works under MPI), or forms
K^-1 B^T with multi-right-hand-side solves
(``MatMatSolve``: on one rank with MUMPS B^T as one sparse right-hand side, else dense blocks
of columns) only to get S, or takes S from MUMPS' Schur complement; it caches w for the loads seen
(f1, f2), and LU-factors the reduced system (free multipliers only, see ``_factor``) per
inactive-set combination (dense, cached).  :meth:`CondensedSolver.displacements` forms u for
many (alpha, lam) at once (one multi-RHS solve per block): the exact method stores only the
multipliers of a branch and forms u on demand (:class:`cfcontact.path.SolutionPath`).  It has the interface of
:class:`cfcontact.ssnm.DirNeuSolver` (``solve(Z, f)``, ``stats``, ``K_times``), so
``ssnm(..., solver=CondensedSolver(system))`` and ``trace_path(..., solver=...)`` use it.
Cost: O(n m) memory for K^-1 B^T; it pays off for small m (tens to a few hundred nodes).
"""

from __future__ import annotations

import logging
import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import Optional

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from petsc4py import PETSc

from cfcontact import linalg, native
from cfcontact.compat_petsc import factor_schur_complement, factor_set_schur_is
from cfcontact.errors import CfcontactError, InputError, SingularSystemError
from cfcontact.ssnm import (InactiveSets, SolverOptions, SolverStats, _default_solver_type, canonical_codes,
                            canonical_key)
from cfcontact.system import ContactSystem

log = logging.getLogger(__name__)

#: Form K^-1 B^T (n x 2m doubles) for S in one multi-RHS solve when it has at most this many
#: entries per rank; otherwise in column blocks of at most this many entries.
STORE_LIMIT = 50_000_000
#: By default S comes from MUMPS' Schur complement when K^-1 B^T (n x 2m) has at least this
#: many entries.  Below it the 2m solves cost a few milliseconds and give S about 100x more
#: accurately (two steel blocks, n = 1320: worst relative residual of the path 1e-11 instead
#: of 6e-10); above it the Schur complement is much cheaper (two blocks, n = 9744, m = 84: S
#: and K's factorization in 29 ms instead of 104 ms).
SCHUR_MIN_ENTRIES = 1_000_000
#: ... and only when the contact unknowns are at most this share of the DOFs (compact bodies):
#: along a long interface the Schur complement is neither faster than the solves (a 30 x 1 strip,
#: m = 1500: 20.7 s against 14.4 s) nor as accurate (residuals of (1)-(3) of 3e-9 instead of 2e-12
#: on a 4 x 1 strip, m = 200).
SCHUR_MAX_CONTACT_SHARE = 0.02
#: On one rank, K with at most this many DOFs is factored by PETSc's own sparse Cholesky (K is
#: SPD: no pivoting needed) in reverse Cuthill-McKee order, and S, w1, w2 come from forward
#: substitutions alone (:meth:`CondensedSolver._condense_forward`).  At this size MUMPS' fixed
#: cost dominates: the solver's set-up on the main demo (n = 1320) took 4.1 ms instead of 6.0 ms
#: with MUMPS' LU and its sparse-right-hand-side solve for S.  The band of an RCM-ordered 2D mesh
#: grows like sqrt(n): on the two-block meshes of the benchmark MUMPS was as fast at n = 1872 and
#: faster from n = 2880 (13 ms instead of 17 ms; 21 instead of 32 ms at n = 4104).
NATIVE_MAX_DOFS = 2000
#: Beyond NATIVE_MAX_DOFS PETSc's Cholesky is still taken when the envelope of K in RCM order (the
#: entries of that factor, :func:`cfcontact.linalg.rcm_envelope`) is at most this many per DOF:
#: long thin bodies, whose band does not grow with their length.  On the strips of benchmark
#: Part C (13.5 per DOF; n = 48 000) one solve took 0.57 ms instead of MUMPS' 12 ms and the
#: factorization 20 ms instead of 132 ms; on the two-block meshes (37 per DOF at n = 2880, 226 at
#: n = 1.2e5) MUMPS' factorization is as fast or faster and stays.  (S then comes from solves when
#: the forward substitutions' dense rows would exceed STORE_LIMIT entries.)
NATIVE_ENVELOPE_PER_DOF = 32
#: Where PETSc's Cholesky would be the default factorization of K (the two rules above), the same
#: factorization -- L D L^T in RCM order -- is computed by cfcontact.native's compiled kernels
#: (:class:`cfcontact.linalg.EnvelopeCholesky`) when they are there, and S, w1, w2 by forward
#: substitutions that start at each column's first non-zero row.  PETSc's symbolic phase and
#: per-call set-up dominate at this size: on the two steel blocks (n = 1320, m = 30) K's
#: factorization (its RCM order included) took 0.3-0.5 ms instead of 1.5-1.7 ms and S, w1, w2
#: 0.5-0.7 ms instead of 1.8 ms.  PETSc factors K
#: when solver_type is given or the user set options for K's solver (``-<prefix>K_...``).
ENVELOPE = True
#: S from MUMPS' Schur complement is kept only when it agrees with one solve with K to this
#: (relative) on a probe vector; else it is formed by solves.
SCHUR_CHECK_RTOL = 1e-11
#: Iterative refinement of the solves with K, residuals in double-double arithmetic
#: (:class:`cfcontact.linalg.ExactResidual`): at set-up one probe solve K x = B^T v is refined,
#: and when its first correction changes B x by more than this (relative), every solve that
#: forms S, w or u is refined (SolverOptions.refine: None), S by a low-rank correction
#: (:meth:`CondensedSolver._corrected`).  On a 20 x 1 strip (m = 1000) a solve with MUMPS' LU of
#: K is off by 2.7e-10 in B x (3.3e-9 at m = 2000), one step leaves 8e-17; residuals in double
#: precision do not converge (corrections stay at 5e-10): the error is K's condition number
#: times the rounding unit, which only a more precise residual removes (x87 extended precision
#: leaves 1.5e-13, which the path's points show as violations of 1e-9).  Below this threshold
#: (the seed-sized models: 5e-12 and 9e-12; on Debian 13 2.4e-11 and 4e-12) the solves are
#: accurate enough and refinement is not worth its set-up cost.  Above it, up to 1e-10, unrefined
#: solves can leave points beyond 1e-9 (the threshold sits between the main demo's 2.4e-11 on
#: Debian 13 and the m = 500 strips' 3.2e-11, 16 % from each: the probe is one deterministic solve):
#: Part B's n = 1.2e5 blocks (probe 7.7e-11) 1.1e-9 unrefined, 1.8e-12 refined; the m = 500 strip
#: with random loads at F = 30 (probe 3.2e-11) 2.3e-9 unrefined, and refined 2.3e-10 -- with its
#: branches corrected against K (POLISH_RTOL, 24 of 169): refined u shows what is left of S's
#: error after its correction, which unrefined u, sharing S's rounding, hides (refined without
#: that correction it measured 1.7e-9, with K factored by MUMPS: probe 4.7e-11).  The probe
#: does not depend on the loads: the uniform strip's is the same (6.6e-10 unrefined, 1.6e-10
#: refined).  SolverOptions(refine=True) forces refinement.
REFINE_RTOL = 2.7e-11
#: ... and above NATIVE_MAX_DOFS degrees of freedom, when it changes B x by more than this: one
#: probe vector does not tell which of these models need it (strips of L/H = 14, 5 cells across,
#: at F = 30: m = 500 probe 3.2e-11, unrefined points 4.9e-9; m = 700 probe 8.2e-12 -- below
#: REFINE_RTOL --, unrefined 2.1e-8, refined 6.6e-10; m = 400 probe 2.4e-11, 3.1e-10), and there
#: refinement costs a few per cent of the run.  At n <= NATIVE_MAX_DOFS it costs 16-30 % of the
#: whole exact run (the main demo, the two steel blocks), and the models measured there leave
#: at most 1e-11 unrefined (strips one cell across up to m = 250 at F = 30, probe 9e-13; the
#: main demo 1e-13 with probes of 5e-12 to 2.4e-11).
REFINE_RTOL_LARGE = 1e-12
#: Refinement steps are taken until a correction is below this (relative, in B x) or stops
#: shrinking tenfold, at most REFINE_MAX_STEPS; a probe that still needs more (K too
#: ill-conditioned for refinement to contract) is logged as a warning.
REFINE_TARGET = 1e-14
REFINE_MAX_STEPS = 3
#: A branch of the exact method is corrected against K itself (:meth:`CondensedSolver.true_rows`)
#: when S's remaining error (``s_error``, at least the rounding unit) times rho |w| exceeds this
#: share of the branch's indicators (the multipliers and rho B u; :meth:`needs_true`).  On a
#: slender body the data are the deflection the load alone would cause (the m = 2000 strip at
#: F = 30: rho |w| = 4e14 against multipliers of 3e6 and open gaps of 1e9), and the branch's
#: equations N u = g, T u = 0 are differences of such numbers: S's error (7e-15 of S lam, after
#: its correction) left closed nodes 2.8e-9 (relative) from their gap.  The correction -- the
#: equations' residual read from B u with u = K^-1 (f - B^T lam) by refined solves, solved with the
#: branch's factorization -- brings them to the rounding of u.  Two solves with K per branch (and
#: one per refinement step); the seed-sized models and strips up to m = 200 never need it, the
#: m = 500 strips at F = 30 in some branches (only refined models are considered: unrefined, u
#: shares S's rounding).
POLISH_RTOL = 1e-10
#: At most this many corrections per branch (each: one solve with the branch's factorization, two
#: with K); they stop when the equations' residual is within POLISH_RTOL of the indicators.
POLISH_MAX_STEPS = 3
#: ... and while the probe's refinement leaves more than this of B x (relative), every refined
#: solve takes one step more from then on: u and B u must carry the digits the correction is
#: for (the m = 4000 strip: 4.7e-8 after the first solve, 4.7e-15 after one step; with one step
#: closed nodes stayed 1.4e-9 from their gap at F = 30).
POLISH_SOLVE_RTOL = 1e-16
#: A formed point whose imposed rows of B u (N u = g at its closed nodes, T u = 0 at its sticking
#: ones) are off by more than this, relative to its size as (1)-(3) are measured, gets its
#: displacement shifted onto them (:meth:`CondensedSolver._consistent`).  u = K^-1 (f - B^T lam)
#: moves those rows by S times lam's own rounding, and rho |S| can be far above 1: a lumped model
#: with cond(K) = 8e7 (rho |S| = 2e8) had its points 2e-8 to 5e-8 from (1)-(3) with multipliers
#: right to 2e-11 (and the exact solution rounded to doubles verifies to 1e-16).
CONSISTENT_RTOL = 1e-10
#: ... only residuals up to this are rounding to be removed, or up to what lam's rounding can make
#: of them: CONSISTENT_LAM_ULPS units of it times rho max S_ii (the rows move by S times lam's
#: error; weighed by rho as (1)-(3) are measured); larger ones are left for verify to report (the
#: shift must not hide an error of the multipliers).  On bodies of very different stiffness rho
#: is the stiff side's and S the soft side's compliance: rho max S_ii is about the stiffness ratio
#: r, and the gaps of exact multipliers rounded to doubles are off by r times their rounding (two
#: 12 x 4 blocks at F = 0.6: 2e-6 of the point at r = 3e7, 5e-4 at r = 1e10, where the seed
#: method's full solves give 2e-13; shifted, 2.2e-11).
CONSISTENT_MAX_RTOL = 1e-6
CONSISTENT_LAM_ULPS = 1e4
#: ... and only states with at most this many imposed rows (one dense factorization of S's block
#: per state: 0.15 s at 2000 rows).
CONSISTENT_MAX_ROWS = 2000
#: The double-double residuals of many columns go in blocks of at most this many entries.
REFINE_BLOCK_ENTRIES = 40_000_000
#: S's correction to the accuracy of refined solves (:meth:`CondensedSolver._corrected`): random
#: columns per round that fit the correction, how many fewer directions than those it may have,
#: random columns that check it, and the largest rank tried before S is formed by solves instead.
CORRECTION_SKETCH = 14
CORRECTION_OVERSAMPLE = 4
CORRECTION_CHECK = 4
CORRECTION_MAX_RANK = 256


_getrf, _getrs = sla.lapack.dgetrf, sla.lapack.dgetrs  # LAPACK directly: less overhead per branch
_dger = sla.blas.dger  # the point model's rank-1 updates in place (Fortran-ordered)
# per-node state codes (ssnm.STATE_NAMES order) and lam_t / (F lam_n) of a slipping node by code
_OPEN, _STICK, _SLIP_P, _SLIP_M = 0, 1, 2, 3
_SLIP_SIGN = np.array([0.0, 0.0, 1.0, -1.0])
#: From this many rows on, a product or an LU solve with 2 or 3 right-hand sides goes column by
#: column (:func:`_times`, :func:`_lu_solve`).  The branches of the exact method have two (the
#: values and the rates), and OpenBLAS' gemm and getrs with so few columns were slower than as
#: many matrix-vector products and triangular solves: 1.5-2.2x at n = 500-1728 (gemm), 1.5-2.4x
#: at n = 800-1728 (getrs), single thread, Debian 12; about even near n = 300.
COLUMNWISE_MIN_ROWS = 400


#: The cached dense factorizations of the reduced systems (per set combination) are kept within
#: this many bytes, the newest first, besides the count limit (SolverOptions.cache, at least 64).
#: At m = 4000 one LU is 512 MB: 64 of them (the SSNM start at F = 30) took the m = 4000 strip of
#: Part C to 15 GB and the kernel's OOM killer.
DENSE_CACHE_BYTES = 1 << 30


def _trim_to_bytes(cache, nbytes, largest, limit=None):
    """Drop the oldest entries of the OrderedDict ``cache`` until its entries' ``nbytes(entry)``
    sum to at most ``limit`` (default DENSE_CACHE_BYTES); the newest entry always stays.
    ``largest``: an upper bound of one entry's bytes (no sum needed while count x largest fits)."""
    limit = DENSE_CACHE_BYTES if limit is None else limit
    if len(cache) * largest <= limit:
        return
    total = sum(nbytes(e) for e in cache.values())
    while total > limit and len(cache) > 1:
        total -= nbytes(cache.popitem(last=False)[1])


def _by_columns(apply, rows, X):
    """apply(X) (``rows`` rows), column by column when X has 2-3 columns and the operator at least
    COLUMNWISE_MIN_ROWS rows."""
    c = X.shape[1] if X.ndim == 2 else 0
    if c < 2 or c > 3 or rows < COLUMNWISE_MIN_ROWS:
        return apply(X)
    out = np.empty((rows, c))
    for j in range(c):
        out[:, j] = apply(X[:, j])
    return out


def _times(A, X):
    """A @ X: for two columns and a C-ordered A of at least COLUMNWISE_MIN_ROWS rows or columns
    (the rows of S of a few nodes too) by the compiled kernel that reads A once for both
    (:func:`cfcontact.native.gemv2`: 1.2 instead of 1.7 ms at 1728 rows, 5.9 instead of 11 ms at
    4000, as accurate), else :func:`_by_columns`."""
    if X.ndim == 2 and X.shape[1] == 2 and max(A.shape) >= COLUMNWISE_MIN_ROWS:
        Y = native.gemv2(A, X)
        if Y is not None:
            return Y
    return _by_columns(A.__matmul__, A.shape[0], X)


def _rows_t_times(At, rows, X):
    """At[rows].T @ X (A's columns ``rows`` times X, from the rows of a C-ordered At = A^T): for two
    columns of X and at least COLUMNWISE_MIN_ROWS columns of At by the compiled kernel, without
    gathering those rows (:func:`cfcontact.native.gemv2t`: 2.2-2.9x faster at 1728-8000 rows,
    as accurate), else gathered and multiplied by :func:`_times`."""
    if X.ndim == 2 and X.shape[1] == 2 and At.shape[1] >= COLUMNWISE_MIN_ROWS:
        Y = native.gemv2t(At, rows, X)
        if Y is not None:
            return Y
    return _times(At[rows].T, X)


def frictionless_nnls(S_nn: np.ndarray, w_n: np.ndarray) -> Optional[np.ndarray]:
    """lam_n of the frictionless problem in the condensed form -- lam_n >= 0, S_nn lam_n - w_n >= 0
    (the normal gaps of B u = w - S lam), complementary -- as the QP min 1/2 lam^T S_nn lam - w_n^T
    lam over lam >= 0, i.e. the non-negative least-squares problem min |R lam - R^-T w_n| with
    S_nn = R^T R (Lawson and Hanson's active-set method: finite, where SSNM can cycle); None when
    S_nn is not positive definite."""
    from scipy.optimize import nnls

    try:
        R = sla.cholesky(S_nn)
    except np.linalg.LinAlgError:
        return None
    return nnls(R, sla.solve_triangular(R, w_n, trans="T"))[0]


def _lu_solve(lu, piv, B, trans=0):
    """getrs(lu, piv, B) (``trans``: with the transpose): for two columns and the transpose from
    COLUMNWISE_MIN_ROWS rows on by the compiled kernel that reads the factor once for both
    (:func:`cfcontact.native.getrs2t`: 0.7 instead of 1.0 ms at 1728 rows, 4.7 instead of 8.2 ms
    at 4000, as accurate), else :func:`_by_columns`."""
    if trans and B.ndim == 2 and B.shape[1] == 2 and lu.shape[0] >= COLUMNWISE_MIN_ROWS:
        X = native.getrs2t(lu, piv, B)
        if X is not None:
            return X
    return _by_columns(lambda Y: _getrs(lu, piv, Y, trans=trans)[0], lu.shape[0], B)


class PathLoads:
    """Loads of the system's path f(alpha) = (1 - alpha) f1 + alpha f2 given by their exact
    coefficients on (f1, f2): columns of ``coef`` (3 x k: 1 - alpha as a double-double pair, and
    alpha; a rate column f2 - f1 is (-1, 0, 1)).  Solves with K that take them
    (:meth:`CondensedSolver.true_rows`, :meth:`~CondensedSolver.displacements`) form the
    residual f - K u - B^T lam with f's products and sums exact: on a slender body at F = 30 the
    rounding of f(alpha) in double, carried by K^-1 to B u, left a branch's point 7e-10 (relative)
    from its gap once its reference was moved along the branch, where the consistent point had
    9e-11."""

    def __init__(self, values=(), rates: int = 0):
        a = np.asarray(values, dtype=float).ravel()
        hi = 1.0 - a
        v = hi - 1.0  # two-sum of 1 and -alpha: 1 - alpha = hi + lo exactly
        lo = (1.0 - (hi - v)) + (-a - v)
        rate = np.tile(np.array([[-1.0], [0.0], [1.0]]), (1, int(rates)))
        self.coef = np.concatenate([np.vstack([hi, lo, a]), rate], axis=1)

    def vectors(self, f1: np.ndarray, f2: np.ndarray) -> np.ndarray:
        """The loads in double (n x k) from (local rows of) f1, f2."""
        c = self.coef
        return np.outer(f1, c[0] + c[1]) + np.outer(f2, c[2])

    def take(self, cols) -> "PathLoads":
        """The columns ``cols``."""
        out = PathLoads()
        out.coef = self.coef[:, cols]
        return out


@dataclass
class CondensedStats(SolverStats):
    """SolverStats plus the dense work: factorizations / linear_solves count sparse work on K
    (one solve per right-hand side, the 2m columns of K^-1 B^T included)."""

    dense_factorizations: int = 0
    dense_solves: int = 0
    dense_updates: int = 0
    #: branches corrected against K (see POLISH_RTOL)
    true_corrections: int = 0
    #: formed points whose displacement was shifted onto their imposed rows (see CONSISTENT_RTOL)
    consistent_points: int = 0

    def as_dict(self) -> dict:
        d = super().as_dict()
        d.update(dense_factorizations=self.dense_factorizations, dense_solves=self.dense_solves,
                 dense_updates=self.dense_updates, true_corrections=self.true_corrections,
                 consistent_points=self.consistent_points)
        return d


class CondensedSolver:
    """DirNeu(Z, f) through the condensed 2m x 2m system (see the module docstring).

    Parameters
    ----------
    system : ContactSystem
    options : SolverOptions (prefix: the KSP of K uses ``<prefix>K_``; solver_type; cache =
        how many dense LU factorizations of M(Z) to keep, at least 64).  By default, on one rank
        for n <= NATIVE_MAX_DOFS or a small envelope, K's Cholesky factor in RCM order by
        cfcontact.native's envelope kernels (``k_factorization`` "cholesky/envelope"; PETSc's
        own without a C compiler) with S from forward substitutions; solver_type "petsc":
        PETSc's own Cholesky there; "mumps" (the default otherwise) or another package: its LU
        of K.  ``-<prefix>K_pc_type`` etc. still apply (``setFromOptions``; given, they make
        PETSc factor K).
    schur : form S from the Schur complement of K on the contact DOFs, which MUMPS computes
        during the factorization (about the cost of the factorization instead of 2m solves).
        Default: when possible (one rank, MUMPS) and worth it (K^-1 B^T would have at least
        SCHUR_MIN_ENTRIES entries and the contact unknowns are at most SCHUR_MAX_CONTACT_SHARE of the
        DOFs); False: never (S by solves or forward substitutions); True:
        required (MUMPS' LU of K then).  S from the
        Schur complement is slightly less accurate (relative violations of (1)-(3) up to
        ~1e-9 instead of ~1e-11 on the demo mesh).
    store_columns : when S is formed by solves: all of K^-1 B^T at once (default: when it has
        at most STORE_LIMIT entries per rank), else in column blocks (False also skips the
        forward substitutions of K's Cholesky factor, which hold an array of that size).  It is never
        kept: u is always K^-1 (f - B^T lam) by one sparse solve, since K^-1 f - (K^-1 B^T) lam loses accuracy
        (contact forces nearly cancel the load; relative residual 4e-8 measured at n = 1.2e5).
    """

    def __init__(self, system: ContactSystem, options: Optional[SolverOptions] = None,
                 store_columns: Optional[bool] = None, schur: Optional[bool] = None):
        if system.m == 0:
            raise InputError("the condensed backend (the exact method, enumeration, friction maps) needs contact "
                             "nodes; this system has m = 0 (no contact: the problem is linear, K u = f)")
        self.system = system
        self.options = options or SolverOptions()
        self.stats = CondensedStats()
        self.comm = system.comm
        self.rank, self.size = self.comm.Get_rank(), self.comm.Get_size()
        self.n, self.m = system.n, system.m
        self.r0, self.r1 = system.K.getOwnershipRange()
        m = self.m
        self.nloc = self.r1 - self.r0
        self._K_local = None  # SciPy copy of K's local rows, for K_times (formed when first needed)
        N, T = system.contact_maps()
        self.B = sp.vstack([N, T]).tocsr()
        # 2m x nloc (B itself on one rank)
        self.B_local = self.B if (self.r0, self.r1) == (0, self.n) else self.B[:, self.r0:self.r1].tocsr()
        self.F = system.friction_vector
        self._F0 = self.F == 0.0
        self.no_tangent = np.asarray(system.no_tangent, dtype=bool)
        self._any_no_tangent = bool(self.no_tangent.any())
        self._updater = None  # factorization updates of the exact method's branches (_Updater)
        self._kernel = None  # the compiled branch kernel (_branch_kernel), made at the first branch
        self._imposed_cache: "OrderedDict[bytes, np.ndarray]" = OrderedDict()  # imposed_rows by state
        self._rcm = None  # K's RCM order where _native_fits computed it
        self.solver_type = self.options.solver_type or (
            "petsc" if self.size == 1 and not schur and self._native_fits() else _default_solver_type(self.size))
        self._lu: "OrderedDict[bytes, tuple]" = OrderedDict()
        self._lu_extra: dict = {}  # key -> (lu, rows of S on the support, positions of slip nodes' lam_n,
        #                                     their lam_t rows, their coefficients as a column)
        self._loads: list = []  # [(f, w)]
        #: wall times [s] of the set-up: "factorization" (KSP set-up of K), "condensation" (S)
        self.timings = {}
        # ---- factor K
        t0 = time.perf_counter()
        #: K's envelope Cholesky factor (linalg.EnvelopeCholesky) when it replaces PETSc's (see ENVELOPE)
        self._envelope = None
        if (ENVELOPE and self.options.solver_type is None and self.solver_type == "petsc" and self.size == 1
                and not self._k_options_given()):
            # (None without the compiled kernels; the RCM order _native_fits computed, if it did)
            self._envelope = linalg.EnvelopeCholesky.factor(self.K_local, self._rcm)
        self.ksp = None
        self._schur_is = None
        self._schur_dofs = None
        if self._envelope is not None:
            self.stats.factorizations += 1
            system.record_inertia((0, 0, self.n))  # (every pivot positive: K is positive definite)
            #: how K was factored: "<pc type>/<package>", e.g. "cholesky/petsc" or "lu/mumps", or
            #: "cholesky/envelope" (linalg.EnvelopeCholesky)
            self.k_factorization = "cholesky/envelope"
        else:
            self._factor_petsc(schur)
        self._x, self._b = system.K.createVecs()
        self.timings["factorization"] = time.perf_counter() - t0
        # ---- S = B K^-1 B^T
        t0 = time.perf_counter()
        self.store = (self.nloc * 2 * m <= STORE_LIMIT) if store_columns is None else bool(store_columns)
        S = self._schur_from_factor() if self._schur_dofs is not None else None
        if S is None and schur:
            raise SingularSystemError("the Schur complement of K could not be read from MUMPS (schur=True)")
        self._K_exact = None  # K's local rows for the refinement's residuals (linalg.ExactResidual)
        #: ... and [K, B^T, -f1, -f1, -f2]'s, for residuals exact in the multipliers and in the
        #: path's loads too (PathLoads; zero coefficients for other loads)
        self._KBF_exact = None
        self._f_local = None  # the local rows of (f1, f2) (_loads_local)
        #: steps of iterative refinement applied to every solve with K (see REFINE_RTOL), and the
        #: relative correction of B x that the first step made on the set-up's probe solve (None:
        #: no probe)
        self.refine_steps, self.solve_error, self._correction_rtol, self._probed = 0, None, None, False
        #: what the probe's refinement left (relative, in B x), and the refinement steps added once
        #: branches are corrected against K while that is above POLISH_SOLVE_RTOL (see against_K)
        self.refine_floor, self.polish_steps = None, 0
        #: rank of the correction that made S as accurate as refined solves (0: none needed), and
        #: what its check vectors left of S's error (relative; None: S not corrected)
        self.correction_rank, self.s_error = 0, None
        self._s_colmax = None  # max_i |S_ij| (needs_true)
        #: every branch of the exact method is corrected against K (see needs_true)
        self.true_always = False
        #: the smallest residual of a branch's equations (relative to the size of its terms) that
        #: a correction against K failed to halve: the rounding floor of the measure (see against_K)
        self.polish_floor = None
        if S is not None:
            self._probe_refinement()
            if self.refine_steps:
                self._loads.clear()  # (refined w1, w2 come with S's correction)
                S = self._corrected(S, required=bool(schur))
            # (a corrected S agrees with refined solves on random vectors: the check below is done)
            if S is not None and not schur and not self.refine_steps and not self._schur_accurate(S):
                S = None  # (a slender or stiff-contrast model: the solves are accurate, the Schur complement not)
        #: how S was formed: "schur" (MUMPS Schur complement on the contact DOFs), "forward"
        #: (forward substitutions with K's Cholesky factor) or "solves" (2m columns)
        self.condensation = "schur" if S is not None else "solves"
        if S is None:
            if (self.k_factorization in ("cholesky/petsc", "cholesky/envelope") and store_columns is not False
                    and (2 * m + 2) * self.n <= STORE_LIMIT):
                S = self._condense_forward()  # (checks K's regularity first: a clear error if singular)
                if S is not None:
                    self.condensation = "forward"
            if S is None:
                S = self._schur()
            self._probe_refinement()
            if self.refine_steps:
                self._loads.clear()  # w1, w2 of the condensation came from unrefined solves
                S = self._corrected(S, required=True)
        self.S = np.ascontiguousarray(S)
        #: S^T, C-ordered: its rows are S's columns (S lam over few non-zero lam by rows); S itself
        #: when S is exactly symmetric, else a copy, 2m x 2m more memory (S by unrefined solves is
        #: not symmetrized, see :meth:`_schur`; a corrected S is)
        self.St = self.S if np.array_equal(self.S, self.S.T) else np.ascontiguousarray(self.S.T)
        self.timings["condensation"] = time.perf_counter() - t0

    def _k_options_given(self) -> bool:
        """Has the user set PETSc options for K's solver (``-<prefix>K_...``)?  Then PETSc factors it."""
        prefix = self.options.prefix + "K_"
        return any(name.startswith(prefix) for name in PETSc.Options().getAll())

    def _factor_petsc(self, schur):
        """K's factorization by a PETSc KSP (Cholesky or LU, see solver_type), with MUMPS' Schur
        complement requested when wanted (see ``schur``)."""
        m = self.m
        system = self.system
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOperators(system.K)
        ksp.setType("preonly")
        pc = ksp.getPC()
        if self.solver_type == "petsc" and self.size == 1:
            pc.setType("cholesky")  # K is SPD: PETSc's Cholesky needs no pivoting
            pc.setFactorOrdering("rcm")
        else:
            pc.setType("lu")
            pc.setFactorSolverType(self.solver_type)
        ksp.setOptionsPrefix(self.options.prefix + "K_")
        ksp.setFromOptions()
        if pc.getFactorSolverType() == "mumps":
            pc.setFactorSetUpSolverType()
            fm = pc.getFactorMatrix()
            if not PETSc.Options().hasName(self.options.prefix + "K_mat_mumps_icntl_14"):
                # MUMPS' default workspace estimate (ICNTL(14) = 20%) is too small for dense couplings
                fm.setMumpsIcntl(14, 100)
            if not PETSc.Options().hasName(self.options.prefix + "K_mat_mumps_icntl_24"):
                # null pivot detection: MUMPS' LU of a K with a rigid-body mode does not fail (its
                # solves come back some 1e15 times too large); with it, INFOG(28) counts them
                fm.setMumpsIcntl(24, 1)
            if schur or (schur is None and self.size == 1 and self.n * 2 * m >= SCHUR_MIN_ENTRIES
                         and 2 * m <= SCHUR_MAX_CONTACT_SHARE * self.n):
                if self.size > 1:
                    raise InputError("schur=True: PETSc's MUMPS interface has no parallel Schur complement")
                self._request_schur(fm, required=bool(schur))
        elif schur:
            raise InputError(f"schur=True needs MUMPS as the direct solver of K, not "
                             f"{pc.getFactorSolverType() or self.solver_type!r}")
        try:
            ksp.setUp()
        except PETSc.Error as exc:
            raise SingularSystemError(f"factorization of K failed (is K singular? every body needs a Dirichlet "
                                      f"condition): PETSc error {exc.ierr}") from exc
        if pc.getFactorSolverType() == "mumps" and pc.getFactorMatrix().getMumpsInfog(28) > 0:
            nulls = pc.getFactorMatrix().getMumpsInfog(28)
            ksp.destroy()
            raise SingularSystemError(f"K is singular: MUMPS found {nulls} null pivot(s) in its factorization (a "
                                      f"rigid-body motion left free; every body needs a Dirichlet condition)")
        self.stats.factorizations += 1
        self.ksp = ksp
        self.k_factorization = f"{pc.getType()}/{pc.getFactorSolverType()}"

    def _native_fits(self) -> bool:
        """Is PETSc's own Cholesky (RCM order) the better factorization of K (one rank): n at most
        NATIVE_MAX_DOFS, or an RCM envelope of at most NATIVE_ENVELOPE_PER_DOF per DOF?"""
        if self.n <= NATIVE_MAX_DOFS:
            return True
        self._rcm = linalg.rcm_order(self.K_local)  # (K_local: kept; the envelope factor reuses the order)
        return linalg.rcm_envelope(self.K_local, self._rcm) <= NATIVE_ENVELOPE_PER_DOF * self.n

    def _schur_accurate(self, S) -> bool:
        """Does S from the Schur complement agree with B K^-1 B^T applied by one solve with K, on a
        fixed random vector, within SCHUR_CHECK_RTOL?  (On slender bodies the Schur complement lost
        three to four digits more than the solves: residuals of (1)-(3) of 4e-7 instead of 4e-10
        on a 30 x 1 strip of m = 1500 contact nodes.)"""
        rng = np.random.default_rng(12345)
        v = rng.standard_normal(2 * self.m)
        x = linalg.concat_ranks(self.comm, self._ksolve_refined(self.B_local.T @ v))
        ref = self.B @ x
        err = np.abs(S @ v - ref).max() / max(np.abs(ref).max(), 1e-300)
        if err > SCHUR_CHECK_RTOL:
            log.info("S from the Schur complement is off by %.2g (relative) on a probe; forming it by solves", err)
            return False
        return True

    # ------------------------------------------------------- Schur complement
    def _request_schur(self, fm, required=False):
        """Ask MUMPS for the Schur complement of K on the contact DOFs (serial only: PETSc's MUMPS
        interface does not support parallel Schur complements; :mod:`cfcontact.compat_petsc`
        makes the call petsc4py does not wrap); any failure falls back to solves."""
        B = sp.csc_matrix(self.B)
        dofs = np.flatnonzero(np.diff(B.indptr) > 0)
        if self.m == 0 or dofs.size == 0 or dofs.size >= self.n:
            if required:
                raise InputError("schur=True needs contact DOFs and at least one other DOF")
            return
        try:
            is_ = factor_set_schur_is(fm, dofs)
        except (RuntimeError, PETSc.Error) as exc:  # no Schur complement from this PETSc: solves instead
            if required:
                raise InputError(f"schur=True: cannot request the Schur complement from MUMPS ({exc})") from exc
            log.info("MUMPS Schur complement unavailable (%s); S is formed by solves", exc)
            return
        self._schur_is, self._schur_dofs = is_, dofs

    def _schur_from_factor(self) -> Optional[np.ndarray]:
        """S = B_c S_c^-1 B_c^T with S_c the Schur complement of K on the contact DOFs c:
        (K^-1)_cc = S_c^-1.  Read right after the factorization (PETSc factors S_c in place at
        the first solve)."""
        Sc = factor_schur_complement(self.ksp.getPC().getFactorMatrix(), self._schur_dofs.size)
        if Sc is None:
            log.info("MatFactorGetSchurComplement gave no Schur complement; S is formed by solves")
            return None
        if not np.all(np.isfinite(Sc)):
            return None
        Sc = 0.5 * (Sc + Sc.T)
        Bc = self.B[:, self._schur_dofs].toarray()
        try:
            X = sla.cho_solve(sla.cho_factor(Sc, check_finite=False), Bc.T, check_finite=False)
        except np.linalg.LinAlgError:
            X = sla.solve(Sc, Bc.T, check_finite=False)
        S = Bc @ X
        return 0.5 * (S + S.T)

    # ----------------------------------------------------------- K solves
    def _ksolve(self, rhs_local: np.ndarray) -> np.ndarray:
        if self._envelope is not None:
            self.stats.linear_solves += 1
            return self._envelope.solve(rhs_local)
        self._check_alive()
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

    # ------------------------------------------------- iterative refinement
    def _probe_refinement(self):
        """Set refine_steps, solve_error and the tolerance of S's correction from :meth:`_probe`
        (once)."""
        if self._probed:
            return
        self._probed = True
        self.refine_steps, self.solve_error, floor = self._probe()
        self.refine_floor = floor
        self._correction_rtol = max(REFINE_TARGET, 10 * floor) if self.refine_steps else None

    def _probe(self):
        """(steps, error, floor): refine one solve K x = B^T v (v fixed, random) with double-double
        residuals; error = the first correction's share of B x (when it is below REFINE_RTOL, or
        REFINE_RTOL_LARGE above NATIVE_MAX_DOFS: no refinement, steps = 0), steps = how many
        corrections it takes to get below REFINE_TARGET or to stop shrinking, floor = the
        correction after those steps; or as SolverOptions.refine says.  Two solves with K when no
        refinement is needed, one more per step."""
        opt = self.options.refine
        if self.m == 0:
            return 0, None, None
        b = self.B_local.T @ np.random.default_rng(12345).standard_normal(2 * self.m)
        if opt is False:
            return 0, None, None
        x = self._ksolve(b)
        scale = max(np.abs(self._allreduce(self.B_local @ x)).max(), 1e-300)
        corrections = []
        threshold = REFINE_RTOL if self.n <= NATIVE_MAX_DOFS else REFINE_RTOL_LARGE
        while True:
            d = self._ksolve(self._kresidual(b, x))
            x += d
            c = np.abs(self._allreduce(self.B_local @ d)).max() / scale
            if not corrections and not opt and c <= threshold:
                return 0, c, None
            if corrections and (c <= REFINE_TARGET or c > 0.1 * corrections[-1]):
                break  # after len(corrections) steps the error is c
            corrections.append(c)
            if len(corrections) > REFINE_MAX_STEPS:
                log.warning("iterative refinement of solves with K does not reach %.0e in %d steps (corrections %s of "
                            "B x): K is too ill-conditioned for double precision; its refined solves stay off by "
                            "about %.1e", REFINE_TARGET, REFINE_MAX_STEPS, ", ".join(f"{c:.1e}" for c in corrections), c)
                break
        steps = min(len(corrections), REFINE_MAX_STEPS)
        log.info("solves with K are off by %.1e (relative, in B x): refined with %d step(s) of double-double "
                 "residuals to %.1e", corrections[0], steps, c)
        return steps, corrections[0], c

    def _kresidual(self, b: np.ndarray, x_local: np.ndarray, lam: Optional[np.ndarray] = None,
                   coef: Optional[np.ndarray] = None) -> np.ndarray:
        """b - K x (local rows; x: local rows of one vector or of the columns of a matrix),
        computed in double-double arithmetic and rounded to double.  With ``lam`` (2m, or 2m x k
        as x): b - K x - B^T lam, B^T lam's products and sums in the same arithmetic -- not
        b - B^T lam formed in double first, whose rounding (of f against the contact forces
        that nearly cancel it) K^-1 carries to B u as noise that no correction of lam can reduce.
        With ``coef`` (3 x k, :class:`PathLoads`; b is then not used): f - K x - B^T lam for the
        path's loads f = f1 (coef[0] + coef[1]) + f2 coef[2], exact as well."""
        x = linalg.concat_ranks(self.comm, x_local)
        if lam is None:
            if self._K_exact is None:
                self._K_exact = linalg.ExactResidual(self.K_local)
            return self._K_exact(b, x)
        lam = np.asarray(lam, dtype=float).reshape((-1,) + x.shape[1:])
        if self._KBF_exact is None:  # (one matrix for both: zero coefficients add exact zeros)
            f1l, f2l = self._loads_local()
            F = sp.csr_matrix(-np.column_stack([f1l, f1l, f2l]))
            self._KBF_exact = linalg.ExactResidual(sp.hstack([self.K_local, self.B_local.T, F], format="csr"))
        if coef is None:
            coef = np.zeros((3,) + x.shape[1:])
        else:
            b = np.zeros(x_local.shape)
            coef = np.asarray(coef, dtype=float).reshape((3,) + x.shape[1:])
        return self._KBF_exact(b, np.concatenate([x, lam, coef]))

    def _loads_local(self) -> tuple:
        """The local rows of the system's loads (f1, f2) (kept)."""
        if self._f_local is None:
            f1, f2 = self.system.loads_numpy()
            self._f_local = (np.array(f1[self.r0:self.r1]), np.array(f2[self.r0:self.r1]))
        return self._f_local

    def _ksolve_refined(self, rhs_local: np.ndarray, lam: Optional[np.ndarray] = None) -> np.ndarray:
        """K^-1 rhs (local rows of one vector), refined with self.refine_steps steps; with
        ``lam``: K^-1 (rhs - B^T lam), the residuals exact in lam (see :meth:`_kresidual`)."""
        x = self._ksolve(rhs_local if lam is None else rhs_local - self.B_local.T @ lam)
        for _ in range(self.refine_steps + self.polish_steps):
            x += self._ksolve(self._kresidual(rhs_local, x, lam))
        return x

    def _refine_columns(self, X: np.ndarray, rhs, lams: Optional[np.ndarray] = None,
                        coef: Optional[np.ndarray] = None) -> np.ndarray:
        """X = K^-1 rhs (local rows, nloc x k), corrected in place by self.refine_steps steps
        (and polish_steps), in blocks of columns; ``rhs``: the right-hand sides (nloc x k).  With
        ``lams`` (2m x k): X = K^-1 (rhs - B^T lams), the residuals exact in lams, and with
        ``coef`` (3 x k, :class:`PathLoads`) in the path's loads, which rhs then are (see
        :meth:`_kresidual`).  Collective under MPI."""
        steps = self.refine_steps + self.polish_steps
        if not steps or X.shape[1] == 0:
            return X
        k = X.shape[1]
        block = max(1, REFINE_BLOCK_ENTRIES // max(self.n, 1))  # self.n: the same on every rank
        for c0 in range(0, k, block):
            sl = slice(c0, min(k, c0 + block))
            lam = None if lams is None else lams[:, sl]
            c = None if coef is None else coef[:, sl]
            for _ in range(steps):
                X[:, sl] += self._ksolve_dense(np.asfortranarray(self._kresidual(rhs[:, sl], X[:, sl], lam, c)))
        return X

    def _s_exact(self, V: np.ndarray, loads=()) -> tuple:
        """(B K^-1 B^T V, B K^-1 F) by refined solves, V 2m x k, F the ``loads`` (full vectors) as
        columns: one multi-RHS solve (and one per refinement step) for all of them."""
        k = V.shape[1]
        rhs = np.empty((self.nloc, k + len(loads)), order="F")
        rhs[:, :k] = self.B_local.T @ V
        for j, f in enumerate(loads):
            rhs[:, k + j] = f[self.r0:self.r1]
        BX = self._allreduce(np.ascontiguousarray(self.B_local @ self._refine_columns(self._ksolve_dense(rhs), rhs)))
        return BX[:, :k], BX[:, k:]

    def _corrected(self, S: np.ndarray, required: bool) -> Optional[np.ndarray]:
        """S (from unrefined solves, forward substitutions or the Schur complement) corrected to
        the accuracy of refined solves; the system's loads B K^-1 (f1, f2) by refined solves ride
        along in the first round (cached for load_data).

        S's error E = B K^-1 B^T - S is symmetric and lies, to rounding, in the span of a few
        vectors (those of K's softest modes, where its condition number acts: on a 20 x 1 strip,
        m = 1000, E's singular values fall from 6e-8 to 2e-14 of |S| in eight).  One round: Y =
        E Omega for CORRECTION_SKETCH + CORRECTION_CHECK random columns from one multi-RHS refined
        solve (Y = B K^-1 B^T Omega - S Omega); from the sketch columns, Q = Y's leading left
        singular vectors (at most CORRECTION_SKETCH - CORRECTION_OVERSAMPLE of them) and, E
        being symmetric, E ~ Q T Q^T with T fitted to Q^T Y = T Q^T Omega (a single-pass
        randomized approximation: no second solve); S += Q T Q^T.  The check columns, which the
        fit has not seen, then measure what is left: at most REFINE_TARGET (or ten times the
        probe's remaining correction) of |S| ends it, else the next round starts from S so
        corrected.  Cost per round: one multi-RHS solve of 18 columns (+2 for the loads), and
        one more per refinement step after double-double residuals of as many columns (cheap with
        :mod:`cfcontact.native`), instead of 2m columns.  At n = 1e6 (two
        blocks, m = 864) one round of 5 s; there E's singular values fall from 1 to 3e-5 in
        four and then stay at 2e-7 (rounding).  S is made symmetric first (by solves it is not: see
        :meth:`_schur`; refined, u is formed as accurately as S).  None when the error is
        not caught by CORRECTION_MAX_RANK columns (then the caller forms S otherwise), or S with a
        warning when ``required``."""
        m2 = S.shape[0]
        rng = np.random.default_rng(20261202)
        loads = [] if self._loads else list(self.system.loads_numpy())
        ks, kv = CORRECTION_SKETCH, CORRECTION_CHECK
        if m2 <= ks + kv:  # small: S itself by refined solves
            Se, W = self._s_exact(np.eye(m2), loads)
            self._cache_loads(loads, W)
            S[...] = 0.5 * (Se + Se.T)
            self.correction_rank, self.s_error = m2, 0.0
            return S
        if not np.array_equal(S, S.T):
            # S by unrefined solves is not symmetric (see _schur); its antisymmetric part is error
            # too (B K^-1 B^T is symmetric), and with it removed E is symmetric
            S[...] = 0.5 * (S + S.T)
        rank = 0
        while True:
            Om = rng.standard_normal((m2, ks + kv))
            SOm, W = self._s_exact(Om, loads)
            self._cache_loads(loads, W)
            loads = []
            Y = SOm - S @ Om
            scale = max(np.abs(SOm).max(), 1e-300)
            err = np.abs(Y).max() / scale
            if err > self._correction_rtol:
                if rank + ks > min(CORRECTION_MAX_RANK, m2):
                    msg = f"S is off by {err:.1e} (relative) from refined solves after a correction of rank {rank}"
                    if required:
                        log.warning("%s; kept as it is", msg)
                        self.correction_rank, self.s_error = rank, err
                        return S
                    log.info("%s; S is formed by solves instead", msg)
                    return None
                # E ~ Q T Q^T from the sketch columns
                U, sig, _ = np.linalg.svd(Y[:, :ks], full_matrices=False)
                r = int(min(np.count_nonzero(sig > 0.1 * self._correction_rtol * scale), ks - CORRECTION_OVERSAMPLE))
                Q = U[:, :max(r, 1)]
                T = (Q.T @ Y[:, :ks]) @ np.linalg.pinv(Q.T @ Om[:, :ks])
                QT = Q @ (0.5 * (T + T.T))
                C = QT @ Q.T
                S += 0.5 * (C + C.T)  # (exactly symmetric: S stays so if it was)
                rank += Q.shape[1]
                # what is left, seen by the check columns
                err = np.abs(Y[:, ks:] - QT @ (Q.T @ Om[:, ks:])).max() / scale
            if err <= self._correction_rtol:
                self.correction_rank, self.s_error = rank, err
                log.info("S corrected by rank %d: %.1e (relative) left on %d random vectors", rank, err, kv)
                return S

    def _cache_loads(self, loads, W):
        """Keep w_j = B K^-1 f_j (the columns of W) for load_data."""
        self._loads.extend((np.array(f, copy=True), W[:, j].copy()) for j, f in enumerate(loads))

    def _ksolve_dense(self, rhs: np.ndarray) -> np.ndarray:
        """K^-1 applied to the columns of ``rhs`` (local rows, nloc x k): one multi-RHS solve (MatMatSolve)."""
        k = rhs.shape[1]
        if self._envelope is not None:
            self.stats.linear_solves += k
            return self._envelope.solve(rhs)
        self._check_alive()
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

    def _condense_forward(self) -> Optional[np.ndarray]:
        """S and w1, w2 = B K^-1 (f1, f2) from forward substitutions alone, with K's Cholesky factor
        (one rank; the envelope factor's :meth:`~cfcontact.linalg.EnvelopeCholesky.forward_gram`,
        or PETSc's K = U^T D U: MatForwardSolve gives x = (U^T D^(1/2))^-1 b), so with X the
        forward substitutions of B's rows, B K^-1 B^T = X X^T and B K^-1 f = X x_f -- half of each
        solve, and S symmetric positive semidefinite by construction.  One check at the end: the
        backward substitution of X's first row gives z = K^-1 b_0 (b_0 = B's first row), which
        must satisfy K z = b_0 with b_0 . z = S[0, 0] (else None: S by full solves), and a
        condition-number bound |K| |z| / |b_0| beyond 1e14 means K is singular (rigid-body mode:
        a body without Dirichlet condition) -- SingularSystemError."""
        m2 = 2 * self.m
        if m2 == 0:
            return None
        fs = self.system.loads_numpy()
        B = self.B
        if not B.has_canonical_format:
            B = B.copy()
            B.sum_duplicates()
        if self._envelope is not None:  # all columns in one call, each from its first non-zero row
            G, x0 = self._envelope.forward_gram(B, fs)
            finite = np.isfinite(G).all() and np.isfinite(x0).all()
            S, W = G[:m2, :m2], G[:m2, m2:]
            b0 = np.zeros(self.n)
            b0[B.indices[:B.indptr[1]]] = B.data[:B.indptr[1]]
            backward = self._envelope.backward_row
        else:
            fm = self.ksp.getPC().getFactorMatrix()
            X = self._petsc_forward(fm, B, fs)
            if X is None:
                return None
            b0 = X[m2 + 2]  # (the work row holding B's first row)
            finite = np.isfinite(X[:m2 + 2]).all()
            XB, x0 = X[:m2], X[0]
            S = XB @ XB.T
            W = XB @ X[m2:m2 + 2].T

            def backward(x):
                z = np.empty(self.n)
                self._on_arrays(fm.solveBackward, x, z)
                return z
        self.stats.linear_solves += m2 + 2
        if not finite:
            raise SingularSystemError("K is singular or not positive definite (its Cholesky factorization broke "
                                      "down; every body needs a Dirichlet condition)")
        # check: z = K^-1 b_0 by the backward substitution of x_0
        z, Kz = backward(x0), np.empty(self.n)
        self.stats.linear_solves += 1
        self._on_arrays(self.system.K.mult, z, Kz)
        nb, nz = np.abs(b0).max(), np.abs(z).max()
        knorm = self.system.K.norm(PETSc.NormType.INFINITY)
        if not (np.isfinite(z).all() and knorm * nz <= 1e14 * nb):
            raise SingularSystemError(f"K is singular or nearly so (condition number at least "
                                      f"{knorm * nz / nb:.1e}; every body needs a Dirichlet condition)")
        if np.abs(Kz - b0).max() > 1e-8 * knorm * nz or abs(b0 @ z - S[0, 0]) > 1e-8 * abs(S[0, 0]):
            log.warning("forward substitutions with K's Cholesky factor do not give B K^-1 B^T = X X^T here; "
                        "S by solves")
            return None
        self._cache_loads(fs, W)
        return 0.5 * (S + S.T)

    def _petsc_forward(self, fm, B: sp.csr_matrix, fs) -> Optional[np.ndarray]:
        """PETSc's forward substitutions of B's rows and of the loads fs as the rows of X ((2m + 2)
        x n), and B's first row as a dense row after them; None when this factorization has no
        MatForwardSolve."""
        m2 = B.shape[0]
        X = np.empty((m2 + 3, self.n))
        # B's rows scattered one at a time into one work vector (not a dense copy of B: at the
        # seed's size its fresh pages cost more than the scatter)
        b = np.zeros(self.n)
        try:
            for j in range(m2):
                cols = B.indices[B.indptr[j]:B.indptr[j + 1]]
                b[cols] = B.data[B.indptr[j]:B.indptr[j + 1]]
                if j == 0:
                    X[m2 + 2] = b
                self._on_arrays(fm.solveForward, b, X[j])
                b[cols] = 0.0
            for j, f in enumerate(fs):
                self._on_arrays(fm.solveForward, np.array(f, dtype=float), X[m2 + j])
        except PETSc.Error as exc:  # a factorization without MatForwardSolve: full solves instead
            log.info("forward substitution unavailable (PETSc error %s); S by solves", exc.ierr)
            return None
        return X

    def _on_arrays(self, op, src: np.ndarray, dst: np.ndarray):
        """op(b, x) (a PETSc solve or product) with the work vectors b, x placed on the contiguous
        arrays src, dst: no copies in or out."""
        b, x = self._b, self._x
        b.placeArray(src)
        x.placeArray(dst)
        try:
            op(b, x)
        finally:
            b.resetArray()
            x.resetArray()

    def _condense_sparse(self) -> Optional[np.ndarray]:
        """B K^-1 B^T (column by column, not symmetrized) from one multi-RHS solve with B^T as a sparse
        right-hand side (one rank): PETSc passes it to MUMPS as such (ICNTL(20)), which skips
        the zeros in the forward substitution -- the same numbers as with dense columns (checked
        bitwise on the demo), in about 60% of the time.  None when the factorization does not
        take sparse right-hand sides (not MUMPS, other PETSc builds): then S is formed from
        dense columns."""
        if self.m == 0 or self.size > 1 or self._schur_dofs is not None or self._envelope is not None:
            return None
        # the system's loads ride along as two more (full) columns: w1, w2 = B K^-1 (f1, f2) are
        # needed by every path and cost no separate solve this way; so do the exact method's
        # perturbation loads (its first degenerate point needs their data: with MUMPS a separate
        # solve of two columns costs some five times what they add here)
        E = self.system.perturbation_loads()
        fs = [*self.system.loads_numpy(), *E.T]
        B = sp.vstack([self.B_local] + [sp.csr_matrix(f) for f in fs]).tocsr().sorted_indices()
        objs = []
        try:
            Bt = PETSc.Mat().createAIJ(size=B.shape, csr=(B.indptr.astype(PETSc.IntType),
                                                          B.indices.astype(PETSc.IntType), B.data),
                                       comm=PETSc.COMM_SELF)
            objs.append(Bt)
            Bv = PETSc.Mat().createTranspose(Bt)  # B^T, applied by MUMPS as a sparse right-hand side
            objs.append(Bv)
            Xm = PETSc.Mat().createDense((self.n, B.shape[0]), comm=PETSc.COMM_SELF)
            objs.append(Xm)
            Xm.setUp()
            Xm.assemble()
            self.ksp.getPC().getFactorMatrix().matSolve(Bv, Xm)
            BX = self.B_local @ Xm.getDenseArray()  # K^-1 B^T itself is not kept
        except PETSc.Error as exc:
            log.info("sparse right-hand sides unavailable (PETSc error %s); S from dense columns", exc.ierr)
            return None
        finally:
            for obj in objs:
                obj.destroy()
        m2 = 2 * self.m
        self.stats.linear_solves += B.shape[0]
        self._cache_loads(fs, BX[:, m2:])
        return BX[:, :m2]

    def _allreduce(self, a: np.ndarray, op: str = "SUM") -> np.ndarray:
        """The entrywise sum (``op="MAX"``: maximum) of ``a`` over the ranks."""
        if self.size == 1:
            return a
        out = np.empty_like(a)
        from mpi4py import MPI

        self.comm.Allreduce(np.ascontiguousarray(a), out, op=getattr(MPI, op))
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
        S = self._condense_sparse() if block >= m2 else None
        if S is None:
            S = np.zeros((m2, m2))
            for c0 in range(0, m2, block):
                cols = np.arange(c0, min(m2, c0 + block))
                S[:, cols] = self.B_local @ self._kinv_columns(cols)
            S = self._allreduce(np.ascontiguousarray(S))
        # Not symmetrized: S's columns B K^-1 b_j are what the solve that forms u = K^-1 (f - B^T lam)
        # does column by column, so B u = w - S lam holds to the solves' own rounding.  S - S^T is
        # 3e-13 of S on a 20 x 1 strip (m = 1000), yet (S + S^T) / 2 left the formed points' gaps
        # N u - g at closed nodes off by up to 3.3e-8 of the multipliers' size instead of 2.4e-10.
        return S

    # ---------------------------------------------------------------- loads
    def needs_true(self, W: np.ndarray, G: np.ndarray, L: Optional[np.ndarray] = None) -> bool:
        """Can the rounding of a branch's data reach POLISH_RTOL of its point (the multipliers and
        rho B u, from L[:, 0] and the indicators G[:, 0])?  S's error after its correction (or the
        rounding unit), times rho times the larger of |w| (W's first column) and the bound
        sum_j max_i |S_ij| |L_j| of the terms of S L (multipliers of both signs cancel in S L: at
        F = 30 the slip forces, 30 times the normal ones, made S L much smaller than its terms,
        and the m = 2000 strip's branches beyond its 2470th transition fell under the |w|
        estimate with points 1.6e-9 off).
        Only with refined solves (``refine_steps``): unrefined, u shares S's rounding and is
        formed as consistently as S (see REFINE_RTOL).  Once a correction has found a branch's
        equations off by more than POLISH_RTOL (``true_always``), every branch is corrected: the
        estimate is a bound of sizes, not of the error's direction (with it alone, 11 of the
        strip's first 2609 branches went uncorrected, 4 of 225 points there above 1e-9; with
        every branch corrected none, at the same cost).  The threshold is relative to the point's
        size as (1)-(3) are measured, not to the indicators (see below: a strip of L/H = 9, 2
        cells across, m = 450, random loads at F = 30 had its start branch passed 8.4e-10 off, the
        transition it located off by as much, and the next branch's point there 1.1e-8 from
        (1)-(3), though corrected)."""
        if not self.refine_steps or self.s_error is None:
            return False
        if self.true_always:
            return True
        size = np.abs(W[:, 0]).max(initial=0.0)
        if L is not None:
            size = max(size, float(self._colmax() @ np.abs(L[:, 0])))
        err = max(self.s_error, np.finfo(float).eps) * self.system.rho * size
        # the point's size as (1)-(3) are measured: its multipliers and rho B u, i.e. the normal
        # indicators a and the tangential ones without their -+ F lam_n (at F = 30 the slip
        # indicators are thirty times the point, and with them a branch 8e-10 off passed as 0.23 of
        # the threshold)
        m, g = self.m, G[:, 0]
        point = np.abs(g[:m]).max(initial=0.0)
        if L is not None:
            point = max(point, np.abs(L[:, 0]).max(initial=0.0),
                        np.abs(g[m:2 * m] + self.F * L[:m, 0]).max(initial=0.0))
        else:
            point = max(point, np.abs(g[m:]).max(initial=0.0))
        return bool(err > POLISH_RTOL * point)

    def _colmax(self) -> np.ndarray:
        """max_i |S_ij| per column j (once): sum_j of it times |L_j| bounds the terms of S L."""
        if self._s_colmax is None:
            self._s_colmax = np.abs(self.S).max(axis=0)
        return self._s_colmax

    def against_K(self, W, L, G, imposed, true, correction) -> tuple:
        """(L, G) of a branch (data W, multipliers L, indicators G, equation rows ``imposed``)
        with its equations solved against K: R = :meth:`true_rows` (``true`` = (loads, gap):
        full load vectors, a callable returning them, or :class:`PathLoads`), and while the
        equations' residual rho R[imposed] of a column exceeds POLISH_RTOL of that column's own
        size (its multipliers and rho times its free rows of B u, as (1)-(3) are measured),
        L += correction(R, L, cols) for those columns (the branch's own solve, its right-hand
        side R itself; at most POLISH_MAX_STEPS, and only while each halves the column's
        residual: below that it is rounding).  G then reads the free rows of B u from the last R,
        which belongs to the returned L: no product with S.
        A correction that fails to halve a column's residual is thrown away, and when it came
        after one that did, the residual it started from is the measure's rounding floor
        (``polish_floor``, relative to the size of the terms that make the column's B u: rho
        max(|W_j|, sum_i max_k |S_ki| |L_ij|); the smallest seen): once a correction has brought
        a column within twice that floor, no further one is tried.  (The m = 4000 strip at
        F = 30: every branch's first correction left 1.0-1.2 times POLISH_RTOL, and a second,
        thrown away, cost a fifth of the branch.)"""
        if self.refine_floor is not None and self.refine_floor > POLISH_SOLVE_RTOL:
            self.polish_steps = 1  # (the corrections read B u: its solves need that digit too)
        loads, gap = true
        if callable(loads):
            loads = loads()
        rho = self.system.rho

        gap = np.asarray(gap, dtype=bool).reshape(-1)

        def measure(L, cols):
            some = loads.take(cols) if isinstance(loads, PathLoads) else None if loads is None else loads[:, cols]
            R = self.true_rows(some, L, gap[cols])
            return R, rho * np.abs(R[imposed]).max(axis=0, initial=0.0)

        every = np.arange(L.shape[1])
        R, res = measure(L, every)
        # each column's own size, as (1)-(3) are measured: its multipliers and rho times its free
        # rows of B u (not G, whose slip indicators hold F lam_n: at F = 30 thirty times the point)
        size = np.maximum(np.abs(L).max(axis=0, initial=0.0),
                          rho * np.abs(R[~imposed]).max(axis=0, initial=0.0))
        scale = POLISH_RTOL * size
        if (res > scale).any() and not self.true_always:
            self.true_always = True
            log.info("a branch's equations are off by %.1e of its indicators in solves with K: from now on every "
                     "branch is corrected against K", float((res / np.maximum(size, 1e-300)).max()))
        # the size of the terms that make each column's B u (the floor's reference)
        terms = rho * np.maximum(np.abs(W).max(axis=0, initial=0.0), self._colmax() @ np.abs(L))
        rel = res / np.maximum(terms, 1e-300)
        active = res > scale
        if self.polish_floor is not None:  # within twice the measure's rounding: nothing to gain
            active &= rel > 2.0 * self.polish_floor
        worked = np.zeros(L.shape[1], dtype=bool)
        L, R = L.copy(), R.copy()
        for step in range(POLISH_MAX_STEPS):
            cols = active.nonzero()[0]
            if not cols.size:
                break
            L1 = L[:, cols] + correction(R[:, cols], L[:, cols], cols)
            self.stats.dense_solves += cols.size
            R1, res1 = measure(L1, cols)
            # each column judged by its own residual: one that does not halve keeps its last L
            better = res1 < 0.5 * res[cols]
            floor = cols[~better & worked[cols]]  # after a correction that worked: the floor
            if floor.size:
                f = float(rel[floor].min())
                self.polish_floor = f if self.polish_floor is None else min(self.polish_floor, f)
            ok = cols[better]
            L[:, ok], R[:, ok], res[ok] = L1[:, better], R1[:, better], res1[better]
            rel[ok] = res[ok] / np.maximum(terms[ok], 1e-300)
            worked[ok] = True
            active[cols[~better]] = False
            active &= res > scale
            if self.polish_floor is not None:
                active &= rel > 2.0 * self.polish_floor
        self.stats.true_corrections += 1
        return L, self._ind(L, R, np.zeros_like(R), imposed)  # (not W - (W - R): R below W's rounding)

    def true_rows(self, loads: np.ndarray, L: np.ndarray, gap) -> np.ndarray:
        """B u_j - (g; 0) gap_j for u_j = K^-1 (loads_j - B^T L_j), the columns of ``loads`` (full
        vectors, n x c, or :class:`PathLoads`) and of L (2m x c), by refined solves whose
        residuals are exact in L (and in PathLoads' loads): the rows of B u that w_j - S L_j
        stands for, without S's error.  ``gap``: per column, whether its data include the gap (a
        value; not a rate).  Collective under MPI."""
        coef = None
        if isinstance(loads, PathLoads):
            coef = loads.coef
            fl = loads.vectors(*self._loads_local())
        else:
            fl = np.asfortranarray(loads[self.r0:self.r1])
        X = self._refine_columns(self._ksolve_dense(np.asfortranarray(fl - self.B_local.T @ L)), fl, L, coef)
        R = self._allreduce(np.ascontiguousarray(self.B_local @ X))
        if self.system.has_gap:
            R[:self.m] -= np.outer(self.system.gap, np.asarray(gap, dtype=float))
        return R

    def load_data(self, f: np.ndarray) -> np.ndarray:
        """w = B K^-1 f - (g; 0) (B K^-1 f cached for the last few loads), g the system's gap."""
        for g, w in self._loads:
            if g is f or np.array_equal(g, f):
                return self._gap_shifted(w)
        w = self._allreduce(self.B_local @ self._ksolve_refined(f[self.r0:self.r1]))
        self._loads.append((np.array(f, copy=True), w))
        if len(self._loads) > 4:
            self._loads.pop(0)
        return self._gap_shifted(w)

    def load_data_many(self, fs) -> np.ndarray:
        """w_j = B K^-1 f_j - (g; 0) for the loads fs (2m x k), the uncached ones in one multi-RHS solve."""
        fs = [np.asarray(f, dtype=float) for f in fs]
        cached = {}
        for j, f in enumerate(fs):
            for g, w in self._loads:
                if g is f or np.array_equal(g, f):
                    cached[j] = w
                    break
        todo = [j for j in range(len(fs)) if j not in cached]
        if todo:
            rhs = np.column_stack([fs[j][self.r0:self.r1] for j in todo])
            X = self._refine_columns(self._ksolve_dense(rhs), rhs)
            Wn = self._allreduce(np.ascontiguousarray(self.B_local @ X))
            for c, j in enumerate(todo):
                cached[j] = Wn[:, c].copy()
                self._loads.append((np.array(fs[j], copy=True), cached[j]))
            while len(self._loads) > LOAD_CACHE:
                self._loads.pop(0)
        W = np.column_stack([cached[j] for j in range(len(fs))]) if fs else np.zeros((2 * self.m, 0))
        return self._gap_shifted(W)

    def _gap_shifted(self, w: np.ndarray) -> np.ndarray:
        """w - (g; 0) (for a vector or the columns of a matrix): with B u = w - S lam the normal rows
        then give N u - g, so the closed nodes' rows (S lam)_i = w_i read (N u)_i = g_i and every
        quantity formed from w (multipliers, indicators, the condensed SSNM) includes the gap.
        No copy when the gap is zero."""
        gap = self.system.gap
        if not self.system.has_gap:
            return w
        out = np.array(w, dtype=float, copy=True)
        out[:self.m] -= gap if out.ndim == 1 else gap[:, None]
        return out

    # ------------------------------------------------------------ dense part
    def matrix(self, Z: InactiveSets) -> np.ndarray:
        """M(Z) (2m x 2m) of the condensed DirNeu system (a node without tangential unknown has the
        unit row lam_t = 0)."""
        m = self.m
        M = np.zeros((2 * m, 2 * m))
        idx = np.arange(m)
        act_n, act_t = ~Z.nu, ~Z.it & ~self.no_tangent
        M[:m][act_n] = self.S[:m][act_n]
        M[idx[Z.nu], idx[Z.nu]] = 1.0
        M[m:][act_t] = self.S[m:][act_t]
        it = np.flatnonzero(~act_t)
        M[m + it, m + it] = 1.0
        sgn = (Z.tp.astype(float) - Z.tm.astype(float)) * ~self.no_tangent
        M[m + it, it] = -self.F[it] * sgn[it]
        return M

    def rhs(self, Z: InactiveSets, w: np.ndarray) -> np.ndarray:
        m = self.m
        r = np.zeros(2 * m)
        r[:m] = np.where(Z.nu, 0.0, w[:m])
        r[m:] = np.where(Z.it | self.no_tangent, 0.0, w[m:])
        return r

    def _factor(self, Z: InactiveSets):
        """LU of the reduced DirNeu system of Z (cached per canonical Z).

        Only the free multipliers are unknowns: lam_n of closed nodes and lam_t of sticking
        nodes, with their equations (S lam)_i = w_i as rows.  lam_n = lam_t = 0 on open nodes,
        and lam_t,i = +-F lam_n,i of a slipping node is substituted into the lam_n,i column.
        So each branch factors a k x k matrix, k <= 2m, instead of the 2m x 2m M(Z) of
        :meth:`matrix` (which is kept as the reference form)."""
        return self._factor_sets(Z.nu, Z.tp, Z.tm)

    def _factor_sets(self, nu, tp, tm):
        """:meth:`_factor` for the sets given as three boolean arrays (no InactiveSets formed)."""
        key = canonical_key(nu, tp, tm, self._F0)
        hit = self._lu.get(key)
        if hit is not None:
            self._lu.move_to_end(key)
            return hit
        return self._factor_reduced(key, *self._reduction(nu, tp, tm), lambda: repr(InactiveSets(nu, tp, tm)))

    def _reduction(self, nu, tp, tm):
        """(rows, closed, slip, coef) of the reduced system of the sets (nu, tp, tm), see :meth:`_factor`."""
        act_n = ~nu
        it = tp | tm
        no_t = self.no_tangent  # nodes without tangential unknown: lam_t = 0 whatever the sets
        closed = act_n.nonzero()[0]
        rows = np.concatenate([closed, self.m + (~it & ~no_t).nonzero()[0]])  # = the free unknowns
        slip = (it & act_n & ~no_t).nonzero()[0]  # lam_t,i = F sgn lam_n,i substituted
        coef = self.F[slip] * (tp[slip].astype(float) - tm[slip].astype(float))
        return rows, closed, slip, coef

    def _factor_codes(self, key, codes):
        """:meth:`_factor` for the sets given by canonical per-node state codes (0 open, 1 stick,
        2 slip+, 3 slip-, as :func:`cfcontact.exact.canonical_codes`; an open node is
        tangentially free), cached under the caller's ``key``.  The same reduced system as
        :meth:`_factor` for the equivalent InactiveSets, with fewer array operations."""
        # the free unknowns: the closed nodes' lam_n, then the sticking nodes' lam_t (a node without
        # tangential DOFs sticks with lam_t = 0), i.e. the rows of B u the branch imposes
        imposed = self.imposed_rows(codes)
        rows = imposed.nonzero()[0]
        closed = rows[:np.count_nonzero(imposed[:self.m])]
        slip = (codes >= _SLIP_P).nonzero()[0]  # lam_t,i = F sgn lam_n,i substituted
        coef = self.F[slip] * _SLIP_SIGN[codes[slip]]
        return self._factor_reduced(key, rows, closed, slip, coef, lambda: self._describe_codes(codes))

    @staticmethod
    def _describe_codes(codes) -> str:
        """The InactiveSets of canonical state codes, as text (for error messages)."""
        return repr(InactiveSets(codes == _OPEN, (codes == _OPEN) | (codes == _SLIP_P), codes == _SLIP_M))

    def _factor_reduced(self, key, rows, closed, slip, coef, describe):
        """LU of the reduced system with unknowns lam[rows] (``closed``: the closed nodes, the
        first entries of ``rows``; ``slip``: slipping nodes with lam_t = coef lam_n), cached as
        (lu, piv, rows, slip, coef, support); support = the multipliers that can be non-zero
        (rows and the slipping nodes' lam_t).  ``describe()`` names the sets in the error message.
        LAPACK factors the transpose (a Fortran-ordered view of the C-ordered M: no copy); the
        solves use it transposed back (getrs with trans=1)."""
        m = self.m
        Sr = self.S.take(rows, axis=0)
        M = Sr.take(rows, axis=1)
        if slip.size:
            pos = np.searchsorted(closed, slip)  # column of lam_n,i in the reduced system
            M[:, pos] += Sr.take(m + slip, axis=1) * coef
        if M.size:
            lu, piv, info = _getrf(M.T, overwrite_a=True)
            d = np.abs(lu.diagonal())
            dmax = d.max()
            # "not dmax < inf" also catches NaN (every comparison with NaN is false)
            if info < 0 or not dmax < np.inf or d.min() <= 1e-14 * max(dmax, 1e-300):
                raise SingularSystemError(f"DirNeu(Z) is singular (condensed matrix) for {describe()}")
        else:
            lu, piv = M, np.zeros(0, dtype=np.int32)
        self.stats.dense_factorizations += 1
        entry = (lu, piv, rows, slip, coef, np.concatenate([rows, m + slip]) if slip.size else rows)
        self._keep_lu(key, entry)
        return entry

    def _keep_lu(self, key, entry):
        """Keep a reduced system's factorization (:meth:`_factor_reduced`'s ``entry``) under ``key``,
        the cache within its count and 8 (2m)^2 bytes (the oldest dropped first)."""
        self._lu[key] = entry
        while len(self._lu) > max(64, self.options.cache):
            self._lu.popitem(last=False)
        _trim_to_bytes(self._lu, lambda e: e[0].nbytes, 8 * (2 * self.m) ** 2)

    def multipliers(self, Z: InactiveSets, w: np.ndarray) -> np.ndarray:
        """lam = (lam_n, lam_t) of DirNeu(Z, f) from w = B K^-1 f."""
        if self.m == 0:
            return np.zeros(0)
        return self._solve_reduced(self._factor(Z), w)

    def multipliers_many(self, Z: Optional[InactiveSets], W: np.ndarray, key: Optional[bytes] = None,
                         codes: Optional[np.ndarray] = None) -> np.ndarray:
        """lam_j of DirNeu(Z, f_j) for the columns w_j = B K^-1 f_j of W (2m x k): one LU, one
        k-column triangular solve.  ``key``: a caller's cache key standing for Z's canonical key;
        with it, Z may be given as its canonical state ``codes`` instead (see :meth:`_factor_codes`)."""
        if self.m == 0:
            return np.zeros((0, W.shape[1]))
        if key is None:
            entry = self._factor(Z)
        else:
            entry = self._lu.get(key)
            if entry is None:
                if codes is not None:
                    entry = self._factor_codes(key, np.asarray(codes))
                else:
                    entry = self._factor_reduced(key, *self._reduction(Z.nu, Z.tp, Z.tm), lambda: repr(Z))
            else:
                self._lu.move_to_end(key)
        self.stats.dense_solves += W.shape[1]
        return self._solve_entry(entry, W)

    def _solve_entry(self, entry, W: np.ndarray) -> np.ndarray:
        """lam (2m x k) of the reduced system kept as ``entry`` (:meth:`_factor_reduced`) for the
        columns of W: the free unknowns solved, the slipping nodes' lam_t = coef lam_n."""
        lu, piv, rows, slip, coef, _ = entry
        lam = np.zeros((2 * self.m, W.shape[1]))
        if rows.size:
            lam[rows] = _lu_solve(lu, piv, W.take(rows, axis=0), trans=1)
        if slip.size:
            lam[self.m + slip] = coef[:, None] * lam[slip]
        return lam

    def branch_data(self, W: np.ndarray, key: bytes, codes: np.ndarray, refine: bool = False,
                    plain: bool = False, true=None, line=None) -> tuple:
        """(lam, g) = (:meth:`multipliers_many`, :meth:`indicators`) for the columns of W and
        the sets given by their canonical state ``codes`` (cached under ``key``): what the exact
        method needs of a branch.

        One step of iterative refinement (the residual of the reduced system, i.e. the gaps w - S
        lam of its equation rows, solved with the same LU), none with ``plain`` (rates and
        perturbation responses of the intermediate branches of a degenerate point, which only order
        its pivots).  ``refine``: a third result, the change the refinement made to the indicators
        (3m x k), an estimate of their rounding error (with updates: the change of the last of their
        refinement steps, times its contraction).  ``true``: (loads, gap) of W's columns (see
        :meth:`true_rows`; loads may be a callable that returns them): where the data's rounding
        can reach the multipliers (:meth:`needs_true`), last corrections solve the residual of the
        branch's equations in B u from solves with K, not w - S lam (:meth:`against_K`).

        ``line``: (request, around) for the compiled kernel (:meth:`cfcontact.native.BranchKernel.line`,
        with ``refine``): a fourth result, the branch's tolerances and constraints formed in the
        same call, or None where the kernel did not form them (or formed them before a correction
        against K changed the branch)."""
        if self.use_updates:
            if self._updater is None:
                self._updater = _Updater(self)
            res = self._updater.branch_data(W, codes, refine, true)
            return res if line is None else (*res, None)
        if refine and not plain and W.shape[1] == 2 and 2 * self.m <= BRANCH_KERNEL_MAX_ROWS:
            kernel = self._branch_kernel()
            if kernel is not None:
                res = self._branch_data_compiled(kernel, W, key, codes, true, line)
                return res if line is not None else res[:3]
        entry = self._lu.get(key)
        if entry is None:
            entry = self._factor_codes(key, np.asarray(codes))
        else:
            self._lu.move_to_end(key)
        lu, piv, rows, slip, coef, support = entry
        imposed = self.imposed_rows(codes)
        extra = self._lu_extra.get(key)
        if extra is None or extra[0] is not lu:  # the rows of S on the support, for S lam
            if len(self._lu_extra) > 2 * max(64, self.options.cache) or (
                    len(self._lu_extra) * 2 * self.m * support.size * 8 > DENSE_CACHE_BYTES):
                self._lu_extra.clear()
            # (below UPDATE_MIN_SIZE the whole of S is cheaper to multiply than its rows to gather)
            extra = (lu, None if 2 * self.m < UPDATE_MIN_SIZE else self.St.take(support, axis=0),
                     np.searchsorted(rows[:rows.size - (rows >= self.m).sum()], slip), self.m + slip,
                     coef[:, None])
            self._lu_extra[key] = extra
        _, Ssup, pos, tslip, coef_c = extra
        m, c, S = self.m, W.shape[1], self.S
        if not rows.size:
            L = np.zeros((2 * m, c))
            G = self._ind(L, W, np.zeros_like(W), imposed)
            if not refine:
                return L, G
            return (L, G, np.zeros_like(G)) if line is None else (L, G, np.zeros_like(G), None)
        Wr = W[rows]

        def expand(x):  # free unknowns -> (lam_n, lam_t), and S times it
            full = np.zeros((2 * m, x.shape[1]))
            full[rows] = x
            if slip.size:
                full[tslip] = coef_c * x[pos]
            return full, (S @ full if Ssup is None else Ssup.T @ full[support])

        L, SL = expand(_lu_solve(lu, piv, Wr, trans=1))
        # one step of refinement (its correction measures the rounding error of a fresh factorization's
        # solution); none for the intermediate branches of a degenerate point (``plain``)
        steps = 0 if plain else 1
        for _ in range(steps):
            D, SD = expand(_lu_solve(lu, piv, Wr - SL[rows], trans=1))
            L = L + D
            SL = SL + SD
        self.stats.dense_solves += (1 + steps) * c
        G = self._ind(L, W, SL, imposed)
        if true is not None and self.needs_true(W, G, L):  # the equations' residual from solves with K
            L, G = self.against_K(W, L, G, imposed, true,
                                  lambda R, L, c: expand(_lu_solve(lu, piv, R[rows], trans=1))[0])
        if not refine:
            return L, G
        E = np.abs(self._ind(D, np.zeros_like(W), SD, imposed))
        return (L, G, E) if line is None else (L, G, E, None)

    def branch_kernel(self):
        """The compiled kernel that forms the exact method's branches here
        (:class:`cfcontact.native.BranchKernel`), or None: updates in use, 2m above
        BRANCH_KERNEL_MAX_ROWS, or no compiled library."""
        if self.use_updates or 2 * self.m > BRANCH_KERNEL_MAX_ROWS:
            return None
        return self._branch_kernel()

    def has_factorization(self, key: bytes) -> bool:
        """Is a reduced system's factorization kept under ``key``?"""
        return key in self._lu

    def adopt_factorization(self, key: bytes, entry: tuple):
        """Keep a reduced system's factorization that the branch kernel formed outside
        :meth:`branch_data` (``entry`` as :meth:`_factor_reduced` keeps it), counted as
        :meth:`branch_data` counts its own: one factorization, four dense solves."""
        self.stats.dense_factorizations += 1
        self.stats.dense_solves += 4
        self._keep_lu(key, entry)

    def _branch_kernel(self):
        """The compiled branch kernel for this S and F (:class:`cfcontact.native.BranchKernel`), or
        None without the compiled library."""
        k = self._kernel
        if k is None or k.S is not self.S or k.F_source is not self.F:
            k = native.BranchKernel.create(self.S, self.St, self.F)
            if k is None:
                return None
            self._kernel = k
        return k

    def _branch_data_compiled(self, kernel, W, key, codes, true, line=None) -> tuple:
        """:meth:`branch_data` with ``refine`` for two columns by the compiled kernel: the same
        reduced system, LU (partial pivoting), solve, refinement step and indicators in one call
        (L, G, E, constraints; see ``line``)."""
        entry = self._lu.get(key)
        if entry is not None:
            self._lu.move_to_end(key)
        codes = np.asarray(codes, dtype=np.int8)
        imposed = self.imposed_rows(codes)
        W = np.ascontiguousarray(W, dtype=np.float64)
        if line is None:
            res = kernel(imposed, codes, W, self.system.rho, entry)
        else:
            res = kernel.line(imposed, codes, W, self.system.rho, entry, *line)
        if res is None:
            raise SingularSystemError(f"DirNeu(Z) is singular (condensed matrix) for {self._describe_codes(codes)}")
        new, L, G, E = res[:4]
        cons = res[4] if line is not None else None
        if entry is None:
            self.stats.dense_factorizations += 1
            self._keep_lu(key, new)
        self.stats.dense_solves += 4
        if true is not None and self.needs_true(W, G, L):  # the equations' residual from solves with K
            L, G = self.against_K(W, L, G, imposed, true, lambda R, L, c: self._solve_entry(new, R))
            cons = None  # (formed from the uncorrected branch)
        return L, G, E, cons

    def _ind(self, lam, w, Slam, imposed=None):
        """The indicators (a, bp, bm) stacked (3m x k) from lam, w and S lam.  ``imposed``: the
        rows of B u = w - S lam that the branch's own equations set to zero (:meth:`imposed_rows`:
        closed nodes' gaps, sticking nodes' slips); they are taken as exactly zero instead of the
        rounding of w - S lam, which is of the size of w: on a slender body the data w are
        thousands of times the multipliers' scale (over rho), and that rounding would blur the
        multipliers' own indicators (a closed node's lam_n, a sticking node's lam_t -+ F lam_n)."""
        m = self.m
        r = w - Slam
        if imposed is not None:
            r[imposed] = 0.0
        g = lam + self.system.rho * r
        F_lam_n = self.F[:, None] * lam[:m]
        b = g[m:]
        return np.concatenate((g[:m], b - F_lam_n, b + F_lam_n))

    def imposed_rows(self, codes) -> np.ndarray:
        """The rows of B u (2m booleans) that the branch of the state ``codes`` imposes as
        equations: N u = g at its closed nodes, T u = 0 at its sticking ones (kept for the last
        few states: a transition asks for both of its branches' more than once)."""
        codes = np.asarray(codes, dtype=np.int8)
        key = codes.tobytes()
        cache = self._imposed_cache
        rows = cache.get(key)
        if rows is None:
            rows = cache[key] = _imposed_of_codes(self, codes)
            if len(cache) > 16:
                cache.popitem(last=False)
        return rows

    @property
    def s_diag_max(self) -> float:
        """The largest entry of S (S is positive semidefinite: on its diagonal), 0 when m = 0."""
        return float(np.diagonal(self.S).max(initial=0.0))

    @property
    def use_updates(self) -> bool:
        """Are the exact method's branches solved by updates of one kept factorization
        (:class:`_Updater`)?  ``options.updates``: True, False or None (default: when 2m >=
        UPDATE_MIN_SIZE)."""
        choice = getattr(self.options, "updates", None)
        return (2 * self.m >= UPDATE_MIN_SIZE) if choice is None else bool(choice)

    def indicators(self, lam: np.ndarray, w: np.ndarray, support: Optional[np.ndarray] = None,
                   rho: Optional[float] = None) -> np.ndarray:
        """The indicators (17) stacked (a, bp, bm) (3m, or 3m x k for columns) of DirNeu's
        lam for the load with w = B K^-1 f, from B u = w - S lam (no u needed).  ``support``:
        the rows of lam that may be non-zero (default: found from lam).  ``rho``: the
        augmentation parameter (default: the system's)."""
        m = self.m
        rho = self.system.rho if rho is None else float(rho)
        nz = support if support is not None else (lam if lam.ndim == 1 else (lam != 0.0).any(axis=1)).nonzero()[0]
        if 2 * nz.size < lam.shape[0]:  # open nodes carry no force: only the columns of S of the others
            Bu = w - _rows_t_times(self.St, nz, lam[nz])  # columns of S as rows of S^T: contiguous
        else:
            Bu = w - _times(self.S, lam)
        g = lam + rho * Bu  # (a; b) with a = lam_n + rho N u, b = lam_t + rho T u
        F_lam_n = (self.F if lam.ndim == 1 else self.F[:, None]) * lam[:m]
        b = g[m:]
        return np.concatenate((g[:m], b - F_lam_n, b + F_lam_n))  # (a, bp, bm)

    def ssnm(self, f: np.ndarray, y0: np.ndarray, tol: float, max_iter: int, alpha: float):
        """SSNM (:func:`cfcontact.ssnm.ssnm`) in the multipliers: the sets come from the
        indicators lam + rho (w - S lam), the stopping test compares successive multipliers
        (they determine u), and u is formed once, for the result."""
        from cfcontact.errors import ConvergenceError
        from cfcontact.ssnm import Solution, inactive_sets

        system, n = self.system, self.n
        lam, Z, k, converged = self._ssnm_lam(self.load_data(f), inactive_sets(system, y0),
                                              np.asarray(y0[n:], dtype=float), tol, max_iter)
        y = np.concatenate([self.displacement(f, lam, self.imposed_of_sets(Z)), lam])
        if converged:
            return Solution.from_y(system, y, alpha, iterations=k)
        raise ConvergenceError(f"SSNM did not converge in {max_iter} iterations at alpha={alpha}",
                               iterations=max_iter, last=Solution.from_y(system, y, alpha, iterations=max_iter))

    def ssnm_sets(self, f: np.ndarray, tol: float, max_iter: int, rho: Optional[float] = None) -> Optional[InactiveSets]:
        """The inactive sets of the solution SSNM finds from 0 (as :meth:`ssnm` with y0 = 0),
        without forming u; None when SSNM does not converge in ``max_iter`` iterations.  ``rho``:
        the augmentation parameter of SSNM's indicators (default: the system's).  The solutions
        of (1)-(3) do not depend on it, SSNM's convergence does; the sets returned are those of
        the indicators at ``rho``, which are the system's own except where an indicator vanishes
        at the solution (a tie: the caller checks them at the system's rho)."""
        if rho is not None and not (np.isfinite(rho) and rho > 0):
            raise InputError(f"rho must be a positive finite number (SSNM's augmentation parameter), got {rho!r}")
        m = self.m
        Z0 = InactiveSets(np.zeros(m, bool), np.zeros(m, bool), np.zeros(m, bool))
        lam, Z, k, converged = self._ssnm_lam(self.load_data(f), Z0, np.zeros(2 * m), tol, max_iter, rho)
        return Z if converged else None

    def frictionless_solution(self, w: np.ndarray, tol: float, max_iter: int) -> Optional[tuple]:
        """(lam, sets) of the frictionless problem (every F = 0) for the data w = B K^-1 f, by SSNM
        in the multipliers from every node closed; None when it does not converge in
        ``max_iter`` iterations.  The frictionless problem has exactly one solution (S is
        positive definite), the start of the exact method's frictionless homotopy."""
        m = self.m
        saved = self.F, self._F0, self._lu
        none = np.zeros(m, bool)
        try:
            self.F, self._F0, self._lu = np.zeros(m), np.ones(m, dtype=bool), OrderedDict()
            lam, Z, _, converged = self._ssnm_lam(w, InactiveSets(none, none, none), np.zeros(2 * m), tol, max_iter)
            if not converged:
                # SSNM can cycle here too: the problem is a convex QP, whose active-set solution
                # (finite) gives SSNM the sets it then confirms
                lam_n = frictionless_nnls(self.S[:m, :m], w[:m])
                if lam_n is not None:
                    log.info("SSNM on the frictionless problem did not converge; its solution comes from "
                             "non-negative least squares (%d of %d nodes closed)", int((lam_n > 0).sum()), m)
                    lam0 = np.concatenate([lam_n, np.zeros(m)])
                    lam, Z, _, converged = self._ssnm_lam(w, InactiveSets(lam_n <= 0.0, none, none), lam0, tol,
                                                          max_iter)
        finally:
            self.F, self._F0, self._lu = saved
        return (lam, Z) if converged else None

    def _ssnm_lam(self, w, Z, lam_prev, tol, max_iter, rho=None):
        """SSNM iterations in the multipliers from the sets Z and multipliers lam_prev:
        (lam, sets of lam's iteration, iterations, converged); lam is the last iterate (the
        previous one when not converged, as the seed's ConvergenceError reports it).  ``rho``:
        the indicators' augmentation parameter (default: the system's)."""
        m = self.m
        if m == 0:
            return np.zeros(0), Z, 1, True
        nu, tp, tm = Z.nu, Z.tp, Z.tm
        seen = set()
        last = None
        # large systems: after its first iterations SSNM changes a few nodes per iteration (2-3 of
        # 2000 on a strip at F = 30), so the iterates are solved by updates of one kept
        # factorization, as the exact method's branches (a fresh LU each took 0.6 s there)
        updater = _Updater(self) if self.use_updates and 2 * m >= SSNM_UPDATE_MIN_SIZE else None
        for k in range(1, int(max_iter) + 1):
            key = canonical_key(nu, tp, tm, self._F0)
            if key in seen and key != last:
                # the iteration returned to earlier sets: it cycles (SSNM is only locally convergent)
                log.info("SSNM in the multipliers cycles after %d iterations", k - 1)
                return lam_prev, InactiveSets(nu, tp, tm), k - 1, False
            seen.add(key)
            last = key
            codes = None if updater is None else self._codes_of_sets(nu, tp, tm)
            if codes is not None:
                lam = updater.branch_data(w[:, None], codes, refine=False)[0][:, 0]
            else:
                lam = self._solve_reduced(self._factor_sets(nu, tp, tm), w)
            self.stats.ssnm_iterations += 1
            if np.linalg.norm(lam - lam_prev) <= tol * np.linalg.norm(lam):
                return lam, InactiveSets(nu, tp, tm), k, True
            g = self.indicators(lam, w, rho=rho)
            nu, tp, tm = g[:m] < 0, g[m:2 * m] > 0, g[2 * m:] < 0
            lam_prev = lam
        return lam_prev, InactiveSets(nu, tp, tm), int(max_iter), False

    def _codes_of_sets(self, nu, tp, tm) -> Optional[np.ndarray]:
        """The state codes (0 open, 1 stick, 2 slip+, 3 slip-) whose system is that of the sets
        (nu, tp, tm) (see :meth:`_reduction`), or None when no code has it (a closed node with
        a tangential unknown in both tp and tm: lam_t = 0 but T u free)."""
        if np.any(~nu & tp & tm & ~self.no_tangent & ~self._F0):
            return None
        codes = InactiveSets(nu, tp, tm).state_codes()  # (tp & tm: slip+, lam_t = 0 at F = 0)
        codes[~nu & self.no_tangent] = _STICK  # no tangential unknown: lam_t = 0
        return codes

    def _solve_reduced(self, entry, w):
        lu, piv, rows, slip, coef, _ = entry
        self.stats.dense_solves += 1
        lam = np.zeros(2 * self.m)
        if rows.size:
            lam[rows] = _getrs(lu, piv, w[rows], trans=1)[0]
        lam[self.m + slip] = coef * lam[slip]
        return lam

    def displacement(self, f: np.ndarray, lam: np.ndarray, imposed: Optional[np.ndarray] = None) -> np.ndarray:
        """u = K^-1 (f - B^T lam), whole on every rank (one sparse solve).  ``imposed``: the rows
        of B u that the solution's state imposes (:meth:`imposed_rows`, :meth:`imposed_of_sets`),
        which u is then made to satisfy to rounding (:meth:`_consistent`)."""
        u_loc = self._ksolve_refined(np.asarray(f[self.r0:self.r1], dtype=float), lam)
        if imposed is not None:
            u_loc = self._consistent(u_loc[:, None], np.asarray(lam, dtype=float)[:, None], imposed)[:, 0]
        return linalg.concat_ranks(self.comm, u_loc)

    def imposed_of_sets(self, Z: InactiveSets) -> np.ndarray:
        """:meth:`imposed_rows` of the state of the sets Z (in its canonical codes)."""
        return self.imposed_rows(canonical_codes(Z, self.F, self.no_tangent))

    def _consistent(self, X: np.ndarray, lams: np.ndarray, imposed, points=None) -> np.ndarray:
        """The displacements X (local rows, one column per point of multipliers lams; 2m x k)
        shifted onto the rows of B u their states impose (``imposed``: 2m booleans for every
        column, or 2m x k).  The error of a column: the largest of rho |B_I u - g_I| over those
        rows and of the free rows' side violations (an open node's gap N u - g > 0, a slipping
        node's slip T u against lam_t's sign), relative to the point's size as (1)-(3) are
        measured.  Where it exceeds CONSISTENT_RTOL (and both are within what lam's rounding can
        make of them, see CONSISTENT_MAX_RTOL),
        u -= K^-1 B_I^T S_II^-1 (B_I u - g_I), I the imposed rows and the free rows as close to
        their bound as that error (at a transition point the vanishing row of the branch's new
        state: a node that begins to slip has T u = 0 there, and u's rounding gives it either
        sign).  That is u of the multipliers lam + S_II^-1 (B_I u - g_I), a change of lam's own
        error size: (1) keeps its backward error, and the rows that u = K^-1 (f - B^T lam) moves
        by S times lam's rounding hold.  The shift is kept only where it halves the column's
        error, (1)'s backward error included.  ``points``: per column, whether it is a point of
        the path (default: all); the others (a branch's value at alpha + 1, which stands for its
        rate) have only their imposed rows.  Collective under MPI (every rank takes the same
        decisions: R and S are whole on each)."""
        m, k = self.m, X.shape[1]
        if m == 0 or k == 0:
            return X
        imposed = np.asarray(imposed, dtype=bool)
        imposed = np.broadcast_to(imposed[:, None] if imposed.ndim == 1 else imposed, (2 * m, k))
        rho = self.system.rho

        def rows_of(Y):  # B u - (g; 0)
            R = self._allreduce(np.ascontiguousarray(self.B_local @ Y))
            if self.system.has_gap:
                R[:m] -= self.system.gap[:, None]
            return R

        def size_of(R, cols):  # the points' size as (1)-(3) are measured: multipliers and rho B u
            size = np.maximum(np.abs(lams[:, cols]).max(axis=0, initial=0.0), rho * np.abs(R).max(axis=0, initial=0.0))
            return np.maximum(size, 1e-300)

        def errors(R, cols, rows):  # rho |R| on the imposed rows, the free rows' side violations
            res = rho * np.abs(np.where(rows, R, 0.0)).max(axis=0, initial=0.0)
            wrong = rho * np.where(rows, 0.0, np.maximum(side[:, cols] * R, 0.0)).max(axis=0, initial=0.0)
            return res, wrong

        R = rows_of(X)
        size = size_of(R, np.arange(k))
        # the side a free row must keep: N u - g <= 0, and at a node with a contact force (as
        # verify sees one: above 1e-8 of the point) -sign(lam_t) T u <= 0 (0: no condition)
        side = np.vstack([np.ones((m, k)), np.where(lams[:m] > 1e-8 * size, -np.sign(lams[m:]), 0.0)])
        if points is not None:
            side *= np.asarray(points, dtype=bool)
        res, wrong = errors(R, np.arange(k), imposed)
        err = np.maximum(res, wrong) / size
        cap = max(CONSISTENT_MAX_RTOL, CONSISTENT_LAM_ULPS * np.finfo(float).eps * rho * self.s_diag_max)
        todo = ((err > CONSISTENT_RTOL) & (np.maximum(res, wrong) <= cap * size)).nonzero()[0]
        if not todo.size:
            return X
        rows = imposed[:, todo] | ((side[:, todo] != 0.0) & (rho * np.abs(R[:, todo]) <= 2.0 * err[todo] * size[todo]))
        D = np.zeros((2 * m, todo.size))
        groups: dict = {}
        for c in range(todo.size):
            groups.setdefault(rows[:, c].tobytes(), []).append(c)
        for cs in groups.values():
            I = rows[:, cs[0]].nonzero()[0]
            if I.size > CONSISTENT_MAX_ROWS:
                continue
            self.stats.dense_factorizations += 1
            lu = sla.lu_factor(self.S[np.ix_(I, I)], check_finite=False)
            D[np.ix_(I, cs)] = sla.lu_solve(lu, R[np.ix_(I, todo[cs])], check_finite=False)
        BtD = self.B_local.T @ D
        Y = X[:, todo] - self._ksolve_dense(np.asfortranarray(BtD))
        R1 = rows_of(Y)
        res1, wrong1 = errors(R1, todo, rows)
        size1 = size_of(R1, todo)
        # the shift moves (1) by B_I^T D: its backward error as verify measures it, against
        # ||K|| |u| + |B^T lam| (|f| left out: an upper bound)
        amax = self._allreduce(np.vstack([np.abs(BtD).max(axis=0, initial=0.0),
                                          np.abs(self.B_local.T @ lams[:, todo]).max(axis=0, initial=0.0),
                                          np.abs(Y).max(axis=0, initial=0.0)]), "MAX")
        eq1 = amax[0] / np.maximum(self.system.K_norm() * amax[2] + amax[1], 1e-300)
        better = np.maximum(np.maximum(res1, wrong1) / size1, eq1) < 0.5 * err[todo]
        X[:, todo[better]] = Y[:, better]
        self.stats.consistent_points += int(better.sum())
        return X

    def displacements(self, lams: np.ndarray, alphas, imposed: Optional[np.ndarray] = None, points=None) -> np.ndarray:
        """u_j = K^-1 (f(alpha_j) - B^T lam_j) on the system's load path f(alpha) = (1 - alpha) f1
        + alpha f2, for the columns lam_j of ``lams`` (2m x k): whole (n x k) on every rank.
        ``imposed`` (2m x k booleans, or 2m for every column): the rows of B u each column's state
        imposes, which u_j is then made to satisfy to rounding (:meth:`_consistent`; ``points``:
        which columns are points of the path, as there).

        One multi-right-hand-side solve (MatMatSolve) per block of columns (at most STORE_LIMIT
        entries per rank).  Never K^-1 f - (K^-1 B^T) lam, which loses accuracy (contact
        forces nearly cancel the load).  Collective under MPI."""
        lams = np.asarray(lams, dtype=float).reshape(2 * self.m, -1)
        alphas = np.asarray(alphas, dtype=float).ravel()
        k = alphas.size
        if lams.shape[1] != k:
            raise InputError(f"displacements: {lams.shape[1]} multiplier columns but {k} alphas")
        f1l, f2l = self._loads_local()
        block = max(1, int(STORE_LIMIT // max(self.nloc, 1)))
        if self.size > 1:
            from mpi4py import MPI

            block = self.comm.allreduce(block, op=MPI.MIN)
        out = np.empty((self.n, k))
        BT = self.B_local.T.tocsr()
        for c0 in range(0, k, block):
            sl = slice(c0, min(k, c0 + block))
            a = alphas[sl]
            pl = PathLoads(a)
            fa = pl.vectors(f1l, f2l)
            U = self._refine_columns(self._ksolve_dense(np.asfortranarray(fa - BT @ lams[:, sl])), fa, lams[:, sl],
                                     pl.coef)
            if imposed is not None:
                imp = np.asarray(imposed, dtype=bool)
                U = self._consistent(U, lams[:, sl], imp if imp.ndim == 1 else imp[:, sl],
                                     None if points is None else np.asarray(points, dtype=bool)[sl])
            out[:, sl] = linalg.concat_ranks(self.comm, U)
        return out

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
        u = self.displacement(f, lam, self.imposed_of_sets(Z))
        y = np.concatenate([u, lam])
        if not np.all(np.isfinite(y)):
            raise SingularSystemError(f"DirNeu(Z) could not be solved for {Z!r} (non-finite result)")
        return y

    @property
    def K_local(self):
        if self._K_local is None:
            self._K_local = linalg.local_csr(self.system.K)
        return self._K_local

    def K_times(self, u: np.ndarray) -> np.ndarray:
        """K u as a whole vector (for residual checks)."""
        local = self.K_local @ u
        return linalg.concat_ranks(self.comm, local)

    def _check_alive(self):
        """CfcontactError when K's factorization is gone (:meth:`destroy`): no solve with K after it."""
        if self.ksp is None:
            raise CfcontactError("this CondensedSolver was destroyed (destroy()): it solves nothing more; make a new one")

    def destroy(self):
        self._envelope = None
        for obj in (self.ksp, self._x, self._b, self._schur_is):
            if obj is not None:
                obj.destroy()
        self.ksp = None
        self._lu.clear()
        self._loads.clear()


#: A column of an updated branch solve is accepted when its estimated error after refinement (the
#: last correction, times its contraction when applied) is below this share of its own size (or
#: of UPDATE_COLUMN_FLOOR of the largest column, for columns that are rounding around zero).
UPDATE_COLUMN_RTOL = 1e-10
UPDATE_COLUMN_FLOOR = 1e-8


def _columns_converged(csizes, unapplied, Lc, rtol=None) -> bool:
    """Is every column's estimated error within ``rtol`` (default UPDATE_COLUMN_RTOL) of its size?
    ``csizes``: the refinement's corrections' sizes per column, step by step; ``unapplied``: the
    last one is taken as the error (measured, or applied after a first solve); ``Lc``: the
    columns' sizes."""
    last = csizes[-1]
    if not unapplied and len(csizes) > 1:
        prev = csizes[-2]
        last = last * np.divide(last, prev, out=np.ones_like(last), where=prev > 0.0)
    scale = np.maximum(Lc, UPDATE_COLUMN_FLOOR * float(Lc.max(initial=0.0)))
    return bool((last <= (UPDATE_COLUMN_RTOL if rtol is None else rtol) * scale).all())


def _s_times(solver, X):
    """S X, reading only the columns of S (rows of S^T) where X has non-zero rows, or, for most of
    them, all of S -- its upper triangle only where S is exactly symmetric (S^T is S itself) and X
    has two columns (:func:`cfcontact.native.symv2`: Part B's path at n = 1e6 spent a third of
    its time in these products, memory-bound)."""
    nz = (X != 0.0).any(axis=1).nonzero()[0]
    if 4 * nz.size >= X.shape[0]:
        if solver.St is solver.S and X.ndim == 2 and X.shape[1] == 2 and X.shape[0] >= COLUMNWISE_MIN_ROWS:
            Y = native.symv2(solver.S, X)
            if Y is not None:
                return Y
        return _times(solver.S, X)
    return _rows_t_times(solver.St, nz, X[nz])


def _imposed_of_codes(solver, codes) -> np.ndarray:
    """The rows of B u (2m booleans) that the branch of the state ``codes`` imposes: N u = g at
    its closed nodes (first m), T u = 0 at its sticking ones with a tangential unknown (last m)."""
    m = codes.size
    rows = np.empty(2 * m, dtype=bool)
    np.not_equal(codes, _OPEN, out=rows[:m])
    np.equal(codes, _STICK, out=rows[m:])
    if solver._any_no_tangent:
        rows[m:] &= ~solver.no_tangent
    return rows


def _node_types(solver, codes):
    """(closed, S tangential row, slip coefficient) per node of the state codes: what each node's
    two rows of M(Z) are (see :class:`_Updater`); closed and S tangential row are the two halves
    of :func:`_imposed_of_codes`."""
    rows = _imposed_of_codes(solver, codes)
    m = codes.size
    return rows[:m], rows[m:], solver.F * _SLIP_SIGN[codes]


def _imposed(types) -> np.ndarray:
    """The rows of B u (2m) that are equations of the branch whose node types (_node_types) are
    given: N u = g at closed nodes, T u = 0 at sticking ones."""
    closed, t_s, _ = types
    return np.concatenate([closed, t_s])


def _node_rows(m, nodes):
    """The rows of M(Z) owned by the nodes, interleaved: j, m + j per node."""
    out = np.empty(2 * nodes.size, dtype=np.intp)
    out[0::2], out[1::2] = nodes, m + nodes
    return out


def _full_solve(solver, entry, B, rho):
    """M(Z)^-1 B (2m x c) in the full form with the S rows scaled by rho, from the LU ``entry`` of
    Z's reduced system (:meth:`CondensedSolver._factor_codes`): the unknowns fixed by unit rows
    take their right-hand side, the reduced system gets the rest."""
    lu, piv, rows, slip, coef, _ = entry
    m = solver.m
    X = np.array(B, dtype=float, copy=True)
    fixed = np.ones(2 * m, dtype=bool)
    fixed[rows] = False
    nz = (fixed & (X != 0.0).any(axis=1)).nonzero()[0]  # fixed unknowns with non-zero values
    if rows.size:
        rhs = X[rows] / rho
        if nz.size:
            # S[rows, nz] X[nz] from contiguous rows of S^T (a 2-D gather of S is slower)
            rhs = rhs - _rows_t_times(solver.St, nz, X[nz])[rows]
        X[rows] = _lu_solve(lu, piv, rhs, trans=1)
    if slip.size:
        X[m + slip] += coef[:, None] * X[slip]
    return X


def _scaled_rhs(types, W, rho):
    """r(Z, W) of the full form with the S rows scaled by rho: rho w on S rows, 0 on unit rows."""
    closed, t_s, _ = types
    m = closed.size
    B = np.zeros_like(W)
    B[:m] = np.where(closed[:, None], rho * W[:m], 0.0)
    B[m:] = np.where(t_s[:, None], rho * W[m:], 0.0)
    return B


def _scaled_residual(types, W, X, SX, rho):
    """r(Z, W) - M(Z) X (S rows scaled by rho), with SX = S X."""
    closed, t_s, coef = types
    m = closed.size
    R = np.empty_like(X)
    R[:m] = np.where(closed[:, None], rho * (W[:m] - SX[:m]), -X[:m])
    R[m:] = np.where(t_s[:, None], rho * (W[m:] - SX[m:]), -(X[m:] - coef[:, None] * X[:m]))
    return R


def _point_columns(solver, codes, types, W, R):
    """[X, U] = M(codes)^-1 [r(codes, W), P_R] (2m x (p + |R|)) in the full form with the S rows
    scaled by rho, from a fresh factorization of the sets' reduced system (not kept in the
    solver's cache): the start of a degenerate point's model or tableau.  Raises
    SingularSystemError when M(codes) is singular."""
    m, p, rho = solver.m, W.shape[1], solver.system.rho
    entry = solver._factor_codes(b"point-columns", codes)
    solver._lu.pop(b"point-columns", None)
    B = np.zeros((2 * m, p + R.size))
    B[:, :p] = _scaled_rhs(types, W, rho)
    B[R, p + np.arange(R.size)] = 1.0
    return _full_solve(solver, entry, B, rho)


#: The point model's updated solutions are trusted while the residual of M(Z) X = r(Z, W) (S
#: rows scaled by rho) stays below this share of the size of its terms; else it starts over
#: with a fresh factorization at that branch.
POINT_MODEL_RTOL = 1e-11


class PointModel:
    """The branches through one degenerate point, one node's state change at a time: rates and
    perturbation responses by rank-2 updates instead of a solve per branch.

    The pivots of a degenerate point (:func:`cfcontact.exact._resolve`) visit branches that differ
    from their predecessor in one node, always one of the ``nodes`` with a vanishing indicator at
    the point.  In the full form M(Z) lam = r(Z, w) (:class:`_Updater`) such a change replaces the
    two rows q of that node: M' = M + P_q Delta, r' = r + P_q dr.  Kept for the current sets: X =
    M^-1 r(W) for the model's right-hand sides W (the rates' dw and the perturbation loads), U =
    M^-1 P_R for the rows R of all ``nodes``, and S[R] U.  Then, with C = I + Delta U_q (2 x 2),

        X' = X - U_q C^-1 (Delta X - dr),   U' = U - U_q C^-1 Delta U,

    O(m |nodes|) per change instead of a solve with a new factorization.  S X' is formed afresh,
    and the residual of M' X' = r' checks every update (POINT_MODEL_RTOL): when it fails, or C is
    near singular, the model starts over with a fresh factorization at the new sets (which raises
    SingularSystemError when they are singular, as a fresh solve would)."""

    def __init__(self, solver, codes, W, nodes):
        self.s = solver
        self.m = solver.m
        self.rho = solver.system.rho
        self.W = np.asarray(W, dtype=float)
        self.nodes = np.unique(np.asarray(nodes, dtype=np.intp))
        self.local = {int(j): k for k, j in enumerate(self.nodes)}
        self.R = _node_rows(self.m, self.nodes)
        self.updates = 0
        self.rebuilds = 0
        self._build(np.asarray(codes, dtype=np.int8))

    def _build(self, codes):
        s = self.s
        types = _node_types(s, codes)
        p = self.W.shape[1]
        XU = _point_columns(s, codes, types, self.W, self.R)
        # kept as one array: [[X, U], [S[R] X, S[R] U]] (one rank-2 update changes it all)
        self.A = np.asfortranarray(np.vstack([XU, s.S[self.R] @ XU]))  # Fortran: updated in place (dger)
        self.SX = _s_times(s, XU[:, :p])
        self.codes, self.types = codes.copy(), types
        self.rebuilds += 1
        s.stats.dense_solves += p

    @property
    def X(self):
        return self.A[:2 * self.m, :self.W.shape[1]]

    def solution(self):
        """(X, S X) of the current sets (2m x p each, the columns of W)."""
        return self.X.copy(), self.SX

    def move_to(self, codes):
        """Update the model to ``codes`` (differing from its sets only at its nodes, one node at a
        time); returns (X, S X), or None when the change is outside the model (another node) or
        an intermediate branch is singular.  Raises SingularSystemError when ``codes`` is."""
        codes = np.asarray(codes, dtype=np.int8)
        diff = (codes != self.codes).nonzero()[0]
        if any(int(i) not in self.local for i in diff):
            return None
        for i in diff.tolist():
            step = self.codes.copy()
            step[i] = codes[i]
            if not self._change(i, step):
                if i != diff[-1]:
                    return None  # an intermediate branch: leave it to a fresh solve of the target
                self._build(step)
        return self.solution()

    def _change(self, i, codes) -> bool:
        """One node's change by the rank-2 update; False when it cannot be trusted."""
        s, m, rho = self.s, self.m, self.rho
        k = self.local[i]
        p = self.W.shape[1]
        A = self.A
        new = _node_types(s, codes)
        old = self.types
        # node i's two rows of M (old and new types) applied to every column of A: Delta [X, U]
        Yn, Yt = A[i], A[m + i]
        Sn, St = A[2 * m + 2 * k], A[2 * m + 2 * k + 1]
        rows = []
        for closed, t_s, coef in (new, old):
            rows.append((rho * Sn if closed[i] else Yn, rho * St if t_s[i] else Yt - coef[i] * Yn))
        D = np.array([rows[0][0] - rows[1][0], rows[0][1] - rows[1][1]])
        # ... minus the change of the right-hand side (X columns only): Delta X - dr
        w = self.W[[i, m + i]]
        D[0, :p] -= rho * w[0] * (float(new[0][i]) - float(old[0][i]))
        D[1, :p] -= rho * w[1] * (float(new[1][i]) - float(old[1][i]))
        C = np.eye(2) + D[:, [p + 2 * k, p + 2 * k + 1]]
        det = C[0, 0] * C[1, 1] - C[0, 1] * C[1, 0]
        if not abs(det) > 1e-10 * max(np.abs(C).max() ** 2, 1.0):
            return False
        G = np.array([[C[1, 1], -C[0, 1]], [-C[1, 0], C[0, 0]]]) @ D / det
        cols = A[:, [p + 2 * k, p + 2 * k + 1]]  # a copy: the update below overwrites A
        X2 = A[:2 * m, :p] - cols[:2 * m] @ G[:, :p]
        SX2 = _s_times(s, X2)
        R = _scaled_residual(new, self.W, X2, SX2, rho)
        size = rho * (np.abs(SX2).max(initial=0.0) + np.abs(self.W).max(initial=0.0)) + np.abs(X2).max(initial=0.0)
        if not np.abs(R).max(initial=0.0) <= POINT_MODEL_RTOL * size:
            return False
        _dger(-1.0, cols[:, 0], G[0], a=A, overwrite_a=True)  # A -= cols G, in place
        _dger(-1.0, cols[:, 1], G[1], a=A, overwrite_a=True)
        self.SX = SX2
        self.codes, self.types = codes, new
        self.updates += 1
        s.stats.dense_solves += p
        return True


class PointTableau:
    """The branches through one degenerate point, seen only at the point's own nodes: the
    lexicographic walk's tableau, one rank-one or rank-two update per pivot.

    At a degenerate point only the constraints of the nodes with an indicator vanishing there
    can decide a pivot (every other constraint is positive at the point, and the pivots move
    within an infinitesimal neighbourhood of it), and only those nodes change state.  So the
    walk needs, per intermediate branch, the rates and perturbation responses of those nodes'
    indicators only.  With R the two rows of each of the ``nodes`` in the full form M(Z) lam =
    r(Z, W) (:class:`_Updater`; S rows scaled by rho), the tableau keeps

        [[X_R, U_R], [S_R X, S_R U]],   X = M^-1 r(W),  U = M^-1 P_R   (4k x (p + 2k)),

    which a change of one node's state updates by itself, exactly as :class:`PointModel` updates
    its full columns (X' = X - U_q C^-1 (Delta X - dr), U' = U - U_q C^-1 Delta U; rank one when
    only one of the node's rows changes): O(k (p + 2k)) per pivot, independent of m.  The nodes'
    indicators are linear in those rows (plus their constant part rho w) and are formed from
    them when asked, in O(k p): kept as three more rows per node they made every update 7/4 as
    long (the punch of docs/bench.md whose flat face closes at once, k = 105).  There is no
    residual check (it would cost O(m^2)): the walk forms its last branch afresh and compares
    (:func:`cfcontact.exact._tableau_walk`)."""

    def __init__(self, solver, codes, W, nodes):
        s = solver
        m = s.m
        self.rho = rho = s.system.rho
        self.nodes = nodes = np.asarray(nodes, dtype=np.intp)
        self.k = k = nodes.size
        R = _node_rows(m, nodes)
        W = np.asarray(W, dtype=float)
        self.p = p = W.shape[1]
        codes = np.asarray(codes, dtype=np.int8)
        XU = _point_columns(s, codes, _node_types(s, codes), W, R)
        self.F = s.F[nodes]
        self.A = np.asfortranarray(np.vstack([XU[R], s.S[R] @ XU]))
        self.WR = W[R]
        self.rhoW = rho * self.WR
        self.offset = np.repeat(self.rhoW.reshape(k, 2, p), (1, 2), axis=1).reshape(3 * k, p)
        self.no_tangent = np.asarray(s.no_tangent, dtype=bool)[nodes]
        self.updates = 0
        s.stats.dense_solves += p
        # the compiled update and indicators (cfcontact.native: the same operations, without the
        # twenty NumPy and BLAS calls per pivot), or None
        self._lib = native.library()
        if self._lib is not None:
            self.rhoW = np.ascontiguousarray(self.rhoW)
            self.offset = np.ascontiguousarray(self.offset)
            self.F = np.ascontiguousarray(self.F, dtype=np.float64)
            self._work = np.empty(4 * (p + 2 * k) + 8 * k)
            self._addr = (self.A.ctypes.data, self.rhoW.ctypes.data, self._work.ctypes.data, self.F.ctypes.data,
                          self.offset.ctypes.data)

    def indicators(self) -> np.ndarray:
        """(3k x p): the indicators a, bp, bm of each node in turn (row 3 j + i: indicator i of
        node j) for the columns of W: lam + rho (w - S lam) from the tableau's rows (their part
        without rho w: the updates keep every linear function of those rows)."""
        k, p, rho, A = self.k, self.p, self.rho, self.A
        if self._lib is not None:
            H = np.empty((3 * k, p))
            A_addr, _, _, F_addr, off_addr = self._addr
            self._lib.cfc_tableau_indicators(k, p, A_addr, 4 * k, rho, F_addr, off_addr, H.ctypes.data)
            return H
        X, SX = A[:2 * k, :p], A[2 * k:, :p]
        Gn, Gt = X[0::2] - rho * SX[0::2], X[1::2] - rho * SX[1::2]
        FX = self.F[:, None] * X[0::2]
        H = np.empty((3 * k, p))
        H[0::3], H[1::3], H[2::3] = Gn, Gt - FX, Gt + FX
        H += self.offset
        return H

    #: at most this many bytes of visited states for the compiled walk (:meth:`walk`), room for
    #: WALK_STATES_PER_NODE per node and WALK_STATES_EXTRA more (a walk that needs more starts
    #: again in Python)
    WALK_STATE_BYTES = 32 * 2 ** 20
    WALK_STATES_PER_NODE, WALK_STATES_EXTRA = 4, 64

    def walk(self, H, loc, sg, kind, gb, absg, tvf, tsf, spacing, sign, d, fe, delta, pivot, cons, visited,
             maxit) -> Optional[tuple]:
        """The lexicographic walk's loop on this tableau in one compiled call (``cfc_tableau_walk``,
        the loop of :func:`cfcontact.exact._tableau_walk` in the same arithmetic): H its current
        indicators (:meth:`indicators`, updated in place), loc the nodes' states (int8), sg their
        constraints' signs (3k), kind their kinds, gb their b indicators at the point, absg, tvf,
        tsf the point's |indicators| and tolerances (3k), spacing, sign, d, fe and delta (J,
        updated in place) as the loop has them, the pivot and constraint tables, ``visited``:
        (states of the nodes, orientation) pairs where the walk must not arrive, maxit its
        iteration limit.  Returns (status, pivots (n x 5: j, indicator, old, new, d), d, fe):
        status 0 through, 1 given up, 3 more visited states than it had room for (the tableau
        has changed: the caller starts its loop again on a fresh one); None without the compiled
        library or where the visited states would need more than WALK_STATE_BYTES (nothing done:
        the caller's loop decides)."""
        if self._lib is None:
            return None
        k, p = self.k, self.p
        J = p - 1
        cap = min(int(maxit) + len(visited) + 1,
                  self.WALK_STATES_PER_NODE * k + self.WALK_STATES_EXTRA + len(visited))
        if cap * max(k, 1) > self.WALK_STATE_BYTES:
            return None
        vstates = np.empty((cap, max(k, 1)), dtype=np.int8)
        vd = np.empty(cap, dtype=np.int8)
        for v, (state, dv) in enumerate(visited):
            vstates[v, :k] = state
            vd[v] = dv
        piv = np.empty((min(int(maxit), cap) + 1, 5), dtype=np.int64)
        res = np.zeros(4, dtype=np.int64)
        dwork = np.empty(3 * k + 3 * k * J + J + 1)
        iwork = np.empty(6 * k + 1, dtype=np.int64)
        tangent = np.ascontiguousarray(~self.no_tangent, dtype=np.int32)
        A_addr, rhoW_addr, work_addr, F_addr, off_addr = self._addr
        a = native.address
        status = self._lib.cfc_tableau_walk(
            k, p, A_addr, 4 * k, self.rho, rhoW_addr, F_addr, off_addr, a(tangent), work_addr, a(H), a(loc), a(sg),
            a(kind), a(gb), a(absg), a(tvf), a(tsf), spacing, int(sign), int(d), int(fe), a(delta), a(pivot), a(cons),
            a(vstates), a(vd), len(visited), cap, int(maxit), a(piv), a(res), a(dwork), a(iwork))
        self.updates += int(res[3])
        if status == 3:
            return 3, None, d, fe  # (the tableau has moved on: the caller starts again)
        n = int(res[0]) if status == 0 else 0
        return (0 if status == 0 else 1), piv[:n], int(res[1]), int(res[2])

    def change(self, j, old, new) -> bool:
        """Node j (local index) from state ``old`` to ``new``; False (tableau unchanged) when the
        update is near singular.  Its two rows of M change: the normal row between lam_n = 0 and
        rho S (open / closed), the tangential row between rho S (stick) and lam_t - coef lam_n = 0;
        an unchanged row makes the update rank one."""
        p, k, rho, A = self.p, self.k, self.rho, self.A
        if self._lib is not None:
            A_addr, rhoW_addr, work_addr, _, _ = self._addr
            ok = self._lib.cfc_tableau_change(k, p, A_addr, 4 * k, int(j), int(old), int(new), rho, rhoW_addr,
                                              float(self.F[j]), int(not self.no_tangent[j]), work_addr)
            if ok:
                self.updates += 1
            return bool(ok)
        i = 2 * j
        Yn, Yt = A[i], A[i + 1]
        # the change of the normal row (minus that of its right-hand side), None if unchanged
        D0 = None
        if (old == _OPEN) != (new == _OPEN):
            D0 = rho * A[2 * k + i] - Yn if new != _OPEN else Yn - rho * A[2 * k + i]
            D0[:p] -= self.rhoW[i] if new != _OPEN else -self.rhoW[i]
        tangent = not self.no_tangent[j]
        s0, s1 = old == _STICK and tangent, new == _STICK and tangent
        Fj = self.F[j]
        c0, c1 = Fj * _SLIP_SIGN[old], Fj * _SLIP_SIGN[new]
        D1 = None
        if s0 != s1:
            St = rho * A[2 * k + i + 1]
            D1 = St - (Yt - c0 * Yn) if s1 else (Yt - c1 * Yn) - St
            D1[:p] -= self.rhoW[i + 1] if s1 else -self.rhoW[i + 1]
        elif not s0 and c1 != c0:
            D1 = (c0 - c1) * Yn
        c = p + i
        if D0 is None and D1 is None:
            return True
        if D0 is None or D1 is None:  # rank one
            r, D = (1, D1) if D0 is None else (0, D0)
            piv = 1.0 + D[c + r]
            if not abs(piv) > 1e-10 * max(abs(piv), 1.0):
                return False
            col = A[:, c + r].copy()
            _dger(-1.0 / piv, col, D, a=A, overwrite_a=True)
        else:
            C00, C01, C10, C11 = 1.0 + D0[c], D0[c + 1], D1[c], 1.0 + D1[c + 1]
            det = C00 * C11 - C01 * C10
            if not abs(det) > 1e-10 * max(abs(C00), abs(C01), abs(C10), abs(C11), 1.0) ** 2:
                return False
            cols = A[:, c:c + 2].copy()  # the update below overwrites A
            _dger(-1.0, cols[:, 0], (C11 * D0 - C01 * D1) / det, a=A, overwrite_a=True)
            _dger(-1.0, cols[:, 1], (C00 * D1 - C10 * D0) / det, a=A, overwrite_a=True)
        self.updates += 1
        return True


#: The data B K^-1 f of this many loads are kept (the path's two, the exact method's perturbation
#: loads, SSNM's start load, ...).
LOAD_CACHE = 8
#: The exact method's branches are solved by updates of one kept factorization (:class:`_Updater`)
#: from this many multipliers (2m) on; below, a fresh LU per branch is cheaper than the updates'
#: bookkeeping.
UPDATE_MIN_SIZE = 160
#: Reduced systems of up to this many rows (2m) are solved by the compiled branch kernel
#: (:class:`cfcontact.native.BranchKernel`) when no updates are used: it saves the NumPy and
#: LAPACK calls around a small LU (28 instead of 80 us at 2m = 60, 145 instead of 188 us at
#: 160); from ~250 rows on its unblocked LU is slower than LAPACK's (462 against 396 us at 256).
BRANCH_KERNEL_MAX_ROWS = 160
#: SSNM in the multipliers solves its iterates by updates (:class:`_Updater`) from this size 2m
#: of the reduced system on (a fresh LU per iterate below it; ``SolverOptions(updates=False)``:
#: never).
SSNM_UPDATE_MIN_SIZE = 1000
#: A converged refinement correction (below 1e-3 of the first) that is also below this share of
#: the multipliers (per column: values, rates) is only measured, not applied: it would change
#: them by rounding, and applying it costs a product with S (a sixth of Part B's path at
#: n = 1e6).  Larger ones are applied: after a poor first solve (5 % off on a strip at F = 30) a
#: converged correction can still be 3e-8 of lam, and leaving those out put 35 points of the
#: m = 500 strip's path above 1e-9 (a residual of 7.3e-9).
UPDATE_UNAPPLIED_RTOL = 1e-15
#: An updated branch's first solve is taken with one applied correction when that correction is
#: within this share of each column's size: since the base solves the branch's data with its own
#: right-hand side, the first correction of Part B's updated solves is 6.4e-11 of the values and
#: 5.4e-13 of the rates at n = 1e6 (medians), and a second one, measured, is then at the rounding
#: floor: at most 9.4e-16 of the multipliers where the first was up to 1e-8 (1649 branches), 4e-15
#: beyond (6).  Larger first corrections are followed by measured ones, the refinement's
#: contraction (a poor first solve: 5 % off on a strip at F = 30).
UPDATE_FIRST_RTOL = 1e-9
#: ... and what such a corrected solve is taken to be off by, in units of its columns' rounding.
UPDATE_LEFT_ULPS = 8.0
#: Refactor the kept system when a refinement step changes the multipliers by more than this
#: (relative): the updates have lost accuracy.
UPDATE_REFINE_RTOL = 1e-8
#: Most refinement steps of an updated branch's solve refined on to its rounding floor (each one
#: solve with the kept base and the capacitance matrix, and a product with S; three otherwise).
UPDATE_REFINE_STEPS = 6
#: Refactor the kept system at the branch when the refined indicators' estimated rounding error
#: exceeds this share of their size: near a singular branch (between two folds a hair apart) the
#: updated solve can be 1e6 times less accurate than a fresh LU, and its wide rounding bounds
#: would merge separate transitions into one degenerate point (a different path).
UPDATE_ERR_RTOL = 1e-10
#: The rebase rule's cost model (:meth:`_Updater.branch_data`), in seconds of this project's
#: two-core machine (one BLAS thread), fitted to per-branch times of Part B's path (n = 1e6,
#: m = 864): a branch whose sets differ from the kept base at d nodes costs about
#: d m UPDATE_NODE_COST more than one solved on the base itself (28-42 us per node there:
#: Woodbury's products with D's rows of S and Zc in each of its three solves), and refactoring
#: a reduced system of size k costs (2/3) k^3 UPDATE_FLOP_COST + UPDATE_REBASE_COST (LAPACK's
#: getrf at 36 GFlop/s: 0.064 s at k = 1514, 0.30 s at k = 2554).  Only their ratio matters,
#: and not finely: Part B's path took the same time (10.0-10.5 s against 12.2-12.5 s with a
#: refactorization every ~120 changed nodes) with UPDATE_NODE_COST anywhere from 5e-9 to 4.5e-8.
#: A model, not a clock: the renewals fall on the same branches in every run and on every MPI
#: rank (which all trace the replicated dense path).
UPDATE_NODE_COST = 3e-8
UPDATE_FLOP_COST = 2.8e-11
UPDATE_REBASE_COST = 2e-3


class _Updater:
    """DirNeu's condensed system for neighbouring sets by updates of one kept factorization.

    In the full 2m x 2m form M(Z) lam = r(Z, w) (see :meth:`CondensedSolver.matrix`) each node owns
    two rows that depend only on its own state: an S row (closed normal row; sticking tangential
    row) or a unit row (lam_n = 0 or lam_t = 0 of an open node; lam_t - F sgn lam_n = 0 of a
    slipping one).  A branch whose sets differ from a kept base Z0 at the nodes D therefore has
    M(Z) = M(Z0) + U V^T with U = the unit columns of D's rows and V^T = the change of those rows
    (rank 2|D|), and (Sherman-Morrison-Woodbury)

        M(Z)^-1 b = y - Zc C^-1 (V^T y + s),   y = M(Z0)^-1 (b + U s),   Zc = M(Z0)^-1 U,
        C = I + V^T Zc,

    for any s on D's rows; s is what the base's own right-hand side has there, so that y is the
    base state's solution of the same data (with s = 0 a node the branch opens would read w_j = 0
    in the base's gap row, and y would carry the size of the data w: digits lost).

    The S rows are scaled by rho (rho S is of the size of the unit rows: the indicators' own
    weighting), so that V, C and the refinement residual mix no scales.
    M(Z0) is kept as the LU of its reduced system (:meth:`CondensedSolver._factor_codes`); the
    columns Zc of every node that has differed from Z0 and the products S[rows of those nodes] Zc
    are kept too, so a branch costs one solve with the kept LU, O(m |D|) for V^T y and O(|D|^3)
    for C -- O(m^2) per branch instead of the O(m^3) of a fresh factorization.  The base is
    refactored at the branch being solved when what the branches since the last refactorization
    paid for their updates (O(m |D|) each, growing as D does) has reached what a refactorization
    costs (O(k^3)): the rent-or-buy rule, which for a D that grows steadily is the best cycle
    length (the cost model: UPDATE_NODE_COST, UPDATE_FLOP_COST); also when |D| would exceed
    ``max_rank`` (the kept columns' memory), or when a step of iterative refinement against
    M(Z) itself shows that the updates lost accuracy.  Every solve is refined against M(Z) (its
    rows are those of S and unit rows): a first solve whose correction is within UPDATE_FIRST_RTOL
    of each column takes that one correction; others are refined until a correction has fallen
    below 1e-3 of the first (the second step measures the contraction, which is what reveals a
    near-singular branch), which also measures the result's rounding error; a last correction at
    the level of rounding (UPDATE_UNAPPLIED_RTOL) is only measured, not applied.

    Cost per branch: one solve with the kept LU for the values and rates (with the columns of
    nodes new to the cache), a product with S, and per refinement step one more solve and one
    more product (none for a last correction at rounding level; one step after an accurate first
    solve); products and solves with the two columns go column
    by column (:data:`COLUMNWISE_MIN_ROWS`); the products with a symmetric S read its upper
    triangle only (:func:`_s_times`).  (BLAS' symv, a column at a time, made Part B's path only
    4 % faster, and its rounding left points 3x farther from (1)-(3) on the strips: 7.5e-10
    instead of 2.3e-10 at m = 1000, F = 30; the compiled kernel sums as accurately as the full
    product.)"""

    def __init__(self, solver, max_rank: Optional[int] = None):
        self.s = solver
        m = solver.m
        self.m = m
        # C costs O((2|D|)^3) per branch, a refactorization O(k^3) per max_rank branches: balanced
        # near |D| ~ 0.45 k^(3/4) (k <= 2m the size of the reduced system)
        self.max_rank = int(max_rank) if max_rank else max(4, min(400, int(0.45 * (2 * m) ** 0.75)))
        self.rho = solver.system.rho
        self.codes0 = None
        self.paid = self.rebase_cost = 0.0  # updates' cost since the last refactorization, and its cost
        self.refactorizations = 0
        self.updates = 0
        self.unapplied = 0  # last refinement corrections measured, not applied (UPDATE_UNAPPLIED_RTOL)
        self.first_accepted = 0  # branches whose first solve needed one correction only (UPDATE_FIRST_RTOL)
        self.refined_on = 0  # branches whose columns had not all converged, refined on to the floor
        self.reasons = {}

    # ------------------------------------------------------------ node rows
    def _types(self, codes):
        return _node_types(self.s, codes)

    def rebase(self, codes, reason=None):
        """Factor M(codes) (its reduced system) and start over with it as the base; ``reason``
        (why the base was renewed) is counted in ``reasons``.  Returns the nodes at which codes
        now differ from the base: none."""
        if reason is not None:
            self.reasons[reason] = self.reasons.get(reason, 0) + 1
        s = self.s
        codes = np.asarray(codes, dtype=np.int8)
        self.entry0 = s._factor_codes(b"updater-base", codes)
        s._lu.pop(b"updater-base", None)  # kept here, not in the solver's cache
        self.codes0 = codes.copy()
        self.types0 = self._types(codes)
        self.pos = {}  # node -> its index in the cache
        self.nodes = []
        # rows 2q, 2q + 1: (M0^-1 e_j)^T, (M0^-1 e_(m+j))^T of cached node q (Zc's columns as rows:
        # a branch gathers those of its nodes D as contiguous rows)
        self.ZcT = np.empty((16, 2 * self.m))
        self.SR = np.empty((16, 2 * self.m))  # rows 2q, 2q + 1: S[j], S[m + j] (contiguous: no gather per branch)
        self.SZ = np.empty((16, 16))  # rows 2q, 2q + 1: S[j] Zc, S[m + j] Zc
        k = self.entry0[0].shape[0]
        self.paid, self.rebase_cost = 0.0, 2.0 / 3.0 * k ** 3 * UPDATE_FLOP_COST + UPDATE_REBASE_COST
        self.refactorizations += 1
        return np.zeros(0, dtype=np.intp)

    def _base_solve(self, B):
        """M(Z0)^-1 B (2m x c), the S rows of M(Z0) scaled by rho."""
        return _full_solve(self.s, self.entry0, B, self.rho)

    def _ensure(self, D, B=None):
        """Cache Zc and the S products for the nodes D.  With ``B``: return M(Z0)^-1 B too, from
        the same solve as the new columns of Zc when there are any (one pass over the kept LU)."""
        new = [int(j) for j in D if int(j) not in self.pos]
        if not new:
            return None if B is None else self._base_solve(B)
        m, S = self.m, self.s.S
        q0 = len(self.nodes)
        q1 = q0 + len(new)
        if 2 * q1 > self.ZcT.shape[0]:
            cap = max(2 * q1, 2 * self.ZcT.shape[0])
            ZcT, SR = np.empty((cap, 2 * m)), np.empty((cap, 2 * m))
            ZcT[:2 * q0], SR[:2 * q0] = self.ZcT[:2 * q0], self.SR[:2 * q0]
            SZ = np.empty((cap, cap))
            SZ[:2 * q0, :2 * q0] = self.SZ[:2 * q0, :2 * q0]
            self.ZcT, self.SR, self.SZ = ZcT, SR, SZ
        idx = np.array(new)
        k = 2 * len(new)
        U = np.zeros((2 * m, k + (0 if B is None else B.shape[1])))
        U[idx, 2 * np.arange(len(new))] = 1.0
        U[m + idx, 2 * np.arange(len(new)) + 1] = 1.0
        if B is not None:
            U[:, k:] = B
        X = self._base_solve(U)
        self.ZcT[2 * q0:2 * q1] = X[:, :k].T
        for q, j in enumerate(new):
            self.pos[j] = q0 + q
        self.nodes.extend(new)
        self.SR[2 * q0:2 * q1] = S[_node_rows(self.m, idx)]
        self.SZ[2 * q0:2 * q1, :2 * q1] = self.SR[2 * q0:2 * q1] @ self.ZcT[:2 * q1].T
        self.SZ[:2 * q0, 2 * q0:2 * q1] = _times(self.SR[:2 * q0], self.ZcT[2 * q0:2 * q1].T)
        return None if B is None else X[:, k:]

    def _vt(self, D, types, Xn, Xt, SX):
        """V^T X (2|D| x c, rows interleaved per node) from X's rows D (Xn) and m + D (Xt), the only
        ones V^T reads besides SX = S[rows of D] X."""
        closed, t_s, coef = types
        closed0, t_s0, coef0 = self.types0
        SXn, SXt = self.rho * SX[0::2], self.rho * SX[1::2]
        out = np.empty((2 * D.size, Xn.shape[1]))
        out[0::2] = np.where(closed[D, None], SXn, Xn) - np.where(closed0[D, None], SXn, Xn)
        out[1::2] = (np.where(t_s[D, None], SXt, Xt - coef[D, None] * Xn)
                     - np.where(t_s0[D, None], SXt, Xt - coef0[D, None] * Xn))
        return out

    def _solver(self, types, D):
        """B -> M(Z)^-1 B by the Woodbury identity on the kept base (C factored once), or None when
        C is singular."""
        if not D.size:
            return lambda B, y=None, shift=None: self._base_solve(B) if y is None else y
        q = np.array([self.pos[int(j)] for j in D])
        cols = np.empty(2 * q.size, dtype=np.intp)
        cols[0::2], cols[1::2] = 2 * q, 2 * q + 1
        # Zc's rows D and m + D in D's columns: V^T reads no other row of Zc (2|D| x 2|D| gathered
        # instead of the 2|D| x 2m of Zc's columns: 2-4 % of Part B's path at n = 1e6)
        C = self._vt(D, types, self.ZcT[np.ix_(cols, D)].T, self.ZcT[np.ix_(cols, self.m + D)].T,
                     self.SZ[np.ix_(cols, cols)])
        C[np.diag_indices_from(C)] += 1.0
        lu, piv, info = _getrf(C)
        d = np.abs(lu.diagonal())
        if info != 0 or not d.max() < np.inf or d.min() <= 1e-14 * max(d.max(), 1e-300):
            return None
        ZcT, SR, q = self.ZcT, self.SR, len(self.nodes)  # (this branch's: _ensure may replace them later)
        SD = [None]

        def S_D(y):
            """S[rows of D] y: from the kept rows of every cached node when D is most of them (each
            row's product is the same either way), else from D's rows gathered once."""
            if 2 * D.size >= q:
                return _times(SR[:2 * q], y)[cols]
            if SD[0] is None:
                SD[0] = SR[cols]
            return _times(SD[0], y)

        def solve(B, y=None, shift=None):
            """M(Z)^-1 B; y: M(Z0)^-1 (B + U shift) when known (shift: 2|D| x c on D's rows, as
            V^T's; none: y = M(Z0)^-1 B).  M(Z)^-1 B = y - Zc C^-1 (V^T y + shift) for any shift."""
            if y is None:
                y = self._base_solve(B)
            # (D's unit rows hold to rounding only; making them exact cost accuracy: on the m = 1000
            # strip at F = 30 the transitions' alpha drifted 1e-8 from the fresh LUs' after 4900)
            # (ZcD X from the rows of Zc^T, not from ZcD: F-ordered, it took BLAS a pass per column)
            v = self._vt(D, types, y[D], y[self.m + D], S_D(y))
            z = _getrs(lu, piv, v if shift is None else v + shift)[0]
            return y - _rows_t_times(ZcT, cols, z)

        return solve

    def _residual(self, types, W, X, SX):
        """r(Z, W) - M(Z) X (S rows scaled by rho), with SX = S X."""
        return _scaled_residual(types, W, X, SX, self.rho)

    def branch_data(self, W, codes, refine=True, true=None):
        """(lam, g[, Eg]) as :meth:`CondensedSolver.branch_data`, by updates."""
        s = self.s
        codes = np.asarray(codes, dtype=np.int8)
        types = self._types(codes)
        closed, t_s, coef = types
        imposed = _imposed(types)
        if self.codes0 is None:
            self.rebase(codes)
        closed0, t_s0, coef0 = self.types0
        D = ((closed != closed0) | (t_s != t_s0) | (coef != coef0)).nonzero()[0]
        if D.size > self.max_rank or len(self.nodes) + np.setdiff1d(D, self.nodes).size > 2 * self.max_rank:
            D = self.rebase(codes, "rank")
        elif D.size and self.paid >= self.rebase_cost:  # the updates have cost a refactorization
            D = self.rebase(codes, "cost")
        B = _scaled_rhs(types, W, self.rho)
        for attempt in range(2):
            # the base's solution of the same data (its own right-hand side: D's rows as the base
            # has them), not of this branch's right-hand side, from which M(Z)^-1 B differs by a
            # term of the size of the two states' difference; with B itself, an opened node's gap
            # row would read w_j = 0 there and y would be of the size of w -- on slender bodies
            # thousands of times the multipliers, whose difference with y then lost that many digits
            B0 = B if not D.size else _scaled_rhs(self.types0, W, self.rho)
            y = self._ensure(D, B0)
            solve = self._solver(types, D)
            shift = None if not D.size else (B0 - B)[_node_rows(self.m, D)]
            L = None if solve is None else solve(B, y, shift)
            if L is None:  # M(Z) singular (C singular with a regular base), or the updates broke down
                if attempt == 0 and D.size:
                    D = self.rebase(codes, "singular")
                    continue
                raise SingularSystemError(f"DirNeu(Z) is singular (condensed matrix) for "
                                          f"{s._describe_codes(codes)}")
            SL = _s_times(s, L)
            # iterative refinement against M(Z) itself; the updates are trusted while it contracts
            # (each correction well below the previous one), else the base is refactored here
            sizes, csizes, ok = [], [], True
            Eg_scale = 1.0
            more = settled = False  # converged, refined on to the rounding floor (updates only)
            for step in range(UPDATE_REFINE_STEPS):
                Dl = solve(self._residual(types, W, L, SL))
                csizes.append(np.abs(Dl).max(axis=0, initial=0.0))
                size = float(csizes[-1].max(initial=0.0))
                sizes.append(size)
                ratio = size / max(sizes[-2], 1e-300) if step else 1.0  # this correction to the last
                converged = step and size <= 1e-3 * sizes[0]
                unapplied = converged and (csizes[-1] <= UPDATE_UNAPPLIED_RTOL * np.abs(L).max(axis=0)).all()
                if unapplied:
                    # converged to rounding: this correction, this much smaller than the last
                    # applied one, is the error estimate (as that one's indicators times the
                    # contraction) and is not applied, which spares a product with S
                    Eg_scale = ratio
                    self.unapplied += 1
                    break
                stalled = step and size > 0.25 * sizes[-2]
                if stalled and more:
                    # refined on to the rounding floor: the last correction applied stands, this
                    # one (not much smaller) is its error estimate
                    Eg_scale = ratio
                    settled = True
                    break
                # applied (after a poor first solve -- 5 % off on a strip at F = 30 -- the second
                # correction can still be 3e-8 of lam)
                L = L + Dl
                SDl = _s_times(s, Dl)
                SL = SL + SDl
                applied = (Dl, SDl)
                if step == 0:
                    Lc = np.abs(L).max(axis=0, initial=0.0)
                    if _columns_converged(csizes, True, Lc, UPDATE_FIRST_RTOL):
                        # a first solve this accurate leaves, once corrected, its rounding only: the
                        # correction applied, no measured one; the error estimate is UPDATE_LEFT_ULPS
                        # units of each column (as this correction's indicators, scaled per column)
                        Eg_scale = np.minimum(1.0, UPDATE_LEFT_ULPS * np.finfo(float).eps * Lc
                                              / np.maximum(csizes[0], 1e-300))
                        self.first_accepted += 1
                        settled = True  # (its columns' error is that estimate, not the correction)
                        break
                if converged:
                    if more:  # refining on: to the floor, or this many steps
                        if step + 1 == UPDATE_REFINE_STEPS:
                            Eg_scale = ratio
                            break
                    elif D.size and not stalled and step + 1 < UPDATE_REFINE_STEPS and not _columns_converged(
                            csizes, False, np.abs(L).max(axis=0, initial=0.0)):
                        # an updated solve whose columns have not all converged: refined on while
                        # it contracts, to its rounding floor (a correction not below a quarter of
                        # the last one, or below UPDATE_UNAPPLIED_RTOL), and then corrected against
                        # K -- a few more solves cost far less than refactoring: on the m = 1000
                        # strip at F = 30 the updated first solve was 270 times off, the second
                        # correction 2e-5 of the first, and refactoring there at 40 % of the branches
                        # made the path 1.4 times slower
                        more = True
                        self.refined_on += 1
                    else:
                        # converged, the correction applied: the next one would be about this much
                        # smaller than it, the error estimate
                        Eg_scale = ratio
                        break
                if stalled:
                    ok = step == 1 and size <= UPDATE_REFINE_RTOL * max(np.abs(L).max(initial=0.0), 1e-300)
                    break
                if step == 2 and not more:  # three steps unless refining on
                    break
            Eg = Eg_scale * np.abs(s._ind(applied[0], np.zeros_like(W), applied[1], imposed))
            reason = "refine"
            if ok and D.size and not settled:
                # each column's error relative to its own size: the columns (values and rates) can
                # differ by orders of magnitude, and the contraction measured on the largest hid a
                # smaller one's (the m = 500 strip at F = 30, rebased every 50 nodes: a value column
                # 1.7e-5 of the rates', first corrected by 160 times itself, then by 6 %, accepted:
                # its points 3.7e-9 from (1)-(3), its alphas 3e-9 off)
                ok = _columns_converged(csizes, unapplied, np.abs(L).max(axis=0, initial=0.0))
                reason = "column"
            if ok and D.size:  # accurate enough for the path's tie tests (a fresh LU's accuracy)?
                size = np.abs(L).max(axis=0, initial=0.0) + self.rho * np.abs(W).max(axis=0, initial=0.0)
                ok = bool((Eg.max(axis=0, initial=0.0) <= UPDATE_ERR_RTOL * size).all())
                reason = "error"
            if ok or attempt == 1 or not D.size:
                break
            D = self.rebase(codes, reason)  # the updates lost accuracy: start over from this branch
        s.stats.dense_solves += (1 + len(sizes)) * W.shape[1]
        s.stats.dense_updates += 1
        self.updates += 1
        d = D.size
        self.paid += d * self.m * UPDATE_NODE_COST + 2.0 / 3.0 * (2 * d) ** 3 * UPDATE_FLOP_COST
        G = s._ind(L, W, SL, imposed)
        if true is not None and (more or s.needs_true(W, G, L)):  # the equations' residual from solves with K
            L, G = s.against_K(W, L, G, imposed, true,
                               lambda R, L, c: solve(_scaled_residual(types, R, L, np.zeros_like(R), self.rho)))
        if not refine:
            return L, G
        return L, G, Eg


def get_condensed_solver(system: ContactSystem, options: Optional[SolverOptions] = None) -> CondensedSolver:
    """The system's condensed solver (created once and kept on the system; new one if options given)."""
    cache = system._cache
    if options is not None or "condensed" not in cache:
        cache["condensed"] = CondensedSolver(system, options)
    return cache["condensed"]
