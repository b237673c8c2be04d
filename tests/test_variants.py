"""Geometry variants: the arc-in-a-seat model (curved interface), the folds example case and the
pictures of the documentation (demos/pictures.py)."""

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
from matplotlib.image import imread

import cfcontact
from cfcontact import case as case_file
from cfcontact import cli
from cfcontact.errors import GeometryError, InputError
from cfcontact.path import SolutionPath
from cfcontact.condensed import CondensedSolver
from cfcontact.ssnm import DirNeuSolver, SolverOptions
from reference import frictionless_dual

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CASES = os.path.join(ROOT, "demos", "cases")
#: the geometry page's pictures (demos/pictures.py: one per example case)
VARIANTS = ("two_blocks", "foundation", "arc", "inclined", "user_msh", "cylinder", "punch", "nonmatching", "obstacle",
            "half_cylinder")


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _assert_picture(fn, size=None):
    """A PNG of the given (width, height) that is not blank (as in test_cli)."""
    assert os.path.isfile(fn), fn
    with open(fn, "rb") as fh:
        assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    img = imread(fn)
    if img.dtype != np.uint8:
        img = (img[..., :3] * 255).round()
    img = np.asarray(img[..., :3], dtype=int)
    if size is not None:
        assert (img.shape[1], img.shape[0]) == tuple(size)
    flat = img.reshape(-1, 3)
    assert flat.std() > 5, f"{fn} is blank"
    assert len(np.unique(flat, axis=0)) >= 20


def _copy_case(tmp_path, name):
    shutil.copy(os.path.join(CASES, name), tmp_path / name)
    return str(tmp_path / name)


# ------------------------------------------------------------------ arc on block: geometry
@pytest.mark.parametrize("kwargs,words,error", [
    (dict(half_angle=0.0), ["half_angle", "(0, 80]", "0.0"], GeometryError),
    (dict(half_angle=95), ["half_angle", "(0, 80]", "95"], GeometryError),
    (dict(half_angle="wide"), ["half_angle", "number", "'wide'"], InputError),
    (dict(radius=-1.0), ["radius", "positive", "-1.0"], InputError),
    (dict(height2=0), ["height2", "positive"], InputError),
    (dict(nx=1), ["nx", ">= 2", "1"], InputError),
    (dict(ny=2.5), ["ny", "integer", "2.5"], InputError),
    (dict(cell="hexagon"), ["cell", "quadrilateral", "hexagon"], InputError),
])
def test_arc_parameters_validated(kwargs, words, error):
    from cfcontact.meshes import arc_on_block as geo
    with pytest.raises(error) as info:
        geo.check_parameters(**kwargs)
    for w in words:
        assert w in str(info.value), (w, str(info.value))
    with pytest.raises(error):  # the library function validates before building anything
        cfcontact.arc_on_block(**kwargs)


@pytest.fixture(scope="module")
def arc_model():
    return cfcontact.arc_on_block(radius=1.0, half_angle=40.0, nx=12, ny=3, friction=0.0)


