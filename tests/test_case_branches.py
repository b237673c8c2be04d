"""Branches of the case layer that the rest of the suite never ran (a coverage run): bad values
of a case file, a .msh that gmsh cannot read, damaged checkpoints and foreign output folders,
the other forms a case may give a value in (a body force for every body, a single clamp tag, a
tag number as a TOML key), gmsh models that break the tag convention, segment pairing with a
search distance, systems given as arrays, and the command line of the pressed-model scripts.

Bad input: the typed exception (or exit code 2) and a message naming the bad value and what is
valid, with nothing written.  Real branches: checked against an independent reference (an
analytic value, the other form of the same input, a reload of what was saved).
"""

import json
import math
import os
import shutil
import tomllib

import numpy as np
import pytest

from cfcontact import case
from cfcontact.case import CaseError

G = 'geometry = {kind = "two_blocks"}\n'
F = 'geometry = {kind = "block_on_foundation"}\n'

# (label, case text, words of the one-line message)
BAD_VALUES = [
    ("traction not numbers", G + 'loads = {f1 = {top1 = [1, "a"]}}', ["[loads] f1.top1", "[x, y]", "'a'"]),
    ("traction inf", G + 'loads = {f1 = {top1 = [inf, 0]}}', ["[loads] f1.top1", "finite", "inf"]),
    ("obstacle not a table", F + "contact = {obstacle = 3}", ["[contact.obstacle]", 'kind = "line"', "integer 3"]),
    ("obstacle radius 0", F + 'contact = {obstacle = {kind = "circle", center = [1.5, 3.0], radius = 0.0}}',
     ["[contact.obstacle] radius", "> 0", "0.0"]),
    ("obstacle with node pairing",
     F + 'contact = {pairing = "node", obstacle = {kind = "line", point = [0, 0], normal = [0, 1]}}',
     ["[contact] pairing", 'pairing = "segment"']),
    ("dirichlet not a table", G + "loads = {dirichlet = 3}", ["[loads.dirichlet]", "{tag = {x = value", "integer 3"]),
    ("dirichlet component not a table", G + "loads = {dirichlet = {top1 = 0.0}}",
     ["[loads.dirichlet] top1", "{x = 0.0}", "float 0.0"]),
    ("dirichlet no component", G + "loads = {dirichlet = {top1 = {}}}", ["[loads.dirichlet] top1", "table {}"]),
    ("rho nan", G + "contact = {rho = nan}", ["[contact] rho", "finite", "nan"]),
    ("title a number", "title = 3\n" + G, ["title", "string", "integer 3"]),
    ("clamp of booleans", G + "loads = {clamp = [true]}", ["[loads] clamp", "tags", "[True]"]),
    ("slave a float", G + 'contact = {pairing = "segment", slave = 1.5}', ["[contact] slave", "tag", "1.5"]),
    ("E an empty table", G + "material = {E = {}}", ["[material] E", "{body = number}", "{}"]),
    ("plane", G + 'material = {plane = "axisym"}', ["[material] plane", '"strain" or "stress"', "axisym"]),
    ("section not a table", G + "material = 3", ["[material]", "a table", "integer 3"]),
    ("f1 an array", G + "loads = {f1 = [0, 1]}", ["[loads] f1", "{tag = [tx, ty]", "[0, 1]"]),
    ("body force a number", G + "loads = {body_force1 = 3.0}", ["[loads] body_force1", "[bx, by]", "3.0"]),
    ("body force of 3", G + "loads = {body_force1 = [1, 2, 3]}", ["[loads] body_force1", "[x, y]", "[1, 2, 3]"]),
    ("friction a string", G + 'contact = {friction = "high"}', ["[contact] friction", ">= 0", "'high'"]),
    ("friction empty list", G + "contact = {friction = []}", ["[contact] friction", ">= 0", "[]"]),
    ("formats a string", G + 'output = {plot_formats = "png"}', ["[output] plot_formats", '"png"/"pdf"', "'png'"]),
    ("format svg", G + 'output = {plot_formats = ["png", "svg"]}', ["[output] plot_formats", "svg", '"pdf"']),
    ("zoom of 3", G + "output = {zoom = [0.1, 0.2, 0.3]}", ["[output] zoom", "[alpha_lo, alpha_hi]", "0.3"]),
    ("zoom reversed", G + "output = {zoom = [0.5, 0.2]}", ["[output] zoom", "alpha_lo < alpha_hi", "[0.5, 0.2]"]),
    ("window floats", G + "output = {window_size = [800.0, 600]}", ["[output] window_size", "[width, height]",
                                                                     "800.0"]),
    ("window too small", G + "output = {window_size = [8, 600]}", ["[output] window_size", "16..10000", "[8, 600]"]),
    ("animation format", G + 'output = {animation_format = "avi"}', ["[output] animation_format", '"mp4"', "avi"]),
    ("animation frames", G + "output = {animation_frames = 0}", ["[output] animation_frames", ">= 1", "0"]),
    ("magnification", G + "output = {magnification = 0.0}", ["[output] magnification", "> 0", "0.0"]),
    ("component index negative", G + "output = {component = -1}", ["[output] component", ">= 0", "-1"]),
    ("component index not a number", G + 'output = {component = "lam_n:x"}',
     ["[output] component", "NAME:INDEX", "u, lam_n, lam_t", "'lam_n:x'"]),
    ("component list of one", G + 'output = {component = ["lam_n"]}', ["[output] component", '["lam_n", i]',
                                                                       "['lam_n']"]),
    ("component negative index", G + 'output = {component = ["lam_n", -2]}', ["[output] component", ">= 0", "-2"]),
    ("no geometry", 'title = "x"', ["[geometry]", "'two_blocks'", "'msh'"]),
    ("geometry not a table", "geometry = 3", ["[geometry]", "a table", "integer 3"]),
    ("geometry without kind", "geometry = {nx = 3}", ["[geometry] kind", "'two_blocks'", "'msh'"]),
    ("msh without file", 'geometry = {kind = "msh"}', ["[geometry] file", 'file = "model.msh"']),
    ("max_iter 0", G + "path = {max_iter = 0}", ["[path] max_iter", ">= 1", "0"]),
    ("backend", G + 'path = {backend = "gpu"}', ["[path] backend", "gpu", "'condensed'"]),
    ("growth 1.5", 'geometry = {kind = "cylinder", growth = 1.5}', ["[geometry] growth", "(0, 1)", "1.5"]),
]


