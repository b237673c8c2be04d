"""Exact piecewise-affine path following, enumeration and the condensed backend."""

import json
import os
import sys

import numpy as np
import pytest
import scipy.linalg as sla

import cfcontact
from cfcontact.condensed import CondensedSolver
from cfcontact.enumerate import enumerate_solutions
from cfcontact.exact import canonical_codes, follow_alternative, trace_exact
from cfcontact.lumped import one_node, random_system
from cfcontact.ssnm import DirNeuSolver, InactiveSets
from cfcontact.system import ContactSystem
from reference import one_node_solutions
from test_path import alpha_of_direction

try:
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st
except ImportError:  # pragma: no cover
    given = None

K1 = np.array([[1.0, 0.5], [0.5, 1.0]])
HERE = os.path.dirname(os.path.abspath(__file__))


def direction(deg):
    return np.array([np.cos(np.radians(deg)), np.sin(np.radians(deg))])


@pytest.fixture(scope="module")
def one_node_exact():
    system = one_node(2.5, K1)
    return system, cfcontact.trace_path(system, 0.0, 1.0, method="exact")


def assert_transitions_verify(system, path, tol=1e-8):
    for t in path.transitions:
        assert t.bracket == (t.alpha, t.alpha)
        for b in (t.from_branch, t.to_branch):
            y = path.branch_y(b, t.alpha)
            assert cfcontact.verify(system, y, t.alpha).ok(tol), (t, b)


def branch_keys(path, friction):
    return [canonical_codes(b.sets, friction).tolist() for b in path.branches]


# ------------------------------------------------------------------ one node
def test_one_node_exact_two_folds_at_wedge_rays(one_node_exact):
    system, path = one_node_exact
    assert path.status == "completed" and path.method == "exact"
    assert [t.kind for t in path.transitions] == ["fold", "fold"]
    rays = sorted([alpha_of_direction(system, np.arctan(0.4)), alpha_of_direction(system, np.arctan(0.5))])
    got = sorted(t.alpha for t in path.folds)
    assert abs(got[0] - rays[0]) <= 1e-10 and abs(got[1] - rays[1]) <= 1e-10
    assert [b.sets.states() for b in path.branches] == [["open"], ["slip+"], ["stick"]]
    assert [b.orientation for b in path.branches] == [1, -1, 1]
    for b in path.branches[1:]:
        assert b.alpha_enter == path.transitions[b.origin].alpha
        assert b.parent == b.index - 1
    assert_transitions_verify(system, path, 1e-12)
    assert len(path.alphas) == 2 * len(path.branches)  # entry and exit point of every branch


def test_one_node_exact_multiplicity_three_between_folds(one_node_exact):
    system, path = one_node_exact
    a_lo, a_hi = sorted(t.alpha for t in path.folds)
    for a in np.linspace(a_lo + 1e-9, a_hi - 1e-9, 9):
        sols = path.solutions_at(a)
        ref = dict(one_node_solutions(K1, 2.5, system.load(a)))
        assert sorted(s.states()[0] for s in sols) == sorted(ref) == ["open", "slip+", "stick"]
        for sol in sols:
            got = np.array([sol.u[0], sol.u[1], sol.lam_n[0], sol.lam_t[0]])
            assert np.allclose(got, ref[sol.states()[0]], atol=1e-12)
    for a in (0.0, 0.2, a_lo - 1e-6, a_hi + 1e-6, 0.9, 1.0):
        assert path.multiplicity(a) == 1


def test_one_node_exact_reverse_direction(one_node_exact):
    system, fwd = one_node_exact
    back = cfcontact.trace_path(system, 1.0, 0.0, method="exact")
    assert back.status == "completed"
    assert [b.sets.states() for b in back.branches] == [["stick"], ["slip+"], ["open"]]
    assert np.allclose(sorted(t.alpha for t in back.transitions), sorted(t.alpha for t in fwd.transitions),
                       atol=1e-14)


def test_exact_callback_points_and_stop():
    system = one_node(2.5, K1)
    seen = []
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", callback=lambda p: seen.append(p) and False)
    # one point per branch start plus the end point
    assert len(seen) == len(path.branches) + 1
    assert [p.branch for p in seen] == [0, 1, 2, 2]
    assert seen[-1].alpha == 1.0
    for p in seen:
        assert cfcontact.verify(system, p.solution, p.alpha).ok(1e-10)
    stop = cfcontact.trace_path(system, 0.0, 1.0, method="exact", callback=lambda p: p.branch == 1)
    assert stop.status == "stopped by callback" and len(stop.branches) == 2


def test_exact_alpha_range_and_max_transitions():
    system = one_node(2.5, K1)
    p = cfcontact.trace_path(system, 0.0, 1.0, method="exact", alpha_max=0.5)
    assert p.status == "completed" and len(p.transitions) == 0 and p.branches[0].alpha_exit == 0.5
    p = cfcontact.trace_path(system, 0.0, 1.0, method="exact", max_transitions=1)
    assert p.status == "max_transitions" and len(p.transitions) == 1
    assert p.events[-1].kind == "max_transitions"


# -------------------------------------------------------- exact vs seed method
@pytest.mark.parametrize("m", [1, 2, 3, 4, 5])
@pytest.mark.parametrize("friction", [0.0, 0.3, 1.0, 2.5])
def test_exact_matches_seed_on_random_systems(m, friction):
    for seed in range(3):
        system = random_system(m, seed, friction=friction)
        exact = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
        seed_path = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
        assert exact.status == seed_path.status == "completed", (seed, exact.events, seed_path.events)
        assert branch_keys(exact, friction) == branch_keys(seed_path, friction), seed
        assert [t.kind for t in exact.transitions] == [t.kind for t in seed_path.transitions]
        h_min = seed_path.options["h_min"]
        for te, ts in zip(exact.transitions, seed_path.transitions):
            assert abs(te.alpha - ts.alpha) <= h_min
            assert ts.bracket[0] - 1e-12 <= te.alpha <= ts.bracket[1] + 1e-12
        assert_transitions_verify(system, exact)


def test_exact_large_friction_folds_and_enumeration():
    found_fold = False
    for seed in range(6):
        system = random_system(4, seed, friction=30.0, extra_dofs=3)
        path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
        assert path.status == "completed"
        found_fold |= bool(path.folds)
        assert_transitions_verify(system, path)
        mult, at = path.max_multiplicity()
        if mult > 1:
            ens = enumerate_solutions(system, at)
            assert len(ens) >= mult
    assert found_fold


# ------------------------------------------------------------- branch points
def two_identical_nodes():
    K = sla.block_diag(K1, K1)
    N = np.array([[0, 1, 0, 0], [0, 0, 0, 1.0]])
    T = np.array([[1.0, 0, 0, 0], [0, 0, 1, 0]])
    return ContactSystem.from_arrays(K, N, T, np.tile(direction(15), 2), np.tile(direction(35), 2), 2.5)


def test_branch_points_reported_and_followed():
    system = two_identical_nodes()
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert path.status == "completed"
    bps = [i for i, e in enumerate(path.events) if e.kind == "branch_point"]
    assert len(bps) == 2
    first = path.events[bps[0]]
    assert sorted(tuple(a["states"]) for a in first.data["alternatives"]) == \
        [("open", "slip+"), ("slip+", "open"), ("slip+", "slip+")]
    assert all(a["orientation"] == -1 and a["kind"] == "fold" for a in first.data["alternatives"])
    assert sum(a["chosen"] for a in first.data["alternatives"]) == 1
    # the main path alone misses solutions; following every alternative finds all 9 = 3 x 3.  The
    # solutions of the two identical nodes form, besides the path, closed curves (the product of the
    # two middle segments of the nodes' S-shaped curves): an alternative may run around one of them
    # and come back to its first branch ("closed_loop", reported with its data), never cycle.
    assert len(path.solutions_at(0.45)) < 9
    statuses = []
    for i in bps:
        for k in range(len(path.events[i].data["alternatives"])):
            if not path.events[i].data["alternatives"][k]["chosen"]:
                res = follow_alternative(system, path, i, k)
                statuses.append(res["status"])
                assert res["status"] in ("completed", "closed_loop")
                if res["status"] == "closed_loop":
                    assert path.events[-1].kind == "closed_loop"
                b0 = path.branches[res["branches"][0]]
                assert b0.parent == path.events[i].branch and b0.origin is not None
                assert path.events[i].data["followed"][str(k)] is res
    sols = path.solutions_at(0.45)
    assert len(sols) == 9 == len(enumerate_solutions(system, 0.45))
    assert_transitions_verify(system, path, 1e-12)
    with pytest.raises(cfcontact.InputError, match="not a branch_point"):
        follow_alternative(system, path, len(path.events) + 3, 0)


