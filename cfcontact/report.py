"""Reports of a traced path: what ``cfcontact info`` prints and ``summary.json`` holds, and the
worst residual of its stored points (the demo's and the benchmark's check).

:func:`path_report` gathers status, transitions, folds, the multiplicity over alpha
(:meth:`~cfcontact.solution_path.SolutionPath.multiplicity_intervals`), events, solver
statistics, options and the contact pairing (:func:`contact_report`) as strict JSON data;
:func:`format_report` renders it as text.  :func:`model_report` / :func:`format_model_report`
describe a built model (``cfcontact info CASE.toml``): its size and its pairing as the assembly
recorded it (``ContactSystem.info["contact"]``).
"""

from __future__ import annotations

import numpy as np

from cfcontact.jsonio import jsonable
from cfcontact.solution_path import parameter_name
from cfcontact.ssnm import verify


def worst_residual(system, path, solver=None, batch=128, indices=None, points=None) -> float:
    """Worst relative violation of (1)-(3) over the stored points of a path (or the points
    ``indices``); lazy displacements are formed in batches and dropped.  ``points``: the
    (alpha, y) pairs to check instead (e.g. ``path.points``: y of lazy branches interpolated
    between the branch's end points)."""
    if points is None:
        points = path.iter_points(batch, indices)
    return max((verify(system, y, alpha, solver=solver).worst() for alpha, y in points), default=0.0)


def compare_paths(seed, exact, friction) -> dict:
    """Two paths of one system (``seed``: the seed method's, ``exact``: the exact method's): the
    same sequence of set changes (node, set, kind)?  Transition alphas within the seed's h_min?
    The same sequence of branch sets (``same_branch_sets``: where several nodes change at one
    alpha, the seed method names one of them)?"""
    ks = [(t.node, t.set, t.kind) for t in seed.transitions]
    ke = [(t.node, t.set, t.kind) for t in exact.transitions]
    h_min = float(seed.options.get("h_min", 1e-5))
    same = ks == ke
    diffs = [abs(a.alpha - b.alpha) for a, b in zip(seed.transitions, exact.transitions)]
    in_bracket = all(s.bracket[0] - 1e-12 <= e.alpha <= s.bracket[1] + 1e-12
                     for s, e in zip(seed.transitions, exact.transitions))
    first = next((i for i, (a, b) in enumerate(zip(ks, ke)) if a != b), None if same else min(len(ks), len(ke)))
    return {"same_set_changes": same, "first_difference": first, "h_min": h_min,
            "max_alpha_difference": max(diffs, default=0.0),
            "alphas_within_h_min": bool(same and all(d <= h_min for d in diffs)),
            "exact_alpha_in_seed_bracket": bool(same and in_bracket),
            "same_branch_sets": branch_states(seed, friction) == branch_states(exact, friction)}


def branch_states(path, friction) -> list:
    """The state of every node on each of the path's branches (canonical codes, as lists): two
    paths with equal lists pass through the same sequence of sets, whatever node names their
    transitions give."""
    from cfcontact.exact import canonical_codes

    return [canonical_codes(b.sets, friction).tolist() for b in path.branches]


# ------------------------------------------------------------------ contact pairing
def _range(values):
    values = np.asarray(values, dtype=float)
    return [float(values.min()), float(values.max())] if values.size else [0.0, 0.0]


