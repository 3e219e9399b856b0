#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-21-accuracy/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-21-accuracy
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
# The rows were made at commits 7f2dc05, 0c910c5 and c6a8658 (table below), before channel_cost existed; today's
# equivalents of the two rules are --set channel_cost=sum and --set channel_cost=mean.
B=out/studies/2026-11-21-accuracy
export PYTHON
benchmarks/run_paper_bench.sh "$B/gray" --features gray gray-affine --jobs 1
benchmarks/run_paper_bench.sh "$B/sum" --features rgb lab bitplanes dsift tfeat disk --jobs 1 --set channel_cost=sum
benchmarks/run_paper_bench.sh "$B/mean" --features rgb lab bitplanes dsift --jobs 1 --set channel_cost=mean
"$DMTRACK" bench --sequences-file "$R/sequences-tsukuba-kitti.yaml" --features tfeat disk --jobs 2 --init random \
  --set channel_cost=mean --out "$B/learned-mean"
"$PY" "$R/accuracy_table.py" "sum (paper)=$B/gray" "sum (paper)=$B/sum" mean=$B/mean mean=$B/learned-mean \
  --out "$R/accuracy.md" --csv "$R/accuracy.csv"
