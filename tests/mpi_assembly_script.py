"""Helper of tests/test_assembly.py::test_mpi_matches_serial (run under mpirun).

Usage: mpirun -n 2 python3 tests/mpi_assembly_script.py OUT.npz

Assembles the small models of :func:`cases` and writes, on rank 0, the gathered
K, N, T, f1, f2, geometry and the number of cells owned by each rank.
"""

import sys

import numpy as np
from mpi4py import MPI


def cases():
    """name -> keyword arguments of cfcontact.models.two_blocks (also used by the serial side)."""
    return {
        "quad": dict(nx=8, ny=3, cell="quadrilateral", friction=0.3,
                     tractions1={"top1": (1e8, -1e9)}, tractions2={"right1": (2e8, 1e8), "bottom2": (0.0, 5e8)},
                     body_force1={"body1": (0.0, -7e7)}, body_force2=(1e7, 2e7)),
        "tri": dict(nx=8, ny=3, cell="triangle", angle=20.0, plane="stress"),
        "rigid": dict(nx=6, ny=2, foundation=True),
    }


def gathered(system):
    from cfcontact import linalg

    f1, f2 = system.loads_numpy()
    out = {
        "K": linalg.gather_mat(system.K).toarray(),
        "N": linalg.gather_mat(system.N).toarray(),
        "T": linalg.gather_mat(system.T).toarray(),
        "f1": f1,
        "f2": f2,
        "rho": np.array(system.rho),
    }
    out.update({"geometry_" + k: v for k, v in system.geometry.to_dict().items()})
    return out


def main(path):
    from cfcontact.models import two_blocks

    comm = MPI.COMM_WORLD
    result = {}
    for name, kwargs in cases().items():
        system = two_blocks(**kwargs)
        for key, value in gathered(system).items():
            result[f"{name}:{key}"] = value
        result[f"{name}:owned_cells"] = np.array(comm.allgather(system.info.get("owned_cells", -1)))
        result[f"{name}:row_ranges"] = np.array(system.K.getOwnershipRanges())
    if comm.rank == 0:
        np.savez(path, size=comm.size, **result)


if __name__ == "__main__":
    main(sys.argv[1])
