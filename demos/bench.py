"""Benchmarks of cfcontact's path following (see docs/bench.md for measured numbers).

Part A -- seed vs exact on the main demo (``demos/main.py``: ``build(F)`` for every F in
``DEMO_FRICTIONS``).  The seed method runs with the default PETSc backend
(:class:`cfcontact.DirNeuSolver`: one factorization of J(Z) per branch), the exact method with
:class:`cfcontact.condensed.CondensedSolver` (K factored once, dense 2m x 2m systems per branch).
Reported per method: linear solves, factorizations (for the condensed backend: factorizations
of K and dense factorizations separately), wall time, transitions, folds, largest number of
solutions at one alpha, worst residual of (1)-(3) over the stored points; the speed-up
seed / exact and whether both give the same sequence of set changes (node, set, kind) with
transition alphas agreeing within the seed's h_min.

Part B -- the exact method alone on refined two-block meshes (n ~ 1e4, 1.2e5, 1e6 DOFs;
nx = 3 ny cells per block, n = 4 nx (ny + 1), m = nx contact nodes), with the demo's loads and
its largest friction coefficient.  Every size runs in a fresh subprocess (peak memory =
``ru_maxrss`` of that process) and reports the time split

    assembly (two_blocks) | factorization of K (PETSc log: MatLUFactorSym + MatLUFactorNum) |
    condensation (S = B K^-1 B^T) | path (trace_path, the rest)

and the ratio total / (assembly + factorization of K), total = the sum of the four.

Part B runs the condensed backend with two bench-local improvements (``--variant improved``,
default; ``--variant baseline`` runs the library's CondensedSolver unchanged):

* The dense DirNeu system is reduced to the free multipliers (lam_n of closed nodes, lam_t of
  sticking nodes; lam_t = +-F lam_n of slipping nodes is substituted), so each branch
  LU-factors a k x k matrix, k <= 2m, instead of the 2m x 2m matrix with identity rows.
* The two displacements of a branch, u = K^-1 (f1 - B^T lam1) and K^-1 (f2 - B^T lam2), are
  computed by one 2-column solve with K (MatMatSolve) instead of two single solves.

The library never keeps K^-1 B^T for displacements: u = K^-1 f - (K^-1 B^T) lam cancels
heavily (the contact forces nearly balance the load); its equilibrium residual grew with the
mesh (5e-10 at n = 2e4, 4e-8 at n = 1.2e5, above the 1e-8 of the checks) while
K^-1 (f - B^T lam) stays at 1e-12, and reading the n x 2m dense block was only ~1.5x faster
than a sparse solve.

Sizes above 5e5 DOFs run in "lean" storage: each stored path point is verified when it is
added and only its multipliers are kept (the full path keeps 4 vectors of length n per branch,
about 32 MB per branch at n = 1e6, which does not fit in memory with ~1e3 branches).  The
verification time is subtracted from the path time.

Run:  .venv/bin/python demos/bench.py [--quick] [--sizes 1e4,1.2e5,1e6] [--skip-large]
      [--output DIR] [--part A|B|AB] [--variant improved|baseline] [--timeout S]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import resource
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
for _p in (ROOT, HERE):
    if _p not in sys.path:
        sys.path.insert(0, _p)

SIZES = (1e4, 1.2e5, 1e6)
QUICK_SIZES = (2e3, 1e4)
LARGE = 5e5  # --skip-large drops sizes above this; lean storage above this


def demo():
    """The main demo's constants (imported, never copied: the lead is still tuning them)."""
    import main as demo_main

    return demo_main


def peak_rss_gib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # ru_maxrss is in KiB on Linux


def mesh_for(n_target: float):
    """(nx, ny, n) of a two-block mesh with nx = 3 ny and n = 4 nx (ny + 1) ~ n_target."""
    ny = max(2, int(round((-1.0 + math.sqrt(1.0 + n_target / 3.0)) / 2.0)))
    nx = 3 * ny
    return nx, ny, 4 * nx * (ny + 1)


