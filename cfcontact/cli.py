"""Command line of cfcontact: ``cfcontact SUBCOMMAND ...`` (also ``python -m cfcontact``).

Subcommands
-----------
``run CASE.toml``
    Validate a case file completely, build the model, trace the solution path and write
    the results into an output folder (default ``<case stem>_out/`` next to the case file):
    ``path/`` (:meth:`SolutionPath.save`), ``summary.json``, ``case.toml`` (a copy),
    ``path.png`` and ``multiplicity.png`` (+ ``.pdf`` if asked), ``panel.png`` (solutions at
    the alpha of largest multiplicity) and ``animation.gif`` if asked.
``plot SAVED``, ``render SAVED``, ``info SAVED``, ``export SAVED -o FILE.xdmf``
    Work on a saved path: ``SAVED`` is a ``path/`` folder, a run's output folder, or a
    stopped run's ``<out>.partial/`` folder (its checkpoint).
``bench``
    Reserved (see :data:`SUBCOMMANDS`).

Output folder, checkpoints and resume
-------------------------------------
A run works in ``<out>.partial/`` and renames it to ``<out>/`` only when everything is
written, so ``<out>/`` is always complete.  While the path is traced (either method), a
checkpoint ``<out>.partial/checkpoint/`` (``path/`` = the partial path, ``state.json`` =
the method's resume state and the physics sections of the case) is written every
``--checkpoint-every`` seconds (default 60) and whenever the run is stopped by Ctrl-C
(first Ctrl-C: stop at the next accepted point; second: abort), ``--time-limit``,
``--stop-after-folds``, ``--stop-after-transitions`` or ``--stop-at-alpha``.
``run --resume CASE.toml`` continues from the checkpoint (seed: the last branch's inactive
sets and orientation, the last alpha and y, the step h, the cycle detector; exact: the
branch being followed -- its sets, orientation and entry alpha -- and the cycle detector)
and appends to the stored path: the result equals an uninterrupted run.  A failing run
removes ``<out>.partial/`` unless it holds a checkpoint.

Exit codes: 0 done (path traced, output written), 1 failure, 2 bad input (one message on
stderr, no output), 3 stopped before the end by a stop condition or the time limit
(resumable checkpoint left), 130 stopped by Ctrl-C (resumable checkpoint left).

Case file (TOML)
----------------
::

    title = "optional free text"

    [geometry]
    kind = "two_blocks"      # | "block_on_foundation" | "inclined" | "arc" | "msh"
    nx = 12                  # cells along the interface      (built-in kinds)
    ny = 4                   # cells across each block        (built-in kinds)
    length = 3.0             # block width                    (block kinds)
    height = 1.0             # block height                   (built-in kinds)
    # height2 = 0.5          # height of body 2 (default: height)
    cell = "quadrilateral"   # | "triangle"                   (built-in kinds)
    angle = 20.0             # degrees, counter-clockwise; required for "inclined"
    # radius = 1.0, half_angle = 30.0, ny2 = 4   # kind = "arc" only (no length, angle)
    # file = "model.msh"     # kind = "msh" only: gmsh file, relative to the case file

    [material]
    E = 2.1e11               # Young's modulus (Pa)
    nu = 0.3                 # Poisson's ratio
    plane = "strain"         # | "stress"

    [contact]
    friction = 0.5           # Coulomb coefficient >= 0 (or a list, one per contact node)
    # rho = 1e11             # augmentation parameter (default: automatic)

    [loads]
    clamp = ["left1", "left2"]          # boundary tags (names or numbers) with u = 0
    # body_force1 = [0.0, -7.8e4]       # or a table [loads.body_force1] body1 = [bx, by]
    [loads.f1]                          # surface tractions of f1: tag = [tx, ty]
    top1 = [2.0e7, -1.0e8]
    [loads.f2]
    top1 = [1.0e8, -2.0e7]

    [path]
    method = "seed"          # | "exact"
    alpha_start = 0.0
    alpha_end = 1.0
    # alpha_min, alpha_max, h_min, h_max, c_p, c_s, h0, max_steps, max_transitions, tol, max_iter

    [output]
    plot = true
    plot_formats = ["png"]   # "png", "pdf"
    # component = ["lam_n", 12]   # or "lam_n:12" or an index of y; default: the most varying lam_n
    # zoom = [0.4, 0.6]           # alpha window (optionally + value range: [a0, a1, v0, v1])
    render_panel = true
    render_animation = false
    animation_format = "gif"     # | "mp4" | "frames"
    animation_frames = 60
    # magnification = 50.0
    # window_size = [1200, 600]
    # stress = false             # colour panel.png (and the animation) by the von Mises stress
    # xdmf = false               # solutions.xdmf for ParaView (the panel's solutions)

Every section and key is optional except ``[geometry] kind`` (and ``file`` for "msh",
``angle`` for "inclined", ``[loads] clamp`` / ``[loads.f1]`` / ``[loads.f2]`` for "msh").
Built-in kinds default to the library's loads (:data:`cfcontact.models.DEFAULT_TRACTIONS1`
and ``2``) and clamps (``left1``, ``left2``; ``left1`` on a foundation); their load vectors
are given in the frame of the unrotated blocks.  Kind "arc" (:func:`cfcontact.models.arc_on_block`:
a body with a convex circular-arc bottom in a matching seat, conforming) clamps ``left1`` and
``bottom2`` by default.  Tags follow DESIGN.md: built-in kinds have ``contact1, top1, right1,
left1`` (+ ``contact2, bottom2, right2, left2`` with body 2).
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import logging
import math
import os
import shutil
import signal
import sys
import threading
import time
import traceback

from cfcontact.errors import CfcontactError, InputError

try:  # Python >= 3.11
    import tomllib
except ModuleNotFoundError:  # pragma: no cover - Python 3.9 / 3.10
    import tomli as tomllib

log = logging.getLogger("cfcontact.cli")

EXIT_OK, EXIT_FAILURE, EXIT_INPUT, EXIT_STOPPED, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
RUN_FORMAT, CHECKPOINT_FORMAT = "cfcontact-run", "cfcontact-checkpoint"
DEFAULT_CHECKPOINT_EVERY = 60.0


class CaseError(InputError):
    """A bad case file or command line argument (exit code 2)."""


class _Stopped(Exception):
    """The run was stopped before its end; a checkpoint was written."""

    def __init__(self, reason, code, resumable=True):
        super().__init__(reason)
        self.reason, self.code, self.resumable = reason, code, resumable


# ============================================================ case schema
GEOMETRY_KINDS = ("two_blocks", "block_on_foundation", "inclined", "arc", "msh")
METHODS = ("seed", "exact")
COMPONENT_NAMES = ("u", "lam_n", "lam_t")

# key -> (type, default).  Types: int, float, str, bool, and the composite ones checked below.
_BUILTIN_GEOMETRY = {"kind": ("str", None), "nx": ("int", None), "ny": ("int", None), "length": ("float", None),
                     "height": ("float", None), "height2": ("float", None), "cell": ("str", None),
                     "angle": ("float", None)}
_ARC_GEOMETRY = {"kind": ("str", None), "radius": ("float", None), "half_angle": ("float", None),
                 "height": ("float", None), "height2": ("float", None), "nx": ("int", None), "ny": ("int", None),
                 "ny2": ("int", None), "cell": ("str", None)}
SCHEMA = {
    "geometry": None,  # depends on kind: see _geometry_keys
    "material": {"E": ("material", None), "nu": ("material", None), "plane": ("str", None)},
    "contact": {"friction": ("friction", 0.0), "rho": ("float", None)},
    "loads": {"clamp": ("tags", None), "f1": ("tractions", None), "f2": ("tractions", None),
              "body_force1": ("body_force", None), "body_force2": ("body_force", None)},
    "path": {"method": ("str", "seed"), "backend": ("str", "auto"), "alpha_start": ("float", 0.0), "alpha_end": ("float", 1.0),
             "alpha_min": ("float", None), "alpha_max": ("float", None), "h_min": ("float", None),
             "h_max": ("float", None), "c_p": ("float", None), "c_s": ("float", None), "h0": ("float", None),
             "max_steps": ("int", None), "max_transitions": ("int", None), "tol": ("float", None),
             "max_iter": ("int", None)},
    "output": {"plot": ("bool", True), "plot_formats": ("formats", ["png"]), "component": ("component", None),
               "zoom": ("zoom", None), "render_panel": ("bool", True), "render_animation": ("bool", False),
               "animation_format": ("str", "gif"), "animation_frames": ("int", 60),
               "magnification": ("float", None), "window_size": ("window", None), "stress": ("bool", False),
               "xdmf": ("bool", False)},
}
TOP_LEVEL = ("title", *SCHEMA)
PHYSICS_SECTIONS = ("geometry", "material", "contact", "loads", "path")
_TYPE_NAMES = {"int": "an integer", "float": "a number", "str": "a string", "bool": "a boolean (true/false)",
               "tags": "a list of tags (names or numbers)", "tractions": "a table {tag = [tx, ty] or windowed tractions}",
               "body_force": "[bx, by] or a table {body = [bx, by]}", "formats": 'a list of "png"/"pdf"',
               "component": '["lam_n", i], "lam_n:i" or an integer', "zoom": "[alpha_lo, alpha_hi] (+ [v_lo, v_hi])",
               "window": "[width, height] in pixels", "friction": "a number >= 0 or a list of them",
               "material": "a number or a table {body = number}"}


def _geometry_keys(kind):
    if kind == "msh":
        return {"kind": ("str", None), "file": ("str", None)}
    if kind == "arc":
        return dict(_ARC_GEOMETRY)
    return dict(_BUILTIN_GEOMETRY)


def _tname(value):
    return {bool: "boolean", int: "integer", float: "float", str: "string", list: "array",
            dict: "table"}.get(type(value), type(value).__name__)


def _is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _vec2(value, where):
    if not (isinstance(value, list) and len(value) == 2 and all(_is_number(x) for x in value)):
        raise CaseError(f"{where}: expected [x, y] (two numbers), got {_tname(value)} {value!r}")
    if not all(math.isfinite(x) for x in value):
        raise CaseError(f"{where}: expected finite numbers, got {value!r}")
    return [float(x) for x in value]


_PATCH_FORM = "{value = [tx, ty], x = [x0, x1]} (and/or y = [y0, y1])"


def _traction(value, where):
    """[tx, ty] (the whole piece), a windowed traction {value, x, y}, or a list of these."""
    if isinstance(value, dict):
        unknown = sorted(set(value) - {"value", "x", "y"})
        if unknown or "value" not in value or not ({"x", "y"} & set(value)):
            raise CaseError(f"{where}: a windowed traction is {_PATCH_FORM}, got keys {sorted(value)}")
        out = {"value": _vec2(value["value"], f"{where}.value")}
        for key in ("x", "y"):
            if key in value:
                lo, hi = _vec2(value[key], f"{where}.{key}")
                if not lo < hi:
                    raise CaseError(f"{where}.{key}: expected an interval [lo, hi] with lo < hi, got {value[key]!r}")
                out[key] = [lo, hi]
        return out
    if isinstance(value, list) and value and all(isinstance(v, (dict, list)) for v in value):
        return [_traction(v, f"{where}[{k}]") for k, v in enumerate(value)]
    return _vec2(value, where)


def _check_value(typ, value, where):
    """Normalised value or CaseError naming ``where`` (e.g. "[contact] friction"), the expected type and the got."""
    expected = _TYPE_NAMES[typ]
    bad = CaseError(f"{where}: expected {expected}, got {_tname(value)} {value!r}")
    if typ == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise bad
        return value
    if typ == "float":
        if not _is_number(value):
            raise bad
        if not math.isfinite(value):
            raise CaseError(f"{where}: expected a finite number, got {value!r}")
        return float(value)
    if typ == "str":
        if not isinstance(value, str):
            raise bad
        return value
    if typ == "bool":
        if not isinstance(value, bool):
            raise bad
        return value
    if typ == "tags":
        if isinstance(value, (str, int)) and not isinstance(value, bool):
            value = [value]
        if not isinstance(value, list) or not all(isinstance(t, (str, int)) and not isinstance(t, bool) for t in value):
            raise bad
        return list(value)
    if typ == "material":
        if isinstance(value, dict):
            if not value:
                raise bad
            return {k: _check_value("float", v, f"{where}.{k}") for k, v in value.items()}
        return _check_value("float", value, where)
    if typ == "tractions":
        if not isinstance(value, dict):
            raise bad
        return {k: _traction(v, f"{where}.{k}") for k, v in value.items()}
    if typ == "body_force":
        if isinstance(value, dict):
            return {k: _vec2(v, f"{where}.{k}") for k, v in value.items()}
        if isinstance(value, list):
            return _vec2(value, where)
        raise bad
    if typ == "formats":
        if not isinstance(value, list) or not all(isinstance(f, str) for f in value):
            raise bad
        fmts = [f.lower().lstrip(".") for f in value]
        unknown = [f for f, g in zip(value, fmts) if g not in ("png", "pdf")]
        if unknown:
            raise CaseError(f"{where}: unknown format(s) {unknown}; valid: \"png\", \"pdf\"")
        return fmts
    if typ == "component":
        return _parse_component(value, where)
    if typ == "zoom":
        if not (isinstance(value, list) and len(value) in (2, 4) and all(_is_number(x) for x in value)):
            raise bad
        if not value[0] < value[1] or (len(value) == 4 and not value[2] < value[3]):
            raise CaseError(f"{where}: need alpha_lo < alpha_hi (and v_lo < v_hi), got {value!r}")
        return [float(x) for x in value]
    if typ == "window":
        if not (isinstance(value, list) and len(value) == 2 and all(isinstance(x, int) and not isinstance(x, bool)
                                                                   for x in value)):
            raise bad
        if min(value) < 16 or max(value) > 10000:
            raise CaseError(f"{where}: width and height must be 16..10000 pixels, got {value!r}")
        return list(value)
    if typ == "friction":
        if _is_number(value):
            vals = [value]
        elif isinstance(value, list) and value and all(_is_number(x) for x in value):
            vals = value
        else:
            raise bad
        if not all(math.isfinite(x) and x >= 0 for x in vals):
            raise CaseError(f"{where}: the friction coefficient must be >= 0 (and finite), got {value!r}")
        return float(value) if _is_number(value) else [float(x) for x in value]
    raise AssertionError(typ)


def _parse_component(value, where):
    """("lam_n", 12) / "lam_n:12" / 57 -> ("lam_n", 12) or 57."""
    if isinstance(value, int) and not isinstance(value, bool):
        if value < 0:
            raise CaseError(f"{where}: an index of y must be >= 0, got {value}")
        return value
    if isinstance(value, str):
        name, sep, idx = value.partition(":")
        if not sep:
            try:
                return _parse_component(int(value), where)
            except ValueError:
                pass
        try:
            value = [name.strip(), int(idx)]
        except ValueError:
            raise CaseError(f"{where}: expected \"NAME:INDEX\" (NAME one of {', '.join(COMPONENT_NAMES)}) or an "
                            f"integer, got {value!r}") from None
    if not (isinstance(value, list) and len(value) == 2 and isinstance(value[0], str)
            and isinstance(value[1], int) and not isinstance(value[1], bool)):
        raise CaseError(f"{where}: expected {_TYPE_NAMES['component']}, got {_tname(value)} {value!r}")
    if value[0] not in COMPONENT_NAMES:
        raise CaseError(f"{where}: unknown component {value[0]!r}; valid: {', '.join(COMPONENT_NAMES)}")
    if value[1] < 0:
        raise CaseError(f"{where}: the index must be >= 0, got {value[1]}")
    return (value[0], value[1])


def _check_section(name, table, keys, label=None):
    label = label or f"[{name}]"
    if not isinstance(table, dict):
        raise CaseError(f"{label}: expected a table, got {_tname(table)} {table!r}")
    unknown = sorted(set(table) - set(keys))
    if unknown:
        raise CaseError(f"unknown key {unknown[0]!r} in {label}; valid keys: {', '.join(keys)}")
    out = {}
    for key, (typ, default) in keys.items():
        if key in table:
            out[key] = _check_value(typ, table[key], f"{label} {key}")
        elif default is not None:
            out[key] = default
    return out


def _file_sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def validate_case(raw: dict, base_dir: str = ".") -> dict:
    """Check a parsed case file completely; returns the normalised case (CaseError on the first problem).

    Tags are checked against the model's physical groups (built-in kinds: the two-block
    script's groups; "msh": the groups read from the file).
    """
    if not isinstance(raw, dict):
        raise CaseError("the case file must be a TOML table")
    unknown = sorted(set(raw) - set(TOP_LEVEL))
    if unknown:
        raise CaseError(f"unknown section or key {unknown[0]!r} at the top level; valid: {', '.join(TOP_LEVEL)}")
    case = {}
    if "title" in raw:
        case["title"] = _check_value("str", raw["title"], "title")

    # ---- geometry
    geo = raw.get("geometry")
    if geo is None:
        raise CaseError(f"missing section [geometry] (with kind = one of {', '.join(map(repr, GEOMETRY_KINDS))})")
    if not isinstance(geo, dict):
        raise CaseError(f"[geometry]: expected a table, got {_tname(geo)} {geo!r}")
    if "kind" not in geo:
        raise CaseError(f"[geometry] kind is missing; valid kinds: {', '.join(map(repr, GEOMETRY_KINDS))}")
    kind = _check_value("str", geo["kind"], "[geometry] kind")
    if kind not in GEOMETRY_KINDS:
        raise CaseError(f"[geometry] kind: unknown geometry kind {kind!r}; valid kinds: "
                        f"{', '.join(map(repr, GEOMETRY_KINDS))}")
    keys = _geometry_keys(kind)
    geometry = _check_section("geometry", geo, keys, f"[geometry] (kind = {kind!r})")
    if kind == "msh":
        if "file" not in geometry:
            raise CaseError("[geometry] file is missing: kind = 'msh' needs file = \"model.msh\" "
                            "(relative to the case file)")
        geometry["file"] = os.path.normpath(os.path.join(base_dir, geometry["file"]))
        if not os.path.isfile(geometry["file"]):
            raise CaseError(f"[geometry] file: no such mesh file {geometry['file']!r}")
        geometry["sha256"] = _file_sha256(geometry["file"])
    else:
        if kind == "inclined" and "angle" not in geometry:
            raise CaseError("[geometry] angle is missing: kind = 'inclined' needs the angle in degrees")
        from cfcontact.meshes import arc_on_block, two_blocks

        try:
            script = arc_on_block if kind == "arc" else two_blocks
            script.check_parameters(**{k: v for k, v in geometry.items() if k != "kind"})
        except (InputError, ValueError) as exc:
            raise CaseError(f"[geometry] {exc}") from None
    case["geometry"] = geometry

    # ---- material
    material = _check_section("material", raw.get("material", {}), SCHEMA["material"])
    if "plane" in material and material["plane"] not in ("strain", "stress"):
        raise CaseError(f"[material] plane: expected \"strain\" or \"stress\", got {material['plane']!r}")
    for key, ok, rule in (("E", lambda v: v > 0, "Young's modulus must be > 0"),
                          ("nu", lambda v: -1.0 < v < 0.5, "Poisson's ratio must lie in (-1, 0.5)")):
        for body, v in (material[key].items() if isinstance(material.get(key), dict) else [(None, material.get(key))]):
            if v is not None and not ok(v):
                raise CaseError(f"[material] {key}{'' if body is None else '.' + body}: {rule}, got {v!r}")
    case["material"] = material

    # ---- contact
    contact = _check_section("contact", raw.get("contact", {}), SCHEMA["contact"])
    if "rho" in contact and not contact["rho"] > 0:
        raise CaseError(f"[contact] rho: must be > 0, got {contact['rho']!r}")
    case["contact"] = contact

    # ---- loads (tags are checked against the model's groups)
    loads = _check_section("loads", raw.get("loads", {}), SCHEMA["loads"])
    if kind == "msh":
        for key in ("clamp", "f1", "f2"):
            if key not in loads:
                what = "clamp = [tags]" if key == "clamp" else f"a table [loads.{key}] (may be empty)"
                raise CaseError(f"[loads] {key} is missing: kind = 'msh' needs {what}")
    groups = _model_groups(kind, geometry)
    for key in ("clamp", "f1", "f2", "body_force1", "body_force2"):
        if key not in loads:
            continue
        val = loads[key]
        label = f"[loads] {key}" if key in ("clamp",) or not isinstance(val, dict) else f"[loads.{key}]"
        if key == "clamp":
            for t in val:
                _check_tag(t, groups, 1, label)
        elif isinstance(val, dict):
            for t in val:
                _check_tag(t, groups, 2 if key.startswith("body") else 1, label)
    for key in ("E", "nu"):  # per-body material: one value for each body of the model
        if isinstance(material.get(key), dict):
            for t in material[key]:
                _check_tag(t, groups, 2, f"[material] {key}")
            named = {_body_number(t, groups) for t in material[key]}
            missing = [name for (dim, num), name in sorted(groups.items()) if dim == 2 and num not in named]
            if missing:
                raise CaseError(f"[material] {key}: no value for body {', '.join(missing)}; give one number "
                                f"per body or a single number")
    case["loads"] = loads

    # ---- path
    path = _check_section("path", raw.get("path", {}), SCHEMA["path"])
    if path["method"] not in METHODS:
        raise CaseError(f"[path] method: unknown method {path['method']!r}; valid: "
                        f"{', '.join(map(repr, METHODS))}")
    from cfcontact.path import BACKENDS

    if path["backend"] not in BACKENDS:
        raise CaseError(f"[path] backend: unknown backend {path['backend']!r}; valid: {', '.join(map(repr, BACKENDS))}")
    a0, a1 = path["alpha_start"], path["alpha_end"]
    if a0 == a1:
        raise CaseError(f"[path] alpha_start = alpha_end = {a0}: the alpha range is empty")
    lo = path.get("alpha_min", min(a0, a1))
    hi = path.get("alpha_max", max(a0, a1))
    if not lo < hi:
        raise CaseError(f"[path] alpha_min, alpha_max: the alpha range [{lo}, {hi}] is empty")
    if not lo <= a0 <= hi:
        raise CaseError(f"[path] alpha_start = {a0} lies outside [alpha_min, alpha_max] = [{lo}, {hi}]")
    from cfcontact.path import PathOptions

    try:
        PathOptions(**{k: v for k, v in path.items() if k in PathOptions.names()})
    except InputError as exc:
        raise CaseError(f"[path] {exc}") from None
    case["path"] = path

    # ---- output
    output = _check_section("output", raw.get("output", {}), SCHEMA["output"])
    if output["animation_format"] not in ("gif", "mp4", "frames"):
        raise CaseError(f"[output] animation_format: expected \"gif\", \"mp4\" or \"frames\", "
                        f"got {output['animation_format']!r}")
    if output["animation_frames"] < 1:
        raise CaseError(f"[output] animation_frames: must be >= 1, got {output['animation_frames']}")
    if "magnification" in output and not output["magnification"] > 0:
        raise CaseError(f"[output] magnification: must be > 0, got {output['magnification']!r}")
    case["output"] = output
    return case


def _model_groups(kind, geometry) -> dict:
    """{(dim, number): name} of the physical groups of the case's model."""
    if kind != "msh":
        from cfcontact.meshes import arc_on_block, two_blocks

        tags = (arc_on_block if kind == "arc" else two_blocks).TAGS
        foundation = kind == "block_on_foundation"
        return {(d, n): name for name, (d, n) in tags.items() if not (foundation and (n == 2 or 20 <= n < 30))}
    import gmsh

    from cfcontact import compat

    with compat.gmsh_model("cfcontact-cli-probe") as model:
        try:
            gmsh.merge(geometry["file"])
        except Exception as exc:
            raise CaseError(f"[geometry] file: gmsh cannot read {geometry['file']!r}: {exc}") from None
        return {(int(d), int(n)): model.getPhysicalName(d, n) for d, n in model.getPhysicalGroups()}


