"""Branches of the friction modules that the rest of the suite does not run: bad input of the
friction paths and maps, the caps and callbacks of the steppers in F, degenerate points in F (a
start on a facet, a cusp on the path, two nodes changing at one F), the probes of the structure
sweep that jump over an event or find no usable path, enumeration through a singular piece.

References are independent of the code under test: the one-node closed form of method.md
(``reference.one_node_solutions``), products of it for two decoupled nodes, enumeration, the
uncapped path, ``trace_exact`` at a sampled F."""

import copy
import json
import os

import numpy as np
import pytest
import scipy.linalg

from cfcontact import fmap
from cfcontact.case import CaseError, build_system, load_case
from cfcontact.condensed import get_condensed_solver
from cfcontact.critical import critical_friction
from cfcontact.enumerate import enumerate_solutions
from cfcontact.errors import InputError
from cfcontact.exact import trace_exact
from cfcontact.fmap import critical_friction_path, fold_curves, multiplicity_map
from cfcontact.friction import friction_system, trace_friction_path, worst_residual_friction
from cfcontact.lumped import one_node, random_system
from cfcontact.map_run import default_friction_range, map_case
from cfcontact.system import ContactSystem
from reference import alpha_of_tan, one_node_solutions

K1 = np.array([[1.0, 0.5], [0.5, 1.0]])  # the cusp (k_tt / k_tn) at F = 2
FOLDS_CASE = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "demos", "cases", "folds.toml")


def two_nodes(Ka, Kb, fa1, fa2, fb1=None, fb2=None, friction=1.0):
    """Two decoupled one-node problems in one system (block-diagonal K): its solutions are the
    pairs of the two nodes' closed-form solutions."""
    K = scipy.linalg.block_diag(Ka, Kb)
    T = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    N = np.array([[0, 1.0, 0, 0], [0, 0, 0, 1.0]])
    f1 = np.concatenate([fa1, fa1 if fb1 is None else fb1])
    f2 = np.concatenate([fa2, fa2 if fb2 is None else fb2])
    return ContactSystem.from_arrays(K, N, T, f1, f2, friction)


def unit(deg):
    return np.array([np.cos(np.radians(deg)), np.sin(np.radians(deg))])


# ------------------------------------------------------------------ bad input
def test_friction_path_refuses_bad_input_and_seed_resume():
    """trace_friction_path: InputError naming the bad value for a non-system, a non-number, a
    solver of another backend, a resume of a seed path or with a state that is not one; a seed
    path stopped by its callback is "stopped by callback" without a resume state."""
    system = one_node(2.5, K1)
    with pytest.raises(InputError, match="must be a ContactSystem, got str"):
        trace_friction_path("system", 0.5, 0.0, 1.0)
    with pytest.raises(InputError, match="must be numbers, got 'half'"):
        trace_friction_path(system, "half", 0.0, 1.0)
    with pytest.raises(InputError, match="condensed backend"):
        trace_friction_path(system, 0.5, 0.0, 1.0, solver=object())
    seed = trace_friction_path(system, alpha_of_tan(system, 0.6), 0.0, 4.0, method="seed",
                               callback=lambda p: p.alpha > 1.0)
    assert seed.status == "stopped by callback" and seed.resume_state is None
    assert 1.0 < seed.alphas[-1] < 4.0
    with pytest.raises(InputError, match="seed method in F cannot resume"):
        trace_friction_path(system, 0.5, 0.0, 4.0, method="seed", resume={"path": seed, "state": {}})
    with pytest.raises(InputError, match="started exact FrictionPath"):
        trace_friction_path(system, 0.5, 0.0, 4.0, resume={"path": seed, "state": {}})
    exact = trace_friction_path(system, 0.5, 0.0, 4.0, callback=lambda p: True)
    with pytest.raises(InputError, match="invalid resume state .*KeyError\\('codes'\\)"):
        trace_friction_path(system, 0.5, 0.0, 4.0, resume={"path": exact, "state": {"branch": 0}})


