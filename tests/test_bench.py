"""``cfcontact bench --quick --skip-large`` (and the demos/bench.py wrapper): JSON fields, seed and
exact agree, residuals small (no timings asserted)."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEMOS = os.path.join(ROOT, "demos")


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run([sys.executable, "-m", "cfcontact", "bench", "--quick", "--skip-large", "--profile",
                           "--output", str(out)], capture_output=True, text=True, cwd=ROOT, env=env, timeout=1200)
    assert proc.returncode == 0, f"STDOUT:\n{proc.stdout}\nSTDERR:\n{proc.stderr}"
    with open(out / "bench.json") as fh:
        return json.load(fh), proc.stdout


@pytest.mark.slow
def test_bench_part_a_fields_and_agreement(bench):
    data, stdout = bench
    assert "Part A" in stdout and "Part B" in stdout
    from cfcontact.demo_models import DEMO_FRICTIONS  # the demo's constants (the lead tunes them)

    rows = data["part_a"]
    assert [(r["case"], r["friction"]) for r in rows] == [(c, F) for c in ("demo", "blocks") for F in DEMO_FRICTIONS]
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
        for name in ("seed", "exact"):  # --quick: one run each; the median of one run is that run
            d = r[name]
            assert len(d["wall_times"]) >= data["repeat"] == 1
            assert d["wall_time"] == min(d["wall_times"]) <= d["median_wall_time"]
        assert r["speedup"] == pytest.approx(r["seed"]["wall_time"] / r["exact"]["wall_time"])
        assert r["speedup_median"] == pytest.approx(r["seed"]["median_wall_time"] / r["exact"]["median_wall_time"])


@pytest.mark.slow
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
        assert r["condensation"] in ("schur", "solves", "forward")
        # --profile: the path traced again under cProfile (the timed run is not profiled)
        assert r["profile_top_tottime"] and all(isinstance(k, str) and v >= 0 for k, v in r["profile_top_tottime"])


@pytest.mark.slow
def test_bench_wrapper_and_bad_options(tmp_path):
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run([sys.executable, os.path.join(DEMOS, "bench.py"), "--help"], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=120)
    assert proc.returncode == 0 and "--skip-large" in proc.stdout and "--seed-check" in proc.stdout
    for bad in (["--part", "X"], ["--sizes", "1e4,x"], ["--repeat", "0"], ["--min-time", "-1"],
                ["--part", "C", "--time-limit", "-3"], ["--part", "D", "--paths", "0"], ["--part", "D", "--seed-check", "-1"],
                ["--part", "C", "--contact-nodes", "100,x"], ["--part", "C", "--contact-nodes", "2"]):
        proc = subprocess.run([sys.executable, "-m", "cfcontact", "bench", *bad, "--output", str(tmp_path)],
                              capture_output=True, text=True, cwd=ROOT, env=env, timeout=120)
        assert proc.returncode == 2 and "error" in proc.stderr, (bad, proc.stderr)
        assert not (tmp_path / "bench.json").exists()



def test_timed_runs_repeat_min_time_and_gc():
    """At least ``repeat`` runs, and more until ``min_time`` has passed; the garbage collector is
    off inside each run (as timeit does) and on again afterwards."""
    import gc
    import time

    from cfcontact.bench import MAX_RUNS, _timed_runs

    states, durations = [], []

    def run():
        states.append(gc.isenabled())
        t0 = time.perf_counter()
        time.sleep(0.01)
        durations.append(time.perf_counter() - t0)
        return len(states)

    assert gc.isenabled()
    out = _timed_runs(run, 2, 0.0)
    assert out == [1, 2] and states == [False, False] and gc.isenabled()
    states.clear()
    durations.clear()
    out = _timed_runs(run, 1, 0.1)  # more runs until the runs (not gc.collect) have taken 0.1 s
    assert 2 <= len(out) <= MAX_RUNS
    assert sum(durations[:-1]) < 0.1 <= sum(durations) + 1e-3
    assert not any(states) and gc.isenabled()


@pytest.mark.slow
def test_bench_parts_c_and_d_quick(tmp_path):
    """Parts C (long interfaces) and D (hard cases) at their quick sizes: every row traced to the end
    (no stuck, cycling, transition cap or start failure), with factorization updates on the strips,
    small residuals, the slope of the time per transition, and the random load paths of the demo
    models at F = 30 all completed; each row and path traced by the seed method too, which gives
    the same states where it completes, or a difference its own runs account for."""
    from cfcontact import bench_stress as bs

    c = bs.part_c(quick=True, time_limit=120, log=lambda *a: None)
    for r in c["rows"]:
        assert r["status"] == "completed" and r["transitions"] > 20, r
        assert r["dense_updates"] > r["refactorizations"] and r["worst_residual"] < 1e-9, r
        assert 0 <= r["true_corrections"] <= r["dense_updates"] + r["refactorizations"]
        assert r["peak_rss_gib"] > 0 and r["time_per_transition"] > 0
        # the start's time is part of the path's, not of its transitions'
        assert 0 < r["start_time"] < r["path_time"]
        assert r["time_per_transition"] * r["transitions"] == pytest.approx(r["path_time"] - r["start_time"])
        assert r["path_time_per_transition"] > r["time_per_transition"]
    assert set(c["slope"]) == set(c["slope_with_start"]) == {"0.3", "30.0"}
    d = bs.part_d(quick=True, paths=4, time_limit=120, log=lambda *a: None, seed_limit=30)
    models = {r["model"] for r in d["rows"]}
    assert models == {"strip", "cylinder", "punch", "closing"}
    for r in d["rows"]:
        assert r["status"] == "completed" and r["worst_residual"] < 1e-9, r
        assert r["backtracks"] == 0, r  # completed without going back to a branch point
    closing = [r for r in d["rows"] if r["model"] == "closing"]
    assert all(r["max_vanishing"] >= r["m"] // 2 for r in closing), closing  # the whole interface at once
    for r in closing:  # the point's cost: the median of three runs of its path
        assert len(r["degenerate_times"]) == 3 and r["worst_degenerate_time"] == np.median(r["degenerate_times"])
    for name in ("demo", "blocks"):
        s = d["random_loads"][name]["summary"]
        assert s["runs"] == 4 and s["status"] == {"completed": 4} and s["backtracks"] == 0, s
    # the seed method on the same rows and paths: where it completes, the same states as the exact
    # path, or a difference its own runs account for (finer steps agree, it runs back along itself)
    runs = d["rows"] + [r for name in ("demo", "blocks") for r in d["random_loads"][name]["runs"]]
    assert all(r["exact_retraces"] is None for r in runs)
    done = [r for r in runs if r["seed_status"] == "completed"]
    assert len(done) >= len(runs) - 2 and sum(r["seed_same"] for r in done) >= len(done) - 4
    assert all(r["seed_same"] or bs._seed_difference_explained(r) for r in done)
    strip30 = [r for r in d["rows"] if r["model"] == "strip" and r["friction"] == 30 and r["kind"] == "uniform"]
    assert strip30[0]["seed_retraces"] is not None and strip30[0]["seed_end_alpha"] == 0.0  # back to its start
    assert any(f["same"] for r in done for f in r.get("finer", []))  # (a blocks path: agrees at h_min = 1e-6)
    text = bs.table(c["rows"] + d["rows"])
    assert "s/trans." in text and "completed" in text


def test_bench_runs_blas_single_threaded_unless_told(monkeypatch):
    """The benchmark's convention (docs/bench.md): one BLAS thread in its own process and in the
    workers it starts (OPENBLAS_NUM_THREADS=1 while it runs, restored after), unless the caller
    set OPENBLAS_NUM_THREADS; bench.json records which."""
    from threadpoolctl import threadpool_info

    from cfcontact.bench import _blas_threads

    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    machine = {}
    with _blas_threads(machine):
        assert os.environ["OPENBLAS_NUM_THREADS"] == "1"
        assert all(p["num_threads"] == 1 for p in threadpool_info() if p["user_api"] == "blas")
    assert "OPENBLAS_NUM_THREADS" not in os.environ
    assert machine["openblas_num_threads"].startswith("1")
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    with _blas_threads(machine):
        assert os.environ["OPENBLAS_NUM_THREADS"] == "2"
    assert machine["openblas_num_threads"] == "2"


def test_a_worker_that_reported_nothing_prints_as_failed():
    """A Part C/D worker that died before its first report (rc 1, no output) is a row, not a
    formatting error: its status says how it failed."""
    from cfcontact.bench_stress import _row_text

    text = _row_text({"model": "strip", "kind": "uniform", "friction": 0.3, "returncode": 1, "stage": None,
                      "worst_residual": None, "error": ""})
    assert text.rstrip().endswith("nan      - failed (rc 1)          -")  # (no seed method run: -)


def test_a_strip_row_with_other_cells_across_is_named_by_them():
    """Part D's strip 8 cells across (its start: SSNM with another rho) prints as strip/8, the
    strips of the default 5 cells across as strip."""
    from cfcontact.bench_stress import _row_text

    row = {"model": "strip", "kind": "random", "friction": 30.0, "status": "completed", "worst_residual": 1e-12}
    assert _row_text(dict(row, cells_across=8)).split()[0] == "strip/8"
    assert _row_text(row).split()[0] == "strip"
