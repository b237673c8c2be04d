"""Compiled kernels for the loops that NumPy and BLAS do not do fast enough here:

* the double-double residual r = b - A x of iterative refinement
  (:class:`cfcontact.linalg.ExactResidual`).  NumPy forms it slot by slot over whole columns,
  with some twenty temporaries per entry of A: at n = 1e6 (K of two refined blocks) that was
  0.5 s per right-hand side, 22 s of the set-up of an exact path that otherwise takes 3 s.  The
  same arithmetic in C over A's CSR rows takes 0.02 s per right-hand side.
* the dense product of a C-ordered A with two columns (:func:`gemv2`: the exact method's
  branches have two, the values and the rates): one pass over A, four rows at a time with
  software prefetch, instead of BLAS' gemv once per column (its gemm with two columns is slower
  still).  1.2 instead of 1.7 ms at 1728 rows, 5.9 instead of 11 ms at 4000, single thread.
* the solve with a dense LU's transpose for those two columns (:func:`getrs2t`): one pass over
  the factor instead of LAPACK's getrs once per column.  0.7 instead of 1.0 ms at 1728 rows,
  4.7 instead of 8.2 ms at 4000.
* the product of some columns of S with two columns (:func:`gemv2t`, from the rows of S^T,
  without gathering them first): 2.2-2.9x faster than the gather and BLAS' gemv.
* the product of a symmetric S with two columns from its upper triangle (:func:`symv2`): half
  of S read, 1.4-1.6x faster than :func:`gemv2` at 1728-8000 rows, as accurate (BLAS' symv,
  a column at a time, had made Part B's path only 4 % faster).
* a small branch of the exact method in one call (:class:`BranchKernel`: reduced matrix, LU,
  solve with one refinement step, indicators; with :meth:`BranchKernel.line` also its
  indicators' scales, tolerances and constraints, :func:`line_scales`,
  :func:`line_constraints`): for small reduced systems NumPy's and LAPACK's per-call overhead
  is most of a branch (73 -> 19 us at 2m = 60).
* the first root of a branch's constraints (:func:`first_root`) and a whole ordinary
  transition of the exact method (:class:`OrdinaryStep`: root, facet, next branch, checks),
  whose Python form was some twenty calls per branch.
* the Cholesky factorization of a sparse K in envelope (profile) storage and its substitutions
  (``cfc_env_*``; :class:`cfcontact.linalg.EnvelopeCholesky`): for the small and the thin
  bodies whose RCM envelope is small PETSc's symbolic phase and per-call set-up were most of
  the factorization (two steel blocks, n = 1320: 1.5-1.7 ms against 0.3-0.5 ms), and its forward
  substitutions cannot start at a right-hand side's first non-zero row nor work on 32 columns
  as vectors (S of those blocks: 1.8 ms against 0.5-0.7 ms).
* the rank-one/rank-two update of a degenerate point's tableau and its indicators
  (``cfc_tableau_change``, ``cfc_tableau_indicators``; :class:`cfcontact.condensed.PointTableau`):
  some twenty NumPy and BLAS calls per pivot before.

The C source below is compiled on first use (never at import) with the C compiler that dolfinx
itself needs for its forms (``cc``, or ``$CC``), ``-O3 -march=native -ffp-contract=off``: no
fast-math and no contraction, which would change the rounding that the error-free
transformations rely on; the exact product's error comes from ``fma`` where the CPU has it,
else from Dekker's splitting (the same value: both are exact).  The shared object is kept in
``$CFCONTACT_CACHE_DIR`` (default ``$XDG_CACHE_HOME/cfcontact`` or ``~/.cache/cfcontact``) under
a name that hashes the source, the flags, the compiler and the CPU's features, so a cache shared
between different machines never loads code built for another CPU; it is written to a temporary
name and renamed, so concurrent first uses (MPI ranks, test workers) are safe.

Without a working compiler (or with ``CFCONTACT_NATIVE=0``) :func:`library` returns None and
NumPy is used: for the residual the same operations in the same order, so the same bits, only
slower; for the products and solves BLAS' gemv and LAPACK's getrs, column by column.  Used by :mod:`cfcontact.linalg` and
:mod:`cfcontact.condensed`; it imports nothing of cfcontact.
"""

from __future__ import annotations

import ctypes
import hashlib
import logging
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Callable, Optional

import numpy as np

log = logging.getLogger(__name__)

_from_buffer, _addressof = ctypes.c_char.from_buffer, ctypes.addressof


def address(a: np.ndarray) -> int:
    """The address of an array's first element: through ctypes' buffer view for a writable
    array (a third of the time of ``a.ctypes.data``, which builds an object per call: the small
    branches make some twenty calls each), else ``a.ctypes.data``."""
    try:
        return _addressof(_from_buffer(a))
    except (TypeError, ValueError, BufferError):
        return a.ctypes.data

