#!/usr/bin/env bash
# The paper-style benchmark (Tables 2–7, Figures 1, 4, 5 of "Direct multichannel tracking") on the shared real
# sequences: 7-Scenes (700 frames), New Tsukuba (150 frames, image folder) and KITTI odometry 06, with the
# features gray, gray-affine, bitplanes and dsift.
#
#   benchmarks/run_paper_bench.sh [OUT_DIR] [more dmtrack bench options, e.g. --max-frames 100 --jobs 4]
#
# Per-sequence options go into OUT_DIR/sequences.yaml (written below, kept with the results):
#   * 7-Scenes: r_l = 1/3 (the default);
#   * Tsukuba: its image folder has no intrinsics → 615,615,320,240 (New Tsukuba), r_l = 1/20 (paper §3.1),
#     ground truth in centimetres (errors are reported in deg/cm);
#   * KITTI: r_l = 1/20.
# The start is the paper's (--init random, seeded random first map); pass --init geometric for dmtrack's default.
# Environment: DMTRACK_SHARED (default REPO/../shared), JOBS (default: all CPUs), PYTHON (default REPO/.venv).
# Resumable: running it again skips the runs already finished with the same settings; `dmtrack report OUT_DIR`
# rebuilds OUT_DIR/report.md alone.  Add --scheduler tcp://HOST:8786 to run it on a Dask cluster (OUT_DIR and
# the data must then be on a filesystem shared with the workers).
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
SHARED="$(cd "${DMTRACK_SHARED:-$REPO/../shared}" && pwd)"
OUT="${1:-$REPO/out/paper-bench}"
shift || true
JOBS="${JOBS:-$(nproc 2>/dev/null || echo 1)}"
PYTHON="${PYTHON:-$REPO/.venv/bin/python}"

for d in "$SHARED/data/7scenes-0000-0699" "$SHARED/data/tsukuba-150" "$SHARED/data/kitti-odometry/sequences/06"; do
  [[ -d "$d" ]] || { echo "run_paper_bench.sh: missing sequence $d (set DMTRACK_SHARED)" >&2; exit 1; }
done

mkdir -p "$OUT"
cat > "$OUT/sequences.yaml" <<YAML
# written by benchmarks/run_paper_bench.sh
sequences:
  - path: "$SHARED/data/7scenes-0000-0699"
    dataset: 7-Scenes
  - path: "$SHARED/data/tsukuba-150"
    intrinsics: 615,615,320,240
    r_l: 1/20
    dataset: Tsukuba
    unit: cm
  - path: "$SHARED/data/kitti-odometry/sequences/06"
    r_l: 1/20
    dataset: KITTI
YAML

exec "$PYTHON" -m dmtrack.cli bench \
  --sequences-file "$OUT/sequences.yaml" \
  --features gray gray-affine bitplanes dsift \
  --out "$OUT" \
  --jobs "$JOBS" \
  --init random \
  "$@"
