"""Contact pairing (issue #12, item 2): node-to-segment, rigid obstacles, the matching identity.

References: the node pairing of a conforming interface (the rows cfcontact has always built),
analytic gaps of lines and circles, the exactness of linear interpolation (a rigid motion or an
affine field gives the same relative displacement through any pairing), and timing.
"""

import os
import sys
import time
import warnings

import numpy as np
import pytest

import cfcontact
from cfcontact import pairing
from cfcontact.errors import GeometryError, InputError, PairingWarning

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "demos"))
import lame  # noqa: E402  (demos/lame.py: the hub's gmsh model)


def _dense(system):
    K, N, T, f1, f2 = system.to_scipy()
    return N.toarray(), T.toarray()


# ------------------------------------------------------------ matching identity
@pytest.mark.parametrize("build", [
    lambda **k: cfcontact.two_blocks(nx=8, ny=3, **k),
    lambda **k: cfcontact.two_blocks(nx=8, ny=3, cell="triangle", angle=20.0, **k),
    lambda **k: cfcontact.arc_on_block(radius=1.0, half_angle=40.0, nx=12, ny=3, **k),
], ids=["quad", "inclined", "arc"])
def test_matching_interface_gives_exactly_the_node_pairing(build):
    """Node to segment on a conforming interface = node to node: the same N, T (bit for bit), no
    gap, the same contact nodes -- whichever side is the slave."""
    ref = build()
    Nr, Tr = _dense(ref)
    assert ref.info["contact"]["pairing"] == "node" and not ref.has_gap
    for slave in ("contact1", "contact2", 20):
        seg = build(pairing="segment", slave=slave)
        N, T = _dense(seg)
        assert np.array_equal(N, Nr) and np.array_equal(T, Tr), slave
        assert not seg.has_gap and seg.info["contact"]["excluded"] == 0
        assert np.array_equal(seg.geometry.contact_nodes, ref.geometry.contact_nodes)
        assert np.array_equal(seg.geometry.normals, ref.geometry.normals)


# ------------------------------------------------------------ non-matching
@pytest.mark.parametrize("slave", ["contact1", "contact2"])
def test_non_matching_blocks_interpolate_affine_fields_exactly(slave):
    """Two blocks with 6 and 9 cells along the interface (refused by node pairing) pair node to
    segment: no gap, every slave node paired, and for any affine displacement field of body 2
    (and another of body 1) N u and T u are the exact relative displacements at the slave nodes."""
    with pytest.raises(GeometryError, match="pairing='segment'"):
        cfcontact.two_blocks(nx=6, ny=2, nx2=9, ny2=3)
    system = cfcontact.two_blocks(nx=6, ny=2, nx2=9, ny2=3, pairing="segment", slave=slave, clamp=("top1", "bottom2"))
    geo = system.geometry
    assert system.m == (7 if slave == "contact1" else 10) and np.abs(system.gap).max() <= 1e-15
    assert geo.tributary.sum() == pytest.approx(3.0)
    N, T = _dense(system)
    X = geo.points[geo.dof_node]
    body = np.zeros(len(geo.points), dtype=int)
    body[geo.cells.ravel()] = np.repeat(geo.cell_body, geo.cells.shape[1])
    b = body[geo.dof_node]
    rng = np.random.default_rng(0)
    G1, c1, G2, c2 = rng.standard_normal((2, 2)), rng.standard_normal(2), rng.standard_normal((2, 2)), rng.standard_normal(2)
    U = np.where((b == 1)[:, None], X @ G1.T + c1, X @ G2.T + c2)
    u = U[np.arange(len(X)), geo.dof_comp]
    xs = geo.contact_points
    rel = (xs @ G1.T + c1) - (xs @ G2.T + c2)
    assert np.allclose(N @ u, np.sum(rel * geo.normals, axis=1), atol=1e-13)
    assert np.allclose(T @ u, np.sum(rel * geo.tangents, axis=1), atol=1e-13)
    sol = cfcontact.ssnm(system, 0.5)
    assert cfcontact.verify(system, sol, 0.5).ok(1e-9)


