"""Case files (cfcontact.case): the schema is the one source of the format, the [path] options
reach the library, the documentation's reference is generated from the schema."""

import os
import subprocess
import sys
import tomllib

import numpy as np
import pytest

from cfcontact import case
from cfcontact.options import PathOptions

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_reference_is_a_valid_case_and_documents_every_key():
    text = case.reference_text()
    checked = case.validate_case(tomllib.loads(text))
    assert checked["geometry"]["kind"] == "two_blocks" and checked["path"]["method"] == "seed"
    for section, keys in case.SCHEMA.items():
        for name in keys or case.BLOCK_GEOMETRY:
            assert f"{name} =" in text or f"# {name} " in text or f"[{section}.{name}]" in text, (section, name)
    for name in PathOptions.names():  # generated from the options dataclass
        assert name in case.SCHEMA["path"]


def test_docs_generate_the_reference_and_hold_no_copy():
    """docs/case-files.md renders the reference with the case-reference directive, which prints
    case.reference_text() (docs/_ext/cfcontact_docs.py; tests/test_docs.py checks the built
    page); no page keeps a copy of it that could fall behind."""
    with open(os.path.join(ROOT, "docs", "case-files.md"), encoding="utf-8") as fh:
        assert "```{case-reference}\n```" in fh.read()
    with open(os.path.join(ROOT, "docs", "_ext", "cfcontact_docs.py"), encoding="utf-8") as fh:
        assert "reference_text()" in fh.read()
    first = case.reference_text().splitlines()[0]
    for fn in os.listdir(os.path.join(ROOT, "docs")):
        if fn.endswith((".md", ".rst")):
            with open(os.path.join(ROOT, "docs", fn), encoding="utf-8") as fh:
                assert first not in fh.read(), f"docs/{fn} holds a copy of the case-file reference"


@pytest.mark.slow
def test_schema_command_prints_the_reference():
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-m", "cfcontact", "schema"], capture_output=True, text=True, env=env,
                          cwd=ROOT, timeout=120)
    assert proc.returncode == 0 and proc.stdout == case.reference_text()


def test_every_path_option_reaches_the_request():
    raw = {"geometry": {"kind": "two_blocks"},
           "path": {"method": "exact", "alpha_start": 1.0, "alpha_end": 0.0, "tie_rtol": 1e-9, "h_min": 1e-6,
                    "max_transitions": 7, "alpha_min": -0.5}}
    options, span = case.path_request(case.validate_case(raw))
    assert options == PathOptions(tie_rtol=1e-9, h_min=1e-6, max_transitions=7, alpha_min=-0.5)
    assert (span.start, span.end, span.lo, span.hi) == (1.0, 0.0, -0.5, 1.0)


@pytest.mark.parametrize("path,words", [
    ({"tie_rtol": 0.5}, ["[path]", "tie_rtol", "0.5"]),
    ({"tie_rtol": "small"}, ["[path] tie_rtol", "number", "string"]),
    ({"alpha_start": 2.0, "alpha_max": 1.5}, ["[path]", "alpha_start=2.0", "outside"]),
    ({"alpha_min": 0.5, "alpha_max": 0.5}, ["[path]", "empty"]),
])
def test_bad_path_options_name_the_key(path, words):
    with pytest.raises(case.CaseError) as info:
        case.validate_case({"geometry": {"kind": "two_blocks"}, "path": path})
    for w in words:
        assert w in str(info.value), (w, str(info.value))


# ------------------------------------------------------------------ real contact geometry (issue #12)
def test_reference_documents_every_geometry_kind():
    text = case.reference_text()
    for kind in case.GEOMETRY_KINDS:
        for name in case.geometry_keys(kind):
            assert f"# {name} " in text or f"{name} =" in text, (kind, name)
    for name in ("[contact.obstacle]", "[loads.dirichlet]", "center", "normal", "search_distance", "slave"):
        assert name in text, name


@pytest.mark.parametrize("kind,geometry", [
    ("two_blocks", {}), ("block_on_foundation", {}), ("inclined", {"angle": 10.0}), ("arc", {}),
    ("cylinder", {}), ("cylinder", {"half": True}), ("punch", {}), ("punch", {"half": True})])
