"""Benchmarks of cfcontact's path following (see docs/bench.md for measured numbers).

Part A -- seed vs exact on the main demo (:func:`cfcontact.demo_models.build_demo` for every F in
``DEMO_FRICTIONS``) and on the two steel blocks of :data:`~cfcontact.demo_models.BLOCKS_MODEL` (a longer path: every
contact node works).  The seed method runs with the default PETSc backend
(:class:`cfcontact.DirNeuSolver`: one factorization of J(Z) per branch), the exact method with
:class:`cfcontact.condensed.CondensedSolver` (K factored once, a dense system of size <= 2m per branch).
Reported per method: linear solves, factorizations (for the condensed backend: factorizations
of K and dense factorizations separately), wall time, transitions, folds, largest number of
solutions at one alpha, worst residual of (1)-(3) over the stored points; the speed-up
seed / exact and whether both give the same sequence of set changes (node, set, kind) with
transition alphas agreeing within the seed's h_min.  Timing as :mod:`timeit` does it: each
method runs at least ``--repeat`` times (default 3, ``--quick``: 1) and until it has run for
``--min-time`` seconds (default 1; each at most MAX_RUNS times), with a fresh solver,
``gc.collect()`` before each run and the garbage collector off during it (as timeit does);
the fastest run is reported for both methods, and the median run as well (the noise of a
shared machine only ever adds time, and adds relatively more to a 15 ms run than to a 2 s one).

Part E (``--part E``) -- the friction map of the main demo's load path on a 200 x 200 (alpha, F) grid,
its fold curves and critical friction, and the same 200 alpha-paths traced alone (:func:`part_e`).
(Parts C and D -- long interfaces and hard cases of the exact method -- are in
:mod:`cfcontact.bench_stress`.)

Part B -- the exact method alone on refined two-block meshes (n ~ 1e4, 1.2e5, 1e6 DOFs;
nx = 3 ny cells per block, n = 4 nx (ny + 1), m = nx contact nodes) of the two steel blocks
(:func:`~cfcontact.demo_models.build_blocks`) at the demo's largest friction coefficient.  Every size runs in a fresh subprocess (peak memory =
``ru_maxrss`` of that process) and reports the time split

    assembly (two_blocks) | factorization of K (PETSc log: MatLUFactorSym + MatLUFactorNum, or the
    MatCholFctr events of a Cholesky factorization; the envelope factor's own time when
    cfcontact.native factored K) |
    condensation (S = B K^-1 B^T) | path (trace_path, the rest)

and the ratio total / (assembly + factorization of K), total = the sum of the four.

The exact method stores only the multipliers of each branch (the condensed backend determines
u from them) and forms the displacements when they are needed.  The worst residual of
(1)-(3) over the stored points is computed after the run with
:meth:`cfcontact.SolutionPath.iter_points` (u formed in batches by multi-right-hand-side
solves and dropped), and its time is reported separately (not in the path time).

Run:  cfcontact bench [--quick] [--sizes 1e4,1.2e5,1e6] [--skip-large] [--output DIR]
      [--part A|B|AB] [--repeat N] [--min-time S] [--timeout S]   (or .venv/bin/python demos/bench.py ...)
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import json
import math
import os
import platform
import sys
import time

import numpy as np

from cfcontact import demo_models as dm
from cfcontact.bench_stress import factorization_time, peak_rss_gib, run_worker
from cfcontact.demo_models import BLOCKS_F1, BLOCKS_F2, BLOCKS_MODEL, build_blocks
from cfcontact.errors import InputError
from cfcontact.report import compare_paths, worst_residual

SIZES = (1e4, 1.2e5, 1e6)
QUICK_SIZES = (2e3, 1e4)
LARGE = 5e5  # --skip-large drops sizes above this
MAX_RUNS = 200  # Part A: most runs of one method (--min-time)

#: Part B verifies every stored point up to this many points, else this many evenly spaced ones.
VERIFY_MAX_POINTS = 400


def mesh_for(n_target: float):
    """(nx, ny, n) of a two-block mesh with nx = 3 ny and n = 4 nx (ny + 1) ~ n_target."""
    ny = max(2, int(round((-1.0 + math.sqrt(1.0 + n_target / 3.0)) / 2.0)))
    nx = 3 * ny
    return nx, ny, 4 * nx * (ny + 1)


# ====================================================================== Part A
def _method_result(path, system, solver, wall, extra=None):
    mult, at = path.max_multiplicity()
    return {"status": path.status, "transitions": len(path.transitions), "folds": len(path.folds),
            "branches": len(path.branches), "points": len(path.alphas), "max_multiplicity": mult,
            "alpha_of_max": at, "wall_time": wall, "events": [e.kind for e in path.events],
            "worst_residual": worst_residual(system, path, solver), **(extra or {})}


def _timed_runs(run, repeat, min_time):
    """Call ``run()`` (which returns its own timing tuple) at least ``repeat`` times and until the
    calls have taken ``min_time`` seconds (at most MAX_RUNS times).  As :mod:`timeit` does, the
    garbage collector is off during each call (``gc.collect()`` before it): a collection
    triggered inside a run would traverse every object alive in the process, including the
    results of earlier runs, and time that instead of the method."""
    out = []
    spent = 0.0  # in the calls (not in gc.collect)
    enabled = gc.isenabled()
    try:
        while len(out) < max(1, int(repeat)) or (spent < min_time and len(out) < MAX_RUNS):
            gc.collect()
            gc.disable()
            try:
                t0 = time.perf_counter()
                out.append(run())
                spent += time.perf_counter() - t0
            finally:
                if enabled:
                    gc.enable()
    finally:
        if enabled:
            gc.enable()
    return out


def part_a(quick=False, frictions=None, log=print, repeat=1, min_time=0.0, cases=("demo", "blocks")) -> list:
    """Seed vs exact for every F on the main demo ("demo") and on the two steel blocks ("blocks",
    :func:`build_blocks`; ``quick``: a coarse mesh of them); each method runs at least ``repeat``
    times and for at least ``min_time`` seconds (fresh solver each time); its time is the fastest
    run (the paths are identical; the noise of a shared machine only adds time), its median is
    reported too."""
    builders = {"demo": dm.build_demo, "blocks": lambda F: build_blocks(F, quick=quick)}
    unknown = [c for c in cases if c not in builders]
    if unknown:
        raise InputError(f"unknown Part A case(s) {unknown}; valid: {sorted(builders)}")
    return [row for case in cases for row in _part_a_case(case, builders[case], frictions or dm.DEMO_FRICTIONS,
                                                          log, repeat, min_time)]


def _part_a_case(case, build, frictions, log, repeat, min_time) -> list:
    import cfcontact
    from cfcontact.condensed import CondensedSolver
    from cfcontact.ssnm import DirNeuSolver

    out = []
    for F in frictions:
        t0 = time.perf_counter()
        system = build(F)
        t_asm = time.perf_counter() - t0
        # seed: default PETSc backend (fresh solver so its counters are this run's)
        last = {}

        def seed_run():
            t0 = time.perf_counter()
            last["ssolver"] = DirNeuSolver(system)
            last["seed"] = cfcontact.trace_path(system, *dm.DEMO_ALPHA, method="seed", solver=last["ssolver"])
            return time.perf_counter() - t0

        seed_times = _timed_runs(seed_run, repeat, min_time)
        sp_, ssolver = last["seed"], last["ssolver"]
        t_seed = min(seed_times)
        st = ssolver.stats.as_dict()
        seed = _method_result(sp_, system, ssolver, t_seed, {
            "linear_solves": st["linear_solves"], "factorizations": st["factorizations"],
            "ssnm_iterations": st["ssnm_iterations"], "wall_times": seed_times,
            "median_wall_time": float(np.median(seed_times))})

        # exact: condensed backend, its construction (K factorization, S) counted in the wall time
        def exact_run():
            t0 = time.perf_counter()
            last["csolver"] = CondensedSolver(system)
            t_setup = time.perf_counter() - t0
            last["exact"] = cfcontact.trace_path(system, *dm.DEMO_ALPHA, method="exact", solver=last["csolver"])
            return time.perf_counter() - t0, t_setup

        exact_times = _timed_runs(exact_run, repeat, min_time)
        ep, csolver = last["exact"], last["csolver"]
        t_exact, t_setup = min(exact_times)
        ct = csolver.stats.as_dict()
        exact = _method_result(ep, system, csolver, t_exact, {
            "linear_solves": ct["linear_solves"], "linear_solves_path": ep.stats.get("linear_solves"),
            "K_factorizations": ct["factorizations"], "dense_factorizations": ct["dense_factorizations"],
            "dense_solves": ct["dense_solves"], "ssnm_iterations": ct["ssnm_iterations"],
            "setup_time": t_setup, "condensation_time": csolver.timings["condensation"],
            "path_time": t_exact - t_setup, "wall_times": [t for t, _ in exact_times],
            "median_wall_time": float(np.median([t for t, _ in exact_times]))})
        exact["linear_solves_with_verification"] = csolver.stats.linear_solves
        res = {"case": case, "friction": F, "n": system.n, "m": system.m, "assembly_time": t_asm, "seed": seed,
               "exact": exact,
               "speedup": t_seed / max(t_exact, 1e-300),
               "speedup_median": seed["median_wall_time"] / max(exact["median_wall_time"], 1e-300),
               **compare_paths(sp_, ep, F)}
        out.append(res)
        log(f"  {case}, F = {F:g}: seed {t_seed:.2f} s ({len(seed_times)} runs), exact {t_exact:.4f} s ({len(exact_times)} "
            f"runs), speed-up {res['speedup']:.0f} (medians: {res['speedup_median']:.0f}), same set changes: "
            f"{res['same_set_changes']}")
    return out


def table_a(rows) -> str:
    head = (f"{'case':>6} {'F':>5} {'n':>6} {'m':>4} {'method':>6} {'solves':>7} {'K fact.':>7} {'dense f.':>8} "
            f"{'time [s]':>9} {'median':>9} {'runs':>4} {'trans.':>6} {'folds':>5} {'max sol':>7} {'residual':>9} "
            f"{'speed-up':>8} {'(median)':>8} {'same seq.':>9} {'max |da|':>9}")
    lines = [head, "-" * len(head)]
    for r in rows:
        for name in ("seed", "exact"):
            d = r[name]
            kf = d["factorizations"] if name == "seed" else d["K_factorizations"]
            dense = "-" if name == "seed" else str(d["dense_factorizations"])
            tail = (f"{r['speedup']:>8.0f} {r.get('speedup_median', float('nan')):>8.0f} "
                    f"{str(r['same_set_changes']):>9} {r['max_alpha_difference']:>9.1e}"
                    if name == "exact" else "")
            lines.append(f"{r.get('case', ''):>6} {r['friction']:>5g} {r['n']:>6} {r['m']:>4} {name:>6} {d['linear_solves']:>7} {kf:>7} "
                         f"{dense:>8} {d['wall_time']:>9.4f} {d.get('median_wall_time', float('nan')):>9.4f} "
                         f"{len(d.get('wall_times', ())):>4} {d['transitions']:>6} {d['folds']:>5} "
                         f"{d['max_multiplicity']:>7} {d['worst_residual']:>9.1e} {tail}".rstrip())
    return "\n".join(lines)


# ====================================================================== Part B
def worker_b(nx, ny, friction, petsc_options, verify_points=True, profile=False) -> dict:
    from petsc4py import PETSc

    for kv in petsc_options:
        k, _, v = kv.partition("=")
        PETSc.Options()[k.lstrip("-")] = v
    PETSc.Log.begin()
    from mpi4py import MPI

    import cfcontact
    from cfcontact.condensed import CondensedSolver

    comm = MPI.COMM_WORLD
    res = {"nx": nx, "ny": ny, "friction": friction, "petsc_options": list(petsc_options), "stage": "assembly",
           "ranks": comm.size}

    def dump():  # partial results survive a crash / kill (rank 0 writes; peak memory of every rank)
        res["peak_rss_gib_per_rank"] = comm.allgather(peak_rss_gib())
        if comm.rank == 0:
            print("BENCH-PARTIAL " + json.dumps(res), flush=True)

    t0 = time.perf_counter()
    system = build_blocks(friction, nx=nx, ny=ny)
    res.update(n=system.n, m=system.m, assembly_time=time.perf_counter() - t0, rss_after_assembly_gib=peak_rss_gib(),
               stage="factorization")
    dump()
    t0 = time.perf_counter()
    solver = CondensedSolver(system)
    t_setup = time.perf_counter() - t0
    t_fact = factorization_time(solver)
    t_cond = solver.timings["condensation"]
    res.update(factorization_time=t_fact, condensation_time=t_cond, setup_other_time=t_setup - t_fact - t_cond,
               condensation=solver.condensation, rss_after_condensation_gib=peak_rss_gib(), stage="path")
    try:
        fm = solver.ksp.getPC().getFactorMatrix()
        res["mumps_info"] = {"INFOG(3) factor entries est.": fm.getMumpsInfog(3),
                             "INFOG(9) factor entries": fm.getMumpsInfog(9),
                             "INFOG(21) MB per proc": fm.getMumpsInfog(21), "ICNTL(7)": fm.getMumpsIcntl(7),
                             "ICNTL(14)": fm.getMumpsIcntl(14), "INFOG(7) ordering": fm.getMumpsInfog(7)}
    except Exception as exc:  # not MUMPS
        res["mumps_info"] = str(exc)
    dump()
    solves0 = solver.stats.linear_solves
    t0 = time.perf_counter()
    path = cfcontact.trace_path(system, *dm.DEMO_ALPHA, method="exact", solver=solver)
    t_path = time.perf_counter() - t0  # (no profiler running: it costs per Python call)
    st = solver.stats.as_dict()
    top = _profiled_path(system, solver) if profile else None
    res.update(path_time=t_path, status=path.status, transitions=len(path.transitions), folds=len(path.folds),
               branches=len(path.branches), points=len(path.alphas), K_factorizations=st["factorizations"],
               linear_solves=st["linear_solves"], linear_solves_path=st["linear_solves"] - solves0,
               dense_factorizations=st["dense_factorizations"], dense_solves=st["dense_solves"],
               dense_updates=st.get("dense_updates", 0), true_corrections=st.get("true_corrections", 0),
               profile_top_tottime=top, rss_after_path_gib=peak_rss_gib(), stage="verify",
               events=[{"kind": e.kind, "alpha": e.alpha, "message": e.message} for e in path.events][:20])
    dump()
    t0 = time.perf_counter()
    res["max_multiplicity"] = path.max_multiplicity()[0]
    res["multiplicity_time"] = time.perf_counter() - t0
    if verify_points:
        P = len(path.alphas)
        idx = None if P <= VERIFY_MAX_POINTS else np.unique(np.linspace(0, P - 1, VERIFY_MAX_POINTS).round().astype(int))
        t0 = time.perf_counter()
        res["worst_residual"] = worst_residual(system, path, solver, indices=idx)
        res["verify_time"] = time.perf_counter() - t0
        res["verified_points"] = P if idx is None else int(len(idx))
    total = res["assembly_time"] + t_fact + t_cond + res["setup_other_time"] + t_path
    base = res["assembly_time"] + t_fact
    res.update(total_time=total, ratio=total / base, peak_rss_gib=peak_rss_gib(),
               peak_rss_gib_per_rank=comm.allgather(peak_rss_gib()),
               transition_alphas=[t.alpha for t in path.transitions],
               transition_keys=[[t.node, t.set, t.kind] for t in path.transitions], stage="done")
    return res


def _profiled_path(system, solver) -> list:
    """The path traced again under cProfile (``--profile``): the 8 functions of most own time,
    [name, seconds] (the timed run is not profiled)."""
    import cProfile
    import pstats

    import cfcontact

    pr = cProfile.Profile()
    pr.enable()
    cfcontact.trace_path(system, *dm.DEMO_ALPHA, method="exact", solver=solver)
    pr.disable()
    prof: dict = {}
    for (fname, _line, func), (_cc, _nc, tt, _ct, _callers) in pstats.Stats(pr).stats.items():
        key = f"{os.path.basename(fname)}:{func}"
        prof[key] = prof.get(key, 0.0) + tt
    return [[k, v] for k, v in sorted(prof.items(), key=lambda kv: -kv[1])[:8]]


def run_size(n_target, friction, timeout, petsc_options, log=print, ranks=1, profile=False) -> dict:
    nx, ny, n_est = mesh_for(n_target)
    cmd = [sys.executable, "-m", "cfcontact.bench", "--worker-b", f"{nx},{ny},{friction!r}"]
    if ranks > 1:
        cmd = ["mpirun", "--allow-run-as-root", "-n", str(int(ranks))] + cmd
    for o in petsc_options:
        cmd += ["--petsc-option", o]
    if profile:
        cmd.append("--profile")
    log(f"  n ~ {n_target:.3g}: nx = {nx}, ny = {ny} (n = {n_est}, m = {nx}) ...")
    res = run_worker(cmd, {"n_target": n_target, "nx": nx, "ny": ny}, timeout, log, error_chars=3000)
    if res["returncode"] != 0:
        res["failed_in_stage"] = res.get("stage")
    return res


def compare_ranks(serial, parallel) -> dict:
    """Does the parallel run give the serial transitions (same sequence, alpha within 1e-9 relative)?"""
    ks, kp = serial.get("transition_keys"), parallel.get("transition_keys")
    if ks is None or kp is None:
        return {"same_as_serial": None}
    same = ks == kp
    d = max((abs(a - b) / max(abs(a), 1e-300) for a, b in zip(serial["transition_alphas"],
                                                              parallel["transition_alphas"])), default=0.0)
    return {"same_as_serial": bool(same and d <= 1e-9), "max_alpha_rel_difference": d}


def table_b(rows) -> str:
    head = (f"{'n':>8} {'m':>4} {'ranks':>5} {'assembly':>9} {'factor K':>9} {'condense':>9} {'path':>9} "
            f"{'total':>9} {'ratio':>6} {'trans.':>6} {'dense f.':>8} {'updates':>7} {'peak GiB':>8} {'residual':>9} "
            f"{'status':>10}")
    lines = [head, "-" * len(head)]
    f = lambda r, k, w=9, p=2: f"{r[k]:>{w}.{p}f}" if isinstance(r.get(k), (int, float)) else f"{'-':>{w}}"  # noqa
    for r in rows:
        status = r.get("status") or f"FAIL:{r.get('failed_in_stage')}"
        per_rank = r.get("peak_rss_gib_per_rank")
        peak = max(per_rank) if per_rank else r.get("peak_rss_gib")
        same = {True: " =serial", False: " !=serial"}.get(r.get("same_as_serial"), "")
        lines.append(f"{r.get('n', r.get('n_target')):>8} {r.get('m', r.get('nx')):>4} {r.get('ranks', 1):>5} "
                     f"{f(r, 'assembly_time')} {f(r, 'factorization_time')} {f(r, 'condensation_time')} "
                     f"{f(r, 'path_time')} {f(r, 'total_time')} {f(r, 'ratio', 6, 1)} {r.get('transitions', '-'):>6} "
                     f"{r.get('dense_factorizations', '-'):>8} {r.get('dense_updates', '-'):>7} "
                     f"{peak if isinstance(peak, (int, float)) else float('nan'):>8.2f} "
                     f"{r.get('worst_residual', float('nan')):>9.1e} {status:>10}{same}")
    return "\n".join(lines)


# ====================================================================== Part E
def part_e(quick=False, log=print, frictions=(0.0, 30.0), points=None) -> dict:
    """The friction map of the main demo's load path (:func:`cfcontact.fmap.multiplicity_map`,
    ``points`` x ``points`` grid: 200, ``quick``: 40), its fold curves and critical friction
    (:func:`cfcontact.fmap.fold_curves`), and the reference of the map's cost: the same alpha-paths
    traced one by one (``trace_exact`` with the same starts and a condensed solver sharing K's
    factorization), their times summed."""
    from cfcontact.condensed import CondensedSolver
    from cfcontact.exact import trace_exact
    from cfcontact.fmap import _Starts, _system_at, fold_curves, multiplicity_map
    from cfcontact.options import PathOptions
    from cfcontact.rational import friction_pattern, solver_at

    n = int(points or (40 if quick else 200))
    system = dm.build_demo(dm.DEMO_FRICTIONS[0])
    solver = CondensedSolver(system)
    alphas, Fs = np.linspace(*dm.DEMO_ALPHA, n), np.linspace(*frictions, n)
    phi, opts = friction_pattern(system), PathOptions()
    starts = _Starts(system, solver, dm.DEMO_ALPHA[0], float(Fs.max()), opts)
    last = {}

    def map_run():
        t0 = time.perf_counter()
        last["map"] = multiplicity_map(system, alphas, Fs, *dm.DEMO_ALPHA, solver=solver)
        return time.perf_counter() - t0

    def paths_run():  # the reference: the same n alpha-paths traced alone (their trace_exact calls timed)
        t, last["transitions"] = 0.0, 0
        for F in Fs:
            sysF = _system_at(system, F, phi)
            view, sets = solver_at(solver, sysF), starts.sets_at(F)
            t0 = time.perf_counter()
            path = trace_exact(sysF, *dm.DEMO_ALPHA, solver=view, start_sets=sets)
            t += time.perf_counter() - t0
            last["transitions"] += len(path.transitions)
        return t

    repeat = 1 if quick else 3  # alternately, the fastest of each (the noise of a shared machine only adds)
    map_times, path_times = [], []
    for _ in range(repeat):
        map_times += _timed_runs(map_run, 1, 0.0)
        path_times += _timed_runs(paths_run, 1, 0.0)
    fmap, transitions = last["map"], last["transitions"]
    t_map, t_paths = min(map_times), min(path_times)
    log(f"  map {n} x {n}: {t_map:.2f} s (fastest of {repeat}; the last: alpha-paths inside "
        f"{fmap.timings['trace']:.2f} s, counting {fmap.timings['count']:.3f} s, start path "
        f"{fmap.timings['start_path']:.2f} s); the {n} alpha-paths alone: {t_paths:.2f} s; ratio {t_map / t_paths:.2f}")
    t0 = time.perf_counter()
    fc = fold_curves(system, frictions, dm.DEMO_ALPHA, solver=solver)
    t_curves = time.perf_counter() - t0
    crit = fc.critical
    log(f"  fold curves F in [{frictions[0]:g}, {frictions[1]:g}]: {t_curves:.2f} s ({fc.probes} probes, "
        f"{len(fc.curves)} curves, {len(fc.cusps)} cusps); critical friction of the path: {crit}")
    return {"points": n, "frictions": list(frictions), "map_time": t_map, "map_timings": fmap.timings,
            "map_times": map_times, "alpha_paths_times": path_times, "alpha_paths_time": t_paths, "alpha_paths_transitions": transitions, "ratio": t_map / t_paths,
            "max_solutions": int(fmap.counts.max()), "curves_time": t_curves, "curve_timings": fc.timings,
            "probes": fc.probes, "curves": len(fc.curves), "cusps": len(fc.cusps),
            "critical_friction": crit.friction, "critical_alpha": crit.alpha, "critical_node": crit.node,
            "critical_set": crit.set, "notes": fc.notes}


def table_e(r) -> str:
    return "\n".join([
        f"map {r['points']} x {r['points']} (alpha x F): {r['map_time']:.2f} s; the {r['points']} alpha-paths alone "
        f"{r['alpha_paths_time']:.2f} s; ratio {r['ratio']:.2f} (target <= 2)",
        f"fold curves F in {r['frictions']}: {r['curves_time']:.2f} s ({r['probes']} probes, {r['curves']} curves, "
        f"{r['cusps']} cusps)",
        f"critical friction of the path: F = {r['critical_friction']:.12g} (alpha = {r['critical_alpha']:.10g}, "
        f"node {r['critical_node']} {r['critical_set']})"])


# ====================================================================== main
def add_arguments(ap):
    """The benchmark's options (shared by ``demos/bench.py`` and ``cfcontact bench``)."""
    ap.add_argument("--quick", action="store_true",
                    help="small sizes in every part (Part A: coarse two-block mesh, the demo as it is; B: 2e3,1e4; "
                         "C and D: see --contact-nodes, --paths, --seed-check; E: a 40 x 40 map)")
    ap.add_argument("--sizes", help="Part B target DOF counts, comma separated (default 1e4,1.2e5,1e6; "
                                    "--quick: 2e3,1e4)")
    ap.add_argument("--contact-nodes", help="Parts C and D: contact node counts m of the strips, comma separated "
                                            "(default C: 1000,2000,4000, D: 500,1000,2000; --quick: C 100,200 at "
                                            "F = 0.3 and 100,120 at F = 30, D 100)")
    ap.add_argument("--skip-large", action="store_true", help=f"drop Part B sizes above {LARGE:g} DOFs")
    ap.add_argument("--output", default="output/bench", help="folder for bench.json (default output/bench)")
    ap.add_argument("--part", default="AB", help="A, B, C, D, E or several, e.g. AB (default): C = long interfaces, "
                                                  "D = hard cases of the exact method (cfcontact.bench_stress), "
                                                  "E = the friction map of the main demo")
    ap.add_argument("--time-limit", type=float, default=600.0,
                    help="Parts C and D: tracing time limit of one row [s] (default 600)")
    ap.add_argument("--paths", type=int, help="Part D: random load paths per demo model (default 200; --quick: 10)")
    ap.add_argument("--seed-check", type=float,
                    help="Part D: also trace each row and random load path by the seed method, at most this many "
                         "seconds each, and compare their states (default 60; --quick: 0; 0: off)")
    ap.add_argument("--repeat", type=int, help="Part A: run each method at least this many times and report the "
                                               "fastest (default 3; --quick: 1)")
    ap.add_argument("--min-time", type=float, help="Part A: run each method for at least this many seconds "
                                                   "(default 1; --quick: 0)")
    ap.add_argument("--timeout", type=float, default=4 * 3600.0, help="per-size time limit of Part B [s]")
    ap.add_argument("--mpi", type=int, default=1, help="Part B: also run every size under mpirun -n MPI "
                                                       "(and compare its transitions with the serial run)")
    ap.add_argument("--petsc-option", action="append", default=[],
                    help="PETSc option for Part B, e.g. cfcontact_K_mat_mumps_icntl_7=5")
    ap.add_argument("--profile", action="store_true",
                    help="Part B: trace each serial path a second time under cProfile and report its 8 functions "
                         "of most own time (the timed run is never profiled)")
    return ap