# ====================================================================== solvers
def _condensed_classes():
    from collections import OrderedDict

    import scipy.linalg as sla

    from cfcontact.condensed import CondensedSolver
    from cfcontact.errors import SingularSystemError

    class TimedCondensedSolver(CondensedSolver):
        """The library's CondensedSolver, timing the condensation (forming S)."""

        t_schur = 0.0

        def _schur(self):
            t0 = time.perf_counter()
            S = super()._schur()
            self.t_schur = time.perf_counter() - t0
            return S

    class ImprovedCondensedSolver(TimedCondensedSolver):
        """Reduced dense DirNeu systems + the two displacements of a branch in one 2-column solve."""

        def _factor(self, Z):
            key = Z.canonical_key(self.system.friction)
            if key in self._lu:
                self._lu.move_to_end(key)
                return self._lu[key]
            m = self.m
            act_n, act_t = ~Z.nu, ~Z.it
            rows = np.concatenate([np.flatnonzero(act_n), m + np.flatnonzero(act_t)])  # = free unknowns
            sgn = Z.tp.astype(float) - Z.tm.astype(float)
            slip = np.flatnonzero(Z.it & act_n)  # lam_t,i = F sgn lam_n,i substituted
            coef = self.F[slip] * sgn[slip]
            pos = np.searchsorted(rows[: int(act_n.sum())], slip)  # column of lam_n,i in the reduced system
            Sr = self.S[rows]
            M = Sr[:, rows]
            if slip.size:
                M[:, pos] += Sr[:, m + slip] * coef
            if M.size:
                lu, piv = sla.lu_factor(M, check_finite=False)
                d = np.abs(np.diag(lu))
                if not np.all(np.isfinite(d)) or d.min() <= 1e-14 * max(d.max(), 1e-300):
                    raise SingularSystemError(f"DirNeu(Z) is singular (reduced condensed matrix) for {Z!r}")
            else:
                lu, piv = M, np.zeros(0, dtype=np.int32)
            self.stats.dense_factorizations += 1
            self._lu[key] = (lu, piv, rows, slip, coef)
            while len(self._lu) > max(64, self.options.cache):
                self._lu.popitem(last=False)
            return self._lu[key]

        def multipliers(self, Z, w):
            if self.m == 0:
                return np.zeros(0)
            lu, piv, rows, slip, coef = self._factor(Z)
            self.stats.dense_solves += 1
            lam = np.zeros(2 * self.m)
            if rows.size:
                lam[rows] = sla.lu_solve((lu, piv), w[rows], check_finite=False)
            lam[self.m + slip] = coef * lam[slip]
            self._remember_pair(Z, w, lam)
            return lam

        # -- the two displacements of a branch (loads f1, f2) in one 2-column solve with K
        def _remember_pair(self, Z, w, lam):
            f = next((g for g, ww in self._loads if ww is w), None)
            if f is None:
                return
            if not hasattr(self, "_pairs"):
                self._pairs, self._done, self._pending = OrderedDict(), OrderedDict(), None
            key = Z.canonical_key(self.system.friction)
            prev = self._pending
            if prev is not None and prev[0] == key and prev[2] is not f:
                self._pairs[id(prev[1])] = (prev[1], lam, f)
                self._pairs[id(lam)] = (lam, prev[1], prev[2])
                while len(self._pairs) > 2048:
                    self._pairs.popitem(last=False)
                self._pending = None
            else:
                self._pending = (key, lam, f)

        def displacement(self, f, lam):
            if self.size > 1 or not hasattr(self, "_pairs"):
                return super().displacement(f, lam)
            done = self._done.pop(id(lam), None)
            if done is not None and done[0] is lam:
                return done[1]
            pair = self._pairs.get(id(lam))
            if pair is None or pair[0] is not lam:
                return super().displacement(f, lam)
            _, other, f_other = pair
            rhs = np.column_stack([f - self.B.T @ lam, f_other - self.B.T @ other])
            U = self._ksolve_dense(rhs)
            self._done[id(other)] = (other, U[:, 1].copy())
            while len(self._done) > 64:
                self._done.popitem(last=False)
            return U[:, 0].copy()

    return TimedCondensedSolver, ImprovedCondensedSolver


def make_condensed(system, variant="baseline"):
    Timed, Improved = _condensed_classes()
    if variant == "baseline":
        return Timed(system)
    return Improved(system)


