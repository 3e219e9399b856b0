"""Orientation drift over time: when does a run's rotation error build up?

Usage::

    python benchmarks/orientation_drift.py GROUNDTRUTH TRAJECTORY... [--every 10] [--until 250] [--after 150]
                                           [--json FILE]

For every TUM trajectory (matched to the ground truth by timestamp), the drift at frame i is the angle between the
estimated and the true rotation of camera i relative to the first matched camera, angle((R_g0ᵀ R_gi)ᵀ (R_e0ᵀ R_ei))
in degrees: the rotation part of an origin-aligned APE, which no scale or translation error enters. Printed per
trajectory: the drift every ``--every`` frames up to ``--until``, the drift at 100 and 150, and the largest
drift *after* frame ``--after`` measured from that frame on (does a run that started badly keep drifting faster?).

It was written to see where the seed-to-seed spread of RPE on 7-Scenes comes from
(``benchmarks/studies/2026-11-27-seed-lottery/``). ``benchmarks/seed_study.py --trajectories`` writes the inputs.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from dmtrack.geometry.lie import rotation_angle
from dmtrack.io.association import associate_trajectories
from dmtrack.io.trajectory import read_tum


def drift_curve(gt_rot: np.ndarray, est_rot: np.ndarray, start: int = 0) -> np.ndarray:
    """Degrees of orientation drift of frames ``start…`` relative to frame ``start`` ((n, 3, 3) rotations each)."""
    rel_g = np.einsum("ji,njk->nik", gt_rot[start], gt_rot[start:])
    rel_e = np.einsum("ji,njk->nik", est_rot[start], est_rot[start:])
    return np.degrees(rotation_angle(np.einsum("nji,njk->nik", rel_g, rel_e)))


def matched(gt_path: str, est_path: str) -> tuple[np.ndarray, np.ndarray]:
    """Rotations of the ground truth and the estimate at their matched timestamps (within 1 ms, time order)."""
    gt, est = associate_trajectories(read_tum(gt_path), read_tum(est_path), max_diff=1e-3)
    if len(est.timestamps) == 0:
        raise SystemExit(f"{est_path}: no timestamp matches the ground truth {gt_path}")
    return gt.rotations, est.rotations


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("groundtruth")
    ap.add_argument("trajectories", nargs="+")
    ap.add_argument("--every", type=int, default=10)
    ap.add_argument("--until", type=int, default=250)
    ap.add_argument("--after", type=int, default=150)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    frames = list(range(a.every, a.until + 1, a.every))
    width = max(len(Path(p).stem) for p in a.trajectories)
    print(f"{'frame':<{width}} " + " ".join(f"{i:5d}" for i in frames) + "   @100   @150  after")
    out = {}
    for path in a.trajectories:
        g, e = matched(a.groundtruth, path)
        d = drift_curve(g, e)
        later = drift_curve(g, e, a.after) if len(d) > a.after else np.zeros(1)
        row = {
            "curve": {i: round(float(d[i]), 2) for i in frames if i < len(d)},
            "at_100": round(float(d[min(100, len(d) - 1)]), 2),
            "at_150": round(float(d[min(150, len(d) - 1)]), 2),
            f"max_after_{a.after}": round(float(later.max()), 2),
        }
        out[Path(path).stem] = row
        cells = " ".join(f"{row['curve'].get(i, float('nan')):5.1f}" for i in frames)
        print(f"{Path(path).stem:<{width}} {cells} {row['at_100']:6.1f} {row['at_150']:6.1f} "
              f"{row[f'max_after_{a.after}']:6.1f}")
    if a.json:
        Path(a.json).write_text(json.dumps(out, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
