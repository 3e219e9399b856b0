#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-24-channel-cost/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-24-channel-cost
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
"$PY" benchmarks/channel_cost_ablation.py --out "$R" --features gray,rgb,lab,bitplanes,dsift \
  --sequences 7scenes,tsukuba,kitti --seeds 0-2 --jobs 2