def test_slave_must_be_a_contact_boundary():
    for bad in ("top1", 12):
        with pytest.raises(GeometryError, match="slave must be a contact boundary .*top1=12"):
            cfcontact.two_blocks(nx=3, ny=1, pairing="segment", slave=bad)
    with pytest.raises(GeometryError, match="slave must be a contact boundary .*'contact3', which is not"):
        cfcontact.two_blocks(nx=3, ny=1, pairing="segment", slave="contact3")
    with pytest.raises(InputError, match="pairing must be one of 'node', 'segment', got 'nodes'"):
        cfcontact.two_blocks(nx=3, ny=1, pairing="nodes")
    with pytest.raises(GeometryError, match="needs a master"):
        cfcontact.two_blocks(nx=3, ny=1, foundation=True, pairing="segment")


@pytest.mark.parametrize("value", [0, 0.0, -1.0, float("nan"), "far", True])
def test_search_distance_must_be_positive(value):
    with pytest.raises(InputError, match="search_distance must be a positive number"):
        cfcontact.two_blocks(nx=3, ny=1, pairing="segment", search_distance=value)


# ------------------------------------------------------------ obstacles
def _block_on(obstacle, **kw):
    """A 2 x 0.5 block (body 1 alone, contact1 = its bottom y = 0) pressed down by its top."""
    return cfcontact.two_blocks(nx=kw.pop("nx", 10), ny=2, length=2.0, height=0.5, foundation=True, obstacle=obstacle,
                                clamp=(), dirichlet={"top1": {"x": 0.0, "y": (0.0, -0.02)}},
                                tractions1={}, tractions2={}, **kw)


def test_line_obstacle_gap_and_rows():
    """A rigid line y = -0.01 x - 0.005 below the block: the gap is each node's distance to the line
    and the rows are taken along the line's normal (non-penetration linearised at the node), not
    along the block's (0, -1); they involve body 1's DOFs only, as the rigid foundation's."""
    slope, off = -0.01, -0.005
    nv = np.array([-slope, 1.0]) / np.hypot(slope, 1.0)
    system = _block_on({"kind": "line", "point": (0.0, off), "normal": tuple(nv)})
    x = system.geometry.contact_points[:, 0]
    assert np.allclose(system.gap, x * nv[0] - off * nv[1], rtol=1e-12, atol=1e-15)
    assert np.all(system.geometry.contact_nodes[:, 1] == -1)
    assert np.allclose(system.geometry.normals, -nv, rtol=0, atol=1e-15)
    N, T = _dense(system)
    ref = cfcontact.two_blocks(nx=10, ny=2, length=2.0, height=0.5, foundation=True, clamp=(),
                               dirichlet={"top1": {"x": 0.0, "y": (0.0, -0.02)}}, tractions1={}, tractions2={})
    Nr, Tr = _dense(ref)  # rows along n = (0, -1), t = (1, 0): Tr reads u_x, -Nr u_y
    n = -nv
    t = np.array([-n[1], n[0]])
    assert np.allclose(N, n[0] * Tr - n[1] * Nr, rtol=0, atol=1e-15)
    assert np.allclose(T, t[0] * Tr - t[1] * Nr, rtol=0, atol=1e-15)
    assert system.info["contact"]["obstacle"]["kind"] == "line"
    assert system.geometry.obstacle == system.info["contact"]["obstacle"]


def test_circle_obstacle_gap_excluded_nodes_and_warning():
    """A rigid disc of radius 0.65 below the block's centre: the gap is the distance to the disc,
    sqrt((x - x0)^2 + (R + d)^2) - R, along the disc's radial normal; nodes whose normal misses the
    disc (|x - x0| > R) are left out, with one warning naming how many and where."""
    R, x0, d = 0.65, 1.0, 0.001
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        system = _block_on({"kind": "circle", "center": (x0, -R - d), "radius": R}, nx=20)
    ours = [w for w in caught if issubclass(w.category, PairingWarning)]
    assert len(ours) == 1
    msg = str(ours[0].message)
    x = system.geometry.contact_points[:, 0]
    assert np.all(np.abs(x - x0) <= R)
    dist = np.hypot(x - x0, R + d)
    assert np.allclose(system.gap, dist - R, rtol=1e-12)
    assert np.allclose(system.geometry.normals, -np.column_stack([x - x0, np.full_like(x, R + d)]) / dist[:, None],
                       rtol=0, atol=1e-15)
    info = system.info["contact"]
    assert info["excluded"] == 21 - 13 and info["pairs"] == 13 and info["excluded_reasons"] == {"miss": 8}
    assert "8 contact1=10 node(s) left out" in msg and "misses the obstacle" in msg and "x in [0, 2]" in msg
    assert info["gap_range"] == [pytest.approx(d), pytest.approx(np.hypot(0.6, R + d) - R)]
    # a search distance keeps only the nodes within it
    with pytest.warns(PairingWarning, match="not within the search distance along their normal"):
        near = _block_on({"kind": "circle", "center": (x0, -R - d), "radius": R}, nx=20, search_distance=0.05)
    assert near.m < system.m and near.gap.max() <= 0.05


