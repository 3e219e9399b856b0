#!/bin/bash
# Alternating runs of 60 frames of the shared 7-Scenes, grey: metrics.json startup (import_s run_s warmup_s start_s first_frame_s).
# base: a git worktree of b37b056 in /tmp/base (no bytecode: PYTHONDONTWRITEBYTECODE=1); base_pyc: the same in /tmp/base2 with
# `python -m compileall`; new_nopyc: a copy of the new src/ without bytecode; new: this tree after `dmtrack warmup`.
SEQ=/work/shared/data/7scenes-0000-0699
PY=/work/main/.venv/bin/python
run() { # name, src
  rm -rf /tmp/abff
  (cd /tmp && PYTHONPATH=$2 $PY -m dmtrack run $SEQ --feature gray --max-frames 60 --out /tmp/abff >/dev/null 2>&1)
  python3 -c "import json;m=json.load(open('/tmp/abff/metrics.json'));s=m['startup'];print('$1', s['import_s'], s['run_s'], s['warmup_s'], s['start_s'], s['first_frame_s'], sep='\t')"
}
for r in $(seq 1 ${1:-6}); do
  run base /tmp/base/src
  run base_pyc /tmp/base2/src
  run new_nopyc /tmp/newnp/src
  run new /work/main/src
done
