"""Compiled kernels for the two loops that NumPy and BLAS do not do fast enough here:

* the double-double residual r = b - A x of iterative refinement
  (:class:`cfcontact.linalg.ExactResidual`).  NumPy forms it slot by slot over whole columns,
  with some twenty temporaries per entry of A: at n = 1e6 (K of two refined blocks) that was
  0.5 s per right-hand side, 22 s of the set-up of an exact path that otherwise takes 3 s.  The
  same arithmetic in C over A's CSR rows takes 0.02 s per right-hand side.
* the dense product of a C-ordered A with two columns (:func:`gemv2`: the exact method's
  branches have two, the values and the rates): one pass over A, two rows at a time with
  software prefetch, instead of BLAS' gemv once per column (its gemm with two columns is slower
  still).  1.2 instead of 1.7 ms at 1728 rows, 5.9 instead of 11 ms at 4000, single thread.

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
slower; for the products BLAS' gemv, column by column.  Used by :mod:`cfcontact.linalg` and
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

_SOURCE = r"""
#include <math.h>
#include <stdint.h>

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

/* two rows' dot products with x0 and x1 (4 accumulators of 4 lanes; two memory streams) */
static inline void rows2(int64_t nc, const double *a, const double *b, const double *x0, const double *x1,
                         double *y)
{
    v4d z = {0.0, 0.0, 0.0, 0.0}, sa0 = z, sa1 = z, sb0 = z, sb1 = z;
    int64_t j = 0;
    for (; j + 4 <= nc; j += 4) {
        __builtin_prefetch(a + j + 256);
        __builtin_prefetch(b + j + 256);
        v4d u = *(const v4d *)(x0 + j), v = *(const v4d *)(x1 + j);
        v4d ra = *(const v4d *)(a + j), rb = *(const v4d *)(b + j);
        sa0 += ra * u;
        sa1 += ra * v;
        sb0 += rb * u;
        sb1 += rb * v;
    }
    double t[4] = {0.0, 0.0, 0.0, 0.0};
    for (; j < nc; j++) {
        t[0] += a[j] * x0[j];
        t[1] += a[j] * x1[j];
        t[2] += b[j] * x0[j];
        t[3] += b[j] * x1[j];
    }
    y[0] = ((sa0[0] + sa0[2]) + (sa0[1] + sa0[3])) + t[0];
    y[1] = ((sa1[0] + sa1[2]) + (sa1[1] + sa1[3])) + t[1];
    y[2] = ((sb0[0] + sb0[2]) + (sb0[1] + sb0[3])) + t[2];
    y[3] = ((sb1[0] + sb1[2]) + (sb1[1] + sb1[3])) + t[3];
}

void cfc_gemv2(int64_t nr, int64_t nc, const double *A, int64_t lda, const double *x0, const double *x1,
               double *y0, double *y1)
{
    double y[4];
    int64_t i = 0;
    for (; i + 2 <= nr; i += 2) {
        rows2(nc, A + i * lda, A + (i + 1) * lda, x0, x1, y);
        y0[i] = y[0];
        y1[i] = y[1];
        y0[i + 1] = y[2];
        y1[i + 1] = y[3];
    }
    if (i < nr) {
        rows2(nc, A + i * lda, A + i * lda, x0, x1, y);
        y0[i] = y[0];
        y1[i] = y[1];
    }
}
"""

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
    lib.cfc_dd_residual.restype = lib.cfc_gemv2.restype = None
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
    lib.cfc_gemv2(nr, nc, A.ctypes.data, max(nc, 1), X[:, 0].ctypes.data, X[:, 1].ctypes.data, Y[:, 0].ctypes.data,
                  Y[:, 1].ctypes.data)
    return Y


def dd_residual(kernel, indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, b: np.ndarray,
                x: np.ndarray) -> np.ndarray:
    """b - A x through the compiled ``kernel`` (A: CSR arrays as int64/int64/float64; b: rows x k,
    x: columns x k, k >= 1); the result rows x k, in Fortran order (as PETSc's dense solves take
    it)."""
    nrows, k = b.shape
    b = np.asfortranarray(b, dtype=np.float64)
    x = np.asfortranarray(x, dtype=np.float64)
    r = np.empty((nrows, k), order="F")
    kernel(nrows, indptr.ctypes.data, indices.ctypes.data, data.ctypes.data, k, b.ctypes.data, max(nrows, 1),
           x.ctypes.data, max(x.shape[0], 1), r.ctypes.data, max(nrows, 1))
    return r