@pytest.mark.parametrize("obstacle,words", [
    ({"kind": "line", "point": (0, -0.01), "normal": (0, -1)}, "does not face contact1"),
    ({"kind": "line", "point": (0, 1.0), "normal": (0, 1)}, "does not face contact1"),
    ({"kind": "circle", "center": (1.0, 3.0), "radius": 0.5}, "does not face contact1"),
    ({"kind": "circle", "center": (5.0, -1.0), "radius": 0.5}, "does not face contact1"),
])
def test_obstacle_that_does_not_face_the_body(obstacle, words):
    with pytest.raises(GeometryError, match=words):
        _block_on(obstacle)


@pytest.mark.parametrize("obstacle,words", [
    ({"kind": "plane", "point": (0, 0)}, "'kind' must be one of 'line', 'circle'"),
    ({"kind": "line", "point": (0, 0)}, "missing: normal"),
    ({"kind": "line", "point": (0, 0), "normal": (0, 0)}, "must not be zero"),
    ({"kind": "circle", "center": (0, 0), "radius": -1}, "'radius' must be a positive number"),
    ({"kind": "circle", "centre": (0, 0), "radius": 1}, "unknown: centre"),
    ("line", "must be a dict"),
])
def test_obstacle_specification_errors(obstacle, words):
    with pytest.raises(InputError, match=words):
        pairing.make_obstacle(obstacle)
    with pytest.raises(InputError, match=words):  # the assembly validates it before building anything
        cfcontact.assemble_contact_system("/nonexistent.msh", obstacle=obstacle)


def _hub_in_bore(clearance, U, nodes=48, inside=True, friction=0.3, nu=0.3):
    """A hub (annulus of radii 0.3 and 1, body 1 alone, its outer circle contact1 with ``nodes``
    equally spaced nodes) in a rigid bore of radius 1 + clearance centred on it; its inner circle
    is moved by alpha U (prescribed), nothing else holds it."""
    from cfcontact import compat

    with compat.gmsh_model("hub") as model:
        lame.mesh_hub(model, nodes, 0.15)  # (demos/lame.py: radii 0.3 and 1)
        return cfcontact.assemble_contact_system(
            model, clamp=(), friction=friction, nu=nu, obstacle={"kind": "circle", "center": (0.0, 0.0),
                                                           "radius": 1.0 + clearance, "inside": inside},
            dirichlet={"inner1": {"x": (0.0, U[0]), "y": (0.0, U[1])}})


