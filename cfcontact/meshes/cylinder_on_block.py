"""A (half-)cylinder pressed on a block: a Hertz contact with an initial gap (gmsh only, no dolfinx).

Plane strain model of a cylinder of radius ``R`` on a block.  Body 1 (``body1``) is the lower
half of the cylinder -- the half-disc below its diameter ``y = R + gap0``, lowest point
``(0, gap0)`` -- loaded through its flat top (``top1``); body 2 (``body2``) is the block
``[-width/2, width/2] x [-depth, 0]``.  The bodies are meshed independently, so their contact
boundaries do not match: pair them node to segment (``pairing="segment"``); the initial gap
along the block's normal is ``gap0 + R - sqrt(R^2 - x^2) = gap0 + x^2 / (2 R) + O(x^4)``::

                 (-R, R+gap0) +=============== top1 ===============+ (R, R+gap0)
                               \\                                  /
                          left1  \\            body 1            /  right1
                                   `-._      contact1      _.-'
                                        `--.___________.--'     (0, gap0)
        (-w/2, 0) +---- top2 ----+======== contact2 =========+---- top2 ----+ (w/2, 0)
                  |                          body 2                        |
            left2 |                                                        | right2
                  +----------------------- bottom2 ------------------------+ (w/2, -depth)

``contact2`` is the block's top for ``|x| <= zone``; ``contact1`` the cylinder's arc for
``|x| <= 1.25 zone`` (so that every block node of ``contact2`` faces it).  Both are meshed
uniformly with elements of size ``size``; away from them the elements grow by ``growth`` per unit
distance up to ``size_far`` (a distance field).  Triangles, or quadrilaterals (each triangle of
a mesh of twice the size split into three, :func:`cfcontact.meshes.common.subdivide_to_quads`).

The mesh is mirror-symmetric about ``x = 0`` (the left half is meshed as the mirror image of
the right half), so nodes at ``x`` and ``-x`` change state together on symmetric loads.  With
``half=True`` only the right half ``x >= 0`` is built -- exactly the right half of the full
model's mesh -- with the symmetry edges ``sym1`` (body 1) and ``sym2`` (body 2) on ``x = 0``.

Physical groups (DESIGN.md)::

    body1 = 1      body2 = 2                                              (2-D)
    contact1 = 10  top1 = 12  right1 = 13  left1 = 14  sym1 = 15          (1-D, body 1)
    contact2 = 20  top2 = 21  bottom2 = 22  right2 = 23  left2 = 24  sym2 = 25   (1-D, body 2)

Usage as a library (gmsh initialised by the caller; builds into the current model)::

    from cfcontact.meshes import cylinder_on_block
    cylinder_on_block.build(radius=1.0, zone=0.3, size=0.02)

Usage as a script (writes a .msh file)::

    python3 -m cfcontact.meshes.cylinder_on_block cylinder.msh --radius 1 --zone 0.3 --size 0.02
"""

from __future__ import annotations

import math

import gmsh

from cfcontact.meshes import common

TAGS, CELLS = common.TAGS, common.CELLS

#: default parameters of :func:`build`
DEFAULTS = dict(radius=1.0, width=4.0, depth=2.0, zone=0.3, size=0.02, size_far=0.25, growth=0.2, gap0=0.0,
                cell="triangle", half=False)

#: contact1 spans |x| <= ARC_FACTOR * zone on the cylinder
ARC_FACTOR = 1.25