def test_map_functions_refuse_bad_input(tmp_path):
    """multiplicity_map, critical_friction_path, fold_curves, enumerate_solutions and map_case:
    typed errors naming the bad value (alpha range, friction range, start mode, grid, load
    length, the case's friction range and grid size), before any path is traced."""
    system = one_node(2.5, K1)
    with pytest.raises(InputError, match="condensed backend"):
        multiplicity_map(system, [0.0, 1.0], [1.0], solver=object())
    with pytest.raises(InputError, match=r"alpha_range must be \(alpha_start, alpha_end\), got 0.5"):
        critical_friction_path(system, 0.5, F_max=3.0)
    with pytest.raises(InputError, match=r"alpha_range must be \(alpha_start, alpha_end\), got \(0, 0.5, 1\)"):
        fold_curves(system, (0.0, 3.0), (0, 0.5, 1))
    with pytest.raises(InputError, match=r"friction range must be an interval .* got \(3.0, 1.0\)"):
        critical_friction_path(system, F_min=3.0, F_max=1.0)
    with pytest.raises(InputError, match="F_min = -1.0"):
        critical_friction_path(system, F_min=-1.0, F_max=1.0)
    with pytest.raises(InputError, match="got -1.0"):
        fold_curves(system, (-1.0, 1.0))
    with pytest.raises(InputError, match="start must be 'continued' or 'ssnm', got 'first'"):
        multiplicity_map(system, [0.0, 1.0], [1.0], start="first")
    with pytest.raises(InputError, match="frictions .*-0.5"):
        multiplicity_map(system, [0.0, 1.0], [1.0, -0.5])
    with pytest.raises(InputError, match="alphas .*nan"):
        multiplicity_map(system, [0.0, np.nan], [1.0])
    with pytest.raises(InputError, match="alphas .*empty"):
        multiplicity_map(system, [], [1.0])
    with pytest.raises(InputError, match="length 3, expected n = 2"):
        enumerate_solutions(system, f=np.ones(3))
    case = load_case(FOLDS_CASE)
    with pytest.raises(CaseError, match="need 0 <= F0 < F1, got 3.0 1.0"):
        map_case(case, str(tmp_path / "m"), (3.0, 1.0))
    with pytest.raises(CaseError, match="--frictions: need 2..100000 grid points, got 1"):
        map_case(case, str(tmp_path / "m"), (0.0, 1.0), n_frictions=1)
    assert not (tmp_path / "m").exists()


def test_map_of_a_case_defaults_to_the_range_up_to_its_friction(tmp_path):
    """map_case without a friction range: F from 0 to the case's friction (30 for folds.toml; the
    largest of per-node values; at least 1), marked at the case's friction; the map's rows are
    the alpha-paths at those F (compared with trace_exact at F = 30)."""
    case = load_case(FOLDS_CASE)
    assert case["contact"]["friction"] == 30.0
    small, per_node = copy.deepcopy(case), copy.deepcopy(case)
    small["contact"]["friction"], per_node["contact"]["friction"] = 0.5, [0.2, 3.0, 1.0]
    assert default_friction_range(small) == (0.0, 1.0) and default_friction_range(per_node) == (0.0, 3.0)
    res = map_case(case, str(tmp_path / "m"), None, n_frictions=2, n_alphas=5, curves=False)
    data = json.loads((tmp_path / "m" / "map.json").read_text())
    assert data["frictions"] == [0.0, 30.0] and data["marks"] == [30.0] and res["untraced"] == []
    path = trace_exact(build_system(case), 0.0, 1.0)  # (the case's system is at F = 30)
    assert len(path.folds) > 0 and data["folds"][1] == pytest.approx([t.alpha for t in path.folds], abs=1e-10)


