"""Contact pairing on coordinates: matching nodes, node-to-segment, rigid obstacles.

NumPy/SciPy only.  The assembly layer (:mod:`cfcontact.assembly`) extracts the node coordinates
and the tagged boundary facets with dolfinx and hands them here; the result says, for every
contact node (one row of N and T), which nodes it couples, with which weights, along which
normal, and with which initial gap.  Everything is linearised at the reference configuration
(small deformations), so N, T and the gap g are fixed: the conditions stay linear in u.

Conventions (DESIGN.md): n is the outer normal of body 1, t = (-n_y, n_x), and
(N u)_i = (u^1 - u^2) . n_i <= g_i is non-penetration.

* :func:`match_nodes`: a conforming interface, node matched to node (g = 0).
* :func:`node_to_segment`: each node of the slave boundary is projected along its outer normal
  (the average of the outer normals of its facets) onto the master boundary; the nearest crossing
  (smallest |t|, t < 0 an initial interference) of the line x + t n with a master facet that
  faces it (outer normals opposed) gives the segment, its linear shape functions at the crossing
  the master weights, and the signed distance t along the normal the gap.  The search walks the
  rays down a bounding-volume hierarchy of the master facets built on SciPy's k-d tree
  (``cKDTree``): no double loop.  A slave node within ``snap`` of a master
  node pairs with it node to node (weights exactly (1, 0), g = 0), so a matching interface gives
  exactly the rows of :func:`match_nodes`; a gap within ``snap`` of 0 is 0 (a slave node on a
  master facet, placed there to rounding: on a rotated interface the ray's distance is +-1e-16).
* A slave node with one prescribed displacement component (a roller, or a node on a symmetry
  plane through the contact boundary: ``fixed``) takes its normal along its free component
  (:func:`roller_normals`).
* :class:`Line`, :class:`Circle`: rigid obstacles given analytically, master of a single body
  (:func:`obstacle_pairing`); their rows involve the slave body's DOFs only, along the
  obstacle's own normal at the nearest point, with the signed distance as the gap.

Slave nodes whose ray misses the master boundary, meets only its back, or meets it farther than
``search_distance`` are left out; :attr:`Pairing.excluded` lists them and
:meth:`Pairing.exclusion_message` describes them (the assembly warns once).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from cfcontact.errors import GeometryError, InputError

PAIRINGS = ("node", "segment")
#: shape-function weights closer than this to 0 or 1 are snapped (rounding of a ray through a vertex)
WEIGHT_SNAP = 1e-12


# ============================================================== results
@dataclass(eq=False)
class Pairing:
    """The contact pairs of one interface (one entry per row of N and T).

    Attributes
    ----------
    slave : (m,) int -- slave node of each pair
    master : (m, 2) int -- master nodes (a segment; -1 where absent: node to node has one, an
        obstacle none)
    weights : (m, 2) float -- linear shape functions of the master nodes at the projection
    normals : (m, 2) float -- unit n (the outer normal of body 1); tangents t = (-n_y, n_x)
    gap : (m,) float -- initial gap: distance from the slave node to the master along the ray
    tributary : (m,) float -- half the length of the slave facets around each slave node
        (a nodal force over it is a pressure)
    slave_body : 1 or 2 -- the body of the slave nodes (their rows carry +n for body 1, -n for body 2)
    excluded : (k,) int -- slave nodes left out;  excluded_reason : (k,) str ("miss", "back" or
        "distance": the ray misses the master, meets only its back, or meets no front of it within
        the search distance -- with a search distance, a ray that misses the master altogether is
        "distance" too: the search looks no farther)
    projections : (m, 2) float -- the master points the slave nodes are paired with
    """

    slave: np.ndarray
    master: np.ndarray
    weights: np.ndarray
    normals: np.ndarray
    gap: np.ndarray
    tributary: np.ndarray
    slave_body: int = 1
    excluded: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    excluded_reason: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype="<U8"))
    projections: Optional[np.ndarray] = None

    @property
    def m(self) -> int:
        return int(self.slave.size)

    @property
    def tangents(self) -> np.ndarray:
        return np.column_stack([-self.normals[:, 1], self.normals[:, 0]]).reshape(-1, 2)

    def select(self, keep) -> "Pairing":
        """The pairs ``keep`` (a boolean mask or indices), in that order."""
        idx = np.arange(self.m)[keep]
        return Pairing(self.slave[idx], self.master[idx], self.weights[idx], self.normals[idx], self.gap[idx],
                       self.tributary[idx], self.slave_body, self.excluded, self.excluded_reason,
                       None if self.projections is None else self.projections[idx])

    def body_nodes(self) -> np.ndarray:
        """(m, 2): the body-1 node and the body-2 node of each pair (the master node of larger
        weight on the master side; -1 for a rigid master) -- ``ContactGeometry.contact_nodes``."""
        j = np.argmax(self.weights, axis=1)
        main = self.master[np.arange(self.m), j]
        main = np.where(self.weights.max(axis=1, initial=0.0) > 0, main, -1)
        pair = np.column_stack([self.slave, main]) if self.slave_body == 1 else np.column_stack([main, self.slave])
        return pair.astype(np.int64).reshape(-1, 2)

    def entries(self):
        """Per pair the (node, factor) terms of its rows: (N u)_i = sum factor * u[node] . n_i
        (and the same with t_i for T); zero weights dropped.  Returns (pair, node, factor) arrays."""
        s = 1.0 if self.slave_body == 1 else -1.0
        rows = [np.arange(self.m), np.repeat(np.arange(self.m), 2)]
        nodes = [self.slave, self.master.ravel()]
        facs = [np.full(self.m, s), -s * self.weights.ravel()]
        pair, node, fac = np.concatenate(rows), np.concatenate(nodes), np.concatenate(facs)
        keep = (node >= 0) & (fac != 0.0)
        return pair[keep], node[keep], fac[keep]

    def exclusion_message(self, points, what="slave", master="the master boundary") -> str:
        """One sentence: how many nodes were left out, why, and where (empty if none)."""
        k = self.excluded.size
        if not k:
            return ""
        pts = np.asarray(points)[self.excluded]
        why = {"miss": f"their normal misses {master}", "back": f"their normal meets only the back of {master}",
               "distance": f"{master} is not within the search distance along their normal"}
        counts = ", ".join(f"{int(np.sum(self.excluded_reason == r))} because {text}" for r, text in why.items()
                           if np.any(self.excluded_reason == r))
        shown = "; ".join(f"({x:.6g}, {y:.6g})" for x, y in pts[:6]) + ("; ..." if k > 6 else "")
        box = (f" within x in [{pts[:, 0].min():.6g}, {pts[:, 0].max():.6g}], "
               f"y in [{pts[:, 1].min():.6g}, {pts[:, 1].max():.6g}]")
        return (f"{k} {what} node(s) left out of the contact pairing ({counts}){box}: {shown}")


# ============================================================== geometry
def facet_normals(points, facets, centroids):
    """(unit outer normals (F, 2), lengths (F,)) of boundary facets given by node pairs, oriented
    away from the centroid of the adjacent cell."""
    pts = np.asarray(points, dtype=float)
    facets = np.asarray(facets, dtype=np.int64).reshape(-1, 2)
    d = pts[facets[:, 1]] - pts[facets[:, 0]]
    length = np.hypot(d[:, 0], d[:, 1])
    if np.any(length <= 0):
        raise GeometryError("a contact boundary has facets of zero length")
    fn = np.column_stack([d[:, 1], -d[:, 0]]) / length[:, None]
    mid = 0.5 * (pts[facets[:, 1]] + pts[facets[:, 0]])
    outward = np.sum(fn * (mid - np.asarray(centroids, dtype=float)), axis=1)
    fn[outward < 0] *= -1.0
    return fn, length


def node_normals(points, facets, centroids, what="contact1", fixed=None):
    """(nodes, unit outer normals) of the nodes of a boundary: the normalised sum of the outer
    normals of each node's facets (summed in a fixed order: rank independent); with ``fixed``
    ((P, 2) bool, the prescribed displacement components of every node) turned at rollers by
    :func:`roller_normals`."""
    facets = np.asarray(facets, dtype=np.int64).reshape(-1, 2)
    fn, _ = facet_normals(points, facets, centroids)
    nodes = np.unique(facets)
    acc = np.zeros((len(nodes), 2))
    pos = np.searchsorted(nodes, facets)
    order = np.lexsort((facets[:, 1], facets[:, 0]))  # fixed summation order
    for j in order:
        acc[pos[j, 0]] += fn[j]
        acc[pos[j, 1]] += fn[j]
    norm = np.hypot(acc[:, 0], acc[:, 1])
    if np.any(norm < 1e-12):
        bad = nodes[norm < 1e-12]
        raise GeometryError(f"{what} normal undefined at node(s) {np.asarray(points)[bad].tolist()} "
                            "(facets with opposite normals)")
    normals = acc / norm[:, None]
    return nodes, (normals if fixed is None else roller_normals(normals, np.asarray(fixed, dtype=bool)[nodes]))


def roller_normals(normals, fixed):
    """The normals (k, 2) of k boundary nodes, those with one prescribed displacement component
    (``fixed``: (k, 2) bool) turned along the free one, where they are nearer to it than to the
    prescribed one.

    Such a node lies on a roller or on a symmetry plane, which the contact boundary meets there:
    it moves along the plane only.  Its averaged normal comes from the one facet on its side and
    is tilted by half that facet's turn (a cylinder's node on its axis of symmetry, the end
    node of a quarter model): its normal and tangential rows would then both read the one free
    component, and where the master side is held the same way (the other body's node on the
    plane, a rigid obstacle) they are dependent -- J(Z) singular for a closed sticking node.  By
    symmetry the normal lies in the plane; along it the node's tangential row reads only
    prescribed components, so the pair has no tangential unknown
    (:attr:`cfcontact.system.ContactSystem.no_tangent`).  The gap is then measured along the
    direction the node can move."""
    normals = np.array(normals, dtype=float).reshape(-1, 2)
    fixed = np.asarray(fixed, dtype=bool).reshape(-1, 2)
    for comp in (0, 1):  # comp prescribed, the other free
        free = 1 - comp
        turn = fixed[:, comp] & ~fixed[:, free] & (np.abs(normals[:, free]) >= np.abs(normals[:, comp]))
        normals[turn, comp] = 0.0
        normals[turn, free] = np.sign(normals[turn, free])
    return normals


def tributary_lengths(points, facets, nodes):
    """Half the total length of the facets around each of ``nodes`` (0 for a node on none)."""
    pts = np.asarray(points, dtype=float)
    facets = np.asarray(facets, dtype=np.int64).reshape(-1, 2)
    d = pts[facets[:, 1]] - pts[facets[:, 0]]
    half = 0.5 * np.hypot(d[:, 0], d[:, 1])
    total = np.zeros(len(pts))
    np.add.at(total, facets[:, 0], half)
    np.add.at(total, facets[:, 1], half)
    return total[np.asarray(nodes, dtype=np.int64)]


def order_along_interface(points, nodes, tangents):
    """Indices sorting ``nodes`` by their coordinate along the mean tangent (node index breaks ties)."""
    nodes = np.asarray(nodes, dtype=np.int64)
    if not len(nodes):
        return np.zeros(0, dtype=np.int64)
    tangents = np.asarray(tangents, dtype=float)
    tbar = tangents.sum(axis=0)
    if np.hypot(*tbar) < 1e-12 * len(nodes):
        tbar = tangents[0]
    s = np.asarray(points, dtype=float)[nodes] @ (tbar / np.hypot(*tbar))
    return np.lexsort((nodes, s))


# ================================================================ input
def check_search_distance(value):
    """None (no limit) or a finite positive number, else InputError."""
    if value is None:
        return None
    try:
        if isinstance(value, bool):
            raise TypeError
        value = float(value)
    except (TypeError, ValueError):
        raise InputError(f"search_distance must be a positive number (or None: no limit), got {value!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise InputError(f"search_distance must be a positive number (or None: no limit), got {value!r}")
    return value


def check_pairing(value):
    if value not in PAIRINGS:
        raise InputError(f"pairing must be one of {', '.join(map(repr, PAIRINGS))}, got {value!r}")
    return value


def _point(value, what):
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise InputError(f"{what} must be a finite 2-vector (x, y), got {value!r}")
    return arr


# ============================================================ obstacles
class Obstacle:
    """A rigid obstacle given analytically (master of a single body)."""

    kind = ""

    def ray(self, x, d):
        """First crossing of the rays x + t d (unit d) with the obstacle's surface from outside:
        (t, status) with status 0 = hit (t may be < 0: x inside, an initial interference),
        1 = miss, 2 = the obstacle lies behind / is met from inside only (back)."""
        raise NotImplementedError

    def closest(self, x):
        """The signed distance of the points x (k, 2) to the obstacle's surface (positive outside
        the obstacle) and its direction: (gap (k,), n (k, 2)) with n the unit normal of the
        surface at the nearest point, pointing into the obstacle (the outer normal of a body
        touching it there).  gap - n . u >= 0 is non-penetration linearised at x: n is minus the
        distance's gradient.  n is NaN where the direction is undefined (the centre of a circle)."""
        raise NotImplementedError

    def to_dict(self) -> dict:
        raise NotImplementedError


