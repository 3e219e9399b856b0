#!/usr/bin/env bash
# Issue 14, dense SIFT's stereo: one observe call of the shared 7-Scenes replayed (profile_observe.py), the merged
# code only (the float32 and stereo-projection variants were unmerged: README.md). From the repository root:
#   bash benchmarks/studies/2026-11-27-dsift-stereo/run.sh
set -euo pipefail
R=benchmarks/studies/2026-11-27-dsift-stereo
PY=${PYTHON:-.venv/bin/python}
for i in 1 2 3; do "$PY" "$R/profile_observe.py" --json "$R/observe_base_$i.json"; done
# B: keyframe and frame maps stored as uint8, step 1 (a replay, no code change)
"$PY" "$R/profile_observe.py" --quantize 1 --json "$R/observe_baseline_uint8.json"