def _fail_after_first_branch_point(monkeypatch, ex, status="cycling"):
    """Fault injection: the first walk to step after a branch point (the main walk: a start's
    homotopy has none, the alternatives come later) ends ``status`` there, as a walk that met a
    numerical inconsistency."""
    from cfcontact.solution_path import PathEvent

    real_step = ex._Walk.step
    seen = {}

    def step(self):
        if "fired" not in seen and any(e.kind == "branch_point" for e in self.path.events):
            seen["fired"] = self.branch.index
            self.branch.alpha_exit = self.alpha
            self.path.events.append(PathEvent(status, self.alpha, "injected", self.branch.index, {}))
            return "status", status
        return real_step(self)

    monkeypatch.setattr(ex._Walk, "step", step)
    return seen


@pytest.mark.parametrize("status", ["cycling", "stuck"])
def test_a_path_that_cycles_after_a_branch_point_backtracks_to_an_alternative(monkeypatch, status):
    """A main path that ends "cycling" or "stuck" after a branch point goes back to the latest
    branch point with an untried alternative and follows it (depth first, at most
    MAX_BACKTRACKS tries): the path completes, each try is a "backtrack" event, every transition
    verifies, and every solution on the tree at alpha = 0.45 is one of the enumerated ones."""
    import cfcontact.exact as ex

    system = two_identical_nodes()
    seen = _fail_after_first_branch_point(monkeypatch, ex, status)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert "fired" in seen and path.events[-1].kind == "backtrack"
    assert path.status == "completed" and path.stats["backtracks"] >= 1
    tries = [e for e in path.events if e.kind == "backtrack"]
    assert len(tries) == path.stats["backtracks"] and tries[-1].data["status"] == "completed"
    assert all(t.data["from"] == status for t in tries)
    assert all(t.data["status"] != "completed" for t in tries[:-1])
    last = path.branches[tries[-1].data["branches"][-1]]
    assert last.alpha_exit in (0.0, 1.0)
    assert_transitions_verify(system, path, 1e-12)
    exact = enumerate_solutions(system, 0.45)

    def enumerated(sol):  # one of the enumerated solutions, to 1e-9 in the multipliers
        return min(np.abs(np.concatenate([sol.lam_n - e.lam_n, sol.lam_t - e.lam_t])).max() for e in exact) < 1e-9

    assert all(enumerated(sol) for sol in path.solutions_at(0.45))

    # a tree has followed every alternative: one that completed completes the path
    _fail_after_first_branch_point(monkeypatch, ex, status)
    tree = cfcontact.trace_path(system, 0.0, 1.0, method="exact", tree=True)
    assert tree.status == "completed" and tree.stats["backtracks"] == 1 and tree.events[-1].kind == "backtrack"
    sols = tree.solutions_at(0.45)  # the failed branch is cut: at most the 9, each one of them
    assert len(sols) <= 9 and all(enumerated(x) for x in sols)

    monkeypatch.setattr(ex, "MAX_BACKTRACKS", 0)  # without backtracking the path ends as it failed
    _fail_after_first_branch_point(monkeypatch, ex, status)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert path.status == status and "backtracks" not in path.stats


def test_the_callback_stops_backtracking_and_checkpoints_do_not(monkeypatch):
    """The run's callback also sees the backtracking tries' points: a stop (a time limit, a
    Ctrl-C) ends the try and the backtracking there, the path keeps the status it failed with
    (no resume state: a try cannot be resumed); CHECKPOINT, which a try cannot honour, lets it
    go on to the completed path, and the save is called only by the main run."""
    import cfcontact.exact as ex
    from cfcontact.path import path_stepper
    from cfcontact.options import AlphaSpan, PathOptions
    from cfcontact.stepper import CHECKPOINT

    system = two_identical_nodes()
    seen = _fail_after_first_branch_point(monkeypatch, ex)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", callback=lambda pt: "fired" in seen)
    tries = [e for e in path.events if e.kind == "backtrack"]
    assert path.status == "cycling" and path.resume_state is None
    assert len(tries) == 1 == path.stats["backtracks"] and tries[0].data["status"] == "stopped by callback"
    assert_transitions_verify(system, path, 1e-12)

    seen = _fail_after_first_branch_point(monkeypatch, ex)
    saves = []
    opts = PathOptions()
    stepper = path_stepper(system, AlphaSpan.of(0.0, 1.0, opts), opts, "exact")
    path = stepper.run(lambda pt: CHECKPOINT, lambda p, state: saves.append(("fired" in seen, state)))
    assert path.status == "completed" and path.stats["backtracks"] >= 1
    assert saves and not any(fired for fired, _ in saves)


def test_the_callback_stops_a_tree_and_says_what_is_left():
    """With tree=True the callback sees the alternatives' points too: a stop during them ends the
    tree with a "tree_stopped" event; the main run's status stays, and
    stats["untried_alternatives"] counts the alternatives that follow_alternative can still follow."""
    system = two_identical_nodes()
    main = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    nb = len(main.branches)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", tree=True, callback=lambda pt: pt.branch >= nb)
    assert path.status == "completed" and path.resume_state is None
    assert path.events[-1].kind == "tree_stopped"
    left = [(i, k) for i, e in enumerate(path.events) for k in cfcontact.exact._untried(e)]
    assert left and path.stats["untried_alternatives"] == len(left) == path.events[-1].data["untried"]
    full = cfcontact.trace_path(system, 0.0, 1.0, method="exact", tree=True, callback=lambda pt: None)
    assert "untried_alternatives" not in full.stats and len(full.branches) > len(path.branches)

    # the command line's callback: a stop condition met while the tree grows stops it there
    from cfcontact.run import Runner, StopConditions

    runner = Runner(StopConditions(stop_after_transitions=len(main.transitions) + 1))
    solver = cfcontact.CondensedSolver(system)
    runner.begin(solver)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", tree=True, solver=solver, callback=runner.on_point)
    assert runner.reason.startswith("stopped after") and path.events[-1].kind == "tree_stopped"
    assert path.status == "completed" and len(path.branches) < len(full.branches)


def _traversed_before(monkeypatch, ex, only_rule=False):
    """Make the first branch point of a path look reached a second time: for its decision, the
    branch of the rule's continuation is marked traversed (``only_rule``: and the rule's is the
    only alternative found, as at a vertex whose first crossing looked ordinary; the mark then
    stays until the walk's own check has seen it)."""
    done = []
    if only_rule:
        original = ex._alternatives

        def alternatives(ctx, ln, s, a_star, tied, nxt, d, pivots):
            out = original(ctx, ln, s, a_star, tied, nxt, d, pivots)
            if not done:
                done.append(out[0])
                ctx.visited[ex._digest(nxt.codes.tobytes())] = (d, -1.0)
                return out[:1]
            return out

        revisited = ex._revisited_vertex

        def revisited_vertex(ctx, *args, **kwargs):
            try:
                return revisited(ctx, *args, **kwargs)
            finally:  # the branch was not traversed: a later visit is the first
                ctx.visited.pop(ex._digest(done[0][0].codes.tobytes()), None)

        monkeypatch.setattr(ex, "_alternatives", alternatives)
        monkeypatch.setattr(ex, "_revisited_vertex", revisited_vertex)
    else:
        original = ex._untraversed

        def untraversed(ctx, alternatives, start_key):
            if done or len(alternatives) < 2:
                return original(ctx, alternatives, start_key)
            done.append(alternatives[0])
            key = ex._digest(alternatives[0][0].codes.tobytes())
            ctx.visited[key] = (alternatives[0][1], -1.0)
            try:
                return original(ctx, alternatives, start_key)
            finally:
                del ctx.visited[key]

        monkeypatch.setattr(ex, "_untraversed", untraversed)
    return done


