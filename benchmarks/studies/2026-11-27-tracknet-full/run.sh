#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-27-tracknet-full/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-tracknet-full
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
FRAMES=$(for i in $(seq 0 15 285); do printf 'data/7scenes-redkitchen-0000-0299/frame-%06d.color.jpg ' $i; done)
for s in 0 1; do
  "$DMTRACK" train-feature --out "$R/seed$s" --seed $s --steps 3000 --lr-schedule cosine
  "$PY" -c "import sys; from dmtrack.training.train import calibrate_weights; print(calibrate_weights(sys.argv[1], sys.argv[2:]))" \
    "$R/seed$s/tracknet.npz" $FRAMES
done
"$PY" "$R/tracknet_eval.py" --out "$R" --weights s0="$R/seed0/tracknet.npz" --weights s1="$R/seed1/tracknet.npz"
