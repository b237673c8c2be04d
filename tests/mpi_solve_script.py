"""Helper of tests/test_fem.py::test_mpi_ssnm_and_path_match_serial (run under mpirun).

Usage: mpirun -n 2 python3 tests/mpi_solve_script.py OUT.npz
Solves the cases of :func:`cases` (SSNM at alpha = 0 and 1, a seed path) and writes, on rank 0,
u, lam_n, lam_t, the inactive sets and the path's transitions.
"""

import sys

import numpy as np
from mpi4py import MPI


def cases():
    return {
        "quad": dict(nx=10, ny=4, friction=0.6),
        "tri": dict(nx=10, ny=4, cell="triangle", friction=0.3, angle=15.0),
    }


def solve(system):
    import cfcontact

    out = {}
    for a in (0.0, 1.0):
        sol = cfcontact.ssnm(system, a)
        out[f"u{a:g}"] = sol.u
        out[f"lam{a:g}"] = np.concatenate([sol.lam_n, sol.lam_t])
        out[f"codes{a:g}"] = sol.sets.state_codes()
        out[f"iterations{a:g}"] = np.array(sol.iterations)
    path = cfcontact.trace_path(system, 0.0, 1.0, method="seed")
    out["path_alphas"] = path.alphas
    out["path_kinds"] = np.array([t.kind == "fold" for t in path.transitions], dtype=int)
    out["path_nodes"] = np.array([t.node for t in path.transitions], dtype=int)
    out["path_u"] = path.ys[:, :system.n]
    out["path_lam"] = path.ys[:, system.n:]
    return out


def main(path):
    from cfcontact.models import two_blocks

    comm = MPI.COMM_WORLD
    result = {"size": np.array(comm.size)}
    for name, kwargs in cases().items():
        system = two_blocks(**kwargs)
        result[f"{name}:ranges"] = np.array(system.K.getOwnershipRanges())
        for key, value in solve(system).items():
            result[f"{name}:{key}"] = value
    if comm.rank == 0:
        np.savez(path, **result)


if __name__ == "__main__":
    main(sys.argv[1])