@dataclass(frozen=True)
class Line(Obstacle):
    """The rigid half-plane {x : (x - point) . normal <= 0}: ``normal`` is its outer normal
    (pointing toward the body)."""

    point: tuple
    normal: tuple
    kind = "line"

    def __post_init__(self):
        p = _point(self.point, "obstacle line 'point'")
        nv = _point(self.normal, "obstacle line 'normal'")
        length = float(np.hypot(*nv))
        if length == 0:
            raise InputError("obstacle line 'normal' must not be zero")
        object.__setattr__(self, "point", tuple(p.tolist()))
        object.__setattr__(self, "normal", tuple((nv / length).tolist()))

    def ray(self, x, d):
        p, nv = np.asarray(self.point), np.asarray(self.normal)
        dn = d @ nv
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((p - x) @ nv) / dn
        status = np.where(dn < 0, 0, np.where(dn > 0, 2, 1))
        return np.where(status == 0, t, np.inf), status

    def closest(self, x):
        p, nv = np.asarray(self.point), np.asarray(self.normal)
        x = np.asarray(x, dtype=float).reshape(-1, 2)
        return (x - p) @ nv, np.tile(-nv, (len(x), 1))

    def to_dict(self):
        return {"kind": "line", "point": list(self.point), "normal": list(self.normal)}


