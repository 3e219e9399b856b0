"""The odometry's own photometric error over a grid of (focal length, k1) (study of 2026-11-29).

Usage (from the repository root)::

    python benchmarks/studies/2026-11-29-calibration/residual_grid.py SEQUENCE --out DIR [--focal 525,555,585]
        [--k1 -0.12,-0.08,-0.04,0] [--centre 320,240] [--size 640,480] [--max-frames 350] [--start 0]
        [--feature gray] [--jobs 2]

For each (f, k1) a calibration file (DSO's RadTan line, the images undistorted to the largest valid rectangle,
``crop``) is written into DIR and the whole odometry runs on the frames with it, one process each, one numba thread.
What it prints per candidate: the mean and median of the tracker's final error per tracked frame
(``FrameInfo.residual``: the mean weighted squared photometric residual of its last accepted step, grey levels²)
and, where the sequence has a ground truth, the run's RPE. Images only: the error needs no ground truth, so the
candidate of least error is an estimate of the calibration from the images themselves. Its limits are in README.md
(it is not a fixed principle: on a rendered sequence it falls steadily with f).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[3]


def calibration_file(path: Path, f: float, k1: float, cx: float, cy: float, w: int, h: int) -> Path:
    """DSO's calibration file: RadTan (k2 = p1 = p2 = 0), undistorted to the largest valid rectangle of w × h."""
    path.write_text(f"RadTan {f:g} {f:g} {cx:g} {cy:g} {k1:g} 0 0 0\n{w} {h}\ncrop\n{w} {h}\n")
    return path


def _child(args: list[str]) -> dict:
    """In a child process: track with a sink that keeps each frame's final error; print one JSON line."""
    sys.path.insert(0, str(REPO / "src"))
    from dmtrack.pipeline import track

    class Errors:
        def __init__(self) -> None:
            self.values: list[float] = []

        def on_frame(self, *a) -> None: ...

        def on_keyframe(self, *a) -> None: ...

        def on_lost(self, *a) -> None: ...

        def close(self) -> None: ...

        def on_frame_info(self, info) -> None:
            if info.tracked and np.isfinite(info.residual):
                self.values.append(float(info.residual))

    sequence, feature, calib, start, frames = args
    sink = Errors()
    result = track(sequence, feature, intrinsics=calib, start=int(start),
                   max_frames=None if frames == "all" else int(frames), sink=sink)  # fmt: skip
    m = result.metrics
    v = np.array(sink.values)
    return {"residual_mean": float(v.mean()) if v.size else None, "residual_median": float(np.median(v)) if v.size
            else None, "tracked": result.tracked_frames, "frames": result.total_frames,
            "rpe_rot": m.get("rpe_rot_deg_per_m"), "rpe_trans": m.get("rpe_trans_angle_deg_per_m")}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--focal", default="525,555,585")
    ap.add_argument("--k1", default="-0.12,-0.08,-0.04,0")
    ap.add_argument("--centre", default="320,240")
    ap.add_argument("--size", default="640,480")
    ap.add_argument("--start", type=int, default=0)
    ap.add_argument("--max-frames", default="350")
    ap.add_argument("--feature", default="gray")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--child", nargs=5, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        print(json.dumps(_child(a.child)))
        return
    a.out.mkdir(parents=True, exist_ok=True)
    cx, cy = (float(v) for v in a.centre.split(","))
    w, h = (int(v) for v in a.size.split(","))
    grid = [(float(f), float(k)) for f in a.focal.split(",") for k in a.k1.split(",")]
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}

    def one(fk: tuple[float, float]) -> dict:
        f, k1 = fk
        calib = calibration_file(a.out / f"calib_f{f:g}_k{k1:g}.txt", f, k1, cx, cy, w, h)
        p = subprocess.run([sys.executable, __file__, a.sequence, "--out", str(a.out), "--child", a.sequence,
                            a.feature, str(calib), str(a.start), str(a.max_frames)],
                           env=env, capture_output=True, text=True, check=False)  # fmt: skip
        row = {"f": f, "k1": k1, "rc": p.returncode}
        if p.returncode == 0:
            row.update(json.loads(p.stdout.strip().splitlines()[-1]))
        else:
            row["error"] = p.stderr[-300:]
        print(json.dumps(row), flush=True)
        return row

    with ThreadPoolExecutor(a.jobs) as pool:
        rows = list(pool.map(one, grid))
    (a.out / "grid.json").write_text(json.dumps(rows, indent=1))
    ok = [r for r in rows if r.get("residual_mean") is not None]
    if ok:
        best = min(ok, key=lambda r: r["residual_mean"])
        print(f"least mean error: f={best['f']:g} k1={best['k1']:+g} ({best['residual_mean']:.3f})")


if __name__ == "__main__":
    main()
