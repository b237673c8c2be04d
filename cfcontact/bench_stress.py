"""Benchmark parts for long interfaces and hard cases of the exact method (see docs/bench.md).

Part C -- long interfaces: two stacked strips of length L = m / 50 and height 1, m x 5 cells per
body (triangles), clamped at their left ends, the free edges loaded by uniform tractions with
seeded random values (:func:`strip`), m = 1000, 2000, 4000 contact nodes, F = 0.3 and 30.  Every
row runs in a fresh subprocess (peak memory = its ``ru_maxrss``) and reports n, m, the time split
assembly | factorization of K | condensation (S) | path (of which the start: until the first path
point, e.g. SSNM at alpha = 0 and a homotopy where it fails), the transitions, the time per
transition (the path after its start, per transition), the branches solved by factorization
updates and the refactorizations, the worst residual of (1)-(3) over sampled stored points, and
the log-log slope of the time per transition against m (and of the path's time, start included,
per transition).
A row stops at its time limit (``--time-limit``, status "time limit": the path so far is
measured).

Part D -- hard cases: the strips at m = 500, 1000, 2000 with uniform and random tractions (random:
uniform tractions plus seeded random nodal forces on the free edges' nodes), F = 0.3 and 30; the
cylinder on a block and the rounded punch pressed along their indentation paths; a degenerate point
with many vanishing indicators (two blocks closing along their whole interface at once); and 200
random load paths on each model of the demos (:mod:`cfcontact.demo_models`) at F = 30.  Reported:
how many runs completed, got stuck, cycled, closed a loop, hit the transition cap or failed to
start; the transitions; the degenerate points resolved (and the largest number of indicators
vanishing at one); the time; the cost of a degenerate point against an ordinary branch; the cost
of a start that SSNM could not find (homotopy) against one it found; and, with every row and
path traced by the seed method too (``--seed-check S`` seconds per path), whether it gives the
same sequence of states and, where not, what its own runs say about the difference
(:func:`_seed_check`).

Run:  cfcontact bench --part C [--quick] [--time-limit S]
      cfcontact bench --part D [--quick] [--paths N] [--seed-check S]
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

#: Part C: contact nodes of the strips, friction coefficients, seed of the tractions.
C_SIZES = (1000, 2000, 4000)
C_FRICTIONS = (0.3, 30.0)
#: The quick sizes per friction coefficient: at F = 30 the strip's path grows from 136 transitions
#: (m = 100) and 760 (m = 120) to tens of thousands of folds at m = 150-200 (see docs/bench.md), too
#: long for a check run.
QUICK_C_SIZES = {0.3: (100, 200), 30.0: (100, 120)}
#: Part D: the strips' sizes, and the number of random load paths per demo model.
D_SIZES = (500, 1000, 2000)
QUICK_D_SIZES = (100,)
D_PATHS = 200
QUICK_D_PATHS = 10
#: Part D: each row and random load path is traced by the seed method too, at most this many
#: seconds (0: not at all), and compared with the exact path where the seed method completes; where the
#: two differ, the seed method is run again with its smallest step h_min divided by 10, 100, ...
#: (SEED_FINER_STEPS times) to see whether it agrees once it resolves the transitions.
SEED_CHECK_LIMIT = 60.0
SEED_FINER_STEPS = 2
#: Worst residual over at most this many evenly spaced stored points of a row.
VERIFY_POINTS = 60
TRACTION = 1e7  # Pa: size of the random uniform tractions of the strips


def peak_rss_gib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # ru_maxrss is in KiB on Linux


def factorization_time(solver) -> float:
    """The time K's factorization took in a CondensedSolver's set-up: PETSc's log events
    (symbolic + numeric LU or Cholesky; PETSc.Log must have begun) when PETSc factored it, the
    envelope factor's own time (RCM order, pattern, LDL^T) when cfcontact.native did."""
    if solver.k_factorization == "cholesky/envelope":
        return solver.timings["factorization"]
    from petsc4py import PETSc

    return sum(PETSc.Log.Event(e).getPerfInfo()["time"]
               for e in ("MatLUFactorSym", "MatLUFactorNum", "MatCholFctrSym", "MatCholFctrNum"))


