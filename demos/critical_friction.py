"""How much friction a model needs before its solution path can fold (cfcontact.critical_friction).

For each model below the script scans the small contact configurations (windows of up to 6
neighbouring contact nodes, every slip-sign pattern, stick subsets up to 4 nodes) and prints
the smallest friction coefficient F at which one of them has a DirNeu matrix of negative
determinant: below it no path can fold through the scanned pieces.  This is the measurement
behind the main demo's model: the seed finds three solutions at F = 0.6, where two steel blocks
cannot fold yet, while a steel block on a soft layer with nu = 0 can.

    .venv/bin/python demos/critical_friction.py            # all models (about 30 s)
    .venv/bin/python demos/critical_friction.py --quick    # coarse meshes (the tests run this)
    .venv/bin/python demos/critical_friction.py --json out.json
"""

from __future__ import annotations

import argparse
import json
import time

import cfcontact
from cfcontact.critical import critical_friction
from cfcontact.demo_models import BLOCKS_MODEL, DEMO_MODEL  # the main demo's model; two steel blocks

#: (label, two_blocks arguments).  All have n = 1320, m = 30 on the full mesh (the foundation: m = 30, n = 660).
MODELS = [
    ("main demo model: steel block on a soft layer (E2 = E1/1000, nu2 = 0, height2 = 0.3), triangles",
     dict(DEMO_MODEL)),
    ("steel block on a soft layer, quadrilaterals", dict(DEMO_MODEL, cell="quadrilateral")),
    ("two steel blocks (height2 = 0.5), quadrilaterals", dict(BLOCKS_MODEL)),
    ("two steel blocks, triangles", dict(BLOCKS_MODEL, cell="triangle")),
    ("equal blocks (height2 = height)", dict(BLOCKS_MODEL, height2=BLOCKS_MODEL["height"])),
    ("steel block on a rigid foundation", dict({k: v for k, v in BLOCKS_MODEL.items() if k != "height2"},
                                               foundation=True)),
]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="coarse meshes (12 x 4 cells per block)")
    ap.add_argument("--json", metavar="FILE", help="write the results as JSON")
    args = ap.parse_args(argv)
    rows = []
    print(f"{'model':<72} {'n':>5} {'m':>3} {'critical F':>10}  configuration")
    for label, kw in MODELS:
        if args.quick:
            kw = dict(kw, nx=12, ny=4)
        t0 = time.perf_counter()
        system = cfcontact.two_blocks(**kw)
        crit = critical_friction(system)
        conf = ", ".join(f"{i}:{s}" for i, s in zip(crit.nodes, crit.states))
        print(f"{label:<72} {system.n:>5} {system.m:>3} {crit.friction:>10.4g}  {conf}", flush=True)
        rows.append(dict(model=label, n=system.n, m=system.m, critical_friction=crit.friction,
                         nodes=crit.nodes, states=crit.states, scanned=crit.scanned,
                         seconds=time.perf_counter() - t0))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return rows


if __name__ == "__main__":
    main()
