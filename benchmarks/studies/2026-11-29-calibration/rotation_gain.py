"""How much of the ground truth's rotation an estimate shows, per camera axis (study of 2026-11-29).

Usage (from the repository root)::

    python benchmarks/studies/2026-11-29-calibration/rotation_gain.py runs RUN_DIR [RUN_DIR ...] [--k 15]
    python benchmarks/studies/2026-11-29-calibration/rotation_gain.py lsd SEQUENCE TRAJ START [--k 15]
    python benchmarks/studies/2026-11-29-calibration/rotation_gain.py two-view SEQUENCE --frames A:B
        [--focal 585,555,525] [--k1 -0.08,-0.04,0] [--k 15]

For every pair of frames (i, i + k) the relative rotation of the estimate and of the ground truth are taken as
rotation vectors in frame i's camera (x right, y down, z forward), and per axis a the *gain* is the least-squares
slope Σ g_a e_a / Σ g_a² of the estimate's component on the ground truth's: 1 when the estimate turns as much as the
camera did, below 1 when it turns less. A focal length that is too long, or barrel distortion left in the images, makes
every image-based estimate turn less about x and y (the image's motion of a turn is read as a smaller angle); about z
(roll) neither matters.

* ``runs``: ``dmtrack run`` output folders (``groundtruth.txt``, ``trajectory.txt``).
* ``lsd``: a trajectory of ``tools/lsd_oracle`` (TUM, timestamp = frame index from START) on a 7-Scenes folder.
* ``two-view``: no odometry at all: corners tracked by OpenCV's KLT from frame i to i + k (forward-backward checked),
  the essential matrix by RANSAC on the points undistorted with (f, k1), its rotation — for each (f, k1) asked;
  prints the gains and the mean absolute error per axis against the ground truth.
* ``checks``: for a ``dmtrack run`` folder of a 7-Scenes folder started at START, the paper's RPE (°/m) of the
  estimate against the ground truth delayed by −3 … +3 frames (interpolated), of the estimate with its positions
  smoothed (Gaussian, σ = 1, 2, 3 frames), and of the ground truth smoothed against itself (what the ground truth's
  own frame-to-frame jitter weighs in the metric).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(REPO / "src"))


def gains(gt: np.ndarray, est: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis gain (the metric's own, :func:`dmtrack.evaluation.rotation_gain`, with every axis counted) and mean
    absolute error (degrees) of the k-frame relative rotations of ``est`` (N, 4, 4) against ``gt`` (N, 4, 4), both
    camera-to-world."""
    from dmtrack.evaluation import rotation_gain
    from dmtrack.evaluation.metrics import _relative
    from dmtrack.geometry.lie import so3_log
    from dmtrack.io.trajectory import Trajectory

    t = np.arange(len(gt), dtype=float)
    gain = rotation_gain(Trajectory(t, gt), Trajectory(t, est), k, min_turn_deg=0.0).gain
    i = np.arange(len(gt) - k)
    g, e = (so3_log(_relative(P, i, i + k)[0]) for P in (gt, est))
    return gain, np.degrees(np.abs(e - g).mean(0))


def _gain(g: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The same gain and error of rotation vectors that do not come from a trajectory (the two-view estimate's)."""
    return (g * e).sum(0) / (g * g).sum(0), np.degrees(np.abs(e - g).mean(0))


def _seven_scenes_poses(folder: Path) -> dict[int, np.ndarray]:
    return {int(p.name[6:12]): np.loadtxt(p) for p in sorted(folder.glob("frame-*.pose.txt"))}


def _line(name: str, gain: np.ndarray, err: np.ndarray, n: int) -> str:
    return (f"{name}: gain x {gain[0]:.3f} y {gain[1]:.3f} z {gain[2]:.3f} | mean |error| x {err[0]:.3f}° "
            f"y {err[1]:.3f}° z {err[2]:.3f}° ({n} pairs)")


def cmd_runs(a: argparse.Namespace) -> None:
    from dmtrack.io.trajectory import read_tum

    for run in a.paths:
        gt, est = read_tum(Path(run) / "groundtruth.txt"), read_tum(Path(run) / "trajectory.txt")
        gain, err = gains(gt.poses, est.poses, a.k)
        print(_line(str(run), gain, err, len(gt.poses) - a.k))


def cmd_lsd(a: argparse.Namespace) -> None:
    from scipy.spatial.transform import Rotation

    poses = _seven_scenes_poses(Path(a.sequence))
    rows = np.loadtxt(a.trajectory)
    est = np.repeat(np.eye(4)[None], len(rows), 0)
    est[:, :3, :3] = Rotation.from_quat(rows[:, 4:8]).as_matrix()
    est[:, :3, 3] = rows[:, 1:4]
    gt = np.array([poses[a.start + int(t)] for t in rows[:, 0]])
    gain, err = gains(gt, est, a.k)
    print(_line(f"{a.trajectory} (from frame {a.start})", gain, err, len(gt) - a.k))


def cmd_two_view(a: argparse.Namespace) -> None:
    import cv2

    from dmtrack.geometry.lie import so3_log

    folder = Path(a.sequence)
    poses = _seven_scenes_poses(folder)
    lo, hi = (int(v) for v in a.frames.split(":"))
    images = {i: cv2.imread(str(folder / f"frame-{i:06d}.color.jpg"), cv2.IMREAD_GRAYSCALE) for i in range(lo, hi)}
    tracks = []
    for i in range(lo, hi - a.k, a.every):
        p0 = cv2.goodFeaturesToTrack(images[i], 800, 0.01, 8)
        p1, st, _ = cv2.calcOpticalFlowPyrLK(images[i], images[i + a.k], p0, None, winSize=(21, 21), maxLevel=3)
        pb, st2, _ = cv2.calcOpticalFlowPyrLK(images[i + a.k], images[i], p1, None, winSize=(21, 21), maxLevel=3)
        ok = (st[:, 0] == 1) & (st2[:, 0] == 1) & (np.linalg.norm(pb - p0, axis=2)[:, 0] < 0.5)
        if ok.sum() >= 50:
            tracks.append((i, p0[ok], p1[ok]))
    cx, cy = (float(v) for v in a.centre.split(","))
    for f in (float(v) for v in a.focal.split(",")):
        for k1 in (float(v) for v in a.k1.split(",")):
            K, D = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]]), np.array([k1, 0.0, 0.0, 0.0])
            g, e = [], []
            for i, p0, p1 in tracks:
                a0, a1 = cv2.undistortPoints(p0, K, D)[:, 0], cv2.undistortPoints(p1, K, D)[:, 0]
                E, mask = cv2.findEssentialMat(a0, a1, np.eye(3), cv2.RANSAC, 0.999, 0.5 / f)
                if E is None or E.shape != (3, 3):
                    continue
                _, R, _, _ = cv2.recoverPose(E, a0, a1, np.eye(3), mask=mask)
                e.append(so3_log(R.T))  # R maps frame i's points into frame i + k: the turn from i to i + k is Rᵀ
                g.append(so3_log((np.linalg.inv(poses[i]) @ poses[i + a.k])[:3, :3]))
            gain, err = _gain(np.array(g), np.array(e))
            print(_line(f"two-view f={f:g} k1={k1:+g} frames {lo}-{hi}", gain, err, len(g)), flush=True)


