"""Issue #16 on the command line: ``[path] parameter = "friction"`` runs (stop, resume, info, plot),
``cfcontact map CASE.toml``, the demo script and Part E of the benchmark."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from cfcontact import cli
from cfcontact.friction import FrictionPath, load_path

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: demos/cases/folds.toml (two steel blocks, 12 x 4 cells, F = 30) with more [path] keys, no panel
with open(os.path.join(ROOT, "demos", "cases", "folds.toml")) as _fh:
    CASE = _fh.read().replace('[path]\nmethod = "exact"\n', '[path]\nmethod = "exact"\n{path}\n') \
        .replace("[output]\n", "[output]\nrender_panel = false\n")
assert "{path}" in CASE


def _case(tmp_path, path_keys, name="case.toml"):
    fn = tmp_path / name
    fn.write_text(CASE.replace("{path}", path_keys))
    return str(fn)


@pytest.mark.slow
def test_friction_case_run_info_plot_stop_and_resume(tmp_path, capsys):
    case = _case(tmp_path, 'parameter = "friction"\nalpha_start = 0.3\nfriction_end = 20.0')
    assert cli.main(["run", case, "-q"]) == 0
    out = tmp_path / "case_out"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["summary"]["parameter"] == "friction" and summary["status"] == "completed"
    full = load_path(str(out / "path"))
    assert isinstance(full, FrictionPath) and full.alpha_start == 0.0 and full.alpha_end == 20.0
    assert len(full.transitions) > 3
    capsys.readouterr()
    assert cli.main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "F (friction) 0 -> 20 at the load f(alpha = 0.3)" in text and "multiplicity over F:" in text and "alpha" not in text.split("\n", 2)[2].split("stats:")[0]
    assert cli.main(["plot", str(out), "-o", str(tmp_path / "p.png"), "-q"]) == 0
    # stopped after two transitions, resumed: the same path
    case2 = _case(tmp_path, 'parameter = "friction"\nalpha_start = 0.3\nfriction_end = 20.0', "case2.toml")
    assert cli.main(["run", case2, "-q", "--stop-after-transitions", "2"]) == cli.EXIT_STOPPED
    assert cli.main(["run", case2, "-q", "--resume"]) == 0
    again = load_path(str(tmp_path / "case2_out" / "path"))
    assert [(t.kind, t.node, t.set) for t in again.transitions] == [(t.kind, t.node, t.set) for t in full.transitions]
    assert np.allclose([t.alpha for t in again.transitions], [t.alpha for t in full.transitions], rtol=1e-13)


def test_friction_case_at_the_full_load_needs_no_alpha_range(tmp_path, capsys):
    """A path in F at alpha_start = 1 (the full load f2): alpha_end (default 1) plays no part; it was
    refused as "alpha range is empty".  The path is that of the library at f(1)."""
    import cfcontact
    from cfcontact.case import build_system, load_case

    case = _case(tmp_path, 'parameter = "friction"\nalpha_start = 1.0\nfriction_end = 5.0')
    assert cli.main(["run", case, "-q"]) == 0
    saved = load_path(str(tmp_path / "case_out" / "path"))
    ref = cfcontact.trace_friction_path(build_system(load_case(case)), 1.0, 0.0, 5.0)
    assert saved.status == ref.status == "completed" and len(ref.transitions) >= 1
    assert [(t.kind, t.node, t.set) for t in saved.transitions] == [(t.kind, t.node, t.set) for t in ref.transitions]
    bad = _case(tmp_path, 'alpha_start = 1.0', "alpha.toml")  # an alpha path still needs a range
    assert cli.main(["run", bad]) == cli.EXIT_INPUT
    assert "alpha range is empty" in capsys.readouterr().err


@pytest.mark.parametrize("keys, words", [
    ('parameter = "load"', "parameter"),
    ('parameter = "friction"\nfriction_start = 2.0\nfriction_end = 2.0', "friction_start"),
    ('parameter = "friction"\nbackend = "full"', "condensed"),
])
def test_friction_case_bad_input(tmp_path, capsys, keys, words):
    case = _case(tmp_path, keys)
    assert cli.main(["run", case]) == cli.EXIT_INPUT
    assert words in capsys.readouterr().err
    assert not os.path.exists(tmp_path / "case_out")


@pytest.mark.slow
def test_map_command(tmp_path, capsys):
    case = _case(tmp_path, "")
    args = ["map", case, "--friction-range", "24", "30", "--frictions", "7", "--alphas", "11", "--mark", "30"]
    assert cli.main(args) == 0
    out = tmp_path / "case_map"
    text = capsys.readouterr().out
    assert "critical friction of the path: F = 26.71357" in text and str(out) in text
    for f in ("map.png", "map.json", "map.npz"):
        assert (out / f).exists(), f
    data = json.loads((out / "map.json").read_text())
    assert len(data["counts"]) == 7 and len(data["counts"][0]) == 11 and data["marks"] == [30.0]
    assert data["fold_curves"]["critical"]["node"] == 5
    assert cli.main(args) == cli.EXIT_INPUT  # the folder exists
    assert "--force" in capsys.readouterr().err
    assert cli.main(args + ["--force", "--no-curves", "-q"]) == 0
    assert "fold_curves" not in json.loads((out / "map.json").read_text())
    capsys.readouterr()
    assert cli.main(["map", case, "--friction-range", "3", "1", "--output", str(tmp_path / "other")]) == cli.EXIT_INPUT
    assert "friction" in capsys.readouterr().err and not (tmp_path / "other").exists()


@pytest.mark.slow
def test_demo_script_and_bench_part_e(tmp_path):
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, os.path.join(ROOT, "demos", "friction_map.py"), "--quick", "--output",
                           str(tmp_path / "demo")], capture_output=True, text=True, env=env, cwd=ROOT, timeout=1200)
    assert proc.returncode == 0, proc.stderr
    assert "critical friction of the path: F = 0.5661252421" in proc.stdout
    assert (tmp_path / "demo" / "map.png").exists()
    proc = subprocess.run([sys.executable, "-m", "cfcontact", "bench", "--quick", "--part", "E", "--output",
                           str(tmp_path / "bench")], capture_output=True, text=True, env=env, cwd=ROOT, timeout=1200)
    assert proc.returncode == 0, proc.stderr
    c = json.loads((tmp_path / "bench" / "bench.json").read_text())["part_e"]
    assert c["points"] == 40 and abs(c["critical_friction"] - 0.5661252421) < 1e-8
    assert c["map_time"] > 0 and c["alpha_paths_time"] > 0 and c["curves"] > 0


@pytest.mark.slow
def test_map_exits_4_when_a_row_is_unknown(tmp_path, capsys):
    """A row at the path's critical friction (a cusp: its alpha-path ends "stuck") is marked -1;
    the map is written, the warning names the row, and the exit code is 4, not 0."""
    import numpy as np

    from cfcontact.case import build_system, load_case
    from cfcontact.fmap import critical_friction_path

    case = _case(tmp_path, "")
    Fc = critical_friction_path(build_system(load_case(case)), (0.0, 1.0), F_max=60.0).friction
    args = ["map", case, "--friction-range", repr(Fc), "30", "--frictions", "2", "--alphas", "11", "--no-curves"]
    assert cli.main(args) == cli.EXIT_INCOMPLETE
    assert "1 row(s) of the map could not be traced" in capsys.readouterr().err
    counts = np.asarray(json.loads((tmp_path / "case_map" / "map.json").read_text())["counts"])
    assert (counts[0] == -1).all() and (counts[1] >= 1).all()