def test_shaft_in_a_rigid_bore():
    """``inside=True``: the body lies in the circle's hole.  Gaps are the radial clearance; before
    any contact the hub moves rigidly (u = alpha U), so the first node closes where its clearance
    over its normal displacement, c_i / (n_i . U), is least (the analytic first transition); the
    whole path verifies, and the disc reading of the same circle is refused with a hint."""
    c, U = 1e-3, np.array([1e-3, -3e-3])
    system = _hub_in_bore(c, U)
    x = system.geometry.contact_points[:, :2]
    r = np.hypot(*x.T)
    assert system.m == 48 and np.allclose(r, 1.0, atol=1e-12)
    assert np.allclose(system.gap, 1.0 + c - r, rtol=1e-9, atol=1e-15)
    assert np.allclose(system.geometry.normals[:, :2], x / r[:, None], atol=1e-12)  # outward, radial
    assert system.info["contact"]["obstacle"] == {"kind": "circle", "center": [0.0, 0.0], "radius": 1.0 + c,
                                                  "inside": True}
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert path.status == "completed" and len(path.transitions) > 5
    rate = (x / r[:, None]) @ U
    closing = np.where(rate > 0, system.gap / np.where(rate > 0, rate, 1.0), np.inf)
    first = path.transitions[0]
    assert first.alpha == pytest.approx(closing.min(), rel=1e-9)
    assert first.node == int(np.argmin(closing)) and first.set == "nu"
    (sol,) = path.solutions_at(0.5 * first.alpha)
    u = sol.u.reshape(-1, 2)  # free DOFs in (node, component) order: the contact nodes' are free
    assert np.allclose(u, 0.5 * first.alpha * U, rtol=1e-9, atol=1e-15) and not sol.lam_n.any()
    worst = max(cfcontact.verify(system, y, a).worst() for a, y in path.iter_points())
    assert worst < 1e-10
    with pytest.raises(GeometryError, match="inside = true"):
        _hub_in_bore(c, U, nodes=12, inside=False)
    with pytest.raises(InputError, match="'inside' must be true or false"):
        pairing.make_obstacle({"kind": "circle", "center": (0, 0), "radius": 1.0, "inside": "yes"})


def test_a_bore_without_clearance_pressed_from_zero_load_is_one_ray():
    """No clearance (the hub meshed on the bore's circle: gaps within rounding are exactly 0) and the
    hub moved from zero: the data vanish at alpha = 0, every multiplier and indicator too.  At F = 30
    the lexicographic rule cannot leave that point (it returned to a branch it had crossed: "stuck"
    with no solution beyond alpha = 0); the path leaves it on the ray of a solution at alpha = 1
    ("apex" start), and the problem being positively homogeneous, that ray is the whole path."""
    U = np.array([-2.8e-3, 3.9e-4])
    system = _hub_in_bore(0.0, U, nodes=40, friction=30.0)
    assert not system.gap.any()  # (gmsh: radii of 1 +- 1e-16, snapped)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert path.status == "completed" and path.stats["start"] == "apex" and not path.transitions
    assert [e.kind for e in path.events] == ["apex_start"]
    (half,), (full,) = path.solutions_at(0.5), path.solutions_at(1.0)
    assert np.allclose(half.y, 0.5 * full.y, rtol=1e-12, atol=1e-12 * np.abs(full.y).max())
    assert full.lam_n.max() > 0 and (full.lam_n > 0).sum() < system.m  # pressed on one side only
    assert max(cfcontact.verify(system, y, a).worst() for a, y in path.iter_points()) < 1e-12
    seed = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
    assert seed.status == "completed" and not seed.transitions
    # the seed method there: SSNM from y = 0 cycles at every step size of its degenerate start (39
    # nodes, nu = 0.45), so the start's sets came from nowhere and the path cycled in folds at
    # alpha = 0; the sets of a solution reached otherwise (SSNM's restarts, the exact method's
    # homotopies) give the ray
    system = _hub_in_bore(0.0, np.array([4.35e-4, 7.86e-4]), nodes=39, friction=1.0, nu=0.45)
    seed = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
    assert seed.status == "completed" and not seed.transitions and not seed.events
    (half,), (full,) = seed.solutions_at(0.5), seed.solutions_at(1.0)
    assert np.allclose(half.y, 0.5 * full.y, rtol=1e-10, atol=1e-10 * np.abs(full.y).max())
    assert full.lam_n.max() > 0 and cfcontact.verify(system, full.y, 1.0).worst() < 1e-12


