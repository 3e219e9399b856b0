"""Oracle (2026-11-29): frames tracked again on the *next* keyframe's final map, and the mean of both placements.

Usage: ``python benchmarks/studies/2026-11-29-calibration/next_keyframe_oracle.py OUT_DIR SEQUENCE [run options]``
(from the repository root). It uses the hooks of ``../2026-11-28-window/retrack_oracle.py`` (every frame's pyramid,
its keyframe and its tracked pose on it, each keyframe's final depth as emitted). Each frame whose keyframe has a
successor is tracked against that successor's final map, from the pose the run gave it, and placed by the successor's
final pose; the RPE of that trajectory and of the mean of both placements (rotations halfway, positions averaged) is
printed. Measured (grey): 7-Scenes 0-349 5.163 / 30.29 -> on the next keyframe 5.166 / 30.34, mean 5.164 / 30.29;
start 200 (160 frames) 7.897 / 82.52 -> 7.899 / 82.58, mean 7.896 / 82.54.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "2026-11-28-window"))

import retrack_oracle as ro  # noqa: E402

import dmtrack.odometry.vo as vom  # noqa: E402
from dmtrack.cli import main  # noqa: E402
from dmtrack.evaluation.metrics import rpe_paper  # noqa: E402
from dmtrack.geometry.exact import matmul  # noqa: E402
from dmtrack.io.trajectory import Trajectory, read_tum  # noqa: E402
from dmtrack.odometry.records import _inv_se3, _se3_part, _sim3  # noqa: E402
from dmtrack.odometry.tracker import TrackingReference  # noqa: E402


def _halfway(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([A[:3, :3], B[:3, :3]])))([0.5]).as_matrix()[0]
    T[:3, 3] = 0.5 * (A[:3, 3] + B[:3, 3])
    return T


def run() -> None:
    vom.build_frame = ro._keep_frame
    vom.VisualOdometry._record_pose = ro._keep_pose
    vom.VisualOdometry._emit_keyframe = ro._keep_keyframe
    out, args = sys.argv[1], sys.argv[2:]
    try:
        main(["run", *args, "--out", out, "--no-progress", "--no-pointcloud", "--no-depth-images"])
    except SystemExit:
        pass
    vo = ro.ODOMETRIES[-1]
    gt, est = read_tum(f"{out}/groundtruth.txt"), read_tum(f"{out}/trajectory.txt")
    refs: dict = {}
    on_next, mean = [], []
    for index, _, kf_id, T_fk in ro.REFS:
        kf, snap = ro.FINAL[kf_id]
        T_wf = _se3_part(matmul(_sim3(snap.T_wc, snap.scale), _inv_se3(np.eye(4) if T_fk is None else T_fk)),
                         snap.scale)  # fmt: skip
        placed = T_wf
        nxt = ro.FINAL.get(kf_id + 1)
        if T_fk is not None and nxt is not None and index not in (kf.index, nxt[0].index):
            kf2, snap2 = nxt
            if kf_id + 1 not in refs:
                refs[kf_id + 1] = TrackingReference.from_keyframe(kf2, snap2.idepth, snap2.idepth_var, vo._levels,
                                                                  vo.use_numba)  # fmt: skip
            start = matmul(_inv_se3(T_wf), snap2.T_wc)  # the next keyframe -> this frame, world units
            start[:3, 3] /= snap2.scale  # in that keyframe's map units
            res = vo.tracker.track(refs[kf_id + 1], ro.FRAMES[index], start)
            if not res.diverged:
                placed = _se3_part(matmul(_sim3(snap2.T_wc, snap2.scale), _inv_se3(res.T_fk)), snap2.scale)
        on_next.append(placed)
        mean.append(_halfway(T_wf, placed))
    stamps = np.array([r[1] for r in ro.REFS])
    r0 = rpe_paper(gt, est)
    r1, r2 = (rpe_paper(gt, Trajectory(stamps, np.array(p))) for p in (on_next, mean))
    print(json.dumps({"args": " ".join(args), **{k: [r.rot_deg_per_unit, r.trans_angle_deg_per_unit]
                                                  for k, r in (("run", r0), ("on_next", r1), ("mean", r2))}}))


if __name__ == "__main__":
    run()
