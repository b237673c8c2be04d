"""The layering rules of DESIGN.md: only the assembly and compatibility modules import dolfinx/ufl,
nothing below the command line imports it, and DESIGN.md lists every module."""

import ast
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(ROOT, "cfcontact")
FEM_MODULES = {"cfcontact.assembly", "cfcontact.compat"}
CLI_MODULES = {"cfcontact.cli", "cfcontact.__main__"}


def _modules():
    """{module name: source file} of every module of the package."""
    out = {}
    for folder, _, files in os.walk(PACKAGE):
        for fn in files:
            if fn.endswith(".py"):
                rel = os.path.relpath(os.path.join(folder, fn), ROOT)[:-3].replace(os.sep, ".")
                out[rel[:-len(".__init__")] if rel.endswith(".__init__") else rel] = os.path.join(folder, fn)
    return out


def _imports(name, filename):
    """Every module a module imports, at any level (functions included), as absolute names."""
    package = name if filename.endswith("__init__.py") else name.rpartition(".")[0]
    with open(filename) as fh:
        tree = ast.parse(fh.read(), filename)
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[:len(parts) - node.level + 1] + ([base] if base else []))
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)  # "from cfcontact import cli"
    return out


def test_only_assembly_and_compat_import_dolfinx_or_ufl():
    offenders = {}
    for name, fn in _modules().items():
        fem = {m for m in _imports(name, fn) if m.split(".")[0] in ("dolfinx", "ufl", "basix", "ffcx")}
        if fem and name not in FEM_MODULES:
            offenders[name] = sorted(fem)
    assert not offenders, f"only {sorted(FEM_MODULES)} may import dolfinx/ufl: {offenders}"


def test_nothing_below_the_cli_imports_it():
    offenders = {name for name, fn in _modules().items()
                 if name not in CLI_MODULES and _imports(name, fn) & {"cfcontact.cli", "cfcontact.__main__"}}
    assert not offenders, f"modules below the command line import it: {sorted(offenders)}"


@pytest.mark.slow
def test_importing_the_library_loads_no_fem_code():
    """Import time: everything but the FEM layer (and the renderer) loads without dolfinx or ufl."""
    skip = FEM_MODULES | {"cfcontact.models", "cfcontact.__main__", "cfcontact.render"}
    names = sorted(n for n in _modules() if n not in skip)
    code = ("import sys\n" + "".join(f"import {n}\n" for n in names)
            + "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('dolfinx', 'ufl'))\n"
            + "assert not bad, bad\n")
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]


def test_no_import_circle():
    """The modules' imports, lazy ones included, form no circle (as path -> exact -> path did)."""
    modules = _modules()
    # (the package itself is left out: "from cfcontact import linalg" needs cfcontact/__init__
    # loaded, which it always is first)
    graph = {n: sorted(m for m in _imports(n, fn) if m in modules and m not in (n, "cfcontact"))
             for n, fn in modules.items()}
    state = {}

    def visit(n, stack):
        state[n] = 1
        for d in graph[n]:
            if state.get(d) == 1:
                raise AssertionError("import circle: " + " -> ".join(stack[stack.index(d):] + [n, d]))
            if d not in state:
                visit(d, stack + [n])
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n, [])


def test_design_lists_every_module():
    with open(os.path.join(ROOT, "DESIGN.md")) as fh:
        design = fh.read()
    missing = [fn for fn in (os.path.relpath(f, ROOT) for f in _modules().values()) if f"`{fn}`" not in design]
    assert not missing, f"DESIGN.md does not list {missing}"
