"""JSON and output-folder helpers shared by the saved path, checkpoints, reports and output files."""

from __future__ import annotations

import json
import math
import os

import numpy as np


def jsonable(obj, strict: bool = True):
    """``obj`` with NumPy scalars and arrays turned into Python numbers and lists, tuples into
    lists and dict keys into strings.  ``strict``: non-finite floats become None (RFC 8259 JSON);
    otherwise they stay (Python's json writes NaN / Infinity)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v, strict) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v, strict) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist(), strict)
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if (math.isfinite(obj) or not strict) else None
    return obj


def write_json(filename, obj, strict: bool = True) -> None:
    """Write ``jsonable(obj, strict)`` to ``filename`` (indent 1)."""
    with open(os.fspath(filename), "w") as fh:
        json.dump(jsonable(obj, strict), fh, indent=1)


def read_json(filename):
    with open(os.fspath(filename)) as fh:
        return json.load(fh)


def holds_format(folder, filename, fmt, empty: bool = False) -> bool:
    """Is ``folder`` one that cfcontact wrote: its JSON file ``filename`` says ``"format": fmt``
    (or, with ``empty``, it is an empty folder)?  Only such folders are replaced by a --force or a
    save."""
    folder = os.fspath(folder)
    if empty and os.path.isdir(folder) and not os.listdir(folder):
        return True
    try:
        return read_json(os.path.join(folder, filename)).get("format") == fmt
    except (OSError, ValueError, AttributeError):
        return False


def blocking_file(folder):
    """The file that stands where ``folder`` or one of its parents would have to be created (the
    nearest of them that exists, when it is not a folder), or None."""
    probe = os.path.abspath(os.fspath(folder))
    while not os.path.exists(probe) and os.path.dirname(probe) != probe:
        probe = os.path.dirname(probe)
    return None if os.path.isdir(probe) else probe
