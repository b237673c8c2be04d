"""Geometry variants with real contact geometry (issue #12, item 3): a cylinder on a block and a
rounded punch (gmsh, meshed independently, refined toward the contact zone), paired node to
segment with their initial gaps; a user's non-matching .msh; mirror-symmetric meshes and half
models."""

import os
import subprocess
import sys
import warnings

import numpy as np
import pytest

import cfcontact
from cfcontact.assembly import assemble_contact_system
from cfcontact.errors import GeometryError, InputError
import importlib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CYL = dict(radius=1.0, width=3.0, depth=1.5, zone=0.3, size=0.04, size_far=0.4, E=1.0, nu=0.3)
PUNCH = dict(half_width=0.5, edge_radius=0.1, width=3.0, depth=1.5, size=0.025, size_far=0.4, E=1.0, nu=0.3)


@pytest.fixture(scope="module", params=["triangle", "quadrilateral"])
def cylinder(request):
    """The cylinder model meshed with triangles, and with quadrilaterals (each triangle of a mesh
    of twice the size split into three: common.subdivide_to_quads)."""
    return cfcontact.cylinder_on_block(**CYL, cell=request.param, indentation=(0.0, 0.03))


def _cell(system):
    return system.info["model_parameters"]["cell"]


def _mirror_index(points):
    """Index of the mirror image (-x, y) of every point (KeyError if some has none)."""
    key = lambda p: tuple(np.round(p * 1e9).astype(np.int64))  # noqa: E731
    index = {}
    for i, p in enumerate(points):
        index.setdefault(key(p), []).append(i)
    return index, key


def test_cylinder_gap_is_the_circle_seen_from_the_block(cylinder):
    """Slave = the block's top (vertical normals): g = R - sqrt(R^2 - x^2) up to the sagitta of the
    cylinder's chords (h^2 / (8 R)); about x^2 / (2 R) near the axis.  Every block node is paired."""
    s = cylinder
    x = s.geometry.contact_points[:, 0]
    exact = 1.0 - np.sqrt(1.0 - x ** 2)
    h = 1.25 * CYL["zone"] * 1.0 / np.ceil(np.arcsin(1.25 * CYL["zone"]) / CYL["size"])  # chord length bound
    assert np.all(s.gap >= exact - 1e-14) and np.all(s.gap - exact <= h ** 2 / 8 + 1e-14)
    small = np.abs(x) < 0.1
    assert np.allclose(s.gap[small], x[small] ** 2 / 2, atol=h ** 2 / 8 + 1e-5)
    assert s.info["contact"]["excluded"] == 0 and s.info["contact"]["slave"] == "contact2=20"
    assert np.allclose(np.abs(s.geometry.normals), [0.0, 1.0])
    assert s.geometry.tributary.sum() == pytest.approx(2 * CYL["zone"])
    assert np.all(np.diff(x) > 0)  # ordered along the interface


def test_cylinder_mesh_is_mirror_symmetric(cylinder):
    geo = cylinder.geometry
    assert geo.cells.shape[1] == {"triangle": 3, "quadrilateral": 4}[_cell(cylinder)]
    index, key = _mirror_index(geo.points)
    mirrored = {key(p * [-1, 1]) for p in geo.points}
    assert mirrored == set(index)
    cells = {tuple(sorted(key(geo.points[i]) for i in c)) for c in geo.cells}
    assert {tuple(sorted(key(geo.points[i] * [-1, 1]) for i in c)) for c in geo.cells} == cells
    exact = {(float(p[0]), float(p[1])) for p in geo.points}  # every node's mirror image, to the bit
    assert all((-float(p[0]), float(p[1])) in exact for p in geo.points)
    # gaps mirror too, to a few units of rounding: the pairing's arithmetic follows each facet's
    # orientation, which dolfinx takes from its own vertex numbering (not mirror-symmetric with
    # the quadrilaterals under dolfinx 0.9: 7e-18 apart there)
    x = geo.contact_points[:, 0]
    assert np.all(np.abs(cylinder.gap - cylinder.gap[::-1]) <= 4 * np.spacing(cylinder.gap.max()))
    assert np.allclose(x, -x[::-1], atol=0)


