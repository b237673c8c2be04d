"""Case files (TOML): the schema, its validation, and the model a case describes.

The schema (:data:`SCHEMA`, one :class:`Key` per key with its type, default and doc) is the one
source of the case-file format: :func:`validate_case` checks a parsed file against it, and
:func:`reference_text` renders it as the annotated reference of ``cfcontact schema`` and of
the documentation's case-file page (docs/case-files.md, generated from it at build time).  The ``[path]`` keys beyond ``method``, ``backend``,
``alpha_start`` and ``alpha_end`` are generated from the fields of
:class:`cfcontact.options.PathOptions`, and the checks of E and nu are those of
:mod:`cfcontact.material`, the assembly's.

Every key is checked before any work: :class:`CaseError` (exit code 2 of the command line)
names the key and the valid keys, tags or values.  :func:`build_system` turns a validated case
into a :class:`~cfcontact.system.ContactSystem` (it imports the FEM layer).

Nothing here imports dolfinx or PETSc at import time.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import tomllib
from dataclasses import dataclass, fields
from typing import Any, Optional

from cfcontact.errors import InputError
from cfcontact.interrupts import import_gmsh, python_sigint, sigint_deferred  # noqa: F401 (the CLI imports some)
from cfcontact.material import DEFAULT_MATERIAL, PLANES, check_modulus, check_poisson
from cfcontact.options import BACKENDS, MAX_FRICTION, MAX_TOL, METHODS, AlphaSpan, PathOptions, unused_options
from cfcontact.pairing import OBSTACLE_KEYS, OBSTACLE_OPTIONAL, PAIRINGS

__all__ = ["CaseError", "SCHEMA", "GEOMETRY_KINDS", "PHYSICS_SECTIONS", "Key", "validate_case", "load_case",
           "build_system", "physics", "path_request", "parse_component", "reference_text", "estimate_size",
           "check_size", "available_memory", "SIZE_ESTIMATORS"]


class CaseError(InputError):
    """A bad case file or command line argument (exit code 2)."""


@dataclass(frozen=True)
class Key:
    """One key of a case-file section: its type (see :data:`TYPE_NAMES`), the default filled in
    by validation (None: none), the example shown by :func:`reference_text` (TOML text; None:
    the key is shown commented out with its doc only) and a one-line doc."""

    kind: str
    default: Any = None
    example: Optional[str] = None
    doc: str = ""


GEOMETRY_KINDS = ("two_blocks", "block_on_foundation", "inclined", "arc", "cylinder", "punch", "msh")
#: the kinds pressed on a block by a prescribed displacement of their top (cfcontact.models)
PRESSED_KINDS = ("cylinder", "punch")
#: [path] parameter: the load path (alpha) or the friction coefficient (cfcontact.friction)
PARAMETERS = ("alpha", "friction")
COMPONENT_NAMES = ("u", "lam_n", "lam_t")
#: The sections that determine the path (a resumed run must have the same).
PHYSICS_SECTIONS = ("geometry", "material", "contact", "loads", "path")

TYPE_NAMES = {"int": "an integer", "float": "a number", "str": "a string", "bool": "a boolean (true/false)",
              "tags": "a list of tags (names or numbers)",
              "tractions": "a table {tag = [tx, ty] or windowed tractions}",
              "body_force": "[bx, by] or a table {body = [bx, by]}", "formats": 'a list of "png"/"pdf"',
              "component": '["lam_n", i], "lam_n:i" or an integer', "zoom": "[alpha_lo, alpha_hi] (+ [v_lo, v_hi])",
              "window": "[width, height] in pixels", "friction": "a number >= 0 or a list of them",
              "material": "a number or a table {body = number}", "tag": "a tag (name or number)",
              "obstacle": 'a table {kind = "line", point = [x, y], normal = [nx, ny]} or {kind = "circle", '
                          'center = [x, y], radius = R[, inside = true]}',
              "dirichlet": "a table {tag = {x = value, y = value}}"}

_KIND = Key("str", None, '"two_blocks"', " | ".join(f'"{k}"' for k in GEOMETRY_KINDS))
#: [geometry] keys of the block kinds ("two_blocks", "block_on_foundation", "inclined")
BLOCK_GEOMETRY = {
    "kind": _KIND,
    "nx": Key("int", None, "12", "cells along the interface"),
    "ny": Key("int", None, "4", "cells across each block"),
    "length": Key("float", None, "3.0", "block width"),
    "height": Key("float", None, "1.0", "block height"),
    "height2": Key("float", None, None, "height of body 2 (default: height)"),
    "cell": Key("str", None, '"quadrilateral"', 'or "triangle"'),
    "angle": Key("float", None, None, 'degrees counter-clockwise, required for "inclined"'),
    "nx2": Key("int", None, None, 'cells of body 2 along the interface (default: nx); nx2 != nx is a non-matching '
                                  'interface: pairing = "segment"'),
    "ny2": Key("int", None, None, "cells across body 2 (default: ny)"),
}
#: [geometry] keys of kind "arc" (cfcontact.arc_on_block)
ARC_GEOMETRY = {
    "kind": Key("str", None, '"arc"', "a convex circular-arc bottom in a matching seat (conforming)"),
    "radius": Key("float", None, "1.0", "radius R of the arc, centred at (0, R); lowest point at the origin"),
    "half_angle": Key("float", None, "45.0", "half opening angle, degrees in (0, 80]; normals turn by 2 x it"),
    "height": Key("float", None, "0.5", "body 1 above the ends of the arc"),
    "height2": Key("float", None, None, "body 2 below the lowest point (default: height)"),
    "nx": Key("int", None, "16", "cells along the arc, >= 2"),
    "ny": Key("int", None, "4", "cells across body 1"),
    "ny2": Key("int", None, None, "cells across body 2 (default: ny)"),
    "cell": Key("str", None, '"quadrilateral"', 'or "triangle"'),
}
_PRESSED_COMMON = {
    "width": Key("float", None, "4.0", "the block [-width/2, width/2] x [-depth, 0]"),
    "depth": Key("float", None, "2.0", "depth of the block"),
    "size": Key("float", None, None, "element size along the contact boundaries"),
    "size_far": Key("float", None, None, "element size far from them"),
    "growth": Key("float", None, None, "growth of the element size per unit distance, in (0, 1)"),
    "gap0": Key("float", None, None, "initial distance between body 1's lowest point and the block, >= 0"),
    "cell": Key("str", None, None, '"triangle" or "quadrilateral"'),
    "half": Key("bool", None, None, "the right half x >= 0 only, symmetry edges sym1, sym2 on x = 0"),
}
#: [geometry] keys of kind "cylinder" (cfcontact.cylinder_on_block)
CYLINDER_GEOMETRY = {
    "kind": Key("str", None, '"cylinder"', "the lower half of a cylinder pressed on a block (Hertz), initial gap"),
    "radius": Key("float", None, "1.0", "radius R; the lowest point at (0, gap0)"),
    **{k: v for k, v in _PRESSED_COMMON.items() if k in ("width", "depth")},
    "zone": Key("float", None, "0.3", "contact2 = the block's top for |x| <= zone (< 0.76 R)"),
    **{k: v for k, v in _PRESSED_COMMON.items() if k not in ("width", "depth")},
}
#: [geometry] keys of kind "punch" (cfcontact.rounded_punch)
PUNCH_GEOMETRY = {
    "kind": Key("str", None, '"punch"', "a flat punch with rounded bottom corners pressed on a block"),
    "half_width": Key("float", None, "0.5", "the punch [-half_width, half_width] x [gap0, gap0 + height]"),
    "edge_radius": Key("float", None, "0.1", "radius of its rounded corners (< half_width, < height)"),
    "height": Key("float", None, None, "height of the punch"),
    **{k: v for k, v in _PRESSED_COMMON.items() if k in ("width", "depth")},
    "zone": Key("float", None, None, "contact2 = the block's top for |x| <= zone (default: half_width - "
                                     "edge_radius / 4)"),
    **{k: v for k, v in _PRESSED_COMMON.items() if k not in ("width", "depth")},
}
#: [geometry] keys of kind "msh" (a user's gmsh file)
MSH_GEOMETRY = {
    "kind": Key("str", None, '"msh"', "a gmsh file following the tag convention (DESIGN.md)"),
    "file": Key("str", None, '"model.msh"', "relative to the case file"),
}


def _toml(value) -> str:
    """A Python value as TOML text (for the reference and the docs)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        text = repr(value)
        if "e" in text or len(text) > 8:  # 2.1e11, 1e-5 rather than 210000000000.0, 1e-05
            mantissa, _, exponent = f"{value:.6g}".partition("e")
            text = mantissa + (f"e{int(exponent)}" if exponent else "")
        return text if any(c in text for c in ".en") else text + ".0"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, str):
        return json.dumps(value)
    return str(value)


