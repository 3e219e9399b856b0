#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-27-tracknet-real/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-tracknet-real
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
FRAMES=$(for i in $(seq 0 15 285); do printf 'data/7scenes-redkitchen-0000-0299/frame-%06d.color.jpg ' $i; done)
for data in 7scenes both; do
  out="$R/$data-s0"
  "$DMTRACK" train-feature --out "$out" --seed 0 --steps 1500 --lr-schedule cosine --data $data \
    --data-path "$S/7scenes-0000-0699"
  "$PY" -c "import sys; from dmtrack.training.train import calibrate_weights; print(calibrate_weights(sys.argv[1], sys.argv[2:]))" \
    "$out/tracknet.npz" $FRAMES
done
"$PY" benchmarks/studies/2026-11-27-tracknet-full/tracknet_eval.py --out "$R" --weights real-both="$R/both-s0/tracknet.npz" \
  --weights real-7s="$R/7scenes-s0/tracknet.npz" --jobs 2
# intrinsics_check.sh: grey's odometry at three focal lengths (it was run from /work/main; paths there)
