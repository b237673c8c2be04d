#!/usr/bin/env bash
# Run the test suite: installs what is missing (scripts/install.sh), then pytest.
#   ./test.sh                 all tests (what CI runs), the documentation build included
#                             (tests/test_docs.py: sphinx -W, the demos of its gallery; ~2 min)
#   ./test.sh --quick         the quick loop: -m "not slow and not mpi" (under a minute)
#   ./test.sh -m "not slow"   pytest options and paths pass through (also after --quick)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
scripts/install.sh
# Open MPI refuses to run as root without these (tests also pass --allow-run-as-root).
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# Single-node MPI: keep Open MPI's TCP transport on loopback (quiets Open MPI 5's
# "Unable to find reachable pairing" warnings in containers and chroots).
export OMPI_MCA_btl_tcp_if_include="${OMPI_MCA_btl_tcp_if_include:-lo}"
# One BLAS thread per process unless told otherwise: the MPI tests run 2 ranks on 2 cores.
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
# Renders: without a DISPLAY the render code starts its own Xvfb (Debian 13's VTK needs X;
# Debian 12's PyPI VTK also renders through EGL). install.sh has made sure Xvfb is there.
if [ -z "${DISPLAY:-}" ] && ! command -v Xvfb >/dev/null; then
    echo "test.sh: warning: no DISPLAY and no Xvfb: render tests will fail" >&2
fi
QUICK=()
if [ "${1:-}" = "--quick" ]; then
    shift
    QUICK=(-m "not slow and not mpi")
fi
exec .venv/bin/python -m pytest -q tests "${QUICK[@]}" "$@"
