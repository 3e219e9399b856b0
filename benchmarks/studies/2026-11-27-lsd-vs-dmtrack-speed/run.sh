#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root:
#   bash benchmarks/studies/2026-11-27-lsd-vs-dmtrack-speed/run.sh
set -euo pipefail
S=${DMTRACK_SHARED:-../shared}/data
R=benchmarks/studies/2026-11-27-lsd-vs-dmtrack-speed
PY=${PYTHON:-.venv/bin/python}
DMTRACK=${DMTRACK:-.venv/bin/dmtrack}
# images.txt / calib.txt as `tools/lsd_oracle/compare.py run` writes them
BUILD_DIR=/tmp/lsdbuild tools/lsd_oracle/build.sh
for i in 1 2 3; do
  /usr/bin/time -v /tmp/lsdbuild/lsd_oracle files=images.txt calib=calib.txt out=/tmp/lsd seed=1
  /usr/bin/time -v "$DMTRACK" run "$S/7scenes-0000-0699" --out /tmp/dmt
  /usr/bin/time -v /tmp/lsdbuild/lsd_oracle files=images.txt calib=calib.txt out=/tmp/lsd seed=1 end=150
  /usr/bin/time -v "$DMTRACK" run "$S/7scenes-0000-0699" --max-frames 150 --out /tmp/dmt
done