def _check_tag(tag, groups, dim, label):
    names = {name for (d, _), name in groups.items() if d == dim and name}
    numbers = {n for (d, n) in groups if d == dim}
    if (isinstance(tag, str) and tag in names) or (isinstance(tag, int) and tag in numbers):
        return
    if isinstance(tag, str) and tag.isdigit() and int(tag) in numbers:  # TOML table keys are strings
        return
    kind = "boundary tag (1-D physical group)" if dim == 1 else "body tag (2-D physical group)"
    valid = ", ".join(f"{name}={n}" if name else str(n) for (d, n), name in sorted(groups.items()) if d == dim)
    raise CaseError(f"{label}: unknown {kind} {tag!r}; valid: {valid or '(none)'}")


def _body_number(tag, groups):
    """The number of a (checked) body tag: a name, a number or a digit string."""
    if isinstance(tag, str) and not tag.isdigit():
        return next(n for (d, n), name in groups.items() if d == 2 and name == tag)
    return int(tag)


def load_case(filename) -> dict:
    """Read and validate a TOML case file; returns the normalised case with its text and location."""
    filename = os.fspath(filename)
    if not os.path.isfile(filename):
        raise CaseError(f"no such case file: {filename!r}")
    with open(filename, "rb") as fh:
        data = fh.read()
    try:
        raw = tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise CaseError(f"{filename}: not UTF-8 text ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise CaseError(f"{filename}: invalid TOML: {exc}") from None
    case = validate_case(raw, os.path.dirname(os.path.abspath(filename)))
    case["_file"] = os.path.abspath(filename)
    case["_text"] = data.decode("utf-8")
    return case


def _physics(case) -> dict:
    """The sections that determine the path (a resumed run must have the same)."""
    return json.loads(json.dumps({k: case.get(k) for k in PHYSICS_SECTIONS}))


# ============================================================ model building
def build_system(case):
    """The ContactSystem of a validated case (imports the FEM layer)."""
    geo, mat, con, loads = case["geometry"], case["material"], case["contact"], case["loads"]
    common = {k: ({_tag_value(t): x for t, x in v.items()} if isinstance(v, dict) else v) for k, v in mat.items()}
    common["friction"] = con["friction"]
    if "rho" in con:
        common["rho"] = con["rho"]
    if "clamp" in loads:
        common["clamp"] = [_tag_value(t) for t in loads["clamp"]]
    for key, arg in (("f1", "tractions1"), ("f2", "tractions2")):
        if key in loads:
            common[arg] = {_tag_value(t): v for t, v in loads[key].items()}
    for key in ("body_force1", "body_force2"):
        if key in loads:
            v = loads[key]
            common[key] = {_tag_value(t): w for t, w in v.items()} if isinstance(v, dict) else v
    if geo["kind"] == "msh":
        from cfcontact.assembly import assemble_contact_system

        return assemble_contact_system(geo["file"], info={"model": "msh", "file": geo["file"]}, **common)
    from cfcontact.models import arc_on_block, two_blocks

    params = {k: v for k, v in geo.items() if k != "kind"}
    if geo["kind"] == "arc":
        return arc_on_block(**params, **common)
    return two_blocks(foundation=geo["kind"] == "block_on_foundation", **params, **common)


def _tag_value(tag):
    return int(tag) if isinstance(tag, str) and tag.isdigit() else tag


# ============================================================ progress / logging
class _Progress:
    """A throttled one-line progress display on stderr (TTY: rewritten in place)."""

    def __init__(self, enabled, tty, interval=0.2):
        self.enabled, self.tty = enabled, tty
        self.interval = interval if tty else 1.0
        self.last = -1e9
        self.shown = False

    def update(self, text, force=False):
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self.last < self.interval:
            return
        self.last = now
        if self.tty:
            sys.stderr.write("\r\x1b[2K" + text)
            self.shown = True
        else:
            sys.stderr.write(text + "\n")
        sys.stderr.flush()

    def clear(self):
        if self.shown:
            sys.stderr.write("\r\x1b[2K")
            sys.stderr.flush()
            self.shown = False

    def done(self):
        if self.shown:
            sys.stderr.write("\n")
            sys.stderr.flush()
            self.shown = False


class _ProgressAwareHandler(logging.StreamHandler):
    """Log records on stderr that first clear the progress line."""

    progress = None

    def emit(self, record):
        if self.progress is not None:
            self.progress.clear()
        super().emit(record)


@contextlib.contextmanager
def _logging(level):
    """Configure the ``cfcontact`` logger for one command (the library itself only logs)."""
    logger = logging.getLogger("cfcontact")
    handler = _ProgressAwareHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    old_level, old_prop = logger.level, logger.propagate
    logger.addHandler(handler)
    logger.setLevel(level)
    logger.propagate = False
    try:
        yield handler
    finally:
        logger.removeHandler(handler)
        logger.setLevel(old_level)
        logger.propagate = old_prop


def _say(args, *text):
    if not getattr(args, "quiet", False):
        print(*text, flush=True)


def _warn(args, text):
    if not getattr(args, "quiet", False):
        print(f"cfcontact: warning: {text}", file=sys.stderr, flush=True)


# ============================================================ run: stop conditions
class _Runner:
    """The PathOptions callback of ``run``: progress line, stop conditions, checkpoint timing."""

    def __init__(self, args, solver, progress, t_start, resumed_path=None):
        self.args, self.solver, self.progress, self.t_start = args, solver, progress, t_start
        self.interrupted = False
        self.reason = None
        self.solves0 = solver.stats.linear_solves
        self.solves_before = int(resumed_path.stats.get("linear_solves", 0)) if resumed_path is not None else 0
        # counts already reached when (re)starting: a condition already met is not triggered again
        self.folds0 = len(resumed_path.folds) if resumed_path is not None else 0
        self.trans0 = len(resumed_path.transitions) if resumed_path is not None else 0
        self.prev_alpha = float(resumed_path.alphas[-1]) if resumed_path is not None else None
        self.last_checkpoint = time.monotonic()
        self.checkpoint_every = args.checkpoint_every
        self.points = 0

    def status_line(self, alpha, branches, transitions, folds):
        solves = self.solves_before + self.solver.stats.linear_solves - self.solves0
        return (f"alpha={alpha:.8g}  branches {branches}  transitions {transitions}  folds {folds}  "
                f"linear solves {solves}  "
                f"{time.monotonic() - self.t_start:.1f} s")

    def on_point(self, pt):
        self.points += 1
        path = pt.path  # both methods pass the live path
        folds, transitions, branches = len(path.folds), len(path.transitions), len(path.branches)
        self.progress.update(self.status_line(pt.alpha, branches, transitions, folds))
        args = self.args
        prev, self.prev_alpha = self.prev_alpha, float(pt.alpha)
        if self.interrupted:
            self.reason = "interrupted (Ctrl-C)"
        elif args.time_limit is not None and time.monotonic() - self.t_start >= args.time_limit:
            self.reason = f"time limit of {args.time_limit:g} s reached"
        elif args.stop_after_folds is not None \
                and folds > self.folds0 and folds >= args.stop_after_folds:
            self.reason = f"stopped after {folds} fold(s)"
        elif args.stop_after_transitions is not None and transitions > self.trans0 \
                and transitions >= args.stop_after_transitions:
            self.reason = f"stopped after {transitions} transition(s)"
        elif args.stop_at_alpha is not None and prev is not None \
                and (pt.alpha - args.stop_at_alpha) * (prev - args.stop_at_alpha) <= 0 and pt.alpha != prev:
            self.reason = f"stopped at alpha={pt.alpha:.8g} (reached {args.stop_at_alpha:g})"
        elif self.checkpoint_every and time.monotonic() - self.last_checkpoint >= self.checkpoint_every:
            self.reason = "checkpoint"
        return self.reason is not None


@contextlib.contextmanager
def _sigint(runner, progress):
    """First Ctrl-C: stop cleanly at the next accepted point; second: KeyboardInterrupt."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        if runner.interrupted:
            signal.signal(signal.SIGINT, signal.default_int_handler)
            raise KeyboardInterrupt
        runner.interrupted = True
        progress.clear()
        print("\ncfcontact: stopping at the next point (checkpoint follows); Ctrl-C again to abort",
              file=sys.stderr, flush=True)

    old = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


# ============================================================ checkpoints
def save_checkpoint(partial, path, case, reason):
    """Write ``<partial>/checkpoint/`` (path/ + state.json) atomically."""
    final = os.path.join(partial, "checkpoint")
    tmp = os.path.join(partial, ".checkpoint-new")
    shutil.rmtree(tmp, ignore_errors=True)
    os.makedirs(tmp)
    path.save(os.path.join(tmp, "path"))
    state = {"format": CHECKPOINT_FORMAT, "version": 1, "reason": reason, "time": time.time(),
             "method": path.method, "resumable": path.resume_state is not None,
             "resume_state": path.resume_state, "physics": _physics(case),
             "case_file": case["_file"], "summary": _jsonable(path.summary())}
    with open(os.path.join(tmp, "state.json"), "w") as fh:
        json.dump(_jsonable(state), fh, indent=1)
    old = os.path.join(partial, ".checkpoint-old")
    shutil.rmtree(old, ignore_errors=True)
    if os.path.isdir(final):
        os.rename(final, old)
    os.rename(tmp, final)
    shutil.rmtree(old, ignore_errors=True)
    log.info("checkpoint written to %s (%s)", final, reason)
    return final


def load_checkpoint(partial):
    """(state dict, SolutionPath) of ``<partial>/checkpoint`` (or the old one of an interrupted swap)."""
    from cfcontact.path import SolutionPath

    for name in ("checkpoint", ".checkpoint-old"):
        ck = os.path.join(partial, name)
        if os.path.isfile(os.path.join(ck, "state.json")) and os.path.isdir(os.path.join(ck, "path")):
            with open(os.path.join(ck, "state.json")) as fh:
                state = json.load(fh)
            if state.get("format") != CHECKPOINT_FORMAT:
                raise CaseError(f"{ck}: not a cfcontact checkpoint")
            return state, SolutionPath.load(os.path.join(ck, "path"))
    raise CaseError(f"no checkpoint to resume from in {partial!r} (run without --resume)")


def _has_checkpoint(partial):
    return any(os.path.isfile(os.path.join(partial, n, "state.json")) for n in ("checkpoint", ".checkpoint-old"))


def _jsonable(o):
    """Strict JSON: NaN/inf -> None, numpy scalars/arrays -> Python."""
    import numpy as np

    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return _jsonable(o.tolist())
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (float, np.floating)):
        return float(o) if math.isfinite(o) else None
    return o


# ============================================================ path reports
def path_report(path) -> dict:
    """Everything ``info`` shows, as a JSON-able dict."""
    mult, at = path.max_multiplicity()
    return _jsonable({
        "method": path.method, "status": path.status, "n": path.n, "m": path.m,
        "alpha_start": path.alpha_start, "alpha_end": path.alpha_end,
        "points": len(path.alphas), "branches": len(path.branches),
        "transitions": [t.to_dict() for t in path.transitions],
        "folds": [t.alpha for t in path.folds],
        "multiplicity": [{"alpha_lo": a, "alpha_hi": b, "solutions": k} for a, b, k in path.multiplicity_intervals()],
        "max_multiplicity": mult, "alpha_of_max": at,
        "events": [e.to_dict() for e in path.events], "stats": path.stats, "options": path.options,
    })


def format_report(rep, source) -> str:
    lines = [f"saved path: {source}",
             f"method {rep['method']}, status {rep['status']}, n = {rep['n']} DOFs, m = {rep['m']} contact nodes, "
             f"alpha {rep['alpha_start']:g} -> {rep['alpha_end']:g}",
             f"points {rep['points']}, branches {rep['branches']}, transitions {len(rep['transitions'])} "
             f"({sum(t['kind'] == 'transversal' for t in rep['transitions'])} transversal, {len(rep['folds'])} folds)"]
    if rep["alpha_of_max"] is not None:
        lines.append(f"max multiplicity {rep['max_multiplicity']} (at alpha = {rep['alpha_of_max']:.10g})")
    lines.append("")
    if rep["transitions"]:
        lines.append("transitions:")
        lines.append(f"  {'#':>4}  {'kind':<11}  {'alpha':>16}  {'node':>5}  {'set':<4}  branches")
        for t in rep["transitions"]:
            lines.append(f"  {t['index']:>4}  {t['kind']:<11}  {t['alpha']:>16.10g}  {t['node']:>5}  "
                         f"{str(t['set']):<4}  {t['from_branch']} -> {t['to_branch']}")
    else:
        lines.append("transitions: none")
    lines.append("folds: " + (", ".join(f"alpha = {a:.10g}" for a in rep["folds"]) if rep["folds"] else "none"))
    lines.append("multiplicity over alpha:")
    for iv in rep["multiplicity"]:
        lines.append(f"  [{iv['alpha_lo']:.10g}, {iv['alpha_hi']:.10g}]  {iv['solutions']} solution(s)")
    if not rep["multiplicity"]:
        lines.append("  (the path covers no alpha interval)")
    if rep["events"]:
        lines.append("events:")
        for e in rep["events"]:
            lines.append(f"  {e['kind']} at alpha = {e['alpha']}: {e['message']}")
    else:
        lines.append("events: none")
    st = rep["stats"] or {}
    if st:
        parts = [f"{k} {v:.3g} s" if k.endswith("time") else f"{k} {v}" for k, v in st.items()]
        lines.append("stats: " + ", ".join(parts))
    return "\n".join(lines)


def resolve_saved(dirname) -> str:
    """The path/ folder of a saved path, a run output folder, or a stopped run's <out>.partial folder."""
    dirname = os.fspath(dirname)
    for cand in (dirname, os.path.join(dirname, "path"), os.path.join(dirname, "checkpoint", "path")):
        if os.path.isfile(os.path.join(cand, "path.json")):
            return cand
    raise CaseError(f"{dirname!r} is not a saved path (expected path.json in it, in path/ or in checkpoint/path/)")


def _load_saved(dirname):
    from cfcontact.path import SolutionPath

    src = resolve_saved(dirname)
    path = SolutionPath.load(src)
    _default_sigpipe()
    return src, path


_PROGRAM = {"main": False}  # True when main() runs as the program (argv from sys.argv)


def _default_sigpipe():
    """Importing PETSc installs a SIGPIPE handler that aborts MPI when stdout is a closed pipe
    (``cfcontact info ... | head``); as a program, die quietly like other command-line tools."""
    if _PROGRAM["main"] and hasattr(signal, "SIGPIPE") and threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGPIPE, signal.SIG_DFL)


