"""Issue #16: continuation in the friction coefficient, critical friction of a load path, the
multiplicity map and fold curves -- against the one-node closed form, enumeration on small
random systems, exact alpha-paths and the seed-style predictor-corrector in F."""

import json
import os

import numpy as np
import pytest

import cfcontact
from cfcontact import rational
from cfcontact.condensed import CondensedSolver
from cfcontact.enumerate import enumerate_solutions
from cfcontact.errors import InputError
from cfcontact.exact import trace_exact
from cfcontact.fmap import _count, critical_friction_path, fold_curves, multiplicity_map, save_map
from cfcontact.friction import (
    FrictionPath,
    friction_system,
    load_path,
    trace_friction_path,
    worst_residual_friction,
)
from cfcontact.lumped import one_node, random_system
from cfcontact.rational import RationalBranch, friction_pattern, solver_at
from cfcontact.solution_path import SolutionPath
from cfcontact.ssnm import verify
from reference import alpha_of_tan, one_node_solutions

K1 = np.array([[1.0, 0.5], [0.5, 1.0]])


def set_changes(path):
    return [(t.node, t.set, t.kind) for t in path.transitions]


# ------------------------------------------------------------------ rational branches
def test_rational_branch_matches_condensed_solver_and_roots_match_sampling():
    rng = np.random.default_rng(7)
    for seed in range(6):
        system = random_system(4, seed, friction=1.0, coupling=5.0)
        solver = CondensedSolver(system)
        w = solver.load_data(system.load(0.3))
        phi = friction_pattern(system)
        codes = rng.integers(0, 4, 4).astype(np.int8)
        rb = RationalBranch(solver.S, system.rho, codes, phi, (phi == 0).astype(np.intp))
        for F in (0.4, 2.3):
            view = solver_at(solver, system.with_friction(F))
            lam_ref, ind_ref = view.branch_data(w[:, None], b"t" + codes.tobytes(), codes)
            lam, ind, _ = rb.solve(F, w[:, None])
            assert np.allclose(lam, lam_ref, rtol=1e-10, atol=1e-12 * np.abs(lam_ref).max())
            assert np.allclose(ind, ind_ref, rtol=1e-9, atol=1e-10 * np.abs(ind_ref).max())
            lam, dlam, g, dg, _ = rb.tangent(F, w)  # the F-derivatives against central differences
            h = 1e-6
            fd = (rb.solve(F + h, w[:, None])[1][:, 0] - rb.solve(F - h, w[:, None])[1][:, 0]) / (2 * h)
            assert np.allclose(dg, fd, rtol=1e-5, atol=1e-6 * np.abs(dg).max())
        Fs = np.linspace(0.0, 40.0, 2001)
        poles = rb.poles(0.0, 40.0)
        batched = rb.pencil_roots_many(w[:, None], rb.cidx[:, None], rb.csgn[:, None], 0.0, 40.0, sigma=13.7)
        # split into batches of one pencil each (the memory bound of a long interface): the same roots
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(rational, "PENCIL_BATCH_BYTES", 1)
            calls = []
            whole = RationalBranch.pencil_roots_many
            mp.setattr(RationalBranch, "pencil_roots_many", lambda self, *a, **k: calls.append(1) or whole(self, *a, **k))
            split = rb.pencil_roots_many(w[:, None], rb.cidx[:, None], rb.csgn[:, None], 0.0, 40.0, sigma=13.7)
        assert len(calls) == 1 + rb.cidx.size  # (the call, then one batch per pencil)
        assert len(split) == len(batched) == rb.cidx.size
        for a, b in zip(split, batched):
            np.testing.assert_array_equal(a, b)
        for j in range(rb.cidx.size):
            roots = rb.pencil_roots(w[:, None], [rb.cidx[j]], [rb.csgn[j]], 0.0, 40.0)
            vals = np.array([rb.csgn[j] * rb.solve(F, w[:, None], refine=False)[1][rb.cidx[j], 0] for F in Fs])
            changes = Fs[:-1][np.sign(vals[:-1]) != np.sign(vals[1:])]
            for c in changes:
                if poles.size and np.min(np.abs(poles - c)) < 0.05:
                    continue  # a sign change through a pole
                assert np.min(np.abs(roots - c)) < 0.03, (seed, j, roots, c)
                assert np.min(np.abs(batched[j] - c)) < 0.03, (seed, j, batched[j], c)


