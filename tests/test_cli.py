"""The command line (cfcontact.cli): run / plot / render / info, bad input, stop and resume."""

import json
import os
import shutil
import signal
import subprocess
import sys

import numpy as np
import pytest
from matplotlib.image import imread

import cfcontact
from cfcontact import case as case_file
from cfcontact import cli, run
from cfcontact.path import SolutionPath

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CASES = os.path.join(ROOT, "demos", "cases")
MSH_NAME = "two_blocks_6x2.msh"  # referenced by demos/cases/user_msh.toml

SMALL = """
title = "small"
[geometry]
kind = "two_blocks"
nx = 12
ny = 4
[contact]
friction = 1.5
[output]
window_size = [640, 400]
"""


# ------------------------------------------------------------------ helpers
def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _rgb(fn):
    img = imread(fn)
    if img.dtype != np.uint8:
        img = (img[..., :3] * 255).round()
    return np.asarray(img[..., :3], dtype=int)


def _assert_picture(fn, size=None):
    """A PNG of the given (width, height) that is not blank."""
    assert os.path.isfile(fn), fn
    with open(fn, "rb") as fh:
        assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    img = _rgb(fn)
    if size is not None:
        assert (img.shape[1], img.shape[0]) == tuple(size)
    flat = img.reshape(-1, 3)
    assert flat.std() > 5, f"{fn} is blank"
    assert len(np.unique(flat, axis=0)) >= 20


def _same_path(a: SolutionPath, b: SolutionPath):
    assert a.status == b.status
    assert [(t.kind, t.alpha, t.node, t.set, t.from_branch, t.to_branch) for t in a.transitions] == \
        [(t.kind, t.alpha, t.node, t.set, t.from_branch, t.to_branch) for t in b.transitions]
    np.testing.assert_array_equal(a.alphas, b.alphas)
    np.testing.assert_array_equal(a.point_branch, b.point_branch)
    np.testing.assert_allclose(a.ys, b.ys, rtol=0, atol=1e-12 * np.abs(b.ys).max())


def _write(tmp_path, text, name="case.toml"):
    fn = tmp_path / name
    fn.write_text(text)
    return str(fn)


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    """demos/cases copied to a temporary folder, with the .msh that user_msh.toml needs."""
    d = tmp_path_factory.mktemp("cases")
    for name in os.listdir(CASES):
        if name.endswith(".toml"):
            shutil.copy(os.path.join(CASES, name), d / name)
    subprocess.run([sys.executable, "-m", "cfcontact.meshes.two_blocks", str(d / MSH_NAME),
                    "--nx", "6", "--ny", "2"], check=True, capture_output=True, env=_env(), cwd=ROOT)
    return d


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    """An uninterrupted run of SMALL: (case file, output folder)."""
    d = tmp_path_factory.mktemp("small")
    case = _write(d, SMALL)
    assert cli.main(["run", case, "-q"]) == 0
    return case, str(d / "case_out")


# ------------------------------------------------------------------ run
@pytest.mark.slow
@pytest.mark.parametrize("name", ["two_blocks", "inclined", "user_msh"])
def test_example_cases_run(cases, name):
    case = str(cases / f"{name}.toml")
    assert cli.main(["run", case, "-q"]) == 0
    out = cases / f"{name}_out"
    assert not os.path.exists(str(out) + ".partial")
    for f in ("path/path.json", "summary.json", "case.toml", "path.png", "multiplicity.png", "panel.png"):
        assert (out / f).exists(), f
    summary = json.loads((out / "summary.json").read_text())
    assert summary["format"] == "cfcontact-run"
    assert summary["status"] == "completed"
    assert summary["summary"]["points"] > 2
    assert summary["max_multiplicity"] >= 1
    assert "checkpoint" not in os.listdir(out)
    _assert_picture(str(out / "panel.png"), (800, 500))
    _assert_picture(str(out / "path.png"), (800, 450))
    path = SolutionPath.load(str(out / "path"))
    assert path.geometry is not None and len(path.transitions) == len(summary["transitions"])


@pytest.mark.slow
@pytest.mark.parametrize("name,slave,transitions", [("cylinder", "contact2=20", 12), ("punch", "contact2=20", 1),
                                                     ("nonmatching", "contact1=10", 7), ("obstacle", "contact1=10", 13),
                                                     ("half_cylinder", "contact2=20", 12)])
def test_example_contact_geometry_cases_run(cases, name, slave, transitions, capsys):
    """The example cases of the contact geometry run to the end without events (half_cylinder: the
    seed method from the zero load, as many transitions as the full cylinder).  obstacle.toml: the
    nodes at 1 +- x change state up to 2e-11 apart in alpha (the mesh is symmetric to 5e-12, the
    gaps to 1e-12; the exact method does not merge roots its rounding separates): 13 transitions,
    six pairs and the centre node.  The pairing's warning is one line of the command's, with
    neither the Python warning's file and source line nor logging's prefix (dolfinx routes Python
    warnings into logging)."""
    case = str(cases / f"{name}.toml")
    assert cli.main(["run", case]) == 0
    err = capsys.readouterr().err
    left_out = [line for line in err.splitlines() if "left out of the contact pairing" in line]
    assert len(left_out) == (name == "obstacle")  # nodes beyond obstacle.toml's search distance
    assert all(line.startswith("cfcontact: warning: 14 contact1=10 node(s) left out") for line in left_out)
    assert "py.warnings" not in err and "Warning" not in err and "return assemble" not in err
    out = cases / f"{name}_out"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and not summary["events"]
    assert len(summary["transitions"]) == transitions
    assert summary["contact"]["pairing"] == "segment" and summary["contact"]["slave"] == slave
    _assert_picture(str(out / "panel.png"), (800, 500))


