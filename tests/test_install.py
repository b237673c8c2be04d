"""The package works installed, away from the source tree: a wheel built from a copy of the
package files, installed (without dependencies: Debian's) into a fresh venv, runs a small model
from a folder outside the source tree."""

import os
import shutil
import subprocess
import sys
import textwrap

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

SMALL_MODEL = textwrap.dedent("""
    import os, sys
    import cfcontact
    from cfcontact import demo_models
    from cfcontact.case import build_system, validate_case
    from cfcontact.meshes import two_blocks as script
    root = sys.argv[1]
    assert not os.path.realpath(cfcontact.__file__).startswith(root + os.sep), cfcontact.__file__
    system = cfcontact.two_blocks(nx=4, ny=2, friction=0.5)
    assert (system.n, system.m) == (48, 4)
    for method in ("seed", "exact"):
        path = cfcontact.trace_path(system, 0.0, 1.0, method=method)
        assert path.status == "completed", (method, path.status)
        assert cfcontact.verify(system, path.solutions_at(0.5)[0], 0.5).ok(1e-8)
    case = validate_case({"geometry": {"kind": "arc", "nx": 4, "ny": 1}, "path": {"method": "exact"}})
    assert build_system(case).m == 5
    assert demo_models.DEMO_FRICTIONS == (0.1, 0.6, 30.0) and script.DEFAULTS["nx"] == 30
    print("installed", cfcontact.__version__, "from", os.path.dirname(cfcontact.__file__))
""")


def _run(cmd, **kw):
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=900, **kw)
    assert proc.returncode == 0, f"{cmd}\nSTDOUT:\n{proc.stdout}\nSTDERR:\n{proc.stderr}"
    return proc


@pytest.mark.slow
def test_installed_wheel_runs_a_small_model_outside_the_source_tree(tmp_path):
    src = tmp_path / "src"  # only what the wheel is built from (no build/ left in the source tree)
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(os.path.join(ROOT, name), src / name)
    shutil.copytree(os.path.join(ROOT, "cfcontact"), src / "cfcontact",
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    wheels = tmp_path / "wheels"
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    _run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation", "-w", str(wheels),
          str(src)], env=env, cwd=tmp_path)
    (wheel,) = wheels.glob("cfcontact-*.whl")
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--system-site-packages", str(venv)], env=env, cwd=tmp_path)
    python = str(venv / "bin" / "python")
    _run([python, "-m", "pip", "install", "-q", "--no-deps", "--no-index", str(wheel)], env=env, cwd=tmp_path)
    work = tmp_path / "elsewhere"
    work.mkdir()
    proc = _run([python, "-c", SMALL_MODEL, os.path.realpath(ROOT)], env=env, cwd=work)
    assert "installed" in proc.stdout and str(venv) in proc.stdout
    proc = _run([python, "-m", "cfcontact.meshes.two_blocks", "m.msh", "--nx", "3", "--ny", "1"], env=env, cwd=work)
    assert (work / "m.msh").stat().st_size > 0
    proc = _run([str(venv / "bin" / "cfcontact"), "--version"], env=env, cwd=work)
    assert proc.stdout.strip().startswith("cfcontact ")