def test_arc_contact_normals_radial_unit_outward(arc_model):
    """Pairs coincide, normals are unit, radial inside the arc (they vary along it) and point out of body 1."""
    g = arc_model.geometry
    R, theta, nx = 1.0, np.radians(40.0), 12
    assert arc_model.m == nx + 1  # the clamped left1 end node still pairs with a free body-2 node
    pairs = np.asarray(g.contact_nodes)
    pts = np.asarray(g.points)[:, :2]
    assert np.all(pairs[:, 1] >= 0)
    np.testing.assert_allclose(pts[pairs[:, 0]], pts[pairs[:, 1]], rtol=0, atol=1e-12)
    x = np.asarray(g.contact_points)[:, :2]
    # on the circle of radius R about (0, R), at angles -theta..theta, uniformly, ordered left to right
    centre = np.array([0.0, R])
    np.testing.assert_allclose(np.hypot(*(x - centre).T), R, rtol=0, atol=1e-7)
    phi = np.arctan2(x[:, 0], R - x[:, 1])
    np.testing.assert_allclose(phi, np.linspace(-theta, theta, nx + 1), rtol=0, atol=1e-7)
    n, t = np.asarray(g.normals), np.asarray(g.tangents)
    np.testing.assert_allclose(np.hypot(n[:, 0], n[:, 1]), 1.0, rtol=0, atol=1e-14)
    np.testing.assert_allclose(t, np.column_stack([-n[:, 1], n[:, 0]]), rtol=0, atol=0)
    # interior nodes: the average of the two adjacent facet normals is exactly radial
    radial = np.column_stack([np.sin(phi), -np.cos(phi)])
    np.testing.assert_allclose(n[1:-1], radial[1:-1], rtol=0, atol=1e-7)
    # end nodes: the normal of their one facet
    for end, d in ((0, x[1] - x[0]), (-1, x[-1] - x[-2])):  # facets oriented left to right
        np.testing.assert_allclose(n[end], np.array([d[1], -d[0]]) / np.hypot(*d), rtol=0, atol=1e-7)
    # the normals really turn: by 2 theta minus half a cell at each end, monotonically
    ang = np.arctan2(n[:, 0], -n[:, 1])
    assert np.all(np.diff(ang) > 0)
    np.testing.assert_allclose(ang[-1] - ang[0], 2 * theta - 2 * theta / nx, rtol=0, atol=1e-7)
    # outward for body 1: away from the arc's centre (body 1 lies on the centre's side) and away
    # from the body-1 cells next to each contact node
    assert np.all(np.sum(n * (x - centre), axis=1) > 0)
    cells, body = np.asarray(g.cells), np.asarray(g.cell_body)
    for k, node in enumerate(pairs[:, 0]):
        adj = cells[(body == 1) & np.any(cells == node, axis=1)]
        assert len(adj) >= 1
        cent = pts[adj].mean(axis=1)
        assert np.all((x[k] - cent) @ n[k] > 0), k


def test_arc_frictionless_against_dual_qp(arc_model):
    """F = 0: SSNM against SciPy's dual QP (NNLS), with contact active somewhere and open somewhere."""
    K, N, T, f1, f2 = arc_model.to_scipy()
    saw_open = saw_active = False
    for alpha in (0.0, 0.5, 1.0):
        f = (1 - alpha) * f1 + alpha * f2
        u_ref, lam_ref = frictionless_dual(K, N, f)
        sol = cfcontact.ssnm(arc_model, alpha)
        assert np.allclose(sol.u, u_ref, rtol=0, atol=1e-8 * np.abs(u_ref).max())
        assert np.allclose(sol.lam_n, lam_ref, rtol=0, atol=1e-8 * np.abs(lam_ref).max())
        saw_active |= bool(np.any(lam_ref > 1e-6 * lam_ref.max()))
        saw_open |= bool(np.any(lam_ref <= 1e-12 * lam_ref.max()))
    assert saw_active and saw_open


def test_seed_crosses_a_transition_into_an_exact_tie():
    """Only body 1 is loaded and the left end of its arc is clamped: once every node is open, body 2
    carries nothing and that end node has N u = g and lam = 0 for every alpha (an exact tie, both
    states are solutions).  The seed's strict fixed-point test put it in the active set, no
    candidate of its branching passed, and its fold rule turned the path back to alpha = 0 (26
    transitions instead of 13).  Now it crosses as the exact method does."""
    system = cfcontact.arc_on_block(nx=7, ny=3, half_angle=70.2126807587366, cell="triangle", friction=0.3,
                                    tractions1={"top1": (-13350769.6, -103154161.9)},
                                    tractions2={"top1": (-56979658.2, 7663425.7)})
    exact = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    seed = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
    assert exact.status == seed.status == "completed"
    ends_open = exact.branches[exact.transitions[-1].to_branch].sets
    assert ends_open.nu.all()  # the last branch: every node open
    y = DirNeuSolver(system).solve(ends_open, system.load(0.9))  # u = K^-1 f, lam = 0
    gaps = system.contact_maps()[0] @ y[:system.n] - system.gap
    assert np.count_nonzero(gaps == 0.0) >= 1  # the tied node: closed would do as well
    assert [(t.node, t.set, t.kind) for t in seed.transitions] == [(t.node, t.set, t.kind) for t in exact.transitions]
    assert len(exact.transitions) == 13 and seed.reach() == 1.0
    assert not [e for e in seed.events if e.kind == "unverified_transition"]
    for i in range(len(seed.alphas)):
        assert cfcontact.verify(system, seed.point_y(i), seed.alphas[i]).worst() < 1e-10


