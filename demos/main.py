"""The seed's experiment (its Figures 5 and 6): the main demo of cfcontact.

Two stacked elastic blocks (the default two-block model: 30 x 10 quadrilaterals each,
n = 1320, m = 30), loaded along f(alpha) = (1 - alpha) f1 + alpha f2, traced for three
friction coefficients.  For each F it prints and writes:

* a Figure-6-style plot, alpha against lam_n at one contact node, folds marked (PNG + PDF);
* the number of transitions, folds, the largest number of solutions at one alpha, linear
  solves, factorizations and wall time (``summary.json`` and a table on stdout);
* a check that every stored path point solves (1)-(3) (worst relative residual);
* pyvista pictures of the deformed bodies for every distinct solution at an alpha of largest
  multiplicity (contact nodes coloured open / stick / slip).

Run ``./demo.sh`` (or ``.venv/bin/python demos/main.py --help``).  ``--quick`` uses a coarse
mesh (the test suite runs it that way).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time

import numpy as np

import cfcontact
from cfcontact import plotting

# The load path of the demo (tractions in Pa on the tagged edges of the two-block model, both
# blocks clamped on their left edges).  The lower block is half as high as the upper one: with
# identical mirrored blocks the normal and tangential compliances of each contact node do not
# couple (by symmetry), and without that coupling friction cannot make the solution non-unique.
# The loads were found by a search over random tractions with the exact method (the per-F
# outcome is printed by the demo and checked by tests/test_demos.py on a coarse mesh):
# f1 presses/shears body 1 on its top and right edges and pushes body 2's bottom to the right;
# f2 shears body 1's top to the right and pushes body 2 up and to the left.
DEMO_MODEL = dict(height=1.0, height2=0.5, length=3.0)
DEMO_F1 = {"top1": (-5.734e7, 3.658e6), "right1": (3.910e7, -8.724e7), "bottom2": (1.877e8, -1.500e6)}
DEMO_F2 = {"top1": (1.0e8, 0.0), "right2": (-5.807e7, 1.510e3), "bottom2": (-1.045e8, 1.450e8)}
DEMO_FRICTIONS = (0.1, 0.6, 30.0)
DEMO_ALPHA = (0.0, 1.0)


def build(friction, quick=False, comm=None):
    kw = dict(DEMO_MODEL)
    if quick:
        kw.update(nx=12, ny=4)
    return cfcontact.two_blocks(friction=friction, tractions1=DEMO_F1, tractions2=DEMO_F2, comm=comm, **kw)


def worst_residual(system, path, solver=None):
    """Worst relative violation of (1)-(3) over the stored points of a path."""
    return max((cfcontact.verify(system, y, alpha, solver=solver).worst() for alpha, y in path.points), default=0.0)


def run(frictions=DEMO_FRICTIONS, quick=False, output="output/demo", method="seed", render=True, log=print):
    """Trace the three paths; return the list of per-F result dicts."""
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    rank0 = comm.rank == 0
    if rank0:
        os.makedirs(output, exist_ok=True)
    results = []
    for F in frictions:
        t0 = time.perf_counter()
        system = build(F, quick=quick)
        t_asm = time.perf_counter() - t0
        path = cfcontact.trace_path(system, *DEMO_ALPHA, method=method)
        mult, alpha_star = path.max_multiplicity()
        res = {
            "friction": F, "n": system.n, "m": system.m, "method": method, "status": path.status,
            "transitions": len(path.transitions), "folds": len(path.folds),
            "max_multiplicity": mult, "alpha_of_max": alpha_star,
            "fold_alphas": [t.alpha for t in path.folds],
            "linear_solves": path.stats.get("linear_solves"), "factorizations": path.stats.get("factorizations"),
            "wall_time_path": path.stats.get("wall_time"), "wall_time_assembly": t_asm,
            "worst_residual": worst_residual(system, path), "events": [e.kind for e in path.events],
        }
        tag = f"F{F:g}"
        if rank0:
            path.save(os.path.join(output, f"path_{tag}"))
            comp = plotting.default_component(path)
            zoom = None
            if path.folds:
                a = sorted(t.alpha for t in path.folds)
                pad = max(0.05 * (a[-1] - a[0]), 1e-3)
                zoom = (a[0] - pad, a[-1] + pad)
            fig = plotting.plot_path(path, component=comp, zoom=zoom,
                                     title=f"F = {F:g}: {len(path.folds)} folds, up to {mult} solutions")
            for ext in ("png", "pdf"):
                plotting.save_figure(fig, os.path.join(output, f"path_{tag}.{ext}"))
            res["plot"] = os.path.join(output, f"path_{tag}.png")
        if render and rank0 and np.isfinite(alpha_star):
            from cfcontact import render as rnd

            sols = path.solutions_at(alpha_star)
            res["panel"] = os.path.join(output, f"solutions_{tag}.png")
            rnd.render_panel(system.geometry, sols, res["panel"])
        results.append(res)
        log(f"F = {F:g}: {res['status']}, {res['transitions']} transitions, {res['folds']} folds, "
            f"max {mult} solutions at alpha = {alpha_star:.6g}, {res['linear_solves']} solves, "
            f"{res['wall_time_path']:.2f} s, worst residual {res['worst_residual']:.1e}")
    if rank0:
        with open(os.path.join(output, "summary.json"), "w") as fh:
            json.dump(results, fh, indent=1)
    return results


def table(results) -> str:
    head = f"{'F':>6} {'n':>6} {'m':>4} {'transitions':>11} {'folds':>5} {'max sol.':>8} {'solves':>7} " \
           f"{'factor.':>7} {'time [s]':>8} {'residual':>9}"
    rows = [head, "-" * len(head)]
    for r in results:
        rows.append(f"{r['friction']:>6g} {r['n']:>6} {r['m']:>4} {r['transitions']:>11} {r['folds']:>5} "
                    f"{r['max_multiplicity']:>8} {r['linear_solves']:>7} {r['factorizations']:>7} "
                    f"{r['wall_time_path']:>8.2f} {r['worst_residual']:>9.1e}")
    return "\n".join(rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--output", default="output/demo", help="output folder (default: output/demo)")
    ap.add_argument("--quick", action="store_true", help="coarse mesh (12 x 4 cells per block)")
    ap.add_argument("--method", default="seed", choices=("seed", "exact"), help="path-following method")
    ap.add_argument("--no-render", action="store_true", help="skip the pyvista pictures")
    ap.add_argument("--friction", type=float, action="append", help="friction coefficient(s) (default 0.1 0.6 30)")
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    from mpi4py import MPI

    say = print if MPI.COMM_WORLD.rank == 0 else (lambda *a, **k: None)
    results = run(tuple(args.friction or DEMO_FRICTIONS), quick=args.quick, output=args.output, method=args.method,
                  render=not args.no_render, log=say)
    say("")
    say(table(results))
    say(f"\nwritten to {os.path.abspath(args.output)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