# ------------------------------------------------------------------ friction paths
def test_one_node_friction_path_closed_form():
    system = one_node(2.5, K1)
    # tan = 0.6: slip+ for F < 1/0.6, stick above: one transversal transition at F = 1/tan
    a = alpha_of_tan(system, 0.6)
    for F0, F1 in ((0.0, 4.0), (4.0, 0.0)):
        path = trace_friction_path(system, a, F0, F1)
        assert path.status == "completed" and isinstance(path, FrictionPath)
        assert [t.kind for t in path.transitions] == ["transversal"]
        assert abs(path.transitions[0].alpha - 1 / 0.6) <= 1e-12 * (1 / 0.6)
        assert path.multiplicity_intervals() == [(0.0, 4.0, 1)]
    # tan = 0.45 (< k_tn / k_tt): from F = 3 down the stick solution folds at F = 1/tan into slip+
    a = alpha_of_tan(system, 0.45)
    path = trace_friction_path(system, a, 3.0, 0.0)
    assert [t.kind for t in path.folds] == ["fold"]
    assert abs(path.folds[0].alpha - 1 / 0.45) <= 1e-12 * (1 / 0.45)
    assert [b.sets.states() for b in path.branches] == [["stick"], ["slip+"]]
    f = system.load(a)
    for F in (2.3, 2.7, 2.99):
        sols = path.solutions_at(F)
        ref = dict(one_node_solutions(K1, F, f))
        assert sorted(s.states()[0] for s in sols) == ["slip+", "stick"]
        for s in sols:
            assert np.allclose([s.u[0], s.u[1], s.lam_n[0], s.lam_t[0]], ref[s.states()[0]], atol=1e-12)
    assert path.multiplicity(2.5) == 2 and path.multiplicity(2.0) == 0
    assert worst_residual_friction(system, path) < 1e-12


@pytest.mark.parametrize("coupling, direction", [(1.0, 1), (8.0, -1)])
def test_friction_paths_exact_vs_seed_and_enumeration(coupling, direction):
    folds = 0
    for m in (2, 3, 4):
        for seed in range(4):
            system = random_system(m, seed, friction=1.0, coupling=coupling, extra_dofs=0 if coupling > 1 else 2)
            for a in (0.0, 0.5):
                F0, F1 = (0.0, 40.0) if direction > 0 else (40.0, 0.0)
                exact = trace_friction_path(system, a, F0, F1)
                seed_path = trace_friction_path(system, a, F0, F1, method="seed")
                assert exact.status == seed_path.status == "completed", (m, seed, a, exact.events)
                assert set_changes(exact) == set_changes(seed_path), (m, seed, a)
                h_min = seed_path.options["h_min"]
                for te, ts in zip(exact.transitions, seed_path.transitions):
                    assert abs(te.alpha - ts.alpha) <= h_min
                folds += len(exact.folds)
                assert worst_residual_friction(system, exact) < 1e-9
                for lo, hi, k in exact.multiplicity_intervals():
                    F = 0.5 * (lo + hi)
                    sysF = friction_system(system, F)
                    assert k <= len(enumerate_solutions(sysF, a))
                    for sol in exact.solutions_at(F):
                        assert verify(sysF, sol, a).ok(1e-9)
    if coupling > 1:
        assert folds > 0  # these systems fold in F


