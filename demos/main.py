"""The seed's experiment (its Figures 5 and 6): the main demo of cfcontact.

Two stacked elastic bodies -- a steel block on a soft layer, 30 x 10 cells each (triangles),
n = 1320, m = 30 -- loaded along f(alpha) = (1 - alpha) f1 + alpha f2 and traced for the seed's
three kinds of friction coefficient: a small one (F = 0.1: transversal transitions only, one
solution everywhere), F = 0.6 (two folds, three solutions on an alpha interval) and F = 30
(five folds, six solutions).  For each F it prints and writes:

* a Figure-6-style plot, alpha against lam_n at one contact node, folds marked (PNG + PDF);
* the number of transitions, folds, the largest number of solutions at one alpha, linear
  solves, factorizations and wall time, the set-up of the path's linear-algebra backend included
  (``summary.json`` and a table on stdout);
* a check that every stored path point solves (1)-(3) (worst relative residual);
* pyvista pictures of the deformed bodies for every distinct solution at an alpha of largest
  multiplicity (contact nodes coloured open / stick / slip).

Run ``./demo.sh`` (or ``.venv/bin/python demos/main.py --help``); ``--method exact`` traces the
same paths with the exact method.  The test suite runs this demo (tests/test_demos.py).
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
from cfcontact.demo_models import DEMO_ALPHA, DEMO_FRICTIONS, build_demo
from cfcontact.path import select_solver
from cfcontact.report import worst_residual

# The model and the load path (numbers, and why this model) live in the package, where the
# benchmark and the tests use them too: cfcontact/demo_models.py.
build = build_demo


def fold_component(path):
    """The plotted component: lam_n at the node of the folds whose lam_n varies most along the path
    (the turning points show there, as in the seed's Figure 6), else plotting's default."""
    nodes = sorted({t.node for t in path.folds if t.node is not None and t.node >= 0})
    if not nodes:
        return plotting.default_component(path)
    lam_n = path.lams[:, nodes]
    return ("lam_n", nodes[int(np.argmax(lam_n.max(axis=0) - lam_n.min(axis=0)))])


def run(frictions=DEMO_FRICTIONS, output="output/demo", method="seed", render=True, log=print):
    """Trace the three paths; return the list of per-F result dicts."""
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    rank0 = comm.rank == 0
    if rank0:
        os.makedirs(output, exist_ok=True)
    results = []
    for F in frictions:
        t0 = time.perf_counter()
        system = build(F)
        t_asm = time.perf_counter() - t0
        t0 = time.perf_counter()
        path = cfcontact.trace_path(system, *DEMO_ALPHA, method=method)
        t_path = time.perf_counter() - t0
        # the backend trace_path made for this new system: its counters include its set-up (for
        # the exact method's condensed solver: the factorization of K and the solves for S),
        # which path.stats (the work of the tracing alone) leaves out
        work = select_solver(system, method).stats
        mult, alpha_star = path.max_multiplicity()
        res = {
            "friction": F, "n": system.n, "m": system.m, "method": method, "status": path.status,
            "transitions": len(path.transitions), "folds": len(path.folds),
            "max_multiplicity": mult, "alpha_of_max": alpha_star,
            "fold_alphas": [t.alpha for t in path.folds],
            "linear_solves": work.linear_solves, "factorizations": work.factorizations,
            "wall_time_path": t_path, "wall_time_assembly": t_asm,
            "worst_residual": worst_residual(system, path, points=path.points), "events": [e.kind for e in path.events],
        }
        tag = f"F{F:g}"
        if rank0:
            path.save(os.path.join(output, f"path_{tag}"))
            comp = fold_component(path)
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
            f"{res['wall_time_path']:.3g} s, worst residual {res['worst_residual']:.1e}")
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
                    f"{r['wall_time_path']:>8.3g} {r['worst_residual']:>9.1e}")
    return "\n".join(rows)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--output", default="output/demo", help="output folder (default: output/demo)")
    ap.add_argument("--method", default="seed", choices=("seed", "exact"), help="path-following method")
    ap.add_argument("--no-render", action="store_true", help="skip the pyvista pictures")
    ap.add_argument("--friction", type=float, action="append", help="friction coefficient(s) (default 0.1 0.6 30)")
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    from mpi4py import MPI

    say = print if MPI.COMM_WORLD.rank == 0 else (lambda *a, **k: None)
    results = run(tuple(args.friction or DEMO_FRICTIONS), output=args.output, method=args.method,
                  render=not args.no_render, log=say)
    say("")
    say(table(results))
    say(f"\nwritten to {os.path.abspath(args.output)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