def _branch_codes(path):
    return [b.sets.state_codes().tolist() for b in path.branches]


@pytest.mark.parametrize("case,transitions", [("sticking node opens", 7), ("near-tie minimizer jumps", 7),
                                              ("a slipping node's indicator ranks ninth", 24)])
def test_seed_follows_the_exact_branches_at_degenerate_transitions(case, transitions):
    """Two transitions the seed's branching algorithm got wrong (found by a sweep of random
    variants; both turned its path back before alpha = 1):

    * the arc's clamped end node sticks with zero force and opens as the next node closes: rule
      (18) opened it still sticking (T u = 0 imposed with lam_n = 0), no candidate was a solution
      and the fold rule was applied.  An opening node is now freed tangentially.
    * two blocks at F = 30 on a non-matching interface: at the second of two folds 0.0006 apart the
      minimizer of (17) led back onto the open branch the path came from (consistent there, but
      not continuous with the branch being left).  The seed's own choice is now checked for
      continuity as the other candidates were.
    * soft blocks on rollers (E = 2.1e9 on 2.1e6), F = 0.6: a node that had just closed slipping
      goes on sticking.  A step before its root its indicator (lam_t + rho T u + F lam_n, rho of
      the stiff block) was larger than eight closed nodes' lam_n, so rule (17) left it out of the
      candidates, the fold rule was applied and the path cycled.  The indicators that change sign
      over the failed step are now tried right after the seed's own choice."""
    if case == "sticking node opens":
        system = cfcontact.arc_on_block(nx=4, ny=2, half_angle=52.22950899853359, cell="triangle", friction=0.3,
                                        tractions1={"top1": (-69256995.85, 16998109.49)},
                                        tractions2={"top1": (60681730.87, -108134746.94)})
    elif case.startswith("a slipping"):
        system = cfcontact.two_blocks(
            nx=12, ny=2, cell="triangle", E={"body1": 2.1e9, "body2": 2.1e6}, nu=0.45, friction=0.6,
            clamp=("left1",), dirichlet={"bottom2": {"y": 0.0}, "left2": {"x": 0.0}},
            body_force1=(0.0, -372090.288351006), tractions1={"top1": (417543.48068758706, -925423.0971665207)},
            tractions2={"top1": [(-439303.3557341346, -450768.41825452284),
                                 {"value": (421982.0659854218, 0.0), "x": (1.2385163859024642, 1.8385163859024642)}]})
    else:
        system = cfcontact.two_blocks(nx=3, ny=3, nx2=10, pairing="segment", cell="quadrilateral", angle=-30.0,
                                      friction=30.0, tractions1={"top1": (-58753826.95, 25382302.67)},
                                      tractions2={"top1": (44898306.26, -56903415.38),
                                                  "right1": (-38573520.75, -117039257.88)})
    exact = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    seed = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
    assert exact.status == seed.status == "completed" and exact.reach() == seed.reach() == 1.0
    assert len(exact.transitions) == transitions
    assert _branch_codes(seed) == _branch_codes(exact)
    assert [t.kind for t in seed.transitions] == [t.kind for t in exact.transitions]
    for t, e in zip(seed.transitions, exact.transitions):
        assert t.bracket[0] - 1e-12 <= e.alpha <= t.bracket[1] + 1e-12
    assert not [e for e in seed.events if e.kind == "unverified_transition"]