def test_friction_path_save_load_resume_and_errors(tmp_path):
    system = random_system(3, 2, friction=1.0, coupling=8.0, extra_dofs=0)
    path = trace_friction_path(system, 0.5, 40.0, 0.0)
    F = 0.5 * (path.transitions[0].alpha + path.transitions[1].alpha)
    before = [s.y for s in path.solutions_at(F)]
    path.save(tmp_path / "fp")
    loaded = load_path(tmp_path / "fp")
    assert isinstance(loaded, FrictionPath) and loaded.load_alpha == 0.5
    assert repr(loaded).startswith("FrictionPath(method='exact', ") and repr(loaded).endswith("[alpha=0.5]")
    assert np.allclose(loaded.ys, path.ys) and loaded.multiplicity_intervals() == path.multiplicity_intervals()
    for y, s in zip(before, loaded.solutions_at(F)):
        assert np.allclose(s.y, y, rtol=1e-13, atol=1e-13 * np.abs(y).max())
    with pytest.raises(InputError, match="unsupported format"):
        SolutionPath.load(tmp_path / "fp")  # a path over F is not a path over alpha
    stopped = trace_friction_path(system, 0.5, 40.0, 0.0, callback=lambda p: p.branch == 2)
    assert stopped.status == "stopped by callback"
    stopped.save(tmp_path / "stopped")
    again = load_path(tmp_path / "stopped")
    resumed = trace_friction_path(system, 0.5, 40.0, 0.0, resume={"path": again, "state": stopped.resume_state})
    assert resumed.status == "completed" and set_changes(resumed) == set_changes(path)
    assert np.allclose([t.alpha for t in resumed.transitions], [t.alpha for t in path.transitions], rtol=1e-14)
    for bad in ((0.5, 1.0, 1.0), (0.5, -1.0, 2.0), (float("nan"), 0.0, 1.0)):
        with pytest.raises(InputError):
            trace_friction_path(system, *bad)
    with pytest.raises(InputError):
        trace_friction_path(system, 0.5, 0.0, 1.0, method="full")


# ------------------------------------------------------------------ critical friction, curves, map
@pytest.mark.parametrize("K", [K1, np.array([[2.0, 0.8], [0.8, 1.0]]), np.array([[1.5, 0.9], [0.9, 1.2]])])
def test_one_node_critical_friction_and_fold_curves_closed_form(K):
    system = one_node(2.5, K)
    ktt, ktn = K[0, 0], K[0, 1]
    crit = critical_friction_path(system, (0.0, 1.0), F_max=10.0)
    assert abs(crit.friction - ktt / abs(ktn)) <= 1e-8 * ktt / abs(ktn)
    assert abs(crit.alpha - alpha_of_tan(system, ktn / ktt)) <= 1e-8
    assert crit.bracket[0][1] == 0 and crit.bracket[1][1] > 0  # the probes below and above
    F_top = 1.0 / np.tan(np.radians(15.0))  # the moving ray leaves the range at alpha = 0 here
    fc = fold_curves(system, (0.0, 6.0), frictions=np.linspace(0.0, 6.0, 13))
    assert len(fc.curves) == 2 and len(fc.cusps) == 1
    a_c, F_c = fc.cusps[0]
    assert abs(F_c - ktt / ktn) <= 1e-8 * F_c and abs(a_c - alpha_of_tan(system, ktn / ktt)) <= 1e-8
    for F in np.linspace(ktt / ktn, 6.0, 23)[1:-1]:
        got = fc.alphas_at(F)
        want = sorted([alpha_of_tan(system, ktn / ktt)] + ([alpha_of_tan(system, 1.0 / F)] if F < F_top else []))
        assert np.allclose(got, want, atol=1e-10), (F, got, want)
    assert fc.alphas_at(0.9 * ktt / ktn) == []


@pytest.mark.parametrize("width", [1e-9, 1e-6])
def test_fold_curves_of_a_friction_range_narrower_than_the_join_tolerance(width):
    """An F range above the cusp only 1e-9 wide (narrower than the tolerance that joins pieces in
    F, 2e-9 max(|F|, 1)): the two folds of every path in it are two curves at the closed-form
    alphas (they had joined each other's ends into a cycle: no curve, alphas_at empty)."""
    system = one_node(2.5, K1)
    ktt, ktn = K1[0, 0], K1[0, 1]
    F_lo = ktt / ktn + 1e-9
    fc = fold_curves(system, (F_lo, F_lo + width))
    F = F_lo + 0.5 * width
    assert len(fc.curves) == 2 and len(fc.critical.folds) == 2
    want = sorted([alpha_of_tan(system, ktn / ktt), alpha_of_tan(system, 1.0 / F)])
    assert np.allclose(fc.alphas_at(F), want, atol=1e-10)


