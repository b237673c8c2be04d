"""The main demo runs as a test (coarse mesh) and checks its numbers."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "demos"))
import main as demo  # noqa: E402

sys.path.pop(0)


@pytest.fixture(scope="module")
def quick_results(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo")
    results = demo.run(quick=True, output=str(out), render=False, log=lambda *a: None)
    return out, {r["friction"]: r for r in results}


def test_small_friction_single_valued_transversal_only(quick_results):
    _, res = quick_results
    r = res[0.1]
    assert r["status"] == "completed" and r["folds"] == 0 and r["transitions"] > 0
    assert r["max_multiplicity"] == 1


def test_large_friction_folds_and_multiple_solutions(quick_results):
    _, res = quick_results
    r = res[30.0]
    assert r["status"] == "completed"
    assert r["folds"] == 2 and r["max_multiplicity"] == 3


def test_every_point_verifies_and_outputs_written(quick_results):
    out, res = quick_results
    for r in res.values():
        assert r["worst_residual"] <= 1e-8
        assert os.path.getsize(out / f"path_F{r['friction']:g}.png") > 1000
        with open(out / f"path_F{r['friction']:g}.pdf", "rb") as fh:
            assert fh.read(5) == b"%PDF-"
    summary = json.loads((out / "summary.json").read_text())
    assert [s["friction"] for s in summary] == [0.1, 0.6, 30.0]


def test_multiplicity_matches_enumeration_free_check(quick_results):
    """Every solution the path reports at the alpha of largest multiplicity solves (1)-(3)."""
    import cfcontact

    out, res = quick_results
    r = res[30.0]
    path = cfcontact.SolutionPath.load(out / "path_F30")
    system = demo.build(30.0, quick=True)
    sols = path.solutions_at(r["alpha_of_max"])
    assert len(sols) == 3
    for s in sols:
        assert cfcontact.verify(system, s, r["alpha_of_max"]).ok(1e-8)
    # distinct solutions
    ys = np.array([s.y for s in sols])
    assert np.linalg.matrix_rank(ys - ys[0], tol=1e-9 * np.abs(ys).max()) == 2


@pytest.mark.slow
def test_demo_script_default_model_reproduces_seed_multiplicities(tmp_path):
    """The full demo (default model n = 1320, m = 30) as the README's main command runs it."""
    proc = subprocess.run([sys.executable, os.path.join(ROOT, "demos", "main.py"), "--output", str(tmp_path),
                           "--friction", "0.1", "--friction", "30"],
                          capture_output=True, text=True, timeout=900, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    summary = {r["friction"]: r for r in json.loads((tmp_path / "summary.json").read_text())}
    assert summary[0.1]["folds"] == 0 and summary[0.1]["max_multiplicity"] == 1
    assert summary[30.0]["n"] == 1320 and summary[30.0]["m"] == 30
    assert summary[30.0]["folds"] >= 4 and summary[30.0]["max_multiplicity"] >= 5
    assert os.path.getsize(tmp_path / "solutions_F30.png") > 10000