@pytest.mark.parametrize("friction", [0.0, 0.4])
def test_cylinder_half_model_gives_the_full_solution(cylinder, friction):
    """The half model (sym1, sym2: u_x = 0) has exactly the right half of the full mesh and gives
    the full model's displacements there; contact forces too (the centre node carries half)."""
    full = cylinder.with_friction(friction)
    half = cfcontact.cylinder_on_block(**CYL, indentation=(0.0, 0.03), half=True, friction=friction,
                                       cell=_cell(cylinder))
    assert half.info["dirichlet"]["sym1=15"] == {"x": [0.0, 0.0]} and half.no_tangent.tolist() == [True] + [False] * (
        half.m - 1)
    sols = []
    for s in (full, half):
        start = cfcontact.ssnm(s.with_rho(0.1 * s.rho), 1.0)  # (the default rho cycles with friction here)
        sol = cfcontact.ssnm(s, 1.0, y0=start)
        assert cfcontact.verify(s, sol, 1.0).ok(1e-9)
        sols.append(sol)
    sf, sh = sols
    assert np.count_nonzero(sf.lam_n) >= 7
    Uf = full.geometry.displacement_field(sf.u, 1.0)
    Uh = half.geometry.displacement_field(sh.u, 1.0)
    key = lambda p: tuple(np.round(p * 1e9).astype(np.int64))  # noqa: E731
    body = np.zeros(len(full.geometry.points), dtype=int)
    body[full.geometry.cells.ravel()] = np.repeat(full.geometry.cell_body, full.geometry.cells.shape[1])
    bodyh = np.zeros(len(half.geometry.points), dtype=int)
    bodyh[half.geometry.cells.ravel()] = np.repeat(half.geometry.cell_body, half.geometry.cells.shape[1])
    index = {(key(p), b): i for i, (p, b) in enumerate(zip(full.geometry.points, body))}
    match = np.array([index[(key(p), b)] for p, b in zip(half.geometry.points, bodyh)])
    assert np.abs(Uh - Uf[match]).max() <= 1e-8 * np.abs(Uf).max()
    xf, xh = full.geometry.contact_points[:, 0], half.geometry.contact_points[:, 0]
    jf = np.searchsorted(xf, xh)
    assert np.allclose(xf[jf], xh, atol=1e-12)
    w = np.where(xh == 0.0, 0.5, 1.0)
    assert np.abs(sh.lam_n - w * sf.lam_n[jf]).max() <= 1e-7 * sf.lam_n.max()


@pytest.mark.parametrize("build, kw", [(cfcontact.cylinder_on_block, CYL), (cfcontact.rounded_punch, PUNCH)],
                         ids=["cylinder", "punch"])
@pytest.mark.parametrize("half", [False, True], ids=["full", "half"])
def test_quadrilateral_meshes_of_the_pressed_models(build, kw, half):
    """cell="quadrilateral" on the unstructured pressed models (gmsh's recombination left
    triangles there): quadrilaterals only, every one convex and counter-clockwise (corners'
    cross products > 0), angles within (15, 165) degrees; the contact boundaries have about the
    elements of ``size`` (the contact nodes of the triangle mesh, within 25 %); the curved
    boundary's nodes lie on the circle."""
    quad = build(**kw, cell="quadrilateral", half=half, indentation=(0.0, 0.002))
    tri = build(**kw, cell="triangle", half=half, indentation=(0.0, 0.002))
    geo = quad.geometry
    assert geo.cells.shape[1] == 4
    P = geo.points[geo.cells]  # cells x 4 corners x 2
    e_in, e_out = P - np.roll(P, 1, axis=1), np.roll(P, -1, axis=1) - P
    cross = e_in[..., 0] * e_out[..., 1] - e_in[..., 1] * e_out[..., 0]
    cos = -(e_in * e_out).sum(-1) / (np.linalg.norm(e_in, axis=-1) * np.linalg.norm(e_out, axis=-1))
    angles = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    assert np.all(cross > 0) and 15 < angles.min() and angles.max() < 165
    assert abs(quad.m - tri.m) <= 0.25 * tri.m
    if build is cfcontact.cylinder_on_block:  # body 1's contact nodes (the block's top is the slave)
        on_arc = np.abs(np.hypot(geo.points[:, 0], geo.points[:, 1] - 1.0) - 1.0) < 1e-14
        below = geo.points[:, 1] < 0.5
        assert np.count_nonzero(on_arc & below) >= quad.m - 2


