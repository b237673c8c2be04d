"""Branches of the command line and its output modules that the rest of the suite never ran.

cfcontact.cli (plot / render / export / info / map / schema options, bad values, Ctrl-C and
failures outside ``run``'s trace, MPI launch, the terminal), cfcontact.report (paths without
transitions or without an interval), cfcontact.plotting (integer components, bad arguments),
cfcontact.render (one-point paths, rigid line and foundation), cfcontact.fields (material keys,
paths saved without a material, alphas of an XDMF), cfcontact.jsonio and cfcontact.map_run.
Every test works on small models (a two-block run of ~1 s, a block on a rigid line).
"""

import json
import logging
import os
import shutil
import signal
import sys
import threading
import warnings
import xml.etree.ElementTree as ET

import numpy as np
import pytest

import cfcontact
from cfcontact import cli, fields, map_run, plotting, run
from cfcontact.case import CaseError, load_case
from cfcontact.errors import InputError
from cfcontact.path import SolutionPath

SMALL = """
title = "small"
[geometry]
kind = "two_blocks"
nx = 12
ny = 4
[contact]
friction = 1.5
[output]
plot = false
render_panel = false
window_size = [320, 200]
"""

# A block on a rigid line y = 0 ([contact.obstacle] kind = "line"); without the obstacle table
# the same block rests on the rigid foundation (no obstacle stored with the geometry).
LINE = """
title = "block on a rigid line"
[geometry]
kind = "block_on_foundation"
nx = 8
ny = 2
[contact]
friction = 0.8
[contact.obstacle]
kind = "line"
point = [0.0, 0.0]
normal = [0.0, 1.0]
[loads]
clamp = ["left1"]
[loads.f1]
top1 = [2.0e7, -1.0e8]
[loads.f2]
top1 = [1.0e8, -2.0e7]
[output]
plot = false
render_panel = false
"""
FOUNDATION = LINE.replace('[contact.obstacle]\nkind = "line"\npoint = [0.0, 0.0]\nnormal = [0.0, 1.0]\n', "")


def _write(folder, text, name="case.toml"):
    fn = os.path.join(str(folder), name)
    with open(fn, "w") as fh:
        fh.write(text)
    return fn


def _files(folder):
    return sorted(os.path.relpath(os.path.join(d, f), folder) for d, _, fs in os.walk(folder) for f in fs)


