#!/usr/bin/env bash
# Whole-process wall time, CPU time and peak memory of grey on 7-Scenes 0-699 (default outputs), window off and
# --window 5 (fixed) and 5 marginalised, interleaved rounds; nothing else running. Prints one JSON line per run.
set -euo pipefail
cd "$(dirname "$0")/../../.."
rounds=${1:-3}
for r in $(seq "$rounds"); do
  for v in off w5 m5; do
    case $v in off) a="";; w5) a="--window 5";; m5) a="--window 5 --set window.leave=marginalise";; esac
    /usr/bin/time -f "%e %U %S %M" -o /tmp/window-speed.time .venv/bin/dmtrack run ../shared/data/7scenes-0000-0699 \
      --feature gray $a --out out/window-speed-$v --no-progress >/dev/null 2>&1
    read -r wall user sys rss < /tmp/window-speed.time
    fps=$(.venv/bin/python -c "import json; print(json.load(open('out/window-speed-$v/metrics.json'))['fps'])")
    echo "{\"round\": $r, \"variant\": \"$v\", \"wall_s\": $wall, \"cpu_s\": $(echo "$user + $sys" | bc), \"peak_rss_mb\": $((rss / 1024)), \"fps\": $fps}"
  done
done
