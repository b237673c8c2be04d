"""``cfcontact map CASE.toml``: the friction map of a case's load path, written to a folder.

Builds the case's model (:func:`cfcontact.case.build_system`), computes the multiplicity map on
an alpha x F grid (:func:`cfcontact.fmap.multiplicity_map`), the fold curves with their cusps
and the path's critical friction (:func:`cfcontact.fmap.fold_curves`), and writes
``map.png`` (and the case's other [output] plot formats), ``map.json`` and ``map.npz``
(:func:`cfcontact.fmap.save_map`) into ``<case stem>_map/`` (or the given folder), atomically:
the files appear together or not at all.  Library code: nothing is printed.
"""

from __future__ import annotations

import os
import shutil
import time

import numpy as np

from cfcontact.case import CaseError, build_system
from cfcontact.jsonio import holds_format
from cfcontact.run import replaceable_output

__all__ = ["map_case", "check_grid", "DEFAULT_POINTS"]

DEFAULT_POINTS = 200


def default_friction_range(case) -> tuple:
    """(0, the case's largest [contact] friction), at least (0, 1)."""
    fr = case["contact"].get("friction", 0.0)
    top = float(max(fr) if isinstance(fr, list) else fr)
    return 0.0, max(top, 1.0)


def check_grid(friction_range, n_frictions, n_alphas):
    """CaseError unless the friction range (None: the case's default) is 0 <= F0 < F1 (finite)
    and both grids have 2..100000 points."""
    if friction_range is not None:
        F_lo, F_hi = friction_range
        if not (0 <= F_lo < F_hi and np.isfinite(F_hi)):
            raise CaseError(f"--friction-range: need 0 <= F0 < F1, got {F_lo} {F_hi}")
    for name, n in (("--frictions", n_frictions), ("--alphas", n_alphas)):
        if not 2 <= int(n) <= 100000:
            raise CaseError(f"{name}: need 2..100000 grid points, got {n}")


def map_case(case, output=None, friction_range=None, n_frictions=DEFAULT_POINTS, n_alphas=DEFAULT_POINTS,
             marks=None, curves=True, force=False) -> dict:
    """Compute and write the friction map of a validated case; returns a summary (files, the
    critical friction, timings).  ``marks``: friction values drawn as lines (default: the case's
    friction when it is one number)."""
    from cfcontact.fmap import fold_curves, multiplicity_map, save_map
    from cfcontact.plotting import plot_friction_map, save_figure

    if output:
        out = os.path.abspath(output).rstrip(os.sep)
    else:
        stem = os.path.splitext(os.path.basename(case["_file"]))[0]
        out = os.path.join(os.path.dirname(case["_file"]), f"{stem}_map")
    replaceable_output(out, force, _is_map_folder, "a cfcontact map folder (no map.json); choose another --output")
    F_lo, F_hi = friction_range if friction_range is not None else default_friction_range(case)
    check_grid((F_lo, F_hi), n_frictions, n_alphas)
    if marks is None:
        fr = case["contact"].get("friction", 0.0)
        marks = [] if isinstance(fr, list) else [float(fr)]
    p = case["path"]
    a0, a1 = p["alpha_start"], p["alpha_end"]
    t0 = time.perf_counter()
    system = build_system(case)
    t_build = time.perf_counter() - t0
    alphas = np.linspace(min(a0, a1), max(a0, a1), int(n_alphas))
    frictions = np.linspace(F_lo, F_hi, int(n_frictions))
    fmap = multiplicity_map(system, alphas, frictions, a0, a1)
    fc = fold_curves(system, (F_lo, F_hi), (a0, a1)) if curves else None
    tmp = out + ".partial"
    shutil.rmtree(tmp, ignore_errors=True)
    os.makedirs(tmp)
    crit = fc.critical if fc is not None else None
    extra = {"case_file": case["_file"], "title": case.get("title"), "build_time": t_build}
    files = save_map(tmp, fmap, fc, marks, extra)
    fig = plot_friction_map(fmap, fc, crit, marks, title=case.get("title"))
    for fmt in case["output"]["plot_formats"]:
        save_figure(fig, os.path.join(tmp, f"map.{fmt}"))
        files.append(f"map.{fmt}")
    if os.path.isdir(out):
        shutil.rmtree(out)
    elif os.path.exists(out):
        os.remove(out)
    os.rename(tmp, out)
    return {"output": out, "files": files, "critical": crit, "map_timings": fmap.timings,
            "curve_timings": fc.timings if fc is not None else None,
            "curves": len(fc.curves) if fc is not None else 0, "cusps": len(fc.cusps) if fc is not None else 0,
            "untraced": [(float(F), st) for F, st in zip(fmap.frictions, fmap.status) if st != "completed"],
            "max_solutions": max([int(fmap.counts.max(initial=0))] + [c for iv in fmap.intervals for _, _, c in iv])}


def _is_map_folder(path) -> bool:
    """Is ``path`` a folder that :func:`map_case` wrote (its map.json says so)?  Only such a
    folder is replaced with ``force``."""
    from cfcontact.fmap import MAP_FORMAT

    return holds_format(path, "map.json", MAP_FORMAT)