def test_builtin_groups_are_the_scripts_groups(kind, geometry):
    """The tags a case may name for a built-in kind are those its gmsh script creates."""
    from cfcontact import compat

    script = case._geometry_script(kind)
    with compat.gmsh_model("probe"):
        params = {k: v for k, v in geometry.items() if k != "angle"}
        if script is case._geometry_script("two_blocks"):
            params = dict(params, foundation=kind == "block_on_foundation")
        created = script.build(mesh=False, **params)
    assert sorted(case.builtin_groups(kind, geometry)) == sorted(created)


#: per example case: [geometry] entries that make it small for the tests
SMALL_GEOMETRY = {"cylinder": {"size": 0.05, "size_far": 0.5}, "half_cylinder": {"size": 0.05, "size_far": 0.5},
                  "punch": {"size": 0.05, "size_far": 0.5}, "nonmatching": {}, "obstacle": {"nx": 20, "ny": 3}}


def _example(name, **geometry):
    """The example case demos/cases/<name>.toml with some [geometry] entries replaced, validated."""
    with open(os.path.join(ROOT, "demos", "cases", f"{name}.toml"), "rb") as fh:
        raw = tomllib.load(fh)
    raw["geometry"].update(geometry)
    return case.validate_case(raw, os.path.join(ROOT, "demos", "cases"))


def test_example_cylinder_and_half_cylinder_cases():
    """cylinder.toml / half_cylinder.toml give the builder's systems (the [loads.dirichlet] table
    is the builder's indentation); the pairing and the gap they report are the circle's."""
    import cfcontact

    params = dict(radius=1.0, width=3.0, depth=1.5, zone=0.3, friction=0.3, indentation=(0.0, 0.04),
                  **SMALL_GEOMETRY["cylinder"])
    for name, half in (("cylinder", False), ("half_cylinder", True)):
        system = case.build_system(_example(name, **SMALL_GEOMETRY[name]))
        ref = cfcontact.cylinder_on_block(**params, half=half)
        info = system.info["contact"]
        assert (info["pairing"], info["slave"], info["excluded"]) == ("segment", "contact2=20", 0)
        assert info["pairs"] == system.m == ref.m and np.array_equal(system.gap, ref.gap)
        x = system.geometry.contact_points[:, 0]
        assert info["gap_range"] == [0.0, pytest.approx(1.0 - np.sqrt(1.0 - 0.3 ** 2), abs=0.05 ** 2 / 8)]
        assert np.all(system.gap >= 1.0 - np.sqrt(1.0 - x ** 2) - 1e-14)
        for a, b in zip(system.loads_numpy(), ref.loads_numpy()):
            assert np.array_equal(a, b)
        assert np.abs(system.loads_numpy()[1]).max() > 0  # the indentation lifted into f2
        assert system.no_tangent.sum() == (1 if half else 0)
        if half:
            assert system.info["dirichlet"]["sym1=15"] == {"x": [0.0, 0.0]} and x.min() == 0.0


def test_example_punch_case():
    system = case.build_system(_example("punch", **SMALL_GEOMETRY["punch"]))
    x, g = system.geometry.contact_points[:, 0], system.gap
    assert system.info["contact"]["pairing"] == "segment" and system.info["contact"]["excluded"] == 0
    assert np.all(g[np.abs(x) <= 0.5 - 0.15] == 0.0) and np.all(g[np.abs(x) > 0.5 - 0.15 + 1e-9] > 0)
    assert system.info["dirichlet"]["top1=12"] == {"x": [0.0, 0.0], "y": [0.0, -0.01]}


def test_example_nonmatching_case():
    system = case.build_system(_example("nonmatching"))
    info = system.info["contact"]
    assert (info["pairing"], info["slave"], info["pairs"], info["gap_range"]) == ("segment", "contact1=10", 12,
                                                                                 [0.0, 0.0])
    assert info["dropped_prescribed"] == 1  # the clamped corner node
    masters = system.geometry.contact_nodes[:, 1]
    assert np.all(masters >= 0)
    raw = tomllib.loads('[geometry]\nkind = "two_blocks"\nnx = 12\nny = 4\nnx2 = 17\n')
    with pytest.raises(case.CaseError, match=r'^\[contact\] pairing: non-matching contact interface.*pairing = '
                                             r'"segment" in \[contact\]\)$'):
        case.build_system(case.validate_case(raw))
    # a friction list of the wrong length is known once the mesh is paired: the error names the key
    raw = tomllib.loads('[geometry]\nkind = "two_blocks"\nnx = 4\nny = 2\n[contact]\nfriction = [0.1, 0.2]\n')
    with pytest.raises(case.CaseError, match=r"^\[contact\] friction: .*one value per contact node \(shape \(4,\)\)"):
        case.build_system(case.validate_case(raw))


