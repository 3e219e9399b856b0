#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-21-table7/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-21-table7
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
"$PY" benchmarks/bench_table7.py --frames 100 --out "$R/table7"
"$PY" benchmarks/bench_table7.py --frames 100 --repeat 3 --features gray,gray-affine,bitplanes,dsift,alexnet,alexnet-pca8 \
  --out "$R/table7_named_repeat3"
