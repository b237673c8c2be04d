#!/usr/bin/env bash
# Install everything cfcontact needs on Debian 12 (bookworm) or Debian 13 (trixie).
#
#   scripts/install.sh          (as root, or as a user with sudo)
#
# * Debian packages (FEniCSx/dolfinx, PETSc, gmsh, SciPy, Matplotlib, threadpoolctl, pytest,
#   hypothesis, OpenBLAS, Open MPI, Xvfb; Sphinx with the MyST parser, the Read-the-Docs theme
#   and MathJax for the documentation; on trixie also Debian's PyVista/VTK), installed only
#   when missing.
# * .venv in the repository root: /usr/bin/python3 -m venv --system-site-packages, so Debian's
#   dolfinx/petsc4py/numpy are used as they are.
# * Debian 12 only: PyVista and VTK from PyPI into .venv, with NumPy and Matplotlib held at
#   Debian's versions (NumPy 2 breaks Debian 12's petsc4py: "numpy.dtype size changed").
#   The PyPI VTK wheel renders off-screen through EGL (Mesa) without any display.
# * cfcontact itself, editable: .venv/bin/pip install --no-deps --no-build-isolation -e .
#
# Idempotent: a stamp (.venv/.cfcontact-install-stamp, a hash of this script, pyproject.toml
# and the Debian release) plus a dpkg-query check make a repeated run take well under a second.
# CFCONTACT_FORCE_INSTALL=1 redoes the venv steps and checks.
# Other systems: use docker/Dockerfile (Debian 13 image).
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$REPO"
PY=/usr/bin/python3          # Debian's Python; never the one first on PATH (pyenv etc.)
VENV="$REPO/.venv"
STAMP="$VENV/.cfcontact-install-stamp"

# PyPI versions for Debian 12 (Python 3.11, NumPy 1.24): verified to install with NumPy held at
# 1.24.2 and to render off-screen (EGL) without a display.
PYVISTA_VERSION=0.49.1
VTK_VERSION=9.7.2

say() { printf '[install] %s\n' "$*" >&2; }
die() { say "error: $*"; exit 1; }

# ---------------------------------------------------------------------------------------------
CODENAME=$( . /etc/os-release 2>/dev/null && echo "${VERSION_CODENAME:-}" ) || CODENAME=
PKGS=(python3-dolfinx-real python3-gmsh python3-venv python3-pip python3-setuptools python3-wheel
      python3-scipy python3-matplotlib python3-threadpoolctl python3-pytest python3-hypothesis
      libopenblas0-pthread openmpi-bin xvfb xauth
      python3-sphinx python3-myst-parser python3-sphinx-rtd-theme libjs-mathjax)
case "$CODENAME" in
    bookworm)
        # The PyPI VTK wheel dlopens libEGL/libGL at run time: Mesa's EGL (surfaceless,
        # llvmpipe) for off-screen rendering, GLX for rendering on an X display (e.g. Xvfb).
        PKGS+=(libegl1 libegl-mesa0 libgl1-mesa-dri libgl1 libglx-mesa0) ;;
    trixie)
        # Debian's PyVista on Debian's VTK 9.3, which needs an X display (Xvfb when headless).
        PKGS+=(python3-pyvista libgl1-mesa-dri libglx-mesa0) ;;
    *)
        die "unsupported system '${CODENAME:-unknown}' (from /etc/os-release VERSION_CODENAME).
  scripts/install.sh supports Debian 12 (bookworm) and Debian 13 (trixie) only.
  On any other system use the Docker image (Debian 13):
      docker build -f docker/Dockerfile -t cfcontact .
      docker run --rm cfcontact              # runs ./test.sh
      docker run --rm cfcontact ./demo.sh" ;;
esac

missing_packages() {
    # dpkg-query prints nothing (and complains on stderr) for packages it has never seen.
    local status
    status=$(dpkg-query -W -f='${Package} ${db:Status-Abbrev}\n' "${PKGS[@]}" 2>/dev/null || true)
    for p in "${PKGS[@]}"; do
        grep -qE "^$p ii" <<<"$status" || printf '%s\n' "$p"
    done
}

stamp_value() {
    { echo "$CODENAME"; cat "$REPO/scripts/install.sh" "$REPO/pyproject.toml"; } | sha256sum | cut -d' ' -f1
}

venv_ok() {   # the venv exists, is Debian's Python and sees the system site-packages
    [ -x "$VENV/bin/python" ] && [ -f "$VENV/pyvenv.cfg" ] || return 1
    grep -qE '^home *= */usr/bin$' "$VENV/pyvenv.cfg" || return 1
    grep -qE '^include-system-site-packages *= *true$' "$VENV/pyvenv.cfg" || return 1
    [ "$("$VENV/bin/python" -c 'import sys; print(sys.version)' 2>/dev/null)" = \
      "$("$PY" -c 'import sys; print(sys.version)' 2>/dev/null)" ] || return 1
}

MISSING=$(missing_packages)

