#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-21-vo-stages/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-21-vo-stages
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
"$PY" benchmarks/bench_vo.py --frames 300 --repeat 3 --threads 1 --label after-1thread --out "$R/vo_gray_1thread.json"
"$PY" benchmarks/bench_vo.py --frames 300 --repeat 3 --label "session 2 final, idle machine" --out "$R/vo_gray.json"
# vo_gray_before.json: the same command in a worktree of 73eab5e (PYTHONPATH=THAT_TREE/src)