@pytest.mark.parametrize("only_rule", [False, True])
def test_a_vertex_reached_again_is_left_by_an_untraversed_branch(monkeypatch, only_rule):
    """A path may reach a vertex where more than two branches meet a second time (after a loop of
    branches from it back to it; the m = 4000 strip of Part C at F = 30 does, its first crossing
    seen as an ordinary transition); it must then leave by a branch it has not traversed, not
    enter one again ("cycling").  Simulated on the two identical nodes: the rule's continuation at
    the first branch point is marked traversed.  With the point's alternatives found, the walk
    takes another one (``_untraversed``); with only the rule's found, it enumerates the states of
    the crossing's nodes (``_revisited_vertex``).  Either way: no cycling, the chosen branch is
    recorded in a branch_point event, and every stored transition verifies."""
    import cfcontact.exact as ex

    system = two_identical_nodes()
    done = _traversed_before(monkeypatch, ex, only_rule)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert done and path.status in ("completed", "closed_loop"), path.events
    assert path.stats["revisited_vertices"] >= 1
    ev = next(e for e in path.events if e.kind == "branch_point")
    chosen = [a for a in ev.data["alternatives"] if a["chosen"]]
    assert len(chosen) == 1
    rule = canonical_codes(done[0][0].sets, system.friction, system.no_tangent)
    assert not np.array_equal(canonical_codes(InactiveSets.from_dict(chosen[0]["sets"]), system.friction,
                                              system.no_tangent), rule)
    assert ("second time" in ev.message) if only_rule else ("alternative" in ev.message)
    assert not any(e.kind == "cycling" for e in path.events)
    assert_transitions_verify(system, path, 1e-12)


@pytest.mark.slow
def test_a_revisited_vertex_known_less_precisely_than_its_crossings_apart():
    """A vertex reached a second time whose two crossings lie closer together than rounding can
    move its roots: on the m = 1000 strip at F = 30, in a homotopy that moves one node's condensed
    data (tests/data/revisit_strip1000.npz: the branch 5.8e-4 below the vertex, the data at both
    ends), the path crosses at t = 0.16208233814 into a branch where node 998 slips, and after
    four transitions returns at t = 0.16208234087, 2.7e-9 away, through node 997 -- while the
    roots of both nodes' gaps on the branch before are uncertain by 6e-9 and 8e-9.  Locating the
    vertex to within twice the distance of the crossings found no untraversed continuation and
    the walk ended "cycling"; widened by that uncertainty it leaves by the one branch not
    traversed (997 slipping, 998 open, alpha decreasing) and goes on.  Every branch the walk
    enters holds its constraints at its midpoint (a fresh solve of its sets there)."""
    import cfcontact.exact as ex
    from cfcontact import bench_stress
    from cfcontact.options import PathOptions
    from cfcontact.solution_path import SolutionPath

    data = np.load(os.path.join(os.path.dirname(__file__), "data", "revisit_strip1000.npz"))
    system = bench_stress.strip(1000, 30.0, seed=1, kind="uniform")
    opts = PathOptions(max_transitions=40, alpha_min=None, alpha_max=None)
    ctx = ex._Context(system, CondensedSolver(system), opts, 0.0, 1.0, float(opts.tie_rtol),
                      W=np.column_stack([data["w0"], data["w1"]]))
    codes = data["codes"].astype(np.int8)
    path = SolutionPath.for_system(system, "exact", 0.0, 1.0, {})
    ln, s = ex._leave_start(ctx, path, codes, 0.1615, 1)
    status = ex._Walk.begin(ctx, path, ln, s, 0.1615).run()
    assert status == "max_transitions" and len(path.transitions) == 40, path.events[-1].message[:300]
    assert not any(e.kind == "cycling" for e in path.events)
    revisits = [e for e in path.events if e.kind == "branch_point" and e.data.get("revisited")]
    assert ctx.stats["revisited_vertices"] == len(revisits) >= 1
    chosen = [a for a in revisits[0].data["alternatives"] if a["chosen"]]
    assert chosen[0]["states"][997] == "slip-" and chosen[0]["states"][998] == "open"
    for b in path.branches[:-1]:
        mid = 0.5 * (b.alpha_enter + b.alpha_exit)
        assert not ex._not_a_solution(ctx.line(ex._canon(system, b.sets), mid)), (b.index, mid)


def test_dead_end_is_reported_not_raised(monkeypatch):
    import cfcontact.exact as ex

    def no_crossing(*a, **k):
        raise ex._Unresolved("singular", "no branch continues here (test)")

    monkeypatch.setattr(ex, "_resolve", no_crossing)
    monkeypatch.setattr(ex, "ORDINARY_COMPILED", False)  # (every transition through _resolve)
    monkeypatch.setattr(ex, "_enumerated_continuations", lambda *a, **k: [])
    path = cfcontact.trace_path(one_node(2.5, K1), 0.0, 1.0, method="exact")
    assert path.status == "stuck" and path.events[-1].kind == "dead_end"
    assert path.branches[0].alpha_exit == pytest.approx(path.events[-1].alpha)


def test_start_sets_and_bad_start_sets():
    system = one_node(2.5, K1)
    a = 0.45
    p = trace_exact(system, a, 1.0, start_sets=InactiveSets.from_states(["slip+"]))
    assert p.status == "completed" and p.branches[0].sets.states() == ["slip+"]
    with pytest.raises(cfcontact.InputError, match="not consistent"):
        trace_exact(system, 0.9, 1.0, start_sets=InactiveSets.from_states(["open"]))


# ------------------------------------------------------------------ enumeration
def test_enumeration_one_node_matches_closed_form():
    system = one_node(2.5, K1)
    for a in np.linspace(-0.5, 1.5, 41):
        ref = dict(one_node_solutions(K1, 2.5, system.load(a)))
        sols = enumerate_solutions(system, a)
        assert sorted(s.states()[0] for s in sols) == sorted(ref), a
        for s in sols:
            got = np.array([s.u[0], s.u[1], s.lam_n[0], s.lam_t[0]])
            assert np.allclose(got, ref[s.states()[0]], atol=1e-12)


def test_enumeration_at_a_fold_point_finds_the_touching_solutions(one_node_exact):
    system, path = one_node_exact
    for t in path.transitions:
        sols = enumerate_solutions(system, t.alpha)
        y = path.branch_y(t.from_branch, t.alpha)
        assert any(np.abs(s.y - y).max() <= 1e-9 for s in sols)