def test_example_obstacle_case():
    """The block on a rigid disc: the gap is each paired node's distance to the circle, nodes
    farther than search_distance are left out (reported, one warning)."""
    from cfcontact.errors import PairingWarning

    with pytest.warns(PairingWarning, match="left out"):
        system = case.build_system(_example("obstacle", **SMALL_GEOMETRY["obstacle"]))
    info = system.info["contact"]
    assert info["obstacle"] == {"kind": "circle", "center": [1.0, -1.0001], "radius": 1.0}
    assert info["excluded"] > 0 and info["excluded_reasons"] == {"distance": info["excluded"]}
    assert info["pairs"] + info["excluded"] == 21 and info["search_distance"] == 0.2
    x = system.geometry.contact_points[:, 0]
    assert np.allclose(system.gap, np.hypot(x - 1.0, 1.0001) - 1.0, rtol=0, atol=1e-12)
    assert info["gap_range"][0] == pytest.approx(1e-4) and info["gap_range"][1] <= 0.2
    assert system.geometry.obstacle == info["obstacle"] and np.all(system.geometry.contact_nodes[:, 1] == -1)


def test_non_matching_msh_case(tmp_path):
    """A user's .msh whose contact boundaries do not match: refused with node pairing (naming the
    key), accepted with pairing = "segment"; the builder's system."""
    import cfcontact
    from cfcontact.meshes import common, cylinder_on_block

    params = cylinder_on_block.check_parameters(width=3.0, depth=1.5, size=0.05, size_far=0.5)
    common.write_msh(str(tmp_path / "cyl.msh"), "cylinder_on_block", cylinder_on_block.build, **params)
    text = ('[geometry]\nkind = "msh"\nfile = "cyl.msh"\n[material]\nE = 1.0\n[loads]\nclamp = ["bottom2"]\n'
            '[loads.f1]\n[loads.f2]\n[loads.dirichlet]\ntop1 = {x = 0.0, y = [0.0, -0.03]}\n')
    with pytest.raises(case.CaseError, match=r"^\[contact\] pairing: non-matching"):
        case.build_system(case.validate_case(tomllib.loads(text), str(tmp_path)))
    text += '[contact]\npairing = "segment"\nslave = 20\n'
    system = case.build_system(case.validate_case(tomllib.loads(text), str(tmp_path)))
    ref = cfcontact.cylinder_on_block(width=3.0, depth=1.5, size=0.05, size_far=0.5, E=1.0, indentation=(0.0, 0.03))
    assert system.info["contact"]["slave"] == "contact2=20" and system.m == ref.m
    assert np.allclose(system.gap, ref.gap, rtol=0, atol=1e-14)


MSH_SCRIPT = """
import sys, gmsh
gmsh.initialize(); gmsh.option.setNumber("General.Terminal", 0); gmsh.model.add("m")
occ = gmsh.model.occ
r1, r2 = occ.addRectangle(0, 0, 0, 3, 1), occ.addRectangle(0, -1, 0, 3, 1)
occ.synchronize()
if sys.argv[2] in ("unnamed", "swapped"):  # the tag convention's numbers, no names / bodies' names swapped
    gmsh.model.addPhysicalGroup(2, [r1], 1); gmsh.model.addPhysicalGroup(2, [r2], 2)
    for body, r, tags in ((1, r1, (10, 12, 14)), (2, r2, (20, 22))):
        curves = [c for _, c in gmsh.model.getBoundary([(2, r)], oriented=False)]
        for tag, c in zip(tags, curves):
            gmsh.model.addPhysicalGroup(1, [c], tag)
    if sys.argv[2] == "swapped":
        for (dim, num), name in {(2, 1): "body2", (2, 2): "body1", (1, 10): "contact1", (1, 20): "contact2",
                                 (1, 12): "top1", (1, 14): "left1", (1, 22): "bottom2"}.items():
            gmsh.model.setPhysicalName(dim, num, name)
if sys.argv[2] == "3d":
    box = occ.addBox(5, 0, 0, 1, 1, 1)
    occ.synchronize()
    gmsh.model.addPhysicalGroup(3, [box], 1); gmsh.model.setPhysicalName(3, 1, "body1")
gmsh.option.setNumber("Mesh.MeshSizeMax", 0.5)
gmsh.model.mesh.generate(3 if sys.argv[2] == "3d" else 2)
gmsh.write(sys.argv[1]); gmsh.finalize()
"""