# ============================================================ run: outputs
def write_outputs(path, case, outdir, timings, args, system=None):
    """Plots, renders, the saved path and summary.json into ``outdir``; returns the files written."""
    out = case["output"]
    files = []
    t = time.perf_counter()
    path.save(os.path.join(outdir, "path"))
    files.append("path/")
    with open(os.path.join(outdir, "case.toml"), "w") as fh:
        fh.write(case["_text"])
    files.append("case.toml")
    timings["save"] = time.perf_counter() - t
    component = out.get("component")
    if component is not None:
        path.component_index(component)  # range check (InputError)
    if out["plot"] and len(path.alphas):
        t = time.perf_counter()
        from cfcontact.plotting import plot_multiplicity, plot_path, save_figure

        fig = plot_path(path, component=component, zoom=out.get("zoom"),
                        title=case.get("title"))
        for fmt in out["plot_formats"]:
            save_figure(fig, os.path.join(outdir, f"path.{fmt}"))
            files.append(f"path.{fmt}")
        if path.multiplicity_intervals():
            fig = plot_multiplicity(path)
            for fmt in out["plot_formats"]:
                save_figure(fig, os.path.join(outdir, f"multiplicity.{fmt}"))
                files.append(f"multiplicity.{fmt}")
        timings["plot"] = time.perf_counter() - t
    if (out["render_panel"] or out["render_animation"] or out["xdmf"]) and path.geometry is None:
        _warn(args, "the path has no geometry; no renders" + (" and no XDMF file" if out["xdmf"] else ""))
    elif out["render_panel"] or out["render_animation"] or out["xdmf"]:
        t = time.perf_counter()
        ws = out.get("window_size")
        mag = out.get("magnification")
        sols = _panel_solutions(path) if out["render_panel"] or out["xdmf"] else []
        if out["xdmf"] and sols:
            from cfcontact import fields

            fields.write_xdmf(os.path.join(outdir, "solutions.xdmf"), path.geometry, sols)
            files.append("solutions.xdmf")
        if out["render_panel"] and sols:
            from cfcontact import render

            stresses = None
            if out["stress"]:
                from cfcontact import fields

                stresses = [fields.von_mises(path.geometry, s.u) for s in sols]
            render.render_panel(path.geometry, sols, os.path.join(outdir, "panel.png"), magnification=mag,
                                window_size=None if ws is None else tuple(ws), stresses=stresses)
            files.append("panel.png")
        if out["render_animation"] and len(path.alphas):
            from cfcontact import render

            fmt = out["animation_format"]
            name = "animation_frames" if fmt == "frames" else f"animation.{fmt}"
            stress = None
            if out["stress"]:
                from cfcontact import fields

                def stress(sol):
                    return fields.von_mises(path.geometry, sol.u)

            res = render.render_animation(path, os.path.join(outdir, name), frames=out["animation_frames"],
                                          magnification=mag, window_size=(960, 640) if ws is None else tuple(ws),
                                          title=case.get("title"), stress=stress)
            if res.note:
                _warn(args, res.note)
            files.append(os.path.relpath(res.path, outdir) + ("/" if res.kind == "png-frames" else ""))
        timings["render"] = time.perf_counter() - t
    summary = {"format": RUN_FORMAT, "version": 1, "case_file": case["_file"], "title": case.get("title"),
               "summary": path.summary(), **path_report(path), "timings": timings, "files": files}
    with open(os.path.join(outdir, "summary.json"), "w") as fh:
        json.dump(_jsonable(summary), fh, indent=1)
    files.append("summary.json")
    return files


