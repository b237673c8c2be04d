"""What the gmsh scripts of :mod:`cfcontact.meshes` share: the tag convention and the parameter checks."""

from __future__ import annotations

import math
import operator
import os

from cfcontact.errors import GeometryError, InputError  # noqa: F401  (GeometryError: for the scripts)

#: physical group numbers of every model (DESIGN.md; README "Tag convention")
TAGS = {
    "body1": (2, 1),
    "body2": (2, 2),
    "contact1": (1, 10),
    "top1": (1, 12),
    "right1": (1, 13),
    "left1": (1, 14),
    "contact2": (1, 20),
    "bottom2": (1, 22),
    "right2": (1, 23),
    "left2": (1, 24),
}

CELLS = ("quadrilateral", "triangle")
_CELL_ALIASES = {"quadrilateral": "quadrilateral", "quad": "quadrilateral", "quadrilaterals": "quadrilateral",
                 "triangle": "triangle", "tri": "triangle", "triangles": "triangle"}


def check_count(name, value, minimum=1):
    """An integer >= ``minimum`` (booleans refused), else InputError naming ``name``."""
    try:
        if isinstance(value, bool):
            raise TypeError
        value = operator.index(value)
    except TypeError:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}") from None
    if value < minimum:
        raise InputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return value


def check_length(name, value):
    """A finite positive number (booleans refused), else InputError naming ``name``."""
    try:
        if isinstance(value, bool):
            raise TypeError
        value = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a positive number, got {value!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"{name} must be a positive number, got {value!r}")
    return value


def check_angle(name, value):
    """A finite number of degrees, else InputError naming ``name``."""
    try:
        if isinstance(value, bool):
            raise TypeError
        value = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a number (degrees), got {value!r}") from None
    if not math.isfinite(value):
        raise InputError(f"{name} must be finite, got {value!r}")
    return value


def check_cell(cell):
    """"quadrilateral" or "triangle" (a few aliases accepted), else InputError listing CELLS."""
    key = str(cell).lower()
    if key not in _CELL_ALIASES:
        raise InputError(f"cell must be one of {CELLS}, got {cell!r}")
    return _CELL_ALIASES[key]


def structured_surface(geo, corners, bottom, right, top, left, mx, my, cell):
    """A transfinite surface bounded by four curves: ``bottom``/``top`` oriented left -> right with
    ``mx`` cells, ``right``/``left`` bottom -> top with ``my`` cells (parallel sides share one
    parametrisation, so opposite nodes match); ``corners`` the four points counter-clockwise from
    bottom-left.  Quadrilaterals are recombined; triangles split each quadrilateral in two."""
    loop = geo.addCurveLoop([bottom, right, -top, -left])
    surf = geo.addPlaneSurface([loop])
    for ln in (bottom, top):
        geo.mesh.setTransfiniteCurve(ln, mx + 1)
    for ln in (right, left):
        geo.mesh.setTransfiniteCurve(ln, my + 1)
    geo.mesh.setTransfiniteSurface(surf, "Left", list(corners))
    if cell == "quadrilateral":
        geo.mesh.setRecombine(2, surf)
    return surf


def add_physical_groups(gmsh, groups):
    """Create the physical groups ``{name: (dim, [entities])}`` with TAGS' numbers and names;
    returns ``{name: (dim, number)}``."""
    created = {}
    for name, (dim, ents) in groups.items():
        number = TAGS[name][1]
        gmsh.model.addPhysicalGroup(dim, ents, number)
        gmsh.model.setPhysicalName(dim, number, name)
        created[name] = (dim, number)
    return created


def write_msh(filename, model_name, build, **params):
    """Build a model (``build(**params)``, a script's builder) in a gmsh session of its own and write
    it to ``filename`` (MSH 4.1): what the scripts do when they run as programs."""
    import gmsh

    gmsh.initialize([], False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(model_name)
        build(**params)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.write(os.fspath(filename))
    finally:
        gmsh.finalize()
