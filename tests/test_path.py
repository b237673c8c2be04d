"""Path following (seed method) against independent references."""

import numpy as np
import pytest

import cfcontact
from cfcontact.lumped import one_node, random_system
from reference import one_node_solutions

K1 = np.array([[1.0, 0.5], [0.5, 1.0]])


def alpha_of_direction(system, theta):
    """alpha at which f(alpha) points along theta (closed form, the one-node model)."""
    f1, f2 = system.loads_numpy()
    d = np.array([np.cos(theta), np.sin(theta)])
    c1 = f1[0] * d[1] - f1[1] * d[0]
    c2 = f2[0] * d[1] - f2[1] * d[0]
    return c1 / (c1 - c2)


@pytest.fixture(scope="module")
def one_node_path():
    system = one_node(2.5, K1)
    return system, cfcontact.trace_path(system, 0.0, 1.0, method="seed")


def test_one_node_two_folds_at_wedge_rays(one_node_path):
    system, path = one_node_path
    assert path.status == "completed"
    assert [t.kind for t in path.transitions] == ["fold", "fold"]
    rays = sorted([alpha_of_direction(system, np.arctan(0.4)), alpha_of_direction(system, np.arctan(0.5))])
    h_min = path.options["h_min"]
    got = sorted(t.alpha for t in path.folds)
    assert abs(got[0] - rays[0]) <= h_min and abs(got[1] - rays[1]) <= h_min
    for t in path.folds:
        assert t.bracket[0] - 1e-15 <= t.alpha <= t.bracket[1] + 1e-15


def test_one_node_multiplicity_three_between_folds(one_node_path):
    system, path = one_node_path
    a_lo, a_hi = sorted(t.alpha for t in path.folds)
    for a in np.linspace(a_lo + 1e-4, a_hi - 1e-4, 7):
        sols = path.solutions_at(a)
        assert len(sols) == 3
        f = system.load(a)
        ref = one_node_solutions(K1, 2.5, f)
        assert sorted(s.states()[0] for s in sols) == sorted(name for name, _ in ref)
        for sol in sols:
            yref = dict(ref)[sol.states()[0]]
            got = np.array([sol.u[0], sol.u[1], sol.lam_n[0], sol.lam_t[0]])
            assert np.allclose(got, yref, atol=1e-12)
    for a in (0.1, a_lo - 1e-3, a_hi + 1e-3, 0.95):
        assert path.multiplicity(a) == 1


def test_folds_are_turning_points(one_node_path):
    _, path = one_node_path
    for t in path.folds:
        b_in, b_out = path.branches[t.from_branch], path.branches[t.to_branch]
        assert b_in.orientation == -b_out.orientation
        a_in = path.alphas[b_in.points]
        a_out = path.alphas[b_out.points]
        # alpha increases then decreases (or the reverse) across the fold
        assert np.all(np.sign(np.diff(a_in)) == b_in.orientation)
        assert np.all(np.sign(np.diff(a_out)) == b_out.orientation)


def test_every_point_is_a_fixed_point_and_solves_the_problem(one_node_path):
    system, path = one_node_path
    for (alpha, y), b in zip(path.points, path.point_branch):
        Z = path.branches[b].sets
        assert cfcontact.is_fixed_point(system, y, Z)
        assert cfcontact.ssnm(system, alpha, y0=y).iterations == 1
        assert cfcontact.verify(system, y, alpha).ok(1e-10)


def test_small_friction_single_valued():
    system = random_system(3, 7, friction=0.05)
    path = cfcontact.trace_path(system, 0.0, 1.0)
    assert path.status == "completed"
    assert all(t.kind == "transversal" for t in path.transitions)
    assert np.all(np.diff(path.alphas) > 0)
    for a in np.linspace(0.01, 0.99, 9):
        assert path.multiplicity(a) == 1


def test_random_systems_every_point_verifies():
    for seed in range(4):
        system = random_system(3, seed, friction=1.5)
        path = cfcontact.trace_path(system, 0.0, 1.0, max_steps=20000)
        assert path.status in ("completed",), (seed, path.status, path.events)
        for (alpha, y) in path.points:
            assert cfcontact.verify(system, y, alpha).ok(1e-9)


def test_callback_stops_the_run():
    system = one_node(2.5, K1)
    seen = []

    def cb(point):
        seen.append(point.alpha)
        return len(seen) >= 5

    path = cfcontact.trace_path(system, 0.0, 1.0, callback=cb)
    assert path.status == "stopped by callback"
    assert len(path.alphas) == 5 == len(seen)


