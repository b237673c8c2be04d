"""Ready-made FEM models (gmsh geometry + assembly).

Importing this module does not import dolfinx or gmsh: the assembly layer and the
geometry scripts are imported inside the functions.
"""

from __future__ import annotations

import math
import warnings
from types import MappingProxyType

from cfcontact.errors import IgnoredOptionWarning, InputError

__all__ = ["two_blocks", "arc_on_block", "cylinder_on_block", "rounded_punch", "DEFAULT_TRACTIONS1",
           "DEFAULT_TRACTIONS2"]

#: Default surface tractions (Pa = N/m^2, force per unit length in 2-D) of the load f1:
#: a downward pressure of 1e8 on the top of body 1 with a small shear (ratio 0.2).
#: Placeholders for the demos to tune: with steel the largest displacement of the
#: free (contact-less) body 1 would be ~0.06 of its length 3.
DEFAULT_TRACTIONS1 = MappingProxyType({"top1": (2.0e7, -1.0e8)})
#: Default surface tractions of the load f2: mostly shear (1e8), less pressure (2e7).
DEFAULT_TRACTIONS2 = MappingProxyType({"top1": (1.0e8, -2.0e7)})


def _rotate(vec, angle):
    c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    try:
        x, y = (float(t) for t in vec)
    except (TypeError, ValueError):
        return vec  # malformed: the assembly reports it
    return (c * x - s * y, s * x + c * y)


def _script(name):
    """The gmsh script module cfcontact.meshes.<name> (it imports gmsh: from any thread)."""
    import importlib

    from cfcontact.interrupts import import_gmsh

    import_gmsh()
    return importlib.import_module(f"cfcontact.meshes.{name}")


def _rotate_loads(loads, angle, kind):
    if loads is None or angle == 0.0:
        return loads
    if kind == "body" and not hasattr(loads, "items"):
        return _rotate(loads, angle)
    if not hasattr(loads, "items"):
        return loads
    for k, v in loads.items():
        # a windowed traction (a dict) or a list of tractions (with a dict or a pair among its items); a
        # pair of numbers of any numeric type (NumPy scalars too) is one uniform traction
        if kind == "traction" and (hasattr(v, "items") or (isinstance(v, (list, tuple)) and any(
                hasattr(t, "items") or (hasattr(t, "__len__") and not isinstance(t, str)) for t in v))):
            raise InputError(f"traction {k!r}: windowed tractions ({v!r}) cannot be combined with angle={angle:g} "
                             f"(their 'x'/'y' windows would be in the rotated frame); use angle=0 or uniform tractions")
    return {k: _rotate(v, angle) for k, v in loads.items()}