def strip(m, friction, seed=0, kind="uniform", cells_across=5):
    """Two stacked strips (L = m / 50, height 1, m x cells_across triangles per body, steel)
    clamped at their left ends; the free edges (top1, right1, bottom2, right2) carry uniform
    tractions with seeded random values, body 1's top pressed down.  ``kind="random"`` adds
    seeded random nodal forces (of the tractions' size per edge node) on those edges' nodes."""
    from cfcontact.models import two_blocks

    rng = np.random.default_rng(seed)

    def tractions():
        t = {k: tuple(float(v) for v in rng.uniform(-TRACTION, TRACTION, 2)) for k in ("top1", "right1", "bottom2",
                                                                                       "right2")}
        t["top1"] = (t["top1"][0], -abs(t["top1"][1]) - 0.2 * TRACTION)
        return t

    t1, t2 = tractions(), tractions()
    L = m / 50.0
    system = two_blocks(nx=m, ny=cells_across, length=L, height=1.0, cell="triangle", friction=friction,
                        tractions1=t1, tractions2=t2)
    if kind == "random":
        g = system.geometry
        x, y = g.points[g.dof_node, 0], g.points[g.dof_node, 1]
        on_edge = (np.isclose(y, 1.0) | np.isclose(y, -1.0) | np.isclose(x, L)) & ~np.isclose(x, 0.0)
        h = L / m
        f1, f2 = system.loads_numpy()
        f1 = f1 + on_edge * rng.uniform(-1, 1, system.n) * TRACTION * h
        f2 = f2 + on_edge * rng.uniform(-1, 1, system.n) * TRACTION * h
        system = system.with_loads(f1, f2)
    elif kind != "uniform":
        raise ValueError(kind)
    return system


def _verify_sample(system, path, solver):
    from cfcontact.report import worst_residual

    P = len(path.alphas)
    idx = None if P <= VERIFY_POINTS else np.unique(np.linspace(0, P - 1, VERIFY_POINTS).round().astype(int))
    return worst_residual(system, path, solver, indices=idx)


def worker(spec) -> dict:
    """One row of Part C / D: build, factor, trace (time-limited), measure."""
    from petsc4py import PETSc

    PETSc.Log.begin()
    import cfcontact
    from cfcontact.condensed import CondensedSolver

    res = dict(spec, stage="assembly")

    def dump():
        print("BENCH-PARTIAL " + json.dumps(res), flush=True)

    t0 = time.perf_counter()
    if spec["model"] == "strip":
        system = strip(spec["m"], spec["friction"], spec.get("seed", 0), spec.get("kind", "uniform"),
                       spec.get("cells_across", 5))
    elif spec["model"] in ("cylinder", "punch"):
        system = _pressed(spec["model"], spec["friction"], spec.get("size"))
    elif spec["model"] == "closing":
        system = _closing(spec["m"], spec["friction"])
        import cfcontact.exact as exact

        exact.APEX_RULE = bool(spec.get("apex_rule", False))  # (the lexicographic rule on m nodes, see part_d)
    else:
        raise ValueError(spec["model"])
    res.update(n=system.n, m=system.m, assembly_time=time.perf_counter() - t0, stage="factorization")
    dump()
    t0 = time.perf_counter()
    solver = CondensedSolver(system)
    t_setup = time.perf_counter() - t0
    t_fact = factorization_time(solver)
    res.update(factorization_time=t_fact, condensation_time=solver.timings["condensation"],
               setup_other_time=t_setup - t_fact - solver.timings["condensation"], stage="path")
    dump()
    limit = float(spec.get("time_limit", 600.0))
    branch_times = []
    last = [time.perf_counter()]

    def callback(point):
        now = time.perf_counter()
        branch_times.append(now - last[0])
        last[0] = now
        return now - t0 > limit

    t0 = time.perf_counter()
    try:
        path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver, callback=callback,
                                    monitor=lambda progress: time.perf_counter() - t0 > limit)
    except cfcontact.StartInterrupted as exc:  # the time limit ended the homotopy start: no path point
        path = None
        res.update(status="time limit (start)", transitions=0, start=exc.progress.stage,
                   homotopy_transitions=exc.progress.transitions, homotopy_t=exc.progress.t)
    t_path = time.perf_counter() - t0
    res.update(path_time=t_path, rss_after_path_gib=peak_rss_gib())
    if path is not None:
        _measure_path(spec, res, system, solver, path, branch_times, dump)
    total = res["assembly_time"] + t_setup + t_path
    res.update(total_time=total, ratio=total / (res["assembly_time"] + t_fact), peak_rss_gib=peak_rss_gib(),
               stage="done")
    return res