def _node_beside_a_far_one(far, f_node):
    """The one-node model (K1) with a second, decoupled node (K = I) loaded by (0, far) away from
    its foundation, and the first node loaded by f_node."""
    from cfcontact.system import ContactSystem

    K = np.zeros((4, 4))
    K[:2, :2], K[2:, 2:] = K1, np.eye(2)
    N = np.array([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    T = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    f = np.concatenate([f_node, [0.0, far]])
    return ContactSystem.from_arrays(K, N, T, f, f, 2.5)


def test_enumeration_beside_a_node_that_moves_far():
    """Another node pulled 1e12 away from its foundation: the three solutions of the one-node
    model at 24 degrees are still three (they were compared at the scale of u, and merged), and a
    closed node with lam_n = -1 is no solution although rho |B u| of the far node (1e12) made its
    indicators and verify's measure look like rounding (the force conditions are judged against
    the forces)."""
    d = np.radians(24.0)
    sols = enumerate_solutions(_node_beside_a_far_one(-1e12, [np.cos(d), np.sin(d)]), 0.0)
    assert sorted(s.states()[0] for s in sols) == ["open", "slip+", "stick"]
    assert all(s.states()[1] == "open" for s in sols)
    pulled = enumerate_solutions(_node_beside_a_far_one(-1e12, [0.3, -1.0]), 0.0)
    assert [s.states() for s in pulled] == [["open", "open"]]


def test_enumeration_refuses_large_problems():
    system = random_system(11, 0)
    with pytest.raises(cfcontact.EnumerationTooLarge, match=r"m = 11 contact nodes exceeds the limit max_nodes = 10"):
        enumerate_solutions(system, 0.5)
    with pytest.raises(cfcontact.EnumerationTooLarge, match="max_nodes = 2"):
        enumerate_solutions(random_system(3, 0), 0.5, max_nodes=2)


def test_enumeration_frictionless_unique():
    for seed in range(3):
        system = random_system(4, seed, friction=0.0)
        for a in (0.0, 0.5, 1.0):
            sols = enumerate_solutions(system, a)
            assert len(sols) == 1  # F = 0: a convex problem, one solution
            ref = cfcontact.ssnm(system, a)
            assert np.allclose(sols[0].y, ref.y, atol=1e-10 * np.abs(ref.y).max())


# ------------------------------------------------------------- condensed backend
@pytest.mark.parametrize("store", [True, False])
def test_condensed_matches_full_backend(store):
    rng = np.random.default_rng(3)
    for seed in range(4):
        system = random_system(4, seed, friction=[0.0, 0.7, 1.3, 2.9], extra_dofs=5)
        cond, full = CondensedSolver(system, store_columns=store), DirNeuSolver(system)
        for _ in range(12):
            Z = InactiveSets(rng.random(4) < 0.3, rng.random(4) < 0.4, rng.random(4) < 0.4)
            f = system.load(rng.uniform(-1, 2))
            yc, yf = cond.solve(Z, f), full.solve(Z, f)
            assert np.abs(yc - yf).max() <= 1e-10 * np.abs(yf).max()
        assert cond.stats.factorizations == 1
        u = rng.standard_normal(system.n)
        assert np.allclose(cond.K_times(u), full.K_times(u))


def test_backend_selection():
    from cfcontact.path import select_solver

    system = random_system(3, 0, friction=1.0)
    assert isinstance(select_solver(system, "exact"), CondensedSolver)  # auto: exact -> condensed
    assert isinstance(select_solver(system, "seed"), DirNeuSolver)  # auto: seed -> J(Z), as the seed
    assert isinstance(select_solver(system, "seed", "condensed"), CondensedSolver)
    assert isinstance(select_solver(system, "exact", "full"), DirNeuSolver)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert path.lazy or not path.branches  # the condensed backend stores multipliers only
    with pytest.raises(cfcontact.InputError, match="unknown backend 'dense'; valid: 'auto', 'full', 'condensed'"):
        cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend="dense")


def test_auto_backend_is_condensed_while_its_dense_data_fit_the_memory():
    """Up to m = 2000 the exact method's auto backend is the condensed one on any machine; beyond,
    while 64 bytes per entry of (2m)^2 fit in half the memory (m = 7100 on 24 GiB); the seed
    method's is the full one."""
    from cfcontact.path import auto_backend, machine_memory

    GiB = 2 ** 30
    assert auto_backend("exact", 2000, memory=GiB) == "condensed"
    assert auto_backend("exact", 4000, memory=24 * GiB) == "condensed"
    assert auto_backend("exact", 7000, memory=24 * GiB) == "condensed"
    assert auto_backend("exact", 7200, memory=24 * GiB) == "full"
    assert auto_backend("exact", 4000, memory=4 * GiB) == "full"
    assert auto_backend("seed", 30, memory=24 * GiB) == "full"
    assert machine_memory() > GiB
    with pytest.raises(cfcontact.InputError, match="unknown method 'newton'; valid: 'seed', 'exact'"):
        auto_backend("newton", 30)


def test_exact_with_condensed_backend_one_factorization():
    for seed in range(3):
        system = random_system(5, seed, friction=1.0)
        solver = CondensedSolver(system)
        pc = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver)
        pf = cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend="full")
        assert pc.status == pf.status == "completed"
        assert solver.stats.factorizations == 1 and pc.stats["factorizations"] == 0
        assert branch_keys(pc, 1.0) == branch_keys(pf, 1.0)
        assert np.allclose([t.alpha for t in pc.transitions], [t.alpha for t in pf.transitions], rtol=0, atol=1e-10)
        for bc, bf in zip(pc.branches, pf.branches):
            for a in (0.0, 1.0):
                yc, yf = pc.branch_y(bc, a), pf.branch_y(bf, a)
                assert np.abs(yc - yf).max() <= 1e-10 * np.abs(yf).max()
    # ssnm with the condensed backend
    sol = cfcontact.ssnm(system, 0.3, solver=solver)
    assert cfcontact.verify(system, sol, 0.3, solver=solver).ok(1e-10)


MPI_SCRIPT = os.path.join(HERE, "mpi_condensed.py")


@pytest.mark.mpi
def test_condensed_and_exact_under_mpi(run_mpi, tmp_path):
    out = tmp_path / "mpi.json"
    run_mpi(2, MPI_SCRIPT, str(out), timeout=300)
    got = json.loads(out.read_text())
    serial_out = tmp_path / "serial.json"
    import subprocess

    env = dict(os.environ, PYTHONPATH=os.path.dirname(HERE) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    subprocess.run([sys.executable, MPI_SCRIPT, str(serial_out)], check=True, env=env, timeout=300)
    ref = json.loads(serial_out.read_text())
    assert got["size"] == 2 and ref["size"] == 1
    assert got["keys"] == ref["keys"] and got["kinds"] == ref["kinds"]
    assert np.allclose(got["alphas"], ref["alphas"], rtol=0, atol=1e-10)
    for a, b in zip(got["ys"], ref["ys"]):
        a, b = np.asarray(a), np.asarray(b)
        assert np.abs(a - b).max() <= 1e-10 * np.abs(b).max()
    assert got["nsol"] == ref["nsol"]
    assert got["factorizations"] == 1
    assert got["refine_steps"] >= 1 and ref["refine_steps"] >= 1
    assert got["refined_kinds"] == ref["refined_kinds"] == ref["kinds"]
    assert np.allclose(got["refined_alphas"], ref["refined_alphas"], rtol=0, atol=1e-10)
    # backtracking from a path that failed after a branch point: the same tries and tree
    assert ref["backtrack"]["status"] == "completed" and ref["backtrack"]["tries"][-1] == "completed"
    for key in ("status", "keys", "tries"):
        assert got["backtrack"][key] == ref["backtrack"][key], key
    assert np.allclose(got["backtrack"]["alphas"], ref["backtrack"]["alphas"], rtol=0, atol=1e-10)


# -------------------------------------------------------------- property-based
if given is not None:

    @settings(max_examples=int(os.environ.get("CFCONTACT_HYPOTHESIS_EXAMPLES", "40")), deadline=20000,
              suppress_health_check=[HealthCheck.too_slow])
    @given(m=st.integers(1, 4), friction=st.one_of(st.just(0.0), st.floats(1e-6, 3.0)), seed=st.integers(0, 10_000),
           alphas=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=3), zero_f=st.booleans())
    def test_property_exact_path_solutions_are_enumerated(m, friction, seed, alphas, zero_f):
        system = random_system(m, seed, friction=0.0 if zero_f else friction, extra_dofs=1 + seed % 3)
        path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
        assert path.status in ("completed", "stuck", "cycling", "max_transitions")
        if path.status != "completed":
            assert path.events, "a non-completed run must report an event"
        assert_transitions_verify(system, path)
        for a in alphas:
            ens = enumerate_solutions(system, a)
            for sol in path.solutions_at(a):
                assert any(np.abs(sol.y - z.y).max() <= 1e-8 * max(np.abs(z.y).max(), 1e-300) for z in ens), a
        if m <= 3 and friction > 0 and not zero_f:
            rng = np.random.default_rng(seed)
            cond, full = CondensedSolver(system), DirNeuSolver(system)
            for _ in range(3):
                Z = InactiveSets.from_states(rng.integers(0, 4, m))
                f = system.load(rng.uniform(0, 1))
                try:
                    yf = full.solve(Z, f)
                except cfcontact.SingularSystemError:
                    continue
                assert np.abs(cond.solve(Z, f) - yf).max() <= 1e-9 * np.abs(yf).max()
