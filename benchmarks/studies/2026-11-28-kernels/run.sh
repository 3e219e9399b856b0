#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-28-kernels/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-28-kernels
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
A=${A:-/tmp/dmtrack-a}   # a worktree of the baseline: git worktree add /tmp/dmtrack-a 3f78434
"$PY" benchmarks/ab_speed.py --a "$A/src" --b src --frames 300 --rounds 9 --out "$R/speed_ab_300.json" \
  | tee "$R/speed_ab_300.log"
"$PY" benchmarks/ab_speed.py --a "$A/src" --b src --features dsift --frames 100 --out "$R/speed_ab_dsift_100.json" \
  | tee "$R/speed_ab_dsift_100.log"
"$PY" benchmarks/ab_accuracy.py --a "$A/src" --b src --features gray,bitplanes,rgb --out "$R/accuracy_ab.json" \
  | tee "$R/accuracy_ab.log"
