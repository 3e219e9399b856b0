#!/usr/bin/env bash
# Issue 38's measurements of the sliding window (docs/window.md); one process per run, one numba thread, two at once.
set -euo pipefail
cd "$(dirname "$0")/../../.."
here=benchmarks/studies/2026-11-28-window
py=.venv/bin/python
# chosen on: 7-Scenes 0-349 and two rendered sequences (sizes, points; the depth prior; marginalisation)
$py benchmarks/window_ab.py --sets tune --variant "w5=window.size=5" --variant "w7=window.size=7" \
    --variant "w7p=window.size=7;window.points=1000" --json $here/tune_fixed_sizes.json
$py benchmarks/window_ab.py --sets 7s-0-349 --variant "w5=window.size=5" --variant "dp0=window.size=5;window.depth_prior=0" \
    --variant "dp01=window.size=5;window.depth_prior=0.1" --variant "it12=window.size=5;window.iterations=12" \
    --jobs 1 > $here/tune_depth_prior.log
$py benchmarks/window_ab.py --sets tune --variant "m5=window.size=5;window.leave=marginalise" \
    --variant "m7=window.size=7;window.leave=marginalise" > $here/tune_marginalise.log
$py benchmarks/window_ab.py --sets tune --variant "w5=window.size=5" \
    --variant "w5g=window.size=5;window.gradient_weight=50" --json $here/tune_gradient_weight.json
# held back: 7-Scenes 350-699, the start scan's starts 50..500, KITTI 06, Tsukuba
$py benchmarks/window_ab.py --sets held --variant "w5=window.size=5" \
    --variant "m5=window.size=5;window.leave=marginalise" --json $here/held.json > $here/held.log
# the focal length from the images, from 585 and from 525 (7-Scenes 0-349, a window of 7, five runs each)
for f in 585 525; do
  for it in 1 2 3 4 5; do
    .venv/bin/dmtrack run ../shared/data/7scenes-0000-0699 --max-frames 350 --intrinsics $f,$f,320,240 \
      --window 7 --refine-intrinsics --out out/window-fp --no-progress --no-pointcloud --no-depth-images >/dev/null
    nf=$($py -c "import json; print(json.load(open('out/window-fp/metrics.json'))['window']['intrinsics']['fx'])")
    echo "start $f iter $it f $f -> $nf"; f=$nf
  done
done > $here/focal_fixed_point_7scenes.txt
# every feature at 585 and at the images' 579.5 (7-Scenes 0-699, no window)
$py benchmarks/window_ab.py --sets 7s-0-699 --features gray,bitplanes,rgb,lab,dsift \
    --variant "f579=--intrinsics=579.5,579.5,320,240" --json $here/focal_7scenes.json
# calibrate-from-video on Tsukuba (615 px) from 10 % off either way
for f in 676.5 553.5; do
  .venv/bin/dmtrack calibrate-from-video ../shared/data/tsukuba-150 --intrinsics $f,$f,320,240 \
    --out out/tsukuba-$f.txt --json > $here/tsukuba_from_$f.json
done
# Bit-Planes with the window's residuals on the grey images (2026-11-29)
$py benchmarks/window_ab.py --sets all --features bitplanes --variant "w5=window.size=5" \
    --variant "wg=window.size=5;window.channels=grey" --json $here/grey_residuals_bitplanes.json \
    > $here/grey_residuals_bitplanes.log
