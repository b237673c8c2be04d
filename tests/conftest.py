import os
import shutil
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def mpirun_cmd(nprocs, *args):
    """Command list running ``python args`` under mpirun with ``nprocs`` ranks."""
    mpirun = shutil.which("mpirun") or shutil.which("mpiexec")
    if mpirun is None:
        pytest.fail("mpirun not found: the install script installs openmpi-bin")
    cmd = [mpirun, "-n", str(nprocs)]
    if os.geteuid() == 0:
        cmd.append("--allow-run-as-root")
    cmd += ["--oversubscribe"]
    return cmd + [sys.executable, *args]


@pytest.fixture
def run_mpi():
    def run(nprocs, *args, timeout=600):
        env = dict(os.environ)
        env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
        env.setdefault("OMPI_MCA_rmaps_base_oversubscribe", "1")
        proc = subprocess.run(mpirun_cmd(nprocs, *args), capture_output=True, text=True, env=env, timeout=timeout, cwd=ROOT)
        if proc.returncode != 0:
            raise AssertionError(f"mpirun failed ({proc.returncode}):\nSTDOUT:\n{proc.stdout}\nSTDERR:\n{proc.stderr}")
        return proc
    return run


def pytest_collection_modifyitems(session, config, items):
    """Run the tests that render with VTK first.

    On Debian 12, dolfinx 0.5 turns on RTLD_GLOBAL, and the PyPI VTK wheel loaded after it binds
    libdolfinx's C++ regex code (other string ABI) and aborts (std::bad_alloc).  install.sh puts a
    hook in the venv that loads VTK's core before dolfinx; running render tests first is a second
    guard for runs outside that venv.
    """
    first = ("test_render.py", "test_cli.py", "test_variants.py")
    items.sort(key=lambda item: 0 if item.fspath.basename in first else 1)
    # every test that runs mpirun carries the mpi marker (so that -m "not mpi" leaves them all out)
    unmarked = [item.nodeid for item in items
                if "run_mpi" in getattr(item, "fixturenames", ()) and item.get_closest_marker("mpi") is None]
    if unmarked:
        raise pytest.UsageError(f"tests using run_mpi without @pytest.mark.mpi: {unmarked}")


@pytest.fixture
def kernels():
    """cfcontact.native's compiled library; a test that compares the compiled kernels with their
    NumPy counterparts is skipped without them (CFCONTACT_NATIVE=0 or no C compiler), where
    cfcontact runs the NumPy code alone."""
    from cfcontact import native

    lib = native.library()
    if lib is None:
        pytest.skip("no compiled kernels (CFCONTACT_NATIVE=0 or no C compiler)")
    return lib
