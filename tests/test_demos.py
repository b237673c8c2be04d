"""The main demo runs as a test (its own model, n = 1320, m = 30) and checks its numbers."""

import json
import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.slow  # the main demo's model (n = 1320) and its full paths

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "demos"))
import main as demo  # noqa: E402

sys.path.pop(0)


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    res = demo.run(output=str(out), render=False, log=lambda *a: None)
    return out, {r["friction"]: r for r in res}


def test_default_model_size(results):
    _, res = results
    for r in res.values():
        assert (r["n"], r["m"]) == (1320, 30) and r["method"] == "seed"


def test_small_friction_single_valued_transversal_only(results):
    import cfcontact

    out, res = results
    r = res[0.1]
    assert r["status"] == "completed" and r["folds"] == 0 and r["transitions"] == 10
    assert r["max_multiplicity"] == 1
    path = cfcontact.SolutionPath.load(out / "path_F0.1")
    assert {t.kind for t in path.transitions} == {"transversal"}


def test_friction_0_6_three_solutions(results):
    """The seed's F = 0.6: two folds, three solutions on an alpha interval."""
    _, res = results
    r = res[0.6]
    assert r["status"] == "completed" and r["folds"] == 2 and r["max_multiplicity"] == 3
    assert 0.7912 < r["alpha_of_max"] < 0.7940  # the three-solution interval [0.79125, 0.79394]


def test_large_friction_folds_and_multiple_solutions(results):
    _, res = results
    r = res[30.0]
    assert r["status"] == "completed" and r["folds"] == 5 and r["max_multiplicity"] == 6


def test_every_point_verifies_and_outputs_written(results):
    out, res = results
    for r in res.values():
        assert r["worst_residual"] <= 1e-8
        assert os.path.getsize(out / f"path_F{r['friction']:g}.png") > 1000
        with open(out / f"path_F{r['friction']:g}.pdf", "rb") as fh:
            assert fh.read(5) == b"%PDF-"
    summary = json.loads((out / "summary.json").read_text())
    assert [s["friction"] for s in summary] == [0.1, 0.6, 30.0]


@pytest.mark.parametrize("F", [0.6, 30.0])
def test_solutions_at_largest_multiplicity_verify_and_differ(results, F):
    """Every solution the path reports at the alpha of largest multiplicity solves (1)-(3), and
    they are distinct."""
    import cfcontact

    out, res = results
    r = res[F]
    path = cfcontact.SolutionPath.load(out / f"path_F{F:g}")
    system = demo.build(F)
    sols = path.solutions_at(r["alpha_of_max"])
    assert len(sols) == r["max_multiplicity"]
    for s in sols:
        assert cfcontact.verify(system, s, r["alpha_of_max"]).ok(1e-8)
    states = {tuple(s.states()) for s in sols}
    assert len(states) == len(sols)


def test_exact_method_gives_the_same_paths(results):
    """The exact method traces the demo's paths through the same set changes (node, set, kind),
    with transition alphas within the seed's h_min."""
    import cfcontact

    out, res = results
    for F in demo.DEMO_FRICTIONS:
        seed = cfcontact.SolutionPath.load(out / f"path_F{F:g}")
        exact = cfcontact.trace_path(demo.build(F), *demo.DEMO_ALPHA, method="exact")
        assert exact.status == "completed"
        assert [(t.node, t.set, t.kind) for t in exact.transitions] == [(t.node, t.set, t.kind) for t in seed.transitions]
        assert max(abs(a.alpha - b.alpha) for a, b in zip(exact.transitions, seed.transitions)) <= 1e-5
        assert exact.max_multiplicity()[0] == res[F]["max_multiplicity"]


def test_exact_demo_counts_the_set_up_of_its_solver(tmp_path):
    """The demo's table counts the condensed solver's set-up for the exact method: one
    factorization of K, the 2m + 2 forward substitutions for S, w1, w2 plus the check, and the
    probe of the solves' accuracy (one solve and one refinement step: no refinement needed here)."""
    (r,) = demo.run(frictions=(30.0,), output=str(tmp_path), method="exact", render=False, log=lambda *a: None)
    assert r["transitions"] == 5 and r["folds"] == 5 and r["max_multiplicity"] == 6
    assert r["factorizations"] == 1 and r["linear_solves"] == 2 * r["m"] + 5
    assert 0 < r["wall_time_path"] < 10


def test_plotted_component_is_a_fold_node(results):
    import cfcontact

    out, _ = results
    path = cfcontact.SolutionPath.load(out / "path_F0.6")
    name, node = demo.fold_component(path)
    assert name == "lam_n" and node in {t.node for t in path.folds}


@pytest.mark.slow
def test_demo_script_default_model_reproduces_seed_multiplicities(tmp_path):
    """The full demo as the README's main command runs it, pictures included."""
    proc = subprocess.run([sys.executable, os.path.join(ROOT, "demos", "main.py"), "--output", str(tmp_path)],
                          capture_output=True, text=True, timeout=900, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = {r["friction"]: r for r in json.loads((tmp_path / "summary.json").read_text())}
    assert summary[0.1]["folds"] == 0 and summary[0.1]["max_multiplicity"] == 1
    assert summary[0.6]["max_multiplicity"] >= 3
    assert summary[30.0]["max_multiplicity"] >= 5
    for F in ("0.1", "0.6", "30"):
        assert os.path.getsize(tmp_path / f"solutions_F{F}.png") > 10000
