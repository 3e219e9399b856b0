#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-27-tracknet-kitti-diagnostic/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-tracknet-kitti-diagnostic
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
K=out/studies/2026-11-27-tracknet-kitti-diagnostic
run() { "$DMTRACK" run "$S/kitti-odometry/sequences/06" --init random --r-l 0.05 --no-pointcloud --no-depth-images "$@"; }
run --feature gray --seed 0 --out "$K/gray-0"
run --feature bitplanes --seed 0 --out "$K/bitplanes-0"
for s in 0 1 2; do run --feature tracknet --seed $s --out "$K/tracknet-$s"; done
"$PY" "$R/per_frame_rotation.py" "$K"/gray-0 "$K"/bitplanes-0 "$K"/tracknet-? > "$R/per_frame_rotation.txt"
OUT="$K/scan" bash "$R/scale_scan.sh"   # its runs; scale_scan.csv holds their RPE
for init in previous gt; do
  "$PY" "$R/decoupled_tracking.py" --sequences kitti --init $init --json "$R/decoupled-init-$init.json" \
    | tee "$R/decoupled-init-$init.log"
done
"$PY" "$R/weights_at_truth.py" > "$R/weights_at_truth.txt"