def _path_keys() -> dict:
    """[path]: the trace_path arguments, then every field of PathOptions (generated)."""
    keys = {
        "method": Key("str", "seed", '"seed"', '"seed" (predictor-corrector, Section 4) or "exact" (piecewise-affine)'),
        "backend": Key("str", "auto", None, 'DirNeu solver: "full" (J(Z) per branch), "condensed" (K factored '
                                            'once) or "auto" (condensed for exact when m <= 2000 and no node lacks a '
                                            'tangential unknown)'),
        "alpha_start": Key("float", 0.0, "0.0", "f(alpha) = (1 - alpha) f1 + alpha f2, from alpha_start"),
        "alpha_end": Key("float", 1.0, "1.0", "towards alpha_end"),
        # continuation in the friction coefficient (cfcontact.friction)
        "parameter": Key("str", "alpha", None, '"alpha" (the load path; default) or "friction": continuation in F at '
                                               'the load f(alpha_start) from friction_start to friction_end '
                                               '(condensed backend)'),
        "friction_start": Key("float", None, None, f'parameter = "friction": the first F, at most {MAX_FRICTION:g} '
                                                   '(default 0)'),
        "friction_end": Key("float", None, None, f'parameter = "friction": the last F, at most {MAX_FRICTION:g} '
                                                 '(default: the largest [contact] friction)'),
    }
    for f in fields(PathOptions):
        notes = [] if f.default is None else [f"default {_toml(f.default)}"]
        if set(f.metadata["methods"]) != set(METHODS):
            notes.append(f"{', '.join(f.metadata['methods'])} only")
        doc = f.metadata["doc"] + (f" ({'; '.join(notes)})" if notes else "")
        keys[f.name] = Key(f.metadata["kind"], None, None, doc)
    return keys


SCHEMA = {
    "geometry": None,  # depends on the kind: see geometry_keys
    "material": {
        "E": Key("material", None, _toml(DEFAULT_MATERIAL["E"]),
                 "Young's modulus [Pa] > 0, or one per body: {body1 = 2.1e11, body2 = 2.1e8}"),
        "nu": Key("material", None, _toml(DEFAULT_MATERIAL["nu"]), "Poisson's ratio in (-1, 0.5), or one per body"),
        "plane": Key("str", None, _toml(DEFAULT_MATERIAL["plane"]), 'or "stress"'),
    },
    "contact": {
        "friction": Key("friction", 0.0, "0.5", f"Coulomb coefficient in [0, {MAX_FRICTION:g}], or a list with one per "
                                                "contact node"),
        "rho": Key("float", None, None, "augmentation parameter > 0 (default: automatic)"),
        "pairing": Key("str", None, None, '"node" (matching nodes, no gap) or "segment" (node to segment, with the '
                                          'initial gap; default for "cylinder", "punch" and an obstacle)'),
        "slave": Key("tag", None, None, 'the contact boundary projected with pairing = "segment": "contact1" (default) '
                                        'or "contact2" (default for "cylinder", "punch")'),
        "search_distance": Key("float", None, None, 'pairing = "segment" leaves out slave nodes farther than this '
                                                    "from the master, > 0 (default: no limit)"),
        "obstacle": Key("obstacle", None, None, "a rigid obstacle as master of body 1 (a model without body 2); "
                                                "see [contact.obstacle] below"),
    },
    "loads": {
        "clamp": Key("tags", None, '["left1", "left2"]', "boundary tags (names or numbers) with u = 0"),
        "body_force1": Key("body_force", None, None, "[bx, by] on every body, or a table {body1 = [bx, by]}"),
        "body_force2": Key("body_force", None, None, "the same for f2"),
        "f1": Key("tractions", None, "{top1 = [2.0e7, -1.0e8]}",
                  "surface tractions of f1, tag = [tx, ty] (force per length); see below"),
        "f2": Key("tractions", None, "{top1 = [1.0e8, -2.0e7]}", "surface tractions of f2"),
        "dirichlet": Key("dirichlet", None, None, "prescribed displacement components along the path; see "
                                                  "[loads.dirichlet] below"),
    },
    "path": _path_keys(),
    "output": {
        "plot": Key("bool", True, "true", "path.png: alpha against one component"),
        "plot_formats": Key("formats", ["png"], '["png"]', '"png", "pdf"'),
        "component": Key("component", None, None, '["lam_n", 12], "lam_n:12", "lam_t:3", "u:7" or an index of y '
                                                  "(default: the most varying lam_n)"),
        "zoom": Key("zoom", None, None, "alpha window of a zoom panel, [a0, a1] (+ value range: [a0, a1, v0, v1])"),
        "render_panel": Key("bool", True, "true", "panel.png: the solutions at the alpha of largest multiplicity"),
        "render_animation": Key("bool", False, "false", "the deformed configuration along the path"),
        "animation_format": Key("str", "gif", '"gif"', '"gif" | "mp4" | "frames"'),
        "animation_frames": Key("int", 60, "60", "frames of the animation"),
        "magnification": Key("float", None, None, "displacement scale (default: automatic)"),
        "window_size": Key("window", None, None, "[width, height] pixels of panel.png and of the animation"),
        "stress": Key("bool", False, "false", "colour panel.png and the animation by the von Mises stress"),
        "xdmf": Key("bool", False, "false", "solutions.xdmf (the panel's solutions) for ParaView"),
    },
}
TOP_LEVEL = ("title", *SCHEMA)


def geometry_keys(kind) -> dict:
    """The [geometry] keys of a geometry kind."""
    return {"msh": MSH_GEOMETRY, "arc": ARC_GEOMETRY, "cylinder": CYLINDER_GEOMETRY,
            "punch": PUNCH_GEOMETRY}.get(kind, BLOCK_GEOMETRY)