# ------------------------------------------------------------------ caps and callbacks
def test_transition_and_step_caps_stop_where_the_full_path_continues():
    """max_transitions = 1 (an override keyword): the exact path stops with that status at the
    full path's second transition (to rounding), the seed path at the same F within h_min;
    max_steps = 5 stops the seed after 5 steps.  A callback that stops the exact run at the
    path's last point leaves it "completed" (nothing is left to resume)."""
    system = random_system(3, 2, friction=1.0, coupling=8.0, extra_dofs=0)
    full = trace_friction_path(system, 0.5, 40.0, 0.0)
    assert full.status == "completed" and len(full.transitions) == 3
    capped = trace_friction_path(system, 0.5, 40.0, 0.0, max_transitions=1)
    assert capped.status == "max_transitions" and len(capped.transitions) == 1
    (ev,) = capped.events
    assert ev.kind == "max_transitions" and abs(ev.alpha - full.transitions[1].alpha) <= 1e-12 * 40
    seed = trace_friction_path(system, 0.5, 40.0, 0.0, method="seed", max_transitions=1)
    assert seed.status == "max_transitions" and len(seed.transitions) == 1
    assert abs(seed.events[0].alpha - full.transitions[1].alpha) <= seed.options["h_min"]
    short = trace_friction_path(system, 0.5, 40.0, 0.0, method="seed", max_steps=5)
    assert short.status == "max_steps" and 0.0 < 40.0 - short.events[0].alpha < 1.0
    last = trace_friction_path(system, 0.5, 40.0, 0.0, callback=lambda p: p.alpha == 0.0)
    assert last.status == "completed" and last.resume_state is None
    assert [t.alpha for t in last.transitions] == [t.alpha for t in full.transitions]


# ------------------------------------------------------------------ degenerate points in F
def test_start_on_a_degenerate_point_stops_there():
    """One node (K1) loaded on the ray tan = k_tn / k_tt = 0.5: the stick solution exists for F >= 2
    only (closed form), and at F = 2 its neighbour slip+ is singular.  From F = 2 down, the start
    (stick) cannot be left: the path must stop there.  It went on along the stick branch to
    F = 0 and said "completed" with points 100 % off (1)-(3)."""
    f = np.array([1.0, 0.5])
    system = one_node(2.5, K1, f1=f, f2=f)
    assert [k for k, _ in one_node_solutions(K1, 1.5, f)] == ["slip+"]  # (the grazing solution only)
    path = trace_friction_path(system, 0.3, 2.0, 0.0)
    assert path.status == "stuck" and [e.kind for e in path.events] == ["start_degenerate"]
    assert np.all(path.alphas == 2.0)
    assert worst_residual_friction(system, path) < 1e-12
    assert path.solutions_at(1.5) == []
    seed = trace_friction_path(system, 0.3, 2.0, 0.0, method="seed")  # (it turns back and forth at F = 2)
    assert seed.status == "cycling" and np.all(seed.alphas == 2.0)


def test_start_on_a_facet_leaves_it_by_the_lexicographic_rule():
    """K = [[1, 0.25], [0.25, 1]] loaded at tan = 0.5: stick holds for F >= 2 and slip+ for F <= 2
    (closed form).  From F = 2 down the start (stick, on its facet) pivots at once into slip+; up,
    it stays stick.  The points agree with the closed-form solutions."""
    K = np.array([[1.0, 0.25], [0.25, 1.0]])
    f = np.array([1.0, 0.5])
    system = one_node(2.5, K, f1=f, f2=f)
    down = trace_friction_path(system, 0.3, 2.0, 0.0)
    up = trace_friction_path(system, 0.3, 2.0, 4.0)
    assert down.status == up.status == "completed"
    assert [b.sets.states() for b in down.branches] == [["slip+"]] and down.stats["start_pivots"] == 1
    assert [b.sets.states() for b in up.branches] == [["stick"]]
    for path, F in ((down, 0.7), (down, 1.9), (up, 2.5), (up, 3.9)):
        (sol,) = path.solutions_at(F)
        ((state, ref),) = one_node_solutions(K, F, f)
        assert sol.states() == [state]
        assert np.allclose([sol.u[0], sol.u[1], sol.lam_n[0], sol.lam_t[0]], ref, atol=1e-12)


