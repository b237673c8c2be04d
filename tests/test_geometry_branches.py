"""Branches of the geometry scripts, the material and path options, the gmsh/JIT helpers of
cfcontact.compat and the benchmark drivers that a coverage run of the whole suite found never run
in process: the scripts' command lines (two blocks on a foundation, turned; non-matching blocks;
an arc in a seat of another thickness; a half rounded punch with a gap) checked against the
geometry itself (node positions on their lines and arcs, areas of the meshed bodies, the groups
present), the refusals of bad geometry parameters, materials, path options and bench arguments
(typed error or exit code 2 naming the bad value and what is valid), the loads of a turned model
(a uniform traction of NumPy scalars turned like one of floats), a model built inside a
caller's gmsh session, a failing JIT compilation's report, and the numbers of Part B's and Part D's
rows against independent computations."""

import logging
import math
import os
import sys

import numpy as np
import pytest

import cfcontact
from cfcontact.errors import GeometryError, InputError


# ------------------------------------------------------------------ reading a .msh back
def _read_msh(path):
    """{group name: {"nodes": (k, 2) coordinates, "cells": [(gmsh type, (c, v, 2) coordinates)]}}
    of every physical group of a .msh file (cells for the 2-D groups)."""
    import gmsh

    from cfcontact import compat

    out = {}
    with compat.gmsh_model("read-back") as model:
        gmsh.merge(str(path))
        tags, xyz, _ = model.mesh.getNodes()
        where = dict(zip(np.asarray(tags, dtype=np.int64).tolist(), np.asarray(xyz).reshape(-1, 3)[:, :2]))
        for dim, num in model.getPhysicalGroups():
            name = model.getPhysicalName(dim, num)
            _, coords = model.mesh.getNodesForPhysicalGroup(dim, num)
            cells = []
            if dim == 2:
                for ent in model.getEntitiesForPhysicalGroup(dim, num):
                    types, _, nodes = model.mesh.getElements(dim, ent)
                    for t, nn in zip(types, nodes):
                        k = {2: 3, 3: 4}[int(t)]
                        pts = np.array([where[int(v)] for v in nn]).reshape(-1, k, 2)
                        cells.append((int(t), pts))
            out[name] = {"number": num, "nodes": np.asarray(coords).reshape(-1, 3)[:, :2], "cells": cells}
    return out


def _area(cells):
    """Total area of the cells (shoelace formula per cell, either orientation)."""
    total = 0.0
    for _, pts in cells:
        x, y = pts[..., 0], pts[..., 1]
        total += np.abs(0.5 * (x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y).sum(axis=1)).sum()
    return total


def _types(group):
    return {t for t, _ in group["cells"]}