# ------------------------------------------------------------------ value checks
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


def _pressed_default(kind, name):
    """The default of a keyword of the model builder of a pressed kind (cfcontact.models)."""
    import inspect

    from cfcontact import models

    builder = {"cylinder": models.cylinder_on_block, "punch": models.rounded_punch}[kind]
    return inspect.signature(builder).parameters[name].default


def _subtable(where):
    """"[contact] obstacle" -> "[contact.obstacle]": how a user writes a table inside a section."""
    section, _, key = where.partition("] ")
    return f"{section}.{key}]" if key else where


_OBSTACLE_DOCS = {"point": "a point of the line", "normal": "its normal, pointing out of the obstacle toward the body",
                  "center": "the centre of the rigid disc", "radius": "its radius > 0",
                  "inside": "true: a rigid bore, the body in its hole (default false: a disc)"}


def _obstacle(value, where):
    """{kind = "line", point, normal} / {kind = "circle", center, radius[, inside]}, checked key by key."""
    where = _subtable(where)
    if not isinstance(value, dict):
        raise CaseError(f"{where}: expected {TYPE_NAMES['obstacle']}, got {_tname(value)} {value!r}")
    kind = value.get("kind")
    if "kind" not in value:
        raise CaseError(f"{where} kind is missing: give kind = \"line\" (with point, normal) or kind = \"circle\" "
                        f"(with center, radius)")
    if kind not in OBSTACLE_KEYS:
        raise CaseError(f"{where} kind: expected \"line\" (with point, normal) or \"circle\" (with center, "
                        f"radius), got {kind!r}")
    keys, optional = OBSTACLE_KEYS[kind], OBSTACLE_OPTIONAL[kind]
    unknown = sorted(set(value) - set(keys) - set(optional) - {"kind"})
    if unknown:
        raise CaseError(f"unknown key {unknown[0]!r} in {where} (kind = {kind!r}); valid keys: kind, "
                        f"{', '.join(keys + optional)}")
    out = {"kind": kind}
    for key in keys:
        if key not in value:
            raise CaseError(f"{where} {key} is missing: kind = {kind!r} needs {', '.join(keys)} ({key}: "
                            f"{_OBSTACLE_DOCS[key]})")
        if key == "radius":
            out[key] = _check_value("float", value[key], f"{where} radius")
            if not out[key] > 0:
                raise CaseError(f"{where} radius: must be > 0, got {value[key]!r}")
        else:
            out[key] = _vec2(value[key], f"{where} {key}")
    if "inside" in optional and "inside" in value:
        out["inside"] = _check_value("bool", value["inside"], f"{where} inside")
    if kind == "line" and out["normal"] == [0.0, 0.0]:
        raise CaseError(f"{where} normal: must not be zero (it points out of the obstacle toward the body)")
    return out


def _dirichlet(value, where):
    """{tag = {x = v | [v1, v2], y = ...}} -> {tag: {"x": [v1, v2], ...}} (tags checked later)."""
    where = _subtable(where)
    if not isinstance(value, dict):
        raise CaseError(f"{where}: expected {TYPE_NAMES['dirichlet']}, got {_tname(value)} {value!r}")
    out = {}
    for tag, comps in value.items():
        here = f"{where} {tag}"
        if not isinstance(comps, dict) or not comps:
            raise CaseError(f"{here}: expected a table of components, e.g. {{x = 0.0}} or {{y = [0.0, -1.0e-3]}}, "
                            f"got {_tname(comps)} {comps!r}")
        unknown = sorted(set(comps) - {"x", "y"})
        if unknown:
            raise CaseError(f"{here}: unknown component {unknown[0]!r}; valid: x, y")
        out[tag] = {}
        for comp, given in comps.items():
            v = [given, given] if _is_number(given) else given
            if not (isinstance(v, list) and len(v) == 2 and all(_is_number(x) for x in v)):
                raise CaseError(f"{here}.{comp}: expected a number or [value at alpha = 0, value at alpha = 1], "
                                f"got {_tname(given)} {given!r}")
            if not all(math.isfinite(x) for x in v):
                raise CaseError(f"{here}.{comp}: values must be finite, got {given!r}")
            out[tag][comp] = [float(x) for x in v]
    return out


def _check_value(typ, value, where):
    """Normalised value or CaseError naming ``where`` (e.g. "[contact] friction"), the expected type and the got."""
    bad = CaseError(f"{where}: expected {TYPE_NAMES[typ]}, got {_tname(value)} {value!r}")
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
    if typ == "tag":
        if isinstance(value, bool) or not isinstance(value, (str, int)):
            raise bad
        return value
    if typ == "obstacle":
        return _obstacle(value, where)
    if typ == "dirichlet":
        return _dirichlet(value, where)
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
        return parse_component(value, where)
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
        if max(vals) > MAX_FRICTION:
            raise CaseError(f"{where}: the friction coefficient must be at most {MAX_FRICTION:g} (the limit of "
                            f"cfcontact map --friction-range), got {max(vals)!r}")
        return float(value) if _is_number(value) else [float(x) for x in value]
    raise AssertionError(typ)


def parse_component(value, where):
    """("lam_n", 12) / "lam_n:12" / 57 -> ("lam_n", 12) or 57."""
    if isinstance(value, int) and not isinstance(value, bool):
        if value < 0:
            raise CaseError(f"{where}: an index of y must be >= 0, got {value}")
        return value
    if isinstance(value, str):
        name, sep, idx = value.partition(":")
        if not sep:
            try:
                number = int(value)
            except ValueError:
                pass
            else:  # (outside the try: the CaseError of a negative index is a ValueError too)
                return parse_component(number, where)
        try:
            value = [name.strip(), int(idx)]
        except ValueError:
            raise CaseError(f"{where}: expected \"NAME:INDEX\" (NAME one of {', '.join(COMPONENT_NAMES)}) or an "
                            f"integer, got {value!r}") from None
    if not (isinstance(value, list) and len(value) == 2 and isinstance(value[0], str)
            and isinstance(value[1], int) and not isinstance(value[1], bool)):
        raise CaseError(f"{where}: expected {TYPE_NAMES['component']}, got {_tname(value)} {value!r}")
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
    for key, spec in keys.items():
        if key in table:
            out[key] = _check_value(spec.kind, table[key], f"{label} {key}")
        elif spec.default is not None:
            out[key] = copy.deepcopy(spec.default)  # (a list default must not be shared with the schema)
    return out


def _file_sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _geometry_script(kind):
    """The gmsh script module of a built-in kind (imports gmsh)."""
    import_gmsh()
    from cfcontact.meshes import arc_on_block, cylinder_on_block, rounded_punch, two_blocks

    python_sigint()
    return {"arc": arc_on_block, "cylinder": cylinder_on_block, "punch": rounded_punch}.get(kind, two_blocks)


_BODY2_PIECES = ("body2", "contact2", "bottom2", "right2", "left2")
_BODY1_PIECES = ("body1", "contact1", "top1", "right1", "left1")