else:  # pragma: no cover
    def test_property_exact_path_solutions_are_enumerated():
        pytest.skip("hypothesis is not installed (apt-get install python3-hypothesis)")


def test_exact_path_save_load_round_trip(tmp_path):
    system = two_identical_nodes()
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    follow_alternative(system, path, 0, 1)
    back = cfcontact.SolutionPath.load(path.save(tmp_path / "exact.cfpath"))
    assert back.method == "exact" and back.status == path.status
    assert [t.to_dict() for t in back.transitions] == [t.to_dict() for t in path.transitions]
    assert [e.kind for e in back.events] == [e.kind for e in path.events]
    assert back.events[0].data["alternatives"] == path.events[0].data["alternatives"]
    assert [(b.parent, b.origin) for b in back.branches] == [(b.parent, b.origin) for b in path.branches]
    for a in (0.2, 0.45, 0.8):
        s1, s2 = path.solutions_at(a), back.solutions_at(a)
        assert len(s1) == len(s2)
        for x, y in zip(s1, s2):
            assert np.array_equal(x.y, y.y)


# ------------------------------------------------------- callback, stop and resume
def _stop_after(k):
    """A callback that stops once the live path has k transitions (PathPoint.path)."""
    return lambda p: len(p.path.transitions) >= k


def _saved(path, tmp_path, name):
    """The path and its resume state as a checkpoint would give them back (save/load, JSON)."""
    back = cfcontact.SolutionPath.load(path.save(tmp_path / name))
    return {"path": back, "state": json.loads(json.dumps(path.resume_state))}


def assert_same_exact_path(a, b):
    """Same transitions (alpha to 1e-12, kind, changes), branches, points, events and multiplicity
    (to the last bits only: a solver's cache may hold the factorization of an equivalent J(Z))."""
    assert a.status == b.status
    strip = lambda d: {k: v for k, v in d.items() if k not in ("alpha", "bracket", "alpha_enter", "alpha_exit")}  # noqa: E731
    assert [strip(t.to_dict()) for t in a.transitions] == [strip(t.to_dict()) for t in b.transitions]
    assert [strip(br.to_dict()) for br in a.branches] == [strip(br.to_dict()) for br in b.branches]
    for x, y in ((a.alphas, b.alphas), ([t.alpha for t in a.transitions], [t.alpha for t in b.transitions]),
                 ([t.alpha for t in a.folds], [t.alpha for t in b.folds]),
                 ([(br.alpha_enter, br.alpha_exit) for br in a.branches],
                  [(br.alpha_enter, br.alpha_exit) for br in b.branches])):
        np.testing.assert_allclose(x, y, rtol=0, atol=1e-12)
    assert np.array_equal(a.point_branch, b.point_branch)
    np.testing.assert_allclose(a.ys, b.ys, rtol=0, atol=1e-12 * np.abs(b.ys).max())
    assert [(e.kind, e.branch) for e in a.events] == [(e.kind, e.branch) for e in b.events]
    assert a.max_multiplicity()[0] == b.max_multiplicity()[0]


def test_exact_callback_sees_the_live_path():
    system = random_system(4, 1, friction=30.0, extra_dofs=3)
    seen = []
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact",
                                callback=lambda p: seen.append((p.path, len(p.path.transitions), len(p.path.folds))))
    assert path.folds and all(p is path for p, _, _ in seen)
    assert [n for _, n, _ in seen] == list(range(len(path.transitions) + 1)) + [len(path.transitions)]
    assert seen[-1][2] == len(path.folds)
    # stop after the first fold: exactly one fold, stopped at the entry of the branch after it
    stop = cfcontact.trace_path(system, 0.0, 1.0, method="exact", callback=lambda p: len(p.path.folds) >= 1)
    assert stop.status == "stopped by callback" and len(stop.folds) == 1
    assert stop.transitions[-1].kind == "fold" and stop.resume_state["branch"] == len(stop.branches) - 1


@pytest.mark.parametrize("system_name,alpha_start,alpha_end", [
    ("folds", 0.0, 1.0), ("folds", 1.0, 0.0), ("branch_points", 0.0, 1.0)])
def test_exact_resume_equals_uninterrupted(tmp_path, system_name, alpha_start, alpha_end):
    system = random_system(4, 1, friction=30.0, extra_dofs=3) if system_name == "folds" else two_identical_nodes()
    ref = cfcontact.trace_path(system, alpha_start, alpha_end, method="exact")
    assert ref.status == "completed" and len(ref.folds) >= 2
    for k in range(len(ref.transitions) + 1):
        part = cfcontact.trace_path(system, alpha_start, alpha_end, method="exact", callback=_stop_after(k))
        assert part.status == "stopped by callback" and len(part.transitions) == k
        st = part.resume_state
        b = part.branches[st["branch"]]
        assert st["orientation"] == b.orientation and st["alpha"] == b.alpha_enter == part.alphas[-1]
        assert InactiveSets.from_states(st["states"]).equivalent(b.sets, system.friction)
        resumed = cfcontact.trace_path(system, alpha_start, alpha_end, method="exact",
                                       resume=_saved(part, tmp_path, f"p{k}"))
        assert_same_exact_path(resumed, ref)
        assert resumed.resume_state is None
        # the resumed path's counters include the stopped part's (the backend, shared by the runs
        # on this system, may have cached some load data meanwhile)
        assert resumed.stats["dense_solves"] >= part.stats["dense_solves"] > 0


def test_exact_resume_twice_and_budget(tmp_path):
    """Stop, resume, stop again: the state equals that of one run stopped there (the cycle detector
    and the max_transitions budget carry over); the transition cap counts along the whole path."""
    system = random_system(4, 1, friction=30.0, extra_dofs=3)
    direct = cfcontact.trace_path(system, 0.0, 1.0, method="exact", callback=_stop_after(6))
    first = cfcontact.trace_path(system, 0.0, 1.0, method="exact", callback=_stop_after(2))
    second = cfcontact.trace_path(system, 0.0, 1.0, method="exact", callback=_stop_after(6),
                                  resume=_saved(first, tmp_path, "first"))
    s2, sd = second.resume_state, direct.resume_state
    assert {k: v for k, v in s2.items() if k not in ("alpha", "visited")} == \
        {k: v for k, v in sd.items() if k not in ("alpha", "visited")}
    assert abs(s2["alpha"] - sd["alpha"]) <= 1e-12 and len(s2["visited"]) == len(sd["visited"]) == 6
    for (k2, o2, a2), (kd, od, ad) in zip(s2["visited"], sd["visited"]):
        assert (k2, o2) == (kd, od) and np.allclose(a2, ad, rtol=0, atol=1e-12)
    assert_same_exact_path(second, direct)
    capped = cfcontact.trace_path(system, 0.0, 1.0, method="exact", max_transitions=5)
    assert capped.status == "max_transitions"
    part = cfcontact.trace_path(system, 0.0, 1.0, method="exact", max_transitions=5, callback=_stop_after(3))
    resumed = cfcontact.trace_path(system, 0.0, 1.0, method="exact", max_transitions=5,
                                   resume=_saved(part, tmp_path, "capped"))
    assert_same_exact_path(resumed, capped)


def test_exact_resume_with_condensed_backend(tmp_path):
    system = random_system(4, 1, friction=30.0, extra_dofs=3)
    ref = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=CondensedSolver(system))
    part = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=CondensedSolver(system),
                                callback=_stop_after(4))
    resumed = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=CondensedSolver(system),
                                   resume=_saved(part, tmp_path, "c"))
    assert_same_exact_path(resumed, ref)


