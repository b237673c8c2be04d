"""Rarely taken branches of the exact method, the start and the solution path: its fallbacks (a
start at a transition point, the start by enumeration, the enumeration where the lexicographic
rule fails), the windowed multiplicity, the resume and save/load checks, each against an
independent reference (the closed-form one-node solutions of method.md, the analytic wedge rays,
the path traced without the fallback)."""

import json
import os

import numpy as np
import pytest

import cfcontact
from cfcontact.exact import follow_alternative, trace_exact
from cfcontact.lumped import one_node, random_system
from cfcontact.ssnm import InactiveSets
from cfcontact.system import ContactSystem
from reference import one_node_solutions
from test_path import alpha_of_direction

K1 = np.array([[1.0, 0.5], [0.5, 1.0]])
F1 = 2.5  # with K1: three solutions between the wedge rays atan(0.4) and atan(0.5) (method.md)


@pytest.fixture(scope="module")
def wedge():
    """The one-node model of method.md, its exact path over [0, 1] and the analytic fold alphas
    (lo, hi) of the wedge rays."""
    system = one_node(F1, K1)
    rays = sorted([alpha_of_direction(system, np.arctan(0.4)), alpha_of_direction(system, np.arctan(0.5))])
    return system, cfcontact.trace_path(system, 0.0, 1.0, method="exact"), rays


def assert_one_node_solutions(system, path, expected):
    """The path's solutions at each alpha of ``expected`` {alpha: states} have those states and the
    closed-form values."""
    for a, states in expected.items():
        ref = dict(one_node_solutions(K1, F1, system.load(a)))
        sols = path.solutions_at(a)
        assert sorted(s.states()[0] for s in sols) == sorted(states), a
        for sol in sols:
            got = np.array([sol.u[0], sol.u[1], sol.lam_n[0], sol.lam_t[0]])
            np.testing.assert_allclose(got, ref[sol.states()[0]], rtol=0, atol=1e-12)


# ------------------------------------------------------------------ bad arguments
def test_entry_points_name_the_bad_argument(wedge, tmp_path):
    """Each entry point refuses a wrong argument with an InputError that names it and its value:
    a system that is no ContactSystem, an orientation that is not +-1, start sets of another
    length, a callback that cannot be called, an alternative index out of range or not an
    integer (a string, a float, None: a bare TypeError before), a component
    index out of range, a multiplicity window that is empty or not finite, an empty save folder."""
    system, path, _ = wedge
    with pytest.raises(cfcontact.InputError, match="system must be a ContactSystem, got ndarray"):
        cfcontact.trace_path(np.eye(2), 0.0, 1.0, method="exact")
    with pytest.raises(cfcontact.InputError, match="orientation must be \\+1 or -1, got 0"):
        trace_exact(system, 0.0, 1.0, orientation=0)
    for bad in (1.5, "1", True):  # (1.5 had been truncated to 1)
        with pytest.raises(cfcontact.InputError, match=f"orientation must be \\+1 or -1, got {bad!r}"):
            trace_exact(system, 0.0, 1.0, orientation=bad)
    two = InactiveSets.from_states(["open", "open"])
    with pytest.raises(cfcontact.InputError, match="start_sets must be InactiveSets of length m = 1"):
        trace_exact(system, 0.0, 1.0, start_sets=two)
    with pytest.raises(cfcontact.InputError, match="callback must be a function.*got 3"):
        trace_exact(system, 0.0, 1.0, callback=3)
    tree = cfcontact.trace_path(_two_identical_nodes(), 0.0, 1.0, method="exact")
    k = next(i for i, e in enumerate(tree.events) if e.kind == "branch_point")
    n_alt = len(tree.events[k].data["alternatives"])
    with pytest.raises(cfcontact.InputError, match=f"alternative {n_alt} out of range \\(0..{n_alt - 1}\\)"):
        follow_alternative(_two_identical_nodes(), tree, k, n_alt)
    for ev, alt, bad in ((k, "1", "alternative must be an integer, got '1'"), (str(k), 0, "event_index"),
                         (k, 1.5, "got 1.5"), (k, None, "got None")):
        with pytest.raises(cfcontact.InputError, match=bad):  # (was TypeError from a comparison or an index)
            follow_alternative(_two_identical_nodes(), tree, ev, alt)
    with pytest.raises(cfcontact.InputError, match="component index 4 out of range \\(0..3\\)"):
        path.component(4)
    for bad in ((0.5, 0.5), (0.0, float("inf"))):
        with pytest.raises(cfcontact.InputError, match="alpha_range must be \\(lo, hi\\) with finite lo < hi"):
            path.multiplicity_intervals(alpha_range=bad)
    with pytest.raises(cfcontact.InputError, match="save needs a folder name"):
        path.save("  ")