def contact_report(path=None, *, system=None, declared=None) -> dict:
    """How the contact pairs of a model or a saved path were formed, as JSON data: ``pairing``,
    ``slave``, ``master``, ``pairs``, ``excluded`` (with ``excluded_reasons``),
    ``dropped_prescribed``, ``search_distance``, ``obstacle``, ``gap_range``, ``no_tangent`` (pairs
    without tangential unknown) and ``source``.

    From a ContactSystem (``system``): everything, as its assembly recorded it.  From a saved
    path: what the path holds -- the pairs, the slave side (body 1 or 2), the master (a body, an
    obstacle, a rigid foundation), the pairs without tangential unknown, the gap when the path
    stores one -- completed by ``declared`` (the pairing, slave and search distance its case
    file asked for); what neither tells is None (the excluded nodes are not stored with a path)."""
    if system is not None:
        info = system.info.get("contact", {})
        rigid = bool(system.info.get("rigid_foundation"))
        slave = info.get("slave")
        master = info.get("master") or ("obstacle" if info.get("obstacle") else "rigid foundation" if rigid else
                                        {"contact1=10": "contact2=20", "contact2=20": "contact1=10"}.get(slave))
        return {"source": "model", "pairing": info.get("pairing"), "slave": slave, "master": master,
                "pairs": system.m, "excluded": info.get("excluded"), "excluded_reasons": info.get("excluded_reasons"),
                "dropped_prescribed": info.get("dropped_prescribed"), "search_distance": info.get("search_distance"),
                "obstacle": info.get("obstacle"), "gap_range": _range(system.gap),
                "no_tangent": int(np.count_nonzero(system.no_tangent))}
    declared = declared or {}
    geo = path.geometry
    nodes = np.asarray(geo.contact_nodes, dtype=np.int64).reshape(-1, 2)
    body2_slave = bool(len(nodes)) and bool(np.all(geo.slave_nodes() == nodes[:, 1]))
    obstacle = getattr(geo, "obstacle", None)
    master = ("obstacle" if obstacle else "rigid foundation" if len(nodes) and np.all(nodes[:, 1] < 0) else
              "contact1=10" if body2_slave else "contact2=20")
    # node-to-segment rows couple a slave node with two master nodes
    N = path.N.tocoo()
    row_node = np.unique(np.column_stack([N.row, np.asarray(geo.dof_node)[N.col]]).reshape(-1, 2), axis=0)
    per_row = np.bincount(row_node[:, 0], minlength=path.m)
    pairing = declared.get("pairing") or ("segment" if np.any(per_row > 2) or obstacle else None)
    gap = getattr(path, "gap", None)
    no_tangent = np.diff(path.T.tocsr().indptr) == 0
    return {"source": "saved path", "pairing": pairing,
            "slave": declared.get("slave") or ("contact2=20" if body2_slave else "contact1=10"), "master": master,
            "pairs": path.m, "excluded": None, "excluded_reasons": None, "dropped_prescribed": None,
            "search_distance": declared.get("search_distance"), "obstacle": obstacle,
            "gap_range": None if gap is None else _range(gap), "no_tangent": int(np.count_nonzero(no_tangent))}


#: why a slave node was left out (cfcontact.pairing.Pairing.excluded_reason)
_EXCLUDED = {"miss": "whose normal misses the master", "back": "whose normal meets only the master's back",
             "distance": "beyond the search distance"}


def contact_lines(c) -> list:
    """The text lines of a :func:`contact_report`."""
    def num(v):
        return "none" if v is None else f"{v:.6g}"

    master = c["master"] if c["master"] != "obstacle" else f"obstacle {c['obstacle']}"
    lines = [f"contact: {c['pairs']} pairs, {c['pairing'] or 'unrecorded'} pairing, slave {c['slave']}, "
             f"master {master}"]
    if c["excluded"] is None:
        lines.append("  excluded nodes: not stored with a saved path (cfcontact info CASE.toml lists them); "
                     f"search distance {num(c['search_distance'])}")
    else:
        why = ", ".join(f"{v} {_EXCLUDED.get(k, k)}" for k, v in sorted((c["excluded_reasons"] or {}).items()))
        lines.append(f"  excluded nodes: {c['excluded']}" + (f" ({why})" if why else "")
                     + f"; search distance {num(c['search_distance'])}"
                     + (f"; {c['dropped_prescribed']} pair(s) dropped (every DOF prescribed)"
                        if c.get("dropped_prescribed") else ""))
    if c["gap_range"] is None:
        lines.append("  initial gap: not stored with a saved path yet (cfcontact info CASE.toml computes it)")
    else:
        lines.append(f"  initial gap: {c['gap_range'][0]:.6g} .. {c['gap_range'][1]:.6g}")
    if c["no_tangent"]:
        lines.append(f"  {c['no_tangent']} pair(s) without tangential unknown (tangential DOFs prescribed)")
    return lines


