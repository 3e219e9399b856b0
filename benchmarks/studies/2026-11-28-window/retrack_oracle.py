"""Oracle (2026-11-29): would frames tracked again against their keyframe's *final* map have better poses?

Usage: ``python retrack_oracle.py OUT_DIR SEQUENCE [dmtrack run options]`` (from the repository root).

Runs ``dmtrack run`` with hooks that keep every frame's pyramid, its keyframe and its tracked pose on that keyframe,
and each keyframe's final depth as emitted; afterwards it tracks each frame again against its keyframe's final
depth, from its tracked pose, places it by the keyframe's final pose, and prints the paper's RPE of the run and of
the re-tracked trajectory ("replay max diff": the same placement without re-tracking against trajectory.txt, a
check of the bookkeeping). A study tool: it patches the odometry's internals and holds every frame in memory.
Measured (grey, window off): 7-Scenes 0-349 5.163 / 30.29 -> 5.160 / 30.24; the scan start 200 (160 frames)
7.897 / 82.52 -> 7.899 / 82.63.
"""

from __future__ import annotations

import json
import sys

import numpy as np

import dmtrack.odometry.vo as vom
from dmtrack.cli import main
from dmtrack.evaluation.metrics import rpe_paper
from dmtrack.geometry.exact import matmul
from dmtrack.io.trajectory import Trajectory, read_tum
from dmtrack.odometry.records import _inv_se3, _se3_part, _sim3
from dmtrack.odometry.tracker import TrackingReference

FRAMES: dict = {}  # frame index -> Frame (its pyramid)
REFS: list = []  # (index, timestamp, keyframe id, T_fk) of the run's odometry, in order
FINAL: dict = {}  # keyframe id -> (keyframe Frame, KeyframeSnapshot as emitted)
ODOMETRIES: list = []  # the warm-up's odometry, then the run's

_build_frame = vom.build_frame
_record_pose = vom.VisualOdometry._record_pose
_emit_keyframe = vom.VisualOdometry._emit_keyframe


def _keep_frame(*args, **kwargs):
    frame = _build_frame(*args, **kwargs)
    FRAMES[frame.index] = frame
    return frame


def _keep_pose(self, index, timestamp, T_wc, T_fk=None):
    if not ODOMETRIES or ODOMETRIES[-1] is not self:  # a new odometry (the run's after the warm-up's)
        ODOMETRIES.append(self)
        REFS.clear()
        FINAL.clear()
    REFS.append((index, timestamp, self._kf_id, None if T_fk is None else np.array(T_fk)))
    return _record_pose(self, index, timestamp, T_wc, T_fk)


def _keep_keyframe(self, kf_id, kf, dm):
    FINAL[kf_id] = (kf, self._snapshot(kf_id, kf, dm))
    return _emit_keyframe(self, kf_id, kf, dm)


def run() -> None:
    vom.build_frame = _keep_frame
    vom.VisualOdometry._record_pose = _keep_pose
    vom.VisualOdometry._emit_keyframe = _keep_keyframe
    out, args = sys.argv[1], sys.argv[2:]
    try:
        main(["run", *args, "--out", out, "--no-progress", "--no-pointcloud", "--no-depth-images"])
    except SystemExit:
        pass
    vo = ODOMETRIES[-1]
    gt, est = read_tum(f"{out}/groundtruth.txt"), read_tum(f"{out}/trajectory.txt")
    refs: dict = {}
    again, replay = [], []
    for index, _, kf_id, T_fk in REFS:
        kf, snap = FINAL[kf_id]
        T_tracked = np.eye(4) if T_fk is None else T_fk
        T = T_tracked
        if T_fk is not None and kf.index != index:
            ref = refs.get(kf_id)
            if ref is None:
                ref = refs[kf_id] = TrackingReference.from_keyframe(kf, snap.idepth, snap.idepth_var, vo._levels,
                                                                     vo.use_numba)  # fmt: skip
            res = vo.tracker.track(ref, FRAMES[index], T_fk)
            T = T_fk if res.diverged else res.T_fk
        S = _sim3(snap.T_wc, snap.scale)
        replay.append(_se3_part(matmul(S, _inv_se3(T_tracked)), snap.scale))
        again.append(_se3_part(matmul(S, _inv_se3(T)), snap.scale))
    stamps = np.array([r[1] for r in REFS])
    print("replay max diff", float(np.abs(np.array(replay) - est.poses).max()))
    a, b = rpe_paper(gt, est), rpe_paper(gt, Trajectory(stamps, np.array(again)))
    print(json.dumps({"args": " ".join(args), "run": [a.rot_deg_per_unit, a.trans_angle_deg_per_unit],
                      "tracked_again": [b.rot_deg_per_unit, b.trans_angle_deg_per_unit]}))  # fmt: skip


if __name__ == "__main__":
    run()
