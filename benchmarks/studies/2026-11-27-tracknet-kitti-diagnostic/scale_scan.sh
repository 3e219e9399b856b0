#!/bin/bash
# KITTI 06 0-50: tracknet default weights at several scales, seeds 0-2
mkdir -p "${OUT:-/tmp/kscan}"
cd "$(dirname "$0")/../../.."
for sc in 78.403 40 110 156 220; do for s in 0 1 2; do
  o=${OUT:-/tmp/kscan}/s$sc-$s; [ -f $o/metrics.json ] && continue
  dmtrack run ../shared/data/kitti-odometry/sequences/06 --feature tracknet --feature-opt scale=$sc --seed $s --out $o --no-pointcloud --no-depth-images --r-l 0.05 > ${OUT:-/tmp/kscan}/log-$sc-$s 2>&1
done; done