def cmd_checks(a: argparse.Namespace) -> None:
    from scipy.ndimage import gaussian_filter1d
    from scipy.spatial.transform import Rotation, Slerp

    from dmtrack.evaluation.metrics import rpe_paper
    from dmtrack.io.trajectory import Trajectory, read_tum

    est = read_tum(Path(a.run) / "trajectory.txt")
    poses = _seven_scenes_poses(Path(a.sequence))
    idx = np.array(sorted(poses))
    P = np.array([poses[i] for i in idx])
    slerp = Slerp(idx.astype(float), Rotation.from_matrix(P[:, :3, :3]))

    def gt_at(t: np.ndarray) -> np.ndarray:
        out = np.repeat(np.eye(4)[None], len(t), 0)
        out[:, :3, :3] = slerp(t).as_matrix()
        for c in range(3):
            out[:, c, 3] = np.interp(t, idx, P[:, c, 3])
        return out

    def smooth(T: np.ndarray, sigma: float) -> np.ndarray:
        out = T.copy()
        out[:, :3, 3] = gaussian_filter1d(T[:, :3, 3], sigma, axis=0, mode="nearest")
        return out

    n = len(est.poses)
    frames = a.start + np.arange(n, dtype=float)
    gt = Trajectory(est.timestamps, gt_at(frames))

    def fmt(r) -> str:
        return f"{r.rot_deg_per_unit:.2f} / {r.trans_angle_deg_per_unit:.1f}"

    print(f"{a.run}: RPE rotation / translation angle (deg per unit)")
    print("  as run:", fmt(rpe_paper(gt, est)))
    for d in (-3, -2, -1, -0.5, 0.5, 1, 2, 3):
        if frames[0] + d >= idx[0] and frames[-1] + d <= idx[-1]:
            delayed = Trajectory(est.timestamps, gt_at(frames + d))
            print(f"  ground truth delayed {d:+g} frames:", fmt(rpe_paper(delayed, est)))
    for sigma in (1.0, 2.0, 3.0):
        smoothed = Trajectory(est.timestamps, smooth(est.poses, sigma))
        print(f"  estimate smoothed, sigma {sigma:g}:", fmt(rpe_paper(gt, smoothed)))
        print(f"  ground truth smoothed against itself, sigma {sigma:g}:",
              fmt(rpe_paper(gt, Trajectory(est.timestamps, smooth(gt.poses, sigma)))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(required=True)
    positional = {"runs": (cmd_runs, ["paths+"]), "lsd": (cmd_lsd, ["sequence", "trajectory", "start:int"]),
                  "two-view": (cmd_two_view, ["sequence"]), "checks": (cmd_checks, ["run", "sequence", "start:int"])}
    for name, (func, args) in positional.items():
        p = sub.add_parser(name)
        for arg in args:
            if arg.endswith("+"):
                p.add_argument(arg[:-1], nargs="+")
            else:
                p.add_argument(arg.split(":")[0], type=int if arg.endswith(":int") else str)
        p.set_defaults(func=func)
    p = sub.choices["two-view"]
    p.add_argument("--frames", required=True, help="A:B")
    p.add_argument("--focal", default="585")
    p.add_argument("--k1", default="0")
    p.add_argument("--centre", default="320,240")
    p.add_argument("--every", type=int, default=3)
    for q in sub.choices.values():
        q.add_argument("--k", type=int, default=15, help="frames between the two of a pair (default 15)")
    a = ap.parse_args()
    a.func(a)


if __name__ == "__main__":
    main()
