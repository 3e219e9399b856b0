#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-24-lsd-fidelity/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-24-lsd-fidelity
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
# The *_before rows: the same commands in a worktree of 046488e. lsd-slam_*_oracle.csv: tools/lsd_oracle (its README).
for rule in smoothed raw; do
  set_rule=(--set depth.update_variance=$rule)
  "$PY" benchmarks/seed_study.py "$S/7scenes-0000-0699" --seeds 0-9 "${set_rule[@]}" --out "$R" --name 7scenes-0000-0699_gray_$rule
  "$PY" benchmarks/seed_study.py "$S/tsukuba-150" --intrinsics 615,615,320,240 --r-l 1/20 --seeds 0-9 "${set_rule[@]}" \
    --out "$R" --name tsukuba-150_gray_$rule
  "$PY" benchmarks/seed_study.py "$S/kitti-odometry/sequences/06" --r-l 1/20 --seeds 0-9 "${set_rule[@]}" --out "$R" \
    --name kitti-06_gray_$rule
done
"$PY" benchmarks/seed_study.py "$S/7scenes-0000-0699" --seeds 0-9 --out "$R" --name 7scenes-0000-0699_gray_raw-search
"$PY" benchmarks/seed_study.py "$S/tsukuba-150" --intrinsics 615,615,320,240 --r-l 1/20 --seeds 0-9 --out "$R" \
  --name tsukuba-150_gray_raw-search
"$PY" benchmarks/seed_study.py "$S/kitti-odometry/sequences/06" --r-l 1/20 --seeds 0-9 --out "$R" --name kitti-06_gray_raw-search
"$PY" benchmarks/bench_vo.py --frames 300 --repeat 3 --out "$R/vo_gray_after.json"