@pytest.mark.parametrize("how,words", [
    ("unnamed", ["[geometry] file", "physical groups without names", "10 (1-D)", "1 (2-D)", "none is named",
                 "body1=1", "contact1=10", "Tag convention"]),
    ("none", ["[geometry] file", "has no physical groups", "body1=1", "contact1=10"]),
    ("swapped", ["[geometry] file", "physical group 1 (2-D) is named 'body2'", "tag convention has body2=2"]),
    ("3d", ["[geometry] file", "the mesh is 3-D (3-D physical groups: body1=1)", "2-D mesh"]),
])
def test_msh_without_named_physical_groups(tmp_path, how, words):
    """A .msh whose groups are numbered but unnamed, that has no physical groups at all, whose
    bodies' names are swapped against their numbers, or that is 3-D: one message about the file
    (not an unknown clamp tag, nor a slave the case never set)."""
    msh = tmp_path / "m.msh"
    subprocess.run([sys.executable, "-c", MSH_SCRIPT, str(msh), how], check=True, timeout=120)
    text = ('[geometry]\nkind = "msh"\nfile = "m.msh"\n[loads]\nclamp = [14, 22]\n[loads.f1]\n12 = [0.0, -1e8]\n'
            '[loads.f2]\n12 = [1e8, -1e7]\n')
    with pytest.raises(case.CaseError) as info:
        case.validate_case(tomllib.loads(text), str(tmp_path))
    msg = str(info.value)
    assert "slave" not in msg and "clamp" not in msg, msg
    for w in words:
        assert w in msg, (w, msg)


def test_an_empty_obstacle_table_says_kind_is_missing_and_alpha_end_of_a_friction_path_warns():
    with pytest.raises(case.CaseError) as info:
        case.validate_case(tomllib.loads('[geometry]\nkind = "block_on_foundation"\n[contact.obstacle]\n'))
    assert str(info.value).startswith("[contact.obstacle] kind is missing") and "None" not in str(info.value)
    raw = tomllib.loads('[geometry]\nkind = "two_blocks"\n[contact]\nfriction = 1.0\n[path]\nparameter = "friction"\n'
                        'method = "exact"\nalpha_end = 0.5\ntree = true\n')
    assert case.validate_case(raw)["_warnings"] == [
        f'[path] {k}: used by paths over alpha only; ignored with parameter = "friction"' for k in ("alpha_end", "tree")]


def test_too_large_prescribed_displacements_name_loads_dirichlet():
    """Prescribed displacements whose loads K u_D overflow are named as such ([loads.dirichlet]),
    not taken for too large tractions or body forces."""
    raw = _example("cylinder", **SMALL_GEOMETRY["cylinder"])
    raw["loads"]["dirichlet"]["top1"] = {"x": 0.0, "y": [0.0, -1e200]}
    with pytest.raises(case.CaseError) as info:
        case.build_system(raw)
    msg = str(info.value)
    assert msg.startswith("[loads.dirichlet]: the prescribed displacements") and "too large" in msg, msg
    assert "tractions" not in msg and "\n" not in msg