# ====================================================================== Part A
def _method_result(path, system, solver, wall, extra=None):
    mult, at = path.max_multiplicity()
    return {"status": path.status, "transitions": len(path.transitions), "folds": len(path.folds),
            "branches": len(path.branches), "points": len(path.points), "max_multiplicity": mult,
            "alpha_of_max": at, "wall_time": wall, "events": [e.kind for e in path.events],
            "worst_residual": demo().worst_residual(system, path, solver), **(extra or {})}


def compare_paths(seed, exact, friction) -> dict:
    """Same sequence of set changes (node, set, kind)?  Transition alphas within the seed's h_min?"""
    from cfcontact.exact import canonical_codes

    ks = [(t.node, t.set, t.kind) for t in seed.transitions]
    ke = [(t.node, t.set, t.kind) for t in exact.transitions]
    h_min = float(seed.options.get("h_min", 1e-5))
    same = ks == ke
    diffs = [abs(a.alpha - b.alpha) for a, b in zip(seed.transitions, exact.transitions)]
    in_bracket = all(s.bracket[0] - 1e-12 <= e.alpha <= s.bracket[1] + 1e-12
                     for s, e in zip(seed.transitions, exact.transitions))
    first = next((i for i, (a, b) in enumerate(zip(ks, ke)) if a != b), None if same else min(len(ks), len(ke)))
    sets_s = [canonical_codes(b.sets, friction).tolist() for b in seed.branches]
    sets_e = [canonical_codes(b.sets, friction).tolist() for b in exact.branches]
    return {"same_set_changes": same, "first_difference": first, "h_min": h_min,
            "max_alpha_difference": max(diffs, default=0.0),
            "alphas_within_h_min": bool(same and all(d <= h_min for d in diffs)),
            "exact_alpha_in_seed_bracket": bool(same and in_bracket),
            "same_branch_sets": sets_s == sets_e}


def part_a(quick=False, frictions=None, log=print) -> list:
    import cfcontact
    from cfcontact.ssnm import DirNeuSolver

    dm = demo()
    out = []
    for F in (frictions or dm.DEMO_FRICTIONS):
        t0 = time.perf_counter()
        system = dm.build(F, quick=quick)
        t_asm = time.perf_counter() - t0
        # seed: default PETSc backend (fresh solver so its counters are this run's)
        t0 = time.perf_counter()
        ssolver = DirNeuSolver(system)
        sp_ = cfcontact.trace_path(system, *dm.DEMO_ALPHA, method="seed", solver=ssolver)
        t_seed = time.perf_counter() - t0
        st = ssolver.stats.as_dict()
        seed = _method_result(sp_, system, ssolver, t_seed, {
            "linear_solves": st["linear_solves"], "factorizations": st["factorizations"],
            "ssnm_iterations": st["ssnm_iterations"]})
        # exact: condensed backend, its construction (K factorization, S) counted in the wall time
        t0 = time.perf_counter()
        csolver = make_condensed(system, "baseline")
        t_setup = time.perf_counter() - t0
        ep = cfcontact.trace_path(system, *dm.DEMO_ALPHA, method="exact", solver=csolver)
        t_exact = time.perf_counter() - t0
        ct = csolver.stats.as_dict()
        exact = _method_result(ep, system, csolver, t_exact, {
            "linear_solves": ct["linear_solves"], "linear_solves_path": ep.stats.get("linear_solves"),
            "K_factorizations": ct["factorizations"], "dense_factorizations": ct["dense_factorizations"],
            "dense_solves": ct["dense_solves"], "ssnm_iterations": ct["ssnm_iterations"],
            "setup_time": t_setup, "condensation_time": csolver.t_schur, "path_time": t_exact - t_setup})
        # the bench-local improved backend (Part B) must give the same path
        t0 = time.perf_counter()
        isolver = make_condensed(system, "improved")
        ip = cfcontact.trace_path(system, *dm.DEMO_ALPHA, method="exact", solver=isolver)
        t_imp = time.perf_counter() - t0
        cmp_i = compare_paths(ep, ip, F)
        improved = {"wall_time": t_imp, "transitions": len(ip.transitions),
                    "worst_residual": demo().worst_residual(system, ip, isolver),
                    "same_set_changes_as_exact": cmp_i["same_set_changes"],
                    "max_alpha_difference_to_exact": cmp_i["max_alpha_difference"]}
        res = {"friction": F, "n": system.n, "m": system.m, "assembly_time": t_asm, "seed": seed, "exact": exact,
               "exact_improved": improved, "speedup": t_seed / max(t_exact, 1e-300), **compare_paths(sp_, ep, F)}
        out.append(res)
        log(f"  F = {F:g}: seed {t_seed:.2f} s, exact {t_exact:.3f} s, speed-up {res['speedup']:.0f}, "
            f"same set changes: {res['same_set_changes']}")
    return out