def model_report(system, source=None, kind=None) -> dict:
    """The size and the contact pairing of a built model (``cfcontact info CASE.toml``), JSON data;
    ``kind``: the case's ``[geometry] kind``, named as the model (else the builder's name, e.g.
    "two_blocks" for "block_on_foundation" and "inclined")."""
    info = system.info
    return jsonable({"source": source, "model": kind or info.get("model"), "n": system.n, "m": system.m,
                     "num_nodes": info.get("num_nodes"), "num_cells": info.get("num_cells"),
                     "cell_type": info.get("cell_type"), "dirichlet": info.get("dirichlet"),
                     "contact": contact_report(system=system)})


def format_model_report(rep) -> str:
    lines = [f"case: {rep['source']}",
             f"model {rep['model']}: n = {rep['n']} DOFs, m = {rep['m']} contact pairs, {rep['num_nodes']} nodes, "
             f"{rep['num_cells']} cells ({rep['cell_type']})"]
    if rep.get("dirichlet"):
        lines.append("prescribed: " + "; ".join(f"{piece} " + ", ".join(f"u_{c} {v[0]:g} -> {v[1]:g}" for c, v in
                                                                          comps.items())
                                                 for piece, comps in rep["dirichlet"].items()))
    return "\n".join(lines + contact_lines(rep["contact"]))


def path_report(path, declared=None) -> dict:
    """Everything ``info`` shows, as a JSON-able dict (non-finite numbers as None); ``declared``:
    see :func:`contact_report`."""
    mult, at = path.max_multiplicity()
    contact = None if getattr(path, "geometry", None) is None else contact_report(path, declared=declared)
    return jsonable({
        "method": path.method, "status": path.status, "n": path.n, "m": path.m,
        "parameter": getattr(path, "parameter", "alpha"),
        "load_alpha": getattr(path, "load_alpha", None),  # (a path over F: its fixed load f(alpha))
        "alpha_start": path.alpha_start, "alpha_end": path.alpha_end,
        "points": len(path.alphas), "branches": len(path.branches),
        "transitions": [t.to_dict() for t in path.transitions],
        "folds": [t.alpha for t in path.folds],
        "multiplicity": [{"alpha_lo": a, "alpha_hi": b, "solutions": k} for a, b, k in path.multiplicity_intervals()],
        "max_multiplicity": mult, "alpha_of_max": at,
        "reach": path.reach(), "turned_back": path.turned_back(),
        "events": [e.to_dict() for e in path.events], "stats": path.stats, "options": path.options,
        "contact": contact,
        "system_checksum": getattr(path, "system_checksum", None),
    })


def turned_back_text(reach, start, parameter="alpha", unverified=False) -> str:
    """What a path that completed without reaching its end means (see SolutionPath.turned_back);
    ``parameter``: the path's ("alpha", or "friction" for a path in F); ``unverified``: it has
    transitions the seed method could not verify (:func:`unverified_text`), so the turn may be its
    fold rule's and not the problem's."""
    par = parameter_name(parameter)
    most = "at most" if reach >= start else "at least"  # (a path traced towards smaller values)
    head = f"the path turned back: it reaches {par} = {reach:.10g} {most} and left its range at {par} = {start:g}; "
    if unverified:
        return head + (f"it passed transitions that could not be verified, so solutions beyond {reach:.10g} may "
                       f"still be connected to the start (method = \"exact\" follows them)")
    return head + (f"beyond {reach:.10g} no solution lies on it (solutions there, if any, are not connected to the "
                   f"start)")


def unverified_alphas(events) -> list:
    """The alphas of a path's "unverified_transition" events (PathEvent objects or their dicts)."""
    out = []
    for e in events:
        kind, alpha = (e.get("kind"), e.get("alpha")) if isinstance(e, dict) else (e.kind, e.alpha)
        if kind == "unverified_transition":
            out.append(float(alpha))
    return out


