#!/usr/bin/env bash
# Run the demo: installs what is missing (scripts/install.sh), then demos/main.py.
#   ./demo.sh [ARGS]          arguments pass through to demos/main.py (try --help)
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")"
scripts/install.sh
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# Single-node MPI: keep Open MPI's TCP transport on loopback (quiets Open MPI 5's
# "Unable to find reachable pairing" warnings in containers and chroots).
export OMPI_MCA_btl_tcp_if_include="${OMPI_MCA_btl_tcp_if_include:-lo}"
exec .venv/bin/python demos/main.py "$@"