def test_cusp_on_a_friction_path_is_a_dead_end():
    """The same ray load on K1 from F = 3 down: stick ends at F = 2 (closed form), where the only
    neighbour branch, slip+, is singular: the exact path stops "stuck" (dead end) at F = 2 to
    rounding; the seed method folds there within h_min."""
    f = np.array([1.0, 0.5])
    system = one_node(2.5, K1, f1=f, f2=f)
    path = trace_friction_path(system, 0.3, 3.0, 0.0)
    assert path.status == "stuck" and [e.kind for e in path.events] == ["dead_end"]
    assert abs(path.events[0].alpha - 2.0) <= 1e-12 and path.events[0].data["reason"] == "singular"
    assert worst_residual_friction(system, path) < 1e-12
    seed = trace_friction_path(system, 0.3, 3.0, 0.0, method="seed")
    assert [t.kind for t in seed.transitions] == ["fold"]
    assert abs(seed.transitions[0].alpha - 2.0) <= seed.options["h_min"]


def test_two_nodes_changing_at_one_friction():
    """Two identical decoupled nodes under one load at tan = 0.6: both go from slip+ to stick at
    F = 1/0.6 (closed form), a degenerate point in F.  The exact method crosses it in one
    transition of two pivots and its solutions are the pairs of closed-form solutions; the seed
    method, which changes one node at a time, is stuck there (no single change is consistent)."""
    fa = unit(np.degrees(np.arctan(0.6)))
    system = two_nodes(K1, K1, fa, fa)
    for F0, F1 in ((0.0, 4.0), (4.0, 0.0)):
        path = trace_friction_path(system, 0.0, F0, F1)
        assert path.status == "completed" and path.stats["degenerate_points"] == 1
        (t,) = path.transitions
        assert abs(t.alpha - 1 / 0.6) <= 1e-12 * 4 and len(t.pivots) == 2 and len(t.changes) == 2
        for F in (0.5, 1.6, 1.7, 3.5):
            (sol,) = path.solutions_at(F)
            ((state, ref),) = one_node_solutions(K1, F, fa)
            assert sol.states() == [state, state]
            y = np.array([sol.u[0], sol.u[1], sol.lam_n[0], sol.lam_t[0]])
            assert np.allclose(y, ref, atol=1e-12)
            assert np.allclose([sol.u[2], sol.u[3], sol.lam_n[1], sol.lam_t[1]], ref, atol=1e-12)
    seed = trace_friction_path(system, 0.0, 0.0, 4.0, method="seed")
    assert seed.status == "stuck" and [e.kind for e in seed.events] == ["no_indicator"]
    assert abs(seed.events[0].alpha - 1 / 0.6) <= 1e-3


def test_enumeration_through_a_singular_piece_at_the_cusp():
    """K = [[2, 1], [1, 1]] (exact inverse) at F = k_tt / k_tn = 2: the slip+ piece of the node is
    exactly singular (det = S_nn + F S_nt = 0), so the batched solve of the pieces fails as a whole;
    it falls back to one solve per piece, drops the singular one and finds the closed-form
    solutions; two decoupled such nodes (16 pieces, 7 singular) give the pairs of them."""
    K = np.array([[2.0, 1.0], [1.0, 1.0]])
    system = one_node(2.0, K)
    S = get_condensed_solver(system).S  # (lam_n, lam_t) order
    assert S[0, 0] + 2.0 * S[0, 1] == 0.0
    pair = two_nodes(K, K, unit(15.0), unit(35.0), friction=2.0)
    for a in (0.0, 0.3, 0.6, 1.0):
        f = system.load(a)
        ref = one_node_solutions(K, 2.0, f)
        got = enumerate_solutions(system, a)
        assert sorted(s.states()[0] for s in got) == sorted(k for k, _ in ref)
        for s in got:
            want = dict(ref)[s.states()[0]]
            assert np.allclose([s.u[0], s.u[1], s.lam_n[0], s.lam_t[0]], want, atol=1e-12)
        assert len(enumerate_solutions(pair, a)) == len(ref) ** 2


