#!/usr/bin/env bash
# Issue 32: tfeat-pca16 and disk-pca16 against their full 128 channels, measured on the CPU (no GPU was lent).
# From the repository root:  bash benchmarks/studies/2026-11-27-pca-learned/run.sh
# The bases (and each reduced feature's scale, N_E, kappa, N_sigma) are fitted by `dmtrack fit-pca` on 8 frames of
# the repository's sample, into home/pca/ here (DMTRACK_HOME), where --feature BASE-pca16 finds them.
# The geometric start does not use the seed, so "seeds 0-2" is one run per cell.
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-pca-learned
PY=${PYTHON:-.venv/bin/python}
export DMTRACK_HOME=$R/home
for base in tfeat disk; do
  .venv/bin/dmtrack fit-pca --feature "$base" --k 16 --frames 8 --samples 100000 --device cpu \
    data/7scenes-redkitchen-0000-0299
done
study() { "$PY" benchmarks/start_study.py "$@" --out "$R" --jobs 1; }
for f in tfeat tfeat-pca16 disk disk-pca16; do
  study "$S/kitti-odometry/sequences/06" --feature "$f" --name "kitti_${f}_geometric"
done
