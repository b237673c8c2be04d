"""Validation against Cattaneo-Mindlin: partial slip of a cylinder on a block under a growing
tangential load, along one solution path (the exact and the seed method).

The model is the Hertz demo's (``demos/hertz.py``: a half-cylinder R = 1 on a block, identical
materials E = 1, nu = 0.3, plane strain, node-to-segment pairing), with friction F.  Along the
load path the cylinder's top is held at the indentation ``delta`` (the normal load P stays
put) and moved sideways by ``alpha * s``: the tangential load Q(alpha) -- the tangential contact
force, sum of lam_t -- grows from 0 to 0.9 F P at alpha = 1 (``s`` is found from an
exploratory exact path).  The top is displacement-controlled because a body held only by
contact has a singular stiffness; Q(alpha) is therefore measured on the path (it is piecewise
affine in alpha), P(alpha) too (it barely changes: identical materials do not couple normal and
tangential contact).

Cattaneo-Mindlin: the stick zone is |x| < c with c = a sqrt(1 - Q / (F P)), a Hertz's half-width
for P.  So node x, in contact and sticking at alpha = 0, starts to slip where c(alpha) = |x|:
the analytic alpha of its stick-to-slip transition.  The demo compares every stick-to-slip
transition of the traced path with it, within the larger of 0.05 and the alpha-change over two
element sizes (|alpha(c = |x| +- 2h) - alpha(c = |x|)|).  The mesh is mirror-symmetric, so the
nodes at x and -x start to slip at nearly the same alpha (up to the small normal-tangential
coupling of the finite bodies): transitions that are (nearly) degenerate.

    python demos/mindlin.py                  # h = 0.01 (a/h ~ 10), F = 0.5, both methods, both cases
    python demos/mindlin.py --size 0.005 --methods exact --cases cylinder -o out

A second case, ``blocks``, removes the coupling: two mirror-identical blocks 3 x 3 (structured
quadrilaterals, a conforming interface) carry the imposed gap (x - 1.5)^2 / (2 R), the
small-strain gap of a Hertz contact put on a flat interface.  There normal and tangential contact
decouple exactly, the nodes at +-x start to slip at the same alpha to rounding, and every
stick-to-slip transition is degenerate (two nodes at once): a test of how the path methods
resolve such points.

Writes ``<output>/mindlin.json`` and ``<output>/mindlin.png`` (the transitions over the analytic
curve c(alpha), one panel per case) and prints the comparison.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
if HERE not in sys.path:
    sys.path.insert(0, HERE)

import hertz as H  # noqa: E402  (demos/hertz.py: the model, Hertz's formulas, the robust SSNM)

import cfcontact  # noqa: E402

SIZE = 0.01
FRICTION = 0.5
DELTA = 0.02
#: the decoupled variant: two mirror-identical blocks with an imposed gap (x - 1.5)^2 / (2 R)
BLOCKS_NX, BLOCKS_RADIUS, BLOCKS_DELTA, BLOCKS_HEIGHT = 90, 10.0, 0.02, 3.0
Q_FINAL = 0.9  # Q(1) / (F P)
ALPHA_TOL = 0.05
METHODS = ("exact", "seed")


def resultants(path, system):
    """Sorted samples (alpha, P, Q) of the path, exact at every breakpoint: the stored points and,
    at each transition, the end of the branch it leaves.  P = sum lam_n, Q = |sum lam_t t_x|."""
    m = system.m
    tx = system.geometry.tangents[:, 0]
    samples = [(a, lam[:m].sum(), lam[m:] @ tx) for a, lam in zip(path.alphas, path.lams)]
    for t in path.transitions:
        lam = np.asarray(path.branch_lam(t.from_branch, t.alpha), dtype=float).ravel()
        samples.append((t.alpha, lam[:m].sum(), lam[m:] @ tx))
    arr = np.array(sorted(samples))
    arr[:, 2] = np.abs(arr[:, 2])
    return arr


def analytic_alpha(samples, x, F, R, Es):
    """Where c(alpha) = a sqrt(1 - Q/(F P)) falls to |x| on the sampled path (linear between
    samples); 0 if already there at alpha = 0, 1 if not reached."""
    al, P, Q = samples.T
    a = np.sqrt(4 * P * R / (math.pi * Es))
    phi = Q / (F * P) - 1.0 + (x / a) ** 2  # increasing in alpha; its root is the transition
    if phi[0] >= 0:
        return float(al[0])
    k = np.flatnonzero(phi >= 0)
    if not k.size:
        return float(al[-1])
    k = k[0]
    return float(al[k - 1] + (al[k] - al[k - 1]) * (-phi[k - 1]) / (phi[k] - phi[k - 1]))


def stick_to_slip(path):
    """[(alpha, node, new state)] of every node that goes from stick to slip at a transition."""
    out = []
    for t in path.transitions:
        before = path.branches[t.from_branch].sets.states()
        after = path.branches[t.to_branch].sets.states()
        for ch in (t.changes or [{"node": t.node, "set": t.set}]):
            i = int(ch["node"])
            if before[i] == "stick" and after[i] in ("slip+", "slip-"):
                out.append((t.alpha, i, after[i]))
    return out


def other_transitions(path):
    out = []
    for t in path.transitions:
        before = path.branches[t.from_branch].sets.states()
        after = path.branches[t.to_branch].sets.states()
        nodes = sorted({int(ch["node"]) for ch in (t.changes or [{"node": t.node}])})
        for i in nodes:
            if not (before[i] == "stick" and after[i] in ("slip+", "slip-")):
                out.append((t.alpha, i, before[i], after[i], t.kind))
    return out


def tune_shift(base, friction, log=print):
    """``base`` has the top's shift 0 at alpha = 0 and 1 at alpha = 1: the same system with the shift
    s at alpha = 1 that makes Q(1) = Q_FINAL F P, found on an exploratory exact path (Q is
    piecewise affine in alpha, and the shift only scales the load's tangential part)."""
    f1, f2 = base.loads_numpy()
    unit = f2 - f1  # the load of a unit shift of the top
    s = 0.05
    for _ in range(12):
        trial = base.with_loads(f1, f1 + s * unit)
        path = cfcontact.trace_path(trial, 0.0, 1.0, method="exact")
        smp = resultants(path, trial)
        ratio = smp[:, 2] / (friction * smp[:, 1])
        hit = np.flatnonzero(ratio >= Q_FINAL)
        if hit.size:
            k = hit[0]
            a_star = smp[k - 1, 0] + (smp[k, 0] - smp[k - 1, 0]) * (Q_FINAL - ratio[k - 1]) / (ratio[k] - ratio[k - 1])
            s *= a_star
            log(f"tangential shift of the top at alpha = 1: {s:.6g} (Q = {Q_FINAL} F P there)")
            return base.with_loads(f1, f1 + s * unit), s
        s *= 2.0
    raise RuntimeError("the tangential load did not reach 0.9 F P")


def cylinder_case(size=SIZE, friction=FRICTION, delta=DELTA, log=print):
    """The cylinder on a block (``demos/hertz.py``'s model): (system, shift, h, R, x of the axis)."""
    base = H.build(size, friction=friction, indentation=(delta, delta), shift=(0.0, 1.0))
    system, shift = tune_shift(base, friction, log)
    return system, shift, size, H.MODEL["radius"], 0.0


def blocks_case(nx=BLOCKS_NX, friction=FRICTION, delta=BLOCKS_DELTA, radius=BLOCKS_RADIUS, log=print):
    """Two mirror-identical blocks 3 x 3 (structured quadrilaterals, matching interface) with the
    imposed gap (x - 1.5)^2 / (2 R) -- the small-strain gap of two cylinders of radius 2R, put on a
    conforming mesh.  The two bodies are mirror images across the interface, so normal and
    tangential contact decouple exactly: the nodes at 1.5 +- x start to slip at the same alpha (to
    rounding), which makes every stick-to-slip transition degenerate (two nodes at once)."""
    base = cfcontact.two_blocks(nx=nx, ny=max(2, nx // 3), length=3.0, height=BLOCKS_HEIGHT, E=H.MODEL["E"],
                                nu=H.MODEL["nu"],
                                friction=friction, clamp=("bottom2",), tractions1={}, tractions2={},
                                dirichlet={"top1": {"x": (0.0, 1.0), "y": (-delta, -delta)}})
    x = base.geometry.contact_points[:, 0]
    base = base.with_gap((x - 1.5) ** 2 / (2.0 * radius))
    system, shift = tune_shift(base, friction, log)
    return system, shift, 3.0 / nx, radius, 1.5


def compare(path, system, friction, h, R, x0=0.0):
    """Every stick-to-slip transition against Cattaneo-Mindlin (element size h, radius R of the
    gap x^2 / (2 R), axis at x0); returns the rows, the other transitions and a summary."""
    g = system.geometry
    x = g.contact_points[:, 0] - x0
    Es = H.e_star(H.MODEL["E"], H.MODEL["nu"])
    smp = resultants(path, system)
    rows = []
    for alpha, i, state in stick_to_slip(path):
        xi = abs(float(x[i]))
        an = analytic_alpha(smp, xi, friction, R, Es)
        spread = max(abs(analytic_alpha(smp, xi + d, friction, R, Es) - an) for d in (-2 * h, 2 * h))
        tol = max(ALPHA_TOL, spread)
        rows.append({"node": int(i), "x": float(x[i]), "state": state, "alpha": float(alpha), "alpha_analytic": an,
                     "error": float(alpha - an), "tolerance": tol, "two_h_change": spread,
                     "ok": abs(alpha - an) <= tol})
    others = [{"alpha": a, "node": i, "x": float(x[i]), "from": b, "to": c, "kind": k}
              for a, i, b, c, k in other_transitions(path)]
    errs = np.array([r["error"] for r in rows]) if rows else np.zeros(0)
    summary = {
        "stick_to_slip": len(rows), "all_within_tolerance": all(r["ok"] for r in rows),
        "max_abs_error": float(np.abs(errs).max(initial=0.0)), "mean_error": float(errs.mean()) if rows else 0.0,
        "other_transitions": len(others), "status": path.status, "events": [e.kind for e in path.events],
        "transitions": len(path.transitions), "folds": len(path.folds) if hasattr(path, "folds") else None,
        "P_range": [float(smp[:, 1].min()), float(smp[:, 1].max())],
        "Q_over_FP_end": float(smp[-1, 2] / (friction * smp[-1, 1])),
        "degenerate_transitions": sum(1 for t in path.transitions if len(t.changes or []) > 1),
    }
    # the pressure centre at alpha = 1, in units of a: how much the tangential load tilts the pressure
    lam = path.lams[-1]
    P1 = lam[:system.m].sum()
    a1 = math.sqrt(4 * P1 * R / (math.pi * Es))
    summary["pressure_centre_over_a"] = float((lam[:system.m] @ x) / P1 / a1)
    return rows, others, summary


def run(case="cylinder", methods=METHODS, log=print, **kw):
    """Trace the case with each method and compare; a JSON-ready dict."""
    t0 = time.perf_counter()
    system, shift, h, R, x0 = (cylinder_case if case == "cylinder" else blocks_case)(log=log, **kw)
    friction = float(system.friction)
    out = {"case": case, "size": h, "radius": R, "axis": x0, "friction": friction, "shift": shift, "n": system.n,
           "m": system.m, "parameters": kw, "methods": {}}
    log(f"{case}: n = {system.n}, m = {system.m}, h = {h:g}, set-up {time.perf_counter() - t0:.1f} s")
    for method in methods:
        t0 = time.perf_counter()
        path = cfcontact.trace_path(system, 0.0, 1.0, method=method)
        elapsed = time.perf_counter() - t0
        rows, others, summary = compare(path, system, friction, h, R, x0)
        summary["time"] = elapsed
        out["methods"][method] = {"rows": rows, "others": others, "summary": summary,
                                  "transitions": [{"alpha": t.alpha, "kind": t.kind, "node": t.node, "set": t.set,
                                                   "changes": t.changes} for t in path.transitions],
                                  "events": [{"kind": e.kind, "alpha": e.alpha, "message": e.message}
                                             for e in path.events],
                                  "samples": resultants(path, system).tolist()}
        log(f"\n{method}: status {path.status}, {len(path.transitions)} transitions "
            f"({summary['degenerate_transitions']} with several nodes at once), {summary['stick_to_slip']} "
            f"stick-to-slip, events {summary['events'] or 'none'}, {elapsed:.1f} s")
        log("   node        x  state   alpha  analytic    error  tolerance")
        for r in sorted(rows, key=lambda r: (r["alpha"], r["x"])):
            log(f"  {r['node']:5d} {r['x']:+8.4f}  {r['state']:5s} {r['alpha']:7.4f}  {r['alpha_analytic']:8.4f} "
                f"{r['error']:+8.4f}  {r['tolerance']:9.4f}{'' if r['ok'] else '  OUTSIDE'}")
        for o in others:
            log(f"  other: node {o['node']} (x = {o['x']:+.4f}) {o['from']} -> {o['to']} at alpha "
                f"{o['alpha']:.4f} ({o['kind']})")
        log(f"  max |error| {summary['max_abs_error']:.4f}, mean error {summary['mean_error']:+.4f}; all within "
            f"tolerance: {summary['all_within_tolerance']}; P from {summary['P_range'][0]:.6g} to "
            f"{summary['P_range'][1]:.6g}; pressure centre at alpha = 1: {summary['pressure_centre_over_a']:+.4f} a")
    return out


def plot(results, fn):
    """One panel per case: the analytic stick-zone edges +-c(alpha) over the traced transitions."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(7.0 * len(results), 4.5), squeeze=False)
    Es = H.e_star(H.MODEL["E"], H.MODEL["nu"])
    for ax, result in zip(axes[0], results):
        F, R = result["friction"], result["radius"]
        for (method, data), mk in zip(result["methods"].items(), ("o", "x")):
            al, P, Q = np.asarray(data["samples"]).T
            a = np.sqrt(4 * P * R / (math.pi * Es))
            c = a * np.sqrt(np.clip(1 - Q / (F * P), 0, None))
            if mk == "o":
                ax.plot(al, c, "k-", lw=1.5, label="Cattaneo-Mindlin  c = a sqrt(1 - Q/(F P))")
                ax.plot(al, -c, "k-", lw=1.5)
                ax.plot(al, a, "k:", lw=1, label="Hertz half-width a")
                ax.plot(al, -a, "k:", lw=1)
            rows = data["rows"]
            ax.plot([r["alpha"] for r in rows], [r["x"] for r in rows], mk, ms=6,
                    mfc="none" if mk == "o" else None, label=f"{method}: node x starts to slip")
        ax.set_xlabel("alpha (tangential load Q from 0 to 0.9 F P)")
        ax.set_ylabel("x (from the axis)")
        title = ("cylinder on block" if result["case"] == "cylinder" else
                 "mirror-identical blocks, imposed gap (decoupled)")
        ax.set_title(f"{title}: F = {F:g}, h = {result['size']:.3g}", fontsize=10)
        ax.legend(fontsize=7, loc="lower left")
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(fn, dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=float, default=SIZE, help="element size along the cylinder's contact zone")
    ap.add_argument("--nx", type=int, default=BLOCKS_NX, help="cells along the decoupled blocks' interface")
    ap.add_argument("--friction", type=float, default=FRICTION)
    ap.add_argument("--cases", default="cylinder,blocks", help="cylinder,blocks")
    ap.add_argument("--methods", default=",".join(METHODS), help="exact,seed")
    ap.add_argument("-o", "--output", default=os.path.join(os.path.dirname(HERE), "output", "validation"))
    ap.add_argument("--no-plot", action="store_true")
    args = ap.parse_args(argv)
    methods = tuple(args.methods.split(","))
    results = []
    for case in args.cases.split(","):
        print(f"\n== Cattaneo-Mindlin, {case}: F = {args.friction:g}")
        kw = {"size": args.size} if case == "cylinder" else {"nx": args.nx}
        results.append(run(case, methods, friction=args.friction, **kw))
    os.makedirs(args.output, exist_ok=True)
    with open(os.path.join(args.output, "mindlin.json"), "w") as fh:
        json.dump({r["case"]: r for r in results}, fh, indent=1)
    if not args.no_plot:
        plot(results, os.path.join(args.output, "mindlin.png"))
    print(f"wrote {os.path.join(args.output, 'mindlin.json')}" + ("" if args.no_plot else " and mindlin.png"))
    ok = all(d["summary"]["all_within_tolerance"] and d["summary"]["stick_to_slip"] > 0
             for r in results for d in r["methods"].values())
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