@pytest.mark.parametrize("text,words", [b[1:] for b in BAD_VALUES], ids=[b[0] for b in BAD_VALUES])
def test_bad_case_values_name_the_key_and_the_valid_values(text, words):
    """Each bad value of a case file is a CaseError (exit code 2) whose message names the key,
    the value given and what would be valid (the words listed with it, chosen by hand)."""
    with pytest.raises(CaseError) as info:
        case.validate_case(tomllib.loads(text))
    for w in words:
        assert w in str(info.value), (w, str(info.value))


def test_other_forms_of_tags_and_components_are_normalised():
    """A single clamp tag (not a list), a component as an integer or as its digits, and the
    forms of parse_component, against the values they stand for written out."""
    got = case.validate_case(tomllib.loads(F + 'loads = {clamp = "left1"}'))
    assert got["loads"]["clamp"] == ["left1"]
    assert case.validate_case(tomllib.loads(G + "output = {component = 7}"))["output"]["component"] == 7
    assert case.validate_case(tomllib.loads(G + 'output = {component = "7"}'))["output"]["component"] == 7
    assert case.parse_component("lam_t:3", "--component") == ("lam_t", 3)
    assert case.parse_component(["u", 0], "--component") == ("u", 0)
    with pytest.raises(CaseError, match=r"--component: an index of y must be >= 0, got -4"):
        case.parse_component("-4", "--component")
    with pytest.raises(CaseError, match=r"--component: expected \"NAME:INDEX\" \(NAME one of u, lam_n, lam_t\)"):
        case.parse_component("lam_n", "--component")