def _panel_solutions(path):
    """The solutions at the alpha of largest multiplicity (else the last path point)."""
    k, a = path.max_multiplicity()
    sols = path.solutions_at(a) if k else []
    if not sols and len(path.alphas):
        from cfcontact.ssnm import Solution

        y = path.point_y(len(path.alphas) - 1)
        n, m = path.n, path.m
        sols = [Solution(y[:n], y[n:n + m], y[n + m:], float(path.alphas[-1]),
                         path.branches[path.point_branch[-1]].sets, 0)]
    return sols


def _is_run_folder(d):
    if not os.listdir(d):
        return True
    try:
        with open(os.path.join(d, "summary.json")) as fh:
            return json.load(fh).get("format") == RUN_FORMAT
    except (OSError, ValueError, AttributeError):
        return False


# ============================================================ subcommands
def cmd_run(args):
    t_start = time.monotonic()
    case = load_case(args.case)
    if args.output:
        out = os.path.abspath(args.output)
    else:
        stem = os.path.splitext(os.path.basename(case["_file"]))[0]
        out = os.path.join(os.path.dirname(case["_file"]), f"{stem}_out")
    out = out.rstrip(os.sep)
    partial = out + ".partial"
    for name in ("stop_after_folds", "stop_after_transitions"):
        v = getattr(args, name)
        if v is not None and v < 1:
            raise CaseError(f"--{name.replace('_', '-')} must be >= 1, got {v}")
    if args.time_limit is not None and not args.time_limit > 0:
        raise CaseError(f"--time-limit must be > 0 seconds, got {args.time_limit}")
    if os.path.exists(out):
        if not args.force:
            raise CaseError(f"the output folder {out!r} exists; use --force to replace it or --output DIR")
        if not os.path.isdir(out) or not _is_run_folder(out):
            raise CaseError(f"refusing to replace {out!r}: it is not a cfcontact output folder")
    resume = None
    if args.resume:
        if not os.path.isdir(partial):
            raise CaseError(f"nothing to resume: no folder {partial!r} (run without --resume)")
        state, saved = load_checkpoint(partial)
        if not state.get("resumable"):
            raise CaseError(f"the checkpoint in {partial!r} (method {state.get('method')!r}) cannot be resumed; "
                            f"start over with --force")
        changed = [k for k in PHYSICS_SECTIONS if state["physics"].get(k) != _physics(case)[k]]
        if changed:
            raise CaseError(f"the case file changed since the checkpoint in section(s) "
                            f"{', '.join(f'[{k}]' for k in changed)}; restore it or start over with --force")
        resume = {"path": saved, "state": state["resume_state"]}
    elif os.path.exists(partial):
        if not args.force:
            raise CaseError(f"a stopped run left {partial!r}; continue it with --resume or start over with --force")
        shutil.rmtree(partial)

    # ---------------------------------------------------------------- work
    created = not os.path.isdir(partial)
    os.makedirs(partial, exist_ok=True)
    method = case["path"]["method"]
    progress = _Progress(enabled=not args.quiet and (args.verbose or sys.stderr.isatty()), tty=sys.stderr.isatty())
    _ProgressAwareHandler.progress = progress
    try:
        timings = {}
        t = time.perf_counter()
        _say(args, f"cfcontact: building the model of {os.path.basename(case['_file'])}")
        system = build_system(case)
        timings["assembly"] = time.perf_counter() - t
        comp = case["output"].get("component")
        if comp is not None:
            from cfcontact.path import SolutionPath

            try:
                SolutionPath(system.n, system.m, *system.contact_maps(), system.friction, system.rho, method, 0, 1) \
                    .component_index(comp)
            except InputError as exc:
                raise CaseError(f"[output] component: {exc}") from None
        path = _trace(system, case, args, partial, resume, progress, t_start, timings)
        if path.status != "completed":
            _warn(args, f"the path ended with status {path.status!r} (see the events in summary.json / info)")
        files = write_outputs(path, case, partial, timings, args, system)
        shutil.rmtree(os.path.join(partial, "checkpoint"), ignore_errors=True)
        shutil.rmtree(os.path.join(partial, ".checkpoint-old"), ignore_errors=True)
        if os.path.isdir(out):
            old = out + ".old"
            shutil.rmtree(old, ignore_errors=True)
            os.rename(out, old)
            os.rename(partial, out)
            shutil.rmtree(old)
        else:
            os.rename(partial, out)
    except _Stopped as stop:
        progress.done()
        again = f"{args.case}" + (f" --output {args.output}" if args.output else "")
        if stop.resumable:
            _say(args, f"cfcontact: {stop.reason}; checkpoint in {os.path.join(partial, 'checkpoint')}\n"
                       f"continue with: cfcontact run --resume {again}")
        else:
            _say(args, f"cfcontact: {stop.reason}; the partial path is in {os.path.join(partial, 'checkpoint')} "
                       f"(cfcontact info {partial}); it left no resume state: start over with "
                       f"cfcontact run --force {again}")
        return stop.code
    except BaseException:
        progress.done()
        if _has_checkpoint(partial):
            for name in os.listdir(partial):  # keep only the checkpoint
                if name not in ("checkpoint", ".checkpoint-old"):
                    p = os.path.join(partial, name)
                    shutil.rmtree(p) if os.path.isdir(p) and not os.path.islink(p) else os.remove(p)
            print(f"cfcontact: a checkpoint remains in {partial} (cfcontact run --resume)", file=sys.stderr)
        elif created or not args.resume:
            shutil.rmtree(partial, ignore_errors=True)
        raise
    finally:
        _ProgressAwareHandler.progress = None
    progress.done()
    s = path.summary()
    _say(args, f"cfcontact: {s['status']}: {s['points']} points, {s['branches']} branches, {s['transitions']} "
               f"transitions ({s['folds']} folds), max multiplicity {s['max_multiplicity']}; wrote {out}/ "
               f"({', '.join(files)})")
    return EXIT_OK