def test_one_node_map_agrees_with_closed_form():
    system = one_node(2.5, K1)
    alphas = np.linspace(0.0, 1.0, 101)
    # the wedge lies inside the alpha range up to F = 3.73; F = 2 (the cusp, where the slip branch is
    # singular) is left out
    frictions = np.linspace(0.05, 3.45, 35)
    fmap = multiplicity_map(system, alphas, frictions)
    for i, F in enumerate(frictions):
        for j, a in enumerate(alphas):
            want = len(one_node_solutions(K1, F, system.load(a)))
            tan = np.tan(np.arctan2(*system.load(a)[::-1]))
            if min(abs(tan - 0.5), abs(tan - 1.0 / max(F, 1e-300))) < 1e-9:
                continue  # on a fold ray: the count there is a convention
            assert fmap.counts[i, j] == want, (F, a)
    assert fmap.counts.max() == 3 and set(np.unique(fmap.counts)) == {1, 3}


@pytest.mark.parametrize("m", [2, 3, 4])
def test_random_maps_enumeration_and_curves_through_path_folds(m):
    frictions = np.linspace(0.0, 12.0, 9)
    alphas = np.linspace(0.0, 1.0, 21)
    folds = 0
    for seed in range(3):
        system = random_system(m, seed, friction=1.0, coupling=8.0, extra_dofs=0)
        fmap = multiplicity_map(system, alphas, frictions)
        fc = fold_curves(system, (0.0, 12.0))
        for i, F in enumerate(frictions):
            sysF = friction_system(system, F)
            path = trace_exact(sysF, 0.0, 1.0, start_sets=fc_start(system, F))
            # the map counts the path's solutions; they are at most all solutions, and each verifies
            for j, a in enumerate(alphas):
                sols = path.solutions_at(a)
                assert fmap.counts[i, j] <= len(enumerate_solutions(sysF, a))
                for s in sols:
                    assert verify(sysF, s, a).ok(1e-9)
            # the same numbers as SolutionPath.multiplicity_intervals (the path's own scan)
            iv, _ = _count(path, alphas)
            assert [tuple(x) for x in iv] == [tuple(x) for x in path.multiplicity_intervals()]
            # the fold curves pass through the path's folds, and only through them
            want = sorted(t.alpha for t in path.folds)
            folds += len(want)
            got = fc.alphas_at(F)
            assert len(got) == len(want) and np.allclose(got, want, atol=1e-8), (seed, F, got, want)
    assert m < 3 or folds > 0  # (seeds 1 of m = 3 and 0, 1 of m = 4 fold)


def fc_start(system, F):
    """The start the map and the curves use: the friction path at alpha = 0 from F = 0 (first pass)."""
    from cfcontact.fmap import _Starts

    key = id(system)
    if fc_start.cache.get("key") != key:
        fc_start.cache = {"key": key, "starts": _Starts(system, cfcontact.condensed.get_condensed_solver(system), 0.0,
                                                        12.0, cfcontact.PathOptions())}
    return fc_start.cache["starts"].sets_at(F)


fc_start.cache = {}


def test_map_files_and_plot(tmp_path):
    from cfcontact.plotting import plot_friction_map, save_figure

    system = one_node(2.5, K1)
    fmap = multiplicity_map(system, np.linspace(0, 1, 11), np.linspace(0, 3, 7))
    fc = fold_curves(system, (0.0, 3.0))
    files = save_map(tmp_path / "m", fmap, fc, marks=[2.5])
    assert files == ["map.json", "map.npz"]
    data = json.loads((tmp_path / "m" / "map.json").read_text())
    assert data["format"] == "cfcontact-friction-map" and data["marks"] == [2.5]
    assert abs(data["fold_curves"]["critical"]["friction"] - 2.0) < 1e-12
    with np.load(tmp_path / "m" / "map.npz") as z:
        assert z["counts"].shape == (7, 11) and "curve_0" in z.files
    fig = plot_friction_map(fmap, fc, fc.critical, marks=[2.5])
    gids = {a.get_gid() for a in fig.axes[0].get_children()}
    assert {"map", "fold_curves", "cusps", "critical", "marks"} <= gids
    save_figure(fig, tmp_path / "map.png")
    assert os.path.getsize(tmp_path / "map.png") > 1000


