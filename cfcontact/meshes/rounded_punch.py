"""A flat punch with rounded edges pressed on a block (gmsh only, no dolfinx).

Body 1 (``body1``) is the punch ``[-w, w] x [gap0, gap0 + height]`` (``w = half_width``) whose
two bottom corners are rounded with radius ``r = edge_radius``: its bottom is flat for
``|x| <= w - r`` and turns up along quarter circles to its vertical sides.  Body 2 (``body2``) is
the block ``[-width/2, width/2] x [-depth, 0]``.  The bodies are meshed independently: pair them
node to segment (``pairing="segment"``); the initial gap along the block's normal is ``gap0``
under the flat part and ``gap0 + r - sqrt(r^2 - (|x| - w + r)^2)`` under the rounded edges::

                (-w, gap0+height) +============ top1 ============+ (w, gap0+height)
                                  |                               |
                            left1 |            body 1             | right1
                                  |                               |
                                   \\_________ contact1 _________/      (rounded edges, radius r)
        (-width/2, 0) +-- top2 --+=========== contact2 ===========+-- top2 --+ (width/2, 0)
                      |                        body 2                         |
                left2 |                                                       | right2
                      +---------------------- bottom2 ------------------------+

``contact1`` is the punch's flat bottom and both rounded edges; ``contact2`` the block's top for
``|x| <= zone`` (default ``w - r / 4``, so that the block's contact nodes all face the punch).
Both are meshed uniformly with elements of size ``size``, growing by ``growth`` per unit distance
up to ``size_far`` away from them; triangles or quadrilaterals (subdivided triangles).  The mesh is mirror-symmetric about ``x = 0``; ``half=True``
builds the right half only, with symmetry edges ``sym1``, ``sym2`` on ``x = 0``.

Physical groups (DESIGN.md)::

    body1 = 1      body2 = 2                                                    (2-D)
    contact1 = 10  top1 = 12  right1 = 13  left1 = 14  sym1 = 15                (1-D, body 1)
    contact2 = 20  top2 = 21  bottom2 = 22  right2 = 23  left2 = 24  sym2 = 25  (1-D, body 2)

Usage as a library (gmsh initialised by the caller; builds into the current model)::

    from cfcontact.meshes import rounded_punch
    rounded_punch.build(half_width=0.5, edge_radius=0.1, size=0.01)

Usage as a script (writes a .msh file)::

    python3 -m cfcontact.meshes.rounded_punch punch.msh --half-width 0.5 --edge-radius 0.1 --size 0.01
"""

from __future__ import annotations

import math

import gmsh

from cfcontact.meshes import common

TAGS, CELLS = common.TAGS, common.CELLS

#: default parameters of :func:`build` (zone 0.0: w - r / 4)
DEFAULTS = dict(half_width=0.5, edge_radius=0.1, height=0.5, width=4.0, depth=2.0, zone=0.0, size=0.01,
                size_far=0.25, growth=0.2, gap0=0.0, cell="triangle", half=False)


def check_parameters(half_width=0.5, edge_radius=0.1, height=0.5, width=4.0, depth=2.0, zone=None, size=0.01,
                     size_far=0.25, growth=0.2, gap0=0.0, cell="triangle", half=False):
    """Validated, normalised parameters of :func:`build` as a dict (InputError / GeometryError)."""
    w = common.check_length("half_width", half_width)
    r = common.check_length("edge_radius", edge_radius)
    if not r < w:
        raise common.GeometryError(f"edge_radius must be below half_width = {w:g}, got {edge_radius!r}")
    height = common.check_length("height", height)
    if not r < height:
        raise common.GeometryError(f"edge_radius must be below the punch's height = {height:g}, got {edge_radius!r}")
    width = common.check_length("width", width)
    depth = common.check_length("depth", depth)
    zone = w - r / 4 if zone in (None, 0, 0.0) else common.check_length("zone", zone)
    if not zone < w:
        raise common.GeometryError(f"zone must be below half_width = {w:g} (the block's contact nodes must face the "
                                   f"punch), got {zone!r}")
    if not w < width / 2:
        raise common.GeometryError(f"the punch (half_width {w:g}) must be narrower than the block (width/2 = "
                                   f"{width / 2:g})")
    size = common.check_length("size", size)
    if size > r / 2:
        raise common.GeometryError(f"size must be at most edge_radius / 2 = {r / 2:g} (a few elements along each "
                                   f"rounded edge), got {size!r}")
    size_far = max(common.check_length("size_far", size_far), size)
    growth = common.check_fraction("growth", growth)
    gap0 = float(gap0) if gap0 == 0 else common.check_length("gap0", gap0)
    return dict(half_width=w, edge_radius=r, height=height, width=width, depth=depth, zone=zone, size=size,
                size_far=size_far, growth=growth, gap0=gap0, cell=common.check_cell(cell), half=bool(half))


