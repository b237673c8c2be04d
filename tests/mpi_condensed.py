"""Run by tests/test_exact.py serially and under mpirun: exact path with the condensed backend.

Writes (rank 0) a JSON summary to argv[1]."""

import json
import sys

import numpy as np
from mpi4py import MPI

import cfcontact
from cfcontact.condensed import CondensedSolver
from cfcontact.enumerate import enumerate_solutions
from cfcontact.exact import canonical_codes
from cfcontact.lumped import random_system
from cfcontact.ssnm import DirNeuSolver, InactiveSets, SolverOptions

comm = MPI.COMM_WORLD
system = random_system(4, 2, friction=1.7, extra_dofs=7)
solver = CondensedSolver(system)
full = DirNeuSolver(system)
rng = np.random.default_rng(0)


def check_against_full(condensed, count):
    """condensed == full J(Z) solve for random sets and loads, also in parallel"""
    for _ in range(count):
        Z = InactiveSets.from_states(rng.integers(0, 4, system.m))
        f = system.load(rng.uniform(0, 1))
        yc, yf = condensed.solve(Z, f), full.solve(Z, f)
        assert np.abs(yc - yf).max() <= 1e-10 * np.abs(yf).max()


check_against_full(solver, 6)
path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver)
assert path.status == "completed", path.events
ys = [path.branch_y(b, a).tolist() for b in path.branches for a in (0.0, 1.0)]
nsol = len(enumerate_solutions(system, 0.5, solver=solver))
# iterative refinement (forced: this K is well conditioned): residuals from the distributed K
refined = CondensedSolver(system, SolverOptions(refine=True))
check_against_full(refined, 3)
rpath = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=refined)
assert rpath.status == "completed", rpath.events
if comm.rank == 0:
    with open(sys.argv[1], "w") as fh:
        json.dump({"size": comm.size, "keys": [canonical_codes(b.sets, 1.7).tolist() for b in path.branches],
                   "kinds": [t.kind for t in path.transitions], "alphas": [t.alpha for t in path.transitions],
                   "ys": ys, "nsol": nsol, "refine_steps": refined.refine_steps,
                   "refined_kinds": [t.kind for t in rpath.transitions],
                   "refined_alphas": [t.alpha for t in rpath.transitions], "factorizations": solver.stats.factorizations}, fh)
