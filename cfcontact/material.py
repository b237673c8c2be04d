"""Linear elastic material of the 2-D models: the checks and the Lamé parameters.

Shared by the assembly (:mod:`cfcontact.assembly`), the case files (:mod:`cfcontact.case`) and
the stress post-processing (:mod:`cfcontact.fields`), so that E, nu and the plane are checked by
one set of rules.  NumPy only.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from cfcontact.errors import InputError

#: The 2-D models: plane strain (sigma_zz = lambda tr eps) or plane stress (sigma_zz = 0).
PLANES = ("strain", "stress")
#: The library's default material: steel, plane strain.
DEFAULT_MATERIAL = {"E": 2.1e11, "nu": 0.3, "plane": "strain"}


def check_plane(plane) -> str:
    if plane not in PLANES:
        raise InputError(f"plane must be 'strain' or 'stress', got {plane!r}")
    return plane


#: The range of Young's modulus the solver handles in double precision: K's entries are of the
#: size of E, and its factorization treats pivots below ~1e-14 as zero; far above, the products
#: of the path (indicators, residual norms) overflow.  Any unit system of real materials fits
#: (rubber 1e6 Pa ... diamond 1.2e12 Pa; 1e-3 ... 1e3 in GPa), and so do nondimensional models.
E_RANGE = (1e-6, 1e20)


def check_modulus(E) -> float:
    """Young's modulus: a finite number > 0 within :data:`E_RANGE`."""
    E = _number(E, "E")
    if not (np.isfinite(E) and E > 0):
        raise InputError(f"Young's modulus E must be a finite positive number, got {E!r}")
    lo, hi = E_RANGE
    if not lo <= E <= hi:
        raise InputError(f"Young's modulus E = {E!r} is too {'small' if E < lo else 'large'} for double precision "
                         f"(the stiffness would be {'zero to the factorization' if E < lo else 'near overflow'}); "
                         f"use units in which it lies in [{lo:g}, {hi:g}] (e.g. MPa or GPa), scaling the loads alike")
    return E


def check_poisson(nu) -> float:
    """Poisson's ratio: a number in (-1, 0.5)."""
    nu = _number(nu, "nu")
    if not (np.isfinite(nu) and -1.0 < nu < 0.5):
        raise InputError(f"Poisson's ratio nu must lie in (-1, 0.5), got {nu!r}")
    return nu


def _number(value, name) -> float:
    if isinstance(value, (bool, np.bool_)):
        raise InputError(f"{name} must be a number, got {value!r}")
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number, got {value!r}") from None


def lame_parameters(E, nu, plane="strain"):
    """Lamé parameters (lambda, mu) of the 2-D model (plane strain or plane stress)."""
    E, nu = check_modulus(E), check_poisson(nu)
    check_plane(plane)
    lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))
    mu = E / (2.0 * (1.0 + nu))
    if plane == "strain":
        return lam, mu
    return 2.0 * lam * mu / (lam + 2.0 * mu), mu


def material_items(value, what):
    """[(body spec or None, value)] of a material parameter: a number or {body: number}."""
    if isinstance(value, Mapping):
        if not value:
            raise InputError(f"{what} is an empty dict; give a number or {{body name/number: value}}")
        return list(value.items())
    return [(None, value)]


def check_material(E, nu, plane="strain"):
    """Validate E and nu (numbers or dicts {body: number}) and ``plane`` before any collective work."""
    check_plane(plane)
    for name, check in (("E", check_modulus), ("nu", check_poisson)):
        for body, v in material_items(E if name == "E" else nu, name):
            where = "" if body is None else f" (in {name}[{body!r}])"
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise InputError(f"{name} must be a number, got {v!r}{where}")
            try:
                check(v)
            except InputError as exc:
                raise InputError(f"{exc}{where}") from None
