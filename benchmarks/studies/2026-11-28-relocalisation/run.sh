#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-28-relocalisation/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-28-relocalisation
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
choose=(--cases 7scenes-540,7scenes-620,7scenes-300-520,7scenes-250-600)
show=(--cases 7scenes,synthetic4,synthetic3 --uncut)
"$PY" benchmarks/kidnap.py "${choose[@]}" --json "$R/choose-vo.json" | tee "$R/choose-vo.txt"
"$PY" benchmarks/kidnap.py "${choose[@]}" --slam --json "$R/choose-slam.json" | tee "$R/choose-slam.txt"
"$PY" benchmarks/kidnap.py "${show[@]}" --json "$R/show-vo.json"
"$PY" benchmarks/kidnap.py "${show[@]}" --slam --json "$R/show-slam.json"
"$PY" benchmarks/kidnap.py --cases 7scenes,synthetic4 --feature rgb --json "$R/rgb-show.json" | tee "$R/rgb.txt"
"$PY" benchmarks/kidnap.py "${choose[@]}" --feature bitplanes --json "$R/bitplanes-choose.json" | tee "$R/bitplanes.txt"
"$PY" benchmarks/kidnap.py "${show[@]}" --feature bitplanes --json "$R/bitplanes-show.json" | tee -a "$R/bitplanes.txt"
# lsd-*.json: the case with LSD-SLAM's thresholds; speed_*: benchmarks/ab_speed.py against main 6e72bd2
"$PY" benchmarks/kidnap.py --cases 7scenes --set relocalisation.good_value=0.7 --set relocalisation.min_good_ratio=0.625 \
  --json "$R/lsd-vo.json" | tee "$R/lsd.txt"
"$PY" benchmarks/kidnap.py --cases 7scenes --slam --set relocalisation.good_value=0.7 \
  --set relocalisation.min_good_ratio=0.625 --json "$R/lsd-slam.json" | tee -a "$R/lsd.txt"
