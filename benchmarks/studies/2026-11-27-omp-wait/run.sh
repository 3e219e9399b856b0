#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-27-omp-wait/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-omp-wait
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
# busy-unset-*.json: the busy runs below before dmtrack set the policy (a worktree of the parent commit)
cli() { "$PY" benchmarks/speed_cli.py --features gray --no-compile "$@"; }
for i in 1 2; do
  cli --frames 300 --repeat 1 --busy 1 --env OMP_WAIT_POLICY=PASSIVE --out "$R/busy-passive-$i.json"
  cli --frames 700 --repeat 1 --env OMP_WAIT_POLICY=ACTIVE --out "$R/idle-active-$i.json"
  cli --frames 700 --repeat 1 --env OMP_WAIT_POLICY=PASSIVE --out "$R/idle-passive-$i.json"
  for f in bitplanes dsift; do
    "$PY" benchmarks/speed_cli.py --features $f --no-compile --frames 150 --repeat 1 --env OMP_WAIT_POLICY=ACTIVE \
      --out "$R/idle150-$f-active-$i.json"
    "$PY" benchmarks/speed_cli.py --features $f --no-compile --frames 150 --repeat 1 --env OMP_WAIT_POLICY=PASSIVE \
      --out "$R/idle150-$f-passive-$i.json"
  done
done
cli --frames 300 --repeat 1 --busy 1 --out "$R/busy-after-1.json"
cli --frames 700 --repeat 3 --out "$R/idle-after-700.json"