def _measure_path(spec, res, system, solver, path, branch_times, dump):
    """A worker's measures of its traced path (added to ``res``): counts, the cost of its
    degenerate points against an ordinary branch, the worst residual of a sample of its points."""
    from cfcontact.condensed import CondensedSolver

    t_path = res["path_time"]
    st = solver.stats.as_dict()
    t_start = branch_times[0] if branch_times else 0.0  # until the start point was accepted
    res.update(status="time limit" if path.status == "stopped by callback" else path.status,
               transitions=len(path.transitions), folds=len(path.folds), start_time=t_start,
               time_per_transition=(t_path - t_start) / max(1, len(path.transitions)),
               path_time_per_transition=t_path / max(1, len(path.transitions)),
               dense_updates=st["dense_updates"], refactorizations=st["dense_factorizations"],
               true_corrections=st.get("true_corrections", 0), start=path.stats.get("start"),
               homotopy_transitions=path.stats.get("homotopy_transitions", 0),
               degenerate_points=path.stats.get("degenerate_points", 0),
               max_vanishing=path.stats.get("max_vanishing", 0), branch_points=path.stats.get("branch_points", 0),
               backtracks=path.stats.get("backtracks", 0),
               events=[{"kind": e.kind, "alpha": e.alpha, "message": e.message[:300]} for e in path.events][:10],
               stage="verify")
    degenerate = _degenerate(path)
    if degenerate and len(branch_times) > 1:
        worst = _worst_degenerate(path, branch_times)
        ordinary_times = [branch_times[i + 1] for i in range(len(path.transitions))
                          if i not in set(degenerate) and i + 1 < len(branch_times)]
        if spec["model"] == "closing":  # its path has no ordinary branch: those of the sheared model
            ref = _closing(spec["m"], spec["friction"], shear=True)
            ordinary_times = _branch_times(ref, CondensedSolver(ref))[1:]
            # and its point's cost the median of three runs, as the ordinary branch is a median: one
            # run is at the mercy of a garbage collection (2.3 ms or 3.7 ms at m = 48)
            again = []
            for _ in range(2):
                times, p = _branch_times(system, CondensedSolver(system), path=True)
                again.append(_worst_degenerate(p, times))
            res["degenerate_times"] = [float(worst), *again]
            worst = float(np.median(res["degenerate_times"]))
        ordinary = float(np.median(ordinary_times)) if ordinary_times else float("nan")
        res.update(ordinary_branch_time=ordinary, worst_degenerate_time=float(worst),
                   degenerate_cost_ratio=float(worst / ordinary) if ordinary > 0 else None)
    dump()
    t0 = time.perf_counter()
    res["worst_residual"] = _verify_sample(system, path, solver)
    res["verify_time"] = time.perf_counter() - t0
    if spec.get("seed_check") and path.status == "completed":
        res["stage"] = "seed method"
        dump()
        res.update(_seed_check(lambda: system.with_loads(system.f1, system.f2), path, spec["friction"],
                               float(spec["seed_check"])))


def _branch_times(system, solver, path=False):
    """Wall time from one accepted point of the exact path to the next (one branch each); with
    ``path``, (times, the path)."""
    import cfcontact

    times, last = [], [time.perf_counter()]

    def tick(point):
        now = time.perf_counter()
        times.append(now - last[0])
        last[0] = now

    traced = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver, callback=tick)
    return (times, traced) if path else times


def _degenerate(path) -> list:
    """The indices of a path's transitions at degenerate points (several pivots or changes)."""
    return [i for i, t in enumerate(path.transitions) if t.pivots or len(t.changes) > 1]


def _worst_degenerate(path, branch_times) -> float:
    """The longest time of a degenerate point's transition (branch_times[i + 1]: from the entry of
    branch i to that of branch i + 1, transition i)."""
    return float(max(branch_times[i + 1] for i in _degenerate(path) if i + 1 < len(branch_times)))


