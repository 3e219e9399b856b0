#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-27-seed-lottery/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-seed-lottery
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
for f in gray rgb lab; do
  "$PY" benchmarks/seed_study.py "$S/7scenes-0000-0699" --seeds 0-9 --feature $f --jobs 2 --out "$R" --name 7scenes_$f \
    --trajectories
  "$PY" benchmarks/orientation_drift.py "$R/7scenes_${f}_groundtruth.txt" "$R"/7scenes_${f}_seed?.txt --every 20 \
    --until 200 --json "$R/drift_$f.json"
done
