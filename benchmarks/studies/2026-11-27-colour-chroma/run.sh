#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-27-colour-chroma/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-colour-chroma
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
study() { "$PY" benchmarks/colour_channel_study.py "$@" --jobs 1; }
study --out "$R" --variants lab-l,grey-ab,rgb-g,lab-ab
study --out "$R" --variants lab-cs2,grey-ab-cs2 --sequences 7scenes,tsukuba
study --out "$R" --variants lab-chroma2,rgb-chroma2 --sequences 7scenes,tsukuba
study --out "$R/seeds-3-9" --variants lab-chroma2,rgb-chroma2 --seeds 3-9
# the packaged defaults after the change
"$PY" benchmarks/channel_cost_ablation.py --out "$R/defaults" --features rgb,lab --seeds 0-2 \
  --variant balanced=channel_cost=balanced --jobs 1
"$PY" benchmarks/channel_cost_ablation.py --out "$R/defaults/seeds-3-9" --features rgb,lab --sequences 7scenes \
  --seeds 3-9 --variant balanced=channel_cost=balanced --jobs 1