def test_exact_resume_bad_input(tmp_path):
    system = random_system(4, 1, friction=30.0, extra_dofs=3)
    part = cfcontact.trace_path(system, 0.0, 1.0, method="exact", callback=_stop_after(2))
    seed = cfcontact.trace_path(system, 0.0, 1.0, method="seed", callback=lambda p: p.index == 3)
    with pytest.raises(cfcontact.InputError, match="'seed' path with method 'exact'"):
        cfcontact.trace_path(system, 0.0, 1.0, method="exact", resume={"path": seed, "state": seed.resume_state})
    with pytest.raises(cfcontact.InputError, match="resume must be a dict"):
        cfcontact.trace_path(system, 0.0, 1.0, method="exact", resume={"path": part})
    with pytest.raises(cfcontact.InputError, match="not from 0.0 to 0.5"):
        cfcontact.trace_path(system, 0.0, 0.5, method="exact", resume=_saved(part, tmp_path, "a"))
    bad = _saved(part, tmp_path, "b")
    bad["state"]["orientation"] = -bad["state"]["orientation"]
    with pytest.raises(cfcontact.InputError, match="does not match branch 2"):
        cfcontact.trace_path(system, 0.0, 1.0, method="exact", resume=bad)
    del bad["state"]["visited"]
    with pytest.raises(cfcontact.InputError, match="invalid resume state"):
        cfcontact.trace_path(system, 0.0, 1.0, method="exact", resume=bad)


def test_steep_constraint_missing_zero_by_rounding_is_a_tie():
    """A branch is evaluated at its own reference point (the transition alpha* where the path enters
    it), so a steep constraint that vanishes there (e.g. rho N u of a node that just opened, on a
    stiff-on-soft model) misses zero by its own rounding only, with either sign: that is a tie, so
    the branch continues only in the direction where the constraint grows, and its root behind
    alpha* is no transition.  A negative value beyond rounding stays a violation in both directions."""
    from types import SimpleNamespace

    from cfcontact.exact import OPEN, TIE_RTOL, _exit, _Line, _directions

    codes = np.array([OPEN], dtype=np.int8)  # one open node: constraint -a >= 0
    slope_a = -1.6e7  # a(alpha) = a(0.5) + (alpha - 0.5) * slope_a, so -a grows with alpha
    scale = 1e9  # the local size of the data (multipliers, rho w)
    ctx = SimpleNamespace(lo=0.0, hi=1.0)

    def line(a_half):
        g, dg = np.array([a_half, 0.0, 0.0]), np.array([slope_a, 0.0, 0.0])
        return _Line(codes, b"k", 0.5, np.zeros(2), np.zeros(2), g, dg, scale, 1e7, TIE_RTOL, np.array([0]))

    tol = TIE_RTOL * scale
    for a_half in (0.3 * tol, -0.3 * tol):  # rounding of either sign
        ln = line(a_half)
        assert _directions(ln) == (True, False)
        assert _exit(ctx, ln, 0.5, 1) == (None, None, None)  # nothing vanishes ahead
        a_star, tied, _ = _exit(ctx, ln, 0.5, -1)  # backwards it vanishes at once
        assert abs(a_star - 0.5) <= tol / abs(slope_a) and list(tied) == [0]  # within its rounding
    assert _directions(line(10 * tol)) == (False, False)  # -a = -10 tol < 0: a violation
    assert _directions(line(-10 * tol)) == (True, True)  # positive: consistent both ways


def test_close_roots_of_small_rows_are_not_merged_by_a_large_row():
    """Each indicator's tolerance comes from its own row of the condensed data, not from the largest
    row: here node 0 is pulled away with w_0 = -1e6 (the largest row; it stays open), and nodes 1
    and 2 (rows of size 1) close at alpha = 1/2 and 1/2 + 3e-8.  With the largest row's size for
    every row (1e-13 x 1e6: an uncertainty of 5e-8 in alpha for each root) the two roots were one
    degenerate point, crossed as one transition; with their own sizes they are two transitions at
    their analytic roots (the m = 4000 strip of Part C cycled after such a merge)."""
    m, delta = 3, 3e-8
    n = 2 * m
    K = np.diag([1.0, 1.0, 1.0, 1.0, 1.0, 1.0])  # (u_t, u_n) per node, uncoupled: S = I
    N, T = np.zeros((m, n)), np.zeros((m, n))
    for i in range(m):
        T[i, 2 * i], N[i, 2 * i + 1] = 1.0, 1.0
    f1, f2 = np.zeros(n), np.zeros(n)
    f1[1] = f2[1] = -1e6  # node 0: pulled away, the largest row
    f1[3], f2[3] = -1.0, 1.0  # node 1: f_n = 2 alpha - 1, closes at 1/2
    f1[5], f2[5] = -1.0, 1.0 / (0.5 + delta) - 1.0  # node 2: closes at 1/2 + delta
    system = ContactSystem.from_arrays(K, N, T, f1, f2, 0.0)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=CondensedSolver(system))
    assert path.status == "completed"
    assert [(t.node, t.set, t.kind) for t in path.transitions] == [(1, "nu", "transversal"), (2, "nu", "transversal")]
    assert [len(t.changes) for t in path.transitions] == [1, 1]
    assert abs(path.transitions[0].alpha - 0.5) <= 1e-14
    assert abs(path.transitions[1].alpha - (0.5 + delta)) <= 1e-14


def test_follow_alternative_stopped_by_callback_keeps_the_main_resume_state():
    """A callback that stops an alternative's sub-run ends that sub-run; the path's resume state
    stays the main run's (here: none, the main run completed), so a resume cannot continue the
    alternative as if it were the main run."""
    system = two_identical_nodes()
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert path.status == "completed" and path.resume_state is None
    i = next(i for i, e in enumerate(path.events) if e.kind == "branch_point")
    k = next(k for k, a in enumerate(path.events[i].data["alternatives"]) if not a["chosen"])
    res = follow_alternative(system, path, i, k, callback=lambda point: True)
    assert res["status"] == "stopped by callback" and len(res["branches"]) == 1
    assert path.status == "completed" and path.resume_state is None


def test_trace_tree_finds_every_solution_of_two_identical_nodes():
    """trace_path(..., tree=True) (or trace_tree) follows every alternative of every branch point:
    the tree reachable from the start holds all 3 x 3 solutions of the two identical nodes at
    alpha = 0.45 (enumeration), each branch knows its origin, and no sub-run cycles."""
    system = two_identical_nodes()
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", tree=True)
    assert path.status == "completed" and path.stats["tree"]
    assert len(path.solutions_at(0.45)) == 9 == len(enumerate_solutions(system, 0.45))
    followed = [r["status"] for e in path.events if e.kind == "branch_point"
                for r in e.data.get("followed", {}).values()]
    assert followed and set(followed) <= {"completed", "closed_loop", "joined"}
    for b in path.branches[1:]:
        assert b.parent is not None and b.origin is not None
    assert_transitions_verify(system, path, 1e-12)
    # trace_tree without a solver: trace_path's backend (the condensed one here), not the PETSc one
    from cfcontact.condensed import get_condensed_solver

    condensed_solver = get_condensed_solver(system)
    solves = condensed_solver.stats.dense_solves
    tree = cfcontact.exact.trace_tree(system, 0.0, 1.0)
    assert len(tree.branches) == len(path.branches)
    assert condensed_solver.stats.dense_solves > solves
    # ... and so does the plain trace_exact
    solves = condensed_solver.stats.dense_solves
    plain = cfcontact.trace_exact(system, 0.0, 1.0)
    assert condensed_solver.stats.dense_solves > solves
    main = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert [(t.node, t.set, t.alpha) for t in plain.transitions] == [(t.node, t.set, t.alpha) for t in main.transitions]


