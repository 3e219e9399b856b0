#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-27-channel-cost/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-channel-cost
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
for f in gray gray-affine rgb lab bitplanes dsift; do
  "$PY" benchmarks/channel_cost_ablation.py --out "$R" --features $f --sequences 7scenes,tsukuba,kitti --seeds 0-2 \
    --variant balanced=channel_cost=balanced --jobs 1
done
"$PY" benchmarks/channel_cost_ablation.py --out "$R" --features tfeat,disk --sequences tsukuba,kitti --seeds 0-2 \
  --variant balanced=channel_cost=balanced --jobs 1
"$PY" benchmarks/channel_cost_ablation.py --out "$R" --table-only
