"""Helper of tests/test_mpi_geometry.py::test_mpi_case_file_matches_serial (run under mpirun).

Usage: mpirun -n 2 python3 tests/mpi_case_script.py CASE.toml OUT.npz

Reads and validates a case file, builds its model (cfcontact.case.build_system), reports it as
``cfcontact info CASE.toml`` does (cfcontact.report.model_report) and traces its path with the
case's [path] section; writes, on rank 0, the gathered matrices and loads, the gap, the report
(JSON text) and the path's transitions and end point.
"""

import json
import sys

import numpy as np
from mpi4py import MPI


def result(case_file):
    """Everything that must not depend on the number of ranks."""
    import cfcontact
    from cfcontact import case, linalg
    from cfcontact.report import model_report

    c = case.load_case(case_file)
    system = case.build_system(c)
    options, span = case.path_request(c)
    path = cfcontact.trace_path(system, span.start, span.end, method=c["path"]["method"], options=options,
                                backend=c["path"]["backend"])
    f1, f2 = system.loads_numpy()
    return {"K": linalg.gather_mat(system.K).toarray(), "N": linalg.gather_mat(system.N).toarray(),
            "T": linalg.gather_mat(system.T).toarray(), "f1": f1, "f2": f2, "gap": system.gap,
            "report": np.array(json.dumps(model_report(system), sort_keys=True)),
            "status": np.array(path.status), "events": np.array(len(path.events)),
            "alphas": np.array([t.alpha for t in path.transitions]),
            "changes": np.array(json.dumps([t.changes for t in path.transitions])),
            "y_end": path.ys[-1], "alpha_end": np.array(path.alphas[-1]),
            "ranges": np.array(system.K.getOwnershipRanges())}


def main(case_file, out):
    res = result(case_file)
    if MPI.COMM_WORLD.rank == 0:
        np.savez(out, size=np.array(MPI.COMM_WORLD.size), **res)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
