"""Validation against Lame: a hub press-fitted into a rigid bore.

The hub is an annulus of radii a = 0.3 and b = 1 (E = 2.1e11, nu = 0.3, linear triangles), its
inner circle clamped; the bore is a rigid circle of radius b - delta (``[contact.obstacle]`` with
``inside = true``): every node of the hub's outer circle starts delta inside the solid, an
interference (a press fit).  The problem is axisymmetric, so the contact pressure is uniform,
the friction does not act and the path is a single branch.  Lame's thick-cylinder solution,
u(r) = A r + B / r with u(a) = 0 and u(b) = -delta, gives the pressure

    p = -sigma_r(b) = -E / ((1 + nu)(1 - 2 nu)) (A - (1 - 2 nu) B / b^2)     (plane strain)
    p = -sigma_r(b) = -E / (1 - nu^2) ((1 + nu) A - (1 - nu) B / b^2)        (plane stress)

The demo meshes the hub with n = 64, 128, 256 nodes on its outer circle (equally spaced, element
size 6.4 / n inside), traces the exact path (alpha from 0 to 1: nothing moves, the fit is the
load), and compares the pressure of every contact node, lam_n,i / l_i (l_i its tributary length),
with Lame's: the mean error, the spread from node to node, and the order of convergence of the
mean error between successive meshes (2 expected of linear elements).

    python demos/lame.py                 # n = 64, 128, 256, plane strain and plane stress
    python demos/lame.py --nodes 32 64 --planes strain -o out

Writes ``<output>/lame.json`` and prints the comparison; exits with status 1 when the finest mesh
misses Lame's pressure by more than 1e-3 or the order of convergence is below 1.5.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))

import cfcontact  # noqa: E402
from cfcontact import compat  # noqa: E402

INNER, OUTER = 0.3, 1.0
DELTA = 1e-4
E, NU, FRICTION = 2.1e11, 0.3, 0.3
NODES = (64, 128, 256)
#: targets of the finest mesh (status 1 otherwise)
MAX_ERROR, MIN_ORDER = 1e-3, 1.5


def mesh_hub(model, nodes, size):
    """Build and mesh the hub into the gmsh ``model``: the annulus INNER < r < OUTER (``body1``),
    ``nodes`` equally spaced nodes on its outer circle (``contact1``), its inner circle
    ``inner1``, elements of at most ``size``."""
    import gmsh

    occ = model.occ
    hub, _ = occ.cut([(2, occ.addDisk(0, 0, 0, OUTER, OUTER))], [(2, occ.addDisk(0, 0, 0, INNER, INNER))])
    occ.synchronize()
    curves = [c for _, c in model.getBoundary(hub, oriented=False)]
    outer = [c for c in curves if model.getBoundingBox(1, c)[3] > 0.5 * (INNER + OUTER)]
    inner = [c for c in curves if c not in outer]
    groups = ((2, [hub[0][1]], 1, "body1"), (1, outer, 10, "contact1"), (1, inner, 14, "inner1"))
    for dim, tags, num, name in groups:
        model.addPhysicalGroup(dim, tags, num)
        model.setPhysicalName(dim, num, name)
    for c in outer:
        model.mesh.setTransfiniteCurve(c, nodes + 1)  # a closed curve: its first node is its last
    gmsh.option.setNumber("Mesh.MeshSizeMax", size)
    model.mesh.generate(2)


def hub_in_bore(nodes, delta=DELTA, plane="strain", friction=FRICTION):
    """The press fit's ContactSystem: the hub meshed by gmsh with ``nodes`` nodes on its outer
    circle, in a rigid bore of radius OUTER - delta."""
    with compat.gmsh_model("lame") as model:
        mesh_hub(model, nodes, 2.0 * math.pi * OUTER / nodes)
        return cfcontact.assemble_contact_system(
            model, E=E, nu=NU, plane=plane, clamp=("inner1",), friction=friction,
            obstacle={"kind": "circle", "center": (0.0, 0.0), "radius": OUTER - delta, "inside": True})


def lame_pressure(delta=DELTA, plane="strain", a=INNER, b=OUTER, E=E, nu=NU) -> float:
    """Lame's contact pressure of the hub (u(a) = 0, u(b) = -delta)."""
    A = -delta / (b - a * a / b)
    B = -A * a * a
    if plane == "strain":
        return -E / ((1 + nu) * (1 - 2 * nu)) * (A - (1 - 2 * nu) * B / b ** 2)
    return -E / (1 - nu ** 2) * ((1 + nu) * A - (1 - nu) * B / b ** 2)


def run(nodes=NODES, planes=("strain", "stress"), log=print) -> dict:
    """The comparison for each plane and mesh, with the order of convergence between meshes."""
    out = {}
    for plane in planes:
        ref = lame_pressure(plane=plane)
        rows = []
        for n in nodes:
            system = hub_in_bore(n, plane=plane)
            path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
            (sol,) = path.solutions_at(1.0)
            p = sol.lam_n / np.asarray(system.geometry.tributary)
            row = {"nodes": int(n), "m": int(system.m), "n_dofs": int(system.n), "status": path.status,
                   "transitions": len(path.transitions), "closed": int((sol.lam_n > 0).sum()),
                   "mean_pressure": float(p.mean()),
                   "error": float(p.mean() / ref - 1.0), "spread": float(np.ptp(p) / ref),
                   "tangential": float(np.abs(sol.lam_t).max() / sol.lam_n.max()),
                   "residual": float(cfcontact.verify(system, sol.y, 1.0).worst())}
            if rows:
                row["order"] = float(math.log(abs(rows[-1]["error"]) / abs(row["error"]), n / rows[-1]["nodes"]))
            rows.append(row)
            log(f"  {plane:6s} n = {n:4d}: p = {row['mean_pressure']:.6e} (Lame {ref:.6e}), error {row['error']:+.2e}, "
                f"spread {row['spread']:.1e}, |lam_t| / max lam_n {row['tangential']:.1e}"
                + (f", order {row['order']:.2f}" if "order" in row else "") + f", residual {row['residual']:.1e}")
        out[plane] = {"lame_pressure": ref, "meshes": rows}
    return out


def meets_targets(result) -> bool:
    for data in result.values():
        rows = data["meshes"]
        if any(r["status"] != "completed" for r in rows) or abs(rows[-1]["error"]) > MAX_ERROR:
            return False
        if len(rows) > 1 and rows[-1]["order"] < MIN_ORDER:
            return False
    return True


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--nodes", type=int, nargs="+", default=list(NODES), help="nodes on the hub's outer circle")
    ap.add_argument("--planes", nargs="+", default=["strain", "stress"], choices=["strain", "stress"])
    ap.add_argument("-o", "--output", default=os.path.join(os.path.dirname(HERE), "output", "validation"))
    args = ap.parse_args(argv)
    print(f"== Lame: a hub (radii {INNER:g}, {OUTER:g}) press-fitted into a rigid bore, interference {DELTA:g}")
    result = run(tuple(args.nodes), tuple(args.planes))
    os.makedirs(args.output, exist_ok=True)
    with open(os.path.join(args.output, "lame.json"), "w") as fh:
        json.dump(result, fh, indent=1)
    ok = meets_targets(result)
    print(f"wrote {os.path.join(args.output, 'lame.json')}; targets (finest error <= {MAX_ERROR:g}, order >= "
          f"{MIN_ORDER:g}) {'met' if ok else 'MISSED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