def _pressed(model, friction, size=None):
    """The cylinder on a block / the rounded punch pressed along their indentation path."""
    import cfcontact

    if model == "cylinder":
        return cfcontact.cylinder_on_block(friction=friction, indentation=(0.0, 0.03),
                                           **({"size": size} if size else {}))
    return cfcontact.rounded_punch(friction=friction, indentation=(0.0, 0.03), **({"size": size} if size else {}))


def _closing(m, friction, shear=False):
    """Two blocks whose whole interface closes at one alpha: a separating traction on body 1's
    top, f2 = -f1, so at alpha = 1/2 the load vanishes and every indicator of the interface with
    it (a degenerate point with all m nodes).  ``shear``: f2 = -f1 plus a shear, which makes the
    nodes close and slip one after another (ordinary transitions, the reference of the cost of
    a branch on the same model)."""
    from cfcontact.models import two_blocks

    p = 1e7
    t1 = (-0.05 * p, p)
    t2 = (0.25 * p, -p) if shear else (-t1[0], -t1[1])
    return two_blocks(nx=m, ny=max(2, m // 3), cell="quadrilateral", friction=friction,
                      tractions1={"top1": t1}, tractions2={"top1": t2}, clamp=("left1", "left2", "right2"))


def run_worker(cmd, res: dict, timeout, log=print, error_chars=2000) -> dict:
    """Run a benchmark worker process (``cmd``; it imports the cfcontact this process runs,
    installed or not) and add to ``res`` what its BENCH-PARTIAL / BENCH-RESULT lines report (the
    partial ones survive a crash, a kill or the timeout), its return code, the elapsed time and,
    when it failed, the tail of its stderr."""
    env = dict(os.environ)
    package_parent = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = package_parent + os.pathsep + env.get("PYTHONPATH", "")
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
        out, err, rc = proc.stdout, proc.stderr, proc.returncode
    except subprocess.TimeoutExpired as exc:
        out = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        err, rc = f"timeout after {timeout} s", "timeout"
    for line in out.splitlines():
        if line.startswith("BENCH-PARTIAL ") or line.startswith("BENCH-RESULT "):
            res.update(json.loads(line.split(" ", 1)[1]))
    res["returncode"], res["elapsed"] = rc, time.perf_counter() - t0
    if rc != 0:
        res["error"] = (err or "")[-error_chars:]
        log(f"    FAILED ({rc}) in stage {res.get('stage')}: {(err or '').strip().splitlines()[-1:] or ''}")
    return res


def run_row(spec, timeout, log=print) -> dict:
    cmd = [sys.executable, "-m", "cfcontact.bench_stress", "--worker", json.dumps(spec)]
    return run_worker(cmd, dict(spec), timeout, log)


def _row_text(r):
    f = lambda k, w=8, p=2: f"{r[k]:>{w}.{p}f}" if isinstance(r.get(k), (int, float)) else f"{'-':>{w}}"  # noqa
    model = r.get("model", "") + (f"/{r['cells_across']}" if "cells_across" in r else "")
    return (f"{model:>8} {r.get('kind', ''):>7} {r.get('n', '-'):>7} {r.get('m', '-'):>5} "
            f"{r.get('friction', 0):>5g} {f('assembly_time')} {f('factorization_time')} {f('condensation_time')} "
            f"{f('path_time')} {f('start_time', 6)} {r.get('transitions', '-'):>7} {f('time_per_transition', 9, 4)} "
            f"{r.get('dense_updates', '-'):>7} {r.get('refactorizations', '-'):>6} {f('peak_rss_gib', 6)} "
            f"{r.get('worst_residual') if isinstance(r.get('worst_residual'), float) else float('nan'):>9.1e} "
            f"{f('ratio', 6, 1)} {_status_text(r):>11} {_seed_text(r):>10}")


def _seed_text(r) -> str:
    """The seed method's run of a row: the same states as the exact path, where they differ, or its status."""
    if "seed_status" not in r:
        return "-"
    if r["seed_status"] != "completed":
        return r["seed_status"][:10]
    return "same" if r["seed_same"] else f"differs@{r['seed_first_difference']}"


def _status_text(r) -> str:
    """A row's status, or the stage it reached, or how its worker failed (it may have reported nothing)."""
    return str(r.get("status") or r.get("stage") or f"failed (rc {r.get('returncode')})")


def table(rows) -> str:
    head = (f"{'model':>8} {'loads':>7} {'n':>7} {'m':>5} {'F':>5} {'assembly':>8} {'factor':>8} {'condense':>8} "
            f"{'path':>8} {'start':>6} {'trans.':>7} {'s/trans.':>9} {'updates':>7} {'refact':>6} {'GiB':>6} {'residual':>9} "
            f"{'ratio':>6} {'status':>11} {'seed':>10}")
    return "\n".join([head, "-" * len(head)] + [_row_text(r) for r in rows])


def slope(rows, key="time_per_transition") -> dict:
    """Log-log slope of the time per transition against m, per friction coefficient (least squares
    over the rows with at least 20 transitions); ``key="path_time_per_transition"``: of the
    path's time with its start."""
    out = {}
    for F in sorted({r["friction"] for r in rows}):
        pts = [(r["m"], r[key]) for r in rows
               if r["friction"] == F and r.get("transitions", 0) >= 20 and r.get(key)]
        if len(pts) >= 2:
            x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
            out[str(F)] = float(np.polyfit(x, y, 1)[0])
    return out


def part_c(quick=False, time_limit=600.0, log=print, sizes=None) -> dict:
    """Part C: the strips at F = 0.3 and 30 (``sizes``: their contact node counts m, default
    C_SIZES, or QUICK_C_SIZES when quick)."""
    rows = []
    for F in C_FRICTIONS:
        for m in (sizes or (QUICK_C_SIZES[F] if quick else C_SIZES)):
            log(f"  strip m = {m}, F = {F:g} ...")
            rows.append(run_row({"model": "strip", "kind": "uniform", "m": m, "friction": F, "seed": 0,
                                 "time_limit": time_limit}, timeout=time_limit * 4 + 600, log=log))
            log("    " + _row_text(rows[-1]))
    return {"rows": rows, "slope": slope(rows), "slope_with_start": slope(rows, "path_time_per_transition")}


def _random_loads(build, friction, paths, seed0, log, seed_limit=0.0):
    """``paths`` random load paths on a demo model: f1, f2 random combinations of the model's own
    loads and of unit tractions on its edges (the same kinds of terms, random sizes).  With
    ``seed_limit`` > 0 each path is traced by the seed method too (:func:`_seed_check`)."""
    import cfcontact
    from cfcontact.path import select_solver

    base = build(friction)
    f1, f2 = base.loads_numpy()
    scale = max(np.abs(f1).max(), np.abs(f2).max())
    out = []
    for k in range(paths):
        rng = np.random.default_rng(seed0 + k)
        g1 = rng.uniform(-1, 1) * f1 + rng.uniform(-1, 1) * f2 + 0.2 * scale * rng.standard_normal(base.n) * (
            rng.random(base.n) < 0.05)
        g2 = rng.uniform(-1, 1) * f1 + rng.uniform(-1, 1) * f2 + 0.2 * scale * rng.standard_normal(base.n) * (
            rng.random(base.n) < 0.05)
        system = base.with_loads(g1, g2)
        t0 = time.perf_counter()
        try:
            path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
            rec = {"status": path.status, "transitions": len(path.transitions), "folds": len(path.folds),
                   "start": path.stats.get("start"), "degenerate_points": path.stats.get("degenerate_points", 0),
                   "homotopy_transitions": path.stats.get("homotopy_transitions", 0),
                   "backtracks": path.stats.get("backtracks", 0)}
        except cfcontact.CfcontactError as exc:
            rec = {"status": "start failure", "error": str(exc)[:200], "transitions": 0}
        rec["time"] = time.perf_counter() - t0
        if rec.get("start") in ("frictionless", "ssnm_rho", "homotopy"):
            # the same path from its start branch's sets (the start given): what the homotopy
            # start adds to this path, apart from the path's own length
            again = base.with_loads(g1, g2)
            first = path.branches[0]
            t0 = time.perf_counter()
            same = cfcontact.trace_exact(again, 0.0, 1.0, start_sets=first.sets, orientation=first.orientation,
                                         solver=select_solver(again, "exact"))
            rec["time_given_start"] = time.perf_counter() - t0
            rec["same_path"] = [t.alpha for t in same.transitions] == [t.alpha for t in path.transitions]
        if seed_limit > 0 and rec["status"] != "start failure":
            rec.update(_seed_check(lambda: base.with_loads(g1, g2), path, friction, seed_limit))
        out.append(rec)
    return out


def _seed_check(make_system, exact_path, friction, limit) -> dict:
    """Trace the path of ``make_system()`` by the seed method (at most ``limit`` seconds) and
    compare its set changes with ``exact_path``'s (:func:`cfcontact.report.compare_paths`).  Where
    both complete and differ: how close the exact transitions around the first difference are
    (``exact_gap``: the smallest distance in alpha from that transition to the two before and the
    two after it, against the seed's h_min), the seed's unverified transitions, where the seed's
    path runs back along itself (``seed_retraces``, :func:`_retrace`), and the seed traced again
    with h_min divided by 10, 100, ... (``finer``: h_min, status, same, first difference) until it
    agrees, fails or SEED_FINER_STEPS runs are made.  When the seed method's SSNM starts from
    another solution at alpha = 0 (``seed_own_start``: that run), it is traced from the exact
    path's start point instead."""
    import cfcontact
    from cfcontact.report import branch_states, compare_paths

    def seed(h_min, y0=None):
        """(path, its states, info) of one seed run (path and states None when it raised)."""
        t0 = time.perf_counter()
        try:
            p = cfcontact.trace_path(make_system(), 0.0, 1.0, method="seed", h_min=h_min, y0=y0,
                                     callback=lambda point: time.perf_counter() - t0 > limit)
        except cfcontact.CfcontactError as exc:
            return None, None, {"status": "error: " + str(exc)[:120], "time": time.perf_counter() - t0}
        status = "time limit" if p.status == "stopped by callback" else p.status
        states = branch_states(p, friction)
        return p, states, {"status": status, "transitions": len(p.transitions), "time": time.perf_counter() - t0,
                           "end_alpha": float(p.alphas[-1]) if len(p.alphas) else None,
                           "unverified": sum(e.kind == "unverified_transition" for e in p.events),
                           "retraces": _retrace(states)}

    exact_states = branch_states(exact_path, friction)
    h_min = cfcontact.PathOptions().h_min
    path, states, info = seed(h_min)
    out = {"exact_retraces": _retrace(exact_states)}  # (never: a check of the exact path)
    y0 = None
    if states and exact_states and _first_state_difference(states, exact_states) < 0:
        # its SSNM found another solution at alpha = 0 (at F = 30 there can be several): the seed
        # method again from the exact path's start point, which is then its own
        out["seed_own_start"] = info
        y0 = next(iter(exact_path.iter_points(indices=[0])))[1]
        path, states, info = seed(h_min, y0)
    out.update({"seed_" + k: v for k, v in info.items()})
    if info["status"] != "completed":
        return out
    # the same sequence of states (sets of every node on every branch): where several nodes change
    # at one alpha (a symmetric pair), the seed names one of them, the exact method all
    cmp = compare_paths(path, exact_path, friction)
    out["seed_same"] = states == exact_states  # (cmp's same_branch_sets)
    out["seed_same_named_changes"] = bool(cmp["same_set_changes"])
    if out["seed_same"]:
        out["seed_max_alpha_difference"] = cmp["max_alpha_difference"]
        return out
    i = _first_state_difference(states, exact_states)
    alphas = [t.alpha for t in exact_path.transitions]
    near = [abs(alphas[i] - alphas[j]) for j in range(i - 2, i + 3)
            if 0 <= i < len(alphas) and j != i and 0 <= j < len(alphas)]
    out.update(seed_first_difference=i, exact_gap=min(near, default=None), seed_h_min=h_min, finer=[])
    for _ in range(SEED_FINER_STEPS):
        h_min /= 10.0
        _, again, info = seed(h_min, y0)
        done = info["status"] == "completed"
        same = done and again == exact_states
        out["finer"].append({"h_min": h_min, "status": info["status"], "same": same,
                             "first_difference": _first_state_difference(again, exact_states)
                             if done and not same else None,
                             "unverified": info.get("unverified"), "retraces": info.get("retraces"),
                             "time": info["time"]})
        if same or not done:
            break
    return out


def _summary(recs) -> dict:
    st = {}
    for r in recs:
        st[r["status"]] = st.get(r["status"], 0) + 1
    times = np.array([r["time"] for r in recs])
    starts = {}
    for r in recs:
        starts.setdefault(r.get("start") or "-", []).append(r["time"])
    ssnm_t = np.median(starts["ssnm"]) if starts.get("ssnm") else float("nan")
    # the paths whose SSNM start failed: started by either homotopy of the exact method or by SSNM
    # with another rho
    hom = starts.get("frictionless", []) + starts.get("ssnm_rho", []) + starts.get("homotopy", [])
    own = [r["time"] / r["time_given_start"] for r in recs if r.get("time_given_start")]
    return {"runs": len(recs), "status": st, "transitions_total": int(sum(r["transitions"] for r in recs)),
            "transitions_max": int(max(r["transitions"] for r in recs)),
            "degenerate_points": int(sum(r.get("degenerate_points", 0) for r in recs)),
            "backtracks": int(sum(r.get("backtracks", 0) for r in recs)),
            "time_total": float(times.sum()), "time_median": float(np.median(times)),
            "starts": {k: len(v) for k, v in starts.items()},
            "homotopy_start_median_time": float(np.median(hom)) if hom else None,
            "ssnm_start_median_time": float(ssnm_t),
            "homotopy_over_ssnm": float(np.median(hom) / ssnm_t) if hom and ssnm_t > 0 else None,
            # per path: its run with the homotopy start over the same path with its start given
            "homotopy_over_given_start": float(np.median(own)) if own else None,
            "homotopy_over_given_start_max": float(np.max(own)) if own else None,
            "homotopy_same_path": int(sum(bool(r.get("same_path")) for r in recs if "same_path" in r)),
            **_seed_summary(recs)}


def _retrace(states):
    """The first transition j of a path (``states``: :func:`cfcontact.report.branch_states`) after
    which its branch has the sets of the branch before transition j - 1: the path undid its last
    set change and runs back along itself (the states of a continuous piecewise-affine path never
    do; None when the path does not)."""
    return next((j for j in range(1, len(states) - 1) if states[j + 1] == states[j - 1]), None)


def _first_state_difference(seed_states, exact_states) -> int:
    """The first transition after which two paths' branches (their :func:`cfcontact.report.branch_states`) have
    different sets (-1: their first branches differ; the length of the shorter path: one path is
    the other's beginning)."""
    pairs = zip(seed_states, exact_states)
    return next((i - 1 for i, (a, b) in enumerate(pairs) if a != b), min(len(seed_states), len(exact_states)) - 1)


def _seed_difference_explained(r) -> bool:
    """Does the seed's run account for its difference from the exact path?  It agrees once its
    smallest step is smaller, or it ran back along itself, or it flagged a transition it could
    not verify, or the exact transitions there are closer together than its smallest step."""
    return bool(any(f["same"] for f in r["finer"]) or r["seed_retraces"] is not None or r["seed_unverified"] > 0
                or (r["exact_gap"] is not None and r["exact_gap"] < r["seed_h_min"]))


def _seed_summary(recs) -> dict:
    """Counts of :func:`_seed_check`'s comparisons (empty when the seed method was not run)."""
    checked = [r for r in recs if "seed_status" in r]
    if not checked:
        return {}
    done = [r for r in checked if r["seed_status"] == "completed"]
    differ = [r for r in done if not r["seed_same"]]
    st = {}
    for r in checked:
        st[r["seed_status"]] = st.get(r["seed_status"], 0) + 1
    return {"seed_status": st, "seed_same": len(done) - len(differ), "seed_differs": len(differ),
            # its SSNM started from another solution at alpha = 0: traced from the exact start instead
            "seed_own_start": sum("seed_own_start" in r for r in checked),
            # where they differ: the exact transitions closer than the seed's h_min there, the seed's
            # own flags, and whether the seed agrees with a smaller h_min
            "seed_differs_below_h_min": sum(r["exact_gap"] is not None and r["exact_gap"] < r["seed_h_min"]
                                            for r in differ),
            "seed_differs_unverified": sum(r["seed_unverified"] > 0 for r in differ),
            "seed_differs_retraces": sum(r["seed_retraces"] is not None for r in differ),
            # none of these: a difference the seed's own run does not account for
            "seed_differs_unexplained": sum(not _seed_difference_explained(r) for r in differ),
            "exact_retraces": sum(r.get("exact_retraces") is not None for r in checked),
            "seed_differs_agrees_finer": sum(any(f["same"] for f in r["finer"]) for r in differ),
            "seed_time_total": float(sum(r["seed_time"] for r in checked))}


def part_d(quick=False, paths=None, time_limit=600.0, log=print, sizes=None, seed_limit=None) -> dict:
    """Part D: strips with uniform and random tractions (``sizes``: their contact node counts,
    default D_SIZES, or QUICK_D_SIZES when quick), the cylinder and the punch, blocks closing
    all at once, and ``paths`` random load paths on each demo model at F = 30, each traced by the
    seed method too for at most ``seed_limit`` seconds (default SEED_CHECK_LIMIT, 0 when quick;
    0: not at all)."""
    from cfcontact.demo_models import build_blocks, build_demo

    sizes = sizes or (QUICK_D_SIZES if quick else D_SIZES)
    paths = (QUICK_D_PATHS if quick else D_PATHS) if paths is None else int(paths)
    seed_limit = (0.0 if quick else SEED_CHECK_LIMIT) if seed_limit is None else float(seed_limit)
    rows = []
    # a row's worker: its exact path, then the seed method's (and its runs with finer steps)
    timeout = time_limit * 4 + 600 + (1 + SEED_FINER_STEPS) * seed_limit
    for F in C_FRICTIONS:
        for kind in ("uniform", "random"):
            for m in sizes:
                log(f"  strip m = {m}, {kind} tractions, F = {F:g} ...")
                rows.append(run_row({"model": "strip", "kind": kind, "m": m, "friction": F, "seed": 1,
                                     "time_limit": time_limit, "seed_check": seed_limit}, timeout=timeout, log=log))
                log("    " + _row_text(rows[-1]))
    if not quick:
        # 8 cells across (strip/8): SSNM cycles at alpha = 0 and the frictionless homotopy is a closed
        # loop; the start comes from SSNM with another rho, before the all-open homotopy (which took
        # more than 28 000 transitions in two minutes here)
        log("  strip m = 500, 8 cells across, random tractions, F = 30 ...")
        rows.append(run_row({"model": "strip", "kind": "random", "m": 500, "friction": 30.0, "seed": 1,
                             "cells_across": 8, "time_limit": time_limit, "seed_check": seed_limit},
                            timeout=timeout, log=log))
        log("    " + _row_text(rows[-1]))
    for model in ("cylinder", "punch"):
        for F in C_FRICTIONS:
            log(f"  {model}, F = {F:g} ...")
            rows.append(run_row({"model": model, "friction": F, "time_limit": time_limit, "seed_check": seed_limit,
                                 **({"size": 0.05} if quick else {})}, timeout=timeout, log=log))
            log("    " + _row_text(rows[-1]))
    # the load vanishes where the interface closes (f2 = -f1): the path crosses that apex by its ray
    # (exact.APEX_RULE); the rows without it measure the lexicographic rule on a point of m nodes
    for apex_rule in (False, True):
        for m in ((12, 24) if quick else (24, 48, 96)):
            log(f"  two blocks closing at once, m = {m}, " + ("by the apex rule" if apex_rule else
                                                              "by the lexicographic rule") + " ...")
            rows.append(run_row({"model": "closing", "m": m, "friction": 0.3, "time_limit": time_limit,
                                 "apex_rule": apex_rule, "kind": "apex" if apex_rule else "lex",
                                 "seed_check": seed_limit}, timeout=timeout, log=log))
            log("    " + _row_text(rows[-1]))
    random = {}
    for name, build in (("demo", build_demo), ("blocks", build_blocks)):
        log(f"  {paths} random load paths on the {name} model at F = 30 ...")
        recs = _random_loads(build, 30.0, paths, 1000, log, seed_limit)
        random[name] = {"summary": _summary(recs), "runs": recs}
        log(f"    {random[name]['summary']}")
    return {"rows": rows, "random_loads": random}


def main(argv=None):
    args = sys.argv[1:] if argv is None else argv
    if len(args) == 2 and args[0] == "--worker":
        res = worker(json.loads(args[1]))
        print("BENCH-RESULT " + json.dumps(res), flush=True)
        return 0
    raise SystemExit("usage: cfcontact bench --part C|D (this module's --worker is internal)")


if __name__ == "__main__":
    sys.exit(main())
