"""Per-frame rotation error of `dmtrack run` outputs against their ground truth (KITTI 06 0-50).

    python per_frame_rotation.py RUN_DIR [RUN_DIR ...]

For each run folder (``trajectory.txt`` and ``groundtruth.txt``, TUM format): the angle (degrees) of
(T_gt,i-1^-1 T_gt,i)^-1 (T_est,i-1^-1 T_est,i) for every frame i, then its sum over all frames and over frames 10+.
Rotation needs no scale alignment.
"""

import sys

import numpy as np
from scipy.spatial.transform import Rotation


def load(path):
    rows = np.loadtxt(path, comments="#")
    out = []
    for r in rows:
        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat(r[4:8]).as_matrix()
        T[:3, 3] = r[1:4]
        out.append(T)
    return out


for run in sys.argv[1:]:
    E, G = load(f"{run}/trajectory.txt"), load(f"{run}/groundtruth.txt")
    errs = []
    for i in range(1, len(E)):
        d = np.linalg.inv(np.linalg.inv(G[i - 1]) @ G[i]) @ (np.linalg.inv(E[i - 1]) @ E[i])
        errs.append(np.degrees(np.linalg.norm(Rotation.from_matrix(d[:3, :3]).as_rotvec())))
    errs = np.array(errs)
    print(run, " ".join(f"{e:.2f}" for e in errs))
    print(f"  sum {errs.sum():.2f}  sum over frames 10+ {errs[10:].sum():.2f}  median {np.median(errs):.3f}")
