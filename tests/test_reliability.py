"""Reliability (issue #14): what a careless user meets in the first hour.

JIT noise on a fresh form cache, interrupts at any moment (one line, exit 130, resumable work
kept), kill -9 and stray temporary folders, the advisory lock of an output folder, size and
range checks before any work, non-finite and extreme numbers, corrupted saved paths and
checkpoints.  Each class is replayed here; the subprocess tests are marked slow."""

import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from cfcontact import cli
from cfcontact.path import SolutionPath

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

TINY = """
title = "tiny"
[geometry]
kind = "two_blocks"
nx = 6
ny = 2
[contact]
friction = 1.5
[output]
plot = false
render_panel = false
"""


def _env(**extra):
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    env.update(extra)
    return env


def _write(folder, text, name="case.toml"):
    fn = os.path.join(str(folder), name)
    with open(fn, "w") as fh:
        fh.write(text)
    return fn


def _cfcontact(*args, env=None, timeout=600, **kw):
    return subprocess.run([sys.executable, "-m", "cfcontact", *args], capture_output=True, text=True,
                          env=env or _env(), cwd=ROOT, timeout=timeout, **kw)


# ------------------------------------------------------------------ 1. JIT noise
@pytest.mark.slow
def test_fresh_form_cache_prints_only_cfcontact_lines(tmp_path):
    """An empty form cache (XDG_CACHE_HOME: dolfinx/FFCx keep compiled forms in $XDG_CACHE_HOME/fenics):
    the JIT compiles the element and the forms, and neither distutils' log lines nor the compiler's
    output reach the terminal, with or without -q."""
    cache = tmp_path / "cache"
    case = _write(tmp_path, TINY)
    proc = _cfcontact("run", case, env=_env(XDG_CACHE_HOME=str(cache)))
    assert proc.returncode == 0, proc.stderr
    assert list((cache / "fenics").glob("libffcx_forms_*.so")), "the forms were not compiled in the fresh cache"
    lines = (proc.stdout + proc.stderr).splitlines()
    assert lines and all(ln.startswith("cfcontact") for ln in lines), lines
    # -q on another fresh cache: nothing at all; a traction on a new tag compiles a new form, also quietly
    case = _write(tmp_path, TINY + "[loads.f2]\nright1 = [1.0e6, 0.0]\n", "new_tag.toml")
    proc = _cfcontact("run", case, "-q", env=_env(XDG_CACHE_HOME=str(tmp_path / "cache2")))
    assert proc.returncode == 0 and proc.stdout == "" and proc.stderr == "", proc.stderr
