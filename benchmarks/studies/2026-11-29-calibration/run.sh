#!/usr/bin/env bash
# The calibration study of 2026-11-29 (issue 38); from the repository root, with ../shared beside it.
# LSD-SLAM's trajectories come from tools/lsd_oracle (build it with tools/lsd_oracle/build.sh): LSD=path/to/lsd_oracle.
set -euo pipefail
D=benchmarks/studies/2026-11-29-calibration
SEQ=../shared/data/7scenes-0000-0699
PY=${PY:-.venv/bin/python}
OUT=${OUT:-out/studies/calibration}
mkdir -p "$OUT"

# 1. rotation gains: dmtrack grey on the 11 held-back runs, documented 585 and (555, -0.04)
for run in 350:350 50:160 100:160 150:160 200:160 250:160 300:160 350:160 400:160 450:160 500:160; do
  s=${run%%:*}; n=${run#*:}
  NUMBA_NUM_THREADS=1 .venv/bin/dmtrack run $SEQ --start $s --max-frames $n --out "$OUT/s$s-n$n-off" --no-progress \
    --no-pointcloud --no-depth-images
  NUMBA_NUM_THREADS=1 .venv/bin/dmtrack run $SEQ --start $s --max-frames $n --intrinsics $D/7scenes-colour-f555-k1-0.04.txt \
    --out "$OUT/s$s-n$n-c555" --no-progress --no-pointcloud --no-depth-images
done
(for v in off c555; do $PY $D/rotation_gain.py runs "$OUT"/*-$v; done) > $D/gains_dmtrack_grey.txt
if [ -n "${LSD:-}" ]; then
  for r in all:0:700 h350:350:700 s200:200:360 s100:100:260; do
    IFS=: read -r name a b <<< "$r"
    for i in $(seq $a $((b - 1))); do printf '%s/frame-%06d.color.jpg\n' "$(realpath $SEQ)" $i; done > "$OUT/$name-list.txt"
    printf '0.9140625 1.21875 0.50078125 0.50104167 0\n640 480\nnone\n640 480\n' > "$OUT/calib.txt"
    "$LSD" files="$OUT/$name-list.txt" calib="$OUT/calib.txt" out="$OUT/lsd-$name"
    $PY $D/rotation_gain.py lsd $SEQ "$OUT/lsd-$name.txt" $a
  done > $D/gains_lsd_slam.txt
fi
(for fr in 0:350 350:700; do $PY $D/rotation_gain.py two-view $SEQ --frames $fr --focal 585,555,525 --k1=-0.08,-0.04,0; done) \
  > $D/two_view.txt
$PY $D/rotation_gain.py checks "$OUT/s200-n160-off" $SEQ 200 > $D/checks_scan200.txt
NUMBA_NUM_THREADS=1 $PY $D/next_keyframe_oracle.py "$OUT/oracle-200" $SEQ --start 200 --max-frames 160
NUMBA_NUM_THREADS=1 $PY $D/next_keyframe_oracle.py "$OUT/oracle-0" $SEQ --max-frames 350

# 2. the images' own preference: the odometry's photometric error over (f, k1)
$PY $D/residual_grid.py $SEQ --out "$OUT/grid0" --max-frames 350 && cp "$OUT/grid0/grid.json" $D/grid_0-349.json
$PY $D/residual_grid.py $SEQ --out "$OUT/grid350" --start 350 --max-frames 350 && cp "$OUT/grid350/grid.json" $D/grid_350-699.json
$PY $D/residual_grid.py $SEQ --out "$OUT/gridf" --focal 540,555,570 --k1=-0.06,-0.04,-0.02 --max-frames 350 \
  && cp "$OUT/gridf/grid.json" $D/grid_0-349_fine.json

# 3. the held-back runs with those calibrations (7-Scenes only: the files are this camera's)
HELD=7s-350-699,$(for s in 50 100 150 200 250 300 350 400 450 500; do printf 'scan-%s,' $s; done | sed 's/,$//')
$PY benchmarks/window_ab.py --features gray,bitplanes --sets $HELD \
  --variant "crop=--intrinsics=$D/7scenes-colour-f525-k1-0.08-crop.txt" \
  --variant "full=--intrinsics=$D/7scenes-colour-f525-k1-0.08-full.txt" --json $D/held_calibrations.json
$PY benchmarks/window_ab.py --features gray,bitplanes --sets $HELD \
  --variant "c555=--intrinsics=$D/7scenes-colour-f555-k1-0.04.txt" --off-from $D/held_calibrations.json --json $D/held_c555.json
$PY benchmarks/window_ab.py --features gray,bitplanes --sets $HELD --variant "w5=window.size=5" \
  --variant "c555w5=--intrinsics=$D/7scenes-colour-f555-k1-0.04.txt;window.size=5" --off-from $D/held_calibrations.json \
  --json $D/held_c555_window.json
$PY benchmarks/window_ab.py --features gray-affine,rgb,lab --sets $HELD \
  --variant "c555=--intrinsics=$D/7scenes-colour-f555-k1-0.04.txt" --json $D/held_c555_more_features.json
$PY $D/table.py

# 4. where the short-length translation angle comes from (translation_anatomy.py), grey, window off:
#    the 11 held-back 7-Scenes runs at 585 (p…) and at (555, −0.04) (c…); start 200 from five random maps (r200_…)
H=$OUT/anatomy; mkdir -p $H
for s in 50 100 150 200 250 300 350 400 450 500 full; do
  if [ $s = full ]; then a="--start 350"; else a="--start $s --max-frames 160"; fi
  $PY -m dmtrack run $SEQ $a --out $H/p$s --no-pointcloud --no-depth-images --no-progress
  $PY -m dmtrack run $SEQ $a --intrinsics $D/7scenes-colour-f555-k1-0.04.txt --out $H/c$s --no-pointcloud --no-depth-images \
    --no-progress
done
for sd in 0 1 2 3 4; do
  $PY -m dmtrack run $SEQ --start 200 --max-frames 160 --init random --seed $sd --out $H/r200_$sd --no-pointcloud \
    --no-depth-images --no-progress
done
$PY $D/translation_anatomy.py $H/p{50,100,150,200,250,300,350,400,450,500,full} --json $D/translation_585.json
$PY $D/translation_anatomy.py $H/c{50,100,150,200,250,300,350,400,450,500,full} --json $D/translation_c555.json
$PY $D/translation_anatomy.py $H/r200_{0,1,2,3,4} $H/p200 --json $D/translation_start200.json

# 5. the calibration from corner tracks (dmtrack calibrate-from-video, its tracks method), chosen on 0–349 only.
#    Sections 5 and 6 run the same calibrations; section 5's files (selfcal/, the *-tracks-0-349.txt file and the
#    held_tracks*.json runs) came from the first tracker (KLT refinement, commit 47590dc): today's code gives
#    section 6's, so section 5 reproduces them only at that commit.
calibrations() {  # DIR: 7-Scenes 0–349 and 350–699 (f, f-k1), 0–349 from 525 (f-k1), Tsukuba (f-k1); JSON and files
  mkdir -p "$1"
  for m in f f-k1; do
    $PY -m dmtrack calibrate-from-video $SEQ --max-frames 350 --model $m --out "$1/c0-$m.txt" --json --quiet \
      > "$1/c0-$m.json"
    $PY -m dmtrack calibrate-from-video $SEQ --start 350 --model $m --out "$1/c350-$m.txt" --json --quiet \
      > "$1/c350-$m.json"
  done
  $PY -m dmtrack calibrate-from-video $SEQ --max-frames 350 --model f-k1 --intrinsics 525,525,320,240 \
    --out "$1/c0-f-k1-525.txt" --json --quiet > "$1/c0-f-k1-525.json"
  $PY -m dmtrack calibrate-from-video ../shared/data/tsukuba-150 --model f-k1 --intrinsics 676.5,676.5,320,240 \
    --out "$1/tsu-k1.txt" --json --quiet > "$1/tsu-k1.json"
}
calibrations "$OUT"
cp "$OUT"/c*.json "$OUT/tsu-k1.json" $D/selfcal/
cp "$OUT/c0-f-k1.txt" $D/7scenes-colour-tracks-0-349.txt
$PY benchmarks/window_ab.py --features gray,bitplanes --sets $HELD \
  --variant "tracks=--intrinsics=$D/7scenes-colour-tracks-0-349.txt" --off-from $D/held_calibrations.json \
  --json $D/held_tracks.json
$PY benchmarks/window_ab.py --features gray,bitplanes --sets $HELD \
  --variant "tracksw5=--intrinsics=$D/7scenes-colour-tracks-0-349.txt;window.size=5" \
  --off-from $D/held_calibrations.json --json $D/held_tracks_window.json
$PY benchmarks/window_ab.py --features gray-affine,rgb,lab --sets $HELD \
  --variant "tracks=--intrinsics=$D/7scenes-colour-tracks-0-349.txt" --off-from $D/held_c555_more_features.json \
  --json $D/held_tracks_more_features.json
for feat in gray bitplanes; do
  $PY -m dmtrack run $SEQ --feature $feat --intrinsics $D/7scenes-colour-tracks-0-349.txt --out "$OUT/full-$feat" \
    --no-pointcloud --no-depth-images --no-progress
done
$PY $D/table.py

# 6. the same with the tracks refined by an affine warp (the current tracker): calibrations, held-back runs, 0–699
calibrations "$OUT/affine"
cp "$OUT"/affine/*.json $D/selfcal-affine/
cp "$OUT/affine/c0-f-k1.txt" $D/7scenes-colour-tracks-affine-0-349.txt
$PY benchmarks/window_ab.py --features gray,bitplanes --sets $HELD \
  --variant "affine=--intrinsics=$D/7scenes-colour-tracks-affine-0-349.txt" \
  --variant "affinew5=--intrinsics=$D/7scenes-colour-tracks-affine-0-349.txt;window.size=5" \
  --off-from $D/held_calibrations.json --json $D/held_tracks_affine.json
$PY benchmarks/window_ab.py --features gray-affine,rgb,lab --sets $HELD \
  --variant "affine=--intrinsics=$D/7scenes-colour-tracks-affine-0-349.txt" \
  --off-from $D/held_c555_more_features.json --json $D/held_tracks_affine_more_features.json
for feat in gray bitplanes; do
  $PY -m dmtrack run $SEQ --feature $feat --intrinsics $D/7scenes-colour-tracks-affine-0-349.txt \
    --out "$OUT/fullA-$feat" --no-pointcloud --no-depth-images --no-progress
done
$PY $D/table.py

# 7. a start that waits for more parallax: chosen on starts 25, 75, …, 475, then the held-back runs
for p in 0.5 1.0 1.5; do
  for s in 25 75 125 175 225 275 325 375 425 475; do
    $PY -m dmtrack run $SEQ --start $s --max-frames 160 --set initializer.min_parallax_deg=$p --out "$OUT/par/s${s}_p$p" \
      --no-pointcloud --no-depth-images --no-progress
  done
done
$PY benchmarks/window_ab.py --features gray,bitplanes --sets held --variant "p10=initializer.min_parallax_deg=1.0" \
  --off-from benchmarks/studies/2026-11-28-window/held.json --json $D/held_parallax.json

# 8. the focal length the datasets' own ground-truth poses and the images agree on (calibrate-from-video --method
#    groundtruth: the poses fixed, only the corners' points and f, or f and k1, adjusted); each half on its own
TSU=../shared/data/tsukuba-150
mkdir -p "$OUT"
gt() {  # name, then calibrate-from-video's arguments
  local name=$1; shift
  $PY -m dmtrack calibrate-from-video "$@" --method groundtruth --out "$OUT/gt-$name.txt" --json --quiet \
    > "$OUT/gt-$name.json" || true
}
gt tsukuba "$TSU"
gt tsukuba-c320 "$TSU" --intrinsics 615,615,320,240
gt tsukuba-0-74 "$TSU" --max-frames 75
gt tsukuba-75-149 "$TSU" --start 75
for s in 0 350; do
  gt 7scenes-$s-f $SEQ --start $s --max-frames 350
  gt 7scenes-$s-f-k1 $SEQ --start $s --max-frames 350 --model f-k1
done
$PY - "$OUT" > $D/groundtruth_focal.json <<'PYEOF'
import json, sys
from pathlib import Path
out = {}
for p in sorted(Path(sys.argv[1]).glob("gt-*.json")):
    d = json.loads(p.read_text())
    last = d["history"][-1]
    out[p.stem[3:]] = {"f": round(d["fx"], 2), "k1": round(d["k1"], 4), "sigma": d["sigma"], "cx": d["cx"],
                       "cy": d["cy"], "converged": d["converged"], "median_error_px": round(last["median_error_px"], 3),
                       "corners": last["points"], "frames_used": last["keyframes"]}
print(json.dumps(out, indent=1))
PYEOF
$PY -m dmtrack calibrate-from-video $SEQ --method groundtruth --model f-k1 --max-frames 350 \
  --out $D/7scenes-colour-groundtruth-0-349.txt --quiet
HELD=7s-350-699,$(for s in 50 100 150 200 250 300 350 400 450 500; do printf 'scan-%s,' $s; done | sed 's/,$//')
$PY benchmarks/window_ab.py --features gray,bitplanes --sets 7s-0-349,$HELD --jobs 2 \
  --variant "gt=--intrinsics=$D/7scenes-colour-groundtruth-0-349.txt" \
  --variant "affine=--intrinsics=$D/7scenes-colour-tracks-affine-0-349.txt" \
  --off-from $D/held_tracks_affine.json --json $D/held_groundtruth_calibration.json