BAD_CONTACT = [
    ('[contact]\npairing = "edge"\n', ['[contact] pairing', '"node" or "segment"', "edge"]),
    ('[contact]\npairing = "segment"\nsearch_distance = 0.0\n', ["[contact] search_distance", "> 0", "0.0"]),
    ('[contact]\npairing = "segment"\nslave = "top1"\n', ["[contact] slave", "contact boundary", "contact2=20",
                                                           "top1=12"]),
    ('[contact]\npairing = "segment"\nslave = "roof"\n', ["[contact] slave", "roof", "contact1=10"]),
    ('[contact]\nslave = "contact2"\n', ["[contact] slave", 'pairing = "segment"']),
    ('[contact]\nsearch_distance = 0.1\n', ["[contact] search_distance", 'pairing = "segment"']),
    ('[contact.obstacle]\nkind = "circle"\ncenter = [1.5, -2]\nradius = 1.0\n',
     ["[contact.obstacle]", "body 2", "block_on_foundation"]),
    ('[loads.dirichlet]\ntop1 = {z = 0.0}\n', ["[loads.dirichlet] top1", "'z'", "x, y"]),
    ('[loads.dirichlet]\nroof = {x = 0.0}\n', ["[loads.dirichlet]", "roof", "top1=12"]),
    ('[loads.dirichlet]\ntop1 = {y = [0.0, -1.0, 2.0]}\n', ["[loads.dirichlet] top1.y", "value at alpha = 0"]),
]


@pytest.mark.parametrize("text,words", BAD_CONTACT, ids=[b[0].split("\n")[1] for b in BAD_CONTACT])
def test_bad_contact_and_dirichlet_keys_name_the_key(text, words):
    with pytest.raises(case.CaseError) as info:
        case.validate_case(tomllib.loads('[geometry]\nkind = "two_blocks"\n' + text))
    msg = str(info.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg, (w, msg)


@pytest.mark.parametrize("text,words", [
    ('[geometry]\nkind = "block_on_foundation"\n[contact]\npairing = "segment"\n',
     ["[contact] pairing", "needs a master"]),
    ('[geometry]\nkind = "block_on_foundation"\n[contact.obstacle]\nkind = "plane"\n',
     ["[contact.obstacle] kind", "line", "circle", "plane"]),
    ('[geometry]\nkind = "block_on_foundation"\n[contact.obstacle]\nkind = "line"\npoint = [0, 0]\nnormal = [0, 0]\n',
     ["[contact.obstacle] normal", "zero"]),
    ('[geometry]\nkind = "block_on_foundation"\n[contact.obstacle]\nkind = "circle"\ncenter = [0, -1]\n',
     ["[contact.obstacle] radius is missing"]),
    ('[geometry]\nkind = "block_on_foundation"\n[contact]\nslave = "contact1"\npairing = "segment"\n'
     '[contact.obstacle]\nkind = "circle"\ncenter = [0, -1]\nradius = 0.5\nscale = 2\n',
     ["unknown key 'scale' in [contact.obstacle]", "center, radius, inside"]),
    ('[geometry]\nkind = "block_on_foundation"\n[contact.obstacle]\nkind = "circle"\ncenter = [0, -1]\nradius = 0.5\n'
     'inside = "yes"\n', ["[contact.obstacle] inside", "'yes'"]),
    ('[geometry]\nkind = "block_on_foundation"\n[contact]\nslave = "contact2"\n[contact.obstacle]\nkind = "line"\n'
     'point = [0, -0.1]\nnormal = [0, 1]\n', ["[contact] slave", "(contact1=10)", "'contact2'", "master of contact1"]),
    ('[geometry]\nkind = "block_on_foundation"\nnx2 = 3\n', ["[geometry] nx2", "no body 2"]),
    ('[geometry]\nkind = "cylinder"\nhalf = true\n[loads.dirichlet]\ntop1 = {y = [0.0, -0.01]}\nsym1 = {x = 0.0}\n',
     ["[loads.dirichlet]", "half model", "sym2 = {x = 0.0}"]),
    ('[geometry]\nkind = "cylinder"\n[loads]\nclamp = ["sym1"]\n', ["[loads] clamp", "sym1", "top2=21"]),
    ('[geometry]\nkind = "cylinder"\nzone = 0.9\n', ["[geometry] zone", "0.76"]),
    ('[geometry]\nkind = "punch"\nedge_radius = 0.6\n', ["[geometry] edge_radius", "half_width"]),
])
def test_bad_geometry_contact_combinations(text, words):
    with pytest.raises(case.CaseError) as info:
        case.validate_case(tomllib.loads(text))
    for w in words:
        assert w in str(info.value), (w, str(info.value))