def test_a_press_fit_in_a_bore_is_an_interference_not_a_misplaced_obstacle():
    """A hub of radius 1 in a bore of radius 0.999: every node starts 1e-3 inside the solid (a press
    fit), which is accepted (an obstacle every node penetrates by more than 1 % of the contact's
    extent is refused as misplaced); both methods trace the same set changes."""
    system = _hub_in_bore(-1e-3, np.array([1e-3, -3e-3]), nodes=40)
    assert np.allclose(system.gap, -1e-3, rtol=1e-9)
    exact = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    seed = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
    assert exact.status == seed.status == "completed" and len(exact.transitions) > 5
    assert [(t.node, t.set, t.kind) for t in exact.transitions] == [(t.node, t.set, t.kind) for t in seed.transitions]
    assert max(cfcontact.verify(system, y, a).worst() for a, y in exact.iter_points()) < 1e-10
    with pytest.raises(GeometryError, match="does not face contact1"):
        _hub_in_bore(-0.05, np.array([1e-3, -3e-3]), nodes=12)


def test_obstacle_needs_a_single_body():
    with pytest.raises(GeometryError, match="single body"):
        cfcontact.two_blocks(nx=3, ny=1, obstacle={"kind": "line", "point": (0, -1), "normal": (0, 1)})
    with pytest.raises(InputError, match="pairing='segment'"):
        _block_on({"kind": "line", "point": (0, -0.01), "normal": (0, 1)}, pairing="node")


# ------------------------------------------------------------ pure pairing
def _arc_over_line(ns, nm, half_angle=0.9):
    """Slave: an arc of radius 1 (centre (0, 1)) with ns facets; master: y = 0, x in [-1.2, 1.2], nm facets."""
    xm = np.linspace(-1.2, 1.2, nm + 1)
    phi = np.linspace(-half_angle, half_angle, ns + 1)
    pts = np.vstack([np.column_stack([xm, np.zeros_like(xm)]), np.column_stack([np.sin(phi), 1 - np.cos(phi)])])
    mf = np.column_stack([np.arange(nm), np.arange(1, nm + 1)])
    mc = np.column_stack([0.5 * (xm[:-1] + xm[1:]), np.full(nm, -0.1)])
    sf = nm + 1 + np.column_stack([np.arange(ns), np.arange(1, ns + 1)])
    pm = 0.5 * (phi[:-1] + phi[1:])
    sc = np.column_stack([np.sin(pm), 1.1 - np.cos(pm)])
    return pts, sf, sc, mf, mc


def test_pairing_gap_of_a_circle_over_a_line_and_its_speed():
    """10^4 slave nodes on an arc of radius 1 over a line of 1.2 10^4 facets: the gap along each
    radial normal is (1 - cos phi) / cos phi (to rounding), rays beyond the line's end are left
    out, and the whole pairing takes well under a second."""
    pts, sf, sc, mf, mc = _arc_over_line(10_000, 12_000)
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        pr = pairing.node_to_segment(pts, sf, sc, mf, mc, slave_body=1)
        best = min(best, time.perf_counter() - t0)
    assert best < 1.0, f"pairing of 10^4 slave nodes took {best:.2f} s"
    phi = np.arcsin(pts[pr.slave, 0])
    assert np.abs(pr.gap - (1 - np.cos(phi)) / np.cos(phi)).max() < 1e-12
    assert pr.m + pr.excluded.size == 10_001
    assert np.all(np.abs(np.tan(np.arcsin(pts[pr.excluded, 0]))) > 1.2 - 1e-9)  # their rays miss the line
    assert np.allclose(pr.weights.sum(axis=1), 1.0) and np.all(pr.weights >= 0)
    assert np.allclose(pr.projections[:, 1], 0.0, atol=1e-14)


def test_pairing_slave_body_two_flips_the_normal_and_signs():
    pts, sf, sc, mf, mc = _arc_over_line(40, 30)
    p1 = pairing.node_to_segment(pts, sf, sc, mf, mc, slave_body=1)
    p2 = pairing.node_to_segment(pts, sf, sc, mf, mc, slave_body=2)
    assert np.array_equal(p1.normals, -p2.normals) and np.array_equal(p1.gap, p2.gap)
    r1, n1, f1 = p1.entries()
    r2, n2, f2 = p2.entries()
    assert np.array_equal(n1, n2) and np.array_equal(f1, -f2)
    assert np.array_equal(p1.body_nodes()[:, 0], p2.body_nodes()[:, 1])