def build(half_width=0.5, edge_radius=0.1, height=0.5, width=4.0, depth=2.0, zone=None, size=0.01, size_far=0.25,
          growth=0.2, gap0=0.0, cell="triangle", half=False, *, mesh=True):
    """Build the rounded-punch geometry and mesh into the *current* gmsh model.

    Parameters
    ----------
    half_width, edge_radius, height : the punch [-w, w] x [gap0, gap0 + height], bottom corners
        rounded with radius edge_radius (defaults 0.5, 0.1, 0.5)
    width, depth : the block [-width/2, width/2] x [-depth, 0] (default 4 x 2)
    zone : half-width of the block's contact boundary (default w - r / 4)
    size, size_far : element size along the contact boundaries / far from them (0.01, 0.25)
    growth : growth of the element size per unit distance from the contact boundaries (0.2)
    gap0 : initial distance between the punch's flat bottom and the block (default 0)
    cell : ``"triangle"`` (default) or ``"quadrilateral"``
    half : the right half x >= 0 only (symmetry edges sym1, sym2)
    mesh : generate the 2-D mesh (default True)

    Returns
    -------
    dict name -> (dim, number) of the physical groups created.
    """
    p = check_parameters(half_width, edge_radius, height, width, depth, zone, size, size_far, growth, gap0, cell, half)
    w, r, H, g0, size = p["half_width"], p["edge_radius"], p["height"], p["gap0"], p["size"]
    sk = common.MirrorSketch(gmsh.model.geo)
    parts = {}

    def half_model(s):
        pt = sk.point
        B0, K, S = pt(0.0, g0, 1), pt(s * (w - r), g0, 1), pt(s * w, g0 + r, 1)
        U, T0 = pt(s * w, g0 + H, 1), pt(0.0, g0 + H, 1)
        flat, rnd = sk.line(B0, K), sk.arc(K, sk.centre(s * (w - r), g0 + r), S)
        side, top, ax1 = sk.line(S, U), sk.line(U, T0), sk.line(T0, B0)
        S1 = sk.surface([flat, rnd, side, top, ax1], s)
        for name, ent in (("body1", S1), ("contact1", flat), ("contact1", rnd), ("top1", top),
                          ("right1" if s > 0 else "left1", side)):
            parts.setdefault(name, []).append(abs(ent))
        c2, ax2 = common.block_half(sk, s, p["zone"], p["width"] / 2, p["depth"], parts)
        if p["half"]:
            parts["sym1"], parts["sym2"] = [abs(ax1)], [abs(ax2)]
        return flat, rnd, c2

    flat, rnd, c2 = half_model(1)
    if not p["half"]:
        half_model(-1)
    tc = gmsh.model.geo.mesh.setTransfiniteCurve
    tc(flat, common.curve_nodes(w - r, size, p["cell"]))
    tc(rnd, common.curve_nodes(0.5 * math.pi * r, size, p["cell"]))
    tc(c2, common.curve_nodes(p["zone"], size, p["cell"]))
    return common.finish_symmetric(gmsh, sk, parts, p["cell"], parts["contact1"] + parts["contact2"], size,
                                   p["size_far"], 2 * r, p["growth"], mesh=mesh)


def _main(argv=None):
    return common.script_main(argv, "rounded_punch", "Write the rounded-punch-on-block contact model as a gmsh "
                              ".msh file.", DEFAULTS, check_parameters, build)


if __name__ == "__main__":
    raise SystemExit(_main())