@pytest.mark.parametrize("friction", [0.3, 30.0])
@pytest.mark.parametrize("reversal", [1.0, 2.0], ids=["apex at 1/2", "apex at 1/3"])
def test_a_load_reversed_through_zero_is_crossed_in_one_transition_by_both_methods(friction, reversal):
    """f2 = -r f1 on a conforming interface: the load vanishes at alpha = 1 / (1 + r), and with it
    every multiplier and indicator (an apex).  Beyond it the problem is positively homogeneous, so
    a solution beyond gives the branch that leaves it.  Before: the seed method found no single or
    double set change there, applied its fold rule unverified and cycled at F = 3 and 30; the exact
    method crossed 1/2 as one degenerate point but 1/3 (not a double: the load there is rounding)
    as 2 to 8 transitions ordered by that rounding.  Now both take the same branch in one
    transition, and name each node's change alike (the exact method had named some by the slip
    constraint its rule crossed first, the seed method by the normal set).  The points at the
    apex itself are zero solutions of a load that is rounding, so the relative residual is
    checked away from it."""
    f = (-3e7, -1e8)
    apex = 1.0 / (1.0 + reversal)
    system = cfcontact.two_blocks(nx=10, ny=3, friction=friction, tractions1={"top1": f},
                                  tractions2={"top1": (-reversal * f[0], -reversal * f[1])})
    exact = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    seed = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
    assert exact.status == seed.status == "completed" and not exact.events and not seed.events
    (te,), (ts,) = exact.transitions, seed.transitions
    assert te.alpha == pytest.approx(apex, abs=1e-15) and ts.bracket[0] <= apex <= ts.bracket[1]
    assert te.kind == ts.kind == "transversal" and len(ts.changes) == len(te.changes) == 10
    assert _branch_codes(seed) == _branch_codes(exact)
    # each change named alike (the first set it toggles), though every constraint vanishes there
    assert sorted((c["node"], c["set"]) for c in te.changes) == sorted((c["node"], c["set"]) for c in ts.changes)
    assert (te.node, te.set) in [(c["node"], c["set"]) for c in ts.changes]
    for path in (exact, seed):
        away = [(a, y) for a, y in path.iter_points() if abs(a - apex) > 1e-9]
        assert max(cfcontact.verify(system, y, a).worst() for a, y in away) < 1e-12
    y_apex = [y for a, y in exact.iter_points() if abs(a - apex) <= 1e-9]
    assert len(y_apex) == 2 and max(np.abs(y[system.n:]).max() for y in y_apex) < 1e-12 * np.abs(f).max()


def test_an_apex_between_branches_referenced_far_from_it_is_stored_as_zero():
    """f2 = -f1 traced from alpha = -0.2226: the load vanishes at alpha = 1/2 (a double, so the data
    are exactly zero there) and the slipping nodes open.  The incoming branch's values
    at 1/2 are the rounding of its ends (4e-9 of loads of 3e7), which the stored points kept
    (relative residual 0.5 to 1 against their own size); zero data have the one solution zero,
    which both points now are."""
    f = (-27620000.0, -20440000.0)
    system = cfcontact.two_blocks(nx=6, ny=2, angle=30.48, friction=0.3, E={"body1": 2.411e10, "body2": 2.241e9},
                                  nu=0.4303, plane="stress", tractions1={"top1": f},
                                  tractions2={"top1": (-f[0], -f[1])})
    path = cfcontact.trace_path(system, -0.2226, 1.143, method="exact")
    (tr,) = path.transitions
    assert path.status == "completed" and tr.alpha == 0.5 and len(tr.changes) >= system.m - 1
    assert {c["from"] for c in tr.changes} == {"slip-"} and {c["to"] for c in tr.changes} == {"open"}
    apex = [y for a, y in path.iter_points() if a == 0.5]
    assert len(apex) == 2 and all(not np.any(y) for y in apex)
    assert max(cfcontact.verify(system, y, a).worst() for a, y in path.iter_points()) < 1e-12