def _trace(system, case, args, partial, resume, progress, t_start, timings):
    """Trace the path in chunks (periodic checkpoints); raises _Stopped when a stop condition fires."""
    from cfcontact.path import PathOptions, select_solver, trace_path

    p = case["path"]
    method = p["method"]
    opts = PathOptions(**{k: v for k, v in p.items() if k in PathOptions.names()})
    solver = select_solver(system, method, p.get("backend", "auto"))
    runner = _Runner(args, solver, progress, t_start, resume["path"] if resume else None)

    t = time.perf_counter()
    with _sigint(runner, progress):
        try:
            while True:
                runner.reason = None
                path = trace_path(system, p["alpha_start"], p["alpha_end"], method=method,
                                  options=opts, callback=runner.on_point, solver=solver, resume=resume)
                if path.status != "stopped by callback" or runner.reason is None:
                    break
                progress.clear()
                save_checkpoint(partial, path, case, runner.reason)
                if runner.reason != "checkpoint":
                    code = EXIT_INTERRUPTED if runner.interrupted else EXIT_STOPPED
                    raise _Stopped(runner.reason, code, resumable=path.resume_state is not None)
                runner.last_checkpoint = time.monotonic()
                resume = {"path": path, "state": path.resume_state}
        except KeyboardInterrupt:
            if _has_checkpoint(partial):
                raise _Stopped("aborted (Ctrl-C twice); the last periodic checkpoint remains", EXIT_INTERRUPTED)
            raise
    timings["trace"] = time.perf_counter() - t
    _default_sigpipe()
    progress.update(runner.status_line(path.alphas[-1], len(path.branches), len(path.transitions),
                                       len(path.folds)), force=True)
    progress.done()
    return path


