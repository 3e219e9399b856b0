#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-28-start/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-28-start
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
OLD=${OLD:-/tmp/dmtrack-old}   # a worktree of main 6e72bd2: git worktree add /tmp/dmtrack-old 6e72bd2
"$PY" benchmarks/start_everywhere.py --src "$OLD/src" --cases kitti,tsukuba,7scenes --json "$R/before.json"
"$PY" benchmarks/start_everywhere.py --json "$R/after.json"
"$PY" benchmarks/start_everywhere.py --set initializer.essential=ransac --json "$R/variant_ransac_0.5.json"
"$PY" benchmarks/start_everywhere.py --set initializer.min_parallax_deg=0.25 --json "$R/variant_magsac_0.25.json"
"$PY" benchmarks/start_everywhere.py --cases 7scenes-long,forward --set initializer.essential=ransac --json "$R/long_ransac.json"
"$PY" benchmarks/start_everywhere.py --cases 7scenes-long,forward --json "$R/long_magsac.json"
(cd "$R" && python3 table.py)   # README's tables
# forward_before.json, full_runs.json and slam/: the README says how each was made
