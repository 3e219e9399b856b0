#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-21-paper-bench/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-21-paper-bench
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
JOBS=2 benchmarks/run_paper_bench.sh out/studies/2026-11-21-paper-bench
cp out/studies/2026-11-21-paper-bench/{report.md,bench.json} "$R/" && cp -r out/studies/2026-11-21-paper-bench/figures "$R/"