def _picture(fn, size):
    """A PNG of (width, height) ``size`` that is not blank."""
    from matplotlib.image import imread

    with open(fn, "rb") as fh:
        assert fh.read(8) == b"\x89PNG\r\n\x1a\n"
    img = imread(fn)[..., :3]
    assert (img.shape[1], img.shape[0]) == tuple(size)
    flat = (np.asarray(img) * 255).round().reshape(-1, 3)
    assert flat.std() > 5 and len(np.unique(flat, axis=0)) >= 20, f"{fn} is blank"


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A completed run of SMALL (no plots, no panel): (case file, output folder)."""
    d = tmp_path_factory.mktemp("small")
    case = _write(d, SMALL)
    assert cli.main(["run", case, "-q"]) == 0
    return case, str(d / "case_out")


@pytest.fixture(scope="module")
def one_point(tmp_path_factory):
    """A run of SMALL stopped by --time-limit at its first point: <out>.partial holds a one-point path."""
    d = tmp_path_factory.mktemp("onept")
    case = _write(d, SMALL)
    assert cli.main(["run", case, "-q", "--time-limit", "1e-9"]) == 3
    partial = str(d / "case_out.partial")
    assert len(SolutionPath.load(os.path.join(partial, "checkpoint", "path")).alphas) == 1
    return partial


# ------------------------------------------------------------------ plot
def test_plot_zoom_outside_the_path_or_reversed(small, tmp_path, capsys):
    """--zoom B < A and a --zoom window beside the path: exit 2, one line naming the window and, for
    the latter, the alpha range the path covers (the library's "give value limits explicitly"
    asked for something --zoom cannot take); no figure written."""
    _, out = small
    png = tmp_path / "z.png"
    assert cli.main(["plot", out, "--zoom", "0.6", "0.4", "-o", str(png)]) == 2
    err = capsys.readouterr().err
    assert err.strip() == "cfcontact plot: error: --zoom: need A < B, got 0.6 0.4"
    assert cli.main(["plot", out, "--zoom", "5", "6", "-o", str(png)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1, err
    assert "--zoom 5 6" in err and "covers alpha in [0, 1]" in err and "value limits" not in err, err
    assert not png.exists() and os.listdir(tmp_path) == []
    # a window that overlaps the path's end is drawn
    assert cli.main(["plot", out, "--zoom", "0.9", "1.5", "-o", str(png), "-q"]) == 0
    _picture(str(png), (800, 450))


def test_integer_and_displacement_components_are_labelled(small, tmp_path):
    """A component given as an index of y (``--component 245``) is drawn and labelled as the
    multiplier it is: "λν at node 5" for n + 5, "λτ at node 2" for n + m + 2, and a displacement
    DOF names its node and direction from the saved geometry; the curve is path.component(index)."""
    _, out = small
    path = SolutionPath.load(os.path.join(out, "path"))
    n, m, geom = path.n, path.m, path.geometry
    for index, label in ((n + 5, "λν at node 5"), (n + m + 2, "λτ at node 2"),
                         (7, f"u at DOF 7 (node {int(geom.dof_node[7])}, {'xy'[int(geom.dof_comp[7])]})")):
        fig = plotting.plot_path(path, component=index)
        ax = fig.axes[0]
        assert ax.get_ylabel() == label
        line = [ln for ln in ax.get_lines() if ln.get_gid() == "path"][0]
        np.testing.assert_array_equal(line.get_ydata(), path.component(index))
    assert plotting.plot_path(path, component=("u", 7)).axes[0].get_ylabel() == label
    png = tmp_path / "c.png"
    assert cli.main(["plot", out, "--component", str(n + 5), "-o", str(png), "-q"]) == 0
    _picture(str(png), (800, 450))


def test_plotting_rejects_bad_arguments(small, tmp_path):
    """The library's plot functions: a zoom of 3 numbers, an unknown zoom_style, dpi 0, a
    figsize of text and a figure file that is a folder are InputErrors naming the value."""
    path = SolutionPath.load(os.path.join(small[1], "path"))
    with pytest.raises(InputError, match=r"zoom must be .*got \(0.1, 0.2, 0.3\)"):
        plotting.plot_path(path, zoom=(0.1, 0.2, 0.3))
    with pytest.raises(InputError, match="zoom_style must be 'panel' or 'inset', got 'side'"):
        plotting.plot_path(path, zoom=(0.1, 0.2), zoom_style="side")
    with pytest.raises(InputError, match="dpi must be a number > 0, got 0"):
        plotting.plot_multiplicity(path, dpi=0)
    with pytest.raises(InputError, match=r"figsize must be .*got \('wide', 3\)"):
        plotting.plot_path(path, figsize=("wide", 3))
    folder = tmp_path / "f.png"
    folder.mkdir()
    with pytest.raises(InputError, match="it is a folder"):
        plotting.save_figure(plotting.plot_multiplicity(path), str(folder))
    assert os.listdir(folder) == []


# ------------------------------------------------------------------ info / report
def test_info_of_a_one_point_stopped_run_and_of_a_library_saved_path(small, one_point, tmp_path, capsys):
    """info of a stopped run's <out>.partial (pairing from its checkpoint's state.json) whose path
    has one point: "transitions: none", "(the path covers no alpha interval)", and --json says
    the same; info of a path saved by the library (no case.toml, no state.json): "unrecorded
    pairing".  plot --multiplicity and export without --alpha of the one-point path: exit 2."""
    assert cli.main(["info", one_point]) == 0
    text = capsys.readouterr().out
    assert "points 1, branches 1, transitions 0" in text
    assert "\ntransitions: none\n" in text and "  (the path covers no alpha interval)" in text
    assert "contact: 12 pairs, node pairing" in text
    assert cli.main(["info", one_point, "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["transitions"] == [] and rep["multiplicity"] == [] and rep["contact"]["pairing"] == "node"
    lib = tmp_path / "lib"
    SolutionPath.load(os.path.join(small[1], "path")).save(str(lib))
    assert cli.main(["info", str(lib)]) == 0
    assert "contact: 12 pairs, unrecorded pairing" in capsys.readouterr().out
    _write(tmp_path, "[geometry\nkind = ")  # an unreadable case.toml beside it: the pairing stays unknown
    assert cli.main(["info", str(lib)]) == 0
    cap = capsys.readouterr()
    assert "contact: 12 pairs, unrecorded pairing" in cap.out and cap.err == ""
    os.remove(tmp_path / "case.toml")
    assert cli.main(["plot", one_point, "--multiplicity", "-o", str(tmp_path / "m.png")]) == 2
    assert "covers no α interval" in capsys.readouterr().err
    assert cli.main(["export", one_point, "-o", str(tmp_path / "e.xdmf")]) == 2
    assert "covers no alpha interval; give --alpha" in capsys.readouterr().err
    assert sorted(os.listdir(tmp_path)) == ["lib"]


# ------------------------------------------------------------------ render
def test_render_refuses_a_lumped_path_and_a_non_png(small, tmp_path, capsys):
    """render of a lumped model's path (no geometry) and render -o FILE.jpg: exit 2, one line
    naming the folder / the file; nothing written."""
    lumped = cfcontact.ContactSystem.from_arrays(np.eye(2), [[0, 1]], [[1, 0]], [0.0, -1.0], [0.1, -1.0], 0.5)
    cfcontact.trace_path(lumped, 0, 1, method="exact").save(str(tmp_path / "lumped"))
    capsys.readouterr()
    assert cli.main(["render", str(tmp_path / "lumped"), "-o", str(tmp_path / "r.png")]) == 2
    err = capsys.readouterr().err
    assert "lumped" in err and "has no geometry" in err and "nothing to render" in err
    assert cli.main(["render", small[1], "-o", str(tmp_path / "r.jpg")]) == 2
    assert "-o: renders are PNG files, got" in capsys.readouterr().err
    assert sorted(os.listdir(tmp_path)) == ["lumped"]


def test_render_picture_and_animation_of_a_one_point_path(one_point, tmp_path, capsys):
    """render --alpha 0 -o FILE.png --animation FILE.gif on a one-point path: both written in one
    command; the animation asked for 5 frames has the path's one configuration (a GIF of 1 frame,
    said so)."""
    from PIL import Image

    png, gif = tmp_path / "r.png", tmp_path / "a.gif"
    assert cli.main(["render", one_point, "--alpha", "0", "-o", str(png), "--animation", str(gif), "--frames", "5",
                     "--window-size", "320", "200"]) == 0
    out = capsys.readouterr().out
    assert "1 solution(s) at alpha = 0" in out and f"wrote {gif} (gif, 1 frames)" in out
    _picture(str(png), (320, 200))
    with Image.open(gif) as im:
        assert im.format == "GIF" and getattr(im, "n_frames", 1) == 1 and im.size == (320, 200)


def test_render_of_a_rigid_line_and_a_rigid_foundation(tmp_path):
    """A block on a rigid line obstacle and on the rigid foundation: the render is a picture; the
    drawn foundation is the obstacle's line (y = 0) a little beyond the contact points, and for
    the foundation the polyline through the contact points in order along the tangent."""
    from cfcontact import render

    for name, text in (("line", LINE), ("foundation", FOUNDATION)):
        case = _write(tmp_path, text, f"{name}.toml")
        assert cli.main(["run", case, "-q"]) == 0
        out = str(tmp_path / f"{name}_out")
        png = str(tmp_path / f"{name}.png")
        assert cli.main(["render", out, "--alpha", "0.5", "--window-size", "320", "200", "-o", png, "-q"]) == 0
        _picture(png, (320, 200))
        path = SolutionPath.load(os.path.join(out, "path"))
        geom = path.geometry
        assert (geom.obstacle is not None) == (name == "line")
        plotter = render._new_plotter((320, 200))
        try:
            render._draw(plotter, geom, path.solutions_at(0.5)[0], 1.0)
            pts = np.asarray(plotter.actors["foundation"].GetMapper().GetInput().GetPoints().GetData())
        finally:
            plotter.close()
        cp = np.asarray(geom.contact_points)[:, :2]
        if name == "line":
            assert len(pts) == render.OBSTACLE_SAMPLES and np.allclose(pts[:, 1:], 0.0)
            assert pts[:, 0].min() < cp[:, 0].min() < cp[:, 0].max() < pts[:, 0].max()
        else:
            np.testing.assert_allclose(pts[:, :2], cp[np.argsort(cp @ np.asarray(geom.tangents)[0])])


# ------------------------------------------------------------------ export / material
def test_a_path_saved_without_its_material(small, tmp_path, capsys):
    """A path saved before the material was stored (fields.npz without geometry_material): with no
    case.toml beside it, export warns and writes every attribute but von_mises (displacements as
    the path's); render --stress is exit 2 naming the missing material, nothing written; with the
    run's case.toml beside it, export takes that material (von_mises = fields.von_mises)."""
    src = os.path.join(small[1], "path")
    old = tmp_path / "old" / "path"
    old.mkdir(parents=True)
    shutil.copy(os.path.join(src, "path.json"), old / "path.json")
    with np.load(os.path.join(src, "fields.npz")) as z:
        arrays = {k: z[k] for k in z.files if k != "geometry_material"}
    np.savez(old / "fields.npz", **arrays)
    path = SolutionPath.load(str(old))
    assert path.geometry.material is None
    x = tmp_path / "e.xdmf"
    assert cli.main(["export", str(old), "--alpha", "0.5", "-o", str(x)]) == 0
    cap = capsys.readouterr()
    assert "stores no material: no von_mises attribute" in cap.err and f"wrote {x}" in cap.out
    grid = ET.parse(x).getroot().find("Domain/Grid").findall("Grid")
    assert len(grid) == 1
    names = [a.get("Name") for a in grid[0].findall("Attribute")]
    assert names == ["displacement", "contact_state", "lam_n", "lam_t", "contact_pressure", "contact_shear", "body"]
    disp = np.array(grid[0].find("Attribute/DataItem").text.split(), dtype=float).reshape(-1, 3)
    sol = path.solutions_at(0.5)[0]
    np.testing.assert_array_equal(disp[:, :2], path.geometry.displacement_field(sol.u, 0.5))
    png = tmp_path / "s.png"
    assert cli.main(["render", str(old), "--alpha", "0.5", "--stress", "-o", str(png)]) == 2
    assert "stores no material" in capsys.readouterr().err and not png.exists()
    shutil.copy(small[0], tmp_path / "old" / "case.toml")
    assert cli.main(["export", str(old), "--alpha", "0.5", "-o", str(x), "-q"]) == 0
    assert capsys.readouterr().err == ""
    grid = ET.parse(x).getroot().find("Domain/Grid").findall("Grid")[0]
    vm = [a for a in grid.findall("Attribute") if a.get("Name") == "von_mises"][0]
    ref = SolutionPath.load(src)
    np.testing.assert_allclose(np.array(vm.find("DataItem").text.split(), dtype=float),
                               fields.von_mises(ref.geometry, ref.solutions_at(0.5)[0]), rtol=1e-12)


def test_material_keys_and_bad_materials(small):
    """Per-body material keys 1, "1", "body1" and "body1=1" give the same stresses; an empty
    dict, a value that is no number, a material that is no dict and one without E are
    InputErrors naming what is wrong; material_of(path) is the saved geometry's material."""
    path = SolutionPath.load(os.path.join(small[1], "path"))
    geom, sol = path.geometry, path.solutions_at(0.5)[0]
    E, nu = 2.1e11, 0.3
    ref = fields.von_mises(geom, sol, {"E": E, "nu": nu, "plane": "strain"})
    for k1, k2 in ((1, 2), ("1", "2"), ("body1", "body2"), ("body1=1", "body2=2")):
        got = fields.von_mises(geom, sol, {"E": {k1: E, k2: E}, "nu": {k1: nu, k2: nu}, "plane": "strain"})
        np.testing.assert_array_equal(got, ref)
    with pytest.raises(InputError, match="material E is an empty dict"):
        fields.von_mises(geom, sol, {"E": {}, "nu": nu})
    with pytest.raises(InputError, match=r"material nu\[2\] must be a number, got 'soft'"):
        fields.von_mises(geom, sol, {"E": E, "nu": {1: nu, 2: "soft"}})
    with pytest.raises(InputError, match=r"material must be a dict .*got list"):
        fields.von_mises(geom, sol, [E, nu])
    with pytest.raises(InputError, match=r"material has no E \(keys \['nu'\]\)"):
        fields.von_mises(geom, sol, {"nu": nu})
    assert fields.material_of(path) == geom.material and geom.material["E"]


def test_export_path_defaults_and_alphas_of_an_xdmf(small, tmp_path):
    """export_path without alpha writes the solutions at the alpha of largest multiplicity; an
    alpha that is no number and alpha with points=True are InputErrors; write_xdmf's ``alphas``
    replaces each solution's alpha in its grid (one value too few: InputError, no file left)."""
    path = SolutionPath.load(os.path.join(small[1], "path"))
    k, a = path.max_multiplicity()
    fn, what = fields.export_path(path, str(tmp_path / "d.xdmf"))
    assert what == f"{k} solution(s) at alpha = {a:.10g}"
    grids = ET.parse(fn).getroot().find("Domain/Grid").findall("Grid")
    assert [float(g.find("Information").get("Value")) for g in grids] == [a] * k
    with pytest.raises(InputError, match="alpha must be a number, got 'half'"):
        fields.export_path(path, str(tmp_path / "x.xdmf"), alpha="half")
    with pytest.raises(InputError, match="not both"):
        fields.export_path(path, str(tmp_path / "x.xdmf"), alpha=0.5, points=True)
    sols = path.solutions_at(0.25) + path.solutions_at(0.75)
    fn = fields.write_xdmf(str(tmp_path / "a.xdmf"), path.geometry, sols, alphas=[0.25, 0.75])
    grids = ET.parse(fn).getroot().find("Domain/Grid").findall("Grid")
    assert [g.get("Name") for g in grids] == [fields.grid_name(0, 0.25), fields.grid_name(1, 0.75)]
    with pytest.raises(InputError, match="alphas has 1 values, fewer than the solutions"):
        fields.write_xdmf(str(tmp_path / "b.xdmf"), path.geometry, sols, alphas=[0.25])
    assert sorted(os.listdir(tmp_path)) == ["a.xdmf", "d.xdmf"]


# ------------------------------------------------------------------ map / schema
def test_map_checks_its_ranges_before_writing(tmp_path, capsys):
    """cfcontact map with --mark -1, a --friction-range that is not finite, reversed or empty,
    --frictions 1 or --alphas 100001: exit 2, one line on stderr naming the value, nothing on
    stdout and no folder made for -o (the range order and grid sizes were checked after the
    output's parent folders had been created).  map_case itself refuses them too."""
    case = _write(tmp_path, SMALL)
    out = str(tmp_path / "new" / "sub" / "m")
    for extra, words in ((["--mark", "-1"], "--mark: friction coefficients are finite numbers >= 0, got -1.0"),
                         (["--friction-range", "nan", "1"], "--friction-range: need 0 <= F0 < F1"),
                         (["--friction-range", "1", "0.5"], "got 1.0 0.5"),
                         (["--friction-range", "2", "2"], "got 2.0 2.0"),
                         (["--frictions", "1"], "--frictions: need 2..100000 grid points, got 1"),
                         (["--alphas", "100001"], "--alphas: need 2..100000 grid points, got 100001")):
        assert cli.main(["map", case, "-o", out] + extra) == 2, extra
        cap = capsys.readouterr()
        assert cap.out == "" and len(cap.err.strip().splitlines()) == 1 and words in cap.err, (extra, cap)
        assert os.listdir(tmp_path) == ["case.toml"], extra
    c = load_case(case)
    with pytest.raises(CaseError, match="need 0 <= F0 < F1, got 1 0.5"):
        map_run.map_case(c, out, (1, 0.5))
    with pytest.raises(CaseError, match="--alphas: need 2..100000 grid points, got 1"):
        map_run.map_case(c, out, (0, 1), 3, 1)
    assert os.listdir(tmp_path) == ["case.toml"]


def test_map_default_friction_range(tmp_path):
    """map without --friction-range: F from 0 to the case's friction, at least 1 (friction 0.4:
    F = 0, 0.5, 1 on 3 points), the case's friction marked; map.json says so and map.png is a picture."""
    case = _write(tmp_path, SMALL.replace("friction = 1.5", "friction = 0.4"))
    assert cli.main(["map", case, "--frictions", "3", "--alphas", "3", "--no-curves", "-q"]) == 0
    out = tmp_path / "case_map"
    data = json.loads((out / "map.json").read_text())
    assert data["frictions"] == [0.0, 0.5, 1.0] and data["alphas"] == [0.0, 0.5, 1.0] and data["marks"] == [0.4]
    assert np.asarray(data["counts"]).shape == (3, 3)
    _picture(str(out / "map.png"), (800, 600))


def test_schema_is_a_valid_case(tmp_path, capsys):
    """cfcontact schema prints the case-file reference as TOML that is itself a valid case
    (load_case accepts it; kind two_blocks)."""
    import tomllib

    assert cli.main(["schema"]) == 0
    text = capsys.readouterr().out
    assert tomllib.loads(text)["geometry"]["kind"] == "two_blocks"
    case = load_case(_write(tmp_path, text))
    assert case["geometry"]["kind"] == "two_blocks"


# ------------------------------------------------------------------ the program: MPI, Ctrl-C, failures
def test_mpirun_is_refused(small, monkeypatch, capsys):
    """Started under mpirun (the launcher's variables say 2 ranks): exit 2 before any work, rank 0
    says why, the other ranks say nothing; malformed variables are ignored (one process)."""
    monkeypatch.setenv("OMPI_COMM_WORLD_SIZE", "2")
    monkeypatch.setenv("OMPI_COMM_WORLD_RANK", "0")
    assert cli.main(["info", small[1]]) == 2
    cap = capsys.readouterr()
    assert cap.out == "" and "cfcontact info: error:" in cap.err and "2 MPI ranks (mpirun -n 2)" in cap.err
    monkeypatch.setenv("OMPI_COMM_WORLD_RANK", "1")
    assert cli.main(["info", small[1]]) == 2
    assert capsys.readouterr() == ("", "")
    monkeypatch.setenv("OMPI_COMM_WORLD_SIZE", "two")
    monkeypatch.delitem(sys.modules, "mpi4py.MPI", raising=False)
    assert cli.mpi_launch() == (1, 0)
    assert cli.main(["info", small[1]]) == 0


def test_ctrl_c_and_failures_outside_a_run(small, monkeypatch, capsys):
    """A Ctrl-C while a saved path is read: exit 130, one line "cfcontact info: interrupted"; one
    before the command is known (the parser): "cfcontact: interrupted"; a failure: exit 1, one
    line with the exception and the --verbose hint, and with --verbose the traceback."""
    def interrupted(*a):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "load_saved_path", interrupted)
    assert cli.main(["info", small[1]]) == 130
    assert capsys.readouterr().err == "cfcontact info: interrupted\n"

    def broken(*a):
        raise RuntimeError("disk on fire")

    monkeypatch.setattr(cli, "load_saved_path", broken)
    assert cli.main(["info", small[1]]) == 1
    assert capsys.readouterr().err == ("cfcontact info: failed: RuntimeError: disk on fire  (--verbose for the "
                                       "traceback)\n")
    assert cli.main(["info", small[1], "-v"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("Traceback") and err.endswith("cfcontact info: failed: RuntimeError: disk on fire\n")
    monkeypatch.setattr(cli, "build_parser", interrupted)
    assert cli.main(["info", small[1]]) == 130
    assert capsys.readouterr().err == "cfcontact: interrupted\n"


def test_a_ctrl_c_lost_in_a_finalizer_as_the_program(small, monkeypatch, capsys):
    """As the program (argv from sys.argv), a Ctrl-C that Python swallowed in a finalizer while the
    command worked makes it exit 130 "(the command had finished its work)", without the
    "Exception ignored" traceback; any other unraisable exception still goes to Python's hook."""
    def command(kind):
        def cmd(args):
            class Finalized:
                def __del__(self):
                    raise kind("in a finalizer")

            Finalized()  # (collected at once: the exception is "unraisable")
            return 0
        return cmd

    old = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGPIPE)
    monkeypatch.setattr(sys, "unraisablehook", sys.unraisablehook)
    monkeypatch.setattr(sys, "argv", ["cfcontact", "info", small[1]])
    try:
        monkeypatch.setattr(cli, "cmd_info", command(KeyboardInterrupt))
        assert cli.main() == 130
        err = capsys.readouterr().err
        assert err == "cfcontact: interrupted (the command had finished its work)\n"
        monkeypatch.setattr(cli, "cmd_info", command(ValueError))
        assert cli.main() == 0
        err = capsys.readouterr().err
        assert "Exception ignored" in err and "ValueError: in a finalizer" in err
    finally:
        signal.signal(signal.SIGINT, old[0])
        signal.signal(signal.SIGPIPE, old[1])


def test_ctrl_c_twice_keeps_the_last_periodic_checkpoint(small, tmp_path, monkeypatch, capsys):
    """Two Ctrl-C while tracing (the second before the first was acted on): the run aborts with exit
    130, the last periodic checkpoint is kept and --resume traces the same path as the
    uninterrupted run."""
    on_point = run.Runner.on_point

    def twice_at_20(self, pt):
        if pt.index == 20:
            signal.raise_signal(signal.SIGINT)
            signal.raise_signal(signal.SIGINT)
        return on_point(self, pt)

    monkeypatch.setattr(run.Runner, "on_point", twice_at_20)
    case = _write(tmp_path, SMALL)
    before = signal.getsignal(signal.SIGINT)  # (SIG_IGN where the suite runs in a background job)
    assert cli.main(["run", case, "-q", "--checkpoint-every", "1e-9"]) == 130
    assert signal.getsignal(signal.SIGINT) is before
    assert sorted(os.listdir(tmp_path)) == ["case.toml", "case_out.partial"]
    state = json.loads((tmp_path / "case_out.partial" / "checkpoint" / "state.json").read_text())
    assert state["resumable"] and not state["traced"]
    monkeypatch.setattr(run.Runner, "on_point", on_point)
    assert cli.main(["run", case, "-q", "--resume"]) == 0
    a, b = SolutionPath.load(str(tmp_path / "case_out" / "path")), SolutionPath.load(os.path.join(small[1], "path"))
    np.testing.assert_array_equal(a.alphas, b.alphas)
    np.testing.assert_array_equal(a.point_branch, b.point_branch)


def test_a_failure_while_tracing_keeps_the_periodic_checkpoint(small, tmp_path, monkeypatch, capsys):
    """A failure (not bad input) in the middle of the trace after periodic checkpoints: exit 1, the
    error and "a checkpoint remains in <out>.partial (cfcontact run --resume)"; --resume then
    traces the same path as the uninterrupted run."""
    on_point = run.Runner.on_point

    def fail_at_20(self, pt):
        if pt.index == 20:
            raise RuntimeError("solver lost")
        return on_point(self, pt)

    monkeypatch.setattr(run.Runner, "on_point", fail_at_20)
    case = _write(tmp_path, SMALL)
    assert cli.main(["run", case, "--checkpoint-every", "1e-9"]) == 1
    err = capsys.readouterr().err
    partial = tmp_path / "case_out.partial"
    assert f"cfcontact: a checkpoint remains in {partial} (cfcontact run --resume)" in err
    assert "failed: RuntimeError: solver lost" in err
    assert sorted(os.listdir(tmp_path)) == ["case.toml", "case_out.partial"] and os.listdir(partial) == ["checkpoint"]
    monkeypatch.setattr(run.Runner, "on_point", on_point)
    assert cli.main(["run", case, "-q", "--resume"]) == 0
    a, b = SolutionPath.load(str(tmp_path / "case_out" / "path")), SolutionPath.load(os.path.join(small[1], "path"))
    np.testing.assert_array_equal(a.alphas, b.alphas)


def test_render_mp4_without_imageio_ffmpeg_writes_frames(small, tmp_path, monkeypatch, capsys):
    """render --animation FILE.mp4 where imageio-ffmpeg is missing: one warning saying so, the
    frames as PNGs in FILE_frames/ (3 pictures for --frames 3), and the summary names that folder."""
    from cfcontact import render

    importable = render._importable
    monkeypatch.setattr(render, "_importable", lambda name: name != "imageio_ffmpeg" and importable(name))
    mp4 = tmp_path / "a.mp4"
    assert cli.main(["render", small[1], "--animation", str(mp4), "--frames", "3", "--window-size", "320",
                     "200"]) == 0
    cap = capsys.readouterr()
    frames = tmp_path / "a_frames"
    assert cap.err == "cfcontact: warning: imageio-ffmpeg is not installed: wrote PNG frames instead of an MP4\n"
    assert f"wrote {frames} (png-frames, 3 frames)" in cap.out
    assert sorted(os.listdir(tmp_path)) == ["a_frames"]
    assert sorted(os.listdir(frames)) == ["frame_0000.png", "frame_0001.png", "frame_0002.png"]
    for fn in sorted(os.listdir(frames)):
        _picture(str(frames / fn), (320, 200))


def test_ctrl_c_after_the_last_output(tmp_path, monkeypatch, capsys):
    """A Ctrl-C that comes once the outputs are written: exit 130 and one line saying the outputs
    are complete; the output folder is whole (summary.json, path) and no checkpoint is left."""
    finish = run.CaseRun.finish

    def finish_then_ctrl_c(self, *a, **k):
        files = finish(self, *a, **k)
        signal.raise_signal(signal.SIGINT)  # handled by the CLI: noted, nothing left to stop
        return files

    monkeypatch.setattr(run.CaseRun, "finish", finish_then_ctrl_c)
    case = _write(tmp_path, SMALL)
    assert cli.main(["run", case, "-q"]) == 130
    err = capsys.readouterr().err
    assert err.strip().endswith(f"cfcontact run: interrupted (the outputs were complete: {tmp_path / 'case_out'}/)")
    assert sorted(os.listdir(tmp_path)) == ["case.toml", "case_out"]
    assert json.loads((tmp_path / "case_out" / "summary.json").read_text())["summary"]["status"] == "completed"
    assert SolutionPath.load(str(tmp_path / "case_out" / "path")).status == "completed"


def test_run_from_a_worker_thread(small, tmp_path, monkeypatch):
    """cli.main in a thread other than the main one (where no signal handler can be set): run
    builds the model (gmsh 4.8 sets SIGINT's handler on import and in finalize: those steps are
    left out there), traces and writes its outputs (the same path as in the main thread), and a
    run that fails there exits 1 and leaves no folder."""
    case = _write(tmp_path, SMALL)
    codes = []

    def in_thread(argv):
        t = threading.Thread(target=lambda: codes.append(cli.main(argv)))
        t.start()
        t.join(300)
        return codes.pop()

    assert in_thread(["run", case, "-q"]) == 0
    a, b = SolutionPath.load(str(tmp_path / "case_out" / "path")), SolutionPath.load(os.path.join(small[1], "path"))
    np.testing.assert_array_equal(a.alphas, b.alphas)
    np.testing.assert_array_equal(a.point_branch, b.point_branch)

    def boom(*a, **k):
        raise RuntimeError("boom")

    monkeypatch.setattr(run, "write_outputs", boom)
    assert in_thread(["run", case, "-q", "-o", str(tmp_path / "f")]) == 1
    assert sorted(os.listdir(tmp_path)) == ["case.toml", "case_out"]


def test_a_model_built_by_a_worker_thread_of_a_fresh_process():
    """In a process that has not imported gmsh, a worker thread builds a model (gmsh 4.8's import
    sets a signal handler, which only the main thread may: it failed with "signal only works in
    main thread"), the same as the main thread's, and the process's Ctrl-C handler is left as it was."""
    import subprocess

    code = ("import signal, sys, threading\n"
            "before = signal.getsignal(signal.SIGINT)\n"  # (SIG_IGN in a background job)
            "import cfcontact\n"
            "out = []\n"
            "t = threading.Thread(target=lambda: out.append(cfcontact.two_blocks(nx=3, ny=1).checksum()))\n"
            "t.start(); t.join()\n"
            "assert 'gmsh' in sys.modules and out, out\n"
            "assert signal.getsignal(signal.SIGINT) is before, (signal.getsignal(signal.SIGINT), before)\n"
            "assert out[0] == cfcontact.two_blocks(nx=3, ny=1).checksum()\n"
            "print('ok')\n")
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = dict(os.environ, PYTHONPATH=root + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0 and proc.stdout.strip() == "ok", proc.stderr[-2000:]


# ------------------------------------------------------------------ the terminal
def test_progress_line_on_a_terminal(capsys):
    """On a TTY the progress line is rewritten in place ("\\r" + erase line), a log record first
    erases it, and the end of the run moves past it with one newline."""
    progress = cli._Progress(enabled=True, tty=True)
    handler = cli._ProgressAwareHandler(sys.stderr)
    handler.progress = progress
    progress.update("point 1", force=True)
    progress.update("point 2", force=True)
    handler.emit(logging.makeLogRecord({"msg": "a log line", "levelno": logging.WARNING}))
    progress.done()  # nothing shown since the log line: nothing to end
    progress.update("point 3", force=True)
    progress.done()
    assert capsys.readouterr().err == ("\r\x1b[2Kpoint 1\r\x1b[2Kpoint 2\r\x1b[2Ka log line\n"
                                       "\r\x1b[2Kpoint 3\n")


def test_python_warnings_routed_through_logging(small, monkeypatch, capsys):
    """Once a library has called logging.captureWarnings (ffcx does), Python warnings arrive as
    "py.warnings" log records "file:line: Category: message" plus the source line: the command
    shows each as one line "cfcontact: warning: Category: message" (cfcontact's PairingWarning
    without its category), and nothing with --quiet."""
    def cmd(args):
        log = logging.getLogger("py.warnings")
        log.warning("%s", warnings.formatwarning("the mesh is odd\nsecond line", UserWarning, "/x/mod.py", 12,
                                                 "warnings.warn('the mesh is odd')"))
        log.warning("%s", warnings.formatwarning("3 nodes left out", type("PairingWarning", (UserWarning,), {}),
                                                 "/x/pairing.py", 7, "warn()"))
        log.warning("%s", "no location here")
        return 0

    monkeypatch.setattr(cli, "cmd_info", cmd)
    assert cli.main(["info", small[1]]) == 0
    assert capsys.readouterr().err == ("cfcontact: warning: UserWarning: the mesh is odd\n"
                                       "cfcontact: warning: 3 nodes left out\n"
                                       "cfcontact: warning: no location here\n")
    assert cli.main(["info", small[1], "-q"]) == 0
    assert capsys.readouterr().err == ""


# ------------------------------------------------------------------ JSON, output folders
def test_numpy_scalars_in_json_and_an_empty_output_folder(tmp_path, capsys):
    """write_json turns NumPy booleans and integers into JSON ones (they reload equal); run -o into
    an empty folder that exists: refused without --force, replaced with it (and the case's unused
    [path] key is one warning line)."""
    from cfcontact.jsonio import read_json, write_json

    fn = tmp_path / "x.json"
    write_json(fn, {"ok": np.bool_(True), "n": np.int64(7), "v": np.arange(3), "x": np.float32(0.5),
                    "bad": float("nan")})
    assert read_json(fn) == {"ok": True, "n": 7, "v": [0, 1, 2], "x": 0.5, "bad": None}
    case = _write(tmp_path, SMALL.replace("[output]", "[path]\nfriction_start = 0.5\n[output]"))
    empty = tmp_path / "empty"
    empty.mkdir()
    assert cli.main(["run", case, "-q", "-o", str(empty)]) == 2
    assert os.listdir(empty) == []
    assert cli.main(["run", case, "-o", str(empty), "--force"]) == 0
    assert "summary.json" in os.listdir(empty) and "path" in os.listdir(empty)
    assert ('cfcontact: warning: [path] friction_start: used with parameter = "friction" only; ignored'
            in capsys.readouterr().err)