# ------------------------------------------------------------------ critical friction
def test_critical_configuration_text_and_an_uncoupled_node():
    """critical_friction's result as text: the bound k_tt/|k_tn| = 2 of K1 with its piece; a node
    without normal-tangential coupling (k_tn = 0) is unique for every F (closed form): no sign
    change, inf."""
    crit = critical_friction(one_node(2.5, K1))
    assert str(crit) == "F = 2 (0:slip+; 2 configurations scanned)"
    free = critical_friction(one_node(2.5, np.diag([1.0, 2.0])))
    assert free.friction == np.inf and str(free) == "no sign change in 2 configurations"
    uncoupled = critical_friction_path(one_node(2.5, np.diag([1.0, 2.0])), F_max=10.0)
    assert uncoupled.stopped_at is None and str(uncoupled) == "no fold in the friction range"


def test_sweep_from_the_cusp_itself_and_with_probes_that_jump_over_events(monkeypatch):
    """The one-node path first folds for F > k_tt/k_tn = 2 (closed form).  A sweep starting exactly
    at F = 2 probes at an event (the probe is moved up) and reports 2, at the range start.  With a
    probe step so coarse that the probe after the event at F = 1.428 (the moving fold ray enters
    the alpha range) lands beyond 2, the chain found there starts above the last event: the gap
    below it is probed, and the critical friction, the cusp and the fold curves are the closed
    form's still."""
    system = one_node(2.5, K1)
    crit = critical_friction_path(system, F_min=2.0, F_max=3.0)
    assert crit.friction == 2.0 and crit.below_range and crit.tests[0][0] > 2.0
    monkeypatch.setattr(fmap, "PROBE_STEP", 0.2)
    crit = critical_friction_path(system, F_max=3.0)
    assert abs(crit.friction - 2.0) <= 1e-8 and abs(crit.alpha - alpha_of_tan(system, 0.5)) <= 1e-8
    assert any(F > 2.0 for F, _, _ in crit.tests[:2])  # (a probe above the cusp came before the gap's)
    fc = fold_curves(system, (0.0, 3.0))
    ((a_c, F_c),) = fc.cusps
    assert abs(F_c - 2.0) <= 1e-8 and abs(a_c - alpha_of_tan(system, 0.5)) <= 1e-8
    assert np.allclose(fc.alphas_at(2.6), sorted([alpha_of_tan(system, 0.5), alpha_of_tan(system, 1 / 2.6)]),
                       atol=1e-10)


def test_a_sweep_that_stops_early_does_not_claim_there_is_no_fold(monkeypatch):
    """Two identical decoupled nodes under one load: every transition of the alpha-path is two
    nodes at once, no probe of the sweep is usable and it stops at F = 0.  The alpha-path traced
    at F = 2.5 has folds, yet critical_friction_path said "no fold in the friction range" (the
    stop only in ``notes``).  Now: ``stopped_at`` = 0 and the text says where and why it stopped.
    The same for a sweep stopped by the probe cap (one node, 2 probes: it covered F <= 2)."""
    system = two_nodes(K1, K1, unit(15.0), unit(35.0))
    assert trace_exact(friction_system(system, 2.5), 0.0, 1.0).folds
    crit = critical_friction_path(system, F_max=3.0)
    assert crit.friction == np.inf and crit.stopped_at == 0.0
    text = str(crit)
    assert "no fold in the friction range" not in text and "no usable probe" in text and "up to 0" in text
    assert crit.to_dict()["stopped_at"] == 0.0
    fc = fold_curves(system, (0.0, 3.0))
    assert fc.critical.stopped_at == 0.0 and any("the sweep stops" in n for n in fc.notes)
    monkeypatch.setattr(fmap, "MAX_PROBES", 2)
    crit = critical_friction_path(one_node(2.5, K1), F_max=3.0)
    assert crit.friction == np.inf and abs(crit.stopped_at - 2.0) <= 1e-12
    assert "probe cap 2 reached" in str(crit) and "no fold in the friction range" not in str(crit)
