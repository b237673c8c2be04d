"""A compiled kernel for the one loop NumPy cannot do fast: the double-double residual
r = b - A x of iterative refinement (:class:`cfcontact.linalg.ExactResidual`).

NumPy forms that residual slot by slot over whole columns, with some twenty temporaries per
entry of A: at n = 1e6 (K of two refined blocks) that was 0.5 s per right-hand side, 22 s of the
set-up of an exact path that otherwise takes 3 s.  The same arithmetic in C over A's CSR rows
takes a few hundredths of a second per right-hand side.

The C source below is compiled on first use (never at import) with the C compiler that dolfinx
itself needs for its forms (``cc``, or ``$CC``), ``-O3 -march=native -ffp-contract=off``: no
fast-math and no contraction, which would change the rounding that the error-free
transformations rely on; the exact product's error comes from ``fma`` where the CPU has it,
else from Dekker's splitting (the same value: both are exact).  The shared object is kept in
``$CFCONTACT_CACHE_DIR`` (default ``$XDG_CACHE_HOME/cfcontact`` or ``~/.cache/cfcontact``) under
a name that hashes the source, the flags, the compiler and the CPU's features, so a cache shared
between different machines never loads code built for another CPU; it is written to a temporary
name and renamed, so concurrent first uses (MPI ranks, test workers) are safe.

Without a working compiler (or with ``CFCONTACT_NATIVE=0``) :func:`dd_residual_kernel` returns
None and the NumPy implementation is used: the same operations in the same order, so the same
bits, only slower.  Nothing here is imported by the other layers but :mod:`cfcontact.linalg`.
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
"""

_FLAGS = ["-O3", "-ffp-contract=off", "-fno-fast-math", "-fPIC", "-shared"]
_ARCH_FLAGS = (["-march=native"], [])  # the second when the compiler refuses the first

_kernel: Optional[Callable] = None
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
            target = folder / f"ddresidual-{key}.so"
            if target.exists():
                return target
            try:
                folder.mkdir(parents=True, exist_ok=True)
                with tempfile.TemporaryDirectory(dir=folder) as tmp:
                    src = Path(tmp) / "ddresidual.c"
                    src.write_text(_SOURCE)
                    out = Path(tmp) / "ddresidual.so"
                    proc = subprocess.run([cc, *flags, str(src), "-o", str(out), "-lm"], capture_output=True,
                                          text=True, timeout=300)
                    if proc.returncode != 0:
                        log.info("compiling the double-double kernel with %s failed: %s", " ".join(flags),
                                 proc.stderr.strip()[-500:])
                        break  # the next flags
                    os.replace(out, target)  # atomic: a concurrent build leaves one complete file
                return target
            except (OSError, subprocess.SubprocessError) as exc:
                log.info("cannot build the double-double kernel in %s: %s", folder, exc)
                continue  # the next folder
    return None


def _load() -> Optional[Callable]:
    if os.environ.get("CFCONTACT_NATIVE", "1") == "0":
        return None
    cc = _compiler()
    if cc is None:
        log.info("no C compiler found (cc, gcc, $CC): double-double residuals by NumPy (slower)")
        return None
    path = _build(cc)
    if path is None:
        return None
    try:
        lib = ctypes.CDLL(str(path))
    except OSError as exc:
        log.info("cannot load %s (%s): double-double residuals by NumPy", path, exc)
        return None
    fn = lib.cfc_dd_residual
    ptr = ctypes.c_void_p
    i64 = ctypes.c_int64
    fn.argtypes = [i64, ptr, ptr, ptr, i64, ptr, i64, ptr, i64, ptr, i64]
    fn.restype = None
    return fn


def dd_residual_kernel() -> Optional[Callable]:
    """The compiled kernel (built and loaded once per process), or None when none can be built."""
    global _kernel, _tried
    if not _tried:
        _tried = True
        _kernel = _load()
    return _kernel


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