def check_parameters(radius=1.0, width=4.0, depth=2.0, zone=0.3, size=0.02, size_far=0.25, growth=0.2, gap0=0.0,
                     cell="triangle", half=False):
    """Validated, normalised parameters of :func:`build` as a dict (InputError / GeometryError)."""
    radius = common.check_length("radius", radius)
    width = common.check_length("width", width)
    depth = common.check_length("depth", depth)
    zone = common.check_length("zone", zone)
    size = common.check_length("size", size)
    size_far = common.check_length("size_far", size_far)
    growth = common.check_fraction("growth", growth)
    if gap0 != 0:
        gap0 = common.check_length("gap0", gap0)
    gap0 = float(gap0)
    cell = common.check_cell(cell)
    if ARC_FACTOR * zone >= 0.95 * radius:
        raise common.GeometryError(f"zone must be below {0.95 / ARC_FACTOR:.3g} x radius (the contact arc spans "
                                   f"|x| <= {ARC_FACTOR:g} zone on the cylinder), got zone={zone!r}, radius={radius!r}")
    if zone >= 0.5 * width:
        raise common.GeometryError(f"zone must be below width / 2 = {0.5 * width:g}, got {zone!r}")
    if size > zone / 2:
        raise common.GeometryError(f"size must be at most zone / 2 = {zone / 2:g} (a few elements along the contact "
                                   f"zone), got {size!r}")
    size_far = max(size_far, size)
    return dict(radius=radius, width=width, depth=depth, zone=zone, size=size, size_far=size_far, growth=growth,
                gap0=gap0, cell=cell, half=bool(half))


def build(radius=1.0, width=4.0, depth=2.0, zone=0.3, size=0.02, size_far=0.25, growth=0.2, gap0=0.0,
          cell="triangle", half=False, *, mesh=True):
    """Build the cylinder-on-block geometry and mesh into the *current* gmsh model.

    Parameters
    ----------
    radius : cylinder radius R (default 1)
    width, depth : the block [-width/2, width/2] x [-depth, 0] (default 4 x 2)
    zone : half-width of the block's contact boundary contact2 (default 0.3; the cylinder's
        contact1 spans |x| <= 1.25 zone)
    size : element size along the contact boundaries (default 0.02); it grows by ``growth`` per unit
        distance (default 0.2) up to ``size_far`` (default 0.25) away from them
    gap0 : initial distance between the cylinder's lowest point and the block (default 0)
    cell : ``"triangle"`` (default) or ``"quadrilateral"`` (subdivided triangles)
    half : build the right half x >= 0 only (symmetry edges sym1, sym2 on x = 0)
    mesh : generate the 2-D mesh (default True)

    Returns
    -------
    dict name -> (dim, number) of the physical groups created.
    """
    p = check_parameters(radius, width, depth, zone, size, size_far, growth, gap0, cell, half)
    R, w2, depth, zone, size, gap0 = p["radius"], p["width"] / 2, p["depth"], p["zone"], p["size"], p["gap0"]
    x1 = ARC_FACTOR * zone
    phi1 = math.asin(x1 / R)
    sk = common.MirrorSketch(gmsh.model.geo)
    parts = {}

    def half_model(s):
        pt = sk.point
        # body 1: the half-disc below y = R + gap0
        B0, T0 = pt(0.0, gap0, 1), pt(0.0, R + gap0, 1)
        A1, A2 = pt(s * x1, gap0 + R * (1 - math.cos(phi1)), 1), pt(s * R, R + gap0, 1)
        c1, r1, t1, ax1 = sk.arc(B0, T0, A1), sk.arc(A1, T0, A2), sk.line(A2, T0), sk.line(T0, B0)
        S1 = sk.surface([c1, r1, t1, ax1], s)
        for name, ent in (("body1", S1), ("contact1", c1), ("top1", t1), ("right1" if s > 0 else "left1", r1)):
            parts.setdefault(name, []).append(abs(ent))
        c2, ax2 = common.block_half(sk, s, zone, w2, depth, parts)
        if p["half"]:
            parts["sym1"], parts["sym2"] = [abs(ax1)], [abs(ax2)]
        return c1, c2

    c1, c2 = half_model(1)
    if not p["half"]:
        half_model(-1)
    gmsh.model.geo.mesh.setTransfiniteCurve(c1, common.curve_nodes(R * phi1, size, p["cell"]))
    gmsh.model.geo.mesh.setTransfiniteCurve(c2, common.curve_nodes(zone, size, p["cell"]))
    return common.finish_symmetric(gmsh, sk, parts, p["cell"], parts["contact1"] + parts["contact2"], size,
                                   p["size_far"], 0.5 * zone, p["growth"], mesh=mesh)


def _main(argv=None):
    return common.script_main(argv, "cylinder_on_block", "Write the cylinder-on-block (Hertz) contact model as a "
                              "gmsh .msh file.", DEFAULTS, check_parameters, build)


if __name__ == "__main__":
    raise SystemExit(_main())
