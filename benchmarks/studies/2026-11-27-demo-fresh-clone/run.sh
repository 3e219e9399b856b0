#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-27-demo-fresh-clone/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-demo-fresh-clone
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
rm -rf /tmp/democlone && git clone . /tmp/democlone
(cd /tmp/democlone && PIP_CACHE_DIR=$(mktemp -d) /usr/bin/time -v make demo)
