"""Accuracy of two source trees of dmtrack on the same runs (``dmtrack run``), side by side.

Usage::

    python benchmarks/ab_accuracy.py --a /path/to/old/src --b src [--features gray,bitplanes] [--out FILE.json]
                                     [--runs 7s-0-699,7s-0-349,7s-350-699,kitti06,tsukuba]

Each (run, feature) is tracked by tree A and by tree B, one process each (``PYTHONPATH`` = the tree, its own numba
cache), with dmtrack's defaults (the geometric start; ``--init random --seed S`` with ``--init random``). Reported:
RPE rotation and translation angle, ATE RMSE, tracked frames, the start's accepted frame. The splits are the ones
the project chooses and shows on: 7-Scenes 0–349 against 350–699, KITTI 06 and Tsukuba (the shared data).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
RUNS = {
    "7s-0-699": [str(SHARED / "7scenes-0000-0699")],
    "7s-0-349": [str(SHARED / "7scenes-0000-0699"), "--max-frames", "350"],
    "7s-350-699": [str(SHARED / "7scenes-0000-0699"), "--start", "350"],
    "kitti06": [str(SHARED / "kitti-odometry" / "sequences" / "06")],
    "tsukuba": [str(SHARED / "tsukuba-150"), "--intrinsics", "615,615,320,240"],
}
KEYS = ("rpe_rot_deg_per_m", "rpe_trans_angle_deg_per_m", "ate_rmse", "tracked_frames", "total_frames",
        "init_accepted_frame")  # fmt: skip


def _run(src: Path, cache: Path, args: list[str], feature: str, extra: list[str], out: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
    env.update(PYTHONPATH=str(src), NUMBA_CACHE_DIR=str(cache))
    cmd = [sys.executable, "-m", "dmtrack.cli", "run", *args, "--feature", feature, "--out", str(out), "--no-progress",
           "--no-pointcloud", "--no-depth-images", *extra]  # fmt: skip
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if proc.returncode != 0 and not (out / "metrics.json").exists():
        return {"error": proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else f"exit {proc.returncode}"}
    m = json.loads((out / "metrics.json").read_text())
    return {k: m.get(k) for k in KEYS}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--a", required=True, type=Path)
    ap.add_argument("--b", required=True, type=Path)
    ap.add_argument("--features", default="gray,bitplanes")
    ap.add_argument("--runs", default=",".join(RUNS))
    ap.add_argument("--extra", default="", help="more arguments of dmtrack run, e.g. '--init random --seed 0'")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="dmtrack-abacc-"))
    trees = {"A": args.a.resolve(), "B": args.b.resolve()}
    rows = []
    for run in args.runs.split(","):
        for feature in args.features.split(","):
            row = {"run": run, "feature": feature}
            for k, src in trees.items():
                out = work / f"{k}-{run}-{feature}"
                row[k] = _run(src, work / f"cache-{k}", RUNS[run], feature, args.extra.split(), out)
            rows.append(row)
            a, b = row["A"], row["B"]
            fmt = lambda m: ("error: " + m["error"]) if "error" in m else (  # noqa: E731
                f"{m['rpe_rot_deg_per_m']:.3f} / {m['rpe_trans_angle_deg_per_m']:.2f} °/m, ATE {m['ate_rmse']:.4f}, "
                f"{m['tracked_frames']}/{m['total_frames']}, start {m['init_accepted_frame']}")
            print(f"{run:11s} {feature:10s} A {fmt(a)} | B {fmt(b)}", flush=True)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"trees": {k: str(v) for k, v in trees.items()}, "extra": args.extra,
                                        "rows": rows}, indent=1) + "\n")  # fmt: skip


if __name__ == "__main__":
    main()
