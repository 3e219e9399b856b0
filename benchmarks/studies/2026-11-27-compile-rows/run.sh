#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-27-compile-rows/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-compile-rows
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
# "old": the same commands with PYTHONPATH=OLD_TREE/src (a worktree of the parent commit), interleaved with these
for i in 1 2 3 4; do
  NUMBA_CACHE_DIR=$(mktemp -d) "$PY" "$R/cold_compile.py" new-$i
done
for i in 1 2; do
  "$PY" benchmarks/speed_cli.py --features gray --frames 700 --repeat 1 --out "$R/ab-new-idle-$i.json"
  "$PY" benchmarks/speed_cli.py --features gray --frames 300 --repeat 1 --busy 1 --out "$R/ab-new-busy-$i.json"
done
"$PY" benchmarks/profile_mapping.py "$S/7scenes-0000-0699" --frames 150 --repeat 2
