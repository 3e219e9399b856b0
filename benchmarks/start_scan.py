"""The start's own lottery: one configuration from many start frames of a sequence, 160 frames each.

Usage::

    python benchmarks/start_scan.py SEQUENCE [--starts 0,50,...,500] [--frames 160] [--seeds 0]
        [--set init=random ...] [--json FILE]

For every (start frame, seed) the run's orientation drift at its frames 100 and 150 (``orientation_drift.py``:
the angle between the estimated and the true rotation relative to the run's first frame, no scale in it) and its
RPE over its frames. A random start is a lottery over seeds; a geometric start does not depend on the seed but on the
frames it starts from, so spreading the start over a recording is how its luck is measured (and every start frame
but 0 is a frame nobody tuned on). One process per run, one numba thread, two at a time.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))


def _run(job: tuple) -> dict:
    sequence, start, seed, frames, overrides = job
    os.environ["NUMBA_NUM_THREADS"] = "1"
    warnings.simplefilter("ignore")
    from orientation_drift import drift_curve

    import dmtrack
    from dmtrack.io.association import associate_trajectories
    from dmtrack.odometry.config import VOConfig

    r = dmtrack.track(sequence, config=VOConfig().with_overrides(*overrides), start=start, max_frames=frames,
                      seed=seed)
    gt, est = associate_trajectories(r.groundtruth, r.trajectory, max_diff=1e-3)
    d = drift_curve(gt.rotations, est.rotations)
    m = r.metrics
    return {"start": start, "seed": seed, "tracked": m["tracked_frames"], "init": m["init"],
            "accepted_at": m.get("init_accepted_frame"), "refused": m.get("init_refused"),
            "drift_100": round(float(d[min(100, len(d) - 1)]), 3),
            "drift_150": round(float(d[min(150, len(d) - 1)]), 3),
            "rpe_rot": m["rpe_rot_deg_per_m"], "rpe_trans_angle": m["rpe_trans_angle_deg_per_m"]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence")
    ap.add_argument("--starts", default=",".join(str(s) for s in range(0, 501, 50)))
    ap.add_argument("--frames", type=int, default=160)
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    jobs = [(a.sequence, int(st), int(s), a.frames, tuple(a.set)) for st in a.starts.split(",")
            for s in a.seeds.split(",")]
    with ProcessPoolExecutor(2) as pool:
        rows = list(pool.map(_run, jobs))
    for r in rows:
        start = f"refused ({r['refused']})" if r["refused"] else (f"accepted at {r['accepted_at']}"
                                                                    if r["accepted_at"] is not None else r["init"])
        print(f"start {r['start']:4d} seed {r['seed']}: {r['tracked']} tracked, {start}; "
              f"drift@100 {r['drift_100']:6.2f}° @150 {r['drift_150']:6.2f}°  "
              f"RPE rot {r['rpe_rot']:.3f} trans-angle {r['rpe_trans_angle']:.2f}")
    summary = {}
    for k in ("drift_100", "drift_150", "rpe_rot", "rpe_trans_angle"):
        v = [r[k] for r in rows]
        summary[k] = {"median": round(statistics.median(v), 3), "min": round(min(v), 3), "max": round(max(v), 3)}
        print(f"{k:>16}: median {summary[k]['median']:.3f}  range {summary[k]['min']:.3f}–{summary[k]['max']:.3f}")
    if a.json:
        Path(a.json).write_text(json.dumps({"command": sys.argv, "rows": rows, "summary": summary}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