def builtin_groups(kind, geometry) -> tuple:
    """The names of the physical groups the script of a built-in kind creates (tags: the scripts'
    TAGS; a test compares them with the scripts' own build)."""
    if kind == "block_on_foundation":
        return _BODY1_PIECES
    if kind in PRESSED_KINDS:
        names = _BODY1_PIECES + _BODY2_PIECES + ("top2",)
        if geometry.get("half"):
            names = tuple(n for n in names if n not in ("left1", "left2")) + ("sym1", "sym2")
        return names
    return _BODY1_PIECES + _BODY2_PIECES


# ------------------------------------------------------------------ validation
def validate_case(raw: dict, base_dir: str = ".") -> dict:
    """Check a parsed case file completely; returns the normalised case (CaseError on the first problem).

    Tags are checked against the model's physical groups (built-in kinds: their script's groups;
    "msh": the groups read from the file).  The [path] section is checked by the library's own
    validation (:class:`~cfcontact.options.PathOptions`, :class:`~cfcontact.options.AlphaSpan`),
    whose results :func:`path_request` returns.
    """
    if not isinstance(raw, dict):
        raise CaseError("the case file must be a TOML table")
    unknown = sorted(set(raw) - set(TOP_LEVEL))
    if unknown:
        raise CaseError(f"unknown section or key {unknown[0]!r} at the top level; valid: {', '.join(TOP_LEVEL)}")
    case = {}
    if "title" in raw:
        case["title"] = _check_value("str", raw["title"], "title")
    case["geometry"] = geometry = _validate_geometry(raw.get("geometry"), base_dir)
    case["material"] = material = _validate_material(raw.get("material", {}))
    _check_msh_loads(raw.get("loads", {}), geometry)
    groups = _model_groups(geometry["kind"], geometry)
    case["contact"] = _validate_contact(raw.get("contact", {}), geometry, groups)
    case["loads"] = _validate_loads(raw.get("loads", {}), geometry, material, groups)
    case["path"], case["_request"] = _validate_path(raw.get("path", {}))
    case["_warnings"] = _unused_path_keys(raw.get("path", {}), case["path"])
    _validate_friction_parameter(case["path"], case["contact"])
    output = _check_section("output", raw.get("output", {}), SCHEMA["output"])
    if output["animation_format"] not in ("gif", "mp4", "frames"):
        raise CaseError(f"[output] animation_format: expected \"gif\", \"mp4\" or \"frames\", "
                        f"got {output['animation_format']!r}")
    if output["animation_frames"] < 1:
        raise CaseError(f"[output] animation_frames: must be >= 1, got {output['animation_frames']}")
    if "magnification" in output and not output["magnification"] > 0:
        raise CaseError(f"[output] magnification: must be > 0, got {output['magnification']!r}")
    _check_zoom(output.get("zoom"), case["path"])
    case["output"] = output
    return case


def _check_zoom(zoom, path):
    """[output] zoom against the range of the path's parameter (alpha, or F with parameter =
    "friction"): a window outside it can hold no point of the path."""
    if zoom is None:
        return
    if path.get("parameter") == "friction":
        name, ends = "F", (path["friction_start"], path["friction_end"])
    else:
        name, ends = "alpha", (path["alpha_start"], path["alpha_end"])
    lo, hi = min(ends), max(ends)
    if zoom[1] < lo or zoom[0] > hi:
        raise CaseError(f"[output] zoom: the window {zoom[0]:g} <= {name} <= {zoom[1]:g} lies outside the path's "
                        f"range {lo:g} .. {hi:g}")


def _validate_geometry(geo, base_dir):
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
    geometry = _check_section("geometry", geo, geometry_keys(kind), f"[geometry] (kind = {kind!r})")
    if kind == "msh":
        if "file" not in geometry:
            raise CaseError("[geometry] file is missing: kind = 'msh' needs file = \"model.msh\" "
                            "(relative to the case file)")
        geometry["file"] = os.path.normpath(os.path.join(base_dir, geometry["file"]))
        if not os.path.isfile(geometry["file"]):
            raise CaseError(f"[geometry] file: no such mesh file {geometry['file']!r}")
        geometry["sha256"] = _file_sha256(geometry["file"])
        return geometry
    if kind == "inclined" and "angle" not in geometry:
        raise CaseError("[geometry] angle is missing: kind = 'inclined' needs the angle in degrees")
    if kind == "block_on_foundation":
        extra = [k for k in ("height2", "nx2", "ny2") if k in geometry]
        if extra:
            raise CaseError(f"[geometry] {extra[0]}: kind = 'block_on_foundation' has no body 2")
    try:
        _geometry_script(kind).check_parameters(**{k: v for k, v in geometry.items() if k != "kind"})
    except (InputError, ValueError) as exc:
        raise CaseError(f"[geometry] {exc}") from None
    return geometry


def _validate_material(table):
    material = _check_section("material", table, SCHEMA["material"])
    if "plane" in material and material["plane"] not in PLANES:
        raise CaseError(f"[material] plane: expected \"strain\" or \"stress\", got {material['plane']!r}")
    for key, check in (("E", check_modulus), ("nu", check_poisson)):
        value = material.get(key)
        for body, v in (value.items() if isinstance(value, dict) else [(None, value)]):
            if v is None:
                continue
            try:
                check(v)
            except InputError as exc:
                raise CaseError(f"[material] {key}{'' if body is None else '.' + body}: {exc}") from None
    return material


def _check_msh_loads(table, geometry):
    """kind = "msh" has no default loads: clamp, [loads.f1] and [loads.f2] are required."""
    if geometry["kind"] != "msh" or not isinstance(table, dict):
        return
    for key in ("clamp", "f1", "f2"):
        if key not in table:
            what = "clamp = [tags]" if key == "clamp" else f"a table [loads.{key}] (may be empty)"
            raise CaseError(f"[loads] {key} is missing: kind = 'msh' needs {what}")


def effective_pairing(contact, geometry) -> str:
    """The pairing a case's [contact] and [geometry] sections ask for: [contact] pairing, else
    "segment" for the pressed kinds and with an obstacle, else "node" (the library's defaults)."""
    if "pairing" in contact:
        return contact["pairing"]
    return "segment" if geometry.get("kind") in PRESSED_KINDS or "obstacle" in contact else "node"


def contact_settings(geometry, contact) -> dict:
    """The pairing a case's [geometry] and [contact] sections ask for, the library's defaults filled
    in: {"pairing", "slave", "search_distance"} (for ``cfcontact info`` on a saved run; the
    sections may be unvalidated text of a run's case.toml)."""
    pairing = effective_pairing(contact, geometry)
    slave = contact.get("slave")
    if slave is None:
        slave = "contact2" if pairing == "segment" and geometry.get("kind") in PRESSED_KINDS else "contact1"
    slave = {"contact1": "contact1=10", "contact2": "contact2=20", 10: "contact1=10", 20: "contact2=20",
             "10": "contact1=10", "20": "contact2=20"}.get(slave, str(slave))
    return {"pairing": pairing, "slave": slave, "search_distance": contact.get("search_distance")}


