"""The start on every kind of motion (issue 37): grey runs from many start frames of every shared sequence and of a
rendered forward-driving one; when each start was accepted, whether it fell back to a random map, and the accuracy.

Usage::

    python benchmarks/start_everywhere.py [--src SRC] [--set initializer.essential=magsac ...] [--json FILE]
                                          [--cases kitti,tsukuba,7scenes,forward] [--workers 2]

The cases (the issue's):

* ``kitti``: the shared KITTI 06 (51 frames, forward driving at 10 Hz) from frames 0, 5, …, 30, to its end;
* ``tsukuba``: the shared New Tsukuba (150 frames, fast hand-held) from 0, 25, …, 100, to its end;
* ``7scenes``: the shared 7-Scenes 0–699 from 0, 50, …, 500, each for 200 frames;
* ``7scenes-long`` (not in the default set): from 0, 50, …, 350, each for 350 frames (what a start leaves to the
  drift of a longer run);
* ``forward``: ``synthetic:motion=forward,fps=10`` at 3 m/s (70 frames) and 6 m/s (40 frames) down a 5 m wide hall
  (seeds 3 and 7; a car's camera at that scale: the first frame's corners leave the image within ten frames), from
  frames 0 and 10.

Every run is ``dmtrack.track(..., feature="gray")`` with the default start (``init=geometric``) in its own process
(``--src``: the ``PYTHONPATH`` of another tree, to compare), and reports the start's reference and accepted frame
(relative to the run's first), a refusal and its fallback, the tracked frames and RPE / ATE against the ground truth.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
FWD = "synthetic:motion=forward,fps=10,width=640,height=480"
CASES: dict[str, list[tuple[str, dict, int, int | None]]] = {  # (sequence, options, start, max_frames)
    "kitti": [(str(SHARED / "kitti-odometry" / "sequences" / "06"), {}, s, None) for s in range(0, 31, 5)],
    "tsukuba": [(str(SHARED / "tsukuba-150"), {"intrinsics": "615,615,320,240"}, s, None) for s in range(0, 101, 25)],
    "7scenes": [(str(SHARED / "7scenes-0000-0699"), {}, s, 200) for s in range(0, 501, 50)],
    "7scenes-long": [(str(SHARED / "7scenes-0000-0699"), {}, s, 350) for s in range(0, 351, 50)],
    "forward": [(f"{FWD},speed={v},n_frames={n},seed={seed}", {}, s, None)
                for v, n in ((3, 70), (6, 40)) for seed in (3, 7) for s in (0, 10)],  # fmt: skip
}

_RUN = """
import json, sys, warnings
warnings.simplefilter("ignore")
import dmtrack
from dmtrack.odometry.config import VOConfig
seq, opts, start, frames, sets = json.loads(sys.argv[1])
r = dmtrack.track(seq, "gray", VOConfig().with_overrides(*sets), start=start, max_frames=frames, **opts)
m = r.metrics
info = m.get("init_info") or {}
print(json.dumps({k: m.get(k) for k in ("total_frames", "tracked_frames", "init_accepted_frame", "init_refused",
                  "init_fallback", "rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "ate_rmse", "lost_at",
                  "before_start")} | {"reference": info.get("reference_frame"), "redetected": info.get("redetected")}))
"""


def _one(job: tuple, src: str | None) -> dict:
    seq, opts, start, frames, sets = job
    env = dict(os.environ)
    if src:
        env["PYTHONPATH"] = src
    env["NUMBA_NUM_THREADS"] = "1"
    proc = subprocess.run([sys.executable, "-c", _RUN, json.dumps([seq, opts, start, frames, list(sets)])],
                          capture_output=True, text=True, env=env)  # fmt: skip
    if proc.returncode != 0:
        return {"sequence": seq, "start": start, "error": (proc.stderr.strip().splitlines() or ["?"])[-1]}
    return {"sequence": seq, "start": start, **json.loads(proc.stdout.strip().splitlines()[-1])}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--src", default=None, help="PYTHONPATH of the tree to run (default: the installed dmtrack)")
    ap.add_argument("--set", action="append", default=[], help="VOConfig override (repeatable)")
    ap.add_argument("--cases", default="kitti,tsukuba,7scenes,forward")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    jobs = [(seq, opts, start, frames, tuple(a.set))
            for c in a.cases.split(",") for seq, opts, start, frames in CASES[c]]  # fmt: skip
    with ThreadPoolExecutor(a.workers) as pool:
        rows = list(pool.map(lambda j: _one(j, a.src), jobs))
    accepted_within = []
    for r in rows:
        name = Path(r["sequence"]).name if not r["sequence"].startswith("synthetic") else r["sequence"].split(",", 1)[1]
        if "error" in r:
            print(f"{name:45s} start {r['start']:4d}: error {r['error']}")
            continue
        acc = r["init_accepted_frame"]
        rel = None if acc is None else acc - r["start"]
        accepted_within.append(rel)
        start = f"accepted at +{rel}" if acc is not None else f"REFUSED ({r['init_refused']})"
        if r.get("reference") is not None and r["reference"] != r["start"]:
            start += f" (reference +{r['reference'] - r['start']})"
        print(f"{name:45s} start {r['start']:4d}: {start:28s} tracked {r['tracked_frames']}/{r['total_frames']}  "
              f"RPE {r['rpe_rot_deg_per_m']:.3f} / {r['rpe_trans_angle_deg_per_m']:.2f}  ATE {r['ate_rmse']:.4f}",
              flush=True)  # fmt: skip
    ok = [x for x in accepted_within if x is not None]
    print(f"accepted {len(ok)}/{len(accepted_within)}, within 25 frames: {sum(x <= 25 for x in ok)}, "
          f"latest +{max(ok) if ok else '-'}; median RPE rot "
          f"{statistics.median(r['rpe_rot_deg_per_m'] for r in rows if 'error' not in r):.3f}")
    if a.json:
        Path(a.json).write_text(json.dumps({"command": sys.argv, "set": a.set, "src": a.src, "rows": rows}, indent=1)
                                + "\n")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
