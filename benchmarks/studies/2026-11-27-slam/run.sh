#!/usr/bin/env bash
# The measurements of issue 31 (SLAM), as run for docs/slam.md and README.md. From the repository root:
#   bash benchmarks/studies/2026-11-27-slam/run.sh
# Each accuracy run is one `dmtrack run --slam` (one numba thread); runs/NAME_seedK/ keeps its metrics.json,
# graph.json and trajectories (the point clouds are not kept).
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data/7scenes-0000-0699
R=benchmarks/studies/2026-11-27-slam
PY=${PYTHON:-.venv/bin/python}
"$PY" benchmarks/slam_study.py "$S" --feature gray --init geometric --seeds 0 --jobs 1 --out "$R" --name 7scenes_gray_geometric
"$PY" benchmarks/slam_study.py "$S" --feature gray --init random --seeds 0-4 --out "$R" --name 7scenes_gray_random
"$PY" benchmarks/slam_study.py "$S" --feature bitplanes --init geometric --seeds 0 --jobs 1 --out "$R" --name 7scenes_bitplanes_geometric
"$PY" benchmarks/slam_study.py "$S" --feature dsift --init geometric --seeds 0 --jobs 1 --out "$R" --name 7scenes_dsift_geometric
# whole-run speed, VO and SLAM alternated three times (nothing else running)
"$PY" benchmarks/slam_study.py "$S" --feature gray --speed 3 --out "$R" --name 7scenes_gray
"$PY" benchmarks/slam_study.py data/7scenes-redkitchen-0000-0299 --feature dsift --speed 2 --out "$R" --name sample_dsift \
  --max-frames 150
# every accepted edge of the default run against the ground truth
"$PY" benchmarks/slam_edges.py "$R/runs/7scenes_gray_geometric_seed0" --json "$R/7scenes_gray_geometric_edges.json" \
  > "$R/7scenes_gray_geometric_edges.txt"
# LSD-SLAM beside dmtrack (issue 31's anchor): upstream LSD-SLAM through tools/lsd_oracle (build it first with
# tools/lsd_oracle/build.sh), full system (slam=1, FabMap off) and VO (slam=0), one process at a time, from
# dmtrack's random initial maps of seeds 0-4, from LSD-SLAM's own srand maps (seeds 1-5: srand(0) is srand(1)), and
# every seed three more times (LSD-SLAM's threads make runs differ)
"$PY" benchmarks/lsd_slam_anchor.py "$S" --seeds 0-4 --out "$R" --name lsd_slam_anchor
"$PY" benchmarks/lsd_slam_anchor.py "$S" --field lsd --seeds 1-5 --out "$R" --name lsd_slam_anchor_srand
"$PY" benchmarks/lsd_slam_anchor.py "$S" --seeds 0-4 --repeat 3 --out "$R" --name lsd_slam_anchor_repeat
