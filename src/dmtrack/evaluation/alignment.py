"""Least-squares alignment of point sets and trajectories (Umeyama 1991).

The similarity ``x ↦ s R x + t`` acts on a camera-to-world pose ``T = [R_i | t_i]`` as
``[R R_i | s R t_i + t]`` (rotation kept orthonormal, the scale applied to positions only) — what
evo does.  It is returned as the 4×4 matrix ``[[s R, t], [0, 1]]``.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from dmtrack.io.trajectory import Trajectory

AlignMode = Literal["sim3", "se3", "scale", "none"]
ALIGN_MODES: tuple[str, ...] = ("sim3", "se3", "scale", "none")

_REL_SPREAD_TOL = 1e-12  # spread below this fraction of the coordinates' magnitude = "all identical"


def _check_spread(points: np.ndarray, name: str) -> None:
    spread = np.sqrt(np.mean(np.sum((points - points.mean(axis=0)) ** 2, axis=1)))
    magnitude = max(1.0, float(np.abs(points).max()))
    if not spread > _REL_SPREAD_TOL * magnitude:
        raise ValueError(
            f"umeyama: all {name} points are identical (RMS spread {spread:.3g}); "
            "the alignment is undetermined"
        )


def umeyama(
    src: np.ndarray, dst: np.ndarray, with_scale: bool = True
) -> tuple[float, np.ndarray, np.ndarray]:
    """The similarity minimising ``Σ |dst_i − (s R src_i + t)|²`` (Umeyama 1991, eqs. 34–43).

    Parameters
    ----------
    src, dst : (N, 3) corresponding points, N ≥ 3.
    with_scale : estimate ``s``; ``False`` fixes ``s = 1`` (rigid alignment).

    Returns
    -------
    s : float scale (1.0 without scale).
    R : (3, 3) rotation, det +1 (the reflection case is handled with Umeyama's sign matrix).
    t : (3,) translation.

    Raises
    ------
    ValueError
        Shapes differ or are not (N, 3), fewer than 3 points, non-finite values, or all points of
        ``src`` (or of ``dst``) identical.  Collinear points are accepted: the rotation about the
        line is then arbitrary but the residual is still the minimum.
    """
    src = np.asarray(src, dtype=np.float64)
    dst = np.asarray(dst, dtype=np.float64)
    if src.ndim != 2 or src.shape[1] != 3 or src.shape != dst.shape:
        raise ValueError(f"umeyama: src and dst must both have shape (N, 3), got {src.shape} and {dst.shape}")
    n = src.shape[0]
    if n < 3:
        raise ValueError(f"umeyama: need at least 3 corresponding points, got {n}")
    if not (np.isfinite(src).all() and np.isfinite(dst).all()):
        raise ValueError("umeyama: points must be finite (no NaN or inf)")
    _check_spread(src, "source")
    _check_spread(dst, "destination")
    mean_src = src.mean(axis=0)
    mean_dst = dst.mean(axis=0)
    xs = src - mean_src
    ys = dst - mean_dst
    var_src = np.sum(xs * xs) / n  # eq. 36
    cov = ys.T @ xs / n  # eq. 38, Σ_xy
    u, d, vt = np.linalg.svd(cov)
    S = np.ones(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0.0:  # eq. 43: reflection → flip the smallest axis
        S[2] = -1.0
    R = (u * S) @ vt  # eq. 40
    s = float(np.sum(d * S) / var_src) if with_scale else 1.0  # eq. 42
    t = mean_dst - s * (R @ mean_src)  # eq. 41
    return s, R, t


def sim3_matrix(s: float, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The 4×4 matrix ``[[s R, t], [0, 1]]``."""
    T = np.eye(4)
    T[:3, :3] = s * np.asarray(R, dtype=np.float64)
    T[:3, 3] = np.asarray(t, dtype=np.float64)
    return T


def apply_sim3(traj: Trajectory, s: float, R: np.ndarray, t: np.ndarray) -> Trajectory:
    """Every pose ``[R_i | t_i]`` becomes ``[R R_i | s R t_i + t]`` (rotations stay orthonormal)."""
    R = np.asarray(R, dtype=np.float64)
    poses = traj.poses.copy()
    poses[:, :3, :3] = R @ traj.poses[:, :3, :3]
    poses[:, :3, 3] = s * traj.poses[:, :3, 3] @ R.T + np.asarray(t, dtype=np.float64)
    return Trajectory(traj.timestamps.copy(), poses)


def align_trajectory(
    est: Trajectory, gt: Trajectory, mode: AlignMode = "sim3"
) -> tuple[Trajectory, np.ndarray]:
    """Align an (already associated) estimate to the ground truth by its camera positions.

    Parameters
    ----------
    est, gt : trajectories of equal length N (pose ``k`` of one corresponds to pose ``k`` of the other).
    mode :
        * ``"sim3"`` — rotation, translation and scale (7 DoF Umeyama), the monocular default;
        * ``"se3"`` — rotation and translation (6 DoF);
        * ``"scale"`` — scale only, about the world origin, with the scale of the 7-DoF Umeyama solution
          (what ``evo_ape --correct_scale`` without ``--align`` does);
        * ``"none"`` — identity.

    Returns
    -------
    aligned : the transformed estimate (see :func:`apply_sim3`).
    T : (4, 4) the applied similarity ``[[s R, t], [0, 1]]``.
    """
    if mode not in ALIGN_MODES:
        raise ValueError(f"unknown alignment mode {mode!r} (use one of {', '.join(ALIGN_MODES)})")
    if len(est) != len(gt):
        raise ValueError(
            f"align_trajectory: trajectories must be associated first ({len(est)} vs {len(gt)} poses)"
        )
    if mode == "none":
        s, R, t = 1.0, np.eye(3), np.zeros(3)
    else:
        s, R, t = umeyama(est.positions, gt.positions, with_scale=mode != "se3")
        if mode == "scale":
            R, t = np.eye(3), np.zeros(3)
    return apply_sim3(est, s, R, t), sim3_matrix(s, R, t)
