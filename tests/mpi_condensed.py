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

def check_against_full(system, full, rng, condensed, count):
    """condensed == full J(Z) solve for random sets and loads, also in parallel"""
    for _ in range(count):
        Z = InactiveSets.from_states(rng.integers(0, 4, system.m))
        f = system.load(rng.uniform(0, 1))
        yc, yf = condensed.solve(Z, f), full.solve(Z, f)
        assert np.abs(yc - yf).max() <= 1e-10 * np.abs(yf).max()


class _Patch:  # the test's fault injection needs only monkeypatch.setattr
    def setattr(self, obj, name, value):
        setattr(obj, name, value)


def backtracked():
    """A path that ends "cycling" after its first branch point (fault injection, as in
    test_exact.py) and backtracks: its branches' keys, the tries' statuses, its status."""
    import cfcontact.exact as ex
    from test_exact import _fail_after_first_branch_point, two_identical_nodes

    step = ex._Walk.step
    try:
        _fail_after_first_branch_point(_Patch(), ex)
        two = two_identical_nodes()
        bpath = cfcontact.trace_path(two, 0.0, 1.0, method="exact", solver=CondensedSolver(two))
    finally:
        ex._Walk.step = step
    return {"status": bpath.status, "keys": [canonical_codes(b.sets, 2.5).tolist() for b in bpath.branches],
            "tries": [e.data["status"] for e in bpath.events if e.kind == "backtrack"],
            "alphas": [t.alpha for t in bpath.transitions]}


def main(out):
    comm = MPI.COMM_WORLD
    system = random_system(4, 2, friction=1.7, extra_dofs=7)
    solver = CondensedSolver(system)
    full = DirNeuSolver(system)
    rng = np.random.default_rng(0)
    check_against_full(system, full, rng, solver, 6)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=solver)
    assert path.status == "completed", path.events
    ys = [path.branch_y(b, a).tolist() for b in path.branches for a in (0.0, 1.0)]
    nsol = len(enumerate_solutions(system, 0.5, solver=solver))
    # iterative refinement (forced: this K is well conditioned): residuals from the distributed K
    refined = CondensedSolver(system, SolverOptions(refine=True))
    check_against_full(system, full, rng, refined, 3)
    rpath = cfcontact.trace_path(system, 0.0, 1.0, method="exact", solver=refined)
    assert rpath.status == "completed", rpath.events
    backtrack = backtracked()
    if comm.rank == 0:
        with open(out, "w") as fh:
            json.dump({"size": comm.size, "keys": [canonical_codes(b.sets, 1.7).tolist() for b in path.branches],
                       "kinds": [t.kind for t in path.transitions], "alphas": [t.alpha for t in path.transitions],
                       "ys": ys, "nsol": nsol, "refine_steps": refined.refine_steps,
                       "refined_kinds": [t.kind for t in rpath.transitions],
                       "refined_alphas": [t.alpha for t in rpath.transitions],
                       "factorizations": solver.stats.factorizations, "backtrack": backtrack}, fh)


if __name__ == "__main__":
    main(sys.argv[1])
