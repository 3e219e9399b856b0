#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-27-tracknet-prelim/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-tracknet-prelim
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
"$PY" benchmarks/channel_cost_ablation.py --out "$R" --features tracknet --sequences tsukuba,kitti,7scenes --seeds 0-2 \
  --variant balanced=channel_cost=balanced --jobs 1
