"""``cfcontact bench --quick --skip-large`` (and the demos/bench.py wrapper): JSON fields, seed and
exact agree, residuals small (no timings asserted)."""

import json
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEMOS = os.path.join(ROOT, "demos")


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run([sys.executable, "-m", "cfcontact", "bench", "--quick", "--skip-large",
                           "--output", str(out)], capture_output=True, text=True, cwd=ROOT, env=env, timeout=1200)
    assert proc.returncode == 0, f"STDOUT:\n{proc.stdout}\nSTDERR:\n{proc.stderr}"
    with open(out / "bench.json") as fh:
        return json.load(fh), proc.stdout


def test_bench_part_a_fields_and_agreement(bench):
    data, stdout = bench
    assert "Part A" in stdout and "Part B" in stdout
    if DEMOS not in sys.path:
        sys.path.insert(0, DEMOS)
    import main as demo_main  # the demo's constants (the lead tunes them)

    rows = data["part_a"]
    assert [r["friction"] for r in rows] == list(demo_main.DEMO_FRICTIONS)
    for r in rows:
        for key in ("n", "m", "speedup", "same_set_changes", "max_alpha_difference", "alphas_within_h_min", "h_min"):
            assert key in r, key
        for name in ("seed", "exact"):
            d = r[name]
            for key in ("linear_solves", "wall_time", "transitions", "folds", "max_multiplicity", "worst_residual",
                        "status"):
                assert key in d, (name, key)
            assert d["status"] == "completed"
            assert d["worst_residual"] <= 1e-8, (r["friction"], name, d["worst_residual"])
        assert "factorizations" in r["seed"]
        assert r["exact"]["K_factorizations"] == 1 and "dense_factorizations" in r["exact"]
        assert r["same_set_changes"], r
        assert r["alphas_within_h_min"], r
        assert r["seed"]["transitions"] == r["exact"]["transitions"]
        assert r["seed"]["folds"] == r["exact"]["folds"]
        assert r["seed"]["max_multiplicity"] == r["exact"]["max_multiplicity"]
        assert r["exact"]["linear_solves"] < r["seed"]["linear_solves"]


def test_bench_part_b_fields(bench):
    data, _ = bench
    rows = data["part_b"]
    assert rows and all(r["n"] <= 5e5 for r in rows)  # --skip-large
    for r in rows:
        assert r["returncode"] == 0 and r["status"] == "completed", r.get("error")
        for key in ("n", "m", "assembly_time", "factorization_time", "condensation_time", "path_time", "total_time",
                    "ratio", "peak_rss_gib", "transitions", "K_factorizations", "dense_factorizations"):
            assert key in r, key
        assert r["K_factorizations"] == 1
        assert r["worst_residual"] <= 1e-8 and r["verified_points"] == r["points"]
        assert r["condensation"] in ("schur", "solves")


def test_bench_wrapper_and_bad_options(tmp_path):
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run([sys.executable, os.path.join(DEMOS, "bench.py"), "--help"], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=120)
    assert proc.returncode == 0 and "--skip-large" in proc.stdout
    for bad in (["--part", "C"], ["--sizes", "1e4,x"], ["--repeat", "0"]):
        proc = subprocess.run([sys.executable, "-m", "cfcontact", "bench", *bad, "--output", str(tmp_path)],
                              capture_output=True, text=True, cwd=ROOT, env=env, timeout=120)
        assert proc.returncode == 2 and "error" in proc.stderr, (bad, proc.stderr)
        assert not (tmp_path / "bench.json").exists()