# Fast path: nothing missing and the stamp matches.
if [ -z "$MISSING" ] && [ -z "${CFCONTACT_FORCE_INSTALL:-}" ] && [ -f "$STAMP" ] &&
   [ "$(cat "$STAMP")" = "$(stamp_value)" ] && venv_ok; then
    say "up to date (Debian $CODENAME, $VENV)"
    exit 0
fi

t0=$SECONDS
if [ "$(id -u)" -eq 0 ]; then SUDO=(); else
    command -v sudo >/dev/null || die "not root and no sudo: run scripts/install.sh as root"
    SUDO=(sudo)
fi

# ---------------------------------------------------------------------------------------------
# 1. Debian packages.
if [ -n "$MISSING" ]; then
    say "installing Debian packages: $(echo $MISSING)"
    export DEBIAN_FRONTEND=noninteractive
    APT=(apt-get -y -q -o DPkg::Lock::Timeout=600 -o Dpkg::Use-Pty=0)
    "${SUDO[@]}" "${APT[@]}" update
    # shellcheck disable=SC2086
    "${SUDO[@]}" "${APT[@]}" install $MISSING
    MISSING=$(missing_packages)
    [ -z "$MISSING" ] || die "still missing after apt-get install: $(echo $MISSING)"
    say "Debian packages installed ($((SECONDS - t0)) s)"
fi

# OpenBLAS must be the BLAS/LAPACK behind libblas.so.3 / liblapack.so.3.
MA=$("$PY" -c 'import sysconfig; print(sysconfig.get_config_var("MULTIARCH") or "")')
[ -n "$MA" ] || MA=$(gcc -print-multiarch 2>/dev/null || echo x86_64-linux-gnu)
for lib in libblas.so.3 liblapack.so.3; do
    want="/usr/lib/$MA/openblas-pthread/$lib"
    cur=$(update-alternatives --query "$lib-$MA" 2>/dev/null | awk '/^Value:/ {print $2}')
    if [ -e "$want" ] && [ "$cur" != "$want" ]; then
        say "switching $lib to OpenBLAS (was: ${cur:-none})"
        "${SUDO[@]}" update-alternatives --set "$lib-$MA" "$want"
    fi
done
BLAS=$("$PY" - <<'EOF'
import numpy
numpy.dot(numpy.ones((64, 64)), numpy.ones((64, 64)))
libs = sorted({l.split()[-1] for l in open("/proc/self/maps") if "blas" in l.split()[-1].lower()})
print(" ".join(libs))
EOF
)
case "$BLAS" in
    *openblas*) say "BLAS in use: $BLAS" ;;
    *) die "NumPy does not use OpenBLAS (loaded: ${BLAS:-nothing}); check 'update-alternatives --display libblas.so.3-$MA'" ;;
esac

command -v Xvfb >/dev/null && command -v xvfb-run >/dev/null || die "Xvfb/xvfb-run not found after installing xvfb"
command -v mpirun >/dev/null || die "mpirun not found after installing openmpi-bin"

# ---------------------------------------------------------------------------------------------
# 2. The virtual environment.
if ! venv_ok; then
    if [ -e "$VENV" ]; then say "recreating $VENV (not a --system-site-packages venv of $PY)"; rm -rf "$VENV"; fi
    say "creating $VENV"
    "$PY" -m venv --system-site-packages "$VENV"
fi
PIP=("$VENV/bin/python" -m pip --disable-pip-version-check)

# 3. PyVista/VTK from PyPI on Debian 12, NumPy and Matplotlib held at Debian's versions.
if [ "$CODENAME" = bookworm ]; then
    CONSTRAINTS="$VENV/cfcontact-constraints.txt"
    "$PY" - >"$CONSTRAINTS" <<'EOF'
import numpy, matplotlib
print(f"numpy=={numpy.__version__}")
print(f"matplotlib=={matplotlib.__version__}")
try:  # Debian's Sphinx Markdown parser needs markdown-it-py < 3 (pyvista's rich would pull 4)
    import myst_parser  # noqa: F401
    print("markdown-it-py<3")
except ImportError:
    pass
