"""Where a run's RPE comes from: the paper's errors per length in degrees, and pairs on one keyframe against pairs
across keyframes.

Usage::

    python benchmarks/rpe_anatomy.py RUN_DIR [RUN_DIR ...] [--r-l 0.3333] [--json]

``RUN_DIR`` is a ``dmtrack run`` output folder (``groundtruth.txt``, ``trajectory.txt``, ``keyframes.txt``). The
paper's RPE (conventions.md) is the mean over the lengths L_k = k/8 · r_l · path of the mean error divided by L_k;
divided by L_k, the shortest length weighs eight times the longest. This prints, per length, the mean rotation and
translation-angle error in degrees (not per metre) and, at the shortest length, the translation-angle error of pairs
whose two frames were tracked on the same keyframe against pairs that straddle a keyframe change (a frame is tracked
on the newest keyframe made at or before it).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

from dmtrack.evaluation.metrics import _relative, _vector_angle_deg, rpe_pairs, rpe_paper  # noqa: E402
from dmtrack.io.trajectory import read_tum  # noqa: E402


def anatomy(run: Path, r_l: float = 1.0 / 3.0) -> dict:
    """The paper's RPE of one run folder per length in degrees (the metric's own per-length means times L_k) and, at
    the shortest length, the translation angle of pairs on one keyframe against pairs across keyframes (the
    metric's own relative poses and angles)."""
    gt, est = read_tum(run / "groundtruth.txt"), read_tum(run / "trajectory.txt")
    if len(gt.timestamps) != len(est.timestamps):
        raise SystemExit(f"{run}: {len(gt.timestamps)} ground-truth poses against {len(est.timestamps)} estimated")
    rpe = rpe_paper(gt, est, r_l)
    out: dict = {"run": str(run), "lengths": [
        {"L": float(L), "pairs": int(n), "rot_deg": float(r * L), "trans_angle_deg": float(t * L)}
        for L, n, r, t in zip(rpe.lengths, rpe.pairs_per_length, rpe.per_length_rot, rpe.per_length_trans,
                              strict=True)]}  # fmt: skip
    kf_path = run / "keyframes.txt"
    if kf_path.exists():
        kf = read_tum(kf_path)
        ref = np.searchsorted(kf.timestamps, est.timestamps + 1e-9, side="right") - 1
        L, i, j = rpe_pairs(gt, r_l)[0]
        trans, _ = _vector_angle_deg(_relative(gt.poses, i, j)[1], _relative(est.poses, i, j)[1])
        same = ref[i] == ref[j]
        out["shortest"] = {"L": L, "same_keyframe": {"pairs": int(same.sum()), "trans_angle_deg": _mean(trans[same])},
                           "across_keyframes": {"pairs": int((~same).sum()),
                                                "trans_angle_deg": _mean(trans[~same])}}  # fmt: skip
    return out


def _mean(x: np.ndarray) -> float | None:
    return float(np.mean(x)) if x.size else None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--r-l", type=float, default=1.0 / 3.0, help="r_l of the lengths (1/20 for KITTI and Tsukuba)")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    for run in a.runs:
        res = anatomy(run, a.r_l)
        if a.json:
            print(json.dumps(res))
            continue
        print(run)
        for row in res["lengths"]:
            print(f"  L {row['L']:.3f}: rotation {row['rot_deg']:.2f}°, translation angle {row['trans_angle_deg']:.1f}°"
                  f"  ({row['pairs']} pairs)")
        s = res.get("shortest")
        if s:
            one, across = s["same_keyframe"], s["across_keyframes"]
            print(f"  at L {s['L']:.3f}, translation angle: one keyframe {one['trans_angle_deg']:.1f}° "
                  f"({one['pairs']} pairs), across keyframes {across['trans_angle_deg']:.1f}° "
                  f"({across['pairs']} pairs)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
