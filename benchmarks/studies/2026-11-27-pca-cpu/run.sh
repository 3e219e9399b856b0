#!/usr/bin/env bash
# Issue 32, the CPU part: dsift-pca8 as a first-class feature. From the repository root:
#   bash benchmarks/studies/2026-11-27-pca-cpu/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-pca-cpu
PY=${PYTHON:-.venv/bin/python}
# the basis and the reduced feature's calibration (scale, N_E, κ, N_σ), on 20 frames of the repository's sample;
# written to the user's PCA folder, where --feature dsift-pca8 finds it (dsift-pca8.npz here is that file)
.venv/bin/dmtrack fit-pca --feature dsift --k 8 data/7scenes-redkitchen-0000-0299
study() { "$PY" benchmarks/start_study.py "$@" --out "$R" --jobs 1; }
study "$S/7scenes-0000-0699" --feature dsift-pca8 --name 7scenes_dsift-pca8_geometric
study "$S/tsukuba-150" --intrinsics 615,615,320,240 --r-l 1/20 --feature dsift-pca8 --name tsukuba_dsift-pca8_geometric
study "$S/kitti-odometry/sequences/06" --feature dsift-pca8 --name kitti_dsift-pca8_geometric
# whole runs of 100 frames of the sample, dsift and dsift-pca8 alternated three times (nothing else running)
"$PY" benchmarks/pca_cost.py --json "$R/pca_cost.json"