# ------------------------------------------------------------ rollers and symmetry planes
def test_roller_normals_turn_along_the_free_component():
    """A node with one prescribed component moves along the other: its normal is turned along it
    (keeping its side) when it is nearer to it; clamped, free, and nearly tangential nodes keep
    theirs."""
    c, s = np.cos(0.05), np.sin(0.05)
    normals = np.array([[s, -c], [c, s], [s, -c], [s, -c], [c, s], [-s, c]])
    fixed = np.array([[True, False], [False, True], [True, True], [False, False], [True, False], [True, False]])
    turned = pairing.roller_normals(normals, fixed)
    assert turned.tolist() == [[0.0, -1.0], [1.0, 0.0], [s, -c], [s, -c], [c, s], [0.0, 1.0]]
    assert normals[0].tolist() == [s, -c]  # (a copy)


def _quarter_hub(nodes, delta, friction):
    """The press fit of demos/lame.py on a quarter of the hub: the annulus 0.3 < r < 1 in x, y >= 0
    with ``nodes`` + 1 nodes on its outer arc (contact1), its inner arc clamped, the symmetry
    planes x = 0 and y = 0 rollers, in a rigid bore of radius 1 - delta."""
    from cfcontact import compat

    with compat.gmsh_model("quarter_hub") as model:
        occ = model.occ
        pa1, pb1 = occ.addPoint(lame.INNER, 0, 0), occ.addPoint(lame.OUTER, 0, 0)
        pa2, pb2 = occ.addPoint(0, lame.INNER, 0), occ.addPoint(0, lame.OUTER, 0)
        centre = occ.addPoint(0, 0, 0)
        edges = [occ.addLine(pa1, pb1), occ.addCircleArc(pb1, centre, pb2), occ.addLine(pb2, pa2),
                 occ.addCircleArc(pa2, centre, pa1)]
        surface = occ.addPlaneSurface([occ.addCurveLoop(edges)])
        occ.synchronize()
        for dim, tags, num, name in ((2, [surface], 1, "body1"), (1, [edges[1]], 10, "contact1"),
                                     (1, [edges[3]], 14, "inner1"), (1, [edges[0]], 15, "symy1"),
                                     (1, [edges[2]], 16, "symx1")):
            model.addPhysicalGroup(dim, tags, num)
            model.setPhysicalName(dim, num, name)
        model.mesh.setTransfiniteCurve(edges[1], nodes + 1)
        import gmsh

        gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5 * np.pi * lame.OUTER / nodes)
        model.mesh.generate(2)
        return cfcontact.assemble_contact_system(
            model, E=lame.E, nu=lame.NU, clamp=("inner1",), friction=friction,
            dirichlet={"symx1": {"x": 0.0}, "symy1": {"y": 0.0}},
            obstacle={"kind": "circle", "center": (0.0, 0.0), "radius": lame.OUTER - delta, "inside": True})


@pytest.mark.parametrize("friction", [0.0, 0.3])
def test_a_quarter_hub_on_two_symmetry_planes_is_the_press_fit(friction):
    """The end nodes of the quarter's contact arc lie on the symmetry planes, each with one free
    component: their normals are radial (not the one facet's, tilted by half its turn), their gap
    the interference, and they have no tangential unknown (before, their normal and tangential
    rows read the same component: J(Z) singular, the condensed backend stopped).  The pressure
    is Lame's at every node, the end nodes included (they were 2.5 % off at F = 0.3)."""
    delta = 1e-4
    system = _quarter_hub(16, delta, friction)
    x = system.geometry.contact_points[:, :2]
    ends = np.flatnonzero(np.isclose(x[:, 0], 0.0, atol=1e-12) | np.isclose(x[:, 1], 0.0, atol=1e-12))
    assert system.m == 17 and ends.size == 2 and system.no_tangent[ends].all() and not system.no_tangent.sum() > 2
    assert np.allclose(system.geometry.normals[:, :2], x / np.hypot(*x.T)[:, None], atol=1e-12)
    assert np.allclose(system.gap, -delta, rtol=1e-12)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert path.status == "completed" and max(cfcontact.verify(system, y, a).worst() for a, y in path.iter_points()) < 1e-12
    (sol,) = path.solutions_at(1.0)
    pressure = sol.lam_n / system.geometry.tributary
    assert np.abs(pressure / lame.lame_pressure(delta) - 1.0).max() < 6e-3
    assert not sol.lam_t[ends].any()


