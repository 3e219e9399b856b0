#!/bin/bash
# How the study's runs were made (2026-11-29, issue 38). From the repository root, with tools/dso_oracle built
# (tools/dso_oracle/build.sh) and ../shared beside it. Each run is one folder KIND-CAL-START-FRAMES under $RUNS.
set -euo pipefail
RUNS=${RUNS:-/tmp/common-error}
SEQ=../shared/data/7scenes-0000-0699
V2=benchmarks/studies/2026-11-29-calibration/7scenes-colour-tracks-affine-0-349.txt  # the images' own, made on 0-349
mkdir -p "$RUNS"

one() {  # KIND CAL START FRAMES [CALFILE]
  local K=$1 C=$2 S=$3 N=$4 F=${5:-} O="$RUNS/$1-$2-$3-$4" A=""
  [ -f "$O/done" ] && return 0
  rm -rf "$O"
  [ -n "$F" ] && A="--intrinsics $F"
  if [ "$K" = dso ]; then
    [ -n "$F" ] && A="$A --rectify dmtrack"  # DSO gets the frames dmtrack rectified, with their pinhole camera
    .venv/bin/python tools/dso_oracle/run_dso.py $SEQ --start "$S" --frames "$N" $A --out "$O" > "$O.log" 2>&1
  else
    case $K in
      gray) X="--feature gray";; bitplanes) X="--feature bitplanes";;
      grayw5) X="--feature gray --window 5";; bitplanesw5) X="--feature bitplanes --window 5";;
      grayl0) X="--feature gray --set tracker.levels=[4,3,2,1,0]";;
      grayw5m) X="--feature gray --window 5 --set window.leave=marginalise";;
      grayw7) X="--feature gray --window 7";;
      grayw7m) X="--feature gray --window 7 --set window.leave=marginalise";;
      grayw7mk07|grayw7mk10) X="--feature gray --window 7 --set window.leave=marginalise --set keyframe.threshold=0.${K#grayw7mk}";;
      grayk10) X="--feature gray --set keyframe.threshold=0.10";;
      grayw7mL0) X="--feature gray --window 7 --set window.leave=marginalise --set window.levels=[2,1,0]";;
      grayw7mP2) X="--feature gray --window 7 --set window.leave=marginalise --set window.points=2000";;
      grayw7mDP01) X="--feature gray --window 7 --set window.leave=marginalise --set window.depth_prior=0.1";;
      grayw7mI12) X="--feature gray --window 7 --set window.leave=marginalise --set window.iterations=12";;
    esac
    .venv/bin/dmtrack run $SEQ --start "$S" --max-frames "$N" $X $A --out "$O" > "$O.log" 2>&1
  fi
  touch "$O/done"
}

HELD="50:160 100:160 150:160 200:160 250:160 300:160 350:160 400:160 450:160 500:160 350:350"
CHOSEN="0:350 25:160 75:160 125:160 175:160 225:160 275:160 325:160 375:160 425:160 475:160"
for r in $HELD $CHOSEN; do
  S=${r%:*}; N=${r#*:}
  for K in dso gray bitplanes grayw5 bitplanesw5; do
    one $K 585 "$S" "$N"
    one $K v2 "$S" "$N" "$V2"
  done
  # each run calibrated from its own frames (no other frame involved), then every method with that file
  CAL="$RUNS/selfcal-$S-$N.txt"
  [ -f "$CAL" ] || .venv/bin/dmtrack calibrate-from-video $SEQ --start "$S" --max-frames "$N" --model f-k1 --quiet \
      --json --out "$CAL" > "$RUNS/selfcal-$S-$N.json"
  for K in dso gray bitplanes grayw5 bitplanesw5; do one $K self "$S" "$N" "$CAL"; done
done
# tracking down to level 0, with the images' calibration: on the chosen-on runs only (it did not go further)
for r in $CHOSEN; do one grayl0 v2 "${r%:*}" "${r#*:}" "$V2"; done
# the window's size and how keyframes leave it: chosen on with v2 (all four), then the two marginalising ones held back
for r in $CHOSEN; do
  for K in grayw5 grayw5m grayw7 grayw7m; do one $K v2 "${r%:*}" "${r#*:}" "$V2"; done
  for K in grayw5m grayw7m; do one $K 585 "${r%:*}" "${r#*:}"; done
done
for r in $HELD; do for K in grayw5m grayw7m; do one $K 585 "${r%:*}" "${r#*:}"; one $K v2 "${r%:*}" "${r#*:}" "$V2"; done; done
# more keyframes (keyframe.threshold 0.14 → 0.10, 0.07): chosen on with v2; 0.07 with the window of 7 then held back
for r in $CHOSEN; do for K in grayk10 grayw7mk10 grayw7mk07; do one $K v2 "${r%:*}" "${r#*:}" "$V2"; done; done
for r in $CHOSEN; do one grayw7mk07 585 "${r%:*}" "${r#*:}"; done
for r in $HELD; do one grayw7mk07 585 "${r%:*}" "${r#*:}"; one grayw7mk07 v2 "${r%:*}" "${r#*:}" "$V2"; done
# the window of 7 marginalised down to level 0, or with 2,000 points a keyframe: chosen on with v2 only
for r in $CHOSEN; do for K in grayw7mL0 grayw7mP2; do one $K v2 "${r%:*}" "${r#*:}" "$V2"; done; done
# a tenth of the depth prior, or 12 iterations: chosen on with v2; the depth prior then held back and at 585
for r in $CHOSEN; do for K in grayw7mDP01 grayw7mI12; do one $K v2 "${r%:*}" "${r#*:}" "$V2"; done; done
for r in $CHOSEN; do one grayw7mDP01 585 "${r%:*}" "${r#*:}"; done
for r in $HELD; do one grayw7mDP01 585 "${r%:*}" "${r#*:}"; one grayw7mDP01 v2 "${r%:*}" "${r#*:}" "$V2"; done

D=benchmarks/studies/2026-11-29-common-error
.venv/bin/python $D/table.py "$RUNS" $D/results.json > $D/results.txt
.venv/bin/python $D/extras.py "$RUNS" $D/extras.json > /dev/null
for f in "$RUNS"/selfcal-*.txt; do echo "$(basename "$f" .txt) $(head -1 "$f")"; done > $D/selfcal.txt