def cmd_plot(args):
    src, path = _load_saved(args.saved)
    component = _parse_component(args.component, "--component") if args.component is not None else None
    if component is not None:
        path.component_index(component)
    zoom = list(args.zoom) if args.zoom else None
    if zoom and not zoom[0] < zoom[1]:
        raise CaseError(f"--zoom: need A < B, got {zoom[0]} {zoom[1]}")
    out = args.output or ("multiplicity.png" if args.multiplicity else "path.png")
    if os.path.splitext(out)[1].lower() not in (".png", ".pdf"):
        raise CaseError(f"-o: unsupported figure format {out!r}; use .png or .pdf")
    from cfcontact.plotting import plot_multiplicity, plot_path, save_figure

    if args.multiplicity:
        fig = plot_multiplicity(path)
    else:
        fig = plot_path(path, component=component, zoom=zoom)
    save_figure(fig, out)
    _say(args, f"wrote {out}")
    return EXIT_OK


def _render_animation(args, path, ws, src):
    from cfcontact import render

    stress = None
    if args.stress:  # cells coloured by the von Mises stress, one scale for all frames
        from cfcontact import fields

        material = _saved_material(src, path)

        def stress(sol):
            return fields.von_mises(path.geometry, sol.u, material)

    res = render.render_animation(path, args.animation, frames=args.frames, magnification=args.magnification,
                                  window_size=ws or (960, 640), stress=stress)
    if res.note:
        _warn(args, res.note)
    _say(args, f"wrote {res.path} ({res.kind}, {res.frames} frames)")