def _two_identical_nodes():
    """Two identical decoupled nodes (as in test_exact.py): branch points at every transition."""
    K = np.kron(np.eye(2), K1)
    N = np.array([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    T = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    f1, f2 = np.tile([np.cos(0.2), np.sin(0.2)], 2), np.tile([np.cos(0.6), np.sin(0.6)], 2)
    return ContactSystem.from_arrays(K, N, T, f1, f2, F1)


# ------------------------------------------------------------------ start
def test_start_at_a_fold_point_leaves_by_the_lexicographic_rule(wedge):
    """Started exactly at the fold on the ray atan(0.5) (the analytic alpha) on the open branch
    in direction +1: the open branch's gap vanishes there and decreases, so the start's own
    branch does not leave the point; the rule pivots once onto the slip+ branch, backward (a
    fold).  The path then is the rest of the path from 0: slip+ down to the other ray, a fold to
    stick, stick up to 1, its solutions the closed-form ones."""
    system, full, (lo, hi) = wedge
    # which ray ends the open branch: the one where the open solution stops existing
    a0 = full.transitions[0].alpha
    assert abs(a0 - hi) <= 1e-12
    path = trace_exact(system, hi, 1.0, start_sets=InactiveSets.from_states(["open"]), orientation=1,
                       options=cfcontact.PathOptions(alpha_min=0.0))
    assert path.status == "completed" and path.stats["start_pivots"] == 1
    assert [(b.sets.states(), b.orientation) for b in path.branches] == [(["slip+"], -1), (["stick"], 1)]
    assert [t.kind for t in path.transitions] == ["fold"] and abs(path.transitions[0].alpha - lo) <= 1e-12
    # (the open branch, which ends at the start point, is not on this path)
    assert_one_node_solutions(system, path, {hi - 1e-9: ["slip+", "stick"], 0.5 * (lo + hi): ["slip+", "stick"],
                                             lo + 1e-9: ["slip+", "stick"], 0.7: ["stick"], 1.0: ["stick"]})


def test_start_by_enumeration_where_every_other_start_fails(wedge, monkeypatch):
    """Where SSNM and the exact method's homotopies all fail to give a start (forced here), a
    small problem starts from enumeration: at an alpha inside the wedge the event lists the three
    closed-form solutions, the path starts on the first of them and its start point is that
    solution.  A problem with more than START_ENUMERATION_MAX_NODES nodes raises
    ConvergenceError naming m instead."""
    import cfcontact.exact as ex

    system, _, (lo, hi) = wedge
    monkeypatch.setattr(ex, "_ssnm_start", lambda ctx, alpha, y0: None)
    monkeypatch.setattr(ex, "_reach_start", lambda ctx, alpha, monitor=None: (None, "homotopy", 0))
    a = 0.5 * (lo + hi)
    path = trace_exact(system, a, 1.0)
    assert path.status == "completed" and path.stats["start"] == "enumeration"
    (event,) = [e for e in path.events if e.kind == "start_by_enumeration"]
    ref = dict(one_node_solutions(K1, F1, system.load(a)))
    listed = [s["states"][0] for s in event.data["solutions"]]
    assert sorted(listed) == sorted(ref) == ["open", "slip+", "stick"]
    assert path.branches[0].sets.states() == [listed[0]]
    y = path.point_y(0)
    np.testing.assert_allclose([y[0], y[1], y[2], y[3]], ref[listed[0]], rtol=0, atol=1e-12)
    big = random_system(ex.START_ENUMERATION_MAX_NODES + 1, 0, friction=1.0)
    with pytest.raises(cfcontact.ConvergenceError, match=f"m = {big.m}"):
        trace_exact(big, 0.0, 1.0)


def test_a_start_the_rule_cannot_leave_is_reported_and_the_walk_crosses_it(wedge, monkeypatch):
    """The fold start of the test above with the lexicographic rule failing there (forced): a
    start_degenerate event says so, the path starts on the open branch itself, which ends at once
    at the same point, and the walk crosses it onto the same branches as the rule (slip+ down to
    the other ray, stick up to 1), with the closed-form solutions."""
    import cfcontact.exact as ex

    system, _, (lo, hi) = wedge
    rule = ex._resolve

    def fails_at_start(*a, **k):
        if k.get("start"):
            raise ex._Unresolved("singular", "the rule fails at the start (test)")
        return rule(*a, **k)

    monkeypatch.setattr(ex, "_resolve", fails_at_start)
    path = trace_exact(system, hi, 1.0, start_sets=InactiveSets.from_states(["open"]), orientation=1,
                       options=cfcontact.PathOptions(alpha_min=0.0))
    assert path.status == "completed"
    assert [e.kind for e in path.events] == ["start_degenerate"] and "(test)" in path.events[0].message
    assert [(b.sets.states(), b.orientation) for b in path.branches] == [(["open"], 1), (["slip+"], -1),
                                                                          (["stick"], 1)]
    assert abs(path.branches[0].alpha_exit - hi) <= 1e-12 and abs(path.transitions[-1].alpha - lo) <= 1e-12
    assert_one_node_solutions(system, path, {0.5 * (lo + hi): ["slip+", "stick"], 0.7: ["stick"]})


def test_a_given_y0_where_ssnm_fails_raises_instead_of_another_start():
    """With a y0 of its own the start is SSNM from y0 only: on a lumped model at F = 30 where SSNM
    from 0 does not converge (the path without y0 starts from the frictionless homotopy), y0 = 0
    gives ConvergenceError naming alpha_start, on the condensed and the full backend alike."""
    system = random_system(6, 213, friction=30.0)
    assert trace_exact(system, 0.0, 1.0).stats["start"] == "frictionless"
    for backend in ("condensed", "full"):
        with pytest.raises(cfcontact.ConvergenceError, match="SSNM did not converge.*alpha=0.0"):
            cfcontact.trace_path(system, 0.0, 1.0, method="exact", backend=backend,
                                 y0=np.zeros(system.n + 2 * system.m))


def test_apex_start_where_ssnm_fails_at_the_probe():
    """Loaded from zero (f1 = 0, no gap) towards a load where SSNM does not converge (the F = 30
    model above): the apex start's probe at alpha = 1 is reached by the frictionless homotopy
    (the event says so), and the path is one ray: y(alpha) = alpha y(1) (positive homogeneity),
    each point a solution (verify)."""
    base = random_system(6, 213, friction=30.0)
    f1, _ = base.loads_numpy()
    system = base.with_loads(np.zeros_like(f1), f1)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    assert path.status == "completed" and path.stats["start"] == "apex" and not path.transitions
    (event,) = path.events
    assert event.kind == "apex_start" and event.data == {"probe_alpha": 1.0, "found_by": "frictionless"}
    y1 = path.solutions_at(1.0)[0].y
    assert np.abs(y1).max() > 0.1
    for a in (0.25, 0.5, 1.0):
        (sol,) = path.solutions_at(a)
        np.testing.assert_allclose(sol.y, a * y1, rtol=0, atol=1e-14 * np.abs(y1).max())
        assert cfcontact.verify(system, sol.y, a).worst() < 1e-12


def test_seed_degenerate_start_shrinks_the_step_to_its_first_branch():
    """Two decoupled nodes (method.md's K, F = 0.3): node 0 unloaded at alpha = 0 with zero gap (a
    degenerate start: every state of it is consistent there), pulled open beyond; node 1 open,
    reaching the ray atan(0.5), where it closes and slips, at alpha = 0.007 -- inside the first
    trial step h0 = 0.01.  At h0 neither SSNM's start sets (node 0 sticking) nor those of alpha =
    0.01 (node 1 slipping) are a branch through the start; the step is halved, and the seed path
    starts on (open, open) -- the closed-form state of both nodes just after 0 -- with one
    transversal transition at the analytic 0.007, as the exact method finds."""
    d = lambda deg: np.array([np.cos(np.radians(deg)), np.sin(np.radians(deg))])  # noqa: E731
    ray = np.array([1.0, 0.5]) / np.hypot(1.0, 0.5)
    v = d(60.0) - ray
    f1 = np.concatenate([np.zeros(2), ray - 0.007 * v])
    f2 = np.concatenate([d(10.0), ray + 0.993 * v])
    K = np.kron(np.eye(2), K1)
    N = np.array([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
    T = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
    system = ContactSystem.from_arrays(K, N, T, f1, f2, 0.3)
    opts = cfcontact.PathOptions()
    assert opts.h0 == 0.01 and opts.c_s == 0.5
    for a in (0.004, 0.006):  # the closed form on each node just after the start
        load = system.load(a)
        assert [s for s, _ in one_node_solutions(K1, 0.3, load[:2])] == ["open"]
        assert [s for s, _ in one_node_solutions(K1, 0.3, load[2:])] == ["open"]
    assert [s for s, _ in one_node_solutions(K1, 0.3, system.load(0.008)[2:])] == ["slip+"]
    seed = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
    exact = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    for path in (seed, exact):
        assert path.status == "completed"
        assert [b.sets.states() for b in path.branches] == [["open", "open"], ["open", "slip+"]]
        assert [(t.node, t.set, t.kind) for t in path.transitions] == [(1, "nu", "transversal")]
    assert abs(exact.transitions[0].alpha - 0.007) <= 1e-12
    assert abs(seed.transitions[0].alpha - 0.007) <= opts.h_min


# ------------------------------------------------------------------ degenerate points
def test_enumeration_continues_where_the_lexicographic_rule_fails(monkeypatch):
    """Where the lexicographic rule cannot cross a transition point (forced here at every point),
    the enumeration of the point's node states continues the path: on the one-node wedge (two
    folds) and a 4-node model at F = 30 (folds and transversal transitions) the path is the one
    the rule gives -- branches, orientations, transition kinds and alphas -- and on the wedge
    the folds are the analytic rays."""
    import cfcontact.exact as ex

    def summary(p):
        return (p.status, [(b.sets.states(), b.orientation) for b in p.branches],
                [t.kind for t in p.transitions], [e.kind for e in p.events])

    systems = [one_node(F1, K1), random_system(4, 1, friction=30.0, extra_dofs=3)]
    refs = [cfcontact.trace_path(s, 0.0, 1.0, method="exact") for s in systems]

    def no_crossing(*a, **k):
        raise ex._Unresolved("singular", "the rule fails here (test)")

    monkeypatch.setattr(ex, "_resolve", no_crossing)
    monkeypatch.setattr(ex, "ORDINARY_COMPILED", False)  # (every transition through _resolve)
    paths = [cfcontact.trace_path(system, 0.0, 1.0, method="exact") for system in systems]
    for path, ref in zip(paths, refs):
        assert ref.status == "completed" and len(ref.folds) >= 2
        assert summary(path) == summary(ref)
        np.testing.assert_allclose([t.alpha for t in path.transitions], [t.alpha for t in ref.transitions],
                                   rtol=0, atol=1e-12)
    rays = sorted([alpha_of_direction(systems[0], np.arctan(0.4)), alpha_of_direction(systems[0], np.arctan(0.5))])
    np.testing.assert_allclose(sorted(t.alpha for t in paths[0].transitions), rays, rtol=0, atol=1e-12)


# ------------------------------------------------------------------ multiplicity
def test_multiplicity_in_a_window_and_by_samples(wedge):
    """multiplicity_intervals with a window gives, inside it, one solution outside the wedge and
    three between its rays (the analytic fold alphas); the window's own ends bound the first and
    last interval.  max_multiplicity with samples finds three at an alpha between the rays, and
    (0, nan) on a path without branches."""
    system, path, (lo, hi) = wedge
    got = path.multiplicity_intervals(alpha_range=(0.2, 0.9))
    assert [k for _, _, k in got] == [1, 3, 1]
    assert got[0][0] == 0.2 and got[-1][1] == 0.9
    np.testing.assert_allclose([got[0][1], got[1][0], got[1][1], got[2][0]], [lo, lo, hi, hi], rtol=0, atol=1e-12)
    inner = path.multiplicity_intervals(alpha_range=(lo + 0.01, hi - 0.01))
    assert inner == [(lo + 0.01, hi - 0.01, 3)]
    k, a = path.max_multiplicity(samples=50)
    assert k == 3 and lo < a < hi
    assert len(one_node_solutions(K1, F1, system.load(a))) == 3
    empty = cfcontact.SolutionPath.for_system(system, "exact", 0.0, 1.0, {})  # (no branch: was a ValueError of min())
    k, a = empty.max_multiplicity(samples=5)
    assert k == 0 and np.isnan(a) and empty.multiplicity_intervals() == []


# ------------------------------------------------------------------ resume
def test_a_callback_that_stops_at_the_end_point_completes_the_path(wedge):
    """A callback that answers True at the last point (alpha_end) does not make the path
    "stopped by callback": it has reached its end, so it is "completed" with no resume state and
    the same branches as the path traced without the callback."""
    system, full, _ = wedge
    seen = []
    path = trace_exact(system, 0.0, 1.0, callback=lambda p: seen.append(p.alpha) or p.alpha == 1.0)
    assert seen[-1] == 1.0 and path.status == "completed" and path.resume_state is None
    assert [b.sets.states() for b in path.branches] == [b.sets.states() for b in full.branches]



def test_resume_refuses_a_path_that_is_not_this_runs(tmp_path):
    """A resume argument whose path is no SolutionPath, a path that never started, a path of a
    system with other sizes, or of a system of the same sizes with another friction (its
    checksum) is refused with an InputError saying which; the genuine state resumes to the
    uninterrupted path."""
    from cfcontact.solution_path import SolutionPath

    system = random_system(4, 1, friction=30.0, extra_dofs=3)
    part = trace_exact(system, 0.0, 1.0, callback=lambda p: len(p.path.transitions) >= 2)
    assert part.status == "stopped by callback"
    state = json.loads(json.dumps(part.resume_state))
    with pytest.raises(cfcontact.InputError, match="resume must be a dict"):
        trace_exact(system, 0.0, 1.0, resume={"path": "run.cfpath", "state": state})
    fresh = SolutionPath.for_system(system, "exact", 0.0, 1.0, {})
    with pytest.raises(cfcontact.InputError, match="not a started exact path"):
        trace_exact(system, 0.0, 1.0, resume={"path": fresh, "state": state})
    other = random_system(3, 1, friction=30.0, extra_dofs=3)
    with pytest.raises(cfcontact.InputError, match=f"the path has n={system.n}, m=4, the system n={other.n}, m=3"):
        trace_exact(other, 0.0, 1.0, resume={"path": part, "state": state})
    softer = system.with_friction(0.3)
    with pytest.raises(cfcontact.InputError, match="belongs to another system"):
        trace_exact(softer, 0.0, 1.0, resume={"path": part, "state": state})
    back = SolutionPath.load(part.save(tmp_path / "part.cfpath"))
    with pytest.raises(cfcontact.InputError, match="belongs to another system"):
        trace_exact(softer, 0.0, 1.0, resume={"path": back, "state": state})
    resumed = trace_exact(system, 0.0, 1.0, resume={"path": back, "state": state})
    ref = trace_exact(system, 0.0, 1.0)
    assert resumed.status == ref.status == "completed"
    assert [(t.node, t.set, t.kind) for t in resumed.transitions] == [(t.node, t.set, t.kind) for t in ref.transitions]


# ------------------------------------------------------------------ save and load
def test_a_save_that_fails_leaves_the_old_save_and_no_debris(wedge, tmp_path, monkeypatch):
    """A save that fails while writing its arrays (a full disk, say) raises that error, leaves the
    path saved before at the same folder as it was (it loads, with the same solutions) and no
    temporary folder beside it."""
    system, path, (lo, hi) = wedge
    target = tmp_path / "run.cfpath"
    path.save(target)
    before = sorted(os.listdir(tmp_path))

    def full_disk(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez_compressed", full_disk)
    with pytest.raises(OSError, match="No space left"):
        path.save(target)
    monkeypatch.undo()
    assert sorted(os.listdir(tmp_path)) == before == ["run.cfpath"]
    back = cfcontact.SolutionPath.load(target)
    a = 0.5 * (lo + hi)
    assert [s.states() for s in back.solutions_at(a)] == [s.states() for s in path.solutions_at(a)]


def test_a_version_1_save_loads_with_the_same_solutions(wedge, tmp_path):
    """A path saved in format version 1 (each branch by its points at alpha = 0 and 1, Y1 and Y2,
    no gap array) loads, and its branches give the same solutions as the path it was made from --
    the closed-form ones -- at alphas on every branch."""
    system, path, (lo, hi) = wedge
    d = tmp_path / "v1.cfpath"
    path.save(d)
    with np.load(d / "fields.npz") as z:
        arrays = {k: z[k] for k in z.files}
    a_ref, Y_ref, dY = arrays.pop("alpha_ref"), arrays.pop("Y_ref"), arrays.pop("dY")
    arrays["Y1"] = Y_ref - a_ref[:, None] * dY
    arrays["Y2"] = Y_ref + (1.0 - a_ref)[:, None] * dY
    del arrays["gap"]
    np.savez(d / "fields.npz", **arrays)
    meta = json.loads((d / "path.json").read_text())
    meta["version"] = 1
    (d / "path.json").write_text(json.dumps(meta))
    back = cfcontact.SolutionPath.load(d)
    for a in (0.1, lo + 1e-6, 0.5 * (lo + hi), hi - 1e-6, 0.9):
        got, ref = back.solutions_at(a), path.solutions_at(a)
        assert [s.states() for s in got] == [s.states() for s in ref]
        for x, y in zip(got, ref):
            np.testing.assert_allclose(x.y, y.y, rtol=0, atol=1e-14)
    assert back.multiplicity_intervals() == path.multiplicity_intervals()


def _json(fn, edit):
    data = json.loads(fn.read_text())
    edit(data)
    fn.write_text(json.dumps(data))


def _npz(fn, edit):
    with np.load(fn) as z:
        arrays = {k: z[k] for k in z.files}
    edit(arrays)
    np.savez(fn, **arrays)


def _set(key, value):
    return lambda d: d.update({key: value})


CORRUPTED = [
    # (label, file, edit, words of the message)
    ("n zero", "path.json", _set("n", 0), ["n = 0", "need n >= 1"]),
    ("rho negative", "path.json", _set("rho", -1.0), ["rho = -1.0 must be > 0"]),
    ("checksum", "path.json", _set("system_checksum", "abc"), ["system_checksum 'abc'", "SHA-256"]),
    ("branch not object", "path.json", lambda d: d["branches"].__setitem__(1, [1]), ["branches[1] is not an object"]),
    ("branch index", "path.json", lambda d: d["branches"][1].update(index=5), ["branches[1] has index 5"]),
    ("orientation", "path.json", lambda d: d["branches"][0].update(orientation=0),
     ["branches[0].orientation must be +1 or -1"]),
    ("parent type", "path.json", lambda d: d["branches"][1].update(parent="0"), ["'parent' in branches[1]", "type"]),
    ("transition not object", "path.json", lambda d: d["transitions"].__setitem__(0, None),
     ["transitions[0] is not an object"]),
    ("transition key", "path.json", lambda d: d["transitions"][0].pop("bracket"),
     ["missing key 'bracket' in transitions[0]"]),
    ("transition kind", "path.json", lambda d: d["transitions"][1].update(kind="jump"),
     ["transitions[1].kind = 'jump'"]),
    ("transition bracket", "path.json", lambda d: d["transitions"][0].update(bracket=[0.5]),
     ["transitions[0].bracket = [0.5] is not two numbers"]),
    ("event", "path.json", lambda d: d["events"].append({"kind": "x"}), ["events[0] is not an event"]),
    ("branch points", "path.json", lambda d: d["branches"][2]["points"].append(99),
     ["path.json", "branches[2].points refer to points outside 0..5"]),
    ("text ys", "fields.npz", lambda a: a.update(ys=a["ys"].astype(str)), ["fields.npz", "'ys' is not numeric"]),
    ("float point_branch", "fields.npz", lambda a: a.update(point_branch=a["point_branch"].astype(float)),
     ["'point_branch' is not an integer array"]),
    ("negative friction", "fields.npz", lambda a: a.update(friction=np.array(-1.0)),
     ["'friction' must be a number >= 0"]),
]


@pytest.mark.parametrize("label,name,edit,words", CORRUPTED, ids=[c[0] for c in CORRUPTED])
def test_a_corrupted_saved_path_is_refused_naming_what_is_wrong(wedge, tmp_path, label, name, edit, words):
    """Each corruption of a saved exact path (path.json's structure, fields.npz's arrays and the
    references between them) makes load raise an InputError naming the file and what is wrong;
    the uncorrupted save loads."""
    _, path, _ = wedge
    d = tmp_path / "p.cfpath"
    path.save(d)
    assert len(path.branches) == 3 and len(path.alphas) == 6 and not path.events
    cfcontact.SolutionPath.load(d)
    (_json if name == "path.json" else _npz)(d / name, edit)
    with pytest.raises(cfcontact.InputError) as exc:
        cfcontact.SolutionPath.load(d)
    msg = str(exc.value)
    assert name in msg or "fields.npz" in msg, msg
    for w in words:
        assert w in msg, (w, msg)