@pytest.mark.slow
def test_frictionless_start_is_a_solution_and_starts_the_same_path():
    """Where SSNM from 0 does not converge (a lumped model at F = 30), the start is reached from
    the frictionless solution by a homotopy in the tangential data (7 transitions): the start
    point verifies, it is a point of the path traced from its sets, and a path at F = 0.3 on the
    same model (SSNM converges) never tries it."""
    system = random_system(6, 213, friction=30.0)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend="condensed")
    assert path.status == "completed"
    assert path.stats["start"] == "frictionless" and path.stats["homotopy_transitions"] >= 3
    a, y = next(iter(path.iter_points(indices=[0])))
    assert a == 0.0 and cfcontact.verify(system, y, 0.0).worst() < 1e-10
    first = path.branches[0]
    again = cfcontact.trace_exact(system, 0.0, 1.0, start_sets=first.sets, orientation=first.orientation,
                                  solver=cfcontact.CondensedSolver(system))
    assert [(t.node, t.set, t.kind) for t in again.transitions] == [(t.node, t.set, t.kind) for t in path.transitions]
    assert cfcontact.trace_path(system.with_friction(0.3), 0.0, 1.0, method="exact",
                                backend="condensed").stats["start"] == "ssnm"


def test_start_by_ssnm_with_another_rho_where_both_homotopies_fail_to_be_quick():
    """A strip of 10 x 1, 8 cells across, m = 500, random loads at F = 30: SSNM cycles, the
    homotopy from the frictionless solution is a closed loop back to its start, and the all-open
    homotopy took more than 28 000 transitions in two minutes without reaching t = 1.  SSNM with
    another augmentation parameter (rho x 100) converges; its sets are a solution at the system's
    own rho, which verifies to rounding, and the path from it completes."""
    import cfcontact.exact as ex
    from cfcontact import bench_stress

    system = bench_stress.strip(500, 30.0, 1, "random", cells_across=8)
    solver = cfcontact.CondensedSolver(system)
    assert solver.ssnm_sets(system.load(0.0), 1e-9, ex.START_SSNM_ITERATIONS) is None
    ctx = ex._Context(system, solver, cfcontact.PathOptions(), 0.0, 1.0, cfcontact.PathOptions().tie_rtol)
    assert ex._frictionless_start(ctx, 0.0)[0] is None
    path = cfcontact.trace_exact(system, 0.0, 1.0, solver=solver)
    assert path.status == "completed" and path.stats["start"] == "ssnm_rho"
    assert cfcontact.verify(system, path.point_y(0), 0.0).worst() < 1e-9
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(cfcontact.InputError, match="rho must be a positive finite number"):
            solver.ssnm_sets(system.load(0.0), 1e-9, 5, rho=bad)


@pytest.mark.parametrize("seed, how", [(213, "frictionless"), (103, "homotopy")])
def test_seed_method_and_full_backend_start_where_ssnm_fails(seed, how, monkeypatch):
    """Lumped models at F = 30 where SSNM fails from every restart of start_point with the full
    backend.  The seed method and the exact method on the full PETSc backend raised
    ConvergenceError (the homotopy start was the condensed backend's alone); now both start from
    the solution the exact method reaches in the condensed multipliers, and give the condensed
    run's path.  Model 103's homotopy from the frictionless solution folds back to t = 0; confined
    to t >= 0 it gives up there, and the all-open homotopy starts the path."""
    import cfcontact.exact as ex
    from cfcontact.errors import ConvergenceError
    from cfcontact.ssnm import get_solver
    from cfcontact.start import start_point

    if how == "homotopy":
        monkeypatch.setattr(ex, "FRICTIONLESS_T_MIN", 0.0)
        monkeypatch.setattr(ex, "START_RHO_FACTORS", ())
    system = random_system(6, seed, friction=30.0)
    with pytest.raises(ConvergenceError):
        start_point(system, 0.0, None, cfcontact.PathOptions(), get_solver(system))
    ref = cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend="condensed")
    seq = [(t.node, t.set, t.kind) for t in ref.transitions]
    assert ref.stats["start"] == how and seq
    for path in (cfcontact.trace_path(system, 0.0, 1.0, method="seed"),
                 cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend="full")):
        assert path.status == "completed" and path.stats["start"] == how
        assert path.stats["homotopy_transitions"] == ref.stats["homotopy_transitions"]
        assert [(t.node, t.set, t.kind) for t in path.transitions] == seq
        assert cfcontact.verify(system, path.point_y(0), 0.0).worst() < 1e-10
    events = [e for e in path.events if e.kind == "start_reached"]
    assert not events  # the exact method says it in its stats
    seen = []
    seed_path = cfcontact.trace_path(system, 0.0, 1.0, method="seed", monitor=seen.append)
    (event,) = [e for e in seed_path.events if e.kind == "start_reached"]
    assert event.data == {"how": how, "transitions": ref.stats["homotopy_transitions"]}
    assert seen and seen[-1].transitions == ref.stats["homotopy_transitions"]  # the monitor saw the homotopy
    with pytest.raises(cfcontact.StartInterrupted):
        cfcontact.trace_path(system, 0.0, 1.0, method="seed", monitor=lambda progress: True)


def test_homotopy_start_is_not_bounded_by_the_path_cap():
    """On a long strip (m = 500, F = 0.3) SSNM from 0 does not converge within the start's 25
    iterations; the exact method reaches the start by its homotopy from the frictionless solution
    (390 transitions; from the all-open state it took 532), whatever the path's own
    max_transitions.  The start point verifies."""
    from cfcontact.bench_stress import strip

    system = strip(500, 0.3, seed=0)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", max_transitions=5)
    assert path.status == "max_transitions" and len(path.transitions) == 5
    assert path.stats["start"] == "frictionless" and path.stats["homotopy_transitions"] > 5
    a, y = next(iter(path.iter_points(indices=[0])))
    assert a == 0.0 and cfcontact.verify(system, y, 0.0).worst() < 1e-8


def test_frictionless_nnls_solves_the_frictionless_problem():
    """The frictionless problem's QP by non-negative least squares satisfies its complementarity
    conditions (they determine the solution: S_nn is positive definite); it answers None for a
    matrix that is not positive definite."""
    from cfcontact.condensed import frictionless_nnls

    rng = np.random.default_rng(5)
    A = rng.standard_normal((40, 40))
    S = A @ A.T + 0.1 * np.eye(40)
    w = rng.standard_normal(40)
    lam = frictionless_nnls(S, w)
    gap = S @ lam - w
    scale = np.abs(S).max() * np.abs(lam).max()
    assert lam.min() >= 0.0 and gap.min() > -1e-12 * scale and np.abs(lam * gap).max() < 1e-12 * scale
    assert 5 < (lam > 0).sum() < 35
    assert frictionless_nnls(-S, w) is None


def test_frictionless_start_where_ssnm_cycles_on_the_frictionless_problem(monkeypatch):
    """A random load on the main demo at F = 30 where SSNM cycles both on the problem and on the
    frictionless problem: the frictionless solution comes from non-negative least squares (SSNM
    confirms its sets), and the path starts from it."""
    import cfcontact.condensed as cd
    from cfcontact.demo_models import build_demo

    base = build_demo(30.0)
    f1, f2 = base.loads_numpy()
    scale = max(np.abs(f1).max(), np.abs(f2).max())
    rng = np.random.default_rng(1049)  # (Part D's random load paths, number 49)
    g = [rng.uniform(-1, 1) * f1 + rng.uniform(-1, 1) * f2
         + 0.2 * scale * rng.standard_normal(base.n) * (rng.random(base.n) < 0.05) for _ in range(2)]
    system = base.with_loads(*g)
    calls = []
    nnls = cd.frictionless_nnls
    monkeypatch.setattr(cd, "frictionless_nnls", lambda S, w: calls.append(1) or nnls(S, w))
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert calls and path.status == "completed" and path.stats["start"] == "frictionless"
    assert cfcontact.verify(system, path.point_y(0), 0.0).worst() < 1e-10