# ------------------------------------------------------------------ the geometry scripts
def test_two_blocks_script_builds_a_turned_block_on_a_foundation(tmp_path):
    """``python -m cfcontact.meshes.two_blocks OUT --foundation --angle 30`` (in process): body 1
    alone (groups body1, contact1, top1, right1, left1 with the convention's numbers, nothing of
    body 2), its (nx+1)(ny+1) nodes, contact1 on the line through the origin at 30 degrees with
    its nodes evenly spaced from 0 to length, top1 at distance height from it, and the block's
    area length x height -- against the rectangle turned by hand."""
    from cfcontact.meshes import two_blocks

    out = tmp_path / "foundation.msh"
    assert two_blocks._main([str(out), "--foundation", "--angle", "30", "--nx", "4", "--ny", "2",
                             "--length", "2", "--height", "0.5"]) == 0
    g = _read_msh(out)
    assert {k: v["number"] for k, v in g.items()} == {"body1": 1, "contact1": 10, "top1": 12, "right1": 13,
                                                      "left1": 14}
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))

    def unturned(p):  # back to the block's own frame
        return np.column_stack([c * p[:, 0] + s * p[:, 1], -s * p[:, 0] + c * p[:, 1]])

    assert len(g["body1"]["nodes"]) == 5 * 3 and _types(g["body1"]) == {3}
    contact = unturned(g["contact1"]["nodes"])
    np.testing.assert_allclose(contact[:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(np.sort(contact[:, 0]), np.linspace(0.0, 2.0, 5), atol=1e-12)
    np.testing.assert_allclose(unturned(g["top1"]["nodes"])[:, 1], 0.5, atol=1e-12)
    np.testing.assert_allclose(unturned(g["right1"]["nodes"])[:, 0], 2.0, atol=1e-12)
    assert g["contact1"]["nodes"][:, 1].max() == pytest.approx(2.0 * s)  # (the right end turned up)
    assert _area(g["body1"]["cells"]) == pytest.approx(1.0, rel=1e-12)


def test_two_blocks_script_builds_non_matching_blocks_and_refuses_a_bad_angle(tmp_path, capsys):
    """``--nx2 5 --ny2 3 --height2 0.25 --cell triangle``: body 2 meshed on its own (6 interface
    nodes evenly spaced on y = 0 against body 1's 5, bottom2 at y = -0.25, 2 x 5 x 3 triangles,
    area length x height2); ``--angle nan`` exits 2 naming the angle and writes nothing."""
    from cfcontact.meshes import two_blocks

    out = tmp_path / "nonmatching.msh"
    assert two_blocks._main([str(out), "--nx", "4", "--ny", "2", "--nx2", "5", "--ny2", "3", "--height2", "0.25",
                             "--length", "3", "--height", "1", "--cell", "triangle"]) == 0
    g = _read_msh(out)
    assert {"body1", "body2", "contact1", "contact2", "bottom2", "right2", "left2"} <= set(g)
    np.testing.assert_allclose(np.sort(g["contact1"]["nodes"][:, 0]), np.linspace(0, 3, 5), atol=1e-12)
    np.testing.assert_allclose(np.sort(g["contact2"]["nodes"][:, 0]), np.linspace(0, 3, 6), atol=1e-12)
    np.testing.assert_allclose(g["contact2"]["nodes"][:, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(g["bottom2"]["nodes"][:, 1], -0.25, atol=1e-12)
    assert _types(g["body2"]) == {2} and sum(len(p) for _, p in g["body2"]["cells"]) == 2 * 5 * 3
    assert _area(g["body2"]["cells"]) == pytest.approx(3 * 0.25, rel=1e-12)
    assert _area(g["body1"]["cells"]) == pytest.approx(3 * 1.0, rel=1e-12)

    with pytest.raises(SystemExit) as info:
        two_blocks._main([str(tmp_path / "bad.msh"), "--angle", "nan"])
    err = capsys.readouterr().err
    assert info.value.code == 2 and "angle" in err and "nan" in err and "finite" in err
    assert not (tmp_path / "bad.msh").exists()
    with pytest.raises(SystemExit) as info:  # body 2's mesh with a rigid foundation (no body 2)
        two_blocks._main([str(tmp_path / "bad.msh"), "--foundation", "--nx2", "7", "--height2", "0.3"])
    err = capsys.readouterr().err
    assert info.value.code == 2 and "--nx2 7, --height2 0.3: body 2's mesh, but --foundation" in err
    assert not (tmp_path / "bad.msh").exists()


def test_arc_script_meshes_the_seat_with_its_own_thickness_and_triangles(tmp_path):
    """``python -m cfcontact.meshes.arc_on_block OUT --radius 2 --half-angle 30 --nx 6 --ny 2
    --ny2 3 --height2 0.25 --cell triangle`` (in process): the interface nodes of both bodies on
    the circle of radius 2 about (0, 2), one to one, at the angles -30, -20, ..., 30 degrees from
    its lowest point; triangles only (2 nx ny per body 1, 2 nx ny2 per body 2); the bodies' areas
    those of the rectangles above / below the chord y = yc plus / minus the polygon of the arc's
    nodes, R^2/2 (nx sin(2 theta / nx) - sin 2 theta)."""
    from cfcontact.meshes import arc_on_block

    out = tmp_path / "arc.msh"
    R, th, nx, h, h2 = 2.0, math.radians(30.0), 6, 0.5, 0.25
    assert arc_on_block._main([str(out), "--radius", "2", "--half-angle", "30", "--nx", "6", "--ny", "2",
                               "--ny2", "3", "--height2", "0.25", "--cell", "triangle"]) == 0
    g = _read_msh(out)
    for name in ("contact1", "contact2"):
        p = g[name]["nodes"]
        np.testing.assert_allclose(np.hypot(p[:, 0], p[:, 1] - R), R, rtol=0, atol=1e-12)
        # (gmsh spaces the nodes of a circle arc evenly in angle to ~1e-9, on the circle to rounding)
        np.testing.assert_allclose(np.sort(np.arctan2(p[:, 0], R - p[:, 1])), np.linspace(-th, th, nx + 1),
                                   rtol=0, atol=1e-8)
    key = lambda p: np.round(p[np.argsort(p[:, 0])], 12)  # noqa: E731
    np.testing.assert_array_equal(key(g["contact1"]["nodes"]), key(g["contact2"]["nodes"]))
    a, yc = R * math.sin(th), R * (1 - math.cos(th))
    segment = 0.5 * R**2 * (nx * math.sin(2 * th / nx) - math.sin(2 * th))
    assert _types(g["body1"]) == _types(g["body2"]) == {2}
    assert sum(len(p) for _, p in g["body1"]["cells"]) == 2 * nx * 2
    assert sum(len(p) for _, p in g["body2"]["cells"]) == 2 * nx * 3
    assert _area(g["body1"]["cells"]) == pytest.approx(2 * a * h + segment, rel=1e-12)
    assert _area(g["body2"]["cells"]) == pytest.approx(2 * a * (yc + h2) - segment, rel=1e-12)
    np.testing.assert_allclose(g["bottom2"]["nodes"][:, 1], -h2, atol=1e-12)


def test_punch_script_builds_a_half_punch_with_a_gap(tmp_path):
    """``python -m cfcontact.meshes.rounded_punch OUT --half --gap0 0.05 --size 0.025`` (in
    process; --zone left at its 0, the default w - r/4): the half model's groups (sym1, sym2, no
    left1/left2), every node at x >= 0, contact1 flat at y = gap0 up to x = w - r and on the
    rounded edge's circle (centre (w - r, gap0 + r), radius r) beyond, up to x = w; contact2 on
    y = 0 up to x = w - r/4; sym1 on x = 0 from gap0 to gap0 + height; the half punch's area
    w h - r^2 + k r^2/2 sin(pi / (2k)) for the k segments of its rounded edge, the half block's
    width/2 x depth."""
    from cfcontact.meshes import rounded_punch

    out = tmp_path / "punch.msh"
    w, r, H, g0 = 0.5, 0.1, 0.5, 0.05
    assert rounded_punch._main([str(out), "--half", "--gap0", "0.05", "--size", "0.025", "--size-far", "0.2"]) == 0
    g = _read_msh(out)
    assert set(g) == {"body1", "body2", "contact1", "top1", "right1", "sym1", "contact2", "top2", "bottom2",
                      "right2", "sym2"}
    assert min(v["nodes"][:, 0].min() for v in g.values()) >= 0.0
    p = g["contact1"]["nodes"]
    flat, edge = p[p[:, 0] <= w - r + 1e-12], p[p[:, 0] > w - r + 1e-12]
    np.testing.assert_allclose(flat[:, 1], g0, atol=1e-12)
    np.testing.assert_allclose(np.hypot(edge[:, 0] - (w - r), edge[:, 1] - (g0 + r)), r, rtol=0, atol=1e-12)
    assert flat[:, 0].min() == 0.0 and edge[:, 0].max() == pytest.approx(w, abs=1e-12)
    q = g["contact2"]["nodes"]
    np.testing.assert_allclose(q[:, 1], 0.0, atol=1e-12)
    assert q[:, 0].min() == 0.0 and q[:, 0].max() == pytest.approx(w - r / 4, abs=1e-12)
    s = g["sym1"]["nodes"]
    assert np.all(s[:, 0] == 0.0) and s[:, 1].min() == pytest.approx(g0) and s[:, 1].max() == pytest.approx(g0 + H)
    k = len(edge)  # the rounded edge's segments: its nodes beyond x = w - r
    assert k >= 4
    assert _area(g["body1"]["cells"]) == pytest.approx(w * H - r**2 + k * r**2 / 2 * math.sin(math.pi / (2 * k)),
                                                       rel=1e-12)
    assert _area(g["body2"]["cells"]) == pytest.approx(2.0 * 2.0, rel=1e-12)


@pytest.mark.parametrize("script,kwargs,words,good", [
    ("cylinder_on_block", dict(zone=0.5, width=1.0), ["zone must be below width / 2 = 0.5", "got 0.5"],
     dict(zone=0.49, width=1.0)),
    ("rounded_punch", dict(edge_radius=0.1, height=0.08), ["edge_radius must be below the punch's height = 0.08",
                                                           "got 0.1"], dict(edge_radius=0.1, height=0.1001)),
    ("rounded_punch", dict(edge_radius=0.1, size=0.06), ["size must be at most edge_radius / 2 = 0.05", "got 0.06"],
     dict(edge_radius=0.1, size=0.05)),
], ids=["cylinder-zone-vs-width", "punch-radius-vs-height", "punch-size-vs-radius"])
def test_pressed_models_refuse_parameters_that_do_not_fit(script, kwargs, words, good):
    """A contact zone as wide as the block, an edge radius as large as the punch's height, elements
    larger than half the edge radius: GeometryError (an InputError) naming the bad value and the
    bound, from check_parameters and from the builder before meshing; a value just inside the
    bound passes."""
    import importlib

    mod = importlib.import_module(f"cfcontact.meshes.{script}")
    for call in (mod.check_parameters, getattr(cfcontact, script)):
        with pytest.raises(GeometryError) as info:
            call(**kwargs)
        assert all(w in str(info.value) for w in words), str(info.value)
        assert isinstance(info.value, InputError)
    assert mod.check_parameters(**good)


# ------------------------------------------------------------------ materials, loads, options
def test_bad_materials_are_refused_naming_the_value_and_the_body():
    """A negative or NaN Young's modulus (also one body's), an empty per-body dict, a body's modulus
    given as a string; a string or a boolean given to lame_parameters: InputError naming the value (and the body); the builder
    refuses a negative modulus of body 2 the same way, before meshing."""
    from cfcontact.assembly import lame_parameters
    from cfcontact.material import check_material

    cases = [(dict(E=-2e11, nu=0.3), ["finite positive number", "-2"]),
             (dict(E=float("nan"), nu=0.3), ["finite positive number", "nan"]),
             (dict(E={"body1": 2.1e11, "body2": -1.0}, nu=0.3), ["finite positive number", "-1.0", "E['body2']"]),
             (dict(E={}, nu=0.3), ["E is an empty dict", "body name/number: value"]),
             (dict(E={"body1": "steel"}, nu=0.3), ["E must be a number, got 'steel'", "E['body1']"])]
    for kw, words in cases:
        with pytest.raises(InputError) as info:
            check_material(**kw)
        assert all(w in str(info.value) for w in words), (kw, str(info.value))
    for bad in ("steel", True):
        with pytest.raises(InputError, match=f"E must be a number, got {bad!r}"):
            lame_parameters(bad, 0.3)
    with pytest.raises(InputError, match=r"got -1\.0 \(in E\['body2'\]\)"):
        cfcontact.two_blocks(nx=2, ny=1, E={"body1": 2.1e11, "body2": -1.0})


@pytest.mark.parametrize("loads,words", [
    (dict(body_force1=(1.0, "x")), "body_force1 must be a 2-vector"),
    (dict(body_force1=(1.0, 2.0, 3.0)), "body_force1 must be a finite 2-vector"),
    (dict(tractions1=[("top1", (1.0, 2.0))]), "tractions1 must be a dict"),
])
def test_malformed_loads_of_a_turned_model_are_reported_as_unturned(loads, words):
    """two_blocks(angle=10) turns the loads before assembling: a malformed body force or a
    traction that is no dict passes through the turning untouched and is refused by the assembly
    with the same InputError as without the angle (not a bare ValueError of the turning)."""
    for angle in (0.0, 10.0):
        with pytest.raises(InputError, match=words):
            cfcontact.two_blocks(nx=2, ny=1, angle=angle, **loads)


@pytest.mark.parametrize("traction", [(np.float32(1e6), np.int64(-10**7)), (np.float64(1e6), -10**7)],
                         ids=["numpy-scalars", "mixed"])
def test_a_turned_model_takes_a_uniform_traction_of_any_numbers(traction):
    """two_blocks(angle=10) with a uniform traction given as a pair of NumPy scalars (float32,
    int64) or of mixed number types: its load vector is the unturned model's turned by 10 degrees
    node by node, as with Python floats (before: refused as a "windowed traction" that cannot be
    turned); a windowed traction and lists of tractions are still refused with the angle."""
    def loads(angle, t):
        s = cfcontact.two_blocks(nx=2, ny=1, angle=angle, tractions1={"top1": t}, tractions2={})
        return s.loads_numpy()[0].reshape(-1, 2)

    c, s = math.cos(math.radians(10)), math.sin(math.radians(10))
    flat = loads(0.0, traction)
    np.testing.assert_allclose(flat, loads(0.0, (1e6, -1e7)), rtol=0, atol=0)
    turned = loads(10.0, traction)
    np.testing.assert_allclose(turned, flat @ np.array([[c, s], [-s, c]]), rtol=0, atol=1e-12 * np.abs(flat).max())
    np.testing.assert_allclose(turned, loads(10.0, (1e6, -1e7)), rtol=0, atol=0)
    window = {"value": (1e6, -1e7), "x": (0.0, 1.0)}
    for other in (window, [window, (1e6, 0.0)], [(1e6, 0.0), np.array([0.0, -1e7])]):  # (still refused)
        with pytest.raises(InputError, match="cannot be combined with angle=10"):
            loads(10.0, other)


def test_path_options_refuse_inconsistent_steps_and_tolerances():
    """PathOptions names every inconsistent value at once (h_min > h_max, c_p <= 1, h0 <= 0,
    max_steps < 1, tol beyond MAX_TOL) with the rule it breaks; with_overrides refuses options
    that are not PathOptions (a dict), AlphaSpan.of an alpha that is no number; the defaults
    with h_min = h_max pass."""
    from cfcontact.options import MAX_TOL, AlphaSpan, PathOptions

    with pytest.raises(InputError) as info:
        PathOptions(h_min=1.0, h_max=0.5, c_p=1.0, h0=0.0, max_steps=0, tol=0.1)
    msg = str(info.value)
    for words in ("need 0 < h_min <= h_max, got h_min=1.0, h_max=0.5", "need c_p > 1, got 1.0",
                  "need h0 > 0, got 0.0", "need max_steps >= 1", f"tol must be in (0, {MAX_TOL:g}], got 0.1"):
        assert words in msg, (words, msg)
    assert "c_s" not in msg and "tie_rtol" not in msg  # (the valid ones are not named)
    assert PathOptions(h_min=0.5, h_max=0.5).h_min == 0.5
    with pytest.raises(InputError, match="options must be PathOptions, got dict"):
        PathOptions.with_overrides({"h_min": 1e-4}, h_max=1.0)
    with pytest.raises(InputError, match=r"alpha_start and alpha_end must be numbers, got 'a', 1"):
        AlphaSpan.of("a", 1, PathOptions())


# ------------------------------------------------------------------ compat: gmsh and JIT helpers
def test_a_model_built_in_a_callers_gmsh_session_leaves_it_as_it_was():
    """cfcontact.two_blocks called while the caller has gmsh initialised with two models of its
    own (the first current): gmsh stays initialised, the caller's first model is current again
    with its point, both models are still there and cfcontact's is gone."""
    import gmsh

    from cfcontact import compat

    assert not compat.gmsh_is_initialized()
    gmsh.initialize([], False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add("mine")
        gmsh.model.geo.addPoint(0.25, 0.5, 0.0)
        gmsh.model.geo.synchronize()
        gmsh.model.add("other")
        gmsh.model.setCurrent("mine")
        system = cfcontact.two_blocks(nx=2, ny=1)
        assert (system.n, system.m) == (2 * 2 * (3 * 2 - 2), 2)
        assert compat.gmsh_is_initialized()
        assert gmsh.model.getCurrent() == "mine"
        assert gmsh.model.getEntities(0) == [(0, 1)]
        assert "other" in gmsh.model.list() and not any("cfcontact" in m for m in gmsh.model.list())
    finally:
        gmsh.finalize()
    assert not compat.gmsh_is_initialized()


def test_a_failing_jit_compilation_carries_the_compilers_output(capfd, caplog):
    """compat.quiet_jit: what the compiler writes to fds 1 and 2 does not reach the terminal; when
    the compilation fails the error carries it as a note (and the descriptors and the root logger's
    level are restored); when it succeeds it is logged at DEBUG by cfcontact.compat."""
    from cfcontact import compat

    root_level = logging.getLogger().level
    with pytest.raises(RuntimeError, match="compilation failed") as info:
        with compat.quiet_jit("form"):
            os.write(2, b"cc: error: unknown type name 'ufc_form'\n")
            raise RuntimeError("compilation failed")
    notes = getattr(info.value, "__notes__", [])
    assert notes == ["output of the JIT compilation of a form:\ncc: error: unknown type name 'ufc_form'"]
    os.write(2, b"after\n")
    out, err = capfd.readouterr()
    assert err == "after\n" and out == ""
    assert logging.getLogger().level == root_level

    caplog.set_level(logging.DEBUG, logger="cfcontact.compat")
    with compat.quiet_jit("finite element"):
        os.write(1, b"warning: unused variable 'w0'\n")
    out, err = capfd.readouterr()
    assert out == err == ""
    assert any("JIT compilation of a finite element" in r.getMessage() and "unused variable" in r.getMessage()
               for r in caplog.records if r.name == "cfcontact.compat" and r.levelno == logging.DEBUG)


def test_dolfinx_versions_parse_to_their_numeric_parts():
    """parse_version keeps the leading numeric parts: a dev or post release stops at its tag."""
    from cfcontact.compat import parse_version

    assert parse_version("0.10.0.post1") == (0, 10, 0)
    assert parse_version("0.9.0.dev0") == (0, 9, 0)
    assert parse_version("0.5.2") == (0, 5, 2)
    assert parse_version("0.10.0rc1") == (0, 10, 0)


# ------------------------------------------------------------------ bench drivers
@pytest.mark.parametrize("argv,words", [
    (["--timeout", "-1"], "--timeout must be a positive number of seconds, got -1.0"),
    (["--timeout", "inf"], "--timeout must be a positive number of seconds, got inf"),
    (["--mpi", "0"], "--mpi must be a number of MPI ranks >= 1, got 0"),
    (["--petsc-option", "mat mumps=1"], "--petsc-option must be KEY=VALUE"),
    (["--sizes", "50"], "--sizes must be DOF counts >= 100, got '50'"),
    (["--sizes", "nan"], "--sizes must be DOF counts >= 100, got 'nan'"),
])
def test_bench_refuses_bad_arguments_with_exit_code_2(tmp_path, capsys, argv, words):
    """cfcontact bench with a bad --timeout, --mpi, --petsc-option or --sizes: exit code 2, the
    message names the bad value and the valid range, nothing is measured or written."""
    from cfcontact import bench

    assert bench.main([*argv, "--output", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("bench: error: ") and words in err, err
    if argv[0] == "--petsc-option":
        assert "'mat mumps=1'" in err
    assert not (tmp_path / "out").exists()


def test_part_b_mesh_has_the_dofs_and_contact_nodes_it_announces():
    """Part B's mesh_for(n_target): nx = 3 ny and n = 4 nx (ny + 1) within 5 % of the targets of
    the full run; at the smallest size the bench accepts (100) the two steel blocks assembled with
    those cells have exactly n free DOFs and m = nx contact nodes (the row's n and m)."""
    from cfcontact.bench import SIZES, mesh_for
    from cfcontact.demo_models import build_blocks

    for target in SIZES:
        nx, ny, n = mesh_for(target)
        assert nx == 3 * ny and n == 4 * nx * (ny + 1) and abs(n - target) <= 0.05 * target, (target, nx, ny, n)
    nx, ny, n = mesh_for(100)
    system = build_blocks(0.3, nx=nx, ny=ny)
    assert (system.n, system.m) == (n, nx) == (72, 6)


def test_part_b_compares_the_parallel_run_with_the_serial_one():
    """compare_ranks (the rows of ``--mpi N``): the same transitions within 1e-9 relative in
    alpha are the serial run's; a larger difference or another set change is not, and the largest
    relative difference is reported; a run that failed before its path compares to nothing."""
    from cfcontact.bench import compare_ranks

    serial = {"transition_keys": [[3, "slip+", "slip"], [5, "gap", "open"]], "transition_alphas": [0.25, 0.5]}
    close = dict(serial, transition_alphas=[0.25, 0.5 * (1 + 1e-12)])
    far = dict(serial, transition_alphas=[0.25 * (1 - 1e-8), 0.5])
    other = dict(serial, transition_keys=[[3, "slip+", "slip"], [6, "gap", "open"]])
    r = compare_ranks(serial, close)
    assert r["same_as_serial"] is True and r["max_alpha_rel_difference"] == pytest.approx(1e-12, rel=1e-3)
    r = compare_ranks(serial, far)
    assert r["same_as_serial"] is False and r["max_alpha_rel_difference"] == pytest.approx(1e-8, rel=1e-6)
    assert compare_ranks(serial, other)["same_as_serial"] is False
    assert compare_ranks(serial, {"returncode": 1, "stage": "factorization"}) == {"same_as_serial": None}


def test_a_worker_that_times_out_or_dies_keeps_its_partial_report():
    """run_worker (every Part B, C and D row): a worker killed at its timeout keeps what its
    BENCH-PARTIAL line reported (stage, n), with return code "timeout" and the reason; a worker
    that dies keeps it too, with its return code and the tail of its stderr; the log says in which
    stage each failed."""
    from cfcontact.bench_stress import run_worker

    logs = []
    partial = 'print("BENCH-PARTIAL {\\"stage\\": \\"path\\", \\"n\\": 72}", flush=True)'
    res = run_worker([sys.executable, "-c", f"import time; {partial}; time.sleep(60)"], {"m": 6}, timeout=3,
                     log=logs.append)
    assert res["m"] == 6 and res["n"] == 72 and res["stage"] == "path" and res["returncode"] == "timeout"
    assert res["error"] == "timeout after 3 s" and res["elapsed"] < 30
    res = run_worker([sys.executable, "-c", f"{partial}; raise SystemExit('x' * 50 + 'worker died: out of memory')"],
                     {}, timeout=60, log=logs.append, error_chars=30)
    assert res["stage"] == "path" and res["returncode"] == 1
    assert res["error"] == ("x" * 50 + "worker died: out of memory\n")[-30:]  # (the tail)
    assert "FAILED (timeout) in stage path" in logs[0] and "FAILED (1) in stage path" in logs[1]
    assert "worker died: out of memory" in logs[1]


def test_part_d_summary_without_the_seed_method():
    """Part D's summary of random load paths when the seed method was not run (--quick's default
    --seed-check 0): the counts, times and start ratios of the records, and no seed fields."""
    from cfcontact.bench_stress import _summary

    recs = [{"status": "completed", "transitions": 5, "time": 1.0, "start": "ssnm", "degenerate_points": 2},
            {"status": "completed", "transitions": 7, "time": 3.0, "start": "homotopy", "time_given_start": 1.5,
             "same_path": True, "backtracks": 1},
            {"status": "start failure", "transitions": 0, "time": 0.5, "start": None}]
    s = _summary(recs)
    assert s == {"runs": 3, "status": {"completed": 2, "start failure": 1}, "transitions_total": 12,
                 "transitions_max": 7, "degenerate_points": 2, "backtracks": 1, "time_total": 4.5, "time_median": 1.0,
                 "starts": {"ssnm": 1, "homotopy": 1, "-": 1}, "homotopy_start_median_time": 3.0,
                 "ssnm_start_median_time": 1.0, "homotopy_over_ssnm": 3.0, "homotopy_over_given_start": 2.0,
                 "homotopy_over_given_start_max": 2.0, "homotopy_same_path": 1}


def test_body_2_mesh_with_a_foundation_is_named_as_ignored():
    """two_blocks(foundation=True) has no body 2: nx2, ny2, height2 given with it warn that they
    are ignored (a case file refuses them) and the model is the one built without them."""
    with pytest.warns(cfcontact.IgnoredOptionWarning, match=r"nx2=7, height2=0.3 ignored: body 2's mesh"):
        system = cfcontact.two_blocks(nx=3, ny=1, foundation=True, nx2=7, height2=0.3)
    assert system.checksum() == cfcontact.two_blocks(nx=3, ny=1, foundation=True).checksum()
