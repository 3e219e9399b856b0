#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-25-speed-cli/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-25-speed-cli
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
"$PY" benchmarks/speed_cli.py --features gray --frames 700 --repeat 3 --out "$R/speed_cli_gray.json"
"$PY" benchmarks/speed_cli.py --features gray,bitplanes,dsift --frames 150 --repeat 3 --out "$R/speed_cli_150.json"