def _validate_contact(table, geometry, groups):
    """[contact]: friction, rho, and the pairing keys (pairing, slave, search_distance, obstacle)
    checked against the model: a slave must be one of its contact boundaries, an obstacle needs a
    model without body 2, segment pairing needs a master."""
    contact = _check_section("contact", table, SCHEMA["contact"])
    if "rho" in contact and not 0 < contact["rho"] <= 1e100:
        raise CaseError(f"[contact] rho: must be > 0 and at most 1e+100, got {contact['rho']!r}")
    if "pairing" in contact and contact["pairing"] not in PAIRINGS:
        raise CaseError(f"[contact] pairing: expected {' or '.join(map(json.dumps, PAIRINGS))}, "
                        f"got {contact['pairing']!r}")
    if "search_distance" in contact and not contact["search_distance"] > 0:
        raise CaseError(f"[contact] search_distance: must be > 0 (leave it out for no limit), got "
                        f"{contact['search_distance']!r}")
    pairing = effective_pairing(contact, geometry)
    body2 = (2, 2) in groups
    if "obstacle" in contact:
        if body2:
            where = ('kind = "block_on_foundation"' if geometry["kind"] != "msh" else "a .msh without body2")
            raise CaseError(f"[contact.obstacle]: an obstacle is the master of a single body, but kind = "
                            f"{geometry['kind']!r} has body 2; use {where}")
        if pairing != "segment":
            raise CaseError('[contact] pairing: an obstacle is paired node to segment: use pairing = "segment" '
                            "(or leave pairing out)")
    elif pairing == "segment" and not body2:
        raise CaseError('[contact] pairing: "segment" needs a master: body 2 (contact2) or a [contact.obstacle]')
    for key in ("slave", "search_distance"):
        if key in contact and pairing != "segment":
            raise CaseError(f'[contact] {key}: only used with pairing = "segment" (node pairing matches the nodes '
                            f'of contact1 and contact2); add pairing = "segment" or leave {key} out')
    if "slave" in contact:
        slave = contact["slave"]
        valid = "contact1=10" + (" or contact2=20" if body2 and "obstacle" not in contact else "")
        try:
            _check_tag(slave, groups, 1, "[contact] slave")
        except CaseError:
            raise CaseError(f"[contact] slave: must be a contact boundary ({valid}), got {slave!r}, which is not a "
                            "boundary piece of the model" + (" (an obstacle is the master of contact1)"
                                                             if "obstacle" in contact else "")) from None
        number = _tag_number(slave, groups, 1)
        if number not in (10, 20) or (number == 20 and "obstacle" in contact):
            raise CaseError(f"[contact] slave: must be a contact boundary ({valid}), got {slave!r}"
                            + (f" ({groups[(1, number)]}={number})" if groups.get((1, number)) else ""))
    return contact


def _validate_loads(table, geometry, material, groups):
    kind = geometry["kind"]
    loads = _check_section("loads", table, SCHEMA["loads"])
    for key in ("clamp", "f1", "f2", "body_force1", "body_force2", "dirichlet"):
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
    if geometry.get("half") and "dirichlet" in loads:  # the symmetry conditions replaced by the user's
        named = {_tag_number(t, groups, 1) for t in [*loads["dirichlet"], *loads.get("clamp", [])]}
        missing = [name for name in ("sym1", "sym2") if _tag_number(name, groups, 1) not in named]
        if missing:
            raise CaseError(f"[loads.dirichlet]: a half model (half = true) needs its symmetry conditions, which "
                            f"[loads.dirichlet] replaces: add {' and '.join(f'{m} = {{x = 0.0}}' for m in missing)}")
    for key in ("E", "nu"):  # per-body material: one value for each body of the model
        if isinstance(material.get(key), dict):
            for t in material[key]:
                _check_tag(t, groups, 2, f"[material] {key}")
            named = {_tag_number(t, groups, 2) for t in material[key]}
            missing = [name for (dim, num), name in sorted(groups.items()) if dim == 2 and num not in named]
            if missing:
                raise CaseError(f"[material] {key}: no value for body {', '.join(missing)}; give one number "
                                f"per body or a single number")
    return loads


def _validate_path(table):
    """(normalised [path] section, (PathOptions, AlphaSpan)), both checked by the library's rules."""
    path = _check_section("path", table, SCHEMA["path"])
    if path["method"] not in METHODS:
        raise CaseError(f"[path] method: unknown method {path['method']!r}; valid: {', '.join(map(repr, METHODS))}")
    if path.get("tol") is not None and not 0 < path["tol"] <= MAX_TOL:
        raise CaseError(f"[path] tol: must be in (0, {MAX_TOL:g}], got {path['tol']!r}")
    if path.get("max_iter") is not None and not path["max_iter"] >= 1:
        raise CaseError(f"[path] max_iter: must be >= 1, got {path['max_iter']!r}")
    if path["backend"] not in BACKENDS:
        raise CaseError(f"[path] backend: unknown backend {path['backend']!r}; valid: {', '.join(map(repr, BACKENDS))}")
    try:
        options = PathOptions(**{k: v for k, v in path.items() if k in PathOptions.names()})
        if path.get("parameter") == "friction":
            # a path in F at the fixed load f(alpha_start): alpha_end plays no part (alpha_start = 1,
            # the full load, with the default alpha_end = 1 was refused as an empty alpha range)
            a0 = AlphaSpan.of(path["alpha_start"], path["alpha_start"] + 1.0, PathOptions()).start
            span = AlphaSpan(a0, a0, a0, a0)
        else:
            span = AlphaSpan.of(path["alpha_start"], path["alpha_end"], options)
    except InputError as exc:
        raise CaseError(f"[path] {exc}") from None
    return path, (options, span)


def _unused_path_keys(raw, path) -> list:
    """Warnings for [path] keys the case gives but its method or parameter does not use."""
    notes = [f"[path] {note}" for note in unused_options(path["method"], raw)]
    if path.get("parameter") != "friction":
        notes += [f'[path] {k}: used with parameter = "friction" only; ignored' for k in ("friction_start", "friction_end")
                  if k in raw]
    else:
        notes += [f'[path] {k}: used by paths over alpha only; ignored with parameter = "friction"'
                  for k in ("alpha_end", "alpha_min", "alpha_max", "tree") if k in raw]
    return notes


def _validate_friction_parameter(path, contact):
    """[path] parameter: "alpha" or "friction"; for "friction" the range (filled in) and the backend."""
    if path["parameter"] not in PARAMETERS:
        raise CaseError(f"[path] parameter: expected one of {', '.join(map(repr, PARAMETERS))}, "
                        f"got {path['parameter']!r}")
    if path["parameter"] != "friction":
        return
    fr = contact.get("friction", 0.0)
    path.setdefault("friction_start", 0.0)
    path.setdefault("friction_end", float(max(fr) if isinstance(fr, list) else fr))
    F0, F1 = path["friction_start"], path["friction_end"]
    for key, F in (("friction_start", F0), ("friction_end", F1)):
        if F > MAX_FRICTION:
            raise CaseError(f"[path] {key}: the friction coefficient must be at most {MAX_FRICTION:g} (the limit of "
                            f"cfcontact map --friction-range), got {F!r}")
    if F0 == F1 == 0.0 and not fr:
        raise CaseError('[path] parameter = "friction": the path runs from friction_start to friction_end (default '
                        "[contact] friction, here 0); give friction_end > 0")
    if min(F0, F1) < 0 or F0 == F1:
        raise CaseError(f"[path] friction_start, friction_end: need two different values >= 0, got {F0}, {F1}")
    if path["backend"] == "full":
        raise CaseError('[path] backend: parameter = "friction" needs the condensed backend ("condensed" or "auto")')