EOF
    have=$("$VENV/bin/python" -c 'import importlib.metadata as m
try: print(m.version("pyvista"), m.version("vtk"))
except Exception: print("")' 2>/dev/null || true)
    if [ "$have" != "$PYVISTA_VERSION $VTK_VERSION" ]; then
        say "installing pyvista==$PYVISTA_VERSION vtk==$VTK_VERSION from PyPI (constraints: $(tr '\n' ' ' <"$CONSTRAINTS"))"
        # (the filter drops pip's notes about find-links/index folders a host's pip.conf may name)
        "${PIP[@]}" install -q -c "$CONSTRAINTS" "pyvista==$PYVISTA_VERSION" "vtk==$VTK_VERSION" 2>&1 |
            { grep -v 'is ignored: it is neither a file nor a directory' || true; } >&2
    fi
    # Debian 12's dolfinx 0.5 turns on RTLD_GLOBAL for good (dolfinx/__init__.py), so libdolfinx's
    # std::regex code (new C++ string ABI) interposes on the PyPI VTK wheel's own (old ABI,
    # manylinux2014) when VTK is loaded after dolfinx: abort with std::bad_alloc as soon as VTK
    # formats a label (scalar bars). A small startup hook in the venv loads VTK's core library
    # just before the first `import dolfinx`, whoever imports it (tests, demos, cfcontact).
    SITE=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
    [ -d "$SITE" ] || die "venv site-packages not found: $SITE"
    cat >"$SITE/_cfcontact_vtk_first.py" <<'PYEOF'
"""Written by cfcontact's scripts/install.sh (Debian 12 venv only).

Debian 12's dolfinx 0.5 sets RTLD_GLOBAL for every later extension module, so libdolfinx's
std::regex instantiations (C++11 string ABI) would be bound into the PyPI VTK wheel (old string
ABI) if VTK were loaded after dolfinx, and VTK aborts (std::bad_alloc) when it formats a label.
Loading vtkCommonCore first binds VTK to its own code. Costs ~0.2 s, once, on `import dolfinx`.
"""
import sys


class _VTKBeforeDolfinx:
    @staticmethod
    def find_spec(name, path=None, target=None):
        if name == "dolfinx":
            try:
                sys.meta_path.remove(_VTKBeforeDolfinx)
            except ValueError:
                pass
            try:
                import vtkmodules.vtkCommonCore  # noqa: F401
            except Exception:
                pass
        return None


sys.meta_path.insert(0, _VTKBeforeDolfinx)
PYEOF
    echo "import _cfcontact_vtk_first" >"$SITE/_cfcontact_vtk_first.pth"
    "$VENV/bin/python" - "$CONSTRAINTS" <<'EOF'
import sys, numpy, matplotlib
want = dict(l.strip().split("==") for l in open(sys.argv[1]) if "==" in l)
got = {"numpy": numpy.__version__, "matplotlib": matplotlib.__version__}
assert got == want, f"venv shadows Debian's packages: {got} != {want}"
assert numpy.__file__.startswith("/usr/lib/python3/"), numpy.__file__
EOF
fi

# 4. cfcontact, editable.
say "installing cfcontact (editable)"
"${PIP[@]}" install -q --no-deps --no-build-isolation -e "$REPO"

# 5. Checks.
"$VENV/bin/python" - "$REPO" <<'EOF'
import importlib.util, os, sys
import numpy, scipy, matplotlib, gmsh, dolfinx, pyvista, vtk, threadpoolctl
import sphinx, myst_parser, sphinx_rtd_theme   # the documentation build (tests/test_docs.py)
from mpi4py import MPI
from petsc4py import PETSc
v = PETSc.Vec().createSeq(4); v.set(1.0); assert v.sum() == 4.0   # petsc4py works with this numpy
spec = importlib.util.find_spec("cfcontact")
assert spec is not None, "cfcontact is not importable from the venv"
loc = os.path.realpath(list(spec.submodule_search_locations)[0])
assert loc == os.path.realpath(os.path.join(sys.argv[1], "cfcontact")), loc
print(f"[install] python {sys.version.split()[0]}, numpy {numpy.__version__}, scipy {scipy.__version__}, "
      f"matplotlib {matplotlib.__version__}, dolfinx {dolfinx.__version__}, "
      f"petsc4py {PETSc.Sys.getVersion()}, gmsh {gmsh.__version__}, pyvista {pyvista.__version__}, "
      f"vtk {vtk.vtkVersion.GetVTKVersion()}, cfcontact from {loc}", file=sys.stderr)
EOF

# Off-screen rendering smoke test (a warning only: everything but the renders works without it).
RENDER_TEST='
import dolfinx   # first, as in the tests: checks the VTK/dolfinx load order on Debian 12
import numpy as np, pyvista as pv
pl = pv.Plotter(off_screen=True, window_size=(160, 120))
mesh = pv.Sphere()
mesh["s"] = np.arange(mesh.n_points, dtype=float)
pl.add_mesh(mesh, scalars="s", scalar_bar_args={"title": "s"})
img = pl.screenshot(return_img=True)
pl.close()
assert img.std() > 1.0, "blank image"
print(pl.__class__.__name__, "rendered a", img.shape, "image")
'
render_ok=0
RENDER_LOG="$VENV/cfcontact-render-check.log"
if [ "$CODENAME" = bookworm ]; then
    # PyPI VTK: EGL without any display.
    env -u DISPLAY VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow \
        "$VENV/bin/python" -c "$RENDER_TEST" >"$RENDER_LOG" 2>&1 && render_ok=1
else
    # Debian's VTK needs X: a private Xvfb.
    timeout 120 xvfb-run -a -s "-screen 0 1024x768x24" "$VENV/bin/python" -c "$RENDER_TEST" \
        >"$RENDER_LOG" 2>&1 && render_ok=1
fi
if [ $render_ok = 1 ]; then say "pyvista renders off-screen"
else
    tail -n 15 "$RENDER_LOG" >&2
    say "WARNING: pyvista could not render off-screen (log: $RENDER_LOG); renders will fail, everything else works"
fi

stamp_value >"$STAMP"
say "done in $((SECONDS - t0)) s: $VENV (Debian $CODENAME)"
