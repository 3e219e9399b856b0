#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-28-candidates/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-28-candidates
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
"$PY" benchmarks/candidate_search_speed.py --rooms 16 --per-room 125 --out "$R"
