"""Three checks on the held-back runs of ``run.sh``: the rotation gain (per camera axis, the slope of the estimate's
turn on the ground truth's over 15 frames) of DSO and dmtrack for each calibration; the RPE on the keyframes alone
against all frames (is the difference to DSO in the frames tracked between keyframes?); and the rotation error over
k frames (median over the pairs (i, i + k), then over the ten 160-frame runs; the frames both methods posed): scatter
from frame to frame against drift.

Usage: extras.py RUNS_DIR OUT.json
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from dmtrack.evaluation.metrics import _relative, _rotation_angle_rad, rotation_gain, rpe_paper
from dmtrack.io.association import associate_trajectories
from dmtrack.io.trajectory import Trajectory, read_trajectory

sys.path.insert(0, str(Path(__file__).parent))
from three_way import common_frames  # noqa: E402

HELD = [(s, 160) for s in range(50, 501, 50)] + [(350, 350)]
FRAMES_APART = (1, 3, 10, 30, 60, 100)


def _sub(t: Trajectory, keep: np.ndarray) -> Trajectory:
    return Trajectory(t.timestamps[keep], t.poses[keep])


def main(runs: Path, out: Path) -> None:
    result: dict = {"rotation_gain_median_xyz": {}, "keyframes_only_median": {}, "rotation_error_deg_by_frames": {}}
    for cal in ("585", "v2", "self"):
        for kind in ("dso", "gray", "grayw5", "bitplanes"):
            gains = []
            for s, n in HELD:
                gt = read_trajectory(runs / f"gray-{cal}-{s}-{n}" / "groundtruth.txt")
                g, a = associate_trajectories(gt, read_trajectory(runs / f"{kind}-{cal}-{s}-{n}" / "trajectory.txt"),
                                              max_diff=0.01)  # fmt: skip
                gains.append(rotation_gain(g, a).gain)
            result["rotation_gain_median_xyz"][f"{cal} {kind}"] = np.nanmedian(np.array(gains), 0).tolist()
        for kind in ("gray", "grayw5", "bitplanes"):
            rows = []
            for s, n in HELD:
                d, o = runs / f"{kind}-{cal}-{s}-{n}", runs / f"dso-{cal}-{s}-{n}"
                g, a, b = common_frames(*(read_trajectory(p) for p in (d / "groundtruth.txt", d / "trajectory.txt",
                                                                        o / "trajectory.txt")), f"{s}+{n}")  # fmt: skip
                kf = np.loadtxt(d / "keyframes.txt", ndmin=2)[:, 0]
                keep = np.isin(np.round(a.timestamps, 4), np.round(kf, 4))
                r = [rpe_paper(g, x) for x in (a, b)] + [rpe_paper(_sub(g, keep), _sub(x, keep)) for x in (a, b)]
                rows.append([x.rot_deg_per_unit for x in r] + [x.trans_angle_deg_per_unit for x in r])
            m = np.median(np.array(rows), 0)
            result["keyframes_only_median"][f"{cal} {kind}"] = {
                "all_frames": {"dmtrack": m[[0, 4]].tolist(), "dso": m[[1, 5]].tolist()},
                "keyframes": {"dmtrack": m[[2, 6]].tolist(), "dso": m[[3, 7]].tolist()},
            }
        for kind in ("dso", "gray", "grayw5", "bitplanes"):
            by_k: dict[int, list[float]] = {k: [] for k in FRAMES_APART}
            for s, n in HELD[:-1]:
                ref = runs / f"gray-{cal}-{s}-{n}"
                e = read_trajectory(runs / f"{kind}-{cal}-{s}-{n}" / "trajectory.txt")
                for other in (runs / f"dso-{cal}-{s}-{n}", ref):  # the frames both methods posed
                    _, e = associate_trajectories(read_trajectory(other / "trajectory.txt"), e, max_diff=0.01)
                g, e = associate_trajectories(read_trajectory(ref / "groundtruth.txt"), e, max_diff=0.01)
                for k in FRAMES_APART:
                    i = np.arange(len(g) - k)
                    Rg, _ = _relative(g.poses, i, i + k)
                    Re, _ = _relative(e.poses, i, i + k)
                    by_k[k].append(float(np.median(np.degrees(_rotation_angle_rad(np.swapaxes(Rg, -1, -2) @ Re)))))
            result["rotation_error_deg_by_frames"][f"{cal} {kind}"] = {k: float(np.median(v)) for k, v in by_k.items()}
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