def test_a_seed_start_whose_sticking_jz_mumps_cannot_factor_takes_the_exact_start():
    """Body 2 stiffer by 1e6: Debian 12's MUMPS finds the all-sticking J(Z) of SSNM's first iterate
    singular (Debian 13's factors it, and SSNM does not converge), and the seed method's start
    raised SingularSystemError.  That is one more start that failed: the next ones are tried, on
    Debian 12 down to the exact method's (from the frictionless solution), and the seed path then
    gives the exact path's set changes (same branches), its points within 1e-13.
    (test_path.py::test_a_jz_the_backend_cannot_factor_is_a_failed_start_not_a_crash makes the
    backend refuse that J(Z) on every platform.)"""
    system = cfcontact.two_blocks(nx=7, nx2=29, ny=4, ny2=7, length=4.739, height=1.458, cell="quadrilateral",
                                  E={"body1": 5.612e10, "body2": 5.612e16}, nu=0.4187, plane="stress", friction=3.0,
                                  pairing="segment", slave="contact2",
                                  tractions1={"top1": (65230000.0, -54620000.0)},
                                  tractions2={"top1": (28240000.0, 23890000.0), "right1": (-55400000.0, 60860000.0),
                                              "bottom2": (-42140000.0, -40080000.0)})
    from cfcontact.errors import ConvergenceError, SingularSystemError
    from cfcontact.report import compare_paths

    with pytest.raises((SingularSystemError, ConvergenceError)):
        cfcontact.ssnm(system, 0.0)  # (the PETSc DirNeuSolver: J(Z) by MUMPS)
    exact = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    seed = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
    assert seed.status == exact.status == "completed" and exact.stats["start"] == "frictionless"
    # (Debian 12: the exact method's start, an event says so; Debian 13: SSNM from a restart)
    assert (seed.stats["start"], [e.kind for e in seed.events]) in (("frictionless", ["start_reached"]), ("ssnm", []))
    assert compare_paths(seed, exact, system.friction_vector)["same_set_changes"]
    assert max(cfcontact.verify(system, y, a).worst() for a, y in seed.iter_points()) < 1e-13


@pytest.mark.slow
def test_arc_script_writes_msh_that_assembles_alike(tmp_path, arc_model):
    msh = tmp_path / "arc.msh"
    proc = subprocess.run([sys.executable, "-m", "cfcontact.meshes.arc_on_block", str(msh),
                           "--half-angle", "40", "--nx", "12", "--ny", "3"],
                          capture_output=True, text=True, env=_env(), cwd=ROOT, timeout=300)
    assert proc.returncode == 0, proc.stderr
    system = cfcontact.assemble_contact_system(str(msh), clamp=("left1", "bottom2"),
                                               tractions1={"top1": (2e7, -1e8)}, tractions2={"top1": (1e8, -2e7)})
    assert (system.n, system.m) == (arc_model.n, arc_model.m)
    np.testing.assert_allclose(system.geometry.normals, arc_model.geometry.normals, rtol=0, atol=1e-12)
    bad = subprocess.run([sys.executable, "-m", "cfcontact.meshes.arc_on_block", str(tmp_path / "b.msh"),
                          "--half-angle", "120"], capture_output=True, text=True, env=_env(), cwd=ROOT, timeout=300)
    assert bad.returncode == 2 and "half_angle" in bad.stderr and not (tmp_path / "b.msh").exists()


# ------------------------------------------------------------------ arc on block: command line
@pytest.mark.slow
def test_arc_example_case_runs(tmp_path):
    case = _copy_case(tmp_path, "arc.toml")
    assert cli.main(["run", case, "-q"]) == 0
    out = tmp_path / "arc_out"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["m"] == 17
    assert len(summary["transitions"]) > 0
    _assert_picture(str(out / "panel.png"), (800, 500))
    _assert_picture(str(out / "path.png"), (800, 450))
    path = SolutionPath.load(str(out / "path"))
    n = np.asarray(path.geometry.normals)
    assert np.ptp(np.arctan2(n[:, 0], -n[:, 1])) > np.radians(80)  # half-angle 45: the normals turn by ~84 degrees