def test_a_rotated_non_matching_interface_has_no_rounding_gaps():
    """Slave nodes on the master's facets to rounding (a non-matching interface turned by 30 deg:
    the rays' distances were +-1e-16) have the gap 0, as on the unturned interface."""
    for angle in (0.0, 30.0):
        system = cfcontact.two_blocks(nx=12, ny=2, nx2=17, ny2=2, angle=angle, cell="triangle", pairing="segment")
        assert system.m == 12 and not system.has_gap and not system.gap.any(), angle


def test_a_roller_node_on_a_rigid_disc_keeps_its_free_direction():
    """A block on a rigid disc whose centre is not under the block's left edge, that edge on a
    roller (u_x = 0): the corner node can only move vertically, so its row is along y and its gap
    the vertical distance to the circle, R + d - sqrt(R^2 - xc^2), not the distance to the nearest
    point (tilted); it has no tangential unknown.  Every other node: the distance to the circle
    along the circle's radius."""
    R, d, xc = 5.0, 0.01, 1.3
    system = cfcontact.two_blocks(nx=10, ny=2, length=2.0, height=0.5, foundation=True, clamp=(),
                                  obstacle={"kind": "circle", "center": (xc, -R - d), "radius": R},
                                  dirichlet={"top1": {"x": 0.0, "y": (0.0, -0.02)}, "left1": {"x": 0.0}},
                                  tractions1={}, tractions2={})
    x = system.geometry.contact_points[:, :2]
    corner = np.flatnonzero(np.isclose(x[:, 0], 0.0, atol=1e-12))
    assert corner.size == 1 and system.no_tangent[corner].all() and system.no_tangent.sum() == 1
    assert np.allclose(system.geometry.normals[corner, :2], [[0.0, -1.0]], atol=1e-14)
    assert system.gap[corner][0] == pytest.approx(R + d - np.sqrt(R ** 2 - xc ** 2), rel=1e-12)
    rest = np.setdiff1d(np.arange(system.m), corner)
    radial = x[rest] - (xc, -R - d)
    assert np.allclose(system.gap[rest], np.hypot(*radial.T) - R, rtol=1e-12)
    assert np.allclose(system.geometry.normals[rest, :2], -radial / np.hypot(*radial.T)[:, None], atol=1e-12)


def test_a_roller_node_of_a_turned_block_on_a_sloped_line():
    """A block turned by 10 degrees on a rigid line of slope 0.05, its left edge on a roller
    (u_x = 0): the corner node's own normal is tilted by 10 degrees and the line's by 3, but the
    node can only move vertically, so its row is along y and its gap the vertical distance to the
    line (0.1), not the distance along either normal (0.1007 along its own).  The other nodes: the
    signed distance to the line, along the line's normal."""
    slope, y0 = 0.05, -0.1
    nv = np.array([-slope, 1.0]) / np.hypot(slope, 1.0)
    system = cfcontact.two_blocks(nx=8, ny=2, length=2.0, height=0.5, foundation=True, clamp=(), angle=10.0,
                                  obstacle={"kind": "line", "point": (0.0, y0), "normal": tuple(nv)},
                                  dirichlet={"top1": {"x": 0.0, "y": (0.0, -0.02)}, "left1": {"x": 0.0}},
                                  tractions1={}, tractions2={})
    x = system.geometry.contact_points[:, :2]
    corner = np.flatnonzero(np.hypot(*x.T) <= 1e-12)
    assert corner.size == 1 and system.no_tangent[corner].all() and system.no_tangent.sum() == 1
    assert np.allclose(system.geometry.normals[corner, :2], [[0.0, -1.0]], atol=1e-14)
    assert system.gap[corner][0] == pytest.approx(-y0, rel=1e-12)
    rest = np.setdiff1d(np.arange(system.m), corner)
    np.testing.assert_allclose(system.gap[rest], (x[rest] - (0.0, y0)) @ nv, rtol=1e-12)
    np.testing.assert_allclose(system.geometry.normals[rest, :2], np.tile(-nv, (rest.size, 1)), atol=1e-14)
