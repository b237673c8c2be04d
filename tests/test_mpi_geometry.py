"""Real contact geometry under ``mpirun -n 2`` (issue #12, item 7): the pairing, the gap, the
prescribed displacements and the solutions (both backends, an exact path) equal the serial ones;
so does a case file of the new geometry (model, info report, seed path)."""

import os
import sys

import numpy as np
import pytest

HERE = os.path.dirname(os.path.abspath(__file__))


@pytest.mark.mpi
def test_mpi_geometry_matches_serial(tmp_path, run_mpi):
    sys.path.insert(0, HERE)
    try:
        import mpi_geometry_script as script
    finally:
        sys.path.remove(HERE)
    out = tmp_path / "mpi.npz"
    run_mpi(2, os.path.join(HERE, "mpi_geometry_script.py"), str(out), timeout=600)
    par = np.load(out)
    assert int(par["size"]) == 2
    for name in script.cases():
        ranges = par[f"{name}:ranges"]
        assert 0 < ranges[1] < ranges[2], f"{name}: the DOFs must really be split over 2 ranks"
        assert np.all(par[f"{name}:owned_cells"] > 0), name
        serial = script.gathered(script.build(name))
        assert set(serial) == {k.split(":", 1)[1] for k in par.files if k.startswith(name + ":")} - {
            "ranges", "owned_cells"}, name
        for key, ref in serial.items():
            got = par[f"{name}:{key}"]
            assert got.shape == ref.shape, (name, key, got.shape, ref.shape)
            if key in ("contact_nodes", "no_tangent", "path_nodes") or key.startswith("codes"):
                assert np.array_equal(got, ref), (name, key)
            else:
                scale = max(np.abs(ref).max(initial=0.0), 1e-300)
                assert np.abs(got - ref).max(initial=0.0) <= 1e-10 * scale, (name, key)
        if f"{name}:yc1" in par.files:  # the condensed backend agrees with the full one
            y, yc = par[f"{name}:y1"], par[f"{name}:yc1"]
            assert np.abs(y - yc).max() <= 1e-8 * np.abs(y).max(), name
    assert par["half:no_tangent"][0] == 1 and par["obstacle:gap"].min() > 0
    assert len(par["cylinder:path_alphas"]) >= 1


@pytest.mark.mpi
def test_mpi_case_file_matches_serial(tmp_path, run_mpi):
    """A new example case (half_cylinder.toml, coarser): its validation, model, `info` report and
    seed path from the zero load under mpirun -n 2 equal the serial ones."""
    sys.path.insert(0, HERE)
    try:
        import mpi_case_script as script
    finally:
        sys.path.remove(HERE)
    text = open(os.path.join(os.path.dirname(HERE), "demos", "cases", "half_cylinder.toml")).read()
    case = tmp_path / "half.toml"
    case.write_text(text.replace("size = 0.025", "size = 0.05").replace("size_far = 0.3", "size_far = 0.5"))
    out = tmp_path / "mpi.npz"
    run_mpi(2, os.path.join(HERE, "mpi_case_script.py"), str(case), str(out), timeout=600)
    par = np.load(out)
    assert int(par["size"]) == 2 and 0 < par["ranges"][1] < par["ranges"][2]
    serial = script.result(str(case))
    assert str(par["report"]) == str(serial["report"]) and '"no_tangent": 1' in str(serial["report"])
    assert str(par["status"]) == str(serial["status"]) == "completed" and int(par["events"]) == 0
    assert str(par["changes"]) == str(serial["changes"]) and len(serial["alphas"]) >= 4
    np.testing.assert_allclose(par["alphas"], serial["alphas"], rtol=0, atol=1e-10)
    for key in ("K", "N", "T", "f1", "f2", "gap", "y_end"):
        ref = serial[key]
        assert par[key].shape == ref.shape, key
        assert np.abs(par[key] - ref).max(initial=0.0) <= 1e-9 * max(np.abs(ref).max(initial=0.0), 1e-300), key


