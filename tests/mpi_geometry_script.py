"""Helper of tests/test_mpi_geometry.py (run under mpirun): the real contact geometry under MPI.

Usage: mpirun -n 2 python3 tests/mpi_geometry_script.py OUT.npz

Builds the models of :func:`cases` (node-to-segment pairing of independent meshes, a rigid
obstacle, prescribed displacements, a half model with symmetry edges) and writes, on rank 0,
the gathered K, N, T, f1, f2, the gap, the pairing data, the SSNM solutions (the full and the
condensed backend) and an exact path's transitions.
"""

import sys

import numpy as np
from mpi4py import MPI


def cases():
    """name -> (builder name, keyword arguments); also used by the serial side."""
    cyl = dict(radius=1.0, width=3.0, depth=1.5, zone=0.3, size=0.04, size_far=0.4, E=1.0, nu=0.3)
    return {
        "cylinder": ("cylinder_on_block", dict(cyl, friction=0.3, indentation=(0.01, 0.03), shift=(0.0, 2e-3))),
        "half": ("cylinder_on_block", dict(cyl, friction=0.3, indentation=(0.0, 0.03), half=True)),
        "blocks": ("two_blocks", dict(nx=6, ny=2, nx2=9, ny2=3, pairing="segment", slave="contact1", friction=0.4,
                                      clamp=("bottom2",), tractions1={"top1": (2e7, -1e8)}, tractions2={},
                                      dirichlet={"top1": {"x": (0.0, 1e-4), "y": (-1e-4, -2e-4)}})),
        "obstacle": ("two_blocks", dict(nx=10, ny=2, length=2.0, height=0.5, foundation=True, clamp=(), friction=0.2,
                                        tractions1={}, tractions2={}, search_distance=0.1,
                                        obstacle={"kind": "circle", "center": (1.0, -2.0001), "radius": 2.0},
                                        dirichlet={"top1": {"x": 0.0, "y": (0.0, -0.01)}})),
    }


def build(name):
    import warnings

    import cfcontact

    builder, kwargs = cases()[name]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cfcontact.PairingWarning)
        return getattr(cfcontact, builder)(**kwargs)


def gathered(system):
    """Everything that must not depend on the number of ranks."""
    import cfcontact
    from cfcontact import linalg
    from cfcontact.condensed import CondensedSolver

    f1, f2 = system.loads_numpy()
    g = system.geometry
    out = {"K": linalg.gather_mat(system.K).toarray(), "N": linalg.gather_mat(system.N).toarray(),
           "T": linalg.gather_mat(system.T).toarray(), "f1": f1, "f2": f2, "gap": system.gap,
           "rho": np.array(system.rho), "contact_nodes": g.contact_nodes, "contact_points": g.contact_points,
           "tributary": g.tributary, "no_tangent": system.no_tangent.astype(int)}
    condensed = CondensedSolver(system)
    for a in (0.0, 1.0):
        start = cfcontact.ssnm(system.with_rho(0.1 * system.rho), a)  # (rho x 0.1: SSNM from 0 may cycle)
        sol = cfcontact.ssnm(system, a, y0=start)
        out[f"y{a:g}"] = sol.y
        out[f"codes{a:g}"] = sol.sets.state_codes()
        out[f"yc{a:g}"] = cfcontact.ssnm(system, a, y0=start, solver=condensed).y
    path = cfcontact.trace_path(system, 0.0, 1.0, method="exact")
    out["path_alphas"] = np.array([t.alpha for t in path.transitions])
    out["path_nodes"] = np.array([t.node for t in path.transitions], dtype=int)
    return out


def main(path):
    comm = MPI.COMM_WORLD
    result = {"size": np.array(comm.size)}
    for name in cases():
        system = build(name)
        result[f"{name}:ranges"] = np.array(system.K.getOwnershipRanges())
        result[f"{name}:owned_cells"] = np.array(comm.allgather(system.info.get("owned_cells", -1)))
        for key, value in gathered(system).items():
            result[f"{name}:{key}"] = value
    if comm.rank == 0:
        np.savez(path, **result)


if __name__ == "__main__":
    main(sys.argv[1])
