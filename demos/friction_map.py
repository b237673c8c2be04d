"""For which friction coefficients, and where, the main demo's load path has 1, 3, 5, ... solutions.

The main demo's model and load path (demos/main.py), for F from 0 to 30: the number of solutions on
the exact alpha-path at every point of a 200 x 200 (alpha, F) grid (one exact path per F), the fold
curves (exact, piece by piece) with their cusps, the critical friction of the path (the smallest F
with a fold) and the seed's three friction coefficients (0.1, 0.6, 30) as horizontal lines.  The
right panel zooms on the right end of the interface, where the first folds are born (nodes 27, 28;
the seed's three solutions at F = 0.6).

    .venv/bin/python demos/friction_map.py                    # writes output/friction_map/
    .venv/bin/python demos/friction_map.py --quick            # 40 x 40 grids
    .venv/bin/python demos/friction_map.py --figure docs/img/friction_map.png
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from cfcontact.demo_models import DEMO_ALPHA, DEMO_FRICTIONS, build_demo
from cfcontact.fmap import fold_curves, multiplicity_map, save_map
from cfcontact.plotting import _new_figure, plot_friction_map, save_figure

#: The zoom panel: alpha and F window around the first cusp.
ZOOM = (0.785, 0.800, 0.0, 2.0)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="40 x 40 grids")
    ap.add_argument("--output", default="output/friction_map", help="folder for map.png, map.json, map.npz")
    ap.add_argument("--figure", help="also write the figure here (e.g. docs/img/friction_map.png)")
    ap.add_argument("--fmax", type=float, default=30.0, help="largest friction coefficient (default 30)")
    args = ap.parse_args(argv)
    n = 40 if args.quick else 200
    t0 = time.perf_counter()
    system = build_demo(DEMO_FRICTIONS[0])
    print(f"main demo model: n = {system.n}, m = {system.m} ({time.perf_counter() - t0:.1f} s)", flush=True)
    fmap = multiplicity_map(system, np.linspace(*DEMO_ALPHA, n), np.linspace(0.0, args.fmax, n), *DEMO_ALPHA)
    print(f"map {n} x {n}: {fmap.timings['total']:.2f} s (alpha-paths {fmap.timings['trace']:.2f} s), up to "
          f"{int(fmap.counts.max())} solutions on the path", flush=True)
    fc = fold_curves(system, (0.0, args.fmax), DEMO_ALPHA)
    crit = fc.critical
    print(f"fold curves: {fc.timings['total']:.2f} s, {len(fc.curves)} curves, {len(fc.cusps)} cusps", flush=True)
    print(f"critical friction of the path: {crit}", flush=True)
    a0, a1, F0, F1 = ZOOM
    zmap = multiplicity_map(system, np.linspace(a0, a1, n), np.linspace(F0, F1, n), *DEMO_ALPHA)
    for F in DEMO_FRICTIONS:
        row = zmap if F <= F1 else fmap
        i = int(np.argmin(np.abs(row.frictions - F)))
        print(f"  F = {F:g}: up to {int(row.counts[i].max())} solutions on the path (grid row F = {row.frictions[i]:.4g})")
    fig, (ax, zax) = _new_figure((13.0, 5.5), 100, ncols=2)
    plot_friction_map(fmap, fc, crit, DEMO_FRICTIONS, ax=ax, title="main demo: solutions on the load path")
    plot_friction_map(zmap, fc, crit, [F for F in DEMO_FRICTIONS if F <= F1], ax=zax,
                      title=f"zoom: α in [{a0:g}, {a1:g}], F in [{F0:g}, {F1:g}]")
    os.makedirs(args.output, exist_ok=True)
    save_map(args.output, fmap, fc, DEMO_FRICTIONS, {"zoom": list(ZOOM)})
    save_figure(fig, os.path.join(args.output, "map.png"))
    if args.figure:
        save_figure(fig, args.figure)
    print(f"wrote {args.output}/ (map.png, map.json, map.npz)" + (f" and {args.figure}" if args.figure else ""))
    return fmap, fc


if __name__ == "__main__":
    main()
