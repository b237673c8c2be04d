"""What the gmsh scripts of :mod:`cfcontact.meshes` share: the tag convention and the parameter checks."""

from __future__ import annotations

import contextlib
import math
import operator
import os

import numpy as np

from cfcontact.errors import GeometryError, InputError  # noqa: F401  (GeometryError: for the scripts)

#: physical group numbers of every model (DESIGN.md; docs/geometry.md "Tag convention"); ``sym1`` /
#: ``sym2`` are the symmetry edges (x = 0) of half models, ``top2`` the top of a block outside
#: its contact boundary
TAGS = {
    "body1": (2, 1),
    "body2": (2, 2),
    "contact1": (1, 10),
    "top1": (1, 12),
    "right1": (1, 13),
    "left1": (1, 14),
    "sym1": (1, 15),
    "contact2": (1, 20),
    "top2": (1, 21),
    "bottom2": (1, 22),
    "right2": (1, 23),
    "left2": (1, 24),
    "sym2": (1, 25),
}

#: The groups every model names and numbers alike: (dim, number) -> name.
CONVENTION = {TAGS[name]: name for name in ("body1", "body2", "contact1", "contact2")}


def _groups_text(groups, dim) -> str:
    items = sorted((num, name) for (d, num), name in groups.items() if d == dim)
    return ", ".join(f"{name}={num}" if name else str(num) for num, name in items) or "(none)"


def convention_mismatch(groups) -> str | None:
    """A text naming a physical group whose name is one of the tag convention's (body1, body2,
    contact1, contact2, in any letter case) on another number -- body1 and body2 swapped, say, whose
    contact normal would follow the numbers and whose per-body material the names -- else None.  A
    convention number with a name of its own ("interface" on 10) is fine.  ``groups``: {(dim,
    number): name}."""
    by_name = {name: key for key, name in CONVENTION.items()}
    for (dim, num), name in sorted(groups.items()):
        want = by_name.get((name or "").strip().lower())
        if want is not None and want != (dim, num):
            return (f"physical group {num} ({dim}-D) is named {name!r}, but the tag convention has "
                    f"{CONVENTION[want]}={want[1]} ({want[0]}-D): number the groups body1=1, body2=2, contact1=10, "
                    "contact2=20 (the numbers decide which body is which)")
    return None


def volume_problem(model, groups) -> str | None:
    """A text saying that the gmsh ``model`` is 3-D (3-D physical groups or elements), else None."""
    _, elements, _ = model.mesh.getElements(3)
    if not any(d == 3 for d, _ in groups) and not any(len(tags) for tags in elements):
        return None
    what = f"3-D physical groups: {_groups_text(groups, 3)}" if any(d == 3 for d, _ in groups) else "it has 3-D elements"
    return (f"the mesh is 3-D ({what}); cfcontact models plane problems: give a 2-D mesh in the plane z = 0 "
            "(gmsh: mesh.generate(2) of a 2-D geometry)")


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


#: The largest length a geometry takes (1000 km in metres): beyond, gmsh's tolerances and the
#: stiffness's scale break down (a length of 1e300 made gmsh ask on stdin and PETSc crash).
LENGTH_MAX = 1e6
#: The largest ratio of two lengths of one body (cells of aspect ratio 1e12 make K singular to rounding).
ASPECT_MAX = 1e6


def check_length(name, value):
    """A finite positive number up to LENGTH_MAX (booleans refused), else InputError naming ``name``."""
    try:
        if isinstance(value, bool):
            raise TypeError
        value = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be a positive number, got {value!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"{name} must be a positive number, got {value!r}")
    if value > LENGTH_MAX:
        raise InputError(f"{name} = {value!r} is beyond {LENGTH_MAX:g} (lengths are in the units of E's, e.g. "
                         "metres with Pa); rescale the model")
    return value


