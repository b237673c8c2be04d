"""Pictures of the geometry variants for the README (``docs/img/<variant>.png``).

For each variant the example case file in ``demos/cases/`` is read and its model built, one
point of its load path is solved by the semi-smooth Newton method, and the deformed bodies
are rendered off-screen with the contact nodes coloured by state (open / stick / slip)::

    .venv/bin/python demos/pictures.py                        # all variants -> docs/img/
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
=================  ==========================  ==============================================
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
    import cfcontact
    from cfcontact import render
    from cfcontact.case import build_system, load_case

    case_name, alpha, title = VARIANTS[variant]
    case_file = os.path.join(CASES, case_name)
    with tempfile.TemporaryDirectory() as tmp:
        if variant == "user_msh":
            case_file = _user_msh(case_file, tmp)
        case = load_case(case_file)
        system = build_system(case)
    sol = cfcontact.ssnm(system, alpha)
    os.makedirs(output, exist_ok=True)
    fn = os.path.join(output, f"{variant}.png")
    render.render_solution(system.geometry, sol, fn, window_size=tuple(window_size),
                           title=f"{title}, F = {_friction(case)}")
    counts = render.state_counts(sol.states())
    log(f"{fn}: n = {system.n}, m = {system.m}, alpha = {alpha}, "
        + ", ".join(f"{k} {v}" for k, v in counts.items() if v) + f", {os.path.getsize(fn) // 1024} kB")
    return fn


def _friction(case):
    F = case["contact"]["friction"]
    return f"{F:g}" if isinstance(F, (int, float)) else "per node"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variant", action="append", choices=sorted(VARIANTS),
                    help="variant to draw (repeatable; default: all)")
    ap.add_argument("-o", "--output", default=os.path.join(ROOT, "docs", "img"), help="folder of the PNGs")
    ap.add_argument("--window-size", type=int, nargs=2, default=(600, 360), metavar=("W", "H"))
    args = ap.parse_args(argv)
    for variant in args.variant or list(VARIANTS):
        picture(variant, args.output, args.window_size)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
