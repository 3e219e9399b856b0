#!/usr/bin/env python3
"""Run DSO (run_dso.py) on the held-back slices and collect their metrics.json into one JSON list.

    python tools/dso_oracle/held.py --json tools/dso_oracle/results/held.json --runs /tmp/dso_held
    python tools/dso_oracle/held.py --json tools/dso_oracle/results/held_calibrated.json --runs /tmp/dso_held_cal \
        --intrinsics benchmarks/studies/2026-11-29-calibration/7scenes-colour-tracks-affine-0-349.txt --only-7scenes

Slices: 7-Scenes (``../shared/data/7scenes-0000-0699``) 160 frames from 50, 100, …, 500 and 350 frames from 350;
tsukuba-150 (all 150, ``--intrinsics 615,615,320,240``, r_l 1/20); KITTI 06 (all 51, r_l 1/20).  ``--intrinsics``
replaces the calibration of the 7-Scenes slices only.  Extra arguments after ``--`` go to every run_dso.py call.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
DATA = REPO.parent / "shared" / "data"


def slices(intrinsics: str | None, only_7scenes: bool) -> list[tuple[str, list[str]]]:
    seven = str(DATA / "7scenes-0000-0699")
    cal = ["--intrinsics", intrinsics] if intrinsics else []
    jobs = [(f"7scenes-{s}+160", [seven, "--start", str(s), "--frames", "160", *cal]) for s in range(50, 501, 50)]
    jobs.append(("7scenes-350+350", [seven, "--start", "350", "--frames", "350", *cal]))
    if not only_7scenes:
        jobs.append(("tsukuba-150", [str(DATA / "tsukuba-150"), "--intrinsics", "615,615,320,240", "--r-l", "1/20"]))
        jobs.append(("kitti-06", [str(DATA / "kitti-odometry"), "--r-l", "1/20"]))
    return jobs


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", required=True, type=Path, help="the list of metrics objects written here")
    ap.add_argument("--runs", required=True, type=Path, help="folder for the runs' output folders")
    ap.add_argument("--intrinsics", help="calibration for the 7-Scenes slices (default: the folder's own)")
    ap.add_argument("--only-7scenes", action="store_true")
    ap.add_argument("extra", nargs="*", help="after --: more run_dso.py arguments")
    args = ap.parse_args()
    results = []
    for name, run_args in slices(args.intrinsics, args.only_7scenes):
        out = args.runs / name
        cmd = [sys.executable, str(HERE / "run_dso.py"), *run_args, "--out", str(out), *args.extra]
        print(name, end=" ", flush=True)
        proc = subprocess.run(cmd, check=False, stderr=subprocess.PIPE, text=True)
        if (out / "metrics.json").exists():
            results.append({"slice": name, **json.loads((out / "metrics.json").read_text())})
        else:  # run_dso.py refused (e.g. --images original on a sequence that needs a crop)
            err = (proc.stderr.strip().splitlines() or ["?"])[-1]
            print(err)
            results.append({"slice": name, "error": err, "args": run_args + args.extra})
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=1) + "\n")
    seven = [r for r in results if r["slice"].startswith("7scenes") and r["rpe_rot_deg_per_m"] is not None]
    if seven:
        print(f"7-Scenes slices with a result: {len(seven)}; median RPE rot "
              f"{statistics.median(r['rpe_rot_deg_per_m'] for r in seven):.3f} deg/m, trans-angle "
              f"{statistics.median(r['rpe_trans_angle_deg_per_m'] for r in seven):.3f} deg/m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