def check_aspect(**lengths):
    """InputError when two of the lengths of one body differ by more than ASPECT_MAX."""
    (a, va), (b, vb) = max(lengths.items(), key=lambda kv: kv[1]), min(lengths.items(), key=lambda kv: kv[1])
    if va > ASPECT_MAX * vb:
        raise InputError(f"{a} = {va:g} and {b} = {vb:g} differ by more than {ASPECT_MAX:g} times: the stiffness would "
                         "be singular to rounding; model the thin body otherwise (or rescale)")


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


def check_fraction(name, value, upper=1.0):
    """A number in (0, upper), else InputError naming ``name``."""
    value = check_length(name, value)
    if not value < upper:
        raise InputError(f"{name} must lie in (0, {upper:g}), got {value!r}")
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


class MirrorSketch:
    """Build a geometry symmetric about x = 0 from its right half (x >= 0), in the gmsh geo kernel.

    A script describes the right half once, as a function of a sketch ``sk`` and a side
    ``s = +1`` (``sk.point(s * x, y, body)``, ``sk.line``, ``sk.arc``, ``sk.surface``).  Called with
    s = +1 and, for the full model, again with s = -1, it gives the two halves; points and lines on
    x = 0 are shared (created once).  :meth:`make_symmetric` then makes the left half's mesh the
    mirror image of the right half's (gmsh periodic meshing with the reflection x -> -x), so the
    full mesh is exactly symmetric and its right half is exactly the half model's mesh (call
    :meth:`mirror_nodes` after meshing to remove gmsh's rounding).
    """

    def __init__(self, geo):
        self.geo = geo
        self._points = {}
        self._lines = {}
        self._centres = []
        self.created = {1: [], -1: []}  # per side: (dim, tag) of the curves and surfaces created, in order

    def point(self, x, y, body=1):
        """The point (x, y) of ``body`` (bodies never share points; a half's points on x = 0 are
        shared with the other half)."""
        key = (int(body), 0.0 if x == 0 else float(x), float(y))
        if key not in self._points:
            self._points[key] = self.geo.addPoint(key[1], key[2], 0.0)
        return self._points[key]

    def centre(self, x, y):
        """A construction point (the centre of arcs), removed by :meth:`remove_centres` after
        ``synchronize`` so that it leaves no orphan mesh node."""
        tag = self.geo.addPoint(float(x), float(y), 0.0)
        self._centres.append(tag)
        return tag

    def remove_centres(self, gmsh):
        if self._centres:
            gmsh.model.removeEntities([(0, t) for t in self._centres])

    def _side(self, *coords):
        xs = [c for c in coords if c != 0]
        return 1 if not xs or xs[0] > 0 else -1

    def _coords(self, p):
        for key, tag in self._points.items():
            if tag == p:
                return key[1:]
        raise KeyError(f"point {p} was not made by MirrorSketch.point")

    def line(self, p, q):
        """A straight line p -> q (shared when it lies on x = 0)."""
        (xp, _), (xq, _) = self._coords(p), self._coords(q)
        if xp == 0 and xq == 0:
            key = tuple(sorted((p, q)))
            if key not in self._lines:
                self._lines[key] = (self.geo.addLine(p, q), p)
            tag, start = self._lines[key]
            return tag if start == p else -tag
        tag = self.geo.addLine(p, q)
        self.created[self._side(xp, xq)].append((1, tag))
        return tag

    def arc(self, p, centre, q):
        """A circular arc p -> q about ``centre`` (less than 180 degrees)."""
        (xp, _), (xq, _) = self._coords(p), self._coords(q)
        tag = self.geo.addCircleArc(p, centre, q)
        self.created[self._side(xp, xq)].append((1, tag))
        return tag

    def surface(self, curves, side):
        """A plane surface bounded by the closed loop of (signed) curves."""
        tag = self.geo.addPlaneSurface([self.geo.addCurveLoop(list(curves))])
        self.created[side].append((2, tag))
        return tag

    def make_symmetric(self, gmsh):
        """After ``synchronize``: mesh the left half as the mirror image of the right half."""
        right, left = self.created[1], self.created[-1]
        if not left:
            return
        if [d for d, _ in right] != [d for d, _ in left]:
            raise RuntimeError("the two halves were not built alike")
        reflect = [-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
        for (dim, r), (_, l) in zip(right, left):
            gmsh.model.mesh.setPeriodic(dim, [l], [r], reflect)

    def mirror_nodes(self, gmsh):
        """After meshing: place every node of the left half exactly at the mirror image of its
        right-half node (gmsh's periodic copy of curved entities is only accurate to ~1e-8)."""
        mesh = gmsh.model.mesh
        for dim, l in self.created[-1]:
            _, slaves, masters, _ = mesh.getPeriodicNodes(dim, l)
            for s_tag, m_tag in zip(slaves, masters):
                xyz = mesh.getNode(m_tag)[0]
                mesh.setNode(s_tag, [-xyz[0], xyz[1], xyz[2]], [])


def refine_near(gmsh, curves, size, size_far, dist_min, growth):
    """Mesh size ``size`` within ``dist_min`` of the curves, growing linearly with the distance
    (by ``growth`` per unit length) up to ``size_far`` (a gmsh Distance + Threshold background
    field; mesh inside :func:`field_sizes_only` so that point sizes do not interfere).  A constant
    growth rate keeps the elements well shaped and costs only a logarithmic number of them."""
    field = gmsh.model.mesh.field
    dist = field.add("Distance")
    field.setNumbers(dist, "CurvesList", list(curves))
    for name in ("Sampling", "NumPointsPerCurve"):  # the option's name since gmsh 4.11 / before
        try:
            field.setNumber(dist, name, 400)
            break
        except Exception:  # gmsh raises a plain Exception for an unknown option
            continue
    thr = field.add("Threshold")
    field.setNumber(thr, "InField", dist)
    field.setNumber(thr, "SizeMin", size)
    field.setNumber(thr, "SizeMax", size_far)
    field.setNumber(thr, "DistMin", dist_min)
    field.setNumber(thr, "DistMax", dist_min + max(size_far - size, 0.0) / growth)
    field.setAsBackgroundMesh(thr)


@contextlib.contextmanager
def field_sizes_only(gmsh):
    """Mesh sizes from the background field alone inside the block (gmsh's global options restored)."""
    names = ("Mesh.MeshSizeExtendFromBoundary", "Mesh.MeshSizeFromPoints", "Mesh.MeshSizeFromCurvature")
    old = [gmsh.option.getNumber(n) for n in names]
    try:
        for n in names:
            gmsh.option.setNumber(n, 0)
        yield
    finally:
        for n, v in zip(names, old):
            gmsh.option.setNumber(n, v)



def block_half(sk, s, zone, half_width, depth, parts):
    """One half (side ``s``) of body 2 as the block [-half_width, half_width] x [-depth, 0] under a
    body pressed on it: ``contact2`` (its top for |x| <= zone), ``top2`` (the rest of its top),
    ``right2`` / ``left2``, ``bottom2``; names -> entities added to ``parts``.  Returns
    (contact2 curve, symmetry-axis curve)."""
    pt = sk.point
    O, Z, E = pt(0.0, 0.0, 2), pt(s * zone, 0.0, 2), pt(s * half_width, 0.0, 2)
    F, G = pt(s * half_width, -depth, 2), pt(0.0, -depth, 2)
    c2, t2, r2, b2, ax2 = sk.line(O, Z), sk.line(Z, E), sk.line(E, F), sk.line(F, G), sk.line(G, O)
    S2 = sk.surface([c2, t2, r2, b2, ax2], s)
    for name, ent in (("body2", S2), ("contact2", c2), ("top2", t2), ("right2" if s > 0 else "left2", r2),
                      ("bottom2", b2)):
        parts.setdefault(name, []).append(abs(ent))
    return c2, ax2


def triangle_size(size, cell):
    """The size of the triangles that gmsh meshes for elements of ``size``: quadrilaterals come
    from splitting each triangle in three (:func:`subdivide_to_quads`), which halves its edges."""
    return 2.0 * size if cell == "quadrilateral" else size


def curve_nodes(length, size, cell):
    """setTransfiniteCurve's node count for a curve of ``length`` with elements of ``size``, at
    least two (quadrilaterals: half as many segments, each split in two by subdivide_to_quads)."""
    if cell == "quadrilateral":
        return max(1, math.ceil(length / (2.0 * size))) + 1
    return max(2, math.ceil(length / size)) + 1


def finish_symmetric(gmsh, sk, parts, cell, contact_curves, size, size_far, dist_min, growth, mesh=True):
    """The common end of a mirror-symmetric model: synchronize, symmetric meshing, refinement
    near ``contact_curves``, physical groups from ``parts`` ({name: [entities]}, names of TAGS),
    meshing.  Quadrilaterals: triangles of twice the size, each split into three
    (:func:`subdivide_to_quads`; gmsh's recombination of these unstructured surfaces leaves
    triangles, and its full-quad options fail on the mirrored halves).  Returns {name: (dim, number)}."""
    gmsh.model.geo.synchronize()
    sk.remove_centres(gmsh)
    sk.make_symmetric(gmsh)
    refine_near(gmsh, contact_curves, triangle_size(size, cell), triangle_size(size_far, cell), dist_min, growth)
    groups = {name: (TAGS[name][0], ents) for name, ents in parts.items()}
    created = add_physical_groups(gmsh, groups)
    if mesh:
        with field_sizes_only(gmsh):
            gmsh.model.mesh.generate(2)
        sk.mirror_nodes(gmsh)
        if cell == "quadrilateral":
            subdivide_to_quads(gmsh, mirrored=bool(sk.created[-1]))
        gmsh.model.mesh.renumberNodes()
    return created


def subdivide_to_quads(gmsh, mirrored=False):
    """Split every linear triangle of the model's mesh into three quadrilaterals (its vertices,
    edge midpoints and centroid) and every line element into two: an all-quadrilateral mesh with
    half the edge length, conforming across entities.  A midpoint on a curve is placed on the
    curve (gmsh's closest point).  ``mirrored``: the mesh is mirror-symmetric about x = 0 node
    for node (:meth:`MirrorSketch.mirror_nodes`); the new nodes of the left half are then placed
    exactly at the mirror images of the right half's."""
    mesh = gmsh.model.mesh
    ents = sorted(gmsh.model.getEntities())
    xyz, owned, elems = {}, {}, {}
    for dim, tag in ents:
        tags, coords, _ = mesh.getNodes(dim, tag, includeBoundary=False, returnParametricCoord=False)
        owned[dim, tag] = [int(t) for t in tags]
        xyz.update(zip(owned[dim, tag], np.asarray(coords, dtype=float).reshape(-1, 3)))
        types, _, nodes = mesh.getElements(dim, tag)
        if any(int(t) not in (15, 1, 2) for t in types):
            raise GeometryError(f"subdivide_to_quads: entity {(dim, tag)} has elements of gmsh types "
                                f"{sorted(map(int, types))}; only points, lines and linear triangles can be split")
        elems[dim, tag] = {int(t): np.asarray(n, dtype=np.int64).reshape(-1, {15: 1, 1: 2, 2: 3}[int(t)])
                           for t, n in zip(types, nodes)}
    new_tag = max(xyz, default=0) + 1
    mid, centre, added = {}, {}, {}  # (a, b) -> node; (a, b, c) sorted -> node; entity -> [node]

    def node(key, table, point, entity):
        nonlocal new_tag
        t = table.get(key)
        if t is None:
            t = table[key] = new_tag
            new_tag += 1
            xyz[t] = point
            added.setdefault(entity, []).append(t)
        return t

    for (dim, tag), by_type in elems.items():  # curves first (sorted): their midpoints lie on them
        for a, b in by_type.get(1, ()):
            key = _edge(a, b)
            if key not in mid:
                point = np.array(gmsh.model.getClosestPoint(dim, tag, list(0.5 * (xyz[a] + xyz[b])))[0], dtype=float)
                node(key, mid, point, (dim, tag))
    for (dim, tag), by_type in elems.items():
        for tri in by_type.get(2, ()):
            for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
                node(_edge(a, b), mid, 0.5 * (xyz[a] + xyz[b]), (dim, tag))
            node(tuple(sorted(tri)), centre, (xyz[tri[0]] + xyz[tri[1]] + xyz[tri[2]]) / 3.0, (dim, tag))
    if mirrored:
        _mirror_new_nodes(xyz, mid, centre)
    mesh.clear()
    elem_tag = 1
    for dim, tag in ents:
        tags = owned[dim, tag] + added.get((dim, tag), [])
        if tags:
            mesh.addNodes(dim, tag, tags, np.concatenate([xyz[t] for t in tags]).tolist())
    for dim, tag in ents:
        for etype, conn in elems[dim, tag].items():
            if etype == 15:
                out, otype = conn, 15
            elif etype == 1:
                m = np.array([mid[_edge(a, b)] for a, b in conn], dtype=np.int64)
                out, otype = np.column_stack([conn[:, 0], m, m, conn[:, 1]]).reshape(-1, 2), 1
            else:
                quads = []
                for a, b, c in conn:
                    mab, mbc, mca = (mid[_edge(p, q)] for p, q in ((a, b), (b, c), (c, a)))
                    g = centre[tuple(sorted((a, b, c)))]
                    quads += [a, mab, g, mca, b, mbc, g, mab, c, mca, g, mbc]
                out, otype = np.array(quads, dtype=np.int64).reshape(-1, 4), 3
            n = out.shape[0]
            mesh.addElementsByType(tag, otype, list(range(elem_tag, elem_tag + n)), out.ravel().tolist())
            elem_tag += n


def _edge(a, b):
    """The key of the edge between nodes a and b (either order)."""
    return (a, b) if a < b else (b, a)


def _mirror_new_nodes(xyz, mid, centre):
    """Place each new node left of x = 0 at the exact mirror image of its right-half counterpart
    (the node of the mirrored edge or triangle; the old nodes are exact mirrors already)."""
    at = {(float(p[0]), float(p[1])): t for t, p in xyz.items()}

    def image(t):
        p = xyz[t]
        return t if p[0] == 0.0 else at.get((-float(p[0]), float(p[1])))

    for table in (mid, centre):
        for key, t in list(table.items()):
            p = xyz[t]
            if not p[0] < 0.0:
                continue
            imgs = [image(v) for v in key]
            other = table.get(tuple(sorted(imgs))) if None not in imgs else None
            if other is None:
                raise GeometryError(f"subdivide_to_quads: the mesh is not mirror-symmetric at node {t} ({p[0]}, {p[1]})")
            q = xyz[other]
            xyz[t] = np.array([-q[0], q[1], q[2]])


def script_main(argv, name, description, defaults, check_parameters, build, cells=CELLS):
    """The command line of a geometry script: ``python3 meshes/<name>.py OUT.msh --key value ...``
    (one option per entry of ``defaults``; booleans are flags), writes a version 4.1 .msh file."""
    import argparse

    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("output", help="output file (.msh)")
    for key, value in defaults.items():
        opt = "--" + key.replace("_", "-")
        if isinstance(value, bool):
            ap.add_argument(opt, action="store_true", dest=key)
        elif key == "cell":
            ap.add_argument(opt, choices=cells, default=value, dest=key)
        else:
            ap.add_argument(opt, type=type(value) if value is not None else float, default=value, dest=key)
    args = ap.parse_args(argv)
    try:
        params = check_parameters(**{k: getattr(args, k) for k in defaults})
    except ValueError as exc:
        ap.error(str(exc))
    write_msh(args.output, name, build, **params)
    return 0


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