def _system(loads, geometry=None, material=None):
    raw = {"geometry": geometry or {"kind": "two_blocks", "nx": 4, "ny": 2}, "loads": loads}
    if material:
        raw["material"] = material
    return case.build_system(case.validate_case(raw))


def test_one_body_force_for_every_body_against_the_area():
    """body_force1 = [bx, by] (one vector for all bodies): the x and y sums of f1 over the free
    DOFs equal b times the area the free nodes carry (two 3 x 1 blocks, nx = 4: the clamped left
    column carries hx / 2 x 1 of each block, so 2 x (3 - 0.375) = 5.25), and f1 is the one of the
    table form {body1 = b, body2 = b}."""
    s = _system({"f1": {}, "f2": {}, "body_force1": [1.0, -2.0]})
    comp = np.asarray(s.geometry.dof_comp)
    f1 = s.f1.getArray()
    assert f1[comp == 0].sum() == pytest.approx(5.25, rel=1e-12)
    assert f1[comp == 1].sum() == pytest.approx(-10.5, rel=1e-12)
    assert not np.any(s.f2.getArray())
    table = _system({"f1": {}, "f2": {}, "body_force1": {"body1": [1.0, -2.0], "body2": [1.0, -2.0]}})
    np.testing.assert_array_equal(table.f1.getArray(), f1)


def test_tag_numbers_as_toml_keys_equal_the_names():
    """TOML table keys are strings: [loads.f1] "12" = ... (top1=12) and E = {"1" = ..., "2" = ...}
    give the system of the same case written with the names."""
    by_number = _system({"f1": {"12": [0.0, -1.0e6]}, "f2": {"12": [1.0e6, 0.0]}},
                        material={"E": {"1": 2.0e11, "2": 1.0e11}})
    by_name = _system({"f1": {"top1": [0.0, -1.0e6]}, "f2": {"top1": [1.0e6, 0.0]}},
                      material={"E": {"body1": 2.0e11, "body2": 1.0e11}})
    assert by_number.checksum() == by_name.checksum()
    assert np.any(by_number.f1.getArray())


# ------------------------------------------------------------------ case files and .msh files
def _write_blocks_msh(fn):
    from cfcontact.meshes import common, two_blocks

    params = two_blocks.check_parameters(4, 2, 3.0, 1.0, "quadrilateral", 0.0)
    common.write_msh(str(fn), "two_blocks", two_blocks.build, **params)


def test_case_files_that_cannot_be_read_exit_2_and_write_nothing(tmp_path, capsys):
    """A case file that is not UTF-8, a .msh that gmsh cannot read and a .msh case without its
    required [loads]: exit code 2, one message naming the file or key, no output folder."""
    from cfcontact import cli

    (tmp_path / "latin1.toml").write_bytes(b'title = "caf\xe9"\n[geometry]\nkind = "two_blocks"\n')
    (tmp_path / "bad.msh").write_text("this is not a mesh\n")
    (tmp_path / "badmsh.toml").write_text('[geometry]\nkind = "msh"\nfile = "bad.msh"\n[loads]\nclamp = ["left1"]\n'
                                          "[loads.f1]\n[loads.f2]\n")
    _write_blocks_msh(tmp_path / "blocks.msh")
    (tmp_path / "noclamp.toml").write_text('[geometry]\nkind = "msh"\nfile = "blocks.msh"\n[loads.f1]\n[loads.f2]\n')
    before = sorted(os.listdir(tmp_path))
    for name, words in (("latin1.toml", ["latin1.toml", "not UTF-8"]),
                        ("badmsh.toml", ["[geometry] file", "gmsh cannot read", "bad.msh"]),
                        ("noclamp.toml", ["[loads] clamp is missing", "kind = 'msh'", "clamp = [tags]"])):
        assert cli.main(["run", str(tmp_path / name), "-q"]) == 2
        err = capsys.readouterr().err
        assert err.startswith("cfcontact run: error:") and "Traceback" not in err
        for w in words:
            assert w in err, (w, err)
        assert sorted(os.listdir(tmp_path)) == before