@pytest.mark.parametrize("extra,words", [
    ("length = 3.0\n", ["length", "kind = 'arc'", "half_angle"]),
    ("half_angle = 95.0\n", ["half_angle", "(0, 80]", "95"]),
    ("radius = 0.0\n", ["radius", "positive"]),
    ("nx = 1\n", ["nx", ">= 2"]),
])
def test_arc_case_bad_geometry_exit_2(tmp_path, capsys, extra, words):
    case = tmp_path / "case.toml"
    case.write_text('[geometry]\nkind = "arc"\n' + extra)
    assert cli.main(["run", str(case)]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("cfcontact run: error:"), err
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert sorted(os.listdir(tmp_path)) == ["case.toml"]


def test_arc_case_tags_and_default_clamps(tmp_path, capsys):
    case = tmp_path / "case.toml"
    case.write_text('[geometry]\nkind = "arc"\nnx = 4\nny = 1\n[loads]\nclamp = ["left1", "base"]\n')
    assert cli.main(["run", str(case)]) == 2
    err = capsys.readouterr().err
    assert "base" in err and "bottom2=22" in err
    # default clamps left1 + bottom2: both bodies held, the model builds
    system = case_file.build_system(case_file.validate_case({"geometry": {"kind": "arc", "nx": 4, "ny": 1}}))
    assert system.m == 5 and system.info["clamp"] == ["left1=14", "bottom2=22"]


# ------------------------------------------------------------------ folds example
@pytest.mark.slow
def test_folds_example_case_has_folds_and_three_solutions(tmp_path, capsys):
    case = _copy_case(tmp_path, "folds.toml")
    assert cli.main(["run", case, "-q"]) == 0
    out = tmp_path / "folds_out"
    path = SolutionPath.load(str(out / "path"))
    assert path.status == "completed"
    assert len(path.folds) >= 2
    mult, alpha = path.max_multiplicity()
    assert mult >= 3
    assert len(path.solutions_at(alpha)) == mult
    assert cli.main(["info", str(out), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert len(rep["folds"]) >= 2 and max(iv["solutions"] for iv in rep["multiplicity"]) >= 3
    _assert_picture(str(out / "panel.png"), (800, 500))


# ------------------------------------------------------------------ pictures of the geometry page
@pytest.mark.slow
@pytest.mark.parametrize("variant,m", [("arc", 17), ("nonmatching", 12)])
def test_pictures_script_renders_a_variant(tmp_path, variant, m):
    """A picture from its case file (nonmatching.toml: node-to-segment pairing, 12 pairs)."""
    proc = subprocess.run([sys.executable, os.path.join(ROOT, "demos", "pictures.py"), "--variant", variant,
                           "-o", str(tmp_path), "--window-size", "600", "360"],
                          capture_output=True, text=True, env=_env(), cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stderr
    fn = tmp_path / f"{variant}.png"
    _assert_picture(str(fn), (600, 360))
    assert fn.stat().st_size < 150_000 and f"m = {m}," in proc.stdout
    assert sorted(os.listdir(tmp_path)) == [f"{variant}.png"]


def test_geometry_page_shows_every_variant():
    """Every example case has its picture on the geometry page, drawn by demos/pictures.py while
    the documentation is built (docs/_ext/cfcontact_docs.py, job "variants")."""
    import runpy

    page = open(os.path.join(ROOT, "docs", "geometry.md"), encoding="utf-8").read()
    pictures = runpy.run_path(os.path.join(ROOT, "demos", "pictures.py"))
    assert tuple(pictures["VARIANTS"]) == VARIANTS
    for v in VARIANTS:
        assert os.path.isfile(os.path.join(ROOT, "demos", "cases", pictures["VARIANTS"][v][0]))
        assert f"```{{gallery-figure}} variants/{v}.png" in page, v


@pytest.mark.slow
def test_soft_layer_case_is_the_main_demo_at_0_6(tmp_path):
    """demos/cases/soft_layer.toml builds the main demo's system at F = 0.6 (same loads, bit for
    bit up to assembly order) and its path has two folds and three solutions."""
    sys.path.insert(0, os.path.join(ROOT, "demos"))
    try:
        import main as demo
    finally:
        sys.path.pop(0)
    case = _copy_case(tmp_path, "soft_layer.toml")
    system = case_file.build_system(case_file.load_case(case))
    ref = demo.build(0.6)
    assert (system.n, system.m) == (1320, 30)
    for a, b in zip(system.loads_numpy(), ref.loads_numpy()):
        assert np.abs(a - b).max() <= 1e-12 * np.abs(b).max()
    assert cli.main(["run", case, "-q"]) == 0
    path = SolutionPath.load(str(tmp_path / "soft_layer_out" / "path"))
    assert path.status == "completed" and len(path.folds) == 2
    assert path.max_multiplicity()[0] == 3


def test_exact_transition_onto_a_branch_whose_crossed_constraint_has_no_rate():
    """The arc at F = 30 (3 cells): the path opens its last node at alpha ~ 0.334, where the clamped
    end node stays tied (N u = g, lam = 0) on the all-open branch: the constraint the new branch
    was entered through has rate exactly 0 there (dolfinx 0.5's assembly).  Moving the entry onto that constraint's root
    divided by it (ZeroDivisionError); such a constraint locates nothing and is now left alone."""
    system = cfcontact.arc_on_block(nx=3, ny=2, half_angle=58.61851307690787, cell="triangle", friction=30.0,
                                    tractions1={"top1": (-87374219.67335112, 29359256.020878475)},
                                    tractions2={"top1": (-71696855.24528542, -89679587.91712631)})
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", tree=True)
    assert path.status == "completed" and len(path.transitions) == 7
    assert [e.kind for e in path.events] == ["branch_point"]
    # (which of the tied node's equivalent states the tree takes there -- open, or closed slipping
    # with lam = 0 -- is decided by rounding: open with dolfinx 0.5, closed with 0.9)
    for t in path.transitions:
        for b in (t.from_branch, t.to_branch):
            assert cfcontact.verify(system, path.branch_y(b, t.alpha), t.alpha).worst() < 1e-10


#: Cylinders at F = 30 (indentation, mesh size) whose exact path meets a branch point where a fold
#: alternative goes back (by ~1e-14 in alpha) into the branch the main path came from.  Whether
#: the two roots there count as one point is decided by rounding, which differs between CPUs
#: (the first case has no branch point on an AMD EPYC with FMA) and between factorizations of K
#: (these were found with PETSc's Cholesky, which the test therefore asks for): the test needs
#: one of them.
JOINING_CYLINDERS = [((0.008018832492423484, 0.01619364866998529), 0.05992678918563923),
                     ((0.0030592123670732446, 0.015597919352438695), 0.0552169707954613),
                     ((0.009252939380762389, 0.015846392132820734), 0.05724906995109625),
                     ((0.00889630155447081, 0.014004277168842453), 0.04308335234002155)]


def test_a_tree_alternative_that_runs_into_the_tree_ends_joined():
    """Cylinders at F = 30 whose exact path has a branch point: the fold alternative goes back a
    few 1e-14 in alpha and enters the branch the main path came from.  In a tree that is where
    the alternative joins the tree: status "joined", and a "joined" event -- not the "cycling"
    event of a path revisiting its own branch ("a numerical inconsistency"), which `cfcontact
    info` listed."""
    met = 0
    for indentation, size in JOINING_CYLINDERS:
        system = cfcontact.cylinder_on_block(friction=30.0, indentation=indentation, cell="triangle", size=size)
        solver = CondensedSolver(system, SolverOptions(solver_type="petsc"))
        tree = cfcontact.trace_path(system, 0.0, 1.0, method="exact", tree=True, solver=solver)
        assert tree.status == "completed"
        kinds = [e.kind for e in tree.events]
        assert "cycling" not in kinds, tree.events
        if "branch_point" not in kinds:
            continue
        met += 1
        assert kinds.count("branch_point") == 1 and kinds.count("joined") == 1, kinds
        (bp,) = [e for e in tree.events if e.kind == "branch_point"]
        assert [r["status"] for r in bp.data["followed"].values()] == ["joined"]
        joined = tree.events[kinds.index("joined")]
        assert "reaches a branch of the tree" in joined.message and joined.data["first_alpha"] < joined.alpha
    assert met, "no case met its branch point"