def path_request(case) -> tuple:
    """(PathOptions, AlphaSpan) of a validated case: its [path] section, validated once."""
    return case["_request"]


def _model_groups(kind, geometry) -> dict:
    """{(dim, number): name} of the physical groups of the case's model."""
    if kind != "msh":
        tags = _geometry_script(kind).TAGS
        return {tags[name]: name for name in builtin_groups(kind, geometry)}
    gmsh = import_gmsh()
    python_sigint()
    from cfcontact import compat
    from cfcontact.meshes.common import convention_mismatch, volume_problem

    with compat.gmsh_model("cfcontact-cli-probe") as model:
        try:
            gmsh.merge(geometry["file"])
        except Exception as exc:
            raise CaseError(f"[geometry] file: gmsh cannot read {geometry['file']!r}: {exc}") from None
        groups = {(int(d), int(n)): model.getPhysicalName(d, n) for d, n in model.getPhysicalGroups()}
        problem = volume_problem(model, groups)
    if problem:
        raise CaseError(f"[geometry] file: {geometry['file']!r}: {problem}")
    _check_msh_groups(groups, geometry["file"])
    problem = convention_mismatch(groups)
    if problem:
        raise CaseError(f"[geometry] file: {geometry['file']!r}: {problem}")
    return groups


def _check_msh_groups(groups, file):
    """CaseError naming what is wrong with a .msh's physical groups as a whole: none at all, or
    the groups of the tag convention numbered but not named (the case's tags, the slave and the
    assembly find them by name)."""
    convention = ("body1=1, contact1=10, and body2=2, contact2=20 for a second body; other boundary pieces "
                  "by name or number (docs/geometry.md, \"Tag convention\")")
    if not groups:
        raise CaseError(f"[geometry] file: {file!r} has no physical groups; a .msh needs the named physical groups "
                        f"of the tag convention: {convention}")
    from cfcontact.meshes.common import CONVENTION

    unnamed = [(d, n) for (d, n), name in sorted(groups.items()) if not name]
    wrong = [(d, n) for (d, n), want in CONVENTION.items() if (d, n) in groups and groups[(d, n)] != want]
    if unnamed and (wrong or len(unnamed) == len(groups)):
        found = ", ".join(f"{n} ({d}-D)" for d, n in unnamed)
        raise CaseError(f"[geometry] file: {file!r} has physical groups without names ({found}"
                        f"{'; none is named' if len(unnamed) == len(groups) else ''}); cfcontact needs them named "
                        f"as the tag convention says: {convention}")


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


def _tag_number(tag, groups, dim):
    """The number of a (checked) tag of dimension ``dim``: a name, a number or a digit string."""
    if isinstance(tag, str) and not tag.isdigit():
        return next(n for (d, n), name in groups.items() if d == dim and name == tag)
    return int(tag)