def cmd_render(args):
    src, path = _load_saved(args.saved)
    if path.geometry is None:
        raise CaseError(f"{src!r} has no geometry (a lumped model): nothing to render")
    from cfcontact import render

    ws = tuple(args.window_size) if args.window_size else None
    if ws is not None and min(ws) < 16:
        raise CaseError(f"--window-size: width and height must be >= 16, got {ws}")
    if args.animation and args.alpha is None and not args.panel and args.output is None:
        _render_animation(args, path, ws, src)
        return EXIT_OK
    if args.alpha is None:
        k, alpha = path.max_multiplicity()
        if not k:
            raise CaseError("the path covers no alpha interval; give --alpha")
    else:
        alpha = args.alpha
    sols = path.solutions_at(alpha)
    if not sols:
        lo, hi = float(path.alphas.min()), float(path.alphas.max())
        raise CaseError(f"--alpha {alpha}: the path has no solution there; it covers alpha in [{lo:.10g}, {hi:.10g}]")
    out = args.output or "render.png"
    if os.path.splitext(out)[1].lower() != ".png":
        raise CaseError(f"-o: renders are PNG files, got {out!r}")
    stresses = None
    if args.stress:
        from cfcontact import fields

        material = _saved_material(src, path)
        stresses = [fields.von_mises(path.geometry, s.u, material) for s in sols]
    if len(sols) > 1 or args.panel:
        render.render_panel(path.geometry, sols, out, magnification=args.magnification, window_size=ws,
                            stresses=stresses)
    else:
        render.render_solution(path.geometry, sols[0], out, magnification=args.magnification,
                               window_size=ws or (1200, 800), stress=None if stresses is None else stresses[0])
    _say(args, f"wrote {out} ({len(sols)} solution(s) at alpha = {alpha:.10g})")
    if args.animation:
        _render_animation(args, path, ws, src)
    return EXIT_OK


def _saved_material(src, path):
    """The material of a saved path: stored with its geometry, else the [material] of the run's case.toml
    (paths saved before the material was stored); CaseError if neither is there."""
    material = getattr(path.geometry, "material", None)
    if material is not None:
        return material
    folder = os.path.abspath(src)
    # <out>/path -> <out>/case.toml; <out>.partial/checkpoint/path -> <out>.partial/case.toml
    for cand in (os.path.dirname(folder), os.path.dirname(os.path.dirname(folder))):
        fn = os.path.join(cand, "case.toml")
        if os.path.isfile(fn):
            try:
                with open(fn, "rb") as fh:
                    mat = tomllib.loads(fh.read().decode("utf-8")).get("material", {})
            except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
                continue
            return {"E": mat.get("E", 2.1e11), "nu": mat.get("nu", 0.3), "plane": mat.get("plane", "strain")}
    raise CaseError(f"{src!r} stores no material (saved by an older cfcontact) and no case.toml is next to it; "
                    f"re-run the case to get stresses")


def cmd_export(args):
    src, path = _load_saved(args.saved)
    if path.geometry is None:
        raise CaseError(f"{src!r} has no geometry (a lumped model): nothing to export")
    out = args.output or "solutions.xdmf"
    if os.path.splitext(out)[1].lower() not in (".xdmf", ".xmf"):
        raise CaseError(f"-o: XDMF files end in .xdmf or .xmf, got {out!r}")
    from cfcontact import fields

    try:
        material = _saved_material(src, path)
    except CaseError:
        material = None
        _warn(args, f"{src!r} stores no material: no von_mises attribute")
    fn, what = fields.export_path(path, out, alpha=args.alpha, points=args.points, material=material)
    _say(args, f"wrote {fn} ({what})")
    return EXIT_OK