def table_a(rows) -> str:
    head = (f"{'F':>5} {'n':>6} {'m':>4} {'method':>6} {'solves':>7} {'K fact.':>7} {'dense f.':>8} "
            f"{'time [s]':>9} {'trans.':>6} {'folds':>5} {'max sol':>7} {'residual':>9} {'speed-up':>8} "
            f"{'same seq.':>9} {'max |da|':>9}")
    lines = [head, "-" * len(head)]
    for r in rows:
        for name in ("seed", "exact"):
            d = r[name]
            kf = d["factorizations"] if name == "seed" else d["K_factorizations"]
            dense = "-" if name == "seed" else str(d["dense_factorizations"])
            tail = (f"{r['speedup']:>8.0f} {str(r['same_set_changes']):>9} {r['max_alpha_difference']:>9.1e}"
                    if name == "exact" else "")
            lines.append(f"{r['friction']:>5g} {r['n']:>6} {r['m']:>4} {name:>6} {d['linear_solves']:>7} {kf:>7} "
                         f"{dense:>8} {d['wall_time']:>9.3f} {d['transitions']:>6} {d['folds']:>5} "
                         f"{d['max_multiplicity']:>7} {d['worst_residual']:>9.1e} {tail}".rstrip())
    return "\n".join(lines)


# ====================================================================== Part B
def _lean_storage(system, solver, acc):
    """Patch SolutionPath so that stored points are verified on the spot and only their
    multipliers are kept (bench worker process only)."""
    import cfcontact
    from cfcontact.path import SolutionPath

    n = system.n
    add_point, add_branch = SolutionPath.add_point, SolutionPath.add_branch

    def lean_point(self, branch, alpha, y):
        t0 = time.perf_counter()
        acc["worst_residual"] = max(acc["worst_residual"], cfcontact.verify(system, y, alpha, solver=solver).worst())
        acc["verify_time"] += time.perf_counter() - t0
        return add_point(self, branch, alpha, np.array(y[n:]))

    def lean_branch(self, sets, orientation, Y1, Y2, **kw):
        return add_branch(self, sets, orientation, np.array(Y1[n:]), np.array(Y2[n:]), **kw)

    SolutionPath.add_point, SolutionPath.add_branch = lean_point, lean_branch