def load_case(filename) -> dict:
    """Read and validate a TOML case file; returns the normalised case with its text and location."""
    filename = os.fspath(filename)
    if os.path.isdir(filename):
        raise CaseError(f"{filename!r} is a folder, not a case file (give the .toml file)")
    if os.path.exists(filename) and not os.path.isfile(filename):
        raise CaseError(f"{filename!r} is not a regular file (a case file is a TOML text file)")
    if not os.path.isfile(filename):
        raise CaseError(f"no such case file: {filename!r}")
    try:
        with open(filename, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise CaseError(f"cannot read the case file {filename!r}: {exc.strerror}") from None
    try:
        raw = tomllib.loads(data.decode("utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise CaseError(f"{filename}: not UTF-8 text ({exc})") from None
    except tomllib.TOMLDecodeError as exc:
        raise CaseError(f"{filename}: invalid TOML: {exc}") from None
    case = validate_case(raw, os.path.dirname(os.path.abspath(filename)))
    case["_file"] = os.path.abspath(filename)
    case["_text"] = data.decode("utf-8-sig")
    return case


# ------------------------------------------------------------------ size
#: Largest number of DOFs PETSc can index with its (default) 32-bit integers.
MAX_DOFS = 2**31 - 1
#: Memory model of a run (calibrated on docs/bench.md, Part B: peak 1.65 GiB at n = 1.2e5 and
#: 9.9 GiB at n = 1e6, MUMPS): a fixed part (Python, PETSc, dolfinx), per DOF the mesh,
#: the assembly and the path (bytes), per factorization of K (or J(Z)) BYTES_PER_FACTOR_DOF x
#: log2(n) bytes per DOF (the fill of a nested-dissection factor of a 2-D mesh and MUMPS' workspace).
BASE_BYTES, BYTES_PER_DOF, BYTES_PER_FACTOR_DOF = 3.2e8, 3000.0, 450.0
#: Factorizations kept at once: the condensed backend keeps K's; the full one up to SolverOptions.cache J(Z)'s.
FULL_BACKEND_FACTORS = 4


def _blocks_size(geo):
    nodes = (geo.get("nx", 30) + 1) * (geo.get("ny", 10) + 1)
    bodies = 1 if geo["kind"] == "block_on_foundation" else 2
    return 2 * bodies * nodes, geo.get("nx", 30) + 1, ("nx", "ny")


def _arc_size(geo):
    defaults = _geometry_script("arc").DEFAULTS
    nx, ny = geo.get("nx", defaults["nx"]), geo.get("ny", defaults["ny"])
    ny2 = geo.get("ny2") or ny
    return 2 * (nx + 1) * (ny + ny2 + 2), nx + 1, ("nx", "ny", "ny2")


def _msh_size(geo):
    """(nodes, contact1 nodes) of a .msh file, read with gmsh."""
    from cfcontact import compat

    gmsh = import_gmsh()

    with compat.gmsh_model("cfcontact-size-probe") as model:
        try:
            gmsh.merge(geo["file"])
            tags = model.mesh.getNodes()[0]
            try:
                contact = model.mesh.getNodesForPhysicalGroup(1, 10)[0]
            except Exception:  # no contact1 group: the assembly says so later
                contact = ()
        except Exception as exc:
            raise CaseError(f"[geometry] file: gmsh cannot read {geo['file']!r}: {exc}") from None
    return 2 * len(tags), max(len(contact), 1), ("file",)


def _graded_nodes(length, area, size, size_far, growth, dist_min) -> float:
    """Nodes of a body meshed with size ``size`` within ``dist_min`` of a contact curve of the given
    length, growing by ``growth`` per unit distance up to ``size_far`` (the gmsh field of
    :func:`cfcontact.meshes.common.refine_near`): the integral of 1 / (0.866 h^2) (equilateral
    triangles: two per node) over the band of width s around the curve on the body's side, of
    area length s + pi s^2 / 2, and the rest of the body's area at size_far; at most the whole
    area at ``size``."""
    def band(s):
        return length * s + 0.5 * math.pi * s * s

    s1 = dist_min + max(size_far - size, 0.0) / growth
    a, b = length + math.pi * dist_min, math.pi  # band'(dist_min + t) = a + b t, h = size + growth t
    u = size + growth * (s1 - dist_min)
    graded = ((a - b * size / growth) * (1.0 / size - 1.0 / u) + (b / growth) * math.log(u / size)) / growth
    integral = band(dist_min) / size ** 2 + graded + max(area - band(s1), 0.0) / size_far ** 2
    return min(integral, area / size ** 2) / 0.866


def _pressed_size(kind):
    """Estimator of the cylinder and punch models (graded meshes, :func:`_graded_nodes` per body;
    quadrilaterals, subdivided triangles, have about twice the nodes; the punch's corners 1.3
    times the band's): from 0.75 to 1.6 times gmsh's node counts over sizes 0.005-0.05, radii,
    zones, half models and both cells (measured)."""
    def estimate(geo):
        p = {**_geometry_script(kind).DEFAULTS, **geo}
        size, growth, W, D = p["size"], p["growth"], p["width"], p["depth"]
        far = max(p["size_far"], size)  # (as the scripts take it)
        if kind == "cylinder":
            R, zone = p["radius"], p["zone"]
            length1, area1, dist_min = 2.0 * R * math.asin(min(1.25 * zone / R, 1.0)), 0.5 * math.pi * R * R, 0.5 * zone
        else:
            w, r = p["half_width"], p["edge_radius"]
            zone = p.get("zone") or w - 0.25 * r  # (0 or none: the script's default)
            length1, area1, dist_min = 2.0 * (w - r + 0.5 * math.pi * r), 2.0 * w * p["height"], 2.0 * r
        length2, area2 = 2.0 * zone, W * D
        scale = 0.5 if p["half"] else 1.0
        nodes = sum(_graded_nodes(scale * L, scale * A, size, far, growth, dist_min)
                    for L, A in ((length1, area1), (length2, area2)))
        nodes *= (2.0 if p["cell"] == "quadrilateral" else 1.0) * (1.3 if kind == "punch" else 1.0)
        return 2 * nodes, scale * max(length1, length2) / size + 1, ("size", "size_far", "growth", "zone")

    return estimate


#: {geometry kind: geometry table -> (n estimate, m estimate, the keys that set the size)}
SIZE_ESTIMATORS = {"two_blocks": _blocks_size, "block_on_foundation": _blocks_size, "inclined": _blocks_size,
                   "arc": _arc_size, "msh": _msh_size, "cylinder": _pressed_size("cylinder"),
                   "punch": _pressed_size("punch")}


def available_memory() -> Optional[float]:
    """Bytes of memory available to this process: MemAvailable of /proc/meminfo (or the free
    physical pages), at most what a cgroup (container) limit leaves; None if unknown."""
    avail = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    avail = float(line.split()[1]) * 1024
                    break
    except OSError:
        pass
    if avail is None:
        try:
            avail = float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
        except (ValueError, OSError, AttributeError):
            return None
    try:
        with open("/sys/fs/cgroup/memory.max") as fh:
            limit = fh.read().strip()
        with open("/sys/fs/cgroup/memory.current") as fh:
            used = float(fh.read().strip())
        if limit.isdigit():
            avail = min(avail, float(limit) - used)
    except (OSError, ValueError):
        pass
    return avail


def _gib(b) -> str:
    return f"{b / 2**30:.3g} GiB"


def estimate_size(case) -> Optional[dict]:
    """Estimate of a validated case's size before any work: n (DOFs), m (contact nodes) and the
    memory of a run (bytes; :data:`BASE_BYTES` etc.), with the [geometry] keys that set it; None
    for a geometry kind without an estimator (:data:`SIZE_ESTIMATORS`)."""
    geo = case["geometry"]
    estimator = SIZE_ESTIMATORS.get(geo["kind"])
    if estimator is None:
        return None
    n, m, keys = estimator(geo)
    p = case["path"]
    condensed = p["backend"] == "condensed" or (p["backend"] == "auto" and p["method"] == "exact" and m <= 2000)
    factor = BYTES_PER_FACTOR_DOF * n * math.log2(max(n, 2))
    memory = BASE_BYTES + BYTES_PER_DOF * n + factor * (1 if condensed else FULL_BACKEND_FACTORS)
    if condensed:
        memory += 3 * 8.0 * (2 * m) ** 2  # S = B K^-1 B^T, its reduced copies and dense factors
    where = ", ".join(f"{k} = {geo[k]!r}" if k == "file" else f"{k} = {geo[k]}" for k in keys if k in geo)
    return {"n": int(n), "m": int(m), "memory": float(memory), "keys": keys,
            "where": f"[geometry] {where}" if where else f"[geometry] kind = {geo['kind']!r} (its defaults)"}


def check_size(case, allow_large: bool = False, available: Optional[float] = None) -> Optional[dict]:
    """Refuse (CaseError) a case that cannot fit before any work: more DOFs than PETSc can index
    (always), or an estimated memory (:func:`estimate_size`) above the memory available
    (:func:`available_memory`, or ``available`` bytes) unless ``allow_large``.  Returns the estimate."""
    est = estimate_size(case)
    if est is None:
        return None
    n, m = est["n"], est["m"]
    if n > MAX_DOFS:
        raise CaseError(f"{est['where']}: the model would have about {n:.3g} DOFs, beyond the {MAX_DOFS} that PETSc "
                        f"can index; use a coarser mesh")
    if allow_large:
        return est
    available = available_memory() if available is None else available
    if available is not None and est["memory"] > available:
        raise CaseError(f"{est['where']}: the model would have about {n:.3g} DOFs and {m:.3g} contact nodes and "
                        f"need about {_gib(est['memory'])} of memory, more than the {_gib(available)} this machine "
                        f"has available; use a coarser mesh, or --allow-large to run anyway")
    return est


def physics(case) -> dict:
    """The sections that determine the path (a resumed run must have the same), as plain JSON data."""
    return json.loads(json.dumps({k: case.get(k) for k in PHYSICS_SECTIONS}))


# ------------------------------------------------------------------ model building
def build_system(case):
    """The ContactSystem of a validated case (imports the FEM layer).  An error of the assembly
    that only the mesh can reveal (an obstacle that does not face the body, a non-matching
    interface with node pairing, a prescribed displacement on a contact node) is a CaseError
    naming the case key."""
    geo, mat, con, loads = case["geometry"], case["material"], case["contact"], case["loads"]
    common = {k: ({_tag_value(t): x for t, x in v.items()} if isinstance(v, dict) else v) for k, v in mat.items()}
    common["friction"] = con["friction"]
    for key in ("rho", "pairing", "search_distance", "obstacle"):
        if key in con:
            common[key] = con[key]
    if "slave" in con:
        common["slave"] = _tag_value(con["slave"])
    if "clamp" in loads:
        common["clamp"] = [_tag_value(t) for t in loads["clamp"]]
    for key, arg in (("f1", "tractions1"), ("f2", "tractions2"), ("dirichlet", "dirichlet")):
        if key in loads:
            common[arg] = {_tag_value(t): v for t, v in loads[key].items()}
    for key in ("body_force1", "body_force2"):
        if key in loads:
            v = loads[key]
            common[key] = {_tag_value(t): w for t, w in v.items()} if isinstance(v, dict) else v
    try:
        return _build(geo, common)
    except InputError as exc:  # GeometryError too
        raise CaseError(_case_message(str(exc), con)) from None


def _build(geo, common):
    with sigint_deferred():  # dolfinx, ufl, basix and gmsh load here: a Ctrl-C waits for them
        from cfcontact import assembly, models  # noqa: F401
    if geo["kind"] == "msh":
        from cfcontact.assembly import assemble_contact_system

        return assemble_contact_system(geo["file"], info={"model": "msh", "file": geo["file"]}, **common)
    from cfcontact import models

    params = {k: v for k, v in geo.items() if k != "kind"}
    if geo["kind"] == "arc":
        return models.arc_on_block(**params, **common)
    if geo["kind"] == "cylinder":
        return models.cylinder_on_block(**params, **common)
    if geo["kind"] == "punch":
        return models.rounded_punch(**params, **common)
    return models.two_blocks(foundation=geo["kind"] == "block_on_foundation", **params, **common)


def _case_message(message, contact) -> str:
    """An assembly error in the terms of the case file: the key it concerns, one line."""
    first = message.split("\n")[0].rstrip(": ")
    if "non-matching contact interface" in message:
        return "[contact] pairing: " + first.replace(" (pairing='segment')", ' (pairing = "segment" in [contact])')
    if message.startswith("friction must be"):
        return f"[contact] friction: {first}"
    for k in (1, 2):
        if message.startswith(f"tractions{k}["):
            return f"[loads.f{k}] {first[len(f'tractions{k}'):]}"
    if "obstacle" in contact and "obstacle" in message:
        return f"[contact.obstacle]: {first}"
    if message.startswith(("non-zero prescribed displacement", "dirichlet", "the prescribed displacements")) or "prescribed x displacements" in \
            message or "prescribed y displacements" in message:
        return f"[loads.dirichlet]: {first}"
    return message


def _tag_value(tag):
    return int(tag) if isinstance(tag, str) and tag.isdigit() else tag


# ------------------------------------------------------------------ reference
def _section_text(header, keys, commented=False) -> list:
    """``header`` and one line per key: ``key = example  # doc`` (commented out without an
    example); ``commented``: every line commented out (an alternative form of a section)."""
    rows = []
    for name, key in keys.items():
        code = f"{name} = {key.example}" if key.example is not None else f"# {name}"
        rows.append(("# " + code.lstrip("# ") if commented else code, key.doc))
    width = max(len(code) for code, _ in rows)
    return [header, *(f"{code:<{width}}  # {doc}" if doc else code for code, doc in rows)]


def _with_defaults(keys, defaults) -> dict:
    """``keys`` with "(default X)" added to the doc of every key that has a default in ``defaults``
    (the DEFAULTS of a geometry script)."""
    return {name: Key(k.kind, k.default, k.example, f"{k.doc} (default {_toml(defaults[name])})")
            if defaults.get(name) is not None else k for name, k in keys.items()}


def reference_text() -> str:
    """The case-file reference (annotated TOML, itself a valid case file), rendered from :data:`SCHEMA`
    and the defaults of the geometry scripts (imports gmsh)."""
    defaults = {kind: _geometry_script(kind).DEFAULTS for kind in ("two_blocks", "arc", "cylinder", "punch")}
    parts = [
        ["# Every section and key is optional except [geometry] kind (and the keys named 'required').",
         "title = \"optional free text\"  # the title of plots and animations"],
        _section_text("[geometry]  # kind = \"two_blocks\", \"block_on_foundation\" or \"inclined\"",
                      _with_defaults(BLOCK_GEOMETRY, defaults["two_blocks"])),
        _section_text("# [geometry]  # kind = \"arc\" instead (cfcontact.arc_on_block)",
                      _with_defaults(ARC_GEOMETRY, defaults["arc"]), True),
        _section_text("# [geometry]  # kind = \"cylinder\" instead (cfcontact.cylinder_on_block); loads: see below",
                      _with_defaults(CYLINDER_GEOMETRY, defaults["cylinder"]), True),
        _section_text("# [geometry]  # kind = \"punch\" instead (cfcontact.rounded_punch); loads: see below",
                      _with_defaults(PUNCH_GEOMETRY, {k: v for k, v in defaults["punch"].items() if k != "zone"}),
                      True),
        _section_text("# [geometry]  # kind = \"msh\" instead: both keys required", MSH_GEOMETRY, True),
        _section_text("[material]", SCHEMA["material"]),
        _section_text("[contact]", {k: v for k, v in SCHEMA["contact"].items() if k != "obstacle"}),
        _section_text(f"# [contact.obstacle]  # {SCHEMA['contact']['obstacle'].doc.split(';')[0]}: kind = "
                      '"block_on_foundation" or a .msh', {
                          "kind": Key("str", None, '"circle"',
                                      '"circle" (center, radius[, inside]) or "line" (point, normal)'),
                          "center": Key("vec", None, "[1.5, -10.0]", _OBSTACLE_DOCS["center"]),
                          "radius": Key("float", None, "10.0", _OBSTACLE_DOCS["radius"]),
                          "inside": Key("bool", None, "false", f"kind = \"circle\": {_OBSTACLE_DOCS['inside']}"),
                          "point": Key("vec", None, "[0.0, -1.0e-3]", f"kind = \"line\": {_OBSTACLE_DOCS['point']}"),
                          "normal": Key("vec", None, "[0.0, 1.0]", f"kind = \"line\": {_OBSTACLE_DOCS['normal']}"),
                      }, True),
    ]
    loads = {k: v for k, v in SCHEMA["loads"].items() if k not in ("f1", "f2", "dirichlet")}
    parts.append(_section_text("[loads]  # required for kind = \"msh\": clamp, [loads.f1], [loads.f2]", loads))
    for key in ("f1", "f2"):
        spec = SCHEMA["loads"][key]
        tag, value = spec.example.strip("{}").split(" = ")
        parts.append(_section_text(f"[loads.{key}]  # {spec.doc}", {tag: Key("tractions", None, value)}))
    parts[-1] += ["# a traction on a window of a piece (mesh coordinates), or a list of tractions (summed):",
                  "#   bottom2 = {value = [7.0e2, 0.0], x = [2.5, 2.6]}",
                  "#   top1 = [[0.0, -1.0e6], {value = [0.0, 4.0e5], x = [2.2, 2.3]}]",
                  "#   right1 = {value = [1.0e6, 0.0], y = [0.5, 1.0]}"]
    parts.append([
        "# [loads.dirichlet]  # prescribed displacement components (not on contact1/contact2 unless zero):",
        "#   a number, or [value at alpha = 0, value at alpha = 1]: u_D(alpha) = (1 - alpha) u_D(0) + alpha u_D(1)",
        "# top1 = {x = 0.0, y = [0.0, -1.0e-3]}  # the top pushed down along the path",
        "# left1 = {x = 0.0}                     # a roller (symmetry plane): u_x = 0, u_y free",
        f"# Defaults of kind = \"cylinder\" / \"punch\": clamp = [\"bottom2\"], top1 = {{x = 0.0, y = [0.0, -d]}} "
        f"(d = {' / '.join(_toml(_pressed_default(k, 'indentation')[1]) for k in PRESSED_KINDS)}),",
        "#   and with half = true sym1 = {x = 0.0}, sym2 = {x = 0.0}; a [loads.dirichlet] table replaces them all.",
    ])
    for name in ("path", "output"):
        parts.append(_section_text(f"[{name}]", SCHEMA[name]))
    return "\n\n".join("\n".join(p) for p in parts) + "\n"