# ------------------------------------------------------------------ run folders and checkpoints
SMALL = ('[geometry]\nkind = "two_blocks"\nnx = 6\nny = 2\n[contact]\nfriction = 0.3\n'
         "[output]\nplot = false\nrender_panel = false\n")


@pytest.fixture(scope="module")
def stopped(tmp_path_factory):
    """A run stopped at its first point (--time-limit): (case file, its <out>.partial folder)."""
    from cfcontact import cli

    d = tmp_path_factory.mktemp("stopped")
    fn = d / "case.toml"
    fn.write_text(SMALL)
    assert cli.main(["run", str(fn), "-q", "--time-limit", "1e-6"]) == 3
    partial = d / "case_out.partial"
    assert os.path.isfile(partial / "checkpoint" / "state.json")
    return fn, partial


def _damage(state, how):
    if how == "no resume state":
        del state["resume_state"]
    elif how == "checksum":
        state["system_checksum"] = "abc"
    elif how == "not resumable":
        state["resumable"] = False
    elif how == "nan in a list":
        key = next(k for k, v in state["resume_state"].items() if isinstance(v, list))
        state["resume_state"][key][:1] = [float("nan")]
        return key
    return None


@pytest.mark.parametrize("how,words", [
    ("no resume state", ["state.json", "'resume_state' is missing", "--force"]),
    ("checksum", ["system_checksum 'abc'", "SHA-256", "--force"]),
    ("not resumable", ["cannot be resumed", "--force"]),
    ("nan in a list", ["is not a finite number", "--force"]),
])
def test_a_damaged_checkpoint_is_refused_and_kept(stopped, tmp_path, capsys, how, words):
    """--resume of a checkpoint whose state.json was damaged (a key removed, a checksum that is
    no SHA-256, resumable false, a NaN inside a list of the resume state): exit code 2 with a
    message naming the key and --force, the checkpoint left as it was and no output folder."""
    from cfcontact import cli

    fn = tmp_path / "case.toml"
    shutil.copy(stopped[0], fn)
    partial = tmp_path / "case_out.partial"
    shutil.copytree(stopped[1], partial)
    sj = partial / "checkpoint" / "state.json"
    state = json.loads(sj.read_text())
    key = _damage(state, how)
    sj.write_text(json.dumps(state))
    text = sj.read_text()
    assert cli.main(["run", str(fn), "-q", "--resume"]) == 2
    err = capsys.readouterr().err
    for w in words + ([f"resume_state {key}[0] is not"] if key else []):
        assert w in err, (w, err)
    assert sj.read_text() == text and not os.path.exists(tmp_path / "case_out")


def test_force_does_not_replace_a_folder_cfcontact_did_not_write(stopped, tmp_path, capsys):
    """run --force -o DIR where DIR holds a user's files (no summary.json of a run): exit code 2,
    "refusing to replace", and the user's file untouched, no DIR.partial left."""
    from cfcontact import cli

    fn = tmp_path / "case.toml"
    shutil.copy(stopped[0], fn)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep me")
    assert cli.main(["run", str(fn), "-q", "--force", "-o", str(mine)]) == 2
    err = capsys.readouterr().err
    assert "refusing to replace" in err and str(mine) in err and "not a cfcontact output folder" in err
    assert os.listdir(mine) == ["notes.txt"] and (mine / "notes.txt").read_text() == "keep me"
    assert not os.path.exists(str(mine) + ".partial")


def test_write_outputs_saves_the_path_and_warns_of_an_unreached_zoom(stopped, tmp_path):
    """write_outputs without a saved folder saves the path itself (its reload gives back the
    alphas and points), and an [output] zoom the path never reaches (it stopped near alpha 0) is
    a warning naming the zoom, path.png written without its zoom panel."""
    from cfcontact.run import load_saved_path, write_outputs

    path = load_saved_path(str(stopped[1] / "checkpoint" / "path"))
    assert path.alphas[-1] < 0.5
    fn = tmp_path / "zoom.toml"
    fn.write_text(SMALL.replace("plot = false", "plot = true\nzoom = [0.8, 0.9]"))
    c = case.load_case(fn)
    out = tmp_path / "out"
    out.mkdir()
    warnings = []
    files = write_outputs(path, c, str(out), {}, warn=warnings.append)
    assert "path/" in files and "path.png" in files and os.path.getsize(out / "path.png") > 0
    assert len(warnings) == 1 and warnings[0].startswith("[output] zoom:") and "no zoom panel" in warnings[0]
    back = load_saved_path(str(out / "path"))
    np.testing.assert_array_equal(back.alphas, path.alphas)
    np.testing.assert_array_equal(back.ys, path.ys)
    assert back.system_checksum == path.system_checksum