SSNM_FAILS_CASE = """[geometry]
kind = "two_blocks"
nx = 7
ny = 3
nx2 = 6
cell = "triangle"
angle = 30.0
[contact]
friction = 30.0
pairing = "segment"
[loads.f1]
top1 = [15020718.518805802, -14093911.468555167]
right1 = [43154114.597249925, -83411047.27057119]
bottom2 = [-53513049.38049795, -64610928.16515164]
[loads.f2]
top1 = [1527722.3535937965, 58096300.835772604]
right1 = [-64487212.95501079, 80149544.6713045]
[path]
method = "seed"
"""


@pytest.mark.mpi
def test_mpi_seed_start_where_ssnm_fails_matches_serial(tmp_path, run_mpi):
    """Inclined blocks at F = 30 on a non-matching interface, where SSNM fails at alpha = 0 from
    every restart: the seed method starts from the solution the exact method reaches (the
    frictionless homotopy, on a condensed solver formed for it, distributed under MPI); its path
    with two ranks is the serial one (one event: start_reached)."""
    sys.path.insert(0, HERE)
    try:
        import mpi_case_script as script
    finally:
        sys.path.remove(HERE)
    case = tmp_path / "ssnm_fails.toml"
    case.write_text(SSNM_FAILS_CASE)
    out = tmp_path / "mpi.npz"
    run_mpi(2, os.path.join(HERE, "mpi_case_script.py"), str(case), str(out), timeout=600)
    par = np.load(out)
    assert int(par["size"]) == 2 and 0 < par["ranges"][1] < par["ranges"][2]
    serial = script.result(str(case))
    assert str(par["status"]) == str(serial["status"]) == "completed"
    assert int(par["events"]) == int(serial["events"]) == 1
    assert str(par["changes"]) == str(serial["changes"]) and len(serial["alphas"]) == 2
    np.testing.assert_allclose(par["alphas"], serial["alphas"], rtol=0, atol=1e-10)
    ref = serial["y_end"]
    assert np.abs(par["y_end"] - ref).max() <= 1e-9 * np.abs(ref).max()


@pytest.mark.mpi
def test_parallel_demo_equals_the_serial_command_line_which_refuses_mpirun(tmp_path, run_mpi):
    """demos/parallel.py under mpirun -n 2 saves the path `cfcontact run` traces serially (same
    set changes and transitions, points within 1e-9); `cfcontact run` itself under mpirun refuses
    (exit 2, one line from rank 0) before any work, where every rank had raced for the output
    folder's lock and the ranks hung."""
    import subprocess

    from cfcontact.cli import main as cli_main
    from cfcontact.solution_path import SolutionPath
    from conftest import ROOT, mpirun_cmd

    case = os.path.join(ROOT, "demos", "cases", "folds.toml")
    proc = run_mpi(2, os.path.join(ROOT, "demos", "parallel.py"), case, str(tmp_path / "par"), timeout=600)
    assert "2 rank(s): completed" in proc.stdout
    assert cli_main(["run", case, "-o", str(tmp_path / "ser"), "-q"]) == 0
    par, ser = SolutionPath.load(tmp_path / "par" / "path"), SolutionPath.load(tmp_path / "ser" / "path")
    assert par.status == ser.status == "completed"  # (checksums: equal here, but assembly sums may round apart)
    assert np.abs(par.ys - ser.ys).max() <= 1e-9 * np.abs(ser.ys).max()
    assert [t.changes for t in par.transitions] == [t.changes for t in ser.transitions]
    assert len(ser.transitions) >= 20 and len(ser.folds) == 2
    np.testing.assert_allclose([t.alpha for t in par.transitions], [t.alpha for t in ser.transitions],
                               rtol=0, atol=1e-10)
    cmd = mpirun_cmd(2, "-m", "cfcontact", "run", case, "-o", str(tmp_path / "cli"))
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    refused = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300, cwd=ROOT)
    assert refused.returncode != 0
    assert refused.stderr.count("cfcontact run: error: the command line runs as one process") == 1
    assert "2 MPI ranks" in refused.stderr and not (tmp_path / "cli").exists()