def test_rounded_punch_gap_and_pressure_peaks_under_the_edges():
    s = cfcontact.rounded_punch(**PUNCH, indentation=(0.0, 0.002))
    x = s.geometry.contact_points[:, 0]
    w, r = PUNCH["half_width"], PUNCH["edge_radius"]
    flat = np.abs(x) <= w - r
    assert np.all(s.gap[flat] == 0.0)
    d = np.abs(x[~flat]) - (w - r)
    exact = r - np.sqrt(r ** 2 - d ** 2)
    chord = 0.5 * np.pi * r / np.ceil(0.5 * np.pi * r / PUNCH["size"])
    sag = chord ** 2 / (8 * r) / np.sqrt(1 - (d / r) ** 2)  # the chords' sagitta, seen vertically
    assert np.all(s.gap[~flat] >= exact - 1e-14) and np.all(s.gap[~flat] - exact <= sag)
    sol = cfcontact.ssnm(s, 1.0)
    p = sol.lam_n / s.geometry.tributary
    assert set(np.array(sol.states())[flat]) <= {"stick", "slip+", "slip-"}  # the flat part is in contact
    assert np.abs(x[np.argmax(p)]) > w - r - 2 * PUNCH["size"]  # peak near where the rounding starts
    assert p[np.argmin(np.abs(x))] < 0.5 * p.max()


def test_a_flat_punch_landing_with_zero_force_verifies():
    """A punch lowered onto the block with a gap under its flat part: every slave node lands at one
    alpha with zero force, where every multiplier and every gap left N u - g vanish.  Its gaps are
    differences of N u and g (1e-3 each), so rounding them leaves 1e-19; measured against those
    alone (the scale before) the landing point verified to 0.4, now against rho |N u|, rho |g|."""
    system = cfcontact.rounded_punch(half_width=0.5, edge_radius=0.2, zone=0.25, size=0.05, size_far=0.5,
                                     gap0=1e-3, half=True, indentation=(0.0, 0.005), friction=0.6)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    (tr,) = path.transitions
    assert tr.alpha == pytest.approx(0.2, rel=1e-12) and len(tr.changes) == system.m
    landing = [(a, y) for a, y in path.iter_points() if a == tr.alpha]
    assert len(landing) == 2
    for a, y in landing:
        assert np.abs(y[system.n:]).max() <= 1e-12 * np.abs(path.lams).max()  # zero force
        assert cfcontact.verify(system, y, a).worst() < 1e-13
    assert max(cfcontact.verify(system, y, a).worst() for a, y in path.iter_points()) < 1e-13