def worker_b(nx, ny, friction, variant, lean, petsc_options) -> dict:
    from petsc4py import PETSc

    for kv in petsc_options:
        k, _, v = kv.partition("=")
        PETSc.Options()[k.lstrip("-")] = v
    PETSc.Log.begin()
    import cfcontact

    dm = demo()
    res = {"nx": nx, "ny": ny, "friction": friction, "variant": variant, "lean": lean,
           "petsc_options": list(petsc_options), "stage": "assembly"}

    def dump():  # partial results survive a crash / kill
        print("BENCH-PARTIAL " + json.dumps(res), flush=True)

    t0 = time.perf_counter()
    system = cfcontact.two_blocks(nx=nx, ny=ny, friction=friction, tractions1=dm.DEMO_F1, tractions2=dm.DEMO_F2,
                                  **dm.DEMO_MODEL)
    res.update(n=system.n, m=system.m, assembly_time=time.perf_counter() - t0, rss_after_assembly_gib=peak_rss_gib(),
               stage="factorization")
    dump()
    t0 = time.perf_counter()
    solver = make_condensed(system, variant)
    t_setup = time.perf_counter() - t0
    t_fact = sum(PETSc.Log.Event(e).getPerfInfo()["time"] for e in ("MatLUFactorSym", "MatLUFactorNum"))
    res.update(factorization_time=t_fact, condensation_time=solver.t_schur,
               setup_other_time=t_setup - t_fact - solver.t_schur, S_in_one_solve=bool(solver.store),
               rss_after_condensation_gib=peak_rss_gib(), stage="path")
    try:
        fm = solver.ksp.getPC().getFactorMatrix()
        res["mumps_info"] = {"INFOG(3) factor entries est.": fm.getMumpsInfog(3),
                             "INFOG(9) factor entries": fm.getMumpsInfog(9),
                             "INFOG(21) MB per proc": fm.getMumpsInfog(21), "ICNTL(7)": fm.getMumpsIcntl(7),
                             "ICNTL(14)": fm.getMumpsIcntl(14), "INFOG(7) ordering": fm.getMumpsInfog(7)}
    except Exception as exc:  # not MUMPS
        res["mumps_info"] = str(exc)
    dump()
    acc = {"worst_residual": 0.0, "verify_time": 0.0}
    if lean:
        _lean_storage(system, solver, acc)
    prof = {}
    import cProfile
    import pstats

    pr = cProfile.Profile()
    t0 = time.perf_counter()
    pr.enable()
    path = cfcontact.trace_path(system, *dm.DEMO_ALPHA, method="exact", solver=solver)
    pr.disable()
    t_path = time.perf_counter() - t0 - acc["verify_time"]
    stats = pstats.Stats(pr)
    for (fname, line, func), (cc, nc, tt, ct, callers) in stats.stats.items():
        prof[f"{os.path.basename(fname)}:{func}"] = prof.get(f"{os.path.basename(fname)}:{func}", 0.0) + tt
    top = sorted(prof.items(), key=lambda kv: -kv[1])[:8]
    st = solver.stats.as_dict()
    res.update(path_time=t_path, status=path.status, transitions=len(path.transitions), folds=len(path.folds),
               branches=len(path.branches), K_factorizations=st["factorizations"], linear_solves=st["linear_solves"],
               dense_factorizations=st["dense_factorizations"], dense_solves=st["dense_solves"],
               profile_top_tottime=[[k, v] for k, v in top], rss_after_path_gib=peak_rss_gib(), stage="verify")
    if not lean:
        t0 = time.perf_counter()
        acc["worst_residual"] = demo().worst_residual(system, path, solver)
        acc["verify_time"] = time.perf_counter() - t0
    res.update(worst_residual=acc["worst_residual"], verify_time=acc["verify_time"])
    total = res["assembly_time"] + t_fact + solver.t_schur + res["setup_other_time"] + t_path
    base = res["assembly_time"] + t_fact
    res.update(total_time=total, ratio=total / base, peak_rss_gib=peak_rss_gib(), stage="done")
    return res


def run_size(n_target, friction, variant, timeout, petsc_options, log=print) -> dict:
    nx, ny, n_est = mesh_for(n_target)
    lean = n_est > LARGE
    cmd = [sys.executable, os.path.abspath(__file__), "--worker-b", f"{nx},{ny},{friction!r}",
           "--variant", variant] + (["--lean"] if lean else [])
    for o in petsc_options:
        cmd += ["--petsc-option", o]
    log(f"  n ~ {n_target:.3g}: nx = {nx}, ny = {ny} (n = {n_est}, m = {nx}), {variant}{', lean' if lean else ''} ...")
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=ROOT)
        out, err, rc = proc.stdout, proc.stderr, proc.returncode
    except subprocess.TimeoutExpired as exc:
        out = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        err, rc = f"timeout after {timeout} s", "timeout"
    res = {"n_target": n_target, "nx": nx, "ny": ny}
    for line in out.splitlines():
        if line.startswith("BENCH-PARTIAL ") or line.startswith("BENCH-RESULT "):
            res.update(json.loads(line.split(" ", 1)[1]))
    res["returncode"] = rc
    res["elapsed"] = time.perf_counter() - t0
    if rc != 0:
        res["error"] = (err or "")[-3000:]
        res["failed_in_stage"] = res.get("stage")
        log(f"    FAILED ({rc}) in stage {res.get('stage')}: {(err or '').strip().splitlines()[-1:] or ''}")
    return res