def unverified_text(alphas) -> str:
    """What the seed method's unverified transitions mean: no candidate set change gave a solution
    on either side of the step (two set changes within h_min, say) and the fold rule was applied;
    the path may have left the solution path there."""
    where = ", ".join(f"{a:.10g}" for a in alphas[:5]) + (", ..." if len(alphas) > 5 else "")
    return (f"{len(alphas)} transition(s) could not be verified (alpha = {where}): no candidate set change gave a "
            f"solution there (e.g. two set changes closer than h_min) and the seed's fold rule was applied; the "
            f"path may have left the solution path (method = \"exact\" resolves such points)")


def _count(k, noun) -> str:
    """``k`` and ``noun``, in the plural unless k is 1."""
    return f"{k} {noun}" if k == 1 else f"{k} {noun}s"


def format_report(rep, source) -> str:
    """The text of ``cfcontact info``: a :func:`path_report` of the saved path ``source``."""
    friction = rep.get("parameter") == "friction"
    par = "F (friction)" if friction else "alpha"
    x = parameter_name(rep.get("parameter"))  # the path's parameter in the lines below
    lines = [f"saved path: {source}",
             f"method {rep['method']}, status {rep['status']}, n = {rep['n']} DOFs, m = {rep['m']} contact nodes, "
             f"{par} {rep['alpha_start']:g} -> {rep['alpha_end']:g}"
             + (f" at the load f(alpha = {rep['load_alpha']:.10g})" if friction and rep.get("load_alpha") is not None
                else ""),
             f"points {rep['points']}, branches {rep['branches']}, transitions {len(rep['transitions'])} "
             f"({sum(t['kind'] == 'transversal' for t in rep['transitions'])} transversal, "
             f"{_count(len(rep['folds']), 'fold')})"]
    if rep.get("system_checksum"):
        lines.append(f"system checksum {rep['system_checksum']} (SHA-256 of n, m, K, N, T, f1, f2, friction, gap, rho)")
    if rep["alpha_of_max"] is not None:
        lines.append(f"max multiplicity {rep['max_multiplicity']} (at {x} = {rep['alpha_of_max']:.10g})")
    unverified = unverified_alphas(rep.get("events", []))
    if rep.get("turned_back"):
        lines.append(turned_back_text(rep["reach"], rep["alpha_start"], rep.get("parameter", "alpha"),
                                      unverified=bool(unverified)))
    if unverified:
        lines.append(unverified_text(unverified))
    lines.append("")
    if rep["transitions"]:
        lines.append("transitions:")
        lines.append(f"  {'#':>4}  {'kind':<11}  {x:>16}  {'node':>5}  {'set':<4}  branches")
        for t in rep["transitions"]:
            lines.append(f"  {t['index']:>4}  {t['kind']:<11}  {t['alpha']:>16.10g}  {t['node']:>5}  "
                         f"{str(t['set']):<4}  {t['from_branch']} -> {t['to_branch']}")
    else:
        lines.append("transitions: none")
    lines.append("folds: " + (", ".join(f"{x} = {a:.10g}" for a in rep["folds"]) if rep["folds"] else "none"))
    lines.append(f"multiplicity over {x}:")
    for iv in rep["multiplicity"]:
        lines.append(f"  [{iv['alpha_lo']:.10g}, {iv['alpha_hi']:.10g}]  {iv['solutions']} solution(s)")
    if not rep["multiplicity"]:
        lines.append(f"  (the path covers no {x} interval)")
    if rep["events"]:
        lines.append("events:")
        for e in rep["events"]:
            lines.append(f"  {e['kind']} at {x} = {e['alpha']}: {e['message']}")
    else:
        lines.append("events: none")
    st = rep["stats"] or {}
    if st:
        parts = [f"{k} {v:.3g} s" if k.endswith("time") else f"{k} {v}" for k, v in st.items()]
        lines.append("stats: " + ", ".join(parts))
    timings = {k: v for k, v in (rep.get("timings") or {}).items() if isinstance(v, (int, float))}
    if timings:
        lines.append("timings (summary.json): " + ", ".join(f"{k} {v:.3g} s" for k, v in timings.items()))
    if rep.get("contact"):
        lines += contact_lines(rep["contact"])
    return "\n".join(lines)
