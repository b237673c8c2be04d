"""Two stacked elastic blocks: the seed's default geometry (gmsh only, no dolfinx).

Body 1 (upper, ``body1``) occupies ``[0, length] x [0, height]``, body 2 (lower,
``body2``) occupies ``[0, length] x [-height2, 0]``; they touch along the
interface ``y = 0`` (``contact1`` on body 1, ``contact2`` on body 2).  Both blocks
are meshed with structured (transfinite) grids of ``nx x ny`` cells (body 2:
``nx2 x ny2``), quadrilaterals or triangles (each quadrilateral split in two).
The two bodies do *not* share nodes: the interface nodes are duplicated, one copy
per body, at the same coordinates when ``nx2 == nx`` (the contact pairs).

With ``angle`` (degrees) the whole assembly is rotated counter-clockwise about the
origin (the left end of the interface), so the interface is inclined and the
outer normal of body 1 on it is ``(sin(angle), -cos(angle))``.

Physical groups (numbers and names, see DESIGN.md)::

    body1 = 1      body2 = 2          (2-D)
    contact1 = 10  top1 = 12  right1 = 13  left1 = 14      (1-D, body 1)
    contact2 = 20  bottom2 = 22  right2 = 23  left2 = 24   (1-D, body 2)

Defaults: ``nx=30, ny=10, length=3.0, height=1.0`` per block.  Clamped along
``left1`` and ``left2`` this model has n = 2*2*(31*11 - 11) = 1320 free DOFs and
m = 30 contact pairs (the interface node clamped in both bodies is not a contact
node).

With ``foundation=True`` only body 1 is built (a block on a rigid foundation:
``contact1`` is the part of its boundary that touches the foundation).

Usage as a library (gmsh initialised by the caller; builds into the current model)::

    from cfcontact.meshes import two_blocks
    two_blocks.build(nx=30, ny=10)

Usage as a script (writes a .msh file)::

    python3 -m cfcontact.meshes.two_blocks two_blocks.msh --nx 30 --ny 10 --cell triangle
"""

from __future__ import annotations

import math

import gmsh

from cfcontact.meshes import common

TAGS, CELLS = common.TAGS, common.CELLS

#: default parameters of :func:`build`
DEFAULTS = dict(nx=30, ny=10, length=3.0, height=1.0, cell="quadrilateral", angle=0.0)

def check_parameters(nx=30, ny=10, length=3.0, height=1.0, cell="quadrilateral", angle=0.0, *,
                     nx2=None, ny2=None, height2=None):
    """Validated, normalised parameters of :func:`build` as a dict (raises InputError / ValueError)."""
    nx, ny = common.check_count("nx", nx), common.check_count("ny", ny)
    nx2 = nx if nx2 is None else common.check_count("nx2", nx2)
    ny2 = ny if ny2 is None else common.check_count("ny2", ny2)
    length = common.check_length("length", length)
    height = common.check_length("height", height)
    height2 = height if height2 is None else common.check_length("height2", height2)
    common.check_aspect(length=length, height=height)
    common.check_aspect(length=length, height2=height2)
    cell = common.check_cell(cell)
    angle = common.check_angle("angle", angle)
    return dict(nx=nx, ny=ny, length=length, height=height, cell=cell, angle=angle,
                nx2=nx2, ny2=ny2, height2=height2)


