#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-27-tracking-decision/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-tracking-decision
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
"$PY" benchmarks/channel_cost_ablation.py --out "$R" --features tfeat --sequences kitti --seeds 0-2 \
  --variant balanced=channel_cost=balanced --jobs 1
N=out/studies/2026-11-27-tracking-decision; mkdir -p "$N"   # the .npz files (0.5–18 MB) are not kept
"$PY" benchmarks/good_test_residuals.py "$S/7scenes-0000-0699" --feature bitplanes --max-frames 300 --out "$N/7s_bitplanes.npz"
"$PY" benchmarks/good_test_residuals.py "$S/7scenes-0000-0699" --feature dsift --max-frames 300 --out "$N/7s_dsift.npz"
"$PY" benchmarks/good_test_residuals.py "$S/kitti-odometry/sequences/06" --feature tfeat --max-frames 51 --r-l 0.05 \
  --out "$N/kitti_tfeat.npz"
"$PY" "$R/good_fraction.py" "$N"/*.npz > "$R/good_fraction.txt"
"$PY" "$R/unrelated_pair_energy.py" rgb lab bitplanes dsift > "$R/unrelated_pair_energy.txt"