def table_b(rows) -> str:
    head = (f"{'n':>8} {'m':>4} {'assembly':>9} {'factor K':>9} {'condense':>9} {'path':>9} {'total':>9} "
            f"{'ratio':>6} {'trans.':>6} {'dense f.':>8} {'peak GiB':>8} {'residual':>9} {'status':>10}")
    lines = [head, "-" * len(head)]
    f = lambda r, k, w=9, p=2: f"{r[k]:>{w}.{p}f}" if isinstance(r.get(k), (int, float)) else f"{'-':>{w}}"  # noqa
    for r in rows:
        status = r.get("status") or f"FAIL:{r.get('failed_in_stage')}"
        lines.append(f"{r.get('n', r.get('n_target')):>8} {r.get('m', r.get('nx')):>4} {f(r, 'assembly_time')} "
                     f"{f(r, 'factorization_time')} {f(r, 'condensation_time')} {f(r, 'path_time')} "
                     f"{f(r, 'total_time')} {f(r, 'ratio', 6, 1)} {r.get('transitions', '-'):>6} "
                     f"{r.get('dense_factorizations', '-'):>8} {f(r, 'peak_rss_gib', 8, 2)} "
                     f"{r.get('worst_residual', float('nan')):>9.1e} {status:>10}")
    return "\n".join(lines)


# ====================================================================== main
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="coarse demo mesh in Part A, small sizes in Part B")
    ap.add_argument("--sizes", help="Part B target DOF counts, comma separated (default 1e4,1.2e5,1e6; "
                                    "--quick: 2e3,1e4)")
    ap.add_argument("--skip-large", action="store_true", help=f"drop Part B sizes above {LARGE:g} DOFs")
    ap.add_argument("--output", default="output/bench", help="folder for bench.json (default output/bench)")
    ap.add_argument("--part", default="AB", help="A, B or AB (default)")
    ap.add_argument("--variant", default="improved", choices=("improved", "baseline"),
                    help="Part B condensed backend (see the module docstring)")
    ap.add_argument("--timeout", type=float, default=4 * 3600.0, help="per-size time limit of Part B [s]")
    ap.add_argument("--petsc-option", action="append", default=[],
                    help="PETSc option for Part B, e.g. cfcontact_K_mat_mumps_icntl_7=5")
    ap.add_argument("--worker-b", help=argparse.SUPPRESS)
    ap.add_argument("--lean", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)

    if args.worker_b:
        nx, ny, F = args.worker_b.split(",")
        res = worker_b(int(nx), int(ny), float(F), args.variant, args.lean, args.petsc_option)
        print("BENCH-RESULT " + json.dumps(res), flush=True)
        return 0

    dm = demo()
    result = {"machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "python": sys.version.split()[0],
                          "loadavg_start": os.getloadavg()},
              "demo": {"model": dm.DEMO_MODEL, "f1": dm.DEMO_F1, "f2": dm.DEMO_F2,
                       "frictions": list(dm.DEMO_FRICTIONS), "alpha": list(dm.DEMO_ALPHA)},
              "quick": args.quick, "command": " ".join([os.path.relpath(sys.argv[0], ROOT)] + (argv or sys.argv[1:]))}
    os.makedirs(args.output, exist_ok=True)
    jpath = os.path.join(args.output, "bench.json")

    def save():
        with open(jpath, "w") as fh:
            json.dump(result, fh, indent=1, default=float)

    if "A" in args.part.upper():
        print("Part A: seed vs exact on the main demo" + (" (quick mesh)" if args.quick else ""), flush=True)
        result["part_a"] = part_a(quick=args.quick)
        save()
        print(table_a(result["part_a"]), "\n", flush=True)
    if "B" in args.part.upper():
        sizes = [float(s) for s in args.sizes.split(",")] if args.sizes else list(QUICK_SIZES if args.quick else SIZES)
        if args.skip_large:
            sizes = [s for s in sizes if s <= LARGE]
        F = max(dm.DEMO_FRICTIONS)
        print(f"Part B: exact method, condensed backend ({args.variant}), F = {F:g}", flush=True)
        result["part_b"] = []
        for s in sizes:
            result["part_b"].append(run_size(s, F, args.variant, args.timeout, args.petsc_option))
            save()
        print(table_b(result["part_b"]), flush=True)
        print("ratio = (assembly + factor K + condensation + path) / (assembly + factor K)", flush=True)
    result["machine"]["loadavg_end"] = os.getloadavg()
    save()
    print(f"\nwritten {os.path.abspath(jpath)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