def build(nx=30, ny=10, length=3.0, height=1.0, cell="quadrilateral", angle=0.0, *,
          nx2=None, ny2=None, height2=None, foundation=False, mesh=True):
    """Build the two-block geometry and mesh into the *current* gmsh model.

    Parameters
    ----------
    nx, ny : cells along the interface / across the thickness of body 1 (default 30 x 10)
    length : width of both blocks (default 3.0)
    height : thickness of body 1 (default 1.0); ``height2`` of body 2 (default ``height``)
    cell : ``"quadrilateral"`` (default) or ``"triangle"`` (each quadrilateral split in two)
    angle : rotation of the whole assembly about the origin, degrees counter-clockwise
    nx2, ny2 : cells of body 2 (default ``nx``, ``ny``); ``nx2 != nx`` gives a
        non-matching interface (useful only to test error handling)
    foundation : build body 1 only (block on a rigid foundation)
    mesh : generate the 2-D mesh (default True)

    Returns
    -------
    dict name -> (dim, number) of the physical groups created.
    """
    p = check_parameters(nx, ny, length, height, cell, angle, nx2=nx2, ny2=ny2, height2=height2)
    nx, ny, length, height, cell, angle = p["nx"], p["ny"], p["length"], p["height"], p["cell"], p["angle"]
    nx2, ny2, height2 = p["nx2"], p["ny2"], p["height2"]

    c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    geo = gmsh.model.geo

    def point(x, y):
        return geo.addPoint(c * x - s * y, s * x + c * y, 0.0)

    def block(x0, y0, x1, y1, mx, my):
        """Rectangle [x0,x1]x[y0,y1]; returns (surface, bottom, right, top, left) curve tags.

        Lines are oriented left->right (bottom, top) and bottom->top (right, left),
        so that parallel edges share one parametrisation; the loop fixes the sense.
        """
        p1, p2, p3, p4 = point(x0, y0), point(x1, y0), point(x1, y1), point(x0, y1)
        lb = geo.addLine(p1, p2)
        lr = geo.addLine(p2, p3)
        lt = geo.addLine(p4, p3)
        ll = geo.addLine(p1, p4)
        surf = common.structured_surface(geo, (p1, p2, p3, p4), lb, lr, lt, ll, mx, my, cell)
        return surf, lb, lr, lt, ll

    s1, c1, r1, t1, l1 = block(0.0, 0.0, length, height, nx, ny)
    groups = {
        "body1": (2, [s1]),
        "contact1": (1, [c1]),
        "top1": (1, [t1]),
        "right1": (1, [r1]),
        "left1": (1, [l1]),
    }
    if not foundation:
        s2, b2, r2, c2, l2 = block(0.0, -height2, length, 0.0, nx2, ny2)
        groups.update({
            "body2": (2, [s2]),
            "contact2": (1, [c2]),
            "bottom2": (1, [b2]),
            "right2": (1, [r2]),
            "left2": (1, [l2]),
        })
    geo.synchronize()
    created = common.add_physical_groups(gmsh, groups)
    if mesh:
        gmsh.model.mesh.generate(2)
    return created


def _main(argv=None):
    import argparse

    ap = argparse.ArgumentParser(description="Write the two-block contact model as a gmsh .msh file.")
    ap.add_argument("output", help="output file (.msh)")
    ap.add_argument("--nx", type=int, default=DEFAULTS["nx"])
    ap.add_argument("--ny", type=int, default=DEFAULTS["ny"])
    ap.add_argument("--length", type=float, default=DEFAULTS["length"])
    ap.add_argument("--height", type=float, default=DEFAULTS["height"])
    ap.add_argument("--cell", choices=CELLS, default=DEFAULTS["cell"])
    ap.add_argument("--angle", type=float, default=DEFAULTS["angle"], help="rotation in degrees")
    ap.add_argument("--nx2", type=int, default=None)
    ap.add_argument("--ny2", type=int, default=None)
    ap.add_argument("--height2", type=float, default=None)
    ap.add_argument("--foundation", action="store_true", help="body 1 only (rigid foundation)")
    args = ap.parse_args(argv)
    body2 = [f"--{k} {getattr(args, k)}" for k in ("nx2", "ny2", "height2") if getattr(args, k) is not None]
    if args.foundation and body2:
        ap.error(f"{', '.join(body2)}: body 2's mesh, but --foundation builds body 1 alone")
    try:
        params = check_parameters(args.nx, args.ny, args.length, args.height, args.cell, args.angle,
                                  nx2=args.nx2, ny2=args.ny2, height2=args.height2)
    except ValueError as exc:
        ap.error(str(exc))
    common.write_msh(args.output, "two_blocks", build, foundation=args.foundation, **params)
    return 0


if __name__ == "__main__":
    raise SystemExit(_main())
