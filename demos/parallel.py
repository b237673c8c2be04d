"""A case file's path traced in parallel: the model assembled and the path traced on every MPI
rank, the path saved by one.

`cfcontact run` writes files and runs as one process (under mpirun it refuses: every rank would
write the same files).  The library's solvers run under MPI, so a parallel run is a few lines of
Python; the saved path is then read, plotted and rendered by the command line as usual.

    mpirun -n 2 .venv/bin/python demos/parallel.py demos/cases/folds.toml output/folds_mpi
    .venv/bin/cfcontact info output/folds_mpi/path     # the same path as `cfcontact run folds.toml`
    .venv/bin/cfcontact render output/folds_mpi/path --panel -o panel.png

(As root, Open MPI's mpirun needs --allow-run-as-root.)  Without mpirun the script runs on one
process and writes the same path.
"""

from __future__ import annotations

import argparse
import os

from mpi4py import MPI

import cfcontact
from cfcontact.case import build_system, load_case, path_request


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("case", help="a case file (TOML); its [path] section is used, its [output] section is not")
    ap.add_argument("output", help="folder for the saved path (written as OUTPUT/path)")
    args = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    case = load_case(args.case)  # every rank reads and checks the case file
    system = build_system(case)  # assembled in parallel: K, N, T distributed over the ranks
    options, span = path_request(case)
    path_options = case["path"]
    if path_options["parameter"] != "alpha":
        ap.error(f"{args.case}: [path] parameter = {path_options['parameter']!r}; this script traces load paths "
                 f"(parameter = \"alpha\")")
    path = cfcontact.trace_path(system, span.start, span.end, method=path_options["method"], options=options,
                                backend=path_options["backend"])
    path.form()  # collective: the displacements of the lazily stored branches
    if comm.rank == 0:
        os.makedirs(args.output, exist_ok=True)
        saved = path.save(os.path.join(args.output, "path"))
        count, alpha = path.max_multiplicity()
        print(f"{comm.size} rank(s): {path.status}, {len(path.transitions)} transitions ({len(path.folds)} folds), "
              f"max multiplicity {count} at alpha = {alpha:.10g}; wrote {saved}")
    return path


if __name__ == "__main__":
    main()
