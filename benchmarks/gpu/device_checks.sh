#!/usr/bin/env bash
# Issue 32's GPU measurement in one command (prepared for the lent H100; tested on the CPU path with DEVICE=cpu).
#
#   benchmarks/gpu/device_checks.sh [OUT]            # on the GPU machine: DEVICE=cuda (default)
#   DEVICE=cpu FRAMES=10 RUN_FRAMES=20 benchmarks/gpu/device_checks.sh /tmp/x   # the same script on a CPU
#
# It writes into OUT (default $OUT, else out/benchmarks/gpu):
#   info.txt            `dmtrack info` (versions, the GPU's name, whether it is usable)
#   table7_DEVICE.md/json  Table 7 (generation with the transfer, tracking, total) for gray, bitplanes, dsift,
#                       alexnet, alexnet-pca64..pca1, tfeat, disk, tracknet on FRAMES frames of data/
#   learned.txt         bench_learned_features.py: every network feature and its -pcaK on the CPU and on DEVICE
#   runs.txt            whole runs over RUN_FRAMES frames of data/: disk (128 channels), disk-pca16, tfeat-pca16
#                       (bases fitted by `dmtrack fit-pca --device` on 20 frames), their fps and feature_ms
# Needs: python3 with torch (CUDA build on the GPU), numpy, scipy, numba, opencv, pyyaml, tqdm, matplotlib;
# plyfile / plotly are not needed (no point clouds, no HTML). Wheels in .whl/ are installed first if present.
set -uo pipefail   # no -e: a failing step is logged and the next one still runs
cd "$(dirname "$0")/../.."
OUT_DIR=${1:-${OUT:-out/benchmarks/gpu}}
DEVICE=${DEVICE:-cuda}
FRAMES=${FRAMES:-100}
RUN_FRAMES=${RUN_FRAMES:-150}
PY=${PY:-python3}
SEQ=data/7scenes-redkitchen-0000-0299
mkdir -p "$OUT_DIR"
if compgen -G ".whl/*.whl" >/dev/null; then
  $PY -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl
  export PYTHONPATH=/tmp/site${PYTHONPATH:+:$PYTHONPATH}
fi
export PYTHONPATH=$PWD/src${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1
export DMTRACK_HOME=$(mktemp -d)   # no user scales / bases: the packaged defaults and what this script fits
DM="$PY -m dmtrack"
t0=$(date +%s)
stamp() { echo "[$(( $(date +%s) - t0 )) s] $*"; }

stamp "info"
{ $DM info; nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv 2>/dev/null || true; } \
  | tee "$OUT_DIR/info.txt"

stamp "Table 7 on $DEVICE ($FRAMES frames)"
FEATURES=gray,bitplanes,dsift,alexnet,alexnet-pca64,alexnet-pca32,alexnet-pca16,alexnet-pca8,alexnet-pca4
FEATURES=$FEATURES,alexnet-pca2,alexnet-pca1,tfeat,disk,tracknet
$PY benchmarks/bench_table7.py --device "$DEVICE" --frames "$FRAMES" --features "$FEATURES" \
  --warmup-frames 5 --out "$OUT_DIR/table7_${DEVICE/:/}" 2>&1 | tee "$OUT_DIR/table7.log"

stamp "learned features, CPU backends and $DEVICE"
$PY benchmarks/bench_learned_features.py --device "$DEVICE" --repeats 5 --pca 16,8,4,2,1 --no-numpy \
  --exact-pixels 500 2>&1 | tee "$OUT_DIR/learned.txt"

stamp "whole runs on $DEVICE ($RUN_FRAMES frames)"
: > "$OUT_DIR/runs.txt"
for base in disk tfeat; do
  $DM fit-pca --feature "$base" --k 16 --frames 20 --samples 100000 --device "$DEVICE" "$SEQ" \
    --out "$DMTRACK_HOME/pca/$base-pca16.npz" | tee -a "$OUT_DIR/runs.txt"
done
for feat in disk disk-pca16 tfeat-pca16; do
  opt=(); [[ $feat == *-pca16 ]] && opt=(--feature-opt "pca=$DMTRACK_HOME/pca/$feat.npz")
  $DM run "$SEQ" --feature "$feat" "${opt[@]}" --device "$DEVICE" --max-frames "$RUN_FRAMES" \
    --no-pointcloud --no-depth-images --out "$DMTRACK_HOME/run-$feat" | tee -a "$OUT_DIR/runs.txt"
  $PY - "$DMTRACK_HOME/run-$feat/metrics.json" "$feat" >> "$OUT_DIR/runs.txt" <<'PYEOF'
import json, sys
m = json.load(open(sys.argv[1]))
keys = ("device", "gpu", "fps", "feature_ms", "tracking_ms", "mapping_ms", "tracked_frames", "total_frames",
        "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "ate_rmse")
print("METRICS", sys.argv[2], json.dumps({k: m.get(k) for k in keys}))
PYEOF
done
stamp "done"