def test_stop_conditions_refuse_bad_values():
    """StopConditions (the library's stop conditions, checked by the CLI's argparse too): a
    count below 1, a time limit <= 0, a negative checkpoint interval name the field and value."""
    from cfcontact.run import StopConditions

    for kw, words in (({"stop_after_folds": 0}, "stop_after_folds must be >= 1, got 0"),
                      ({"time_limit": 0.0}, "time_limit must be > 0 seconds, got 0.0"),
                      ({"checkpoint_every": -1.0}, "checkpoint_every must be >= 0 seconds, got -1.0")):
        with pytest.raises(CaseError, match=words):
            StopConditions(**kw)


# ------------------------------------------------------------------ systems given as arrays
def _spd(n=4):
    return 2.0 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1) + 0.5 * np.eye(n)


@pytest.mark.parametrize("change,words", [
    ({"K": np.ones((2, 3))}, "K must be square, got shape (2, 3)"),
    ({"K": _spd() + np.eye(4, k=2)}, "K must be symmetric"),
    ({"f1": [0.0, np.inf, 0.0, 0.0]}, "load vector f1 has non-finite entries"),
    ({"N": [[0.0, 0.0, 0.0, 0.0]], "T": [[0.0, 0.0, 0.0, 0.0]]}, "contact nodes [0] have zero rows in both N and T"),
    ({"T": [[0.0, np.nan, 0.0, 0.0]]}, "T has non-finite entries"),
    ({"N": np.zeros((1, 2, 2))}, "N must be a 2-D matrix"),
])
def test_systems_from_arrays_refuse_bad_arrays(change, words):
    """ContactSystem.from_arrays: a non-square or non-symmetric K, a non-finite load or map
    entry, a contact node with zero rows in N and T, a 3-D array: InputError naming the array."""
    from cfcontact.errors import InputError
    from cfcontact.system import ContactSystem

    args = {"K": _spd(), "N": [[0.0, 0.0, 1.0, 0.0]], "T": [[0.0, 0.0, 0.0, 1.0]], "f1": np.zeros(4),
            "f2": np.ones(4), "friction": 0.3, **change}
    with pytest.raises(InputError) as info:
        ContactSystem.from_arrays(**args)
    assert words in str(info.value)


def test_a_one_row_contact_map_and_loads_as_petsc_vectors():
    """N and T given as 1-D arrays are one contact node (the (1, n) matrices), and with_loads
    takes PETSc vectors as well as arrays: the same load(alpha) for both."""
    from cfcontact.system import ContactSystem

    s = ContactSystem.from_arrays(_spd(), [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0], np.zeros(4), np.ones(4), 0.3)
    assert (s.m, s.n) == (1, 4)
    np.testing.assert_array_equal(s.to_scipy()[1].toarray(), [[0.0, 0.0, 1.0, 0.0]])
    g1, g2 = np.arange(4.0), -np.arange(4.0) ** 2
    by_array = s.with_loads(g1, g2)
    by_vec = s.with_loads(by_array.f1, by_array.f2)
    for alpha in (0.0, 0.25, 1.0):
        expect = (1 - alpha) * g1 + alpha * g2
        np.testing.assert_allclose(np.asarray(by_vec.load(alpha)), expect, rtol=0, atol=1e-15)