@dataclass(frozen=True)
class Circle(Obstacle):
    """A rigid disc of radius ``radius`` centred at ``center``, the body outside it; with
    ``inside=True`` a rigid bore instead (the solid is outside the circle, the body lies in its
    hole: a shaft or a pin in a rigid bearing)."""

    center: tuple
    radius: float
    inside: bool = False
    kind = "circle"

    def __post_init__(self):
        c = _point(self.center, "obstacle circle 'center'")
        try:
            r = float(self.radius)
        except (TypeError, ValueError):
            r = float("nan")
        if isinstance(self.radius, bool) or not (math.isfinite(r) and r > 0):
            raise InputError(f"obstacle circle 'radius' must be a positive number, got {self.radius!r}")
        if not isinstance(self.inside, (bool, np.bool_)):
            raise InputError(f"obstacle circle 'inside' must be true or false, got {self.inside!r}")
        object.__setattr__(self, "center", tuple(c.tolist()))
        object.__setattr__(self, "radius", r)
        object.__setattr__(self, "inside", bool(self.inside))

    def ray(self, x, d):
        r = x - np.asarray(self.center)
        rd = np.sum(r * d, axis=1)
        disc = rd * rd - np.sum(r * r, axis=1) + self.radius ** 2
        root = np.sqrt(np.maximum(disc, 0.0))
        t1, t2 = -rd - root, -rd + root  # the ray's crossings with the circle, t1 <= t2
        if self.inside:
            # the solid lies beyond the circle: the ray leaves the hole at t2 (t2 < 0: x is in the
            # solid, an initial interference); t1 > 0: x is in the solid and the ray enters the hole
            status = np.where(disc < 0, 1, np.where(t1 > 0, 2, 0))
            return np.where(status == 0, t2, np.inf), status
        status = np.where(disc < 0, 1, np.where(t2 < 0, 2, 0))
        return np.where(status == 0, t1, np.inf), status

    def closest(self, x):
        r = np.asarray(x, dtype=float).reshape(-1, 2) - np.asarray(self.center)
        dist = np.hypot(r[:, 0], r[:, 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            radial = np.where(dist[:, None] > 0, r / dist[:, None], np.nan)
        if self.inside:  # the solid beyond the circle: the body's normal points away from the centre
            return self.radius - dist, radial
        return dist - self.radius, -radial

    def to_dict(self):
        out = {"kind": "circle", "center": list(self.center), "radius": self.radius}
        if self.inside:  # (left out otherwise: the saved form of a disc is unchanged)
            out["inside"] = True
        return out


OBSTACLE_KEYS = {"line": ("point", "normal"), "circle": ("center", "radius")}
#: An obstacle that every contact node penetrates deeper than this share of the contact boundary's
#: extent is taken for a misplaced one (a reversed normal, a wrong centre) and refused.
INTERFERENCE_LIMIT = 0.01
#: keys an obstacle may leave out (their defaults: a disc with the body outside it)
OBSTACLE_OPTIONAL = {"line": (), "circle": ("inside",)}


def make_obstacle(spec) -> Optional[Obstacle]:
    """An :class:`Obstacle` from itself, None, or a dict ``{"kind": "line", "point": (x, y),
    "normal": (nx, ny)}`` / ``{"kind": "circle", "center": (x, y), "radius": R}`` (InputError
    naming the bad key otherwise)."""
    if spec is None or isinstance(spec, Obstacle):
        return spec
    if not hasattr(spec, "items"):
        raise InputError(f"obstacle must be a dict with a 'kind' ({' or '.join(OBSTACLE_KEYS)}), got {spec!r}")
    kind = spec.get("kind")
    if kind not in OBSTACLE_KEYS:
        raise InputError(f"obstacle 'kind' must be one of {', '.join(map(repr, OBSTACLE_KEYS))}, got {kind!r}")
    keys, optional = OBSTACLE_KEYS[kind], OBSTACLE_OPTIONAL[kind]
    unknown = sorted(set(map(str, spec)) - set(keys) - set(optional) - {"kind"})
    missing = [k for k in keys if k not in spec]
    if unknown or missing:
        raise InputError(f"obstacle of kind {kind!r} takes the keys {', '.join(keys + optional)}"
                         + (f" ({', '.join(optional)} optional)" if optional else "")
                         + (f"; unknown: {', '.join(unknown)}" if unknown else "")
                         + (f"; missing: {', '.join(missing)}" if missing else ""))
    return (Line if kind == "line" else Circle)(*(spec[k] for k in keys), **{k: spec[k] for k in optional if k in spec})


# ============================================================== pairing
def match_nodes(points, nodes1, nodes2, tol, match_tol, h):
    """Partner in ``nodes2`` of every node of ``nodes1`` (coinciding within ``tol``), one to one;
    GeometryError naming the unmatched nodes otherwise."""
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=float)
    dist12, j12 = cKDTree(pts[nodes2]).query(pts[nodes1])
    dist21, _ = cKDTree(pts[nodes1]).query(pts[nodes2])
    bad1 = np.flatnonzero(dist12 > tol)
    bad2 = np.flatnonzero(dist21 > tol)
    if bad1.size or bad2.size:
        lines = []
        for bad, nodes, dist, mine, other in ((bad1, nodes1, dist12, "contact1", "contact2"),
                                              (bad2, nodes2, dist21, "contact2", "contact1")):
            for k in bad[:10]:
                x, y = pts[nodes[k]]
                lines.append(f"{mine} node at ({x:.6g}, {y:.6g}): nearest {other} node at distance {dist[k]:.3g}")
            if bad.size > 10:
                lines.append(f"... and {bad.size - 10} more {mine} nodes")
        raise GeometryError(
            f"non-matching contact interface: {bad1.size} contact1 node(s) and {bad2.size} contact2 node(s) "
            f"have no partner within {tol:.3g} (match_tol={match_tol:g} x shortest contact facet {h:.3g}); "
            "the nodes of contact1 and contact2 must coincide pairwise, or use node-to-segment pairing "
            "(pairing='segment'):\n  " + "\n  ".join(lines))
    partner = np.asarray(nodes2)[j12]
    if np.unique(partner).size != partner.size or len(nodes2) != len(nodes1):
        raise GeometryError("contact1 and contact2 nodes do not pair one-to-one (match_tol too large?)")
    return partner


def _ray_segments(x, d, a, b, fnu):
    """Crossings of the rays x + t d with the segments a-b (arrays aligned row by row; fnu the
    segments' outer normals): (t, xi, ok, back) -- ok: a crossing within the segment from its
    front side, back: a crossing within the segment from behind."""
    e = b - a
    r = a - x
    den = d[..., 0] * e[..., 1] - d[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (r[..., 0] * e[..., 1] - r[..., 1] * e[..., 0]) / den
        xi = (r[..., 0] * d[..., 1] - r[..., 1] * d[..., 0]) / den
    inside = np.isfinite(t) & (xi >= -WEIGHT_SNAP) & (xi <= 1.0 + WEIGHT_SNAP)
    facing = np.sum(fnu * d, axis=-1) < 0
    return t, xi, inside & facing, inside & ~facing


class _SegmentTree:
    """A bounding-volume hierarchy of segments for ray queries: SciPy's k-d tree of the segment
    midpoints (``cKDTree``) gives the nested index ranges, each node gets the bounding box of its
    segments, and :meth:`crossings` walks it for many rays at once (vectorised per level)."""

    def __init__(self, A, B, leafsize=8):
        from scipy.spatial import cKDTree

        self.A, self.B = A, B
        kd = cKDTree(0.5 * (A + B), leafsize=leafsize)
        self.order = kd.indices  # segments in tree order: every node covers a contiguous range
        ranges, children, stack = [], [], [(kd.tree, -1, 0)]
        while stack:  # nodes in depth-first order, parents before children
            node, parent, side = stack.pop()
            k = len(ranges)
            ranges.append((node.start_idx, node.end_idx))
            children.append([-1, -1])
            if parent >= 0:
                children[parent][side] = k
            if node.lesser is not None:
                stack.append((node.greater, k, 1))
                stack.append((node.lesser, k, 0))
        self.ranges = np.asarray(ranges, dtype=np.int64)
        self.children = np.asarray(children, dtype=np.int64)
        lo = np.minimum(A, B)[self.order]
        hi = np.maximum(A, B)[self.order]
        nn = len(ranges)
        self.lo, self.hi = np.empty((nn, 2)), np.empty((nn, 2))
        leaf = self.children[:, 0] < 0
        for k in np.flatnonzero(leaf):
            a, b = self.ranges[k]
            self.lo[k], self.hi[k] = lo[a:b].min(axis=0), hi[a:b].max(axis=0)
        for k in np.flatnonzero(~leaf)[::-1]:  # children come after their parent
            c0, c1 = self.children[k]
            self.lo[k] = np.minimum(self.lo[c0], self.lo[c1])
            self.hi[k] = np.maximum(self.hi[c0], self.hi[c1])
        pad = 1e-12 * max(float(np.abs(np.concatenate([A, B])).max(initial=0.0)), 1.0)
        self.lo -= pad
        self.hi += pad
        self.leaf = leaf

    def crossings(self, x, d, reach=None):
        """(ray, segment) candidate pairs: the segments in a leaf whose box the line x + t d
        crosses (within distance ``reach`` of x, if given)."""
        rays = np.arange(len(x))
        nodes = np.zeros(len(x), dtype=np.int64)
        out_r, out_n = [], []
        while rays.size:
            lo, hi, xr, dr = self.lo[nodes], self.hi[nodes], x[rays], d[rays]
            # the line misses the box iff its four corners lie strictly on one side of it
            side = [dr[:, 0] * (cy - xr[:, 1]) - dr[:, 1] * (cx - xr[:, 0])
                    for cx, cy in ((lo[:, 0], lo[:, 1]), (hi[:, 0], lo[:, 1]), (hi[:, 0], hi[:, 1]), (lo[:, 0], hi[:, 1]))]
            side = np.column_stack(side)
            keep = ~((side > 0).all(axis=1) | (side < 0).all(axis=1))
            if reach is not None:
                gapv = np.maximum(np.maximum(lo - xr, xr - hi), 0.0)
                keep &= np.hypot(gapv[:, 0], gapv[:, 1]) <= reach
            rays, nodes = rays[keep], nodes[keep]
            is_leaf = self.leaf[nodes]
            out_r.append(rays[is_leaf])
            out_n.append(nodes[is_leaf])
            rays, nodes = rays[~is_leaf], nodes[~is_leaf]
            rays = np.repeat(rays, 2)
            nodes = self.children[nodes].ravel()
        r = np.concatenate(out_r) if out_r else np.zeros(0, dtype=np.int64)
        n = np.concatenate(out_n) if out_n else np.zeros(0, dtype=np.int64)
        a, b = self.ranges[n, 0], self.ranges[n, 1]
        count = b - a
        ray = np.repeat(r, count)
        pos = np.repeat(a - np.concatenate([[0], np.cumsum(count)[:-1]]), count) + np.arange(int(count.sum()))
        return ray, self.order[pos]


def node_to_segment(points, slave_facets, slave_centroids, master_facets, master_centroids, *, slave_body=1,
                    search_distance=None, snap=0.0, slave_name="slave", master_name="master", fixed=None) -> Pairing:
    """Node-to-segment pairing of the slave boundary's nodes onto the master boundary (see the
    module docstring).  Facets are (F, 2) node pairs, centroids the centroids of their cells (for
    the outer normals).  ``slave_body``: 1 or 2 (the normal n is the slave's outer normal for 1,
    its opposite for 2).  Pairs are in slave node order; excluded nodes are reported, not raised.

    Search: the rays are walked down a bounding-volume hierarchy of the master facets built on
    SciPy's k-d tree (:class:`_SegmentTree`); only the facets of the leaves whose boxes a ray's
    line crosses are intersected (about log(#facets) boxes per ray).  ``fixed``: see
    :func:`node_normals`."""
    pts = np.asarray(points, dtype=float)
    search = check_search_distance(search_distance)
    snodes, snormal = node_normals(pts, slave_facets, slave_centroids, slave_name, fixed)
    mf = np.asarray(master_facets, dtype=np.int64).reshape(-1, 2)
    if not len(mf):
        raise GeometryError(f"{master_name} has no facets")
    mnu, _ = facet_normals(pts, mf, master_centroids)
    A, B = pts[mf[:, 0]], pts[mf[:, 1]]
    xs = pts[snodes]
    ns = len(snodes)
    ray, seg = _SegmentTree(A, B).crossings(xs, snormal, search)
    t, xi, ok, back = _ray_segments(xs[ray], snormal[ray], A[seg], B[seg], mnu[seg])
    far = ok & (np.abs(t) > search) if search is not None else np.zeros_like(ok)
    seen_back = np.zeros(ns, dtype=bool)
    seen_back[ray[back]] = True
    seen_far = np.zeros(ns, dtype=bool)
    seen_far[ray[far]] = True
    ok &= ~far
    ray, seg, t, xi = ray[ok], seg[ok], t[ok], xi[ok]
    # nearest crossing per ray (|t| smallest; ties: the lower facet index)
    order = np.lexsort((seg, np.abs(t), ray))
    ray, seg, t, xi = ray[order], seg[order], t[order], xi[order]
    first = np.ones(ray.size, dtype=bool)
    first[1:] = ray[1:] != ray[:-1]
    found = np.zeros(ns, dtype=bool)
    found[ray[first]] = True
    best_t, best_seg, best_xi = np.zeros(ns), np.zeros(ns, dtype=np.int64), np.zeros(ns)
    best_t[ray[first]], best_seg[ray[first]], best_xi[ray[first]] = t[first], seg[first], xi[first]

    xi = np.clip(best_xi, 0.0, 1.0)
    xi = np.where(xi < WEIGHT_SNAP, 0.0, np.where(xi > 1.0 - WEIGHT_SNAP, 1.0, xi))
    master = mf[best_seg]
    weights = np.column_stack([1.0 - xi, xi])
    gap = best_t.copy()
    # a slave node on a master node (a matching interface): node to node, g = 0 exactly; on a
    # master facet (to rounding): g = 0
    if snap > 0:
        near_a = np.hypot(*(xs - A[best_seg]).T) <= snap
        near_b = ~near_a & (np.hypot(*(xs - B[best_seg]).T) <= snap)
        weights[near_a] = (1.0, 0.0)
        weights[near_b] = (0.0, 1.0)
        gap = np.where(near_a | near_b | (np.abs(gap) <= snap), 0.0, gap)
    proj = xs + best_t[:, None] * snormal
    normals = snormal if slave_body == 1 else -snormal
    trib = tributary_lengths(pts, slave_facets, snodes)
    reason = np.where(seen_far, "distance", np.where(seen_back, "back", "miss"))
    if search is not None:
        reason = np.where(seen_back & ~seen_far, "back", "distance")
    return Pairing(snodes[found], master[found], weights[found], normals[found].reshape(-1, 2), gap[found],
                   trib[found], int(slave_body), snodes[~found], reason[~found].astype("<U8"), proj[found])


def obstacle_pairing(points, slave_facets, slave_centroids, obstacle: Obstacle, *, search_distance=None,
                     slave_name="contact1", snap=0.0, fixed=None) -> Pairing:
    """Pairing of a single body's contact boundary (body 1) with a rigid obstacle.  The slave nodes
    whose outer normal meets the obstacle from outside are its contact nodes; each one's row is
    the non-penetration condition linearised at the node: the gap is its signed distance to the
    obstacle's surface and the normal is the surface's normal at the nearest point
    (:meth:`Obstacle.closest`), not the node's own averaged normal, which on a curved body is
    tilted against a flat obstacle and would make frictionless contact carry tangential forces.
    A node with one prescribed displacement component (``fixed``) keeps the normal along its free
    component (:func:`roller_normals`) and the distance along it.  The gap is exactly 0 within
    ``snap`` (a node meshed on the obstacle's surface: gmsh places it there to rounding, and a gap
    of -1e-16 would make a touching interface an interference).  GeometryError when no node meets
    the obstacle (it does not face the body)."""
    pts = np.asarray(points, dtype=float)
    search = check_search_distance(search_distance)
    snodes, snormal = node_normals(pts, slave_facets, slave_centroids, slave_name, fixed)
    xs = pts[snodes]
    t, status = obstacle.ray(xs, snormal)
    gap, normal = obstacle.closest(xs)
    status = np.where((status == 0) & ~np.isfinite(normal).all(axis=1), 1, status)  # (a node at a circle's centre)
    if fixed is not None:
        along = roller_normals(np.where(np.isfinite(normal), normal, 0.0), np.asarray(fixed, dtype=bool)[snodes])
        turned = np.isfinite(normal).all(axis=1) & np.any(along != normal, axis=1)
        if turned.any():
            t_turned, hit = obstacle.ray(xs[turned], along[turned])
            gap[turned] = np.where(hit == 0, t_turned, t[turned])
            normal[turned] = along[turned]
    # the surface nearest a node must face it: its normal and the node's outer normal not opposed
    # (a node inside a disc it is meant to lie around meets the disc's far side along its normal)
    status = np.where((status == 0) & (np.sum(np.nan_to_num(normal) * snormal, axis=1) <= 0.0), 2, status)
    t = np.where(status == 0, gap, np.inf)
    t = np.where((status == 0) & (np.abs(t) <= snap), 0.0, t)
    far = (status == 0) & (search is not None) & (np.abs(t) > (search if search is not None else np.inf))
    found = (status == 0) & ~far
    hint = ""
    if isinstance(obstacle, Circle) and not obstacle.inside and np.all(gap < 0):
        hint = " (a body in a circular hole: inside = true)"
    if not found.any():
        why = ("its surface is farther than search_distance from every node" if far.any() else
               "the outer normals of the body's contact nodes miss it or meet it from behind")
        raise GeometryError(f"the obstacle {obstacle.to_dict()} does not face {slave_name}: {why} "
                            f"({slave_name} spans x in [{xs[:, 0].min():.6g}, {xs[:, 0].max():.6g}], "
                            f"y in [{xs[:, 1].min():.6g}, {xs[:, 1].max():.6g}]){hint}")
    extent = float(np.ptp(xs, axis=0).max(initial=0.0))
    if np.all(t[found] < 0) and -t[found].min() > INTERFERENCE_LIMIT * extent:
        # (a shallower interference at every node is a press fit: a shaft in a smaller bore)
        raise GeometryError(f"the obstacle {obstacle.to_dict()} does not face {slave_name}: every {slave_name} node "
                            f"lies inside it (gaps from {t[found].min():.6g} to {t[found].max():.6g}); is its normal "
                            "reversed or its position wrong?" + hint)
    reason = np.where(far, "distance", np.where(status == 2, "back", "miss"))
    m = int(found.sum())
    trib = tributary_lengths(pts, slave_facets, snodes)
    return Pairing(snodes[found], np.full((m, 2), -1, dtype=np.int64), np.zeros((m, 2)), normal[found].reshape(-1, 2),
                   t[found], trib[found], 1, snodes[~found], reason[~found].astype("<U8"),
                   xs[found] + t[found, None] * normal[found])
