"""A body with a convex circular-arc bottom sitting in a matching concave seat (gmsh only, no dolfinx).

A curved-interface variant of the two-block model, Hertz-like in shape but **conforming**: the
two bodies touch along the whole arc in the undeformed state (the assembly pairs contact nodes
by coordinates, so an initial gap cannot be modelled).

Geometry (``R = radius``, ``theta = half_angle`` in degrees, ``a = R sin(theta)``,
``yc = R (1 - cos(theta))``)::

         (-a, yc + height) +----------- top1 -----------+ (a, yc + height)
                           |                            |
                     left1 |           body 1           | right1
                           |                            |
                 (-a, yc)  +.__      contact1       __.+  (a, yc)
                           |   ``--..______..--''    |
                     left2 |           body 2           | right2
                           |        (seat, concave)     |
                (-a, -h2)  +---------- bottom2 ---------+ (a, -h2)

The interface is the arc of the circle of radius ``R`` centred at ``(0, R)`` between the angles
``-theta`` and ``theta`` from its lowest point ``(0, 0)``: the points
``(R sin(phi), R (1 - cos(phi)))``, ``|phi| <= theta``.  The outer normal of body 1 on it is the
radial direction ``(sin(phi), -cos(phi))``, so the contact normals turn by ``2 theta`` along the
interface.  Body 1 (``body1``) lies above the arc (thickness ``height`` at its sides, ``height +
yc`` in the middle); body 2 (``body2``) lies below it (thickness ``height2`` in the middle,
``height2 + yc`` at its sides).

Both bodies are meshed with structured (transfinite) grids: ``nx`` cells along the arc (uniform
in angle) and along the straight top / bottom side, ``ny`` (body 1) and ``ny2`` (body 2) cells
across; quadrilaterals, or triangles (each quadrilateral split in two).  The arc is meshed twice
with the same parametrisation, so the ``nx + 1`` interface nodes of the two bodies coincide one
to one (the contact pairs); they are not shared.

Physical groups (the two-block convention)::

    body1 = 1      body2 = 2          (2-D)
    contact1 = 10  top1 = 12  right1 = 13  left1 = 14      (1-D, body 1)
    contact2 = 20  bottom2 = 22  right2 = 23  left2 = 24   (1-D, body 2)

Defaults: ``radius=1.0, half_angle=30.0, height=0.5, height2=height, nx=16, ny=4, ny2=ny``.

Usage as a library (gmsh initialised by the caller; builds into the current model)::

    from cfcontact.meshes import arc_on_block
    arc_on_block.build(radius=1.0, half_angle=30.0, nx=16, ny=4)

Usage as a script (writes a .msh file)::

    python3 -m cfcontact.meshes.arc_on_block arc.msh --radius 1 --half-angle 30 --nx 16 --ny 4
"""

from __future__ import annotations

import math

import gmsh

from cfcontact.meshes import common

TAGS, CELLS = common.TAGS, common.CELLS

#: default parameters of :func:`build`
DEFAULTS = dict(radius=1.0, half_angle=30.0, height=0.5, height2=None, nx=16, ny=4, ny2=None,
                cell="quadrilateral")

#: valid range of the half-angle of the arc, degrees: (0, MAX_HALF_ANGLE]
MAX_HALF_ANGLE = 80.0


def check_parameters(radius=1.0, half_angle=30.0, height=0.5, height2=None, nx=16, ny=4, ny2=None,
                     cell="quadrilateral"):
    """Validated, normalised parameters of :func:`build` as a dict.

    Raises InputError (a ValueError) for a wrong type or a non-positive size, GeometryError
    (a subclass) for a half-angle outside ``(0, 80]`` degrees.
    """
    radius = common.check_length("radius", radius)
    half_angle = common.check_angle("half_angle", half_angle)
    if not 0.0 < half_angle <= MAX_HALF_ANGLE:
        raise common.GeometryError(f"half_angle must lie in (0, {MAX_HALF_ANGLE:g}] degrees, got {half_angle!r}")
    height = common.check_length("height", height)
    height2 = height if height2 is None else common.check_length("height2", height2)
    nx = common.check_count("nx", nx, 2)
    ny = common.check_count("ny", ny, 1)
    ny2 = ny if ny2 is None else common.check_count("ny2", ny2, 1)
    cell = common.check_cell(cell)
    return dict(radius=radius, half_angle=half_angle, height=height, height2=height2, nx=nx, ny=ny, ny2=ny2,
                cell=cell)