def test_positive_definiteness_of_a_large_k_by_its_diagonal(monkeypatch):
    """Above INERTIA_MAX_DOFS (here lowered to 2) K is checked by its diagonal: a K with one
    non-positive diagonal entry is refused naming it (the inertia of the small-system check
    refuses it too), an SPD K passes."""
    from cfcontact import system as system_mod
    from cfcontact.errors import NotPositiveDefiniteError
    from cfcontact.system import ContactSystem

    K = np.diag([2.0, -1.0, 3.0, 1.0])
    args = ([0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0], np.zeros(4), np.ones(4), 0.0)
    with pytest.raises(NotPositiveDefiniteError, match="negative eigenvalue"):
        ContactSystem.from_arrays(K, *args, rho=1.0).check_positive_definite()
    monkeypatch.setattr(system_mod, "INERTIA_MAX_DOFS", 2)
    with pytest.raises(NotPositiveDefiniteError, match=r"1 diagonal entry is <= 0 \(the first K\[1, 1\]\)"):
        ContactSystem.from_arrays(K, *args, rho=1.0).check_positive_definite()
    ContactSystem.from_arrays(_spd(), *args).check_positive_definite()


# ------------------------------------------------------------------ gmsh models breaking the convention
def _user_model(model, variant):
    """body1 = [0, 2] x [0, 1] (4 x 2 cells), its bottom contact1=10, its left side left1=14; the
    variants leave out or misplace groups, or mesh differently."""
    geo = model.geo
    p = [geo.addPoint(x, y, 0.0) for x, y in ((0, 0), (2, 0), (2, 1), (0, 1))]
    lines = [geo.addLine(p[i], p[(i + 1) % 4]) for i in range(4)]
    surf = geo.addPlaneSurface([geo.addCurveLoop(lines)])
    for line, k in zip(lines, (4, 2, 4, 2)):
        geo.mesh.setTransfiniteCurve(line, k + 1)
    groups = {(2, 1, "body1"): [surf], (1, 10, "contact1"): [lines[0]], (1, 14, "left1"): [lines[3]]}
    if variant == "inside":  # contact1 a line inside body1 (embedded in its mesh)
        a, b = geo.addPoint(0.5, 0.5, 0.0), geo.addPoint(1.5, 0.5, 0.0)
        inner = geo.addLine(a, b)
        geo.mesh.setTransfiniteCurve(inner, 3)
        geo.synchronize()
        model.mesh.embed(1, [inner], 2, surf)
        groups[(1, 10, "contact1")] = [inner]
    else:
        geo.mesh.setTransfiniteSurface(surf)
    if variant == "body2 alone":
        q = [geo.addPoint(x, y, 0.0) for x, y in ((0, -1), (2, -1), (2, -0.001), (0, -0.001))]
        lines2 = [geo.addLine(q[i], q[(i + 1) % 4]) for i in range(4)]
        groups[(2, 2, "body2")] = [geo.addPlaneSurface([geo.addCurveLoop(lines2)])]
    geo.synchronize()
    if variant == "no contact1":
        del groups[(1, 10, "contact1")]
    for (dim, num, name), ents in ({} if variant == "no groups" else groups).items():
        model.addPhysicalGroup(dim, ents, num)
        model.setPhysicalName(dim, num, name)
    if variant != "not meshed":
        model.mesh.generate(2)
    if variant == "second order":
        model.mesh.setOrder(2)


@pytest.mark.parametrize("variant,words", [
    ("no groups", ["no physical groups", "body1=1, contact1=10"]),
    ("no contact1", ["no 1-D physical group 10 (contact1)", "left1"]),
    ("body2 alone", ["body2 (2-D group 2) and contact2 (1-D group 20) must be given together"]),
    ("not meshed", ["no 2-D elements", "generate(2)"]),
    ("second order", ["only meshes of linear triangles or of linear quadrilaterals", "types found: [9]"]),
    ("inside", ["contact1 (1-D group 10) lies inside body1", "2 of its 2 facets"]),
])
def test_gmsh_models_breaking_the_tag_convention_are_named(variant, words):
    """A user's gmsh model without physical groups, without contact1, with body2 but no contact2,
    not meshed, of second order, or with contact1 inside its body: GeometryError saying what is
    wrong (and what the convention wants)."""
    from cfcontact import compat
    from cfcontact.assembly import assemble_contact_system
    from cfcontact.errors import GeometryError

    with compat.gmsh_model(variant.replace(" ", "-")) as model:
        _user_model(model, variant)
        with pytest.raises(GeometryError) as info:
            assemble_contact_system(model, clamp=("left1",), tractions1={}, tractions2={})
    for w in words:
        assert w in str(info.value), (w, str(info.value))