def cmd_info(args):
    src, path = _load_saved(args.saved)
    rep = path_report(path)
    if args.json:
        print(json.dumps(rep, indent=1))
    else:
        print(format_report(rep, src))
    return EXIT_OK


# ============================================================ argument parsing
def _common():
    p = argparse.ArgumentParser(add_help=False)
    g = p.add_mutually_exclusive_group()
    g.add_argument("-q", "--quiet", action="store_true", help="print nothing but errors")
    g.add_argument("-v", "--verbose", action="store_true",
                   help="log the library's progress (INFO), progress line even without a TTY, tracebacks")
    return p


def _setup_run(sub, common):
    p = sub.add_parser("run", parents=[common], help="trace the solution path of a case file",
                       description="Validate CASE.toml, build the model, trace the path and write the results.")
    p.add_argument("case", metavar="CASE.toml")
    p.add_argument("-o", "--output", metavar="DIR", help="output folder (default: <case stem>_out/ next to the case)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing output folder / discard a stopped run's checkpoint")
    p.add_argument("--resume", action="store_true", help="continue the stopped run in <output>.partial/")
    p.add_argument("--stop-after-folds", type=int, metavar="N", help="stop (resumably) once the path has N folds")
    p.add_argument("--stop-after-transitions", type=int, metavar="N",
                   help="stop (resumably) once the path has N transitions")
    p.add_argument("--stop-at-alpha", type=float, metavar="A", help="stop (resumably) when the path reaches alpha A")
    p.add_argument("--time-limit", type=float, metavar="SECONDS",
                   help="stop (resumably) after this wall time (checked at each accepted point)")
    p.add_argument("--checkpoint-every", type=float, metavar="SECONDS", default=DEFAULT_CHECKPOINT_EVERY,
                   help=f"checkpoint interval while tracing (default {DEFAULT_CHECKPOINT_EVERY:g}; 0: only on stop)")
    p.set_defaults(func=cmd_run)


def _setup_plot(sub, common):
    p = sub.add_parser("plot", parents=[common], help="plot a saved path (alpha against a component)")
    p.add_argument("saved", metavar="SAVED_PATH_DIR")
    p.add_argument("--component", metavar="NAME:I", help="lam_n:12, lam_t:3, u:7 or an index of y "
                                                         "(default: the contact node whose lam_n varies most)")
    p.add_argument("--zoom", nargs=2, type=float, metavar=("A", "B"), help="add a zoom panel on alpha in [A, B]")
    p.add_argument("--multiplicity", action="store_true", help="plot the number of solutions over alpha instead")
    p.add_argument("-o", "--output", metavar="FILE", help="FILE.png or FILE.pdf (default path.png / multiplicity.png)")
    p.set_defaults(func=cmd_plot)


def _setup_render(sub, common):
    p = sub.add_parser("render", parents=[common], help="render deformed configurations of a saved path")
    p.add_argument("saved", metavar="SAVED_PATH_DIR")
    p.add_argument("--alpha", type=float, metavar="A",
                   help="render the solutions at alpha A (default: the alpha of largest multiplicity)")
    p.add_argument("--panel", action="store_true", help="panel layout even for a single solution")
    p.add_argument("--animation", metavar="FILE", help="animation along the path: FILE.gif, FILE.mp4 or a folder")
    p.add_argument("--frames", type=int, default=60, help="animation frames (default 60)")
    p.add_argument("--magnification", type=float, help="displacement scale (default: automatic)")
    p.add_argument("--window-size", nargs=2, type=int, metavar=("W", "H"), help="picture size in pixels")
    p.add_argument("--stress", action="store_true", help="colour the cells by the von Mises stress")
    p.add_argument("-o", "--output", metavar="FILE.png", help="picture file (default render.png)")
    p.set_defaults(func=cmd_render)


def _setup_export(sub, common):
    p = sub.add_parser("export", parents=[common], help="write solutions of a saved path as XDMF (ParaView)",
                       description="Write the solutions at one alpha (default: the alpha of largest multiplicity) "
                                   "or every stored path point as an XDMF 3 file with inline XML data: "
                                   "displacement, contact_state, lam_n, lam_t, body, von_mises.")
    p.add_argument("saved", metavar="SAVED_PATH_DIR")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--alpha", type=float, metavar="A",
                   help="all solutions at alpha A (default: the alpha of largest multiplicity)")
    g.add_argument("--points", action="store_true", help="every stored path point, in path order (time series)")
    p.add_argument("-o", "--output", metavar="FILE.xdmf", help="XDMF file (default solutions.xdmf)")
    p.set_defaults(func=cmd_export)


def _setup_info(sub, common):
    p = sub.add_parser("info", parents=[common], help="transitions, folds, multiplicity, events and stats of a path")
    p.add_argument("saved", metavar="SAVED_PATH_DIR")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=cmd_info)


def cmd_bench(args):
    """``cfcontact bench``: the benchmark of :mod:`cfcontact.bench` (tables on stdout, JSON file)."""
    from cfcontact import bench

    return bench.run(args, " ".join(["cfcontact"] + sys.argv[1:]) if _PROGRAM["main"] else "cfcontact bench")


def _setup_bench(sub, common):
    p = sub.add_parser("bench", parents=[common], help="benchmark: seed vs exact on the main demo, exact method "
                                                       "on refined meshes",
                       description="Part A: seed vs exact method on the main demo (demos/main.py) and on two "
                                   "steel blocks. Part B: the exact method on refined meshes of the two steel "
                                   "blocks (time split, peak memory). Prints "
                                   "both tables and writes <output>/bench.json. See docs/bench.md.")
    from cfcontact.bench import add_arguments

    add_arguments(p)
    p.set_defaults(func=cmd_bench)


#: (name, setup(subparsers, common_parent)) of every subcommand.  A subcommand's
#: ``cmd_*(args)`` returns an exit code and raises CaseError / InputError for bad input (exit 2).
SUBCOMMANDS = [("run", _setup_run), ("plot", _setup_plot), ("render", _setup_render), ("info", _setup_info),
               ("export", _setup_export), ("bench", _setup_bench)]


def build_parser():
    from cfcontact import __version__

    parser = argparse.ArgumentParser(prog="cfcontact", description="Path following for 2D static contact with "
                                     "Coulomb friction (FEniCSx + PETSc).")
    parser.add_argument("--version", action="version", version=f"cfcontact {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    common = _common()
    for _, setup in SUBCOMMANDS:
        setup(sub, common)
    return parser


def main(argv=None) -> int:
    """Entry point of the ``cfcontact`` command; returns the exit code."""
    _PROGRAM["main"] = argv is None
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help / --version (0) or a usage error (2)
        return int(exc.code or 0)
    level = logging.ERROR if args.quiet else logging.INFO if args.verbose else logging.WARNING
    with _logging(level):
        try:
            return int(args.func(args) or 0)
        except (CaseError, InputError) as exc:
            print(f"cfcontact {args.command}: error: {exc}", file=sys.stderr, flush=True)
            return EXIT_INPUT
        except KeyboardInterrupt:
            print(f"cfcontact {args.command}: interrupted", file=sys.stderr, flush=True)
            return EXIT_INTERRUPTED
        except Exception as exc:
            if args.verbose:
                traceback.print_exc()
            kind = "" if isinstance(exc, CfcontactError) else f"{type(exc).__name__}: "
            print(f"cfcontact {args.command}: failed: {kind}{exc}"
                  + ("" if args.verbose else "  (--verbose for the traceback)"), file=sys.stderr, flush=True)
            return EXIT_FAILURE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