def build(radius=1.0, half_angle=30.0, height=0.5, height2=None, nx=16, ny=4, ny2=None, cell="quadrilateral",
          *, mesh=True):
    """Build the arc-on-block geometry and mesh into the *current* gmsh model.

    Parameters
    ----------
    radius : radius R of the interface arc (default 1.0)
    half_angle : half the opening angle of the arc, degrees in (0, 80] (default 30)
    height : thickness of body 1 at its sides, above the ends of the arc (default 0.5)
    height2 : thickness of body 2 below the lowest point of the seat (default ``height``)
    nx : cells along the arc (>= 2, default 16)
    ny, ny2 : cells across body 1 / body 2 (default 4, ``ny``)
    cell : ``"quadrilateral"`` (default) or ``"triangle"``
    mesh : generate the 2-D mesh (default True)

    Returns
    -------
    dict name -> (dim, number) of the physical groups created.
    """
    p = check_parameters(radius, half_angle, height, height2, nx, ny, ny2, cell)
    R, th = p["radius"], math.radians(p["half_angle"])
    height, height2, nx, ny, ny2, cell = p["height"], p["height2"], p["nx"], p["ny"], p["ny2"], p["cell"]
    a, yc = R * math.sin(th), R * (1.0 - math.cos(th))
    geo = gmsh.model.geo
    centre = geo.addPoint(0.0, R, 0.0)

    def patch(x0, y0, y1, arc_on_top, my):
        """Four-sided patch [-x0, x0] x [y0, y1]; its top (body 2) or bottom (body 1) side is the arc.

        Returns (surface, bottom, right, top, left) curve tags.  Bottom and top are oriented
        left -> right, right and left bottom -> top (parallel sides share one parametrisation).
        """
        p1, p2, p3, p4 = (geo.addPoint(-x0, y0, 0.0), geo.addPoint(x0, y0, 0.0),
                          geo.addPoint(x0, y1, 0.0), geo.addPoint(-x0, y1, 0.0))
        if arc_on_top:
            lb = geo.addLine(p1, p2)
            lt = geo.addCircleArc(p4, centre, p3)
        else:
            lb = geo.addCircleArc(p1, centre, p2)
            lt = geo.addLine(p4, p3)
        lr = geo.addLine(p2, p3)
        ll = geo.addLine(p1, p4)
        surf = common.structured_surface(geo, (p1, p2, p3, p4), lb, lr, lt, ll, nx, my, cell)
        return surf, lb, lr, lt, ll

    s1, c1, r1, t1, l1 = patch(a, yc, yc + height, False, ny)
    s2, b2, r2, c2, l2 = patch(a, -height2, yc, True, ny2)
    geo.synchronize()
    # the arc centre is a construction point only: no mesh node (and no orphan node) there
    gmsh.model.removeEntities([(0, centre)])
    groups = {
        "body1": (2, [s1]), "contact1": (1, [c1]), "top1": (1, [t1]), "right1": (1, [r1]), "left1": (1, [l1]),
        "body2": (2, [s2]), "contact2": (1, [c2]), "bottom2": (1, [b2]), "right2": (1, [r2]), "left2": (1, [l2]),
    }
    created = common.add_physical_groups(gmsh, groups)
    if mesh:
        gmsh.model.mesh.generate(2)
    return created


def _main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(description="Write the arc-on-block contact model (a body with a convex arc "
                                             "bottom in a matching concave seat) as a gmsh .msh file.")
    ap.add_argument("output", help="output file (.msh)")
    ap.add_argument("--radius", type=float, default=DEFAULTS["radius"])
    ap.add_argument("--half-angle", type=float, default=DEFAULTS["half_angle"],
                    help=f"half opening angle of the arc, degrees in (0, {MAX_HALF_ANGLE:g}]")
    ap.add_argument("--height", type=float, default=DEFAULTS["height"], help="thickness of body 1 at its sides")
    ap.add_argument("--height2", type=float, default=None, help="thickness of body 2 below the seat")
    ap.add_argument("--nx", type=int, default=DEFAULTS["nx"], help="cells along the arc")
    ap.add_argument("--ny", type=int, default=DEFAULTS["ny"])
    ap.add_argument("--ny2", type=int, default=None)
    ap.add_argument("--cell", choices=CELLS, default=DEFAULTS["cell"])
    args = ap.parse_args(argv)
    try:
        params = check_parameters(args.radius, args.half_angle, args.height, args.height2, args.nx, args.ny,
                                  args.ny2, args.cell)
    except ValueError as exc:
        ap.error(str(exc))
    common.write_msh(args.output, "arc_on_block", build, **params)
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
