"""Version compatibility, PETSc side: what petsc4py does not wrap (the compatibility layer's
half without dolfinx, so that the solvers need not import dolfinx; :mod:`cfcontact.compat` is
the dolfinx and gmsh half).

The Schur complement of a factorization (MUMPS computes it during the factorization of K,
:class:`cfcontact.condensed.CondensedSolver`): petsc4py wraps neither ``MatFactorSetSchurIS`` nor
``MatFactorGetSchurComplement`` (3.18 of Debian 12, 3.22 of Debian 13, nor 3.24).  Feature
detection decides how each call is made: a petsc4py method of that name when petsc4py has one,
else the C function through ctypes, looked up in the libraries petsc4py's extension module links
(``dlsym`` on its handle searches them), whatever their names and paths.  PetscInt's width comes
from ``PETSc.IntType``.  When neither is there, :func:`schur_complement_available` is False and
the callers form S another way.
"""

from __future__ import annotations

import ctypes
import functools
from typing import Optional

import numpy as np
from petsc4py import PETSc

#: the C functions of the Schur-complement route
SCHUR_FUNCTIONS = ("MatFactorSetSchurIS", "MatFactorGetSchurComplement", "MatFactorRestoreSchurComplement",
                   "MatDenseGetLDA", "MatDenseGetArrayRead", "MatDenseRestoreArrayRead")


@functools.lru_cache(maxsize=None)
def _libpetsc():
    """libpetsc's functions (ctypes), through petsc4py's extension module; None without them."""
    try:
        lib = ctypes.CDLL(PETSc.__file__)
        for name in SCHUR_FUNCTIONS:
            getattr(lib, name)
    except (OSError, AttributeError):
        return None
    vp, petsc_int = ctypes.c_void_p, ctypes.c_int64 if np.dtype(PETSc.IntType).itemsize == 8 else ctypes.c_int32
    lib.MatFactorSetSchurIS.argtypes = [vp, vp]
    lib.MatFactorGetSchurComplement.argtypes = [vp, ctypes.POINTER(vp), ctypes.POINTER(ctypes.c_int)]
    lib.MatFactorRestoreSchurComplement.argtypes = [vp, ctypes.POINTER(vp), ctypes.c_int]
    lib.MatDenseGetLDA.argtypes = [vp, ctypes.POINTER(petsc_int)]
    lib.MatDenseGetArrayRead.argtypes = [vp, ctypes.POINTER(ctypes.POINTER(ctypes.c_double))]
    lib.MatDenseRestoreArrayRead.argtypes = [vp, ctypes.POINTER(ctypes.POINTER(ctypes.c_double))]
    lib.petsc_int = petsc_int
    return lib


def schur_complement_available() -> bool:
    """Can a factorization be asked for its Schur complement (petsc4py or libpetsc)?"""
    return hasattr(PETSc.Mat, "factorSetSchurIS") or _libpetsc() is not None


def factor_set_schur_is(factor: PETSc.Mat, indices) -> PETSc.IS:
    """``MatFactorSetSchurIS``: ask the (not yet numerically factored) ``factor`` for the Schur
    complement on ``indices`` (serial).  Returns the IS (keep it alive with the factor);
    RuntimeError when PETSc refuses or cannot be asked."""
    is_ = PETSc.IS().createGeneral(np.asarray(indices).astype(PETSc.IntType), comm=PETSc.COMM_SELF)
    native = getattr(factor, "factorSetSchurIS", None)
    if native is not None:
        native(is_)
        return is_
    lib = _libpetsc()
    if lib is None:
        raise RuntimeError("this PETSc offers no MatFactorSetSchurIS (neither petsc4py nor its library)")
    err = lib.MatFactorSetSchurIS(ctypes.c_void_p(factor.handle), ctypes.c_void_p(is_.handle))
    if err:
        raise RuntimeError(f"MatFactorSetSchurIS returned {err}")
    return is_


def factor_schur_complement(factor: PETSc.Mat, k: int) -> Optional[np.ndarray]:
    """A dense copy (k x k) of the Schur complement ``factor`` computed during its factorization
    (``MatFactorGetSchurComplement``), or None when PETSc does not give it.  Read it right after
    the factorization: PETSc factors it in place at the first solve."""
    lib = _libpetsc()
    if lib is None:
        return None
    vp = ctypes.c_void_p
    Smat, status = vp(), ctypes.c_int()
    if lib.MatFactorGetSchurComplement(vp(factor.handle), ctypes.byref(Smat), ctypes.byref(status)) or status.value:
        return None
    try:
        lda = lib.petsc_int()
        arr = ctypes.POINTER(ctypes.c_double)()
        if lib.MatDenseGetLDA(Smat, ctypes.byref(lda)) or lib.MatDenseGetArrayRead(Smat, ctypes.byref(arr)):
            return None
        try:
            return np.ctypeslib.as_array(arr, shape=(k, int(lda.value)))[:, :k].T.copy()  # column-major
        finally:
            lib.MatDenseRestoreArrayRead(Smat, ctypes.byref(arr))
    finally:
        lib.MatFactorRestoreSchurComplement(vp(factor.handle), ctypes.byref(Smat), status.value)