@pytest.mark.slow
def test_demo_path_critical_friction_not_below_scan_bound():
    from cfcontact.critical import critical_friction
    from cfcontact.demo_models import build_demo

    system = build_demo(0.6)
    crit = critical_friction_path(system, (0.0, 1.0), F_max=30.0)
    scan = critical_friction(system)
    assert np.isfinite(crit.friction) and crit.friction >= scan.friction
    assert abs(crit.friction - 0.5661252421) < 1e-8  # nodes 27/28 near the right end (docs/friction.md)
    assert crit.node == 28 and 0.79 < crit.alpha < 0.80
    phi = friction_pattern(system)
    solver = cfcontact.condensed.get_condensed_solver(system)
    for F, folds in ((crit.friction * (1 - 1e-5), 0), (crit.friction * (1 + 1e-5), 2)):
        sysF = friction_system(system, F, phi)
        assert len(trace_exact(sysF, 0.0, 1.0, solver=solver_at(solver, sysF)).folds) == folds


@pytest.mark.slow
def test_quick_blocks_path_critical_friction_not_below_scan_bound():
    from cfcontact.critical import critical_friction
    from cfcontact.demo_models import build_blocks

    system = build_blocks(30.0, quick=True)  # the two steel blocks of the benchmark, 12 x 4 cells per block
    crit = critical_friction_path(system, (0.0, 1.0), F_max=30.0)
    assert crit.friction >= critical_friction(system).friction
    assert abs(crit.friction - 26.7135731744) < 1e-8 * 26.7  # node 5 (docs/friction.md)


@pytest.mark.slow
def test_demo_fold_curves_through_the_folds_of_exact_alpha_paths():
    from cfcontact.demo_models import build_demo

    system = build_demo(0.6)
    frictions = np.linspace(0.3, 12.0, 14)
    fmap = multiplicity_map(system, np.linspace(0.0, 1.0, 11), frictions)
    fc = fold_curves(system, (0.0, 12.0))
    n = 0
    for F, folds in zip(frictions, fmap.folds):
        got = fc.alphas_at(F)
        assert len(got) == len(folds) and np.allclose(got, sorted(folds), atol=1e-8), F
        n += len(folds)
    assert n > 50


def test_per_node_friction_scales_by_one_factor():
    base = random_system(4, 8, friction=1.0, coupling=8.0, extra_dofs=0)
    system = base.with_friction(np.array([0.5, 2.0, 0.0, 1.0]))  # phi = (0.25, 1, 0, 0.5): node 2 frictionless
    phi = np.array([0.25, 1.0, 0.0, 0.5])
    assert np.allclose(friction_pattern(system), phi)
    path = trace_friction_path(system, 0.0, 40.0, 0.0)
    assert path.status == "completed" and np.allclose(path.pattern, phi)
    assert len(path.transitions) == 5 and len(path.folds) == 2
    assert worst_residual_friction(system, path) < 1e-9
    for lo, hi, k in path.multiplicity_intervals():
        F = 0.5 * (lo + hi)
        sysF = friction_system(system, F)
        assert np.allclose(sysF.friction_vector, F * phi)
        assert k <= len(enumerate_solutions(sysF, 0.0))
        for sol in path.solutions_at(F):
            assert verify(sysF, sol, 0.0).ok(1e-9)
            assert sol.lam_t[2] == 0.0  # the frictionless node
    seed_path = trace_friction_path(system, 0.0, 40.0, 0.0, method="seed")
    assert set_changes(seed_path) == set_changes(path)


