"""Pictures of the geometry variants (the documentation's geometry page, ``<output>/<variant>.png``).

For each variant the example case file in ``demos/cases/`` is read and its model built, one
point of its load path is solved by the semi-smooth Newton method, and the deformed bodies
are rendered off-screen with the contact nodes coloured by state (open / stick / slip)::

    .venv/bin/python demos/pictures.py                        # all variants -> output/pictures/
    .venv/bin/python demos/pictures.py --variant arc -o /tmp/img --window-size 600 360

Variants and case files:

=================  ==========================  ==============================================
variant            case file                   geometry
=================  ==========================  ==============================================
two_blocks         two_blocks.toml             two stacked blocks (the seed's model)
foundation         foundation.toml             one block on a rigid foundation
arc                arc.toml                    convex arc bottom in a matching concave seat
inclined           inclined.toml               the two blocks rotated by 20 degrees
user_msh           user_msh.toml               a user's .msh (written here by cfcontact.meshes.two_blocks)
cylinder           cylinder.toml               a half-cylinder pressed on a block (Hertz), initial gap
punch              punch.toml                  a flat punch with rounded edges on a block
nonmatching        nonmatching.toml            two blocks with 12 and 17 cells along the interface
obstacle           obstacle.toml               a block pressed on a rigid disc (an analytic obstacle)
half_cylinder      half_cylinder.toml          the right half of the cylinder, a symmetry plane
=================  ==========================  ==============================================

The picture's magnification is the case's ``[output] magnification`` (a rigid obstacle is drawn
as it is: obstacle.toml sets 1), else automatic.  The documentation build runs this script into
its build directory (docs/_ext/cfcontact_docs.py), so the pictures are never stale.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CASES = os.path.join(ROOT, "demos", "cases")

#: variant -> (case file, alpha of the rendered point, picture title)
VARIANTS = {
    "two_blocks": ("two_blocks.toml", 0.5, "two blocks"),
    "foundation": ("foundation.toml", 0.5, "foundation"),
    "arc": ("arc.toml", 0.5, "arc in a seat"),
    "inclined": ("inclined.toml", 0.5, "inclined"),
    "user_msh": ("user_msh.toml", 0.5, "user .msh"),
    "cylinder": ("cylinder.toml", 1.0, "cylinder on block"),
    "punch": ("punch.toml", 1.0, "rounded punch"),
    "nonmatching": ("nonmatching.toml", 0.5, "non-matching blocks"),
    "obstacle": ("obstacle.toml", 1.0, "block on a rigid disc"),
    "half_cylinder": ("half_cylinder.toml", 1.0, "half cylinder (symmetry plane)"),
}


def _user_msh(case_file, workdir):
    """A copy of user_msh.toml in workdir, next to the mesh it names (written by ``python -m cfcontact.meshes.two_blocks``)."""
    shutil.copy(case_file, os.path.join(workdir, os.path.basename(case_file)))
    subprocess.run([sys.executable, "-m", "cfcontact.meshes.two_blocks",
                    os.path.join(workdir, "two_blocks_6x2.msh"), "--nx", "6", "--ny", "2"],
                   check=True, capture_output=True)
    return os.path.join(workdir, os.path.basename(case_file))


def picture(variant, output, window_size=(600, 360), log=print):
    """Solve one point of the variant's case and render it to ``<output>/<variant>.png``."""
    import warnings

    import cfcontact
    from cfcontact import render
    from cfcontact.case import build_system, load_case

    case_name, alpha, title = VARIANTS[variant]
    case_file = os.path.join(CASES, case_name)
    with tempfile.TemporaryDirectory() as tmp:
        if variant == "user_msh":
            case_file = _user_msh(case_file, tmp)
        case = load_case(case_file)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", cfcontact.PairingWarning)  # (obstacle.toml's search distance)
            system = build_system(case)
    sol = _solve(system, alpha)
    os.makedirs(output, exist_ok=True)
    fn = os.path.join(output, f"{variant}.png")
    render.render_solution(system.geometry, sol, fn, window_size=tuple(window_size),
                           title=f"{title}, F = {_friction(case)}", magnification=case["output"].get("magnification"))
    counts = render.state_counts(sol.states())
    log(f"{fn}: n = {system.n}, m = {system.m}, alpha = {alpha}, "
        + ", ".join(f"{k} {v}" for k, v in counts.items() if v) + f", {os.path.getsize(fn) // 1024} kB")
    return fn


def _solve(system, alpha):
    """SSNM at alpha, with a smaller rho if it cycles from 0 (its convergence depends on rho)."""
    import cfcontact

    for factor in (1.0, 0.1, 0.01):
        try:
            sol = cfcontact.ssnm(system.with_rho(system.rho * factor), alpha)
            return cfcontact.Solution.from_y(system, sol.y, alpha)
        except cfcontact.ConvergenceError:
            continue
    raise cfcontact.ConvergenceError(f"SSNM did not converge at alpha = {alpha}")


def _friction(case):
    F = case["contact"]["friction"]
    return f"{F:g}" if isinstance(F, (int, float)) else "per node"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variant", action="append", choices=sorted(VARIANTS),
                    help="variant to draw (repeatable; default: all)")
    ap.add_argument("-o", "--output", default=os.path.join(ROOT, "output", "pictures"), help="folder of the PNGs")
    ap.add_argument("--window-size", type=int, nargs=2, default=(600, 360), metavar=("W", "H"))
    args = ap.parse_args(argv)
    for variant in args.variant or list(VARIANTS):
        picture(variant, args.output, args.window_size)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