@pytest.mark.slow
def test_example_case_via_python_m(cases):
    """python -m cfcontact run, in a subprocess (the foundation example)."""
    case = str(cases / "foundation.toml")
    proc = subprocess.run([sys.executable, "-m", "cfcontact", "run", case], capture_output=True, text=True,
                          env=_env(), cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stderr
    out = cases / "foundation_out"
    assert "completed" in proc.stdout and str(out) in proc.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["m"] == 12
    _assert_picture(str(out / "panel.png"), (800, 500))
    proc = subprocess.run([sys.executable, "-m", "cfcontact", "info", str(out)], capture_output=True, text=True,
                          env=_env(), cwd=ROOT, timeout=600)
    assert proc.returncode == 0 and "transitions" in proc.stdout


@pytest.mark.slow
def test_run_outputs_pdf_and_animation(tmp_path):
    case = _write(tmp_path, SMALL.replace("[output]", '[output]\nplot_formats = ["png", "pdf"]\n'
                                          'render_animation = true\nanimation_frames = 4\n'
                                          'component = "lam_n:5"\nzoom = [0.4, 0.6]'))
    assert cli.main(["run", case, "-q", "--output", str(tmp_path / "res")]) == 0
    res = tmp_path / "res"
    assert (res / "path.pdf").read_bytes()[:4] == b"%PDF"
    assert (res / "animation.gif").read_bytes()[:3] == b"GIF"
    _assert_picture(str(res / "path.png"))


@pytest.mark.slow
def test_run_refuses_existing_output_then_force(small_run, capsys):
    case, out = small_run
    before = os.path.getmtime(os.path.join(out, "summary.json"))
    assert cli.main(["run", case, "-q"]) == 2
    assert "--force" in capsys.readouterr().err
    assert cli.main(["run", case, "-q", "--force"]) == 0
    assert os.path.getmtime(os.path.join(out, "summary.json")) >= before
    assert not os.path.exists(out + ".partial") and not os.path.exists(out + ".old")
    # a replacement stopped between its two renames (<out> moved to <out>.old, the new one not yet
    # in place): the next run puts the earlier results back and refuses to overwrite them
    os.rename(out, out + ".old")
    assert cli.main(["run", case]) == 2
    err = capsys.readouterr().err
    assert "restored" in err and "--force" in err
    assert os.path.isfile(os.path.join(out, "summary.json")) and not os.path.exists(out + ".old")


@pytest.mark.slow
def test_run_warns_when_the_path_turned_back(tmp_path, monkeypatch, capsys):
    """A path that completed without reaching alpha_end (here: made to look so) gives one warning
    naming how far it got, and summary.json says it (turned_back, reach)."""
    monkeypatch.setattr(SolutionPath, "turned_back", lambda self: True)
    monkeypatch.setattr(SolutionPath, "reach", lambda self: 0.25)
    case = _write(tmp_path, SMALL)
    assert cli.main(["run", case]) == 0
    err = capsys.readouterr().err
    assert err.count("cfcontact: warning: the path turned back: it reaches alpha = 0.25 at most") == 1
    summary = json.loads((tmp_path / "case_out" / "summary.json").read_text())
    assert summary["turned_back"] is True and summary["reach"] == 0.25


UNVERIFIED = """[geometry]
kind = "block_on_foundation"
nx = 6
ny = 2
cell = "triangle"
[contact]
friction = 30.0
[loads.f1]
top1 = [-17511694.73680283, 27230397.169858932]
[loads.f2]
top1 = [34014175.402342595, -119631845.85064337]
right1 = [4145032.102798818, 1788469.482427346]
[path]
method = "seed"
[output]
plot = false
render_panel = false
"""


def test_run_and_info_say_when_the_seed_could_not_verify_a_transition(tmp_path, capsys):
    """A block on a foundation at F = 30 where a node closes slipping and sticks 7e-8 later (two
    set changes within h_min): the seed method finds no candidate, applies its fold rule and goes
    back to alpha = 0 -- a turn of the method, not of the problem (the exact path reaches
    alpha = 1).  The turned-back warning must not claim that no solution beyond is connected:
    run and info say that a transition could not be verified, where, and what resolves it."""
    case = _write(tmp_path, UNVERIFIED)
    assert cli.main(["run", case]) == 0
    err = capsys.readouterr().err
    assert err.count("cfcontact: warning:") == 2
    assert "the path turned back" in err and "may still be connected to the start" in err
    assert "no solution lies on it" not in err
    assert "1 transition(s) could not be verified (alpha = 0.229" in err and 'method = "exact"' in err
    assert cli.main(["info", str(tmp_path / "case_out")]) == 0
    out = capsys.readouterr().out
    assert "1 transition(s) could not be verified" in out and "may still be connected" in out
    exact = cfcontact.trace_path(case_file.build_system(case_file.load_case(case)), 0.0, 1.0, method="exact")
    assert exact.status == "completed" and exact.reach() == 1.0


def test_quiet_prints_nothing_verbose_shows_progress(tmp_path, capsys):
    case = _write(tmp_path, SMALL)
    assert cli.main(["run", case, "--quiet"]) == 0
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err == ""
    assert cli.main(["run", case, "--verbose", "--force"]) == 0
    cap = capsys.readouterr()
    assert "branches" in cap.err and "linear solves" in cap.err and "alpha=" in cap.err  # progress lines
    assert "completed" in cap.out


# ------------------------------------------------------------------ bad input
BAD = [
    ("unknown key", '[geometry]\nkind = "two_blocks"\n[contact]\nfrction = 0.3\n', ["frction", "[contact]", "friction"]),
    ("unknown section", '[geometry]\nkind = "two_blocks"\n[solver]\nx = 1\n', ["solver", "geometry"]),
    ("wrong type", '[geometry]\nkind = "two_blocks"\nnx = "12"\n', ["nx", "integer", "string"]),
    ("wrong type float", '[geometry]\nkind = "two_blocks"\n[material]\nE = "steel"\n', ["E", "number", "string"]),
    ("missing tag", '[geometry]\nkind = "two_blocks"\n[loads]\nclamp = ["left1", "left3"]\n', ["left3", "left2"]),
    ("missing load tag", '[geometry]\nkind = "two_blocks"\n[loads.f1]\ntop = [0, -1]\n', ["top", "[loads.f1]", "top1"]),
    ("foundation tag", '[geometry]\nkind = "block_on_foundation"\n[loads]\nclamp = ["left2"]\n', ["left2", "left1"]),
    ("negative friction", '[geometry]\nkind = "two_blocks"\n[contact]\nfriction = -0.2\n', ["friction", "-0.2"]),
    ("empty alpha range", '[geometry]\nkind = "two_blocks"\n[path]\nalpha_start = 0.5\nalpha_end = 0.5\n',
     ["alpha_start", "alpha_end", "empty"]),
    ("unknown method", '[geometry]\nkind = "two_blocks"\n[path]\nmethod = "newton"\n', ["method", "newton", "seed"]),
    ("bad geometry kind", '[geometry]\nkind = "sphere"\n', ["kind", "sphere", "two_blocks"]),
    ("missing mesh", '[geometry]\nkind = "msh"\nfile = "nope.msh"\n', ["file", "nope.msh"]),
    ("inclined without angle", '[geometry]\nkind = "inclined"\n', ["angle"]),
    ("bad TOML", '[geometry\nkind = "two_blocks"\n', ["TOML"]),
    ("component range", SMALL + 'component = ["lam_n", 99]\n', ["component", "99"]),
    ("material missing body", '[geometry]\nkind = "two_blocks"\n[material]\nE = {body1 = 2.1e11}\n',
     ["[material] E", "body2"]),
    ("material unknown body", '[geometry]\nkind = "two_blocks"\n[material]\nnu = {body1 = 0.3, body3 = 0.3}\n',
     ["[material] nu", "body3", "body2=2"]),
    ("material bad value", '[geometry]\nkind = "two_blocks"\n[material]\nnu = {body1 = 0.3, body2 = 0.7}\n',
     ["nu.body2", "0.7", "(-1, 0.5)"]),
    ("window bad key", '[geometry]\nkind = "two_blocks"\n[loads.f1]\ntop1 = {value = [0, -1], x = [1, 2], z = 1}\n',
     ["[loads] f1.top1", "value", "z"]),
    ("window empty", '[geometry]\nkind = "two_blocks"\n[loads.f1]\ntop1 = [{value = [0, -1], x = [2, 1]}]\n',
     ["[loads] f1.top1[0].x", "lo < hi"]),
    ("unclamped body", '[geometry]\nkind = "two_blocks"\nnx = 4\nny = 2\n[loads]\nclamp = ["left1"]\n',
     ["body 2", "Dirichlet"]),
    # [contact] pairing keys and [loads.dirichlet] (issue #12): checked before the model is built ...
    ("search distance zero", '[geometry]\nkind = "two_blocks"\n[contact]\npairing = "segment"\nsearch_distance = 0\n',
     ["[contact] search_distance", "> 0"]),
    ("slave not a contact boundary", '[geometry]\nkind = "two_blocks"\n[contact]\npairing = "segment"\n'
     'slave = "left2"\n', ["[contact] slave", "contact1=10 or contact2=20", "left2"]),
    # ... or while it is built (what only the mesh tells), still exit 2 with the key named
    ("obstacle not facing", '[geometry]\nkind = "block_on_foundation"\nnx = 6\nny = 2\n[contact.obstacle]\n'
     'kind = "circle"\ncenter = [1.5, 3.0]\nradius = 0.5\n', ["[contact.obstacle]", "does not face contact1"]),
    ("non-matching with node pairing", '[geometry]\nkind = "two_blocks"\nnx = 6\nny = 2\nnx2 = 7\n',
     ["[contact] pairing", "non-matching", 'pairing = "segment" in [contact]']),
    ("prescribed on a contact node", '[geometry]\nkind = "two_blocks"\nnx = 6\nny = 2\n[loads.dirichlet]\n'
     'right1 = {y = [0.0, 1.0e-3]}\n', ["[loads.dirichlet]", "non-zero prescribed displacement", "(3, 0)"]),
]


@pytest.mark.parametrize("label,text,words", BAD, ids=[b[0] for b in BAD])
def test_bad_input_exit_2_one_message_no_output(tmp_path, capsys, label, text, words):
    case = _write(tmp_path, text)
    assert cli.main(["run", case]) == 2
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err and lines[0].startswith("cfcontact run: error:")
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert sorted(os.listdir(tmp_path)) == ["case.toml"]  # no output folder, no .partial


@pytest.mark.slow
def test_bad_input_msh_tag_names_valid_groups(cases, tmp_path, capsys):
    shutil.copy(cases / MSH_NAME, tmp_path / MSH_NAME)
    case = _write(tmp_path, f'[geometry]\nkind = "msh"\nfile = "{MSH_NAME}"\n[loads]\nclamp = ["left1", "left2"]\n'
                            '[loads.f1]\ntop1 = [0, -1]\n[loads.f2]\nroof = [1, 0]\n')
    assert cli.main(["run", case]) == 2
    err = capsys.readouterr().err
    assert "roof" in err and "[loads.f2]" in err and "top1=12" in err
    assert sorted(os.listdir(tmp_path)) == sorted(["case.toml", MSH_NAME])


def test_bad_command_line(tmp_path, capsys):
    assert cli.main(["run"]) == 2  # argparse usage error
    assert cli.main(["run", str(tmp_path / "missing.toml")]) == 2
    assert "no such case file" in capsys.readouterr().err
    assert cli.main(["info", str(tmp_path)]) == 2
    assert "not a saved path" in capsys.readouterr().err
    assert cli.main(["--version"]) == 0


# ------------------------------------------------------------------ plot / render / info
def test_info(small_run, capsys):
    _, out = small_run
    assert cli.main(["info", out]) == 0
    text = capsys.readouterr().out
    for w in ("status completed", "transitions:", "transversal", "folds:", "multiplicity over alpha", "events:",
              "linear_solves", "timings (summary.json): assembly "):
        assert w in text, w
    assert cli.main(["info", os.path.join(out, "path"), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["status"] == "completed" and rep["multiplicity"][0]["solutions"] == 1
    assert rep["timings"] == json.load(open(os.path.join(out, "summary.json")))["timings"]
    folds = len(rep["folds"])
    assert f"transversal, {folds} fold{'' if folds == 1 else 's'})" in text
    assert len(rep["transitions"]) == json.load(open(os.path.join(out, "summary.json")))["summary"]["transitions"]


@pytest.mark.slow
def test_plot(small_run, tmp_path):
    _, out = small_run
    png = str(tmp_path / "p.png")
    assert cli.main(["plot", out, "--component", "lam_t:3", "--zoom", "0.4", "0.6", "-o", png, "-q"]) == 0
    _assert_picture(png, (800, 450))
    pdf = tmp_path / "p.pdf"
    assert cli.main(["plot", out, "-o", str(pdf), "-q"]) == 0
    assert pdf.read_bytes()[:4] == b"%PDF"
    mult = str(tmp_path / "m.png")
    assert cli.main(["plot", out, "--multiplicity", "-o", mult, "-q"]) == 0
    _assert_picture(mult)
    assert cli.main(["plot", out, "--component", "lam_q:1", "-o", png]) == 2
    assert cli.main(["plot", out, "-o", str(tmp_path / "p.jpg")]) == 2


@pytest.mark.slow
def test_render(small_run, tmp_path, capsys):
    _, out = small_run
    one = str(tmp_path / "one.png")
    assert cli.main(["render", out, "--alpha", "0.5", "--window-size", "640", "400", "-o", one]) == 0
    assert "1 solution(s) at alpha = 0.5" in capsys.readouterr().out
    _assert_picture(one, (640, 400))
    panel = str(tmp_path / "panel.png")
    assert cli.main(["render", out, "--panel", "--window-size", "500", "300", "-o", panel, "-q"]) == 0
    _assert_picture(panel, (500, 300))
    gif = tmp_path / "anim.gif"
    assert cli.main(["render", out, "--animation", str(gif), "--frames", "3", "--window-size", "320", "200",
                     "-q"]) == 0
    assert gif.read_bytes()[:3] == b"GIF"
    assert cli.main(["render", out, "--alpha", "7", "-o", one]) == 2
    assert "covers alpha" in capsys.readouterr().err


# ------------------------------------------------------------------ stop and resume
def _resume_equals(tmp_path, small_run, stop_args, expect_code=3):
    ref = SolutionPath.load(os.path.join(small_run[1], "path"))
    case = _write(tmp_path, SMALL)
    out = tmp_path / "case_out"
    assert cli.main(["run", case, "-q", *stop_args]) == expect_code
    assert not out.exists()
    ck = tmp_path / "case_out.partial" / "checkpoint"
    state = json.loads((ck / "state.json").read_text())
    assert state["resumable"] and state["resume_state"]["h"] > 0
    partial = SolutionPath.load(str(ck / "path"))
    assert partial.status == "stopped by callback" and len(partial.alphas) < len(ref.alphas)
    # without --resume: refused (exit 2), checkpoint kept
    assert cli.main(["run", case, "-q"]) == 2
    assert ck.exists()
    assert cli.main(["run", case, "-q", "--resume"]) == 0
    assert not (tmp_path / "case_out.partial").exists()
    _same_path(SolutionPath.load(str(out / "path")), ref)
    return partial


def test_stop_after_transitions_and_resume(tmp_path, small_run):
    partial = _resume_equals(tmp_path, small_run, ["--stop-after-transitions", "3"])
    assert len(partial.transitions) == 3


@pytest.mark.slow
def test_stop_at_alpha_and_resume(tmp_path, small_run):
    partial = _resume_equals(tmp_path, small_run, ["--stop-at-alpha", "0.6"])
    assert partial.alphas[-1] >= 0.6 and partial.alphas[-2] < 0.6


@pytest.mark.slow
def test_time_limit_and_resume(tmp_path, small_run):
    partial = _resume_equals(tmp_path, small_run, ["--time-limit", "1e-6"])
    assert len(partial.alphas) == 1  # stopped at the start point


def test_a_ctrl_c_that_a_library_re_raised_is_an_interrupt(tmp_path, monkeypatch, capsys):
    """A Ctrl-C that lands in a class body's ``__set_name__`` while a module is imported reaches
    the program as RuntimeError("Error calling __set_name__ ...") on Python 3.11 (seen once in
    the random-interrupt test: pyparsing's Regex, which matplotlib imports when the plots are
    written): it is an interrupt, exit 130 with the interrupt line, not "failed" with exit 1."""
    from cfcontact.interrupts import caused_by_interrupt

    class Descriptor:
        def __set_name__(self, owner, name):
            raise KeyboardInterrupt

    try:
        type("Regex", (), {"re": Descriptor()})  # what Python does with a class body
    except BaseException as exc:  # RuntimeError from KeyboardInterrupt (3.11), KeyboardInterrupt (3.12+)
        wrapped = exc
    assert caused_by_interrupt(wrapped)
    assert not caused_by_interrupt(RuntimeError("a real failure"))
    try:
        try:
            raise ValueError("a")
        except ValueError as a:
            raise RuntimeError("b") from a
    except RuntimeError as b:
        assert not caused_by_interrupt(b)

    def build(self):
        raise wrapped

    monkeypatch.setattr(run.CaseRun, "build", build)
    case = _write(tmp_path, SMALL)
    assert cli.main(["run", case, "-q"]) == 130
    err = capsys.readouterr().err
    assert "interrupted before the path was traced" in err and "failed" not in err
    assert not os.path.exists(str(tmp_path / "case_out")) and not os.path.exists(str(tmp_path / "case_out.partial"))


@pytest.mark.slow
def test_ctrl_c_and_resume(tmp_path, small_run, monkeypatch):
    on_point = run.Runner.on_point

    def interrupt_at_40(self, pt):
        if pt.index == 40:
            signal.raise_signal(signal.SIGINT)  # handled by the CLI: stop at the next point
        return on_point(self, pt)

    monkeypatch.setattr(run.Runner, "on_point", interrupt_at_40)
    case = _write(tmp_path, SMALL)
    assert cli.main(["run", case, "-q"]) == 130
    monkeypatch.setattr(run.Runner, "on_point", on_point)
    state = json.loads((tmp_path / "case_out.partial" / "checkpoint" / "state.json").read_text())
    assert "Ctrl-C" in state["reason"]
    assert cli.main(["run", case, "-q", "--resume"]) == 0
    _same_path(SolutionPath.load(str(tmp_path / "case_out" / "path")), SolutionPath.load(
        os.path.join(small_run[1], "path")))


@pytest.mark.slow
def test_periodic_checkpoints_do_not_change_the_path(tmp_path, small_run, monkeypatch):
    saves = []
    save = run.save_checkpoint
    monkeypatch.setattr(run, "save_checkpoint", lambda *a: saves.append(a[3]) or save(*a))
    case = _write(tmp_path, SMALL)
    assert cli.main(["run", case, "-q", "--checkpoint-every", "1e-9"]) == 0
    assert len(saves) > 100 and set(saves) == {"checkpoint"}
    _same_path(SolutionPath.load(str(tmp_path / "case_out" / "path")),
               SolutionPath.load(os.path.join(small_run[1], "path")))
    assert sorted(os.listdir(tmp_path)) == ["case.toml", "case_out"]


@pytest.mark.slow
def test_resume_checks(tmp_path, capsys):
    case = _write(tmp_path, SMALL)
    assert cli.main(["run", case, "-q", "--resume"]) == 2
    assert "nothing to resume" in capsys.readouterr().err
    assert cli.main(["run", case, "-q", "--stop-after-transitions", "2"]) == 3
    _write(tmp_path, SMALL.replace("friction = 1.5", "friction = 1.0"))
    assert cli.main(["run", case, "-q", "--resume"]) == 2
    assert "[contact]" in capsys.readouterr().err
    assert cli.main(["run", case, "-q", "--force"]) == 0  # start over
    assert not (tmp_path / "case_out.partial").exists()


QUICK = SMALL.replace("[output]\n", "[output]\nplot = false\nrender_panel = false\n")


def test_the_printed_resume_command_of_a_forced_run_works(tmp_path, capsys):
    """A run that replaces an existing output (--force) and is stopped prints "continue with:
    cfcontact run --resume ..."; that command, run literally, completes the run and replaces the
    output as the --force run would have (the checkpoint records the --force)."""
    import shlex

    case = _write(tmp_path, QUICK)
    out = str(tmp_path / "G")
    assert cli.main(["run", case, "-o", out]) == 0
    first = os.path.getmtime(os.path.join(out, "summary.json"))
    capsys.readouterr()
    assert cli.main(["run", case, "-o", out, "--force", "--time-limit", "0.001"]) == 3
    printed = [line for line in capsys.readouterr().out.splitlines() if line.startswith("continue with: ")]
    assert len(printed) == 1, printed
    command = shlex.split(printed[0][len("continue with: "):])
    assert command[:3] == ["cfcontact", "run", "--resume"]
    assert json.loads((tmp_path / "G.partial" / "checkpoint" / "state.json").read_text())["replace"] is True
    assert cli.main(command[1:]) == 0, capsys.readouterr().err
    assert not (tmp_path / "G.partial").exists() and os.path.getmtime(os.path.join(out, "summary.json")) > first
    assert SolutionPath.load(os.path.join(out, "path")).status == "completed"
    # a stopped run that was not started with --force still refuses to replace an existing output
    assert cli.main(["run", case, "-o", str(tmp_path / "H"), "--time-limit", "0.001", "-q"]) == 3
    shutil.copytree(out, tmp_path / "H")
    assert cli.main(["run", case, "-o", str(tmp_path / "H"), "--resume", "-q"]) == 2
    assert "exists; use --force" in capsys.readouterr().err


def test_a_path_that_ends_at_max_steps_exits_4(tmp_path, capsys):
    """[path] max_steps cuts the path short like max_transitions: the outputs are written, a warning
    names the status, exit code 4 (not a whole result)."""
    case = _write(tmp_path, QUICK + '[path]\nmethod = "seed"\nmax_steps = 3\n')
    assert cli.main(["run", case]) == 4
    err = capsys.readouterr().err
    assert "status 'max_steps'" in err, err
    assert json.loads((tmp_path / "case_out" / "summary.json").read_text())["summary"]["status"] == "max_steps"


def test_empty_output_names_and_a_file_as_output_folder(tmp_path, capsys):
    """-o "" is refused (exit 2), not read as "no -o" (the default folder written silently); an
    existing regular file as run's or map's output folder is named a file, not an existing folder."""
    case = _write(tmp_path, QUICK)
    (tmp_path / "F").write_text("keep")
    for command, words in ((["run", case, "-o", ""], ["-o/--output", "empty"]),
                           (["map", case, "-o", ""], ["-o/--output", "empty"]),
                           (["plot", str(tmp_path), "-o", ""], ["-o/--output", "empty"]),
                           (["render", str(tmp_path), "--animation", ""], ["--animation", "empty"]),
                           (["run", case, "-o", str(tmp_path / "F")], ["'" + str(tmp_path / "F") + "'",
                                                                       "is a file, not a folder"]),
                           (["run", case, "-o", str(tmp_path / "F"), "--force"], ["is a file, not a folder"]),
                           (["map", case, "-o", str(tmp_path / "F")], ["is a file, not a folder"])):
        assert cli.main(command) == 2, command
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and "exists" not in err, err
        for w in words:
            assert w in err, (w, err)
    assert sorted(os.listdir(tmp_path)) == ["F", "case.toml"] and (tmp_path / "F").read_text() == "keep"


def test_plot_multiplicity_refuses_component_and_zoom(tmp_path, capsys):
    """--multiplicity plots the number of solutions: a --component or --zoom with it is refused
    (exit 2, one line naming the flag), not silently ignored; nothing is written."""
    for extra, flag in ((["--component", "lam_n:3"], "--component"), (["--zoom", "0.1", "0.2"], "--zoom")):
        assert cli.main(["plot", str(tmp_path), "--multiplicity", *extra, "-o", str(tmp_path / "m.png")]) == 2
        err = capsys.readouterr().err
        assert len(err.strip().splitlines()) == 1 and f"{flag}: not with --multiplicity" in err, err
    assert os.listdir(tmp_path) == []


@pytest.mark.slow
def test_ctrl_c_while_the_outputs_are_written_keeps_the_checkpoint(tmp_path):
    """SIGINT while the panel is rendered (VTK: a KeyboardInterrupt raised in there could be lost,
    and the run ended "completed"): exit 130, the traced checkpoint kept, no output folder;
    --resume then writes the outputs.  The signal is sent when the run logs that it renders."""
    case = _write(tmp_path, SMALL.replace("[output]\n", "[output]\nplot = false\n"))
    proc = subprocess.Popen([sys.executable, "-m", "cfcontact", "run", "-v", case], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env=_env(), cwd=ROOT)
    lines = []
    for line in proc.stdout:
        lines.append(line)
        if "writing" in line and "panel.png" in line:
            proc.send_signal(signal.SIGINT)
            break
    rest, _ = proc.communicate(timeout=300)
    text = "".join(lines) + rest
    assert proc.returncode == 130, text
    assert "Traceback" not in text and "cfcontact: completed" not in text, text
    partial = tmp_path / "case_out.partial"
    assert not (tmp_path / "case_out").exists() and os.listdir(partial) == ["checkpoint"], text
    assert json.loads((partial / "checkpoint" / "state.json").read_text())["traced"] is True
    assert cli.main(["run", case, "-q", "--resume"]) == 0
    assert not partial.exists() and (tmp_path / "case_out" / "panel.png").is_file()


def test_the_ctrl_c_note_is_written_past_sys_stderr(capfd):
    """The first Ctrl-C's note is written on stderr's descriptor, not through sys.stderr: a signal
    that comes while a log line is being written there made Python raise "reentrant call" inside
    logging, which printed a traceback (seen on Debian 13 when the SIGINT met the "writing
    panel.png" line)."""
    import io

    class Busy(io.TextIOWrapper):  # a stderr whose writer is busy: any write through it fails
        def write(self, text):
            raise RuntimeError("reentrant call inside <_io.BufferedWriter name='<stderr>'>")

    busy = Busy(io.BufferedWriter(io.FileIO(os.dup(2), "w")))
    real = sys.stderr
    sys.stderr = busy
    try:
        cli._note_from_handler("\ncfcontact: stopping\n")
    finally:
        sys.stderr = real
    assert "cfcontact: stopping" in capfd.readouterr().err


def test_ctrl_c_that_a_library_swallows_while_the_outputs_are_written(tmp_path, monkeypatch, capsys):
    """A library that catches the KeyboardInterrupt of a Ctrl-C while it works (as C libraries with
    Python callbacks can) no longer makes the run end "completed": while the outputs are written a
    Ctrl-C only sets a flag, asked before each output: exit 130, the checkpoint kept, resumable."""
    from cfcontact import plotting

    save = plotting.save_figure

    def swallowing_save(fig, fn, *a, **k):
        try:
            signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt:  # the library's own handling
            pass
        return save(fig, fn, *a, **k)

    monkeypatch.setattr(plotting, "save_figure", swallowing_save)
    case = _write(tmp_path, SMALL.replace("[output]\n", "[output]\nrender_panel = false\n"))
    assert cli.main(["run", case, "-q"]) == 130
    assert "interrupted" in capsys.readouterr().err
    partial = tmp_path / "case_out.partial"
    assert not (tmp_path / "case_out").exists() and os.listdir(partial) == ["checkpoint"]
    monkeypatch.setattr(plotting, "save_figure", save)
    assert cli.main(["run", case, "-q", "--resume"]) == 0
    assert (tmp_path / "case_out" / "path.png").is_file() and not partial.exists()


def test_failure_removes_partial_folder(tmp_path, monkeypatch, capsys):
    def boom(*a, **k):
        raise RuntimeError("boom")

    monkeypatch.setattr(run, "write_outputs", boom)
    case = _write(tmp_path, SMALL)
    assert cli.main(["run", case]) == 1
    assert "boom" in capsys.readouterr().err
    assert sorted(os.listdir(tmp_path)) == ["case.toml"]


# ------------------------------------------------------------------ stop and resume, method exact
# Two blocks with the loads of demos/main.py (triangles, so that friction makes the solution
# non-unique without a second block height): 20 transitions, 2 folds, multiplicity 3, ~1 s.
EXACT = """
title = "exact, folds"
[geometry]
kind = "two_blocks"
nx = 12
ny = 4
cell = "triangle"
[contact]
friction = 30.0
[loads.f1]
top1 = [-5.734e7, 3.658e6]
right1 = [3.910e7, -8.724e7]
bottom2 = [1.877e8, -1.500e6]
[loads.f2]
top1 = [1.0e8, 0.0]
right2 = [-5.807e7, 1.510e3]
bottom2 = [-1.045e8, 1.450e8]
[path]
method = "exact"
[output]
plot = false
render_panel = false
"""


@pytest.fixture(scope="module")
def exact_run(tmp_path_factory):
    """An uninterrupted exact run of EXACT: (case file, output folder)."""
    d = tmp_path_factory.mktemp("exact")
    case = _write(d, EXACT)
    assert cli.main(["run", case, "-q"]) == 0
    out = str(d / "case_out")
    ref = SolutionPath.load(os.path.join(out, "path"))
    assert ref.method == "exact" and ref.status == "completed" and len(ref.folds) >= 2
    assert ref.max_multiplicity()[0] >= 3
    return case, out


def _same_exact_result(out, ref_out):
    """The resumed run's output equals the uninterrupted one's: transitions (alpha to 1e-12, kind,
    nodes, changes), folds, branches (sets, orientation), multiplicity, events.

    Not bit for bit: the resumed process factorizes afresh what the uninterrupted one took from
    its solver's cache (J(Z) of an equivalent Z), which changes the last bits."""
    a, b = SolutionPath.load(os.path.join(out, "path")), SolutionPath.load(os.path.join(ref_out, "path"))
    assert a.status == b.status == "completed"
    assert [(t.kind, t.node, t.set, t.from_branch, t.to_branch, t.changes) for t in a.transitions] == \
        [(t.kind, t.node, t.set, t.from_branch, t.to_branch, t.changes) for t in b.transitions]
    np.testing.assert_allclose([t.alpha for t in a.transitions], [t.alpha for t in b.transitions], rtol=0, atol=1e-12)
    np.testing.assert_allclose([t.alpha for t in a.folds], [t.alpha for t in b.folds], rtol=0, atol=1e-12)
    assert [(br.sets.states(), br.orientation, br.parent, br.origin, br.points) for br in a.branches] == \
        [(br.sets.states(), br.orientation, br.parent, br.origin, br.points) for br in b.branches]
    np.testing.assert_allclose(a.alphas, b.alphas, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(a.point_branch, b.point_branch)
    np.testing.assert_allclose(a.ys, b.ys, rtol=0, atol=1e-12 * np.abs(b.ys).max())
    assert [(e.kind, e.branch) for e in a.events] == [(e.kind, e.branch) for e in b.events]
    assert a.max_multiplicity()[0] == b.max_multiplicity()[0]
    sa, sb = (json.load(open(os.path.join(d, "summary.json"))) for d in (out, ref_out))
    assert sa["max_multiplicity"] == sb["max_multiplicity"]
    assert [m["solutions"] for m in sa["multiplicity"]] == [m["solutions"] for m in sb["multiplicity"]]
    np.testing.assert_allclose([(m["alpha_lo"], m["alpha_hi"]) for m in sa["multiplicity"]],
                               [(m["alpha_lo"], m["alpha_hi"]) for m in sb["multiplicity"]], rtol=0, atol=1e-12)


EXACT_STOPS = [(["--stop-after-folds", "1"], 3), (["--stop-after-transitions", "5"], 3),
               (["--stop-at-alpha", "0.3"], 3), (["--time-limit", "1e-6"], 3)]


@pytest.mark.parametrize("stop_args,code", EXACT_STOPS, ids=[s[0][0] for s in EXACT_STOPS])
def test_exact_stop_and_resume(tmp_path, exact_run, stop_args, code):
    ref = SolutionPath.load(os.path.join(exact_run[1], "path"))
    case = _write(tmp_path, EXACT)
    out = tmp_path / "case_out"
    assert cli.main(["run", case, "-q", *stop_args]) == code
    assert not out.exists()
    ck = tmp_path / "case_out.partial" / "checkpoint"
    state = json.loads((ck / "state.json").read_text())
    assert state["method"] == "exact" and state["resumable"]
    rs = state["resume_state"]
    partial = SolutionPath.load(str(ck / "path"))
    assert partial.status == "stopped by callback" and len(partial.transitions) < len(ref.transitions)
    b = partial.branches[rs["branch"]]
    assert rs["orientation"] == b.orientation and rs["alpha"] == b.alpha_enter == partial.alphas[-1]
    assert rs["states"] == b.sets.states()
    if stop_args[0] == "--stop-after-folds":
        assert len(partial.folds) == 1 and partial.transitions[-1].kind == "fold"  # exactly one fold
    elif stop_args[0] == "--stop-after-transitions":
        assert len(partial.transitions) == 5
    elif stop_args[0] == "--stop-at-alpha":  # the exit and the next entry point share their alpha
        assert partial.alphas[-1] >= 0.3 and [a for a in partial.alphas if a != partial.alphas[-1]][-1] < 0.3
    else:
        assert len(partial.alphas) == 1  # stopped at the start point
    assert cli.main(["run", case, "-q"]) == 2  # without --resume: refused, checkpoint kept
    assert ck.exists()
    assert cli.main(["run", case, "-q", "--resume"]) == 0
    assert not (tmp_path / "case_out.partial").exists()
    _same_exact_result(str(out), exact_run[1])


def test_exact_stop_twice_ctrl_c_and_resume(tmp_path, exact_run, monkeypatch):
    """Ctrl-C, then a stop condition on the resumed run, then the rest: same result."""
    on_point = run.Runner.on_point

    def interrupt_at_4(self, pt):
        if pt.index == 4:
            signal.raise_signal(signal.SIGINT)  # handled by the CLI: stop at the next point
        return on_point(self, pt)

    monkeypatch.setattr(run.Runner, "on_point", interrupt_at_4)
    case = _write(tmp_path, EXACT)
    assert cli.main(["run", case, "-q"]) == 130
    monkeypatch.setattr(run.Runner, "on_point", on_point)
    ck = tmp_path / "case_out.partial" / "checkpoint"
    state = json.loads((ck / "state.json").read_text())
    assert "Ctrl-C" in state["reason"] and state["resumable"]
    assert len(SolutionPath.load(str(ck / "path")).alphas) == 5  # stopped at the next point
    assert cli.main(["run", case, "-q", "--resume", "--stop-after-transitions", "12"]) == 3
    assert len(SolutionPath.load(str(ck / "path")).transitions) == 12
    assert cli.main(["run", case, "-q", "--resume"]) == 0
    _same_exact_result(str(tmp_path / "case_out"), exact_run[1])


def test_exact_periodic_checkpoints_do_not_change_the_path(tmp_path, exact_run, monkeypatch):
    saves = []
    save = run.save_checkpoint
    monkeypatch.setattr(run, "save_checkpoint", lambda *a: saves.append(a[3]) or save(*a))
    case = _write(tmp_path, EXACT)
    assert cli.main(["run", case, "-q", "--checkpoint-every", "1e-9"]) == 0
    ref = SolutionPath.load(os.path.join(exact_run[1], "path"))
    assert len(saves) >= len(ref.transitions) and set(saves) == {"checkpoint"}
    _same_exact_result(str(tmp_path / "case_out"), exact_run[1])
    assert sorted(os.listdir(tmp_path)) == ["case.toml", "case_out"]


def test_windowed_tractions_in_a_case_file(tmp_path):
    """[loads.f1] with a uniform and a windowed traction on one piece (an array of inline tables)
    gives the library's load vectors."""
    case = _write(tmp_path, '[geometry]\nkind = "two_blocks"\nnx = 6\nny = 2\n[loads.f1]\n'
                            'top1 = [[0.0, -1.0e6], {value = [2.0e5, -3.0e5], x = [1.5, 2.5]}]\n'
                            '[loads.f2]\nbottom2 = {value = [1.0e5, 0.0], x = [0.0, 1.0]}\n')
    system = case_file.build_system(case_file.load_case(case))
    ref = cfcontact.two_blocks(nx=6, ny=2, tractions1={"top1": [(0.0, -1.0e6), {"value": (2.0e5, -3.0e5), "x": (1.5, 2.5)}]},
                               tractions2={"bottom2": {"value": (1.0e5, 0.0), "x": (0.0, 1.0)}})
    for a, b in zip(system.loads_numpy(), ref.loads_numpy()):
        assert np.abs(a).max() > 0 and np.array_equal(a, b)
    assert system.info["tractions1"]["top1=12"][1] == {"value": [2.0e5, -3.0e5], "x": [1.5, 2.5]}


def test_seed_periodic_checkpoints_do_not_restart_the_run(tmp_path, monkeypatch):
    """With the seed method a periodic checkpoint is a save: one stepper traces the whole path."""
    from cfcontact import seed

    made, saves = [], []
    init, save = seed.SeedStepper.__init__, run.save_checkpoint
    monkeypatch.setattr(seed.SeedStepper, "__init__", lambda self, *a, **k: made.append(1) or init(self, *a, **k))
    monkeypatch.setattr(run, "save_checkpoint", lambda *a: saves.append(a[3]) or save(*a))
    case = _write(tmp_path, SMALL.replace("[output]", "[output]\nplot = false\nrender_panel = false"))
    assert cli.main(["run", case, "-q", "--checkpoint-every", "0.02"]) == 0
    assert made == [1] and saves and set(saves) == {"checkpoint"}
    assert SolutionPath.load(str(tmp_path / "case_out" / "path")).status == "completed"


# ------------------------------------------------------------------ real contact geometry (issue #12)
HALF_CYLINDER = """
[geometry]
kind = "cylinder"
width = 3.0
depth = 1.5
size = 0.05
size_far = 0.5
half = true
[material]
E = 1.0
[contact]
friction = 0.3
[loads.dirichlet]
top1 = {x = 0.0, y = [0.0, -0.03]}
sym1 = {x = 0.0}
sym2 = {x = 0.0}
[path]
method = "exact"
[output]
plot = false
render_panel = false
"""


def test_info_of_a_case_reports_its_pairing(tmp_path, capsys):
    """cfcontact info CASE.toml builds the model and reports the pairing the assembly recorded."""
    case = _write(tmp_path, open(os.path.join(CASES, "obstacle.toml")).read().replace("nx = 40", "nx = 20"))
    assert cli.main(["info", case]) == 0
    text = capsys.readouterr().out
    with pytest.warns(cfcontact.PairingWarning, match="left out"):
        system = case_file.build_system(case_file.load_case(case))
    c = system.info["contact"]
    for w in (f"m = {system.m} contact pairs", f"contact: {system.m} pairs, segment pairing, slave contact1=10, "
              "master obstacle", f"excluded nodes: {c['excluded']} ({c['excluded']} beyond the search distance); "
              "search distance 0.2", f"initial gap: {c['gap_range'][0]:.6g} .. {c['gap_range'][1]:.6g}",
              "top1=12 u_x 0 -> 0, u_y 0 -> -0.03", "model block_on_foundation: "):
        assert w in text, (w, text)
    assert cli.main(["info", case, "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["model"] == "block_on_foundation"  # the case's kind (its builder is two_blocks)
    rep = rep["contact"]
    assert rep["excluded"] == c["excluded"] > 0 and rep["gap_range"] == c["gap_range"] and rep["source"] == "model"
    assert sorted(os.listdir(tmp_path)) == ["case.toml"]  # info writes nothing
    bad = _write(tmp_path, "[geometry]\nkind = \"two_blocks\"\n[contact]\npairing = \"edge\"\n", "bad.toml")
    assert cli.main(["info", bad]) == 2 and "[contact] pairing" in capsys.readouterr().err


def test_info_of_a_saved_path_reports_its_pairing(tmp_path, capsys):
    """A run's path: the pairing from the path (pairs, slave side, master, pairs without tangential
    unknown) and its case.toml (pairing, slave, search distance), and the gap the path stores; the
    excluded nodes are not stored with a path, and info says so.  summary.json has the same from the path alone.
    (The half model's exact path: its centre node has no tangential unknown.)"""
    case = _write(tmp_path, HALF_CYLINDER)
    assert cli.main(["run", case, "-q"]) == 0
    out = tmp_path / "case_out"
    assert cli.main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    path = SolutionPath.load(str(out / "path"))
    for w in (f"contact: {path.m} pairs, segment pairing, slave contact2=20, master contact1=10",
              "excluded nodes: not stored with a saved path", "search distance none",
              f"initial gap: 0 .. {path.gap.max():.6g}", "1 pair(s) without tangential unknown"):
        assert w in text, (w, text)
    summary = json.loads((out / "summary.json").read_text())["contact"]
    assert summary["pairing"] == "segment" and summary["slave"] == "contact2=20" and summary["no_tangent"] == 1
    from cfcontact.report import contact_report

    path.gap = np.linspace(0.0, 0.05, path.m)  # the path's gap: its range is reported
    assert contact_report(path)["gap_range"] == [0.0, 0.05]
    # a path saved by the library (no case.toml next to it): what the path tells
    path.save(tmp_path / "lib")
    assert cli.main(["info", str(tmp_path / "lib"), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert "timings" not in rep  # (no run folder: no summary.json)
    rep = rep["contact"]
    assert (rep["pairing"], rep["slave"], rep["master"], rep["search_distance"]) == ("segment", "contact2=20",
                                                                                      "contact1=10", None)


def test_info_of_a_two_block_run_reports_node_pairing(small_run, capsys):
    _, out = small_run
    assert cli.main(["info", out]) == 0
    assert "contact: 12 pairs, node pairing, slave contact1=10, master contact2=20" in capsys.readouterr().out


PRESCRIBED = """
[geometry]
kind = "two_blocks"
nx = 6
ny = 2
[contact]
friction = 0.3
[loads]
clamp = ["left2"]
[loads.f1]
right1 = [-1.0e7, 0.0]
[loads.f2]
right1 = [-1.0e7, 0.0]
[loads.dirichlet]
top1 = {x = [0.0, 2.0e-4], y = [-1.0e-4, -2.0e-4]}
[output]
plot = false
stress = true
render_animation = true
animation_frames = 3
"""


def test_stresses_include_the_prescribed_displacements(tmp_path, monkeypatch, capsys):
    """run ([output] stress: panel and animation) and render --stress colour the cells by the von
    Mises stress of each solution at its own alpha: the prescribed displacements enter."""
    from cfcontact import fields, render

    got = {}
    monkeypatch.setattr(render, "render_panel", lambda geo, sols, fn, **kw: got.update(panel=(sols, kw["stresses"])))
    monkeypatch.setattr(render, "render_solution", lambda geo, sol, fn, **kw: got.update(one=(sol, kw["stress"])))

    def animation(path, fn, **kw):
        got["animation"] = kw["stress"]
        return render.AnimationResult("gif", str(fn), 3, [], 1.0)

    monkeypatch.setattr(render, "render_animation", animation)
    case = _write(tmp_path, PRESCRIBED)
    assert cli.main(["run", case, "-q"]) == 0
    path = SolutionPath.load(str(tmp_path / "case_out" / "path"))
    geo = path.geometry
    assert geo.prescribed is not None

    def check(sol, stress):
        assert sol.alpha > 0
        assert np.array_equal(stress, fields.von_mises(geo, sol.u, alpha=sol.alpha))
        assert np.abs(stress - fields.von_mises(geo, sol.u)).max() > 1e-3 * np.abs(stress).max()

    sols, stresses = got["panel"]
    for sol, stress in zip(sols, stresses):
        check(sol, stress)
    sol = path.solutions_at(0.5)[0]
    check(sol, got["animation"](sol))
    assert cli.main(["render", str(tmp_path / "case_out"), "--stress", "--alpha", "0.5", "-o",
                     str(tmp_path / "r.png"), "-q"]) == 0
    check(*got["one"])
    monkeypatch.setattr(render, "render_animation", animation)
    got.pop("animation")
    assert cli.main(["render", str(tmp_path / "case_out"), "--stress", "--animation", str(tmp_path / "a.gif"),
                     "-q"]) == 0
    check(sol, got["animation"](sol))


HOMOTOPY = """
title = "a start SSNM does not reach"
[geometry]
kind = "two_blocks"
nx = 12
ny = 4
cell = "triangle"
[contact]
friction = 30.0
[loads.f1]
top1 = [1.304e8, -1.532e8]
right1 = [-1.255e8, -1.359e8]
right2 = [1.891e8, -1.585e8]
[loads.f2]
top1 = [8.26e7, -1.562e8]
right1 = [1.214e8, -1.587e8]
right2 = [-1.561e8, -6.14e7]
bottom2 = [-1.236e8, -1.51e8]
[path]
method = "exact"
[output]
plot = false
render_panel = false
"""


def test_time_limit_during_a_homotopy_start(tmp_path, capsys):
    """SSNM does not converge at alpha_start on this case (F = 30); the start is reached by the
    exact method's homotopy (from the frictionless solution), which a time limit (and Ctrl-C)
    stops too: exit 3, nothing left behind (the path had no point), and the next run starts over
    without --force."""
    case = _write(tmp_path, HOMOTOPY)
    assert cli.main(["run", case, "--time-limit", "1e-6"]) == 3
    assert "time limit of 1e-06 s reached while reaching the start" in capsys.readouterr().out
    assert not (tmp_path / "case_out").exists() and not (tmp_path / "case_out.partial").exists()
    assert cli.main(["run", case, "-q"]) == 0
    summary = json.loads((tmp_path / "case_out" / "summary.json").read_text())
    path = SolutionPath.load(str(tmp_path / "case_out" / "path"))
    assert path.stats["start"] == "frictionless"  # SSNM did not converge: the homotopy reached it
    assert summary["status"] == "completed"


def test_run_exits_4_when_the_path_is_incomplete(tmp_path, capsys):
    """A path cut short by its transition cap is written (its outputs, summary.json with the
    status) but the exit code is 4, not 0: a script must not take it for a whole result."""
    case = _write(tmp_path, SMALL.replace("[output]", '[path]\nmethod = "exact"\nmax_transitions = 2\n'
                                          '[output]\nplot = false\nrender_panel = false\n'))
    assert cli.main(["run", case]) == cli.EXIT_INCOMPLETE == 4
    err = capsys.readouterr().err
    assert "the path ended with status 'max_transitions'" in err
    summary = json.loads((tmp_path / "case_out" / "summary.json").read_text())
    assert summary["status"] == "max_transitions" and len(summary["transitions"]) == 2