def test_save_load_round_trip(tmp_path, one_node_path):
    system, path = one_node_path
    out = path.save(tmp_path / "run.cfpath")
    back = cfcontact.SolutionPath.load(out)
    assert back.status == path.status and back.method == "seed"
    assert np.array_equal(back.alphas, path.alphas)
    assert np.array_equal(back.ys, path.ys)
    assert [t.to_dict() for t in back.transitions] == [t.to_dict() for t in path.transitions]
    assert [b.sets for b in back.branches] == [b.sets for b in path.branches]
    a = 0.45
    s1 = path.solutions_at(a)
    s2 = back.solutions_at(a)
    assert len(s1) == len(s2) == 3
    for x, y in zip(s1, s2):
        assert np.array_equal(x.y, y.y)
    # saving again over the same directory replaces it whole
    path.save(tmp_path / "run.cfpath")
    assert sorted(p.name for p in (tmp_path / "run.cfpath").iterdir()) == ["fields.npz", "path.json"]
    assert [p.name for p in tmp_path.iterdir()] == ["run.cfpath"]


def test_bad_options_and_ranges():
    system = one_node(0.3)
    with pytest.raises(cfcontact.InputError, match="alpha range is empty"):
        cfcontact.trace_path(system, 0.5, 0.5)
    with pytest.raises(cfcontact.InputError, match="unknown method 'newton'"):
        cfcontact.trace_path(system, 0, 1, method="newton")
    with pytest.raises(cfcontact.InputError, match="unknown path option"):
        cfcontact.trace_path(system, 0, 1, hmin=3)
    with pytest.raises(cfcontact.InputError, match="c_s"):
        cfcontact.trace_path(system, 0, 1, c_s=2.0)
    with pytest.raises(cfcontact.InputError, match="not a saved cfcontact path"):
        cfcontact.SolutionPath.load("/nonexistent-dir")


@pytest.mark.parametrize("m,seed", [(3, 3), (3, 131), pytest.param(5, 43, marks=pytest.mark.slow), (5, 270)])
def test_start_point_when_ssnm_from_zero_fails(m, seed):
    """At F = 30 SSNM from 0 cycles on these small random systems; the start cascade (from the
    frictionless solution, from the open solution, other rho) finds a solution of (1)-(3) with the
    system's own rho, and both methods trace from it."""
    from cfcontact.errors import ConvergenceError
    from cfcontact.lumped import random_system
    from cfcontact.path import PathOptions, start_point

    system = random_system(m, seed, friction=30.0, coupling=3.0)
    with pytest.raises(ConvergenceError):
        cfcontact.ssnm(system, 0.0)
    sol = start_point(system, 0.0, None, PathOptions(), None)
    assert cfcontact.verify(system, sol.y, 0.0).ok(1e-9)
    assert cfcontact.is_fixed_point(system, sol.y, sol.sets)
    for method in ("seed", "exact"):
        path = cfcontact.trace_path(system, 0.0, 1.0, method=method)
        assert path.status == "completed", (method, path.status)


def test_a_jz_the_backend_cannot_factor_is_a_failed_start_not_a_crash():
    """Where the backend cannot factor one J(Z) of SSNM's way (MUMPS at a stiffness ratio of 1e6:
    SingularSystemError), start_point tries its next start, as after a ConvergenceError; an error
    of the model (K not positive definite, an InputError too) still stops it."""
    from cfcontact.errors import NotPositiveDefiniteError, SingularSystemError
    from cfcontact.path import PathOptions, start_point
    from cfcontact.ssnm import get_solver

    system = random_system(4, 7, friction=0.5)
    solver = get_solver(system)
    calls = []

    class Refusing:  # the backend, refusing the all-sticking J(Z) (SSNM's first iterate from 0)
        def __getattr__(self, name):
            return getattr(solver, name)

        def solve(self, Z, f):
            calls.append(Z)
            if not (Z.nu.any() or Z.tp.any() or Z.tm.any()):
                raise SingularSystemError("J(Z) could not be factored")
            return solver.solve(Z, f)

    sol = start_point(system, 0.0, None, PathOptions(), Refusing())
    assert len(calls) > 1 and cfcontact.verify(system, sol.y, 0.0).ok(1e-10)

    class NotPD(Refusing):
        def solve(self, Z, f):
            raise NotPositiveDefiniteError("K is not positive definite")

    with pytest.raises(NotPositiveDefiniteError):
        start_point(system, 0.0, None, PathOptions(), NotPD())


