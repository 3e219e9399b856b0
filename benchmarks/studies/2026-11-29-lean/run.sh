#!/usr/bin/env bash
# Makes this study's files (README.md says which). From the repository root, on an idle machine:
#   bash benchmarks/studies/2026-11-29-lean/run.sh
set -euo pipefail
R=benchmarks/studies/2026-11-29-lean
PY=${PYTHON:-.venv/bin/python}
# LSD-SLAM's C++ VO, built here (about 10 minutes; offline: LSD_SLAM_REPO=… G2O_REPO=… with local mirrors)
BUILD_DIR=/tmp/lsd tools/lsd_oracle/build.sh
# the tree before issue 39's changes, for the baseline row
git worktree add -f /tmp/dmtrack-before 7dc6f32 2>/dev/null || true
"$PY" benchmarks/speed_vs_lsd.py --lsd /tmp/lsd/lsd_oracle --rounds 3 --features gray,bitplanes --windows 0,5 \
    --baseline /tmp/dmtrack-before/src --out "$R/speed-vs-lsd" --readme README.md | tee "$R/speed-vs-lsd.log"
"$PY" benchmarks/memory_profile.py --out "$R/memory" | tee "$R/memory.log"
# byte-identity of the trajectories before / after, on the runs chosen on and held back
"$PY" benchmarks/ab_accuracy.py --a /tmp/dmtrack-before/src --b src --features gray,bitplanes \
    --runs 7s-0-699,7s-350-699,kitti06,tsukuba --out "$R/identity.json" | tee "$R/identity.log"
# the threading layers and the allocator settings (one run each, alternating; /usr/bin/time)
for r in 1 2 3; do
  for L in tbb omp; do
    NUMBA_THREADING_LAYER=$L /usr/bin/time -f "$L %e s %U u %S s %M KB" .venv/bin/dmtrack run \
        ../shared/data/7scenes-0000-0699 --out /tmp/dmt-$L 2>&1 | tail -1
  done
done | tee "$R/threading_layers.log"