def test_the_user_model_assembles_with_one_clamp_tag_given_alone():
    """The valid variant of the models above with clamp = "left1" (a tag, not a list): the
    system of clamp = ("left1",), 4 contact nodes on the bottom but the clamped corner."""
    from cfcontact import compat
    from cfcontact.assembly import assemble_contact_system

    systems = []
    for clamp in ("left1", ("left1",)):
        with compat.gmsh_model("user") as model:
            _user_model(model, "valid")
            systems.append(assemble_contact_system(model, clamp=clamp, tractions1={"left1": (1.0, 0.0)},
                                                   tractions2={}))
    assert systems[0].m == 4 and systems[0].n == 2 * (15 - 3)
    assert systems[0].checksum() == systems[1].checksum()


# ------------------------------------------------------------------ segment pairing, search distance
def test_search_distance_leaves_out_exactly_the_nodes_farther_along_their_normal():
    """Node-to-segment pairing of an arc (R = 1, nodes every 6 degrees over +-60, lowest point at
    height g0 = 0.01) onto the line y = 0 (40 facets): along the radial normal of an interior
    node at angle theta the line is t = (g0 + R (1 - cos theta)) / cos theta away.  Without a
    search distance every node is paired with that gap; with search_distance = 0.1 exactly the
    nodes with t <= 0.1 are, with the same gaps, the others reported with reason "distance"."""
    from cfcontact.pairing import node_to_segment

    R, g0 = 1.0, 0.01
    theta = np.radians(np.arange(-60, 61, 6.0))
    arc = np.column_stack([R * np.sin(theta), g0 + R * (1 - np.cos(theta))])
    line = np.column_stack([np.linspace(-3, 3, 41), np.zeros(41)])
    pts = np.vstack([arc, line])
    k = len(arc)
    sf = np.column_stack([np.arange(k - 1), np.arange(1, k)])
    mf = np.column_stack([np.arange(k, k + 40), np.arange(k + 1, k + 41)])
    s_cent, m_cent = np.tile([0.0, R + g0], (len(sf), 1)), np.column_stack([pts[mf].mean(axis=1)[:, 0], -np.ones(40)])
    t = (g0 + R * (1 - np.cos(theta))) / np.cos(theta)
    interior = np.arange(1, k - 1)

    full = node_to_segment(pts, sf, s_cent, mf, m_cent)
    assert full.excluded.size == 0
    gap = dict(zip(full.slave.tolist(), full.gap))
    np.testing.assert_allclose([gap[i] for i in interior], t[interior], rtol=1e-12, atol=1e-14)

    near = node_to_segment(pts, sf, s_cent, mf, m_cent, search_distance=0.1)
    want = set(interior[t[interior] <= 0.1].tolist())
    assert set(near.slave.tolist()) == want and 3 <= len(want) < k - 2
    np.testing.assert_allclose(near.gap, [gap[i] for i in near.slave.tolist()], rtol=0, atol=0)
    assert sorted(near.excluded.tolist()) == sorted(set(range(k)) - want)
    assert set(near.excluded_reason.tolist()) == {"distance"}