_SOURCE = r"""
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>

/* the rounding error of the product p = fl(a x): a x = p + e exactly */
#ifdef __FMA__
static inline double prod_err(double a, double x, double p) { return fma(a, x, -p); }
#else
static inline double prod_err(double a, double x, double p)
{
    const double split = 134217729.0; /* 2^27 + 1 (Veltkamp) */
    double c = split * a, ah = c - (c - a), al = a - ah;
    double d = split * x, xh = d - (d - x), xl = x - xh;
    return ((ah * xh - p) + ah * xl + al * xh) + al * xl;
}
#endif

#define BLK 4 /* columns handled together in the inner loop */

/* r = b - A x for nb columns (nb <= BLK; inlined with a constant nb, so the inner loops are
   unrolled and vectorized), over the CSR rows of A. */
static inline void columns(int nb, int64_t nrows, const int64_t *indptr, const int64_t *indices,
                           const double *data, const double *b, int64_t ldb, const double *x, int64_t ldx,
                           double *r, int64_t ldr)
{
    for (int64_t i = 0; i < nrows; i++) {
        double s[BLK], c[BLK];
        for (int q = 0; q < nb; q++) {
            s[q] = b[i + q * ldb];
            c[q] = 0.0;
        }
        for (int64_t t = indptr[i]; t < indptr[i + 1]; t++) {
            const double a = data[t];
            const int64_t j = indices[t];
            for (int q = 0; q < nb; q++) {
                double xv = x[j + q * ldx];
                double p = a * xv;
                double e = prod_err(a, xv, p);
                double u = s[q] - p;
                double z = u - s[q];
                c[q] += ((s[q] - (u - z)) - (p + z)) - e;
                s[q] = u;
            }
        }
        for (int q = 0; q < nb; q++)
            r[i + q * ldr] = s[q] + c[q];
    }
}

/* r = b - A x for the CSR rows of A (indptr, indices, data; nrows rows); b, r: nrows x k,
   x: ncols x k, stored column by column (Fortran order, as PETSc's dense matrices: column q of
   x starts at x + q ldx).  Per entry a x_j: the product split exactly (p + e), the sum carried
   as s + c with Knuth's two-sum, rounded once at the end; BLK columns at a time. */
void cfc_dd_residual(int64_t nrows, const int64_t *indptr, const int64_t *indices, const double *data,
                     int64_t k, const double *b, int64_t ldb, const double *x, int64_t ldx, double *r,
                     int64_t ldr)
{
    int64_t q0 = 0;
    for (; q0 + BLK <= k; q0 += BLK)
        columns(BLK, nrows, indptr, indices, data, b + q0 * ldb, ldb, x + q0 * ldx, ldx, r + q0 * ldr, ldr);
    for (; q0 < k; q0++)
        columns(1, nrows, indptr, indices, data, b + q0 * ldb, ldb, x + q0 * ldx, ldx, r + q0 * ldr, ldr);
}

/* Dense products with two right-hand sides in one pass over A (OpenBLAS' gemv reads A once per
   column, its gemm with two columns is slower still): y0 = A x0, y1 = A x1 for a row-major A
   (nr x nc, row stride lda); each row's two dot products in 8 lanes (GCC's portable vector
   type: AVX on x86 with -march=native, pairs or scalars elsewhere), summed pairwise at the
   end -- as accurate as OpenBLAS' gemv (2e-16 of |A| |x| at n = 1728). */
typedef double v4d __attribute__((vector_size(32), aligned(8))); /* aligned(8): unaligned loads */

#define PF 128 /* prefetch distance, doubles */

/* s[2k + r] = sum_{j < len} c_k[j] x_r[j] for four columns c_0..c_3 and the two vectors x_0, x_1 */
static inline void dots4x2(int64_t len, const double *c0, const double *c1, const double *c2, const double *c3,
                           const double *x0, const double *x1, double *s)
{
    v4d z = {0.0, 0.0, 0.0, 0.0}, a00 = z, a01 = z, a10 = z, a11 = z, a20 = z, a21 = z, a30 = z, a31 = z;
    int64_t j = 0;
    for (; j + 4 <= len; j += 4) {
        __builtin_prefetch(c0 + j + PF);
        __builtin_prefetch(c1 + j + PF);
        __builtin_prefetch(c2 + j + PF);
        __builtin_prefetch(c3 + j + PF);
        v4d u = *(const v4d *)(x0 + j), v = *(const v4d *)(x1 + j);
        v4d r0 = *(const v4d *)(c0 + j), r1 = *(const v4d *)(c1 + j);
        v4d r2 = *(const v4d *)(c2 + j), r3 = *(const v4d *)(c3 + j);
        a00 += r0 * u;
        a01 += r0 * v;
        a10 += r1 * u;
        a11 += r1 * v;
        a20 += r2 * u;
        a21 += r2 * v;
        a30 += r3 * u;
        a31 += r3 * v;
    }
    double t[8] = {0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0};
    for (; j < len; j++) {
        t[0] += c0[j] * x0[j];
        t[1] += c0[j] * x1[j];
        t[2] += c1[j] * x0[j];
        t[3] += c1[j] * x1[j];
        t[4] += c2[j] * x0[j];
        t[5] += c2[j] * x1[j];
        t[6] += c3[j] * x0[j];
        t[7] += c3[j] * x1[j];
    }
    v4d acc[8] = {a00, a01, a10, a11, a20, a21, a30, a31};
    for (int q = 0; q < 8; q++)
        s[q] = ((acc[q][0] + acc[q][2]) + (acc[q][1] + acc[q][3])) + t[q];
}

void cfc_gemv2(int64_t nr, int64_t nc, const double *A, int64_t lda, const double *x0, const double *x1,
               double *y0, double *y1)
{
    double s[8];
    const double *c[4];
    for (int64_t i = 0; i < nr; i += 4) { /* four rows at a time (a short last block repeats a row) */
        int nb = nr - i < 4 ? (int)(nr - i) : 4;
        for (int k = 0; k < 4; k++)
            c[k] = A + (i + (k < nb ? k : 0)) * lda;
        dots4x2(nc, c[0], c[1], c[2], c[3], x0, x1, s);
        for (int k = 0; k < nb; k++) {
            y0[i + k] = s[2 * k];
            y1[i + k] = s[2 * k + 1];
        }
    }
}

/* Triangular solves with two right-hand sides in one pass over the factor: x <- A^-T x for
   x = (x0, x1) and A = P L U as LAPACK's getrf leaves it (lu column-major, leading dimension
   lda, piv 0-based), i.e. getrs with trans = 1.  Row i of U^T (of L^T) is column i of U (of L):
   contiguous, so each row is a dot product; four rows at a time share the pass over the part
   already solved (four streams, the way BLAS' gemv_t blocks), the small triangle of the block
   then row by row.  OpenBLAS' getrs with two columns was 2x slower than two with one column;
   this is 1.4-1.8x faster than those two at 1728-4000 rows, as accurate. */
void cfc_getrs2t(int64_t n, const double *lu, int64_t lda, const int32_t *piv, double *x0, double *x1)
{
    double s[8];
    const double *c[4];
    /* U^T y = b, forward */
    for (int64_t i0 = 0; i0 < n; i0 += 4) {
        int nb = n - i0 < 4 ? (int)(n - i0) : 4;
        for (int k = 0; k < 4; k++)
            c[k] = lu + (i0 + (k < nb ? k : 0)) * lda;
        dots4x2(i0, c[0], c[1], c[2], c[3], x0, x1, s);
        for (int k = 0; k < nb; k++) {
            const double *ck = c[k];
            double p0 = s[2 * k], p1 = s[2 * k + 1];
            for (int64_t j = i0; j < i0 + k; j++) {
                p0 += ck[j] * x0[j];
                p1 += ck[j] * x1[j];
            }
            x0[i0 + k] = (x0[i0 + k] - p0) / ck[i0 + k];
            x1[i0 + k] = (x1[i0 + k] - p1) / ck[i0 + k];
        }
    }
    /* L^T z = y, backward (unit diagonal); rows >= top are solved */
    for (int64_t top = n; top > 0;) {
        int nb = top < 4 ? (int)top : 4;
        int64_t i0 = top - nb;
        for (int k = 0; k < 4; k++)
            c[k] = lu + (i0 + (k < nb ? k : 0)) * lda + top;
        dots4x2(n - top, c[0], c[1], c[2], c[3], x0 + top, x1 + top, s);
        for (int k = nb - 1; k >= 0; k--) {
            const double *ck = lu + (i0 + k) * lda;
            double p0 = s[2 * k], p1 = s[2 * k + 1];
            for (int64_t j = i0 + k + 1; j < top; j++) {
                p0 += ck[j] * x0[j];
                p1 += ck[j] * x1[j];
            }
            x0[i0 + k] -= p0;
            x1[i0 + k] -= p1;
        }
        top = i0;
    }
    /* x = P z: the row interchanges in reverse order */
    for (int64_t i = n - 1; i >= 0; i--) {
        int64_t p = piv[i];
        if (p != i) {
            double t = x0[i];
            x0[i] = x0[p];
            x0[p] = t;
            t = x1[i];
            x1[i] = x1[p];
            x1[p] = t;
        }
    }
}

/* y_r = sum_k x_r[k] A[idx[k], :] for r = 0, 1 (A row-major, nc columns, row stride lda; idx:
   nidx row numbers): the product of the transpose of A's rows idx with two columns, without
   gathering those rows (A = S^T: the columns of S where the multipliers are non-zero).  Four
   rows at a time, each added in turn (y0 and y1 stay in the first-level cache). */
void cfc_gemv2t(int64_t nidx, const int64_t *idx, int64_t nc, const double *A, int64_t lda, const double *x0,
                const double *x1, double *restrict y0, double *restrict y1)
{
    for (int64_t j = 0; j < nc; j++)
        y0[j] = y1[j] = 0.0;
    int64_t k = 0;
    for (; k + 4 <= nidx; k += 4) {
        const double *restrict r0 = A + idx[k] * lda, *restrict r1 = A + idx[k + 1] * lda;
        const double *restrict r2 = A + idx[k + 2] * lda, *restrict r3 = A + idx[k + 3] * lda;
        const double a0 = x0[k], a1 = x0[k + 1], a2 = x0[k + 2], a3 = x0[k + 3];
        const double b0 = x1[k], b1 = x1[k + 1], b2 = x1[k + 2], b3 = x1[k + 3];
        for (int64_t j = 0; j < nc; j++) {
            y0[j] = (((y0[j] + r0[j] * a0) + r1[j] * a1) + r2[j] * a2) + r3[j] * a3;
            y1[j] = (((y1[j] + r0[j] * b0) + r1[j] * b1) + r2[j] * b2) + r3[j] * b3;
        }
    }
    for (; k < nidx; k++) {
        const double *r = A + idx[k] * lda;
        const double a = x0[k], b = x1[k];
        for (int64_t j = 0; j < nc; j++) {
            y0[j] += r[j] * a;
            y1[j] += r[j] * b;
        }
    }
}
/* Y_r = A x_r (r = 0, 1) for a symmetric row-major A (n x n, row stride lda), reading only its
   upper triangle (half of A: the products with S are memory-bound): four rows at a time, their
   segment right of the diagonal block read once for both its uses -- the four rows' dot
   products with x (as in gemv2) and, A being symmetric, the four columns' contributions to the
   entries below the block (an axpy, in cache).  Those contributions go to four partial sums by
   row block (mod 4), added pairwise at the end, so that no entry's sum is one long sequential
   chain: as accurate as gemv2 (1.5e-16 of |A| |x| at n = 1728-8000 against 3.3e-16 with one). */
void cfc_symv2(int64_t n, const double *A, int64_t lda, const double *x0, const double *x1,
               double *restrict Y0, double *restrict Y1, double *restrict work)
{
    /* work: 8 n doubles, the four partial sums of y0 and y1 */
    for (int64_t j = 0; j < 8 * n; j++)
        work[j] = 0.0;
    for (int64_t j = 0; j < n; j++)
        Y0[j] = Y1[j] = 0.0;
    for (int64_t i0 = 0; i0 < n; i0 += 4) {
        double *restrict y0 = work + ((i0 >> 2) & 3) * 2 * n, *restrict y1 = y0 + n;
        int nb = n - i0 < 4 ? (int)(n - i0) : 4;
        /* the nb x nb diagonal block (upper triangle) */
        double d0[4] = {0, 0, 0, 0}, d1[4] = {0, 0, 0, 0};
        for (int a = 0; a < nb; a++) {
            const double *r = A + (i0 + a) * lda;
            for (int b = a; b < nb; b++) {
                double v = r[i0 + b];
                d0[a] += v * x0[i0 + b];
                d1[a] += v * x1[i0 + b];
                if (b > a) {
                    d0[b] += v * x0[i0 + a];
                    d1[b] += v * x1[i0 + a];
                }
            }
        }
        if (nb < 4) { /* the last rows: nothing right of their block */
            for (int k = 0; k < nb; k++) {
                Y0[i0 + k] += d0[k];
                Y1[i0 + k] += d1[k];
            }
            break;
        }
        const double *restrict r0 = A + i0 * lda, *restrict r1 = r0 + lda, *restrict r2 = r1 + lda,
                     *restrict r3 = r2 + lda;
        const double a0 = x0[i0], a1 = x0[i0 + 1], a2 = x0[i0 + 2], a3 = x0[i0 + 3];
        const double b0 = x1[i0], b1 = x1[i0 + 1], b2 = x1[i0 + 2], b3 = x1[i0 + 3];
        v4d z = {0.0, 0.0, 0.0, 0.0}, s00 = z, s01 = z, s10 = z, s11 = z, s20 = z, s21 = z, s30 = z, s31 = z;
        const v4d va0 = {a0, a0, a0, a0}, va1 = {a1, a1, a1, a1}, va2 = {a2, a2, a2, a2}, va3 = {a3, a3, a3, a3};
        const v4d vb0 = {b0, b0, b0, b0}, vb1 = {b1, b1, b1, b1}, vb2 = {b2, b2, b2, b2}, vb3 = {b3, b3, b3, b3};
        int64_t j = i0 + 4;
        double t[8] = {0, 0, 0, 0, 0, 0, 0, 0};
        for (; j + 4 <= n; j += 4) {
            __builtin_prefetch(r0 + j + PF);
            __builtin_prefetch(r1 + j + PF);
            __builtin_prefetch(r2 + j + PF);
            __builtin_prefetch(r3 + j + PF);
            v4d u = *(const v4d *)(x0 + j), v = *(const v4d *)(x1 + j);
            v4d c0 = *(const v4d *)(r0 + j), c1 = *(const v4d *)(r1 + j);
            v4d c2 = *(const v4d *)(r2 + j), c3 = *(const v4d *)(r3 + j);
            s00 += c0 * u; s01 += c0 * v;
            s10 += c1 * u; s11 += c1 * v;
            s20 += c2 * u; s21 += c2 * v;
            s30 += c3 * u; s31 += c3 * v;
            v4d *p0 = (v4d *)(y0 + j), *p1 = (v4d *)(y1 + j);
            *p0 = (((*p0 + c0 * va0) + c1 * va1) + c2 * va2) + c3 * va3;
            *p1 = (((*p1 + c0 * vb0) + c1 * vb1) + c2 * vb2) + c3 * vb3;
        }
        for (; j < n; j++) { /* the scalar tail */
            double c0 = r0[j], c1 = r1[j], c2 = r2[j], c3 = r3[j];
            t[0] += c0 * x0[j]; t[1] += c0 * x1[j];
            t[2] += c1 * x0[j]; t[3] += c1 * x1[j];
            t[4] += c2 * x0[j]; t[5] += c2 * x1[j];
            t[6] += c3 * x0[j]; t[7] += c3 * x1[j];
            y0[j] = (((y0[j] + c0 * a0) + c1 * a1) + c2 * a2) + c3 * a3;
            y1[j] = (((y1[j] + c0 * b0) + c1 * b1) + c2 * b2) + c3 * b3;
        }
        v4d acc[8] = {s00, s01, s10, s11, s20, s21, s30, s31};
        for (int k = 0; k < 4; k++) {
            Y0[i0 + k] += d0[k] + ((((acc[2 * k][0] + acc[2 * k][2]) + (acc[2 * k][1] + acc[2 * k][3])) + t[2 * k]));
            Y1[i0 + k] += d1[k] + ((((acc[2 * k + 1][0] + acc[2 * k + 1][2]) + (acc[2 * k + 1][1] + acc[2 * k + 1][3])) + t[2 * k + 1]));
        }
    }
    for (int64_t j = 0; j < n; j++) {
        const double *w = work + j;
        Y0[j] += (w[0] + w[4 * n]) + (w[2 * n] + w[6 * n]);
        Y1[j] += (w[n] + w[5 * n]) + (w[3 * n] + w[7 * n]);
    }
}
/* The exact method's branch data for a small reduced system, in one call (CondensedSolver.
   branch_data without updates; see its docstring for the algebra).  n2 = 2m rows of B u.
   S: n2 x n2, row-major (row stride lds); imposed: n2 flags (the branch's equation rows: the
   free unknowns); codes: m state codes (0 open, 1 stick, 2 slip+, 3 slip-); F: m friction
   coefficients; w: n2 x 2, row-major (the values' and the rates' data).
   factor != 0: forms rows (the imposed rows), slip (the slipping nodes) with coef = +-F, and the
   reduced matrix M = S[rows, rows] with coef S[rows, m + slip] added to the slipping nodes'
   lam_n columns; its LU as LAPACK's getrf of M^T (lu: k x k column-major, i.e. M row-major;
   piv 0-based; partial pivoting, the first largest entry); nk[0] = k, nk[1] = ns.  factor == 0:
   lu, piv, rows, slip, coef, nk are given (a kept factorization).
   Then x = M^-1 w[rows] (getrs with trans = 1), one step of refinement with the same LU, the
   multipliers L (n2 x 2, row-major: x expanded, lam_t = coef lam_n of the slipping nodes), the
   indicators G (3m x 2, row-major: (a, bp, bm) of lam + rho r, r = w - S L with the imposed rows
   zero) and E = |the indicators of the refinement's correction| (3m x 2).
   St: S^T, row-major (S itself when S is symmetric; the products with S read its rows of St,
   cfc_gemv2t).  work: 8 n2 doubles; iwork: 2 n2 int64.  Returns 0, or 1 when M is singular (a pivot below
   1e-14 of the largest, or one not finite). */
static void bs_expand(int64_t m, int64_t k, int64_t ns, const int64_t *rows, const int64_t *slip,
                      const int64_t *pos, const double *coef, const double *x0, const double *x1, double *X)
{
    for (int64_t i = 0; i < 4 * m; i++)
        X[i] = 0.0;
    for (int64_t a = 0; a < k; a++) {
        X[2 * rows[a]] = x0[a];
        X[2 * rows[a] + 1] = x1[a];
    }
    for (int64_t s = 0; s < ns; s++) {
        X[2 * (m + slip[s])] = coef[s] * x0[pos[s]];
        X[2 * (m + slip[s]) + 1] = coef[s] * x1[pos[s]];
    }
}

/* (Y0, Y1) = S X for X (n2 x 2, row-major) non-zero on the rows sup only: cfc_gemv2t over those
   rows of S^T (St, row stride lds), X's entries there gathered into g0, g1 (nsup each). */
static void bs_product(int64_t n2, const double *St, int64_t lds, int64_t nsup, const int64_t *sup,
                       const double *X, double *g0, double *g1, double *Y0, double *Y1)
{
    for (int64_t t = 0; t < nsup; t++) {
        g0[t] = X[2 * sup[t]];
        g1[t] = X[2 * sup[t] + 1];
    }
    cfc_gemv2t(nsup, sup, n2, St, lds, g0, g1, Y0, Y1);
}

static void bs_indicators(int64_t m, const uint8_t *imposed, const double *F, const double *w, const double *L,
                          const double *SL0, const double *SL1, double rho, int absolute, double *G)
{
    for (int64_t q = 0; q < 2; q++) {
        const double *SL = q ? SL1 : SL0;
        for (int64_t i = 0; i < m; i++) {
            double rn = imposed[i] ? 0.0 : (w ? w[2 * i + q] : 0.0) - SL[i];
            double rt = imposed[m + i] ? 0.0 : (w ? w[2 * (m + i) + q] : 0.0) - SL[m + i];
            double ln = L[2 * i + q];
            double a = ln + rho * rn, b = L[2 * (m + i) + q] + rho * rt, fl = F[i] * ln;
            double bp = b - fl, bm = b + fl;
            if (absolute) {
                a = fabs(a);
                bp = fabs(bp);
                bm = fabs(bm);
            }
            G[2 * i + q] = a;
            G[2 * (m + i) + q] = bp;
            G[2 * (2 * m + i) + q] = bm;
        }
    }
}

int cfc_branch_small(int64_t m, const double *S, const double *St, int64_t lds, const uint8_t *imposed,
                     const int8_t *codes,
                     const double *F, const double *w, double rho, int factor, int64_t *nk, double *lu,
                     int32_t *piv, int64_t *rows, int64_t *slip, double *coef, double *L, double *G, double *E,
                     double *work, int64_t *iwork)
{
    const int64_t n2 = 2 * m;
    int64_t k, ns;
    if (factor) {
        k = 0;
        for (int64_t i = 0; i < n2; i++)
            if (imposed[i])
                rows[k++] = i;
        ns = 0;
        for (int64_t i = 0; i < m; i++)
            if (codes[i] >= 2) {
                slip[ns] = i;
                coef[ns++] = codes[i] == 2 ? F[i] : -F[i];
            }
        nk[0] = k;
        nk[1] = ns;
    } else {
        k = nk[0];
        ns = nk[1];
    }
    /* pos: each slipping node's lam_n among the unknowns (rows and slip both ascending) */
    int64_t *pos = iwork, *sup = iwork + n2;
    for (int64_t s = 0, a = 0; s < ns; s++) {
        while (a < k && rows[a] < slip[s])
            a++;
        pos[s] = a;
    }
    for (int64_t a = 0; a < k; a++)
        sup[a] = rows[a];
    for (int64_t s = 0; s < ns; s++)
        sup[k + s] = m + slip[s];
    const int64_t nsup = k + ns;
    if (factor && k) {
        /* lu = M in row-major = M^T in column-major */
        for (int64_t a = 0; a < k; a++) {
            const double *r = S + rows[a] * lds;
            double *o = lu + a * k;
            for (int64_t b = 0; b < k; b++)
                o[b] = r[rows[b]];
            for (int64_t s = 0; s < ns; s++)
                o[pos[s]] += r[m + slip[s]] * coef[s];
        }
        double dmax = 0.0, dmin = INFINITY;
        for (int64_t j = 0; j < k; j++) {
            double *cj = lu + j * k;
            int64_t p = j;
            double amax = fabs(cj[j]);
            for (int64_t i = j + 1; i < k; i++) {
                double a = fabs(cj[i]);
                if (a > amax) {
                    amax = a;
                    p = i;
                }
            }
            piv[j] = (int32_t)p;
            if (p != j)
                for (int64_t l = 0; l < k; l++) {
                    double t = lu[j + l * k];
                    lu[j + l * k] = lu[p + l * k];
                    lu[p + l * k] = t;
                }
            const double d = cj[j];
            if (d != 0.0)
                for (int64_t i = j + 1; i < k; i++)
                    cj[i] /= d;
            for (int64_t l = j + 1; l < k; l++) {
                double *cl = lu + l * k;
                const double t = cl[j];
                if (t != 0.0)
                    for (int64_t i = j + 1; i < k; i++)
                        cl[i] -= cj[i] * t;
            }
            double ad = fabs(d);
            if (!(ad <= dmax)) /* (NaN: not <=) */
                dmax = ad;
            if (ad < dmin)
                dmin = ad;
        }
        if (!(dmax < INFINITY) || dmin <= 1e-14 * (dmax > 1e-300 ? dmax : 1e-300))
            return 1;
    }
    double *x0 = work, *x1 = work + n2, *SL0 = work + 2 * n2, *SL1 = work + 3 * n2, *D = work + 4 * n2,
           *SD0 = work + 6 * n2, *SD1 = work + 7 * n2;
    for (int64_t a = 0; a < k; a++) {
        x0[a] = w[2 * rows[a]];
        x1[a] = w[2 * rows[a] + 1];
    }
    if (k)
        cfc_getrs2t(k, lu, k, piv, x0, x1);
    bs_expand(m, k, ns, rows, slip, pos, coef, x0, x1, L);
    bs_product(n2, St, lds, nsup, sup, L, x0, x1, SL0, SL1); /* (x0, x1: free once expanded) */
    /* one step of refinement: the gaps of the equation rows, solved with the same LU */
    for (int64_t a = 0; a < k; a++) {
        x0[a] = w[2 * rows[a]] - SL0[rows[a]];
        x1[a] = w[2 * rows[a] + 1] - SL1[rows[a]];
    }
    if (k)
        cfc_getrs2t(k, lu, k, piv, x0, x1);
    bs_expand(m, k, ns, rows, slip, pos, coef, x0, x1, D);
    bs_product(n2, St, lds, nsup, sup, D, x0, x1, SD0, SD1);
    for (int64_t i = 0; i < 2 * n2; i++)
        L[i] += D[i];
    for (int64_t i = 0; i < n2; i++) {
        SL0[i] += SD0[i];
        SL1[i] += SD1[i];
    }
    bs_indicators(m, imposed, F, w, L, SL0, SL1, rho, 0, G);
    bs_indicators(m, imposed, F, NULL, D, SD0, SD1, rho, 1, E);
    return 0;
}
/* Per indicator (3m: a, bp, bm) of a branch, what exact._CondensedData.line measures its values
   and rates against: scale_v and scale_s = the multipliers' (values', rates') largest entry plus
   rho times the size of the terms that the indicator's row of B u sums (|w_i| + sqrt(S_ii)
   sum_j sqrt(S_jj) |lam_j|, at most the data's largest entry; zero on the branch's imposed rows),
   and the data floors unit * max |w| (values) and unit * max |dw| (rates) on the free rows (zero on
   the imposed ones).  W, L: n2 x 2, row-major (data and multipliers: values, rates); sq: n2
   square roots of S's diagonal; out: 4 x 3m (scale_v, scale_s, floor_v, floor_s). */
void cfc_line_scales(int64_t m, const double *W, const double *L, const double *sq, const uint8_t *imposed,
                     double rho, double unit, double *out)
{
    const int64_t n2 = 2 * m;
    double s0 = 0.0, s1 = 0.0, l0 = 0.0, l1 = 0.0, w0 = 0.0, w1 = 0.0;
    for (int64_t i = 0; i < n2; i++) {
        double a = fabs(L[2 * i]), b = fabs(L[2 * i + 1]), c = fabs(W[2 * i]), d = fabs(W[2 * i + 1]);
        s0 += sq[i] * a;
        s1 += sq[i] * b;
        l0 = a > l0 ? a : l0;
        l1 = b > l1 ? b : l1;
        w0 = c > w0 ? c : w0;
        w1 = d > w1 ? d : w1;
    }
    double *sv = out, *ss = out + 3 * m, *fv = out + 6 * m, *fs = out + 9 * m;
    const double uv = unit * w0, us = unit * w1;
    for (int64_t i = 0; i < n2; i++) {
        double dv = 0.0, ds = 0.0, f0 = 0.0, f1 = 0.0;
        if (!imposed[i]) {
            dv = fabs(W[2 * i]) + sq[i] * s0;
            ds = fabs(W[2 * i + 1]) + sq[i] * s1;
            dv = dv < w0 ? dv : w0;
            ds = ds < w1 ? ds : w1;
            f0 = uv;
            f1 = us;
        }
        const double v = l0 + rho * dv, r = l1 + rho * ds;
        /* row i of B u is read by indicator i (a: i < m; bp: m <= i < 2m) and, for T u, by bm (i + m) */
        sv[i] = v;
        ss[i] = r;
        fv[i] = f0;
        fs[i] = f1;
        if (i >= m) {
            sv[i + m] = v;
            ss[i + m] = r;
            fv[i + m] = f0;
            fs[i + m] = f1;
        }
    }
}
/* A branch's tolerances and constraints (exact._Line) after its scales (cfc_line_scales' out:
   sv, ss, fv, fs, 3m each): what counts as zero for each indicator's value and rate,
   tv = ((rtol sv + 1e-300) + ef E[:, 0]) + fv and ts likewise from ss, E[:, 1], fs (E: the
   refinement's change of the indicators, 3m x 2 row-major, or NULL); then the constraints of the
   states ``codes`` (node kinds ``kinds``), node by node and each node's in the order of the
   indicators, where cons[(code * 3 + kind) * 3 + q] (the sign s of s * indicator_q >= 0) is not 0:
   cidx = q m + i, cnode = i, csgn = s, c = s G[cidx, 0], dc = s G[cidx, 1],
   tol_v = tv[cidx] + around |dc|, tol_s = ts[cidx] (G: the indicators' values and rates, 3m x 2
   row-major).  out: tv, ts (3m each), then csgn, c, dc, tol_v, tol_s (2m each: at most two
   constraints per node), then max(sv); iout: cidx, cnode (2m each).  Returns the count of
   constraints, or -1 for a code or kind outside the tables. */
int64_t cfc_line_constraints(int64_t m, const double *scales, const int8_t *codes, const int64_t *kinds,
                             const double *cons, const double *G, const double *E, double rtol, double ef,
                             double around, double *out, int64_t *iout)
{
    const int64_t m3 = 3 * m, m2 = 2 * m;
    const double *sv = scales, *ss = scales + m3, *fv = scales + 2 * m3, *fs = scales + 3 * m3;
    double *tv = out, *ts = out + m3;
    double *csgn = out + 2 * m3, *c = csgn + m2, *dc = c + m2, *tolv = dc + m2, *tols = tolv + m2;
    int64_t *cidx = iout, *cnode = iout + m2;
    double smax = m3 ? sv[0] : 0.0;
    for (int64_t i = 0; i < m3; i++) {
        double v = rtol * sv[i] + 1e-300, r = rtol * ss[i] + 1e-300;
        if (E) {
            v = v + ef * E[2 * i];
            r = r + ef * E[2 * i + 1];
        }
        tv[i] = v + fv[i];
        ts[i] = r + fs[i];
        if (sv[i] > smax || sv[i] != sv[i])  /* (NaN stays: NumPy's max propagates it) */
            smax = sv[i];
    }
    int64_t k = 0;
    for (int64_t i = 0; i < m; i++) {
        const int64_t code = codes[i], kind = kinds[i];
        if (code < 0 || code > 3 || kind < 0 || kind > 2)
            return -1;
        for (int64_t q = 0; q < 3; q++) {
            const double s = cons[(code * 3 + kind) * 3 + q];
            if (s == 0.0)
                continue;
            const int64_t j = q * m + i;
            const double d = s * G[2 * j + 1];
            cidx[k] = j;
            cnode[k] = i;
            csgn[k] = s;
            c[k] = s * G[2 * j];
            dc[k] = d;
            tolv[k] = tv[j] + around * fabs(d);
            tols[k] = ts[j];
            k++;
        }
    }
    out[2 * m3 + 5 * m2] = smax;
    return k;
}
/* The first root of a branch's decreasing constraints from alpha0 in the direction s (exact._exit):
   among the constraints with s dc < -tol_s, t = max(0, (c + (alpha0 - aref) dc) / rate) with
   rate = -s dc, j the first smallest; a = alpha0 + s t_j; none when s (a - bound) >= 0 or when
   s (bound - a) <= err_j, err = (tol_v + |a - aref| tol_s) / rate + ulps spacing(max(|a|, 1));
   else the tied ones, t - t_j <= err + err_j, into tied (ascending), a and err_j into res.
   Returns their count, 0 for none, -1 for a NaN root (the caller's NumPy form decides then). */
int64_t cfc_exit(int64_t k, const double *c, const double *dc, const double *tolv, const double *tols, int64_t s,
                 double alpha0, double aref, double bound, double ulps, int64_t *tied, double *res)
{
    const double sd = (double)s, d0 = alpha0 - aref;
    int64_t j = -1;
    double tj = 0.0;
    for (int64_t i = 0; i < k; i++) {
        const double sdc = sd * dc[i];
        if (!(sdc < -tols[i]))
            continue;
        double t = (c[i] + d0 * dc[i]) / (-sdc);
        if (t != t)
            return -1;
        t = t > 0.0 ? t : 0.0;
        if (j < 0 || t < tj) {
            j = i;
            tj = t;
        }
    }
    if (j < 0)
        return 0;
    const double a = alpha0 + sd * tj;
    if (sd * (a - bound) >= 0.0)
        return 0;
    double x = fabs(a);
    x = x > 1.0 ? x : 1.0;
    const double au = ulps * (nextafter(x, INFINITY) - x), da = fabs(a - aref);
    const double ej = (tolv[j] + da * tols[j]) / (-sd * dc[j]) + au;
    if (sd * (bound - a) <= ej)
        return 0;
    int64_t n = 0;
    for (int64_t i = 0; i < k; i++) {
        const double sdc = sd * dc[i];
        if (!(sdc < -tols[i]))
            continue;
        const double rate = -sdc;
        double t = (c[i] + d0 * dc[i]) / rate;
        t = t > 0.0 ? t : 0.0;
        const double e = (tolv[i] + da * tols[i]) / rate + au;
        if (t - tj <= e + ej)
            tied[n++] = i;
    }
    res[0] = a;
    res[1] = ej;
    return n;
}
/* cfc_branch_small, then the branch's scales (cfc_line_scales, into lout[0:12m]) and its
   tolerances and constraints (cfc_line_constraints, into lout[12m:] and liout): what the exact
   method forms of a branch, in one call.  Returns cfc_branch_small's status, or -2 for a code or
   kind outside the tables. */
int cfc_branch_line(int64_t m, const double *S, const double *St, int64_t lds, const uint8_t *imposed,
                    const int8_t *codes, const double *F, const double *w, double rho, int factor, int64_t *nk,
                    double *lu, int32_t *piv, int64_t *rows, int64_t *slip, double *coef, double *L, double *G,
                    double *E, double *work, int64_t *iwork, const double *sq, double unit, const int64_t *kinds,
                    const double *cons, double rtol, double ef, double around, double *lout, int64_t *liout)
{
    int st = cfc_branch_small(m, S, St, lds, imposed, codes, F, w, rho, factor, nk, lu, piv, rows, slip, coef, L, G,
                              E, work, iwork);
    if (st)
        return st;
    cfc_line_scales(m, w, L, sq, imposed, rho, unit, lout);
    const int64_t k = cfc_line_constraints(m, lout, codes, kinds, cons, G, E, rtol, ef, around, lout + 12 * m,
                                           liout);
    if (k < 0)
        return -2;
    liout[4 * m] = k;
    return 0;
}
/* One ordinary transition of the exact method (exact._Walk.step through _exit, _resolve and
   _CondensedData.make_line, in one call): the first root of the branch (c ... indts: its
   constraints, cidx/cnode, indicators g, dg with strides gs, dgs, and tolerances; codes, aref) from
   alpha0 in the direction s; where a single constraint vanishes there, its facet (pivot: the
   table exact._PIVOT, 4 x 3 x 3; an open node closing with friction slips in the direction of
   its T u where the indicator is measurably nonzero), the next branch at the point (its codes,
   imposed rows, data W from w1, w2, dw; then cfc_branch_line: the LU into lu (k x k), piv, ints
   (rows 2m, slip m, (k, ns), then cidx, cnode 4m and their count) and out (L, G, E, coef, then
   the scales, tolerances and constraints)), the constraint it was entered by (e, whose rate
   gives the orientation d) and the check that no other of its constraints vanishes there.
   res: alpha*, its uncertainty; ires: j, node, indicator, old, new, e, d (tied: ires + 16).
   Returns 0 (an ordinary transition), 1 (no root before bound: the path's end), 2 (anything
   else: a tie, a facet the perturbation must decide, no facet, a singular branch, a constraint
   entered without rate, another one vanishing at the point -- the caller's general form
   decides), 3 (a NaN root). */
int cfc_ordinary_step(int64_t m, int64_t kc, const double *c, const double *dc, const double *tolv,
                      const double *tols, const int64_t *cidx, const int64_t *cnode, const double *g, int64_t gs,
                      const double *dg, int64_t dgs, const double *indtv, const double *indts, const int8_t *codes,
                      double aref, int64_t s, double alpha0, double bound, double ulps, const int64_t *kinds,
                      const int8_t *pivot, const uint8_t *no_t, const double *w1, const double *w2, const double *dw,
                      const double *S, const double *St, int64_t lds, const double *F, double rho, double *work,
                      int64_t *iwork, const double *sq, double unit, const double *cons, double rtol, double ef,
                      int8_t *codes_new, uint8_t *imposed, double *W, double *lu, int32_t *piv, int64_t *ints,
                      double *out, double *res, int64_t *ires)
{
    const int64_t n2 = 2 * m;
    int64_t *tied = ires + 16;
    const int64_t n = cfc_exit(kc, c, dc, tolv, tols, s, alpha0, aref, bound, ulps, tied, res);
    if (n < 0)
        return 3;
    if (n == 0)
        return 1;
    if (n > 1)
        return 2;
    const int64_t j = tied[0];
    const double a = res[0];
    const int64_t node = cnode[j], q = cidx[j] / m, old = codes[node], kind = kinds[node];
    if (old < 0 || old > 3 || kind < 0 || kind > 2)
        return 2;
    int64_t nw = pivot[(old * 3 + kind) * 3 + q];
    if (nw == -2)
        return 2;
    if (nw == -1) {
        const int64_t r = m + node;
        const double b = g[r * gs] + (a - aref) * dg[r * dgs];
        const double bt = indtv[r] + fabs(a - aref) * indts[r];
        if (!(fabs(b) > bt))
            return 2;
        nw = b > 0 ? 2 : 3;
    }
    for (int64_t i = 0; i < m; i++)
        codes_new[i] = codes[i];
    codes_new[node] = (int8_t)nw;
    for (int64_t i = 0; i < m; i++) {
        imposed[i] = codes_new[i] != 0;
        imposed[m + i] = codes_new[i] == 1 && !(no_t && no_t[i]);
    }
    for (int64_t i = 0; i < n2; i++) {
        W[2 * i] = w1[i] * (1.0 - a) + a * w2[i];
        W[2 * i + 1] = dw[i];
    }
    double x = fabs(a);
    x = x > 1.0 ? x : 1.0;
    const double around = ulps * (nextafter(x, INFINITY) - x);
    const int64_t n_out = 16 * m + (m > 1 ? m : 1);
    int64_t *nk = ints + n2 + m, *liout = ints + n2 + m + 2;
    if (cfc_branch_line(m, S, St, lds, imposed, codes_new, F, W, rho, 1, nk, lu, piv, ints, ints + n2,
                        out + 16 * m, out, out + 4 * m, out + 10 * m, work, iwork, sq, unit, kinds, cons, rtol, ef,
                        around, out + n_out, liout))
        return 2;
    /* the new branch's constraints (cfc_line_constraints' layout after the scales) */
    const int64_t k2 = liout[4 * m], m3 = 3 * m;
    const double *base = out + n_out + 12 * m + 2 * m3;
    const double *c2 = base + n2, *dc2 = base + 2 * n2, *tolv2 = base + 3 * n2, *tols2 = base + 4 * n2;
    const int64_t *cidx2 = liout, want = q * m + node;
    int64_t e = -1;
    for (int64_t i = 0; i < k2; i++)
        if (cidx2[i] == want) {
            e = i;
            break;
        }
    if (e < 0 || !(fabs(dc2[e]) > tols2[e]))
        return 2;
    for (int64_t i = 0; i < k2; i++)
        if (i != e && fabs(c2[i]) <= tolv2[i])
            return 2;
    /* the factorization's support (rows, then m + slip: cfc_branch_small's iwork + 2m) after liout */
    for (int64_t i = 0; i < nk[0] + nk[1]; i++)
        liout[4 * m + 1 + i] = iwork[n2 + i];
    ires[0] = j;
    ires[1] = node;
    ires[2] = q;
    ires[3] = old;
    ires[4] = nw;
    ires[5] = e;
    ires[6] = dc2[e] > 0 ? 1 : -1;
    return 0;
}
/* The point tableau of the exact method's lexicographic walk (condensed.PointTableau): A is
   4k x nc, column-major (lda), nc = p + 2k: rows 2j, 2j + 1 = node j's X rows (normal,
   tangential), rows 2k + 2j, 2k + 2j + 1 = the same of S X.  cfc_tableau_change: node j from
   state code old to new (0 open, 1 stick, 2 slip+, 3 slip-), the rank-one or rank-two update of
   PointTableau.change (the same operations); rhoW: 2k x p row-major; work: 4 nc + 8 k doubles.
   Returns 1, or 0 (A unchanged) when the update is near singular. */
int cfc_tableau_change(int64_t k, int64_t p, double *A, int64_t lda, int64_t j, int old, int new_, double rho,
                       const double *rhoW, double Fj, int tangent, double *work)
{
    static const double slip_sign[4] = {0.0, 0.0, 1.0, -1.0};
    const int64_t nc = p + 2 * k, i = 2 * j;
    double *D0 = work, *D1 = work + nc, *c0v = work + 2 * nc, *c1v = c0v + 4 * k;
    int has0 = 0, has1 = 0;
#define AT(r, c) A[(r) + (c) * lda]
    if ((old == 0) != (new_ == 0)) {
        has0 = 1;
        for (int64_t l = 0; l < nc; l++)
            D0[l] = new_ != 0 ? rho * AT(2 * k + i, l) - AT(i, l) : AT(i, l) - rho * AT(2 * k + i, l);
        for (int64_t l = 0; l < p; l++) {
            if (new_ != 0)
                D0[l] -= rhoW[i * p + l];
            else
                D0[l] -= -rhoW[i * p + l];
        }
    }
    const int s0 = old == 1 && tangent, s1 = new_ == 1 && tangent;
    const double c0 = Fj * slip_sign[old], c1 = Fj * slip_sign[new_];
    if (s0 != s1) {
        has1 = 1;
        for (int64_t l = 0; l < nc; l++) {
            double St = rho * AT(2 * k + i + 1, l), Yn = AT(i, l), Yt = AT(i + 1, l);
            D1[l] = s1 ? St - (Yt - c0 * Yn) : (Yt - c1 * Yn) - St;
        }
        for (int64_t l = 0; l < p; l++) {
            if (s1)
                D1[l] -= rhoW[(i + 1) * p + l];
            else
                D1[l] -= -rhoW[(i + 1) * p + l];
        }
    } else if (!s0 && c1 != c0) {
        has1 = 1;
        for (int64_t l = 0; l < nc; l++)
            D1[l] = (c0 - c1) * AT(i, l);
    }
    const int64_t c = p + i;
    if (!has0 && !has1)
        return 1;
    const int64_t nr = 4 * k;
    if (!has0 || !has1) { /* rank one */
        const int64_t r = has0 ? 0 : 1;
        const double *D = has0 ? D0 : D1;
        const double piv = 1.0 + D[c + r];
        if (!(fabs(piv) > 1e-10 * (fabs(piv) > 1.0 ? fabs(piv) : 1.0)))
            return 0;
        for (int64_t q = 0; q < nr; q++)
            c0v[q] = AT(q, c + r);
        const double a = -1.0 / piv;
        for (int64_t l = 0; l < nc; l++) {
            const double t = a * D[l];
            if (t != 0.0)
                for (int64_t q = 0; q < nr; q++)
                    AT(q, l) += c0v[q] * t;
        }
    } else {
        const double C00 = 1.0 + D0[c], C01 = D0[c + 1], C10 = D1[c], C11 = 1.0 + D1[c + 1];
        const double det = C00 * C11 - C01 * C10;
        double mx = fabs(C00);
        mx = fabs(C01) > mx ? fabs(C01) : mx;
        mx = fabs(C10) > mx ? fabs(C10) : mx;
        mx = fabs(C11) > mx ? fabs(C11) : mx;
        mx = mx > 1.0 ? mx : 1.0;
        if (!(fabs(det) > 1e-10 * mx * mx))
            return 0;
        for (int64_t q = 0; q < nr; q++) {
            c0v[q] = AT(q, c);
            c1v[q] = AT(q, c + 1);
        }
        for (int64_t l = 0; l < nc; l++) {
            const double y0 = (C11 * D0[l] - C01 * D1[l]) / det, y1 = (C00 * D1[l] - C10 * D0[l]) / det;
            const double t0 = -y0, t1 = -y1;
            if (t0 != 0.0)
                for (int64_t q = 0; q < nr; q++)
                    AT(q, l) += c0v[q] * t0;
            if (t1 != 0.0)
                for (int64_t q = 0; q < nr; q++)
                    AT(q, l) += c1v[q] * t1;
        }
    }
#undef AT
    return 1;
}

/* The point tableau's indicators (PointTableau.indicators): H (3k x p, row-major), row 3 j + i =
   indicator i (a, bp, bm) of node j, = lam + rho (w - S lam) from A's rows plus offset (3k x p,
   row-major: rho w of each indicator's row). */
void cfc_tableau_indicators(int64_t k, int64_t p, const double *A, int64_t lda, double rho, const double *F,
                            const double *offset, double *H)
{
    for (int64_t j = 0; j < k; j++)
        for (int64_t l = 0; l < p; l++) {
            const double xn = A[2 * j + l * lda], xt = A[2 * j + 1 + l * lda];
            const double gn = xn - rho * A[2 * k + 2 * j + l * lda], gt = xt - rho * A[2 * k + 2 * j + 1 + l * lda];
            const double fx = F[j] * xn;
            H[(3 * j) * p + l] = gn + offset[(3 * j) * p + l];
            H[(3 * j + 1) * p + l] = (gt - fx) + offset[(3 * j + 1) * p + l];
            H[(3 * j + 2) * p + l] = (gt + fx) + offset[(3 * j + 2) * p + l];
        }
}
/* The lexicographic walk through a degenerate point on its tableau (exact._tableau_walk's loop,
   the same decisions in the same arithmetic): from the branch entered through the constraint fe
   (flat index 3 j + i over the point's k nodes) in direction d with the vertex's offset delta (J),
   pick the first vanishing constraint that decreases in d (ties: the first column of the
   lexicographic offsets within 1e-9 of their largest, then all J columns as exact._lex_argmin),
   its facet (pivot table; an open node that closes slips the way of its b where that is
   measurably nonzero, else by exact._lex_sign of its perturbation row), update the tableau
   (cfc_tableau_change; H = its indicators, 3k x p, p = 1 + J) and go on until no constraint
   qualifies.  loc (k) are the nodes' states, sg (3k) their constraints' signs, kind (k) their
   kinds, gb (k) their b indicators at the point, absg, tvf, tsf (3k) the point's |indicators| and
   tolerances; visited: nv states (k each, row-major int8) with their orientations vd, where the
   walk must not arrive (room for cap states: the walk's own are added).  piv: per pivot (j, i,
   old, new, d).  res_i: (pivots, d, fe); delta is updated in place.  Returns 0 (no constraint
   qualifies: the walk is through), 1 (it gives up: the general loop decides), 3 (more than cap
   states). */
static int64_t cfc_lex_argmin(int64_t n, int64_t J, const double *rows, int64_t *cand)
{
    int64_t nc = n;
    for (int64_t i = 0; i < n; i++)
        cand[i] = i;
    for (int64_t c = 0; c < J; c++) {
        double lo = INFINITY, amax = 0.0;
        for (int64_t a = 0; a < nc; a++) {
            const double v = rows[cand[a] * J + c];
            lo = v < lo ? v : lo;
            const double av = fabs(v);
            amax = av > amax ? av : amax;
        }
        const double tol = 1e-9 * (amax > 1e-300 ? amax : 1e-300);
        int64_t w = 0;
        for (int64_t a = 0; a < nc; a++)
            if (rows[cand[a] * J + c] <= lo + tol)
                cand[w++] = cand[a];
        nc = w;
        if (nc == 1)
            return cand[0];
    }
    return -1;
}

static int cfc_lex_sign(int64_t J, const double *v)
{
    double sc = 0.0;
    for (int64_t l = 0; l < J; l++) {
        const double a = fabs(v[l]);
        sc = a > sc ? a : sc;
    }
    const double t = 1e-9 * (sc > 1e-300 ? sc : 1e-300);
    for (int64_t l = 0; l < J; l++)
        if (fabs(v[l]) > t)
            return v[l] > 0 ? 1 : -1;
    return 0;
}

int cfc_tableau_walk(int64_t k, int64_t p, double *A, int64_t lda, double rho, const double *rhoW, const double *F,
                     const double *offset, const int32_t *tangent, double *work, double *H, int8_t *loc, double *sg,
                     const int64_t *kind, const double *gb, const double *absg, const double *tvf, const double *tsf,
                     double spacing, int64_t sign, int64_t d, int64_t fe, double *delta, const int8_t *pivot,
                     const double *cons, int8_t *vstates, int8_t *vd, int64_t nv, int64_t cap, int64_t maxit,
                     int64_t *piv, int64_t *res_i, double *dwork, int64_t *iwork)
{
    const int64_t J = p - 1, k3 = 3 * k;
    double *dc = dwork, *rows = dwork + k3, *vec = dwork + k3 + k3 * J;
    int64_t *D = iwork, *cand = iwork + k3;
    int64_t np_ = 0;
    for (int64_t it = 0; it < maxit; it++) {
        int64_t nD = 0;
        for (int64_t r = 0; r < k3; r++) {
            dc[r] = sg[r] * H[r * p];
            const double rate = (double)d * dc[r];
            if (r != fe && absg[r] <= tvf[r] + spacing * fabs(dc[r]) && rate <= tsf[r] && sg[r] != 0.0)
                D[nD++] = r;
        }
        if (!nD) {
            res_i[0] = np_;
            res_i[1] = d;
            res_i[2] = fe;
            return 0;
        }
        for (int64_t a = 0; a < nD; a++)
            if ((double)d * dc[D[a]] >= -tsf[D[a]])
                return 1;
        int64_t f;
        if (nD == 1)
            f = D[0];
        else {
            int64_t ib = 0;
            double best = 0.0, cmax = 0.0;
            for (int64_t a = 0; a < nD; a++) {
                const int64_t r = D[a];
                const double col = (dc[r] * delta[0] + ((double)sign * sg[r]) * H[r * p + 1]) / -((double)d * dc[r]);
                rows[a] = col;
                if (a == 0 || col < best) {
                    best = col;
                    ib = a;
                }
                cmax = fabs(col) > cmax ? fabs(col) : cmax;
            }
            int64_t ties = 0;
            for (int64_t a = 0; a < nD; a++)
                if (rows[a] <= rows[ib] + 1e-9 * cmax)
                    ties++;
            if (ties > 1) {
                for (int64_t a = 0; a < nD; a++) {
                    const int64_t r = D[a];
                    const double sD = (double)sign * sg[r], ad = fabs(dc[r]);
                    for (int64_t l = 0; l < J; l++)
                        rows[a * J + l] = (dc[r] * delta[l] + sD * H[r * p + 1 + l]) / ad;
                }
                ib = cfc_lex_argmin(nD, J, rows, cand);
                if (ib < 0)
                    return 1;
            }
            f = D[ib];
        }
        const int64_t j = f / 3, c = f % 3, old = loc[j];
        int64_t nw = pivot[(old * 3 + kind[j]) * 3 + c];
        if (nw == -2)
            return 1;
        if (nw == -1) {
            const int64_t fb = 3 * j + 1;
            const double b = gb[j];
            if (fabs(b) > tvf[fb])
                nw = b > 0 ? 2 : 3;
            else {
                for (int64_t l = 0; l < J; l++)
                    vec[l] = H[fb * p] * delta[l] + (double)sign * H[fb * p + 1 + l];
                const int sgn = cfc_lex_sign(J, vec);
                if (!sgn)
                    return 1;
                nw = sgn > 0 ? 2 : 3;
            }
        }
        if (!cfc_tableau_change(k, p, A, lda, j, (int)old, (int)nw, rho, rhoW, F[j], tangent[j], work))
            return 1;
        res_i[3] += 1; /* (the tableau's updates) */
        loc[j] = (int8_t)nw;
        for (int64_t q = 0; q < 3; q++)
            sg[3 * j + q] = cons[(nw * 3 + kind[j]) * 3 + q];
        cfc_tableau_indicators(k, p, A, lda, rho, F, offset, H);
        const double de = sg[f] * H[f * p];
        if (!(sg[f] != 0.0) || !(fabs(de) > tsf[f]))
            return 1;
        d = de > 0 ? 1 : -1;
        const double t = (double)sign * sg[f];
        for (int64_t l = 0; l < J; l++)
            delta[l] = -(t * H[f * p + 1 + l]) / de;
        fe = f;
        piv[5 * np_] = j;
        piv[5 * np_ + 1] = c;
        piv[5 * np_ + 2] = old;
        piv[5 * np_ + 3] = nw;
        piv[5 * np_ + 4] = d;
        np_++;
        for (int64_t v = 0; v < nv; v++)
            if (vd[v] == d && !memcmp(vstates + v * k, loc, (size_t)k))
                return 1;
        if (nv >= cap)
            return 3;
        memcpy(vstates + nv * k, loc, (size_t)k);
        vd[nv++] = (int8_t)d;
    }
    return 1;
}

/* ---- envelope (profile) LDL^T of a sparse symmetric positive definite matrix ----
   Row p of the factor (in the permuted order p = iperm[i]) holds columns first[p] .. p at
   v[ptr[p] .. ptr[p+1]-1], the diagonal last: the strict lower part is L (unit diagonal
   implied), the diagonal D. */

/* first[] and ptr[] of A's lower envelope in the order iperm (A: CSR, both triangles); ptr[n] */
int64_t cfc_env_pattern(int64_t n, const int64_t *indptr, const int64_t *indices, const int64_t *iperm,
                        int64_t *first, int64_t *ptr)
{
    for (int64_t i = 0; i < n; i++) {
        const int64_t p = iperm[i];
        int64_t f = p;
        for (int64_t t = indptr[i]; t < indptr[i + 1]; t++) {
            const int64_t q = iperm[indices[t]];
            if (q < f) f = q;
        }
        first[p] = f;
    }
    ptr[0] = 0;
    for (int64_t p = 0; p < n; p++)
        ptr[p + 1] = ptr[p] + (p - first[p] + 1);
    return ptr[n];
}

/* A's lower triangle (in the order iperm) scattered into the envelope v (zeroed by the caller) */
void cfc_env_fill(int64_t n, const int64_t *indptr, const int64_t *indices, const double *data,
                  const int64_t *iperm, const int64_t *first, const int64_t *ptr, double *v)
{
    for (int64_t i = 0; i < n; i++) {
        const int64_t p = iperm[i];
        double *rp = v + ptr[p] - first[p];
        for (int64_t t = indptr[i]; t < indptr[i + 1]; t++) {
            const int64_t q = iperm[indices[t]];
            if (q <= p) rp[q] += data[t];
        }
    }
}

/* sum_{k0 <= k < k1} a[k] b[k] in four partial sums (four independent chains of additions:
   a single chain waits for each addition) */
static inline double env_dot(const double *a, const double *b, int64_t k0, int64_t k1)
{
    double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
    int64_t k = k0;
    for (; k + 4 <= k1; k += 4) {
        s0 += a[k] * b[k];
        s1 += a[k + 1] * b[k + 1];
        s2 += a[k + 2] * b[k + 2];
        s3 += a[k + 3] * b[k + 3];
    }
    for (; k < k1; k++)
        s0 += a[k] * b[k];
    return (s0 + s1) + (s2 + s3);
}

/* the factorization, in place (row by row: g = L D of row i against the rows before it, then
   L and D); 0, or i + 1 when pivot i is not positive (A not positive definite) */
int64_t cfc_env_ldlt(int64_t n, const int64_t *first, const int64_t *ptr, double *v)
{
    for (int64_t i = 0; i < n; i++) {
        const int64_t fi = first[i];
        double *ri = v + ptr[i] - fi;
        for (int64_t j = fi; j < i; j++) {
            const int64_t fj = first[j];
            const double *rj = v + ptr[j] - fj;
            ri[j] -= env_dot(ri, rj, fi > fj ? fi : fj, j);
        }
        double d = ri[i];
        for (int64_t j = fi; j < i; j++) {
            const double g = ri[j], l = g / v[ptr[j + 1] - 1];
            ri[j] = l;
            d -= g * l;
        }
        if (!(d > 0.0))
            return i + 1;
        ri[i] = d;
    }
    return 0;
}

/* x <- L^-1 x for nc columns of x (column-major, leading dimension ldx), one at a time (several:
   cfc_env_forward_rowmajor) */
void cfc_env_forward(int64_t n, const int64_t *first, const int64_t *ptr, const double *v, int64_t nc,
                     double *x, int64_t ldx)
{
    for (int64_t c = 0; c < nc; c++) {
        double *xc = x + c * ldx;
        double prev = 0.0; /* x[i - 1], kept in a register: row i's last term waits for it alone */
        for (int64_t i = 0; i < n; i++) {
            const int64_t fi = first[i];
            const double *ri = v + ptr[i] - fi;
            double a = xc[i];
            if (fi < i) {
                a -= env_dot(ri, xc, fi, i - 1);
                a -= ri[i - 1] * prev;
            }
            xc[i] = prev = a;
        }
    }
}

/* x <- K^-1 x for two columns interleaved (x: n x 2, row-major), the whole solve (L^-1, D^-1,
   L^-T) in one pass over L each way: each row's sums are those of cfc_env_forward and
   cfc_env_backward (the same operations in the same order: the same bits as two solves alone),
   the two columns side by side in the lanes of one vector operation */
void cfc_env_solve2(int64_t n, const int64_t *first, const int64_t *ptr, const double *v, double *x)
{
    double p0 = 0.0, p1 = 0.0;
    for (int64_t i = 0; i < n; i++) {
        const int64_t fi = first[i];
        const double *ri = v + ptr[i] - fi;
        double a[2] = {x[2 * i], x[2 * i + 1]};
        if (fi < i) {
            double s[4][2] = {{0.0, 0.0}, {0.0, 0.0}, {0.0, 0.0}, {0.0, 0.0}};
            const int64_t k1 = i - 1;
            int64_t k = fi;
            for (; k + 4 <= k1; k += 4)
                for (int j = 0; j < 4; j++)
                    for (int q = 0; q < 2; q++)
                        s[j][q] += ri[k + j] * x[2 * (k + j) + q];
            for (; k < k1; k++)
                for (int q = 0; q < 2; q++)
                    s[0][q] += ri[k] * x[2 * k + q];
            for (int q = 0; q < 2; q++)
                a[q] -= (s[0][q] + s[1][q]) + (s[2][q] + s[3][q]);
            a[0] -= ri[i - 1] * p0;
            a[1] -= ri[i - 1] * p1;
        }
        x[2 * i] = p0 = a[0];
        x[2 * i + 1] = p1 = a[1];
    }
    if (n == 0)
        return;
    for (int64_t i = 0; i < n; i++) {
        const double d = v[ptr[i + 1] - 1];
        x[2 * i] /= d;
        x[2 * i + 1] /= d;
    }
    double y[2] = {x[2 * (n - 1)], x[2 * (n - 1) + 1]};
    for (int64_t i = n - 1; i > 0; i--) {
        const int64_t fi = first[i];
        const double *ri = v + ptr[i] - fi;
        double nx[2] = {x[2 * (i - 1)], x[2 * (i - 1) + 1]};
        if (fi < i)
            for (int q = 0; q < 2; q++)
                nx[q] -= ri[i - 1] * y[q];
        for (int64_t k = fi; k < i - 1; k++)
            for (int q = 0; q < 2; q++)
                x[2 * k + q] -= ri[k] * y[q];
        for (int q = 0; q < 2; q++)
            x[2 * (i - 1) + q] = y[q] = nx[q];
    }
}

/* x <- L^-1 x for the nc columns of a row-major x (n x ldx, ldx a multiple of ENV_ROW_COLS >= nc,
   the columns nc..ldx-1 zero), ENV_ROW_COLS columns at a time: one contiguous piece of each row per
   entry of L, which vectorizes.  The columns are ordered by their first non-zero row start[c]
   (non-decreasing; start == NULL: all 0), and a group starts at its first column's. */
void cfc_env_forward_rowmajor(int64_t n, const int64_t *first, const int64_t *ptr, const double *v, int64_t nc,
                              double *x, int64_t ldx, const int64_t *start)
{
    for (int64_t c0 = 0; c0 < nc; c0 += ENV_ROW_COLS) {
        const int64_t s0 = start ? start[c0] : 0;
        for (int64_t i = s0; i < n; i++) {
            const int64_t fi = first[i];
            const double *ri = v + ptr[i] - fi;
            double a[ENV_ROW_COLS];
            for (int q = 0; q < ENV_ROW_COLS; q++)
                a[q] = 0.0;
            for (int64_t k = fi > s0 ? fi : s0; k < i; k++) {
                const double l = ri[k];
                const double *xk = x + k * ldx + c0;
                for (int q = 0; q < ENV_ROW_COLS; q++)
                    a[q] += l * xk[q];
            }
            double *xi = x + i * ldx + c0;
            for (int q = 0; q < ENV_ROW_COLS; q++)
                xi[q] -= a[q];
        }
    }
}

/* x <- L^-T D^-1 x for the nc columns of a row-major x (n x ldx, as cfc_env_forward_rowmajor
   leaves it), ENV_ROW_COLS at a time: one contiguous piece of each row per entry of L */
void cfc_env_backward_rowmajor(int64_t n, const int64_t *first, const int64_t *ptr, const double *v, int64_t nc,
                               double *x, int64_t ldx)
{
    for (int64_t c0 = 0; c0 < nc; c0 += ENV_ROW_COLS) {
        for (int64_t i = 0; i < n; i++) {
            const double d = v[ptr[i + 1] - 1];
            double *xi = x + i * ldx + c0;
            for (int q = 0; q < ENV_ROW_COLS; q++)
                xi[q] /= d;
        }
        for (int64_t i = n - 1; i > 0; i--) {
            const int64_t fi = first[i];
            const double *ri = v + ptr[i] - fi;
            const double *xi = x + i * ldx + c0;
            for (int64_t k = fi; k < i; k++) {
                const double l = ri[k];
                double *xk = x + k * ldx + c0;
                for (int q = 0; q < ENV_ROW_COLS; q++)
                    xk[q] -= l * xi[q];
            }
        }
    }
}

/* x <- L^-T D^-1 x for nc columns (the rest of a solve after cfc_env_forward) */
void cfc_env_backward(int64_t n, const int64_t *first, const int64_t *ptr, const double *v, int64_t nc,
                      double *x, int64_t ldx)
{
    for (int64_t c = 0; c < nc; c++) {
        double *xc = x + c * ldx;
        for (int64_t i = 0; i < n; i++)
            xc[i] /= v[ptr[i + 1] - 1];
        if (n == 0)
            continue;
        double xi = xc[n - 1]; /* x[i], final, kept in a register: the next row waits for it alone */
        for (int64_t i = n - 1; i > 0; i--) {
            const int64_t fi = first[i];
            const double *ri = v + ptr[i] - fi;
            double next = xc[i - 1];
            if (fi < i)
                next -= ri[i - 1] * xi;
            for (int64_t k = fi; k < i - 1; k++)
                xc[k] -= ri[k] * xi;
            xc[i - 1] = xi = next;
        }
    }
}
"""

