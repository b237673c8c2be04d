"""Reports of a traced path: what ``cfcontact info`` prints and ``summary.json`` holds, and the
worst residual of its stored points (the demo's and the benchmark's check).

:func:`path_report` gathers status, transitions, folds, the multiplicity over alpha
(:meth:`~cfcontact.solution_path.SolutionPath.multiplicity_intervals`), events, solver
statistics and options as strict JSON data; :func:`format_report` renders it as text.
"""

from __future__ import annotations

from cfcontact.jsonio import jsonable
from cfcontact.ssnm import verify


def worst_residual(system, path, solver=None, batch=128, indices=None, points=None) -> float:
    """Worst relative violation of (1)-(3) over the stored points of a path (or the points
    ``indices``); lazy displacements are formed in batches and dropped.  ``points``: the
    (alpha, y) pairs to check instead (e.g. ``path.points``: y of lazy branches interpolated
    between the branch's end points)."""
    if points is None:
        points = path.iter_points(batch, indices)
    return max((verify(system, y, alpha, solver=solver).worst() for alpha, y in points), default=0.0)


def path_report(path) -> dict:
    """Everything ``info`` shows, as a JSON-able dict (non-finite numbers as None)."""
    mult, at = path.max_multiplicity()
    return jsonable({
        "method": path.method, "status": path.status, "n": path.n, "m": path.m,
        "parameter": getattr(path, "parameter", "alpha"),
        "alpha_start": path.alpha_start, "alpha_end": path.alpha_end,
        "points": len(path.alphas), "branches": len(path.branches),
        "transitions": [t.to_dict() for t in path.transitions],
        "folds": [t.alpha for t in path.folds],
        "multiplicity": [{"alpha_lo": a, "alpha_hi": b, "solutions": k} for a, b, k in path.multiplicity_intervals()],
        "max_multiplicity": mult, "alpha_of_max": at,
        "events": [e.to_dict() for e in path.events], "stats": path.stats, "options": path.options,
    })


def format_report(rep, source) -> str:
    """The text of ``cfcontact info``: a :func:`path_report` of the saved path ``source``."""
    par = "F (friction)" if rep.get("parameter") == "friction" else "alpha"
    lines = [f"saved path: {source}",
             f"method {rep['method']}, status {rep['status']}, n = {rep['n']} DOFs, m = {rep['m']} contact nodes, "
             f"{par} {rep['alpha_start']:g} -> {rep['alpha_end']:g}",
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