def test_friction_path_with_a_node_without_tangential_unknown():
    """Body 1 on rollers (u_x = 0 on left1) over a clamped body 2: the left contact node's two sides
    cannot move tangentially, its T row is zero (``system.no_tangent``).  A sticking node there
    put the equation (T u)_i = 0 -- the zero row -- into the branch matrix, and every friction
    path from F = 0 (and ``cfcontact run`` with parameter = "friction") failed with "M(F) is
    singular".  Such a node now sticks with lam_t = 0, as in the condensed backend; the path agrees
    with enumeration and with the seed method in F."""
    system = cfcontact.two_blocks(nx=5, ny=4, cell="triangle", friction=30.0, clamp=("left2",),
                                  tractions1={"top1": (45555826.47, -113881675.57)},
                                  tractions2={"top1": (67998807.98, -21120105.01), "right1": (19984913.92, -18844158.81)},
                                  dirichlet={"left1": {"x": 0.0}, "top1": {"y": (0.0, -0.00260757)}})
    assert np.flatnonzero(system.no_tangent).tolist() == [0]
    path = trace_friction_path(system, 0.5, 0.0, 30.0)
    assert path.status == "completed" and len(path.transitions) == 2
    for t in path.transitions:
        sysF = friction_system(system, t.alpha, path.pattern)
        for b in (t.from_branch, t.to_branch):
            assert verify(sysF, path.branch_y(b, t.alpha), 0.5).worst() < 1e-12
    for F in (0.0, 1.0, 10.0, 29.0):
        (sol,) = path.solutions_at(F)
        (ref,) = enumerate_solutions(friction_system(system, F, path.pattern), 0.5)
        assert sol.lam_t[0] == 0.0
        assert np.abs(sol.y - ref.y).max() <= 1e-12 * np.abs(ref.y).max()
    seed = trace_friction_path(system, 0.5, 0.0, 30.0, method="seed")
    assert [b.sets.state_codes().tolist() for b in seed.branches] == [b.sets.state_codes().tolist()
                                                                        for b in path.branches]


def test_a_map_row_that_cannot_be_traced_to_its_end_is_unknown():
    """At the critical friction of the blocks (nx = 4), a cusp, the alpha-path meets a singular
    branch and ends "stuck" (a dead end) at alpha = 0.071: its row was counted as far as it went,
    0 beyond ("the path does not reach"), although what lies beyond is unknown.  It is -1, as a
    path that fails; fold_curves and critical_friction_path are unaffected; a degenerate alpha
    range is refused."""
    from cfcontact.demo_models import BLOCKS_F1, BLOCKS_F2, BLOCKS_MODEL
    from cfcontact.models import two_blocks

    system = two_blocks(nx=4, ny=2, friction=30.0, tractions1=BLOCKS_F1, tractions2=BLOCKS_F2, **BLOCKS_MODEL)
    Fc = critical_friction_path(system, (0.0, 1.0), F_max=60.0).friction
    res = multiplicity_map(system, np.linspace(0.0, 1.0, 11), np.array([0.5 * Fc, Fc]))
    assert res.status[0] == "completed" and (res.counts[0] >= 1).all()
    assert res.status[1] == "stuck" and (res.counts[1] == -1).all()
    with pytest.raises(InputError, match="alpha_range must be two different"):
        critical_friction_path(system, (0.5, 0.5), F_max=60.0)


def test_friction_path_points_formed_from_their_own_multipliers(tmp_path):
    """An inclined non-matching pair (body 2 softer by 283, F from 0 to 30 at alpha = 0.4741): a
    point's u was read off its branch's form u0 + U mu(F), whose columns U are differences of
    displacements; as mu grew along a branch the points lost digits, up to 2.7e-9 from (1)-(3) at
    F = 0.99 (SSNM there: 5e-13).  Formed from the point's own multipliers, u = K^-1 (f - B^T lam),
    they are within 1e-10, as the alpha-paths of the model; a saved and reloaded path keeps them."""
    system = cfcontact.two_blocks(nx=21, nx2=26, ny=9, height2=0.2809, length=4.741, height=0.984, angle=-49.72,
                                  cell="triangle", E={"body1": 5.761e10, "body2": 2.033e8}, nu=0.01497,
                                  friction=3.0, pairing="segment",
                                  tractions1={"top1": (2845000.0, -11880000.0)},
                                  tractions2={"top1": (63390000.0, -69310000.0), "right1": (-7091000.0, 9646000.0),
                                              "bottom2": (1167000.0, 3874000.0)})
    path = trace_friction_path(system, 0.4741, 0.0, 30.0)
    assert path.status == "completed" and len(path.transitions) >= 20
    assert worst_residual_friction(system, path) < 1e-10
    path.save(tmp_path / "fp")
    again = load_path(tmp_path / "fp")
    assert np.array_equal(again.ys, path.ys) and worst_residual_friction(system, again) < 1e-10
