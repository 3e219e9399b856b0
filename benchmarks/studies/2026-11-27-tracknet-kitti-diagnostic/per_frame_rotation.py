"""Per-frame rotation error of `dmtrack run` outputs against their ground truth (KITTI 06 0-50).

    python per_frame_rotation.py RUN_DIR [RUN_DIR ...]

For each run folder (``trajectory.txt`` and ``groundtruth.txt``, TUM format): the angle (degrees) of
(T_gt,i-1^-1 T_gt,i)^-1 (T_est,i-1^-1 T_est,i) for every frame i, then its sum over all frames and over frames 10+.
Rotation needs no scale alignment.
"""

import sys

import numpy as np

from dmtrack.geometry.lie import rotation_angle
from dmtrack.io.trajectory import read_tum

for run in sys.argv[1:]:
    E, G = read_tum(f"{run}/trajectory.txt").poses, read_tum(f"{run}/groundtruth.txt").poses
    rel_e = np.linalg.inv(E[:-1]) @ E[1:]
    rel_g = np.linalg.inv(G[:-1]) @ G[1:]
    errs = np.degrees(rotation_angle((np.linalg.inv(rel_g) @ rel_e)[:, :3, :3]))
    print(run, " ".join(f"{e:.2f}" for e in errs))
    print(f"  sum {errs.sum():.2f}  sum over frames 10+ {errs[10:].sum():.2f}  median {np.median(errs):.3f}")