@contextlib.contextmanager
def _blas_threads(machine: dict):
    """The measurements' convention (docs/bench.md): one BLAS thread, in this process and in the
    worker processes it starts, unless OPENBLAS_NUM_THREADS says otherwise (then that); recorded
    in ``machine``.  Multi-threaded BLAS on the small dense systems of a path costs more than it
    gains, and much more when the machine is busy."""
    chosen = os.environ.get("OPENBLAS_NUM_THREADS")
    machine["openblas_num_threads"] = chosen if chosen is not None else "1 (the benchmark's default)"
    if chosen is not None:
        yield
        return
    from cfcontact.enumerate import single_threaded_blas

    os.environ["OPENBLAS_NUM_THREADS"] = "1"  # the workers: fresh processes read it when they start
    try:
        with single_threaded_blas():
            yield
    finally:
        os.environ.pop("OPENBLAS_NUM_THREADS", None)


def run(args, argv_text="") -> int:
    """Run the benchmark with parsed options; prints the tables, writes <output>/bench.json."""
    part = str(args.part).upper()
    if not part or set(part) - {"A", "B", "C", "D", "E"}:
        raise InputError(f"--part must be letters among A, B, C, D, E (e.g. AB), got {args.part!r}")
    time_limit = getattr(args, "time_limit", 600.0)
    if not (0 < time_limit < math.inf):
        raise InputError(f"--time-limit must be a positive number of seconds, got {time_limit}")
    timeout = getattr(args, "timeout", 1.0)
    if not (0 < timeout < math.inf):
        raise InputError(f"--timeout must be a positive number of seconds, got {timeout}")
    ranks = getattr(args, "mpi", 1)
    if ranks is not None and ranks < 1:
        raise InputError(f"--mpi must be a number of MPI ranks >= 1, got {ranks}")
    for kv in getattr(args, "petsc_option", None) or []:
        key = kv.partition("=")[0].lstrip("-")
        if not key or not key.replace("_", "").isalnum():
            raise InputError(f"--petsc-option must be KEY=VALUE (e.g. mat_mumps_icntl_14=200) or a flag KEY, got {kv!r}")
    paths = getattr(args, "paths", None)
    if paths is not None and paths < 1:
        raise InputError(f"--paths must be >= 1, got {paths}")
    try:
        sizes = [float(s) for s in args.sizes.split(",")] if args.sizes else list(QUICK_SIZES if args.quick else SIZES)
    except ValueError:
        raise InputError(f"--sizes must be comma-separated numbers, got {args.sizes!r}") from None
    if any(not (s >= 100) for s in sizes):
        raise InputError(f"--sizes must be DOF counts >= 100, got {args.sizes!r}")
    strip_m = None
    if getattr(args, "contact_nodes", None):
        try:
            strip_m = [int(v) for v in args.contact_nodes.split(",")]
        except ValueError:
            raise InputError(f"--contact-nodes must be comma-separated integers, got {args.contact_nodes!r}") from None
        if any(v < 4 for v in strip_m):
            raise InputError(f"--contact-nodes must be node counts >= 4, got {args.contact_nodes!r}")
    seed_check = getattr(args, "seed_check", None)
    if seed_check is not None and not (0 <= seed_check < math.inf):
        raise InputError(f"--seed-check must be a number of seconds >= 0 (0: off), got {seed_check}")
    repeat = getattr(args, "repeat", None)
    repeat = repeat if repeat is not None else (1 if args.quick else 3)
    if repeat < 1:
        raise InputError(f"--repeat must be >= 1, got {repeat}")
    min_time = getattr(args, "min_time", None)
    min_time = min_time if min_time is not None else (0.0 if args.quick else 1.0)
    if not (0 <= min_time < math.inf):
        raise InputError(f"--min-time must be a number of seconds >= 0, got {min_time}")
    result = {"machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "python": sys.version.split()[0],
                          "loadavg_start": os.getloadavg()},
              "demo": {"model": dm.DEMO_MODEL, "f1": dm.DEMO_F1, "f2": dm.DEMO_F2,
                       "body_force1": dm.DEMO_BODY_FORCE1, "body_force2": dm.DEMO_BODY_FORCE2,
                       "frictions": list(dm.DEMO_FRICTIONS), "alpha": list(dm.DEMO_ALPHA)},
              "blocks": {"model": BLOCKS_MODEL, "f1": BLOCKS_F1, "f2": BLOCKS_F2},
              "quick": bool(args.quick), "command": argv_text}
    with _blas_threads(result["machine"]):
        os.makedirs(args.output, exist_ok=True)
        jpath = os.path.join(args.output, "bench.json")

        def save():
            with open(jpath, "w") as fh:
                json.dump(result, fh, indent=1, default=float)

        if "A" in part:
            print("Part A: seed vs exact on the main demo and on the two steel blocks"
                  + (" (coarse mesh of the blocks)" if args.quick else ""), flush=True)
            result["repeat"], result["min_time"] = repeat, min_time
            result["part_a"] = part_a(quick=args.quick, repeat=repeat, min_time=min_time)
            save()
            print(table_a(result["part_a"]), "\n", flush=True)
        if "B" in part:
            if args.skip_large:
                sizes = [s for s in sizes if s <= LARGE]
            F = max(dm.DEMO_FRICTIONS)
            print(f"Part B: exact method, condensed backend, F = {F:g}", flush=True)
            result["part_b"] = []
            ranks = int(getattr(args, "mpi", 1) or 1)
            if ranks < 1:
                raise InputError(f"--mpi must be >= 1, got {ranks}")
            for s in sizes:
                result["part_b"].append(run_size(s, F, args.timeout, args.petsc_option, profile=args.profile))
                save()
                if ranks > 1:
                    row = run_size(s, F, args.timeout, args.petsc_option, ranks=ranks)
                    row.update(compare_ranks(result["part_b"][-1], row))
                    result["part_b"].append(row)
                    save()
            print(table_b(result["part_b"]), flush=True)
            print("ratio = (assembly + factor K + condensation + path) / (assembly + factor K)", flush=True)
        if "C" in part or "D" in part:
            from cfcontact import bench_stress as bs
        if "C" in part:
            print("Part C: long interfaces (exact method, condensed backend with factorization updates)", flush=True)
            result["part_c"] = bs.part_c(quick=args.quick, time_limit=time_limit, sizes=strip_m)
            save()
            print(bs.table(result["part_c"]["rows"]), flush=True)
            print(f"log-log slope of the time per transition against m: {result['part_c']['slope']} "
                  f"(the path's time with its start, per transition: {result['part_c']['slope_with_start']})",
                  flush=True)
        if "D" in part:
            print("Part D: hard cases of the exact method", flush=True)
            result["part_d"] = bs.part_d(quick=args.quick, paths=paths, time_limit=time_limit, sizes=strip_m,
                                         seed_limit=seed_check)
            save()
            print(bs.table(result["part_d"]["rows"]), flush=True)
            for name, rl in result["part_d"]["random_loads"].items():
                print(f"random load paths, {name} model, F = 30: {rl['summary']}", flush=True)
        if "E" in part:
            print("Part E: friction map, fold curves and critical friction of the main demo's load path", flush=True)
            result["part_e"] = part_e(quick=args.quick)
            save()
            print(table_e(result["part_e"]), flush=True)
        result["machine"]["loadavg_end"] = os.getloadavg()
        save()
        print(f"\nwritten {os.path.abspath(jpath)}")
        return 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_arguments(ap)
    ap.add_argument("--worker-b", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker_b:
        nx, ny, F = args.worker_b.split(",")
        res = worker_b(int(nx), int(ny), float(F), args.petsc_option, profile=args.profile)
        from mpi4py import MPI

        if MPI.COMM_WORLD.rank == 0:
            print("BENCH-RESULT " + json.dumps(res), flush=True)
        return 0
    try:
        return run(args, " ".join(["cfcontact.bench"] + list(sys.argv[1:] if argv is None else argv)))
    except InputError as exc:
        print(f"bench: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