#: columns that ``cfc_env_forward_rowmajor`` and ``cfc_env_backward_rowmajor`` substitute together
#: (their x's row width is a multiple of it): several independent chains of vector additions (on
#: this project's AVX-512 machine eight columns, one chain, were 2.3x slower)
ENV_ROW_COLS = 32
_SOURCE = f"#define ENV_ROW_COLS {ENV_ROW_COLS}\n" + _SOURCE

_FLAGS = ["-O3", "-ffp-contract=off", "-fno-fast-math", "-fPIC", "-shared"]
_ARCH_FLAGS = (["-march=native"], [])  # the second when the compiler refuses the first

_lib = None
_tried = False


def cache_dir() -> Path:
    """Where compiled kernels are kept."""
    env = os.environ.get("CFCONTACT_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "cfcontact"


def _cpu_features() -> str:
    """The CPU's feature flags (Linux), else the platform's processor string."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith(("flags", "Features")):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def _compiler() -> Optional[str]:
    cc = os.environ.get("CC") or "cc"
    return shutil.which(cc) or shutil.which("gcc")


def _compiler_version(cc: str) -> str:
    try:
        return subprocess.run([cc, "--version"], capture_output=True, text=True, timeout=60).stdout
    except (OSError, subprocess.SubprocessError):
        return ""


def _build(cc: str) -> Optional[Path]:
    """The shared object (compiled now when not cached), or None."""
    version = _compiler_version(cc)
    for arch in _ARCH_FLAGS:
        flags = _FLAGS + arch
        key = hashlib.sha256("\n".join([_SOURCE, " ".join(flags), cc, version, platform.machine(),
                                        _cpu_features()]).encode()).hexdigest()[:20]
        for folder in (cache_dir(), Path(tempfile.gettempdir()) / f"cfcontact-{os.getuid()}"):
            target = folder / f"kernels-{key}.so"
            if target.exists():
                return target
            try:
                folder.mkdir(parents=True, exist_ok=True)
                with tempfile.TemporaryDirectory(dir=folder) as tmp:
                    src = Path(tmp) / "kernels.c"
                    src.write_text(_SOURCE)
                    out = Path(tmp) / "kernels.so"
                    proc = subprocess.run([cc, *flags, str(src), "-o", str(out), "-lm"], capture_output=True,
                                          text=True, timeout=300)
                    if proc.returncode != 0:
                        log.info("compiling cfcontact.native's kernels with %s failed: %s", " ".join(flags),
                                 proc.stderr.strip()[-500:])
                        break  # the next flags
                    os.replace(out, target)  # atomic: a concurrent build leaves one complete file
                return target
            except (OSError, subprocess.SubprocessError) as exc:
                log.info("cannot build cfcontact.native's kernels in %s: %s", folder, exc)
                continue  # the next folder
    return None


def _load():
    """The compiled library with its functions' signatures set, or None."""
    if os.environ.get("CFCONTACT_NATIVE", "1") == "0":
        return None
    cc = _compiler()
    if cc is None:
        log.info("no C compiler found (cc, gcc, $CC): double-double residuals and two-column products by "
                 "NumPy (slower)")
        return None
    path = _build(cc)
    if path is None:
        return None
    try:
        lib = ctypes.CDLL(str(path))
    except OSError as exc:
        log.info("cannot load %s (%s): NumPy instead", path, exc)
        return None
    ptr, i64 = ctypes.c_void_p, ctypes.c_int64
    lib.cfc_dd_residual.argtypes = [i64, ptr, ptr, ptr, i64, ptr, i64, ptr, i64, ptr, i64]
    lib.cfc_gemv2.argtypes = [i64, i64, ptr, i64, ptr, ptr, ptr, ptr]
    lib.cfc_getrs2t.argtypes = [i64, ptr, i64, ptr, ptr, ptr]
    lib.cfc_gemv2t.argtypes = [i64, ptr, i64, ptr, i64, ptr, ptr, ptr, ptr]
    lib.cfc_symv2.argtypes = [i64, ptr, i64, ptr, ptr, ptr, ptr, ptr]
    for f in (lib.cfc_dd_residual, lib.cfc_gemv2, lib.cfc_getrs2t, lib.cfc_gemv2t, lib.cfc_symv2):
        f.restype = None
    lib.cfc_branch_small.argtypes = [i64, ptr, ptr, i64, ptr, ptr, ptr, ptr, ctypes.c_double, ctypes.c_int, ptr, ptr,
                                     ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr]
    lib.cfc_branch_small.restype = ctypes.c_int
    lib.cfc_line_scales.argtypes = [i64, ptr, ptr, ptr, ptr, ctypes.c_double, ctypes.c_double, ptr]
    lib.cfc_line_scales.restype = None
    lib.cfc_branch_line.argtypes = lib.cfc_branch_small.argtypes + [ptr, ctypes.c_double, ptr, ptr, ctypes.c_double,
                                                                     ctypes.c_double, ctypes.c_double, ptr, ptr]
    lib.cfc_branch_line.restype = ctypes.c_int
    d = ctypes.c_double
    lib.cfc_ordinary_step.argtypes = [i64, i64, ptr, ptr, ptr, ptr, ptr, ptr, ptr, i64, ptr, i64, ptr, ptr, ptr, d,
                                      i64, d, d, d, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr, i64, ptr, d, ptr, ptr,
                                      ptr, d, ptr, d, d, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr]
    lib.cfc_ordinary_step.restype = ctypes.c_int
    lib.cfc_tableau_walk.argtypes = [i64, i64, ptr, i64, d, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr, ptr,
                                     ptr, ptr, d, i64, i64, i64, ptr, ptr, ptr, ptr, ptr, i64, i64, i64, ptr, ptr,
                                     ptr, ptr]
    lib.cfc_tableau_walk.restype = ctypes.c_int
    lib.cfc_line_constraints.argtypes = [i64, ptr, ptr, ptr, ptr, ptr, ptr, ctypes.c_double, ctypes.c_double,
                                         ctypes.c_double, ptr, ptr]
    lib.cfc_line_constraints.restype = i64
    lib.cfc_exit.argtypes = [i64, ptr, ptr, ptr, ptr, i64, ctypes.c_double, ctypes.c_double, ctypes.c_double,
                             ctypes.c_double, ptr, ptr]
    lib.cfc_exit.restype = i64
    lib.cfc_tableau_change.argtypes = [i64, i64, ptr, i64, i64, ctypes.c_int, ctypes.c_int, ctypes.c_double, ptr,
                                       ctypes.c_double, ctypes.c_int, ptr]
    lib.cfc_tableau_change.restype = ctypes.c_int
    lib.cfc_tableau_indicators.argtypes = [i64, i64, ptr, i64, ctypes.c_double, ptr, ptr, ptr]
    lib.cfc_tableau_indicators.restype = None
    lib.cfc_env_pattern.argtypes = [i64, ptr, ptr, ptr, ptr, ptr]
    lib.cfc_env_pattern.restype = i64
    lib.cfc_env_fill.argtypes = [i64, ptr, ptr, ptr, ptr, ptr, ptr, ptr]
    lib.cfc_env_fill.restype = None
    lib.cfc_env_ldlt.argtypes = [i64, ptr, ptr, ptr]
    lib.cfc_env_ldlt.restype = i64
    lib.cfc_env_forward.argtypes = [i64, ptr, ptr, ptr, i64, ptr, i64]
    lib.cfc_env_forward.restype = None
    lib.cfc_env_backward.argtypes = [i64, ptr, ptr, ptr, i64, ptr, i64]
    lib.cfc_env_backward.restype = None
    lib.cfc_env_solve2.argtypes = [i64, ptr, ptr, ptr, ptr]
    lib.cfc_env_solve2.restype = None
    lib.cfc_env_forward_rowmajor.argtypes = [i64, ptr, ptr, ptr, i64, ptr, i64, ptr]
    lib.cfc_env_forward_rowmajor.restype = None
    lib.cfc_env_backward_rowmajor.argtypes = [i64, ptr, ptr, ptr, i64, ptr, i64]
    lib.cfc_env_backward_rowmajor.restype = None
    return lib


def library():
    """The compiled library (built and loaded once per process), or None when none can be built."""
    global _lib, _tried
    if not _tried:
        _tried = True
        _lib = _load()
    return _lib


def dd_residual_kernel() -> Optional[Callable]:
    """The compiled double-double residual, or None."""
    lib = library()
    return None if lib is None else lib.cfc_dd_residual


def gemv2(A: np.ndarray, X: np.ndarray) -> Optional[np.ndarray]:
    """A @ X for a C-ordered float64 A and X with two columns, reading A once; None without the
    compiled library or for another layout (then the caller multiplies)."""
    lib = library()
    if lib is None or A.dtype != np.float64 or A.ndim != 2 or not A.flags.c_contiguous or X.shape[1:] != (2,):
        return None
    nr, nc = A.shape
    X = np.asfortranarray(X, dtype=np.float64)
    Y = np.empty((nr, 2), order="F")
    lib.cfc_gemv2(nr, nc, address(A), max(nc, 1), address(X[:, 0]), address(X[:, 1]), address(Y[:, 0]),
                  address(Y[:, 1]))
    return Y


def symv2(A: np.ndarray, X: np.ndarray) -> Optional[np.ndarray]:
    """A @ X for a symmetric C-ordered float64 A and X with two columns, reading only A's upper
    triangle (its lower one is taken to mirror it: the caller checks that A is symmetric); None
    without the compiled library or for another layout (then the caller multiplies)."""
    lib = library()
    if (lib is None or A.dtype != np.float64 or A.ndim != 2 or A.shape[0] != A.shape[1]
            or not A.flags.c_contiguous or X.shape != (A.shape[0], 2)):
        return None
    n = A.shape[0]
    X = np.asfortranarray(X, dtype=np.float64)
    Y = np.empty((n, 2), order="F")
    work = np.empty(8 * n)
    lib.cfc_symv2(n, address(A), max(n, 1), address(X[:, 0]), address(X[:, 1]), address(Y[:, 0]),
                  address(Y[:, 1]), address(work))
    return Y


def gemv2t(A: np.ndarray, idx: np.ndarray, X: np.ndarray) -> Optional[np.ndarray]:
    """A[idx].T @ X for a C-ordered float64 A, row numbers ``idx`` and X with two columns (one row
    per entry of idx), without gathering A's rows; None without the compiled library or for
    another layout (then the caller multiplies)."""
    lib = library()
    if (lib is None or A.dtype != np.float64 or A.ndim != 2 or not A.flags.c_contiguous or X.shape != (len(idx), 2)):
        return None
    nr, nc = A.shape
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    if idx.size and (idx.min() < 0 or idx.max() >= nr):
        raise IndexError(f"row numbers {idx.min()}..{idx.max()} outside 0..{nr - 1}")
    X = np.asfortranarray(X, dtype=np.float64)
    Y = np.empty((nc, 2), order="F")
    lib.cfc_gemv2t(idx.size, address(idx), nc, address(A), max(nc, 1), address(X[:, 0]),
                   address(X[:, 1]), address(Y[:, 0]), address(Y[:, 1]))
    return Y


def getrs2t(lu: np.ndarray, piv: np.ndarray, B: np.ndarray) -> Optional[np.ndarray]:
    """A^-T B for two columns B and A = P L U from LAPACK's getrf (``lu`` Fortran-ordered float64,
    ``piv`` 0-based, as SciPy's ``lapack.dgetrf`` returns them): getrs with trans = 1, one pass
    over the factor for both columns; None without the compiled library or for another layout
    (then the caller solves)."""
    lib = library()
    if (lib is None or lu.dtype != np.float64 or lu.ndim != 2 or lu.shape[0] != lu.shape[1]
            or not lu.flags.f_contiguous or B.shape != (lu.shape[0], 2)):
        return None
    n = lu.shape[0]
    p = np.ascontiguousarray(piv, dtype=np.int32)
    X = np.array(B, dtype=np.float64, order="F")
    lib.cfc_getrs2t(n, address(lu), max(n, 1), address(p), address(X[:, 0]), address(X[:, 1]))
    return X


def dd_residual(kernel, indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, b: np.ndarray,
                x: np.ndarray) -> np.ndarray:
    """b - A x through the compiled ``kernel`` (A: CSR arrays as int64/int64/float64; b: rows x k,
    x: columns x k, k >= 1); the result rows x k, in Fortran order (as PETSc's dense solves take
    it)."""
    nrows, k = b.shape
    b = np.asfortranarray(b, dtype=np.float64)
    x = np.asfortranarray(x, dtype=np.float64)
    r = np.empty((nrows, k), order="F")
    kernel(nrows, address(indptr), address(indices), address(data), k, address(b), max(nrows, 1),
           address(x), max(x.shape[0], 1), address(r), max(nrows, 1))
    return r


def line_scales(W: np.ndarray, L: np.ndarray, sq: np.ndarray, imposed: np.ndarray, rho: float,
                unit: float) -> Optional[np.ndarray]:
    """(scale_v, scale_s, floor_v, floor_s) of a branch (4 x 3m, see ``cfc_line_scales``; the
    NumPy form is :meth:`cfcontact.exact._CondensedData.line`'s) from its data W and multipliers L
    (2m x 2: values, rates), sqrt(diag S) and its imposed rows; None without the compiled library."""
    lib = library()
    if lib is None:
        return None
    n2 = sq.size
    sq = np.ascontiguousarray(sq, dtype=np.float64)
    W = np.ascontiguousarray(W, dtype=np.float64)
    L = np.ascontiguousarray(L, dtype=np.float64)
    if W.shape != (n2, 2) or L.shape != (n2, 2) or imposed.shape != (n2,) or imposed.dtype != np.bool_ or n2 % 2:
        raise ValueError(f"line_scales takes W and L ({n2}, 2) and imposed ({n2},) bool; got {W.shape}, {L.shape}, "
                         f"{imposed.shape} {imposed.dtype}")
    out = np.empty((4, 3 * (n2 // 2)))
    lib.cfc_line_scales(n2 // 2, address(W), address(L), address(sq), address(imposed), rho, unit,
                        address(out))
    return out


def line_constraints(scales: np.ndarray, codes: np.ndarray, kinds: np.ndarray, cons: np.ndarray, G: np.ndarray,
                     E: Optional[np.ndarray], rtol: float, ef: float, around: float) -> Optional[tuple]:
    """A branch's tolerances and constraints in one call (``cfc_line_constraints``; the NumPy form
    is :class:`cfcontact.exact._Line`'s): from its scales (:func:`line_scales`' 4 x 3m), the
    states ``codes`` (int8, m), the node kinds ``kinds`` (int64, m), the constraint signs
    ``cons`` (4 x 3 x 3 float64, C-ordered), the indicators' values and rates G and their
    refinement's change E (3m x 2, C-ordered, or None), rtol, the error factor ef and around =
    what alpha's rounding adds per unit rate.  Returns (tv, ts, cidx, csgn, cnode, c, dc, tol_v,
    tol_s, max(scale_v)), or None without the compiled library."""
    lib = library()
    if lib is None:
        return None
    m = codes.size
    m3 = 3 * m
    if (scales.shape != (4, m3) or not scales.flags.c_contiguous or scales.dtype != np.float64
            or codes.dtype != np.int8 or kinds.dtype != np.int64 or kinds.shape != (m,) or not kinds.flags.c_contiguous
            or cons.shape != (4, 3, 3) or cons.dtype != np.float64 or not cons.flags.c_contiguous):
        raise ValueError(f"line_constraints takes scales (4, {m3}) float64, codes int8, kinds ({m},) int64 and cons "
                         f"(4, 3, 3) float64, C-ordered; got {scales.shape} {scales.dtype}, {codes.dtype}, "
                         f"{kinds.shape} {kinds.dtype}, {cons.shape} {cons.dtype}")
    codes = np.ascontiguousarray(codes)
    G = np.ascontiguousarray(G, dtype=np.float64)
    if E is not None:
        E = np.ascontiguousarray(E, dtype=np.float64)
    if G.shape != (m3, 2) or (E is not None and E.shape != (m3, 2)):
        raise ValueError(f"line_constraints takes G and E ({m3}, 2); got {G.shape}, {None if E is None else E.shape}")
    out = np.empty(6 * m + 10 * m + 1)
    iout = np.empty(4 * m, dtype=np.int64)
    k = lib.cfc_line_constraints(m, address(scales), address(codes), address(kinds), address(cons),
                                 address(G), None if E is None else address(E), rtol, ef, around,
                                 address(out), address(iout))
    if k < 0:
        raise ValueError("line_constraints: a state code outside 0-3 or a node kind outside 0-2")
    m2 = 2 * m
    b = 6 * m
    return (out[:m3], out[m3:b], iout[:k], out[b:b + k], iout[m2:m2 + k], out[b + m2:b + m2 + k],
            out[b + 2 * m2:b + 2 * m2 + k], out[b + 3 * m2:b + 3 * m2 + k], out[b + 4 * m2:b + 4 * m2 + k],
            float(out[-1]))


def first_root(c: np.ndarray, dc: np.ndarray, tol_v: np.ndarray, tol_s: np.ndarray, s: int, alpha0: float,
               aref: float, bound: float, ulps: float):
    """The first root of a branch's decreasing constraints (``cfc_exit``; the NumPy form is
    :func:`cfcontact.exact._exit`'s): (alpha*, tied positions, uncertainty of alpha*), (None,
    None, None) when none lies before ``bound``; False when the compiled library is missing or
    a root is NaN (the caller's NumPy form decides then).  c, dc, tol_v, tol_s: contiguous
    float64 arrays of one size."""
    lib = library()
    if lib is None:
        return False
    k = c.size
    if not (dc.size == tol_v.size == tol_s.size == k and all(
            a.dtype == np.float64 and a.flags.c_contiguous for a in (c, dc, tol_v, tol_s))):
        raise ValueError("first_root takes four contiguous float64 arrays of one size")
    tied = np.empty(k, dtype=np.int64)
    res = np.empty(2)
    n = lib.cfc_exit(k, address(c), address(dc), address(tol_v), address(tol_s), s, alpha0, aref, bound,
                     ulps, address(tied), address(res))
    if n < 0:
        return False
    if n == 0:
        return None, None, None
    return float(res[0]), tied[:n], float(res[1])


def _kept_entry(m: int, k: int, ns: int, lu, piv, ints: np.ndarray, out: np.ndarray, support=None) -> tuple:
    """The factorization entry (lu, piv, rows, slip, coef, support) as
    :meth:`~cfcontact.condensed.CondensedSolver._factor_reduced` keeps it, from the kernel's
    outputs (rows: ints[:k], slip: ints[2m:2m + ns], coef: out[16m:16m + ns]); ``support``: rows
    and m + slip, when the kernel formed it too."""
    rows, slip = ints[:k], ints[2 * m:2 * m + ns]
    coef = out[16 * m:16 * m + ns]
    if not ns:
        return lu, piv, rows, slip, coef, rows
    return lu, piv, rows, slip, coef, (np.concatenate([rows, m + slip]) if support is None else support)


def _line_outputs(m: int, out: np.ndarray, ints: np.ndarray, base: int, ib: int, codes_addr: int) -> tuple:
    """The views of a branch formed by cfc_branch_line in ``out`` / ``ints`` (addresses base, ib):
    (L, G, E, constraints, inputs) -- constraints as :func:`line_constraints` gives them, inputs
    the addresses of the branch's arrays as :class:`OrdinaryStep` reads them (its constraints'
    count, c, dc, tol_v, tol_s, cidx, cnode, g and its stride, dg and its stride, the indicators'
    tolerances, codes), so that a step from this branch needs no address lookups."""
    n2, m3 = 2 * m, 3 * m
    n_out = 16 * m + max(m, 1)
    b, ic, b2 = n_out + 12 * m, n2 + m + 2, n_out + 18 * m
    nc = int(ints[ic + 4 * m])
    L2 = out[:16 * m].reshape(8 * m, 2)
    cons = (out[b:b + m3], out[b + m3:b2], ints[ic:ic + nc], out[b2:b2 + nc], ints[ic + n2:ic + n2 + nc],
            out[b2 + n2:b2 + n2 + nc], out[b2 + 2 * n2:b2 + 2 * n2 + nc], out[b2 + 3 * n2:b2 + 3 * n2 + nc],
            out[b2 + 4 * n2:b2 + 4 * n2 + nc], float(out[b2 + 5 * n2]))
    inputs = (nc, base + 8 * (b2 + n2), base + 8 * (b2 + 2 * n2), base + 8 * (b2 + 3 * n2), base + 8 * (b2 + 4 * n2),
              ib + 8 * ic, ib + 8 * (ic + n2), base + 8 * 2 * n2, 2, base + 8 * (2 * n2 + 1), 2, base + 8 * b,
              base + 8 * (b + m3), codes_addr)
    return L2[:n2], L2[n2:5 * m], L2[5 * m:], cons, inputs


class BranchKernel:
    """The exact method's branch data for small reduced systems in one compiled call
    (``cfc_branch_small``): the reduced matrix of a state, its LU, the solve for the values' and
    the rates' columns with one refinement step, the multipliers, the indicators and the
    refinement's change of them.  What :meth:`cfcontact.condensed.CondensedSolver.branch_data`
    does with some thirty NumPy and LAPACK calls (70 us per branch at 2m = 60, most of it their
    overhead) in one.  Built for one S (C-ordered, 2m x 2m) and friction vector F; :meth:`create`
    returns None without the compiled library."""

    def __init__(self, lib, S: np.ndarray, St: np.ndarray, F: np.ndarray):
        self._lib = lib
        self.S, self.St = S, St  # (kept alive: the kernel reads them by address)
        self.F_source = F  # the caller's friction vector (its owner checks it is still the same)
        self.F = np.ascontiguousarray(F, dtype=np.float64)
        self.m = S.shape[0] // 2
        n2 = 2 * self.m
        self._work = np.empty(max(8 * n2, 1))
        self._iwork = np.empty(max(2 * n2, 1), dtype=np.int64)
        self._addr = (address(S), address(St), address(self.F), address(self._work),
                      address(self._iwork))

    @classmethod
    def create(cls, S: np.ndarray, St: np.ndarray, F: np.ndarray) -> Optional["BranchKernel"]:
        """The kernel for S and its transpose St (the same array when S is symmetric; both
        C-ordered float64), or None without the compiled library or for another layout."""
        lib = library()
        if (lib is None or any(A.dtype != np.float64 or not A.flags.c_contiguous for A in (S, St)) or S.ndim != 2
                or S.shape[0] != S.shape[1] or S.shape[0] % 2 or St.shape != S.shape):
            return None
        return cls(lib, S, St, F)

    def __call__(self, imposed: np.ndarray, codes: np.ndarray, W: np.ndarray, rho: float, entry=None):
        """(entry, L, G, E) for the state ``codes`` (int8, m) with the imposed rows ``imposed``
        (bool, 2m) and the data W (2m x 2, C-ordered float64); entry = (lu, piv, rows, slip, coef,
        support) as :meth:`~cfcontact.condensed.CondensedSolver._factor_reduced` keeps it: formed
        here when ``entry`` is None, else the given one is used.  None when the reduced matrix is
        singular."""
        res = self._run(imposed, codes, W, rho, entry, None, 0.0)
        return None if res is None else res[:4]

    def line(self, imposed: np.ndarray, codes: np.ndarray, W: np.ndarray, rho: float, entry, request: "LineRequest",
             around: float):
        """(entry, L, G, E, (constraints, inputs)): :meth:`__call__`'s, and in the same call the
        branch's tolerances and constraints as :func:`line_constraints` gives them (from
        :func:`line_scales`' scales) for ``request``'s data and ``around``, with the addresses of
        its arrays for :class:`OrdinaryStep` (see ``_line_outputs``); None when the reduced
        matrix is singular."""
        return self._run(imposed, codes, W, rho, entry, request, around)

    def _run(self, imposed, codes, W, rho, entry, request, around):
        m, n2 = self.m, 2 * self.m
        if (W.shape != (n2, 2) or W.dtype != np.float64 or not W.flags.c_contiguous or imposed.shape != (n2,)
                or imposed.dtype != np.bool_ or codes.shape != (m,) or codes.dtype != np.int8):
            raise ValueError(f"cfc_branch_small takes W ({n2}, 2) float64 C-ordered, imposed ({n2},) bool and "
                             f"codes ({m},) int8; got {W.shape} {W.dtype}, {imposed.shape} {imposed.dtype}, "
                             f"{codes.shape} {codes.dtype}")
        # out: L (2m x 2), G (3m x 2), E (3m x 2), coef (m); with a request then the scales (12m),
        # tv, ts (6m), the constraints' csgn, c, dc, tol_v, tol_s (10m), max(sv).  ints: rows (2m),
        # slip (m), (k, ns); with a request then cidx, cnode (4m), their count
        n_out = 16 * m + max(m, 1)
        out = np.empty(n_out + (28 * m + 1 if request is not None else 0))
        ints = np.empty(n2 + m + 2 + (4 * m + 1 if request is not None else 0), dtype=np.int64)
        base, ib = address(out), address(ints)
        S_addr, St_addr, F_addr, work, iwork = self._addr
        if entry is None:
            k = int(np.count_nonzero(imposed))
            lu = np.empty((k, k), order="F")
            piv = np.empty(k, dtype=np.int32)
            args = (ib + 8 * (n2 + m), address(lu), address(piv), ib, ib + 8 * n2, base + 8 * 16 * m)
        else:
            lu, piv, rows, slip, coef, _ = entry
            # (no copies for the kernel's own entries and LAPACK's: already these types)
            lu, piv = np.asfortranarray(lu, dtype=np.float64), np.ascontiguousarray(piv, dtype=np.int32)
            rows, slip = np.ascontiguousarray(rows, dtype=np.int64), np.ascontiguousarray(slip, dtype=np.int64)
            coef = np.ascontiguousarray(coef, dtype=np.float64)
            ints[n2 + m] = rows.size
            ints[n2 + m + 1] = slip.size
            args = (ib + 8 * (n2 + m), address(lu), address(piv), address(rows), address(slip),
                    address(coef))
        common = (m, S_addr, St_addr, max(n2, 1), address(imposed), address(codes), F_addr, address(W), rho,
                  entry is None, *args, base, base + 8 * 4 * m, base + 8 * 10 * m, work, iwork)
        if request is None:
            status = self._lib.cfc_branch_small(*common)
        else:
            sq, kinds, cons = request.addresses
            status = self._lib.cfc_branch_line(*common, sq, request.unit, kinds, cons, request.rtol, request.ef,
                                               around, base + 8 * n_out, ib + 8 * (n2 + m + 2))
            if status == -2:
                raise ValueError("cfc_branch_line: a state code outside 0-3 or a node kind outside 0-2")
        if status:
            return None
        if entry is None:
            k, ns = int(ints[n2 + m]), int(ints[n2 + m + 1])
            entry = _kept_entry(m, k, ns, lu, piv, ints, out)
        if request is not None:
            L, G, E, cons, inputs = _line_outputs(m, out, ints, base, ib, address(codes))
            return entry, L, G, E, (cons, inputs)
        L2 = out[:16 * m].reshape(8 * m, 2)
        return entry, L2[:n2], L2[n2:5 * m], L2[5 * m:], None


class OrdinaryStep:
    """One ordinary transition of the exact method in one compiled call (``cfc_ordinary_step``):
    the first root of a branch, the facet of its single vanishing constraint, the next branch
    there (as :meth:`BranchKernel.line` forms it) and the checks that make the transition an
    ordinary one.  Built once per path from the branch ``kernel``, the constraints' ``request``,
    the pivot table (4 x 3 x 3 int8), the path's data w1, w2 (2m each; dw = w2 - w1) and the
    nodes without tangential unknown (bool m, or None)."""

    def __init__(self, kernel: "BranchKernel", request: "LineRequest", pivot: np.ndarray, w1: np.ndarray,
                 w2: np.ndarray, dw: np.ndarray, no_tangent: Optional[np.ndarray]):
        self.kernel, self.request = kernel, request
        m = self.m = kernel.m
        self.pivot = np.ascontiguousarray(pivot, dtype=np.int8)
        self.w1, self.w2, self.dw = (np.ascontiguousarray(a, dtype=np.float64) for a in (w1, w2, dw))
        if self.pivot.shape != (4, 3, 3) or not (self.w1.shape == self.w2.shape == self.dw.shape == (2 * m,)):
            raise ValueError(f"OrdinaryStep takes a (4, 3, 3) pivot table and data of {2 * m} rows")
        self.no_tangent = (None if no_tangent is None or not np.any(no_tangent) else
                           np.ascontiguousarray(no_tangent, dtype=np.uint8))
        n2 = 2 * m
        self._lu = np.empty(max(n2 * n2, 1))
        self._piv = np.empty(max(n2, 1), dtype=np.int32)
        self._res = np.empty(2)
        self._ires = np.empty(16 + max(4 * m, 1), dtype=np.int64)
        S_addr, St_addr, F_addr, work, iwork = kernel._addr
        sq, kinds, cons = request.addresses
        nt = 0 if self.no_tangent is None else address(self.no_tangent)
        self._fixed = (kinds, address(self.pivot), nt or None, address(self.w1), address(self.w2), address(self.dw),
                       S_addr, St_addr, max(n2, 1), F_addr)
        self._fixed2 = (work, iwork, sq, request.unit, cons, request.rtol, request.ef)
        self._tail = (address(self._lu), address(self._piv))
        self._res_addr = (address(self._res), address(self._ires))

    @staticmethod
    def inputs(c, dc, tol_v, tol_s, cidx, cnode, g, dg, ind_tv, ind_ts, codes) -> Optional[tuple]:
        """The addresses of a branch's arrays as :meth:`__call__` takes them (see
        ``_line_outputs``), or None when they do not have the layout it reads (then the caller's
        general form decides)."""
        m = codes.size
        kc = c.size
        if not (dc.size == tol_v.size == tol_s.size == cidx.size == cnode.size == kc and g.size == dg.size == 3 * m
                and ind_tv.shape == ind_ts.shape == (3 * m,) and codes.dtype == np.int8 and codes.ndim == 1
                and cidx.dtype == cnode.dtype == np.int64 and c.dtype == dc.dtype == tol_v.dtype == tol_s.dtype
                == g.dtype == dg.dtype == ind_tv.dtype == ind_ts.dtype == np.float64 and c.flags.c_contiguous
                and dc.flags.c_contiguous and tol_v.flags.c_contiguous and tol_s.flags.c_contiguous
                and cidx.flags.c_contiguous and cnode.flags.c_contiguous and ind_tv.flags.c_contiguous
                and ind_ts.flags.c_contiguous and codes.flags.c_contiguous
                and g.strides[0] % 8 == 0 and dg.strides[0] % 8 == 0 and g.strides[0] > 0 and dg.strides[0] > 0):
            return None
        return (kc, address(c), address(dc), address(tol_v), address(tol_s), address(cidx), address(cnode),
                address(g), g.strides[0] // 8, address(dg), dg.strides[0] // 8, address(ind_tv), address(ind_ts),
                address(codes))

    @staticmethod
    def moved(inputs: tuple, c: np.ndarray, g: np.ndarray) -> tuple:
        """:meth:`inputs` of a branch whose values c and indicators g were replaced (contiguous
        float64 arrays of the same sizes: its reference point moved)."""
        if not (c.size == inputs[0] and c.dtype == g.dtype == np.float64 and c.flags.c_contiguous
                and g.flags.c_contiguous):
            raise ValueError("OrdinaryStep.moved takes contiguous float64 values of the branch's sizes")
        return (inputs[0], address(c), *inputs[2:7], address(g), 1, *inputs[9:])

    def __call__(self, inputs: tuple, aref: float, s: int, alpha0: float, bound: float, ulps: float, rho: float):
        """(status, result) for the branch whose arrays are at ``inputs`` (:meth:`inputs`; their
        owner keeps them alive) referenced at aref (see ``cfc_ordinary_step``): status 1 (the
        path ends before ``bound``: result None), 2 (not an ordinary transition, or a NaN root:
        None -- the general form decides) or 0 with result = (alpha*, its uncertainty, the
        position j of the vanishing constraint, node, indicator, old and new state, the position
        e of the constraint the new branch is entered by, orientation d, the new codes, their
        imposed rows, the data W, the factorization entry (lu, piv, rows, slip, coef, support),
        L, G, E, the constraints tuple of :meth:`BranchKernel.line` and the new branch's inputs)."""
        m, n2 = self.m, 2 * self.m
        n_out = 16 * m + max(m, 1)
        out = np.empty(n_out + 28 * m + 1 + 2 * n2)  # (then W: 2m x 2)
        ints = np.empty(n2 + m + 2 + 4 * m + 1 + n2, dtype=np.int64)  # (then the support)
        small = np.empty(m + n2, dtype=np.uint8)  # codes (int8, m), imposed (bool, 2m)
        base, ib, sb = address(out), address(ints), address(small)
        nw = n_out + 28 * m + 1
        status = self.kernel._lib.cfc_ordinary_step(
            m, *inputs, aref, s, alpha0, bound, ulps, *self._fixed, rho, *self._fixed2, sb, sb + m, base + 8 * nw,
            *self._tail, ib, base, *self._res_addr)
        if status:
            return (status if status == 1 else 2), None
        j, node, ind, old, new, e, d = self._ires[:7].tolist()
        k, ns = ints[n2 + m:n2 + m + 2].tolist()
        lu = self._lu[:k * k].reshape((k, k), order="F").copy(order="F")
        piv = self._piv[:k].copy()
        so = n2 + m + 3 + 4 * m
        entry = _kept_entry(m, k, ns, lu, piv, ints, out, ints[so:so + k + ns])
        codes = small[:m].view(np.int8)
        L, G, E, cons, new_inputs = _line_outputs(m, out, ints, base, ib, sb)
        res = self._res
        return 0, (float(res[0]), float(res[1]), j, node, ind, old, new, e, d, codes, small[m:].view(bool),
                   out[nw:].reshape(n2, 2), entry, L, G, E, cons, new_inputs)


class LineRequest:
    """What :meth:`BranchKernel.line` needs beyond the branch: sqrt(diag S), the node kinds and
    the constraint signs (kept alive here, read by address), the data's rounding unit, rtol and
    the error factor (see :func:`line_scales`, :func:`line_constraints`)."""

    def __init__(self, sq: np.ndarray, kinds: np.ndarray, cons: np.ndarray, unit: float, rtol: float, ef: float):
        self.sq = np.ascontiguousarray(sq, dtype=np.float64)
        self.kinds = np.ascontiguousarray(kinds, dtype=np.int64)
        self.cons = np.ascontiguousarray(cons, dtype=np.float64)
        if self.cons.shape != (4, 3, 3) or self.kinds.shape != (self.sq.size // 2,):
            raise ValueError(f"LineRequest takes kinds ({self.sq.size // 2},) and cons (4, 3, 3); got "
                             f"{self.kinds.shape}, {self.cons.shape}")
        self.unit, self.rtol, self.ef = float(unit), float(rtol), float(ef)
        self.kinds_given = kinds  # (the caller's array, for its check that the request is still its own)
        self.addresses = (address(self.sq), address(self.kinds), address(self.cons))