def two_blocks(
    *,
    nx=30,
    ny=10,
    length=3.0,
    height=1.0,
    cell="quadrilateral",
    E=2.1e11,
    nu=0.3,
    plane="strain",
    friction=0.0,
    clamp=None,
    tractions1=DEFAULT_TRACTIONS1,
    tractions2=DEFAULT_TRACTIONS2,
    body_force1=None,
    body_force2=None,
    rho=None,
    angle=0.0,
    comm=None,
    nx2=None,
    ny2=None,
    height2=None,
    foundation=False,
    match_tol=1e-8,
    dirichlet=None,
    pairing=None,
    slave="contact1",
    search_distance=None,
    obstacle=None,
):
    """The seed's two stacked blocks as a :class:`cfcontact.system.ContactSystem`.

    Body 1 ``[0, length] x [0, height]`` lies on body 2 ``[0, length] x [-height, 0]``;
    each is meshed with ``nx x ny`` cells (quadrilaterals, or triangles = each
    quadrilateral split in two) and, by default, clamped along its left edge
    (``left1``, ``left2``).  Defaults: 30 x 10 cells, length 3, height 1, steel
    (E = 2.1e11 Pa, nu = 0.3), plane strain -> n = 1320, m = 30.  ``E`` and ``nu`` may also be
    dicts with one value per body, e.g. ``E={"body1": 2.1e11, "body2": 2.1e8}``.

    Loads: ``tractions1`` / ``tractions2`` (dicts ``{boundary piece: (tx, ty)}``,
    pieces ``top1, right1, left1, bottom2, right2, left2``; a value may also be a windowed
    traction ``{"value": (tx, ty), "x": (x0, x1)}`` or a list, see
    :func:`cfcontact.assembly.assemble_contact_system`) and ``body_force1`` /
    ``body_force2`` define f1 and f2.  Defaults :data:`DEFAULT_TRACTIONS1`
    (``top1``: (2e7, -1e8)) and :data:`DEFAULT_TRACTIONS2` (``top1``: (1e8, -2e7));
    pass ``{}`` for no traction.  Load vectors are given in the frame of the
    unrotated blocks and turn with the assembly when ``angle`` (degrees,
    counter-clockwise about the origin) is not zero; prescribed displacements (``dirichlet``)
    are in the global frame and do not turn.

    ``foundation=True`` builds body 1 alone on a rigid foundation (clamp default
    ``("left1",)``), or against a rigid ``obstacle`` (a line or a circle, see
    :func:`cfcontact.assembly.assemble_contact_system`).  ``nx2, ny2, height2`` set body 2's
    mesh separately: ``nx2 != nx`` makes a non-matching interface, which needs
    ``pairing="segment"`` (node-to-segment; with the default node pairing it is rejected).
    ``dirichlet``, ``pairing``, ``slave``, ``search_distance`` and the remaining arguments go to
    :func:`cfcontact.assembly.assemble_contact_system`.
    """
    from mpi4py import MPI

    from cfcontact import compat  # imports dolfinx
    from cfcontact.assembly import assemble_contact_system

    comm = MPI.COMM_WORLD if comm is None else comm
    given = [f"{k}={v!r}" for k, v in (("nx2", nx2), ("ny2", ny2), ("height2", height2)) if v is not None]
    if foundation and given:  # (a case file refuses them)
        warnings.warn(f"{', '.join(given)} ignored: body 2's mesh, but foundation=True builds body 1 alone",
                      IgnoredOptionWarning, stacklevel=2)
        nx2 = ny2 = height2 = None
    geo = _script("two_blocks")
    params = geo.check_parameters(nx, ny, length, height, cell, angle, nx2=nx2, ny2=ny2, height2=height2)
    if clamp is None:
        clamp = ("left1",) if foundation else ("left1", "left2")
    angle = params["angle"]
    kwargs = dict(
        E=E, nu=nu, plane=plane, clamp=clamp,
        tractions1=_rotate_loads(tractions1, angle, "traction"),
        tractions2=_rotate_loads(tractions2, angle, "traction"),
        body_force1=_rotate_loads(body_force1, angle, "body"),
        body_force2=_rotate_loads(body_force2, angle, "body"),
        friction=friction, rho=rho, comm=comm, match_tol=match_tol, dirichlet=dirichlet,
        pairing=pairing, slave=slave, search_distance=search_distance, obstacle=obstacle,
    )
    info = {"model": "two_blocks", "model_parameters": dict(params, foundation=bool(foundation))}
    if comm.rank == 0:
        with compat.gmsh_model("cfcontact-two-blocks") as model:
            geo.build(foundation=foundation, **params)
            return assemble_contact_system(model, info=info, **kwargs)
    return assemble_contact_system(None, info=info, **kwargs)


