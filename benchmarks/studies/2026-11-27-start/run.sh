#!/usr/bin/env bash
# The measurements of issue 30 (the geometric start), as run for README.md and docs/initialization.md.
# Every figure: python benchmarks/start_study.py (one process per run, one numba thread). From the repository root:
#   bash benchmarks/studies/2026-11-27-start/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-start
PY=${PYTHON:-.venv/bin/python}
study() { "$PY" benchmarks/start_study.py "$@" --out "$R" --jobs 2; }
# the features table, geometric start (deterministic: one run each)
for f in gray gray-affine rgb lab bitplanes dsift tracknet; do
  study "$S/7scenes-0000-0699" --feature "$f" --name "7scenes_${f}_geometric" --trajectories
  study "$S/tsukuba-150" --intrinsics 615,615,320,240 --r-l 1/20 --feature "$f" --name "tsukuba_${f}_geometric"
  study "$S/kitti-odometry/sequences/06" --feature "$f" --name "kitti_${f}_geometric"
done
# frames nobody tuned on: 7-Scenes 350-699 started at frame 350
for f in gray dsift bitplanes lab rgb; do
  study "$S/7scenes-0000-0699" --starts 350 --feature "$f" --name "7scenes350_${f}_geometric"
done
# today's start (random, seeds 0-9) where no ten-seed figure was recorded before
for f in bitplanes; do
  study "$S/tsukuba-150" --init random --seeds 0-9 --intrinsics 615,615,320,240 --r-l 1/20 --feature "$f" --name "tsukuba_${f}_random"
  study "$S/kitti-odometry/sequences/06" --init random --seeds 0-9 --feature "$f" --name "kitti_${f}_random"
done
study "$S/7scenes-0000-0699" --init random --seeds 0-9 --feature bitplanes --name "7scenes_bitplanes_random"
study "$S/7scenes-0000-0699" --init random --starts 350 --seeds 0-2 --feature dsift --name "7scenes350_dsift_random"
study "$S/7scenes-0000-0699" --init random --starts 350 --seeds 0-2 --feature gray --name "7scenes350_gray_random"
# the start's own lottery: 11 start frames of 7-Scenes, 160 frames each (drift at frames 100 and 150)
"$PY" benchmarks/start_scan.py "$S/7scenes-0000-0699" --json "$R/scan_geometric.json" > "$R/scan_geometric.txt"
"$PY" benchmarks/start_scan.py "$S/7scenes-0000-0699" --set init=random --json "$R/scan_random.json" > "$R/scan_random.txt"