@pytest.mark.slow  # (a subprocess)
@pytest.mark.parametrize("script,kwargs", [("cylinder_on_block", CYL), ("rounded_punch", PUNCH)])
def test_script_writes_a_non_matching_msh_that_assembles_alike(tmp_path, script, kwargs):
    """A user's .msh whose contact boundaries do not match: refused by node pairing (with the hint),
    accepted by node-to-segment pairing, and equal to the model builder's system."""
    geo_keys = {k: v for k, v in kwargs.items() if k not in ("E", "nu")}
    msh = str(tmp_path / f"{script}.msh")
    args = [a for k, v in geo_keys.items() for a in ("--" + k.replace("_", "-"), str(v))]
    subprocess.run([sys.executable, "-m", f"cfcontact.meshes.{script}", msh, *args], check=True, capture_output=True,
                   env=dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")))
    load = dict(clamp=("bottom2",), dirichlet={"top1": {"x": 0.0, "y": (0.0, -0.03)}}, E=1.0, nu=0.3)
    with pytest.raises(GeometryError, match="non-matching contact interface.*pairing='segment'"):
        assemble_contact_system(msh, **load)
    from_file = assemble_contact_system(msh, pairing="segment", slave="contact2", **load)
    builder = getattr(cfcontact, script)(**kwargs, indentation=(0.0, 0.03))
    a, b = from_file.to_scipy(), builder.to_scipy()
    for x, y in zip(a, b):
        x, y = (x.toarray(), y.toarray()) if hasattr(x, "toarray") else (x, y)
        assert x.shape == y.shape and np.abs(x - y).max(initial=0) <= 1e-12 * max(np.abs(y).max(initial=0), 1e-300)
    assert np.allclose(from_file.gap, builder.gap, rtol=0, atol=1e-14)  # (coordinates through text)


@pytest.mark.parametrize("script,kwargs,error,words", [
    ("cylinder_on_block", dict(zone=0.9), GeometryError, "zone must be below"),
    ("cylinder_on_block", dict(size=0.2), GeometryError, "size must be at most zone / 2"),
    ("cylinder_on_block", dict(radius=0), InputError, "radius must be a positive number"),
    ("cylinder_on_block", dict(gap0=-0.1), InputError, "gap0 must be a positive number"),
    ("rounded_punch", dict(edge_radius=0.6), GeometryError, "edge_radius must be below half_width"),
    ("rounded_punch", dict(zone=0.6), GeometryError, "zone must be below half_width"),
    ("rounded_punch", dict(half_width=3.0), GeometryError, "narrower than the block"),
    ("rounded_punch", dict(cell="hexagon"), InputError, "cell must be one of"),
])
def test_geometry_parameters_validated(script, kwargs, error, words):
    with pytest.raises(error, match=words):
        importlib.import_module(f"cfcontact.meshes.{script}").check_parameters(**kwargs)
    with pytest.raises(error, match=words):  # the builder validates before meshing
        getattr(cfcontact, script)(**kwargs)


def test_half_model_refuses_a_tangential_shift():
    with pytest.raises(InputError, match="half model cannot take a tangential shift"):
        cfcontact.cylinder_on_block(**CYL, half=True, shift=(0.0, 1e-3))
    with pytest.raises(InputError, match="indentation must be a number or a pair"):
        cfcontact.cylinder_on_block(**CYL, indentation="deep")


def test_saved_path_keeps_the_new_geometry_data(tmp_path, cylinder):
    """ContactGeometry's tributary lengths, prescribed displacements and obstacle go through
    SolutionPath.save/load (optional entries: paths saved before them still load)."""
    from cfcontact.solution_path import SolutionPath

    path = cfcontact.trace_path(cylinder.with_friction(0.3), 0.0, 1.0, method="exact")
    path.save(tmp_path / "p")
    geo = SolutionPath.load(tmp_path / "p").geometry
    assert np.array_equal(geo.tributary, cylinder.geometry.tributary)
    assert np.array_equal(geo.prescribed, cylinder.geometry.prescribed) and geo.obstacle is None
    U = geo.displacement_field(path.ys[-1][:cylinder.n], 1.0)
    moved = np.unique(geo.prescribed[geo.prescribed[:, 1] == 1, 0].astype(int))  # the top's nodes, u_y given
    assert moved.size and np.allclose(geo.points[moved, 1], 1.0) and np.allclose(U[moved, 1], -0.03)
    old = {k: v for k, v in geo.to_dict().items() if k not in ("tributary", "prescribed")}
    assert cfcontact.ContactGeometry.from_dict(old).tributary is None


def test_exact_indentation_path_resolves_the_symmetric_degenerate_transitions(cylinder):
    """Indentation from 0 on the mirror-symmetric mesh: the nodes at +-x close (and stick) at the
    same alpha -- degenerate transitions, which the exact method takes as one transition with two
    changes, without events; the half model (full backend) has the same transitions."""
    path = cfcontact.trace_path(cylinder.with_friction(0.3), 0.0, 1.0, method="exact")
    assert path.status == "completed" and not path.events and len(path.transitions) >= 4
    x = cylinder.geometry.contact_points[:, 0]
    for t in path.transitions:
        (a, b) = [c["node"] for c in t.changes]
        assert x[a] == -x[b]
    half = cfcontact.cylinder_on_block(**CYL, indentation=(0.0, 0.03), half=True, friction=0.3, cell=_cell(cylinder))
    hp = cfcontact.trace_path(half, 0.0, 1.0, method="exact", backend="full")
    assert np.allclose([t.alpha for t in hp.transitions], [t.alpha for t in path.transitions], atol=1e-9)


def test_seed_indentation_path_from_zero_load(cylinder):
    """At alpha = 0 the load is zero and y = 0: the centre node's gap is zero, and every
    tangential indicator vanishes, so Z(0) (open nodes "sticking", the centre closed) is the set
    of no branch.  The seed takes the sets of the branch towards alpha = 1 (start.oriented_start)
    and follows the exact method's transitions (within its step h_min), forwards and backwards
    (where the path ends on that tie)."""
    from cfcontact.start import indicator_ties, oriented_start

    system = cylinder.with_friction(0.3)
    exact = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    ref = [t.alpha for t in exact.transitions]
    path = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
    assert path.status == "completed" and not path.events
    assert np.allclose([t.alpha for t in path.transitions], ref, atol=2e-5)
    start = path.branches[0].sets
    assert start.states()[system.m // 2] == "stick" and start.nu.sum() == system.m - 1
    back = cfcontact.trace_path(system, 1.0, 0.0, method="seed")
    assert back.status == "completed" and not back.events and back.alphas[-1] == 0.0
    assert np.allclose([t.alpha for t in back.transitions], ref[::-1], atol=2e-5)
    # the ties at the start: every tangential indicator (but the centre's) and the centre's normal one
    solver = cfcontact.get_solver(system)
    y0 = np.zeros(system.n + 2 * system.m)
    a_tie, tp_tie, tm_tie = indicator_ties(system, y0)
    assert a_tie.tolist() == (system.gap == 0).tolist() and tp_tie.all() and tm_tie.all()
    from cfcontact.options import AlphaSpan, PathOptions
    from cfcontact.ssnm import Solution

    opts = PathOptions()
    s0 = Solution.from_y(system, y0, 0.0)
    assert oriented_start(system, s0, AlphaSpan.of(0.0, 1.0, opts), opts, solver).sets.equivalent(start,
                                                                                                   system.friction)


def test_seed_half_model_and_initial_gap_from_zero_load():
    """The half model (its centre node has no tangential unknown: no tangential toggles) and a
    cylinder starting above the block (gap0 > 0: a rigid approach, T u = 0 until the first
    contact, which then sticks) give the exact method's transitions."""
    half = cfcontact.cylinder_on_block(**CYL, indentation=(0.0, 0.03), half=True, friction=0.3)
    assert half.no_tangent[0]
    for system in (half, cfcontact.cylinder_on_block(**CYL, gap0=0.005, indentation=(0.0, 0.03), friction=0.3)):
        ref = [t.alpha for t in cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend="full").transitions]
        path = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
        assert path.status == "completed" and not path.events
        assert np.allclose([t.alpha for t in path.transitions], ref, atol=2e-5)
        if system is half:  # the centre node only opens and closes
            assert not [c for t in path.transitions for c in t.changes if c["node"] == 0 and c["set"] != "nu"]


def test_half_model_exact_path_condensed_equals_full():
    """A node without tangential unknown (the half model's centre node, on the symmetry plane) is
    open or closed with lam_t = 0 in the exact method; the condensed backend (with and without
    factorization updates) gives the full backend's path."""
    from cfcontact.condensed import CondensedSolver
    from cfcontact.ssnm import SolverOptions

    half = cfcontact.cylinder_on_block(**CYL, indentation=(0.005, 0.03), half=True, friction=0.5)
    assert half.no_tangent[0]
    ref = cfcontact.trace_path(half, 0.0, 1.0, method="exact", backend="full")
    assert ref.status == "completed" and ref.transitions
    for updates in (False, True):
        p = cfcontact.trace_path(half, 0.0, 1.0, method="exact",
                                 solver=CondensedSolver(half, SolverOptions(updates=updates)))
        assert p.status == "completed"
        assert [(t.node, t.set, t.kind) for t in p.transitions] == [(t.node, t.set, t.kind) for t in ref.transitions]
        assert np.allclose([t.alpha for t in p.transitions], [t.alpha for t in ref.transitions], atol=1e-9)
        for t in p.transitions:
            assert cfcontact.verify(half, p.branch_y(t.to_branch, t.alpha), t.alpha).ok(1e-9)


def test_flat_punch_lifting_off_is_one_point_not_a_cascade():
    """A half flat punch (initial gap 1e-4) pressed 2e-3 and released, F = 3: at alpha = 0.05 every
    contact force vanishes at once.  Its roots scatter by the rounding of the load (1 - alpha) f1 +
    alpha f2, a few units in the last place of 1, not of alpha: counted in ulps of 0.05 they were
    23 separate transitions within 6e-15 (900 of them).  In ulps of alpha's scale they are a few
    degenerate points (how many, and whether one is a branch point, depends on the rounding: BLAS
    threads), resolved by the lexicographic rule; the path and its solutions are the same."""
    from cfcontact.ssnm import verify

    system = cfcontact.rounded_punch(size=0.03, size_far=0.5, half=True, gap0=1e-4, friction=3.0, nu=0.45,
                                     E={"body1": 7e10, "body2": 7e8})
    path = cfcontact.trace_path(system, 1.0, 0.0, method="exact")
    assert path.status == "completed" and {e.kind for e in path.events} <= {"branch_point"}
    lift = [t for t in path.transitions if abs(t.alpha - 0.05) < 1e-12]
    assert lift == path.transitions and 1 <= len(lift) <= 8 and path.stats["degenerate_points"] >= 1
    closed = int((~path.branches[0].sets.nu).sum())
    assert closed >= 10 and path.branches[-1].sets.nu.all()  # every closed node opens there
    assert path.max_multiplicity()[0] == 1
    assert max(verify(system, y, a).worst() for a, y in path.iter_points()) < 1e-12