def arc_on_block(
    *,
    radius=1.0,
    half_angle=30.0,
    height=0.5,
    height2=None,
    nx=16,
    ny=4,
    ny2=None,
    cell="quadrilateral",
    E=2.1e11,
    nu=0.3,
    plane="strain",
    friction=0.0,
    clamp=("left1", "bottom2"),
    tractions1=DEFAULT_TRACTIONS1,
    tractions2=DEFAULT_TRACTIONS2,
    body_force1=None,
    body_force2=None,
    rho=None,
    comm=None,
    match_tol=1e-8,
    dirichlet=None,
    pairing=None,
    slave="contact1",
    search_distance=None,
):
    """A body with a convex circular-arc bottom in a matching concave seat: a curved interface.

    Body 2 is a block whose top is a concave arc of radius ``radius`` and half-angle
    ``half_angle`` (degrees, in (0, 80]) centred at ``(0, radius)``, lowest point at the origin;
    body 1 sits in it, its bottom the matching convex arc, its sides ``height`` high above the
    ends of the arc, its top flat.  Body 2 is ``height2`` (default ``height``) thick below the
    lowest point.  ``nx`` cells along the arc, ``ny`` / ``ny2`` across body 1 / body 2
    (structured quadrilaterals or triangles, see :mod:`cfcontact.meshes.arc_on_block`).  The contact
    normals are radial: they turn by ``2 * half_angle`` along the interface.

    The interface is **conforming** (the bodies touch along the whole arc; initial gaps are not
    modelled).  Default clamps: ``left1`` (side of body 1) and ``bottom2`` (base of the seat);
    default loads as in :func:`two_blocks` on ``top1``.  Tags: ``top1, right1, left1, bottom2,
    right2, left2``.  The remaining arguments (``dirichlet``, ``pairing``...) go to
    :func:`cfcontact.assembly.assemble_contact_system`.
    """
    from mpi4py import MPI

    from cfcontact import compat  # imports dolfinx
    from cfcontact.assembly import assemble_contact_system

    comm = MPI.COMM_WORLD if comm is None else comm
    geo = _script("arc_on_block")
    params = geo.check_parameters(radius=radius, half_angle=half_angle, height=height, height2=height2,
                                  nx=nx, ny=ny, ny2=ny2, cell=cell)
    kwargs = dict(
        E=E, nu=nu, plane=plane, clamp=clamp, tractions1=tractions1, tractions2=tractions2,
        body_force1=body_force1, body_force2=body_force2,
        friction=friction, rho=rho, comm=comm, match_tol=match_tol, dirichlet=dirichlet,
        pairing=pairing, slave=slave, search_distance=search_distance,
    )
    info = {"model": "arc_on_block", "model_parameters": dict(params)}
    if comm.rank == 0:
        with compat.gmsh_model("cfcontact-arc-on-block") as model:
            geo.build(**params)
            return assemble_contact_system(model, info=info, **kwargs)
    return assemble_contact_system(None, info=info, **kwargs)


def _pair(value, what):
    """A number (the same along the path) or a pair (value at alpha = 0, value at alpha = 1)."""
    try:
        if isinstance(value, (bool, str)):
            raise TypeError
        vals = [float(v) for v in (value if hasattr(value, "__len__") else (value, value))]
    except (TypeError, ValueError):
        vals = []
    if len(vals) != 2 or not all(math.isfinite(v) for v in vals):
        raise InputError(f"{what} must be a number or a pair (value at alpha = 0, value at alpha = 1), got {value!r}")
    return tuple(vals)


def _punch_loading(dirichlet, indentation, shift, half):
    """The default Dirichlet conditions of a body pressed by its top edge: u = (shift(alpha),
    -indentation(alpha)) on top1, and u_x = 0 on the symmetry edges of a half model."""
    if dirichlet is not None:
        return dirichlet
    out = {"top1": {"x": _pair(shift, "shift"), "y": tuple(-v for v in _pair(indentation, "indentation"))}}
    if half:
        if any(_pair(shift, "shift")):
            raise InputError("a half model cannot take a tangential shift (it breaks the symmetry)")
        out.update({"sym1": {"x": 0.0}, "sym2": {"x": 0.0}})
    return out


def _pressed_on_block(geo, params, *, indentation, E=2.1e11, nu=0.3, plane="strain", friction=0.0, shift=0.0,
                      clamp=("bottom2",), dirichlet=None, tractions1=None, tractions2=None, body_force1=None,
                      body_force2=None, rho=None, comm=None, pairing="segment", slave="contact2",
                      search_distance=None, match_tol=1e-8):
    """Build the gmsh model of ``geo`` (a :mod:`cfcontact.meshes` script) with ``params`` (checked)
    and assemble it as a body pressed on a block; the keywords are those of
    :func:`cylinder_on_block` and :func:`rounded_punch` after their geometry."""
    from mpi4py import MPI

    from cfcontact import compat  # imports dolfinx
    from cfcontact.assembly import assemble_contact_system

    comm = MPI.COMM_WORLD if comm is None else comm
    name = geo.__name__.rpartition(".")[2]
    kwargs = dict(
        E=E, nu=nu, plane=plane, clamp=clamp, dirichlet=_punch_loading(dirichlet, indentation, shift, params["half"]),
        tractions1=tractions1, tractions2=tractions2, body_force1=body_force1, body_force2=body_force2,
        friction=friction, rho=rho, match_tol=match_tol, pairing=pairing, slave=slave,
        search_distance=search_distance, comm=comm,
        info={"model": name, "model_parameters": dict(params)},
    )
    if comm.rank == 0:
        with compat.gmsh_model(f"cfcontact-{name}") as model:
            geo.build(**params)
            return assemble_contact_system(model, **kwargs)
    return assemble_contact_system(None, **kwargs)