def test_with_rho():
    from cfcontact.lumped import one_node

    s = one_node(2.5)
    assert s.with_rho(3.0).rho == 3.0 and s.rho != 3.0
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(cfcontact.InputError, match="rho"):
            s.with_rho(bad)


def test_seed_checkpoint_is_a_save_and_resumes_to_the_same_path(tmp_path):
    """A CHECKPOINT answer saves the live path and the stepper's current resume state and the run
    goes on (its path is that of a run without checkpoints); every saved checkpoint, loaded and
    resumed, ends in that same path."""
    import json

    from cfcontact.options import AlphaSpan, PathOptions
    from cfcontact.path import path_stepper
    from cfcontact.stepper import CHECKPOINT

    system = one_node(2.5, K1)
    ref = cfcontact.trace_path(system, 0.0, 1.0)
    saved = []

    def save(path, state):
        assert path.status == "running" and path.stats["linear_solves"] > 0
        saved.append((path.save(tmp_path / f"ck{len(saved)}"), json.loads(json.dumps(state))))

    options = PathOptions()
    stepper = path_stepper(system, AlphaSpan.of(0.0, 1.0, options), options, "seed")
    path = stepper.run(lambda point: CHECKPOINT if point.index % 9 in (0, 4) else None, save)
    assert len(saved) > 10
    for p in [path] + [cfcontact.trace_path(system, 0.0, 1.0, resume={"path": cfcontact.SolutionPath.load(fn),
                                                                       "state": state})
                       for fn, state in saved[::3]]:
        assert p.status == "completed"
        np.testing.assert_array_equal(p.alphas, ref.alphas)
        np.testing.assert_array_equal(p.ys, ref.ys)
        assert [t.to_dict() for t in p.transitions] == [t.to_dict() for t in ref.transitions]


def test_seed_answers_inside_transition_brackets(one_node_path):
    """The seed method knows a transition only within its bracket (h_min wide): solutions_at there
    evaluates the branches on both sides and keeps the consistent ones -- as many as the exact
    path has, each a solution."""
    system, path = one_node_path
    exact = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert path.transitions
    for t in path.transitions:
        lo, hi = t.bracket
        assert hi > lo
        for a in (lo + 0.25 * (hi - lo), 0.5 * (lo + hi), lo + 0.75 * (hi - lo)):
            sols = path.solutions_at(a)
            assert len(sols) == exact.multiplicity(a) >= 1, (t, a)
            for s in sols:
                assert cfcontact.verify(system, s, a).ok(1e-10)


def test_seed_never_stores_a_point_it_cannot_verify():
    """A transition the seed's indicator cannot verify (random model, F = 30) is reported as an
    event and the path goes on by the seed's rule, but its unverified point is not stored: every
    stored point solves (1)-(3)."""
    system = random_system(5, 5, friction=30.0)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
    assert "unverified_transition" in [e.kind for e in path.events]
    assert max(cfcontact.verify(system, y, a).worst() for a, y in path.points) <= 1e-10


@pytest.mark.parametrize("method", ["exact", "seed"])
def test_a_path_that_turns_back_says_so(method):
    """A random model (m = 4, F = 3) whose path from alpha = 0 folds at alpha ~ 0.094 and leaves
    its range at alpha = 0: status "completed", but turned_back() says it never reached alpha = 1,
    reach() is the fold, and the report says so; at alpha = 0.5 the problem has a solution
    (enumeration) that this path does not hold.  The one-node path reaches alpha = 1: not
    turned back."""
    from cfcontact.enumerate import enumerate_solutions
    from cfcontact.report import format_report, path_report

    system = random_system(4, 560, friction=3.0, coupling=10.0)
    path = cfcontact.trace_path(system, 0.0, 1.0, method=method)
    assert path.status == "completed" and path.turned_back()
    fold = path.folds[-1].alpha
    assert abs(path.reach() - fold) <= 1e-5 and 0.09 < fold < 0.1
    assert not path.solutions_at(0.5) and enumerate_solutions(system, 0.5)
    text = format_report(path_report(path), "mem")
    assert f"the path turned back: it reaches alpha = {path.reach():.10g} at most" in text
    assert path.summary()["turned_back"] is True

    one = cfcontact.trace_path(one_node(), 0.0, 1.0, method=method)
    assert one.status == "completed" and not one.turned_back() and one.reach() == 1.0