# ------------------------------------------------------------------ the pressed models' scripts
def test_the_cylinder_script_writes_a_half_model_and_refuses_a_bad_growth(tmp_path, capsys):
    """python -m cfcontact.meshes.cylinder_on_block OUT.msh --half --cell quadrilateral ...
    (common.script_main, in process): the .msh read back has the physical groups that case.py
    names for a half cylinder model (sym1, sym2, no left1/left2), only quadrilaterals, every node
    at x >= 0; --growth 1.5 exits 2 naming growth and writes nothing."""
    import gmsh

    from cfcontact import compat
    from cfcontact.meshes import cylinder_on_block

    out = tmp_path / "half.msh"
    assert cylinder_on_block._main([str(out), "--half", "--cell", "quadrilateral", "--size", "0.1",
                                    "--size-far", "0.5", "--zone", "0.4"]) == 0
    with compat.gmsh_model("read-back") as model:
        gmsh.merge(str(out))
        names = sorted(model.getPhysicalName(d, n) for d, n in model.getPhysicalGroups())
        types = {int(t) for t in model.mesh.getElementTypes(2)}
        xyz = model.mesh.getNodes()[1].reshape(-1, 3)
    assert names == sorted(case.builtin_groups("cylinder", {"half": True}))
    assert types == {3} and xyz[:, 0].min() >= -1e-12 and 50 < len(xyz) < 2000

    with pytest.raises(SystemExit) as info:
        cylinder_on_block._main([str(tmp_path / "bad.msh"), "--growth", "1.5"])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "growth" in err and "1.5" in err and not os.path.exists(tmp_path / "bad.msh")


# ------------------------------------------------------------------ fields: XDMF export, materials
def test_export_at_the_default_alpha_and_alphas_that_run_short(stopped, tmp_path):
    """export_path without an alpha writes the solutions at the alpha of largest multiplicity:
    the file of export_path at that alpha given explicitly; of a path of one point (no interval)
    it is an InputError asking for an alpha.  write_xdmf with fewer alphas than solutions:
    InputError naming both, and no file (not even a partial one) left."""
    from cfcontact import cli
    from cfcontact.errors import InputError
    from cfcontact.fields import export_path, write_xdmf
    from cfcontact.run import load_saved_path

    with pytest.raises(InputError, match="the path covers no alpha interval; give an alpha"):
        export_path(load_saved_path(str(stopped[1] / "checkpoint" / "path")), str(tmp_path / "none.xdmf"))
    run = tmp_path / "run"
    run.mkdir()
    shutil.copy(stopped[0], run / "case.toml")
    assert cli.main(["run", str(run / "case.toml"), "-q"]) == 0
    path = load_saved_path(str(run / "case_out" / "path"))
    k, a = path.max_multiplicity()
    assert k >= 1 and len(path.alphas) > 2
    _, what = export_path(path, str(tmp_path / "default.xdmf"))
    export_path(path, str(tmp_path / "explicit.xdmf"), alpha=a)
    assert f"at alpha = {float(a):.10g}" in what
    assert (tmp_path / "default.xdmf").read_text() == (tmp_path / "explicit.xdmf").read_text()
    sols = path.solutions_at(a)
    with pytest.raises(InputError, match="alphas has 0 values, fewer than the solutions"):
        write_xdmf(str(tmp_path / "short.xdmf"), path.geometry, sols, alphas=[])
    assert sorted(os.listdir(tmp_path)) == ["default.xdmf", "explicit.xdmf", "run"]


def test_material_per_body_keyed_by_numbers_equals_by_names(stopped):
    """cell_material with {1: E1, "2": E2} (a body number, or its digits as a TOML key gives
    them) gives the per-cell moduli of {"body1": E1, "body2": E2}: E1 on body 1's cells, E2 on
    body 2's."""
    from cfcontact.fields import cell_material
    from cfcontact.run import load_saved_path

    geometry = load_saved_path(str(stopped[1] / "checkpoint" / "path")).geometry
    by_number = cell_material(geometry, {"E": {1: 2.0e11, "2": 1.0e9}, "nu": {"1": 0.3, 2: 0.25}})
    by_name = cell_material(geometry, {"E": {"body1": 2.0e11, "body2": 1.0e9}, "nu": {"body1": 0.3, "body2": 0.25}})
    body = np.asarray(geometry.cell_body)
    np.testing.assert_array_equal(by_number[0], np.where(body == 1, 2.0e11, 1.0e9))
    np.testing.assert_array_equal(by_number[1], np.where(body == 1, 0.3, 0.25))
    np.testing.assert_array_equal(by_number[0], by_name[0])
    assert by_number[2] == by_name[2] == "strain"