def cylinder_on_block(*, radius=1.0, width=4.0, depth=2.0, zone=0.3, size=0.02, size_far=0.25, growth=0.2, gap0=0.0,
                      cell="triangle", half=False, indentation=(0.0, 0.005), **loading):
    """A (half-)cylinder pressed on a block (Hertz contact, plane strain by default), with the
    initial gap of the curved surface: :mod:`cfcontact.meshes.cylinder_on_block`.

    Body 1 is the lower half of a cylinder of radius ``radius`` (lowest point ``gap0`` above the
    block), body 2 the block ``[-width/2, width/2] x [-depth, 0]``.  The bodies are meshed
    independently (element size ``size`` along the contact boundaries, growing by ``growth`` per
    unit distance up to ``size_far``; ``cell`` triangles or quadrilaterals) and paired node to
    segment with the block's top as the slave (vertical normals, gap ``gap0 + R - sqrt(R^2 -
    x^2)``).  The mesh is mirror-symmetric about x = 0; ``half=True`` models the right half with
    the symmetry conditions u_x = 0 on ``sym1`` and ``sym2``.

    Loading and contact keywords (``loading``, shared with :func:`rounded_punch`): ``E=2.1e11,
    nu=0.3, plane="strain", friction=0.0``; the cylinder's flat top ``top1`` is moved by
    ``(shift, -indentation)``, each a number or a pair (value at alpha = 0, value at alpha = 1):
    the indentation depth is the path parameter (default from 0 to 0.005), ``shift=0.0``;
    ``clamp=("bottom2",)``; ``dirichlet`` replaces the conditions on the top (see
    :func:`cfcontact.assembly.assemble_contact_system`); ``tractions1, tractions2, body_force1,
    body_force2`` may be added; ``rho, comm``; ``pairing="segment", slave="contact2",
    search_distance=None, match_tol=1e-8``.  The contact force P is the sum of lam_n
    (``ContactGeometry.tributary`` turns lam_n into a pressure).  Tags: ``contact1, top1, right1,
    left1, sym1, contact2, top2, bottom2, right2, left2, sym2``.
    """
    geo = _script("cylinder_on_block")

    params = geo.check_parameters(radius=radius, width=width, depth=depth, zone=zone, size=size, size_far=size_far,
                                  growth=growth, gap0=gap0, cell=cell, half=half)
    return _pressed_on_block(geo, params, indentation=indentation, **loading)


def rounded_punch(*, half_width=0.5, edge_radius=0.1, height=0.5, width=4.0, depth=2.0, zone=None, size=0.01,
                  size_far=0.25, growth=0.2, gap0=0.0, cell="triangle", half=False, indentation=(0.0, 0.002),
                  **loading):
    """A flat punch with rounded edges pressed on a block: :mod:`cfcontact.meshes.rounded_punch`.

    Body 1 is the punch ``[-half_width, half_width] x [gap0, gap0 + height]`` with its bottom
    corners rounded (radius ``edge_radius``), body 2 the block ``[-width/2, width/2] x [-depth,
    0]``; meshed independently (``size`` along the contact boundaries) and paired node to segment
    with the block's top (``|x| <= zone``, default ``half_width - edge_radius / 4``) as the slave.
    The gap is ``gap0`` under the flat part and grows along the rounded edges.  Mirror-symmetric
    mesh; ``half=True`` models the right half (u_x = 0 on ``sym1``, ``sym2``).  Loading and
    contact keywords as :func:`cylinder_on_block` (the punch's top is moved by ``(shift,
    -indentation)``, default indentation from 0 to 0.002).
    """
    geo = _script("rounded_punch")

    params = geo.check_parameters(half_width=half_width, edge_radius=edge_radius, height=height, width=width,
                                  depth=depth, zone=zone, size=size, size_far=size_far, growth=growth, gap0=gap0,
                                  cell=cell, half=half)
    return _pressed_on_block(geo, params, indentation=indentation, **loading)