def test_frictionless_homotopy_goes_on_through_its_folds_below_t_0(monkeypatch):
    """A slender strip (60 x 1, m = 150) at F = 30: SSNM cycles, and the homotopy from the
    frictionless solution folds back to t = 0 after one transition.  It goes on below t = 0,
    turns again and reaches t = 1 (the monitor sees t < 0; 100 transitions here); the start point
    verifies, and the path from it completes.  Confined to t >= 0 the frictionless homotopy gives
    up at t = 0 and the all-open homotopy follows (it wanders for more than 10^5 transitions on
    this strip: abandoned here by the monitor as soon as it begins)."""
    import cfcontact.exact as ex
    from test_accuracy import slender

    system = slender(30.0)
    seen = []
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", monitor=seen.append)
    assert path.status == "completed" and path.stats["start"] == "frictionless"
    assert {p.stage for p in seen} == {"frictionless"} and min(p.t for p in seen) < 0.0 and seen[-1].t == 1.0
    assert path.stats["homotopy_transitions"] == seen[-1].transitions > 1
    assert cfcontact.verify(system, path.point_y(0), 0.0).worst() < 1e-9
    monkeypatch.setattr(ex, "FRICTIONLESS_T_MIN", 0.0)
    monkeypatch.setattr(ex, "START_RHO_FACTORS", ())
    seen.clear()
    with pytest.raises(cfcontact.StartInterrupted):
        cfcontact.trace_path(system, 0.0, 1.0, method="exact", monitor=lambda p: seen.append(p) or p.stage == "homotopy")
    assert min(p.t for p in seen) == 0.0 and seen[-1].stage == "homotopy"


def test_homotopy_start_keeps_only_its_last_branches_values(monkeypatch):
    """A homotopy start can take 10^5 transitions: its walk keeps the values (multipliers,
    indicators) of its current branch and the one before only, and reaches the same start."""
    import cfcontact.exact as ex

    system = random_system(6, 213, friction=30.0)
    ref = cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend="condensed")
    walks = []
    run = ex._Walk.run
    monkeypatch.setattr(ex._Walk, "run", lambda self, cb=None: walks.append(self) or run(self, cb))
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend="condensed")
    assert path.stats["start"] == "frictionless" and path.stats["homotopy_transitions"] >= 3
    hpath = walks[0].path
    assert len(hpath.branches) > 3 and set(hpath._lam) <= {len(hpath.branches) - 2, len(hpath.branches) - 1}
    assert [t.alpha for t in path.transitions] == [t.alpha for t in ref.transitions]


def test_monitor_sees_and_can_abandon_a_homotopy_start(monkeypatch):
    """A lumped model whose SSNM start does not converge at F = 30, and whose homotopy from the
    frictionless solution, confined to t >= 0, turns back to t = 0 after one transition: the
    start is reached from the all-open state.  The monitor sees every transition of both
    homotopies (each from t = 0, counts rising over both); a monitor that never answers True
    leaves the path as it is without one; a truthy answer abandons the run with StartInterrupted
    carrying the last progress.  A path whose SSNM start converges never calls the monitor."""
    import cfcontact.exact as ex

    monkeypatch.setattr(ex, "FRICTIONLESS_T_MIN", 0.0)
    monkeypatch.setattr(ex, "START_RHO_FACTORS", ())
    system = random_system(6, 103, friction=30.0)
    ref = cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend="condensed")
    assert ref.stats["start"] == "homotopy" and ref.stats["homotopy_transitions"] >= 3
    seen = []
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend="condensed",
                                monitor=lambda p: seen.append(p))
    assert [t.alpha for t in path.transitions] == [t.alpha for t in ref.transitions]
    assert all(isinstance(p, cfcontact.StartProgress) for p in seen)
    stages = [p.stage for p in seen]
    k = stages.index("homotopy")
    assert k > 1 and set(stages[:k]) == {"frictionless"} and set(stages[k:]) == {"homotopy"}
    assert seen[k - 1].t == 0.0 and seen[k].t == 0.0  # the first turned back; the second starts
    assert [p.transitions for p in seen] == sorted(p.transitions for p in seen)
    assert seen[0].t == 0.0 and seen[-1].t == 1.0 and seen[-1].transitions == ref.stats["homotopy_transitions"]
    with pytest.raises(cfcontact.StartInterrupted, match=r"after 2 transition\(s\) of its homotopy") as info:
        cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend="condensed",
                             monitor=lambda p: p.transitions >= 2)
    assert info.value.progress.transitions == 2 and 0.0 < info.value.progress.t < 1.0
    # the start of a path over the friction coefficient too
    seen = []
    assert cfcontact.trace_friction_path(system, 0.0, 30.0, 1.0, monitor=seen.append).stats["start"] == "homotopy"
    assert seen and seen[-1].t == 1.0
    with pytest.raises(cfcontact.StartInterrupted):
        cfcontact.trace_friction_path(system, 0.0, 30.0, 1.0, monitor=lambda p: True)
    # a monitor that cannot be called is refused before any work, whichever the method
    for method in ("exact", "seed"):
        with pytest.raises(cfcontact.InputError, match="monitor must be a function of a StartProgress.*got 5"):
            cfcontact.trace_path(system, 0.0, 1.0, method=method, monitor=5)
    with pytest.raises(cfcontact.InputError, match="monitor must be"):
        cfcontact.trace_friction_path(system, 0.0, 30.0, 1.0, monitor="later")
    easy = random_system(6, 1, friction=0.3)
    calls = []
    assert cfcontact.trace_path(easy, 0.0, 1.0, method="exact", monitor=calls.append).stats["start"] == "ssnm"
    assert calls == []


def test_a_node_whose_data_all_vanish_at_its_transition_verifies():
    """One node without a tangential unknown at zero gap: at its transition lam = 0 and N u =
    (K^-1 f)_n vanishes to the rounding of u = K^-1 f (1e-16 of |u| ~ 1), as every contact
    quantity does; verify measures that against the load, the size equilibrium is measured
    against, not against the contact quantities alone (which made it 1.0 on a correct point)."""
    from cfcontact.report import worst_residual

    K = np.array([[1.0, 0.75], [0.75, 1.5]])
    system = ContactSystem.from_arrays(K, [[0.0, 1.0]], [[0.0, 0.0]], [-1.5, 0.25], [-0.75, -1.3], 1.0)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    (t,) = path.transitions
    (sol,) = path.solutions_at(t.alpha)
    u = np.linalg.solve(K, system.load(t.alpha))  # the independent solution: lam = 0
    assert np.allclose(sol.u, u, rtol=0, atol=1e-15) and not sol.lam_n.any()
    assert cfcontact.verify(system, sol, t.alpha).worst() < 1e-14
    assert worst_residual(system, path) < 1e-14


@pytest.mark.parametrize("seed", range(6))
def test_the_solutions_at_an_apex_are_the_same_lazy_formed_and_reloaded(seed, tmp_path):
    """A load reversed through zero at alpha = 1/3 (f2 = -2 f1, no gap), which no double holds: at
    the doubles around it the path has the one solution y = (1 - 3 alpha) y(f1) whether its branches
    are lazy (decided from their multipliers), formed (from u, whose rounding there is that of the
    data, not of y) or saved and loaded (a formed branch counted 0 solutions there)."""
    base = random_system(4, seed, friction=[0.0, 0.3, 0.3, 1.0])
    f1 = base.loads_numpy()[0]
    system = base.with_loads(f1, -2.0 * f1)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert path.status == "completed"
    apex = min((t.alpha for t in path.transitions), key=lambda a: abs(a - 1.0 / 3.0))
    assert apex == pytest.approx(1.0 / 3.0, abs=1e-15)
    alphas = [apex + k * np.spacing(apex) for k in (-8, -1, 0, 1, 8)]
    lazy = [path.multiplicity(a) for a in alphas]
    path.form()
    formed = [path.multiplicity(a) for a in alphas]
    path.save(str(tmp_path / "apex"))
    loaded = cfcontact.SolutionPath.load(str(tmp_path / "apex"))
    assert lazy == formed == [loaded.multiplicity(a) for a in alphas] == [1] * 5
    for a in alphas:
        (sol,) = loaded.solutions_at(a)
        assert np.abs(sol.y).max() <= 1e-13 * np.abs(path.solutions_at(0.0)[0].y).max()
