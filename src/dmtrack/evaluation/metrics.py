"""Trajectory error metrics: ATE, the paper's scale-free RPE (§3.1), and evo-style RPE.

All functions take camera-to-world poses ``T_wc``.  The ``ate``/``rpe*`` functions need *associated*
trajectories (equal length, pose ``k`` of one corresponds to pose ``k`` of the other);
:func:`evaluate` associates by timestamp first.

The paper's RPE (:func:`rpe_paper`), as fixed in ``conventions.md``:

* relative poses ``P_ij = P_i⁻¹ P_j`` (estimate) and ``Q_ij = Q_i⁻¹ Q_j`` (ground truth);
* rotation error = angle of ``R(Q_ij)ᵀ R(P_ij)``;
* translation-angle error = angle between ``t(Q_ij)`` and ``t(P_ij)`` (scale free);
* 8 lengths ``L_k = k/8 · r_l · D``, ``D`` = total ground-truth path length; for every start ``i`` and
  every ``k``, ``j`` = the first frame with ``d_j ≥ d_i + L_k`` (``d`` = cumulative ground-truth path
  length); starts without such a ``j`` are dropped;
* each error (degrees) is divided by ``L_k`` → degrees per length unit (per metre for metric ground
  truth); per length the mean over its pairs; the reported value is the mean of the per-length means
  over the lengths that have at least one pair (with ``0 < r_l ≤ 1`` all 8 always have one: ``i = 0``).
  Averaging per length first (rather than over all pairs) weights the 8 lengths equally, as KITTI's
  per-length tables do — the short lengths have many more pairs and would dominate otherwise.

Both RPE errors are invariant to a global similarity ``x ↦ s R x + t`` (``s > 0``) of the estimate, so
no alignment is needed.  Angles are computed with ``atan2`` (accurate near 0 and 180°, unlike
``arccos``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np

from dmtrack.errors import InputError
from dmtrack.evaluation.alignment import ALIGN_MODES, AlignMode, align_trajectory
from dmtrack.geometry.lie import so3_log
from dmtrack.io.association import associate_trajectories
from dmtrack.io.trajectory import Trajectory

UNDEFINED_ANGLE_DEG = 90.0
"""Translation-angle error given to a pair whose estimated (or ground-truth) relative translation is
exactly zero.  The direction is then undefined; 90° is the expected angle between the true direction
and a direction drawn uniformly at random, i.e. the score of a guess that carries no information.
Skipping such pairs instead would reward an estimate that stops moving (e.g. a lost tracker that
repeats its last pose), and 0° or 180° would claim information that is not there."""


# -- helpers -------------------------------------------------------------------------------------
def _num(value: Any) -> str:
    """A number for a message: ``0.5``, not ``np.float64(0.5)``."""
    return repr(value.item() if isinstance(value, np.generic) else value)


def _check_pair(gt: Trajectory, est: Trajectory, what: str) -> None:
    if len(gt) != len(est):
        raise ValueError(
            f"{what}: trajectories must be associated first (same number of poses), "
            f"got {len(gt)} ground-truth and {len(est)} estimated poses"
        )


def _rotation_angle_rad(R: np.ndarray) -> np.ndarray:
    """(...) rotation angles in [0, π] of (..., 3, 3) rotation matrices, via atan2(sin, cos)."""
    cos = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    axis = np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], axis=-1
    )
    sin = np.linalg.norm(axis, axis=-1) / 2.0
    return np.arctan2(sin, cos)


def _vector_angle_deg(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Angles (degrees) between rows of (K, 3) ``a`` and ``b``; rows where either is exactly zero get
    :data:`UNDEFINED_ANGLE_DEG`.  Returns (angles (K,), undefined mask (K,))."""
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    dot = np.sum(a * b, axis=-1)
    undefined = ~(np.any(a != 0, axis=-1) & np.any(b != 0, axis=-1))
    ang = np.degrees(np.arctan2(cross, dot))
    ang[undefined] = UNDEFINED_ANGLE_DEG
    return ang, undefined


def _relative(poses: np.ndarray, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation (K, 3, 3) and translation (K, 3) of ``T_i⁻¹ T_j`` without a matrix inverse
    (``R_iᵀ R_j``, ``R_iᵀ (t_j − t_i)``: equal positions give an exactly zero translation)."""
    Ri_t = np.swapaxes(poses[i, :3, :3], -1, -2)
    R = Ri_t @ poses[j, :3, :3]
    t = (Ri_t @ (poses[j, :3, 3] - poses[i, :3, 3])[..., None])[..., 0]
    return R, t


@dataclass(frozen=True, eq=False)
class ErrorStats:
    """Summary statistics of an error vector (``std`` is the population standard deviation)."""

    rmse: float
    mean: float
    median: float
    std: float
    max: float
    errors: np.ndarray

    @classmethod
    def of(cls, errors: np.ndarray) -> ErrorStats:
        errors = np.asarray(errors, dtype=np.float64)
        if errors.size == 0:
            nan = float("nan")
            return cls(nan, nan, nan, nan, nan, errors)
        return cls(
            rmse=float(np.sqrt(np.mean(errors**2))),
            mean=float(np.mean(errors)),
            median=float(np.median(errors)),
            std=float(np.std(errors)),
            max=float(np.max(errors)),
            errors=errors,
        )


# -- ATE -----------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class AteResult:
    """Absolute trajectory error (position errors after alignment).

    Attributes
    ----------
    rmse, mean, median, std, max : float, ground-truth length unit.
    errors : (N,) per-pose position error ``|p_gt − (s R p_est + t)|``.
    alignment : (4, 4) the similarity ``[[s R, t], [0, 1]]`` applied to the estimate.
    scale : float ``s`` (1.0 for ``"se3"`` / ``"none"``).
    """

    rmse: float
    mean: float
    median: float
    std: float
    max: float
    errors: np.ndarray
    alignment: np.ndarray
    scale: float


def ate(gt: Trajectory, est: Trajectory, align: AlignMode = "sim3") -> AteResult:
    """Absolute trajectory error of an associated estimate.

    Parameters
    ----------
    gt, est : associated trajectories of equal length N (N ≥ 3 unless ``align="none"``).
    align : ``"sim3"`` (7-DoF Umeyama, default — monocular), ``"se3"``, ``"scale"`` or ``"none"``;
        see :func:`~dmtrack.evaluation.alignment.align_trajectory`.
    """
    _check_pair(gt, est, "ate")
    if len(gt) == 0:
        raise ValueError("ate: no poses")
    aligned, T = align_trajectory(est, gt, align)
    errors = np.linalg.norm(gt.positions - aligned.positions, axis=1)
    st = ErrorStats.of(errors)
    scale = float(np.cbrt(np.linalg.det(T[:3, :3])))
    return AteResult(st.rmse, st.mean, st.median, st.std, st.max, errors, T, scale)


# -- the paper's RPE ------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class RpeResult:
    """The paper's scale-free relative pose error (§3.1).

    Attributes
    ----------
    rot_deg_per_unit : mean over lengths of the mean rotation error / L_k (degrees per length unit).
    trans_angle_deg_per_unit : same for the translation-angle error.
    lengths : (n_lengths,) the path lengths L_k (ground-truth length unit).
    per_length_rot, per_length_trans : (n_lengths,) per-length means (deg per unit); NaN without pairs.
    pairs_per_length : (n_lengths,) int number of pairs (i, j) per length.
    undefined_trans_pairs : number of pairs whose translation angle was undefined (a zero relative
        translation) and counted as :data:`UNDEFINED_ANGLE_DEG`.
    """

    rot_deg_per_unit: float
    trans_angle_deg_per_unit: float
    lengths: np.ndarray
    per_length_rot: np.ndarray
    per_length_trans: np.ndarray
    pairs_per_length: np.ndarray
    undefined_trans_pairs: int


def rpe_pairs(
    gt: Trajectory, r_l: float = 1.0 / 3.0, n_lengths: int = 8
) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """The pairs of the paper's RPE: a list of ``(L_k, i (K,), j (K,))`` for k = 1..n_lengths.

    ``j`` is the first frame with ``d_j ≥ d_i + L_k`` (``d`` = cumulative ground-truth path length);
    starts ``i`` without such a frame are dropped.
    """
    if not 0.0 < r_l <= 1.0:
        raise ValueError(f"r_l must be in (0, 1], got {_num(r_l)}")
    if n_lengths < 1:
        raise ValueError(f"n_lengths must be >= 1, got {_num(n_lengths)}")
    dist = gt.distances()
    total = float(dist[-1]) if dist.size else 0.0
    if not total > 0.0:
        raise ValueError("rpe: the ground truth does not move (zero path length); RPE lengths are undefined")
    idx = np.arange(dist.shape[0])
    out = []
    for k in range(1, n_lengths + 1):
        L = k / n_lengths * r_l * total
        j = np.searchsorted(dist, dist + L, side="left")
        j = np.maximum(j, idx + 1)  # j > i even if L is below the rounding of d_i
        ok = j < dist.shape[0]
        out.append((L, idx[ok], j[ok]))
    return out


def rpe_paper(gt: Trajectory, est: Trajectory, r_l: float = 1.0 / 3.0, n_lengths: int = 8) -> RpeResult:
    """The paper's RPE (rotation and translation-angle errors per unit path length).

    Parameters
    ----------
    gt, est : associated trajectories of equal length N ≥ 2 (no alignment needed: the errors are
        invariant to a global similarity of the estimate).
    r_l : longest length as a fraction of the total ground-truth path (1/3 TUM monoVO, ICL-NUIM,
        7-Scenes; 1/20 KITTI, Tsukuba), in (0, 1].
    n_lengths : number of uniformly spaced lengths (8 in the paper).

    See the module docstring for the definition; a zero relative translation gives
    :data:`UNDEFINED_ANGLE_DEG`.
    """
    _check_pair(gt, est, "rpe_paper")
    if len(gt) < 2:
        raise ValueError(f"rpe_paper: need at least 2 poses, got {len(gt)}")
    pairs = rpe_pairs(gt, r_l, n_lengths)
    lengths = np.array([p[0] for p in pairs])
    per_rot = np.full(n_lengths, np.nan)
    per_trans = np.full(n_lengths, np.nan)
    counts = np.zeros(n_lengths, dtype=np.int64)
    undefined_total = 0
    for k, (L, i, j) in enumerate(pairs):
        counts[k] = i.size
        if i.size == 0:
            continue
        Rq, tq = _relative(gt.poses, i, j)
        Rp, tp = _relative(est.poses, i, j)
        rot = np.degrees(_rotation_angle_rad(np.swapaxes(Rq, -1, -2) @ Rp))
        trans, undefined = _vector_angle_deg(tq, tp)
        undefined_total += int(undefined.sum())
        per_rot[k] = np.mean(rot) / L
        per_trans[k] = np.mean(trans) / L
    has = counts > 0
    rot_mean = float(np.mean(per_rot[has])) if has.any() else float("nan")
    trans_mean = float(np.mean(per_trans[has])) if has.any() else float("nan")
    return RpeResult(rot_mean, trans_mean, lengths, per_rot, per_trans, counts, undefined_total)


# -- evo-style RPE ---------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class RpeStats:
    """Standard (evo-style) RPE: statistics of the per-pair errors and the pairs (K, 2)."""

    rmse: float
    mean: float
    median: float
    std: float
    max: float
    errors: np.ndarray
    pairs: np.ndarray


# -- rotation gain: a calibration check --------------------------------------------------------------
ROTATION_GAIN_FRAMES = 15
"""Frames between the two poses of a pair in :func:`rotation_gain` (half a second at 30 Hz)."""


@dataclass(frozen=True, eq=False)
class RotationGain:
    """How much of the ground truth's rotation the estimate shows, per camera axis (see :func:`rotation_gain`).

    Attributes
    ----------
    gain : (3,) float — x (right), y (down), z (forward) of the first camera of each pair; NaN for an axis about which
        the ground truth hardly turns (RMS turn below ``min_turn_deg``).
    rms_turn_deg : (3,) float — RMS of the ground truth's turn about each axis over the pairs (degrees).
    pairs : number of pairs (i, i + frames).
    frames : the frames between the two poses of a pair.
    """

    gain: np.ndarray
    rms_turn_deg: np.ndarray
    pairs: int
    frames: int


def rotation_gain(
    gt: Trajectory, est: Trajectory, frames: int = ROTATION_GAIN_FRAMES, min_turn_deg: float = 0.5
) -> RotationGain:
    """Per camera axis, the least-squares slope of the estimate's turn on the ground truth's turn.

    For every pair of associated poses ``(i, i + frames)`` the relative rotations ``R(P_i⁻¹ P_j)`` (estimate) and
    ``R(Q_i⁻¹ Q_j)`` (ground truth) are taken as rotation vectors ``e``, ``g`` in camera ``i``'s frame; per axis
    ``a`` the gain is ``Σ g_a e_a / Σ g_a²``: 1 when the estimate turns as much as the camera did. It is a check of
    the camera's calibration rather than a score: with a focal length that is too long, or barrel distortion left in
    the images, image-based estimates turn less than the camera about x and y (the image's motion is read as a
    smaller angle), and the rotation–translation ambiguity of a narrow field of view lets the translation absorb the
    missing turn; about z (roll) neither matters. A consistent gain below about 0.9 about x and y with z
    near 1 is that signature (7-Scenes' colour images with the depth camera's 585 px: 0.70–0.99 about x,
    benchmarks/studies/2026-11-29-calibration). Invariant to a global similarity of the estimate (no alignment).

    Raises
    ------
    ValueError
        If the trajectories differ in length or ``frames`` < 1.
    """
    _check_pair(gt, est, "rotation gain")
    if frames < 1:
        raise ValueError(f"frames must be >= 1, got {frames}")
    n = len(gt)
    i = np.arange(max(n - frames, 0))
    if i.size == 0:
        nan = np.full(3, np.nan)
        return RotationGain(nan, nan.copy(), 0, frames)
    g = so3_log(_relative(gt.poses, i, i + frames)[0])
    e = so3_log(_relative(est.poses, i, i + frames)[0])
    gg = np.sum(g * g, axis=0)
    rms = np.degrees(np.sqrt(gg / i.size))
    defined = rms >= min_turn_deg
    gain = np.where(defined, np.sum(g * e, axis=0) / np.where(defined, gg, 1.0), np.nan)
    return RotationGain(gain, rms, int(i.size), frames)


def rotation_gain_text(gain: list[float | None] | None, frames: int | None = None) -> list[str]:
    """The rotation gain (``evaluate``'s ``rotation_gain``) as a line of text, with a hint when it has the signature of
    a focal length that is too long or of distortion left in the images (x and y below 0.9, z near 1); no line
    without one."""
    if not gain or all(g is None for g in gain):
        return []
    parts = " ".join(f"{axis} {'–' if g is None else f'{g:.2f}'}" for axis, g in zip("xyz", gain, strict=True))
    over = f" over {frames} poses" if frames else ""
    line = f"rotation gain (the estimate's turn / the ground truth's{over}): {parts}"
    x, y, z = gain
    if x is not None and y is not None and max(x, y) < 0.9 and (z is None or 0.9 <= z <= 1.1):
        line += ("; it turns less about x and y than the camera did: the focal length may be too long or the "
                 "images distorted (check the calibration)")
    return [line]


def _pairs_by_path(poses: np.ndarray, delta: float, tol: float, all_pairs: bool) -> np.ndarray:
    """Index pairs ``(i, j)`` about ``delta`` of path apart, as evo's ``filter_pairs_by_path``."""
    n = poses.shape[0]
    steps = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(steps)])
    if all_pairs:
        i = np.arange(n - 1)
        target = cum[i] + delta
        k = np.searchsorted(cum, target, side="left")  # first with cum >= target
        lo = np.maximum(k - 1, i + 1)  # candidate below (or the first after i)
        lo = np.maximum(np.searchsorted(cum, cum[lo], side="left"), i + 1)  # first of a plateau
        hi = np.minimum(np.maximum(k, i + 1), n - 1)
        d_lo = np.abs(cum[lo] - cum[i] - delta)
        d_hi = np.abs(cum[hi] - cum[i] - delta)
        j = np.where(d_hi < d_lo, hi, lo)
        d = np.minimum(d_lo, d_hi)
        ok = d <= tol
        return np.column_stack([i[ok], j[ok]])
    ids = [0]
    current = 0.0
    for idx in range(1, n):  # sequential like evo: the accumulated path restarts at every chosen pose
        current += float(steps[idx - 1])
        if current >= delta:
            ids.append(idx)
            current = 0.0
    ids_arr = np.asarray(ids, dtype=np.int64)
    return np.column_stack([ids_arr[:-1], ids_arr[1:]])


def rpe(
    gt: Trajectory,
    est: Trajectory,
    delta: float,
    delta_unit: Literal["frames", "m"] = "frames",
    pose_relation: Literal["trans", "rot_deg"] = "trans",
    all_pairs: bool = False,
    pairs_from_reference: bool = False,
    rel_delta_tol: float = 0.1,
) -> RpeStats:
    """Standard RPE as evo's ``metrics.RPE`` (for cross-checking; not scale-free, no alignment).

    Error pose ``E = Q_ij⁻¹ P_ij``; ``"trans"`` → ``|t(E)|`` (length unit), ``"rot_deg"`` → angle of
    ``R(E)`` (degrees).  Pairs: ``delta_unit="frames"`` → ``(i, i+delta)`` (consecutive blocks, or every
    ``i`` with ``all_pairs``); ``"m"`` → ``delta`` of path length apart, measured on the estimate (evo's
    default) or on the ground truth with ``pairs_from_reference``; with ``all_pairs`` a pair is kept
    when its path is within ``rel_delta_tol · delta`` of ``delta``.
    """
    _check_pair(gt, est, "rpe")
    if delta <= 0:
        raise ValueError(f"rpe: delta must be > 0, got {_num(delta)}")
    n = len(gt)
    if delta_unit == "frames":
        if int(delta) != delta:
            raise ValueError(f"rpe: delta in frames must be an integer, got {_num(delta)}")
        d = int(delta)
        i = np.arange(n - d) if all_pairs else np.arange(0, n, d)[:-1]
        i = i[i + d < n]
        pairs = np.column_stack([i, i + d])
    elif delta_unit == "m":
        poses = gt.poses if pairs_from_reference else est.poses
        pairs = _pairs_by_path(poses, float(delta), float(delta) * rel_delta_tol, all_pairs)
    else:
        raise ValueError(f"rpe: unknown delta_unit {delta_unit!r} (use 'frames' or 'm')")
    pairs = pairs.reshape(-1, 2).astype(np.int64)
    i, j = pairs[:, 0], pairs[:, 1]
    Rq, tq = _relative(gt.poses, i, j)
    Rp, tp = _relative(est.poses, i, j)
    RqT = np.swapaxes(Rq, -1, -2)
    if pose_relation == "trans":
        errors = np.linalg.norm((RqT @ (tp - tq)[..., None])[..., 0], axis=1)
    elif pose_relation == "rot_deg":
        errors = np.degrees(_rotation_angle_rad(RqT @ Rp))
    else:
        raise ValueError(f"rpe: unknown pose_relation {pose_relation!r} (use 'trans' or 'rot_deg')")
    st = ErrorStats.of(errors)
    return RpeStats(st.rmse, st.mean, st.median, st.std, st.max, errors, pairs)


# -- all together ----------------------------------------------------------------------------------
#: Largest coordinate :func:`evaluate` computes with (squares of larger ones overflow on the way).
MAX_COORDINATE = 1e100


def _who(role: str, name: str | Path | None) -> str:
    return f"the {role}" if name is None else f"the {role} {name}"


def _check_evaluate_inputs(
    gt: Trajectory, est: Trajectory, max_diff: Any, r_l: Any, align: Any,
    gt_name: str | Path | None, est_name: str | Path | None,
) -> None:
    try:
        md, rl = float(max_diff), float(r_l)
    except (TypeError, ValueError):
        raise InputError(f"max_diff and r_l must be numbers, got {_num(max_diff)} and {_num(r_l)}") from None
    if not (math.isfinite(md) and md >= 0.0):
        raise InputError(f"the largest timestamp difference (max_diff) must be a finite number ≥ 0, got {_num(md)}")
    if not 0.0 < rl <= 1.0:
        raise InputError(f"the RPE length ratio r_l must be in (0, 1], got {_num(rl)}")
    if align not in ALIGN_MODES:
        raise InputError(f"unknown alignment {align!r} (use one of {', '.join(ALIGN_MODES)})")
    for traj, role, name in ((gt, "ground truth", gt_name), (est, "estimate", est_name)):
        if not (np.isfinite(traj.timestamps).all() and np.isfinite(traj.poses).all()):
            raise InputError(f"the {role} has timestamps or poses that are not finite numbers", path=name)
        if len(traj) and np.abs(traj.positions).max() > MAX_COORDINATE:
            raise InputError(f"the {role} has coordinates beyond {MAX_COORDINATE:g}: too large to evaluate", path=name)


def evaluate(
    gt: Trajectory,
    est: Trajectory,
    max_diff: float = 0.01,
    r_l: float = 1.0 / 3.0,
    align: AlignMode = "sim3",
    *,
    gt_name: str | Path | None = None,
    est_name: str | Path | None = None,
) -> dict[str, Any]:
    """Associate by timestamp, then ATE (after ``align``) and the paper's RPE on the matched poses.

    Ground truth with gaps (TUM monoVO has it only at the start and the end; some frames of any
    dataset may be unregistered): only matched poses are evaluated, and they are treated as one
    trajectory.  Path lengths are measured along the *matched* ground-truth poses, so a gap is
    bridged by the straight segment between the last pose before it and the first after it, and
    pairs (i, j) may span a gap (their error then includes the drift over the unobserved part).
    ``max_matched_time_gap`` in the result shows how large the largest gap is.

    Parameters
    ----------
    gt, est : full trajectories (timestamps in seconds, or frame indices for both).
    max_diff : association tolerance (same unit as the timestamps).
    r_l : longest RPE length as a fraction of the matched ground-truth path.
    align : ATE alignment mode.
    gt_name, est_name : the files the trajectories came from, named in the errors (``dmtrack eval``).

    Returns
    -------
    dict with plain Python values: ``ate_rmse``, ``rpe_rot_deg_per_m``, ``rpe_trans_angle_deg_per_m``,
    ``matched_poses`` (the keys of ``conventions.md``; "per m" = per ground-truth length unit) and
    ``ate_mean``, ``ate_median``, ``ate_std``, ``ate_max``, ``ate_scale``, ``ate_alignment`` (4×4 as
    nested lists), ``rpe_lengths``, ``rpe_rot_per_length``, ``rpe_trans_per_length``,
    ``rpe_pairs_per_length``, ``rpe_undefined_trans_pairs``, ``gt_poses``, ``est_poses``,
    ``gt_path_length`` (matched), ``max_matched_time_gap``, ``align``, ``r_l``, ``max_diff``, and
    ``rotation_gain`` (x, y, z; None for an axis the ground truth hardly turns about) over pairs
    ``rotation_gain_frames`` matched poses apart (:func:`rotation_gain`).

    Raises
    ------
    InputError
        Fewer than 3 poses match; a trajectory that does not move (nothing to align, no RPE lengths); poses that
        are not finite or too large to compute with; a bad ``max_diff``, ``r_l`` or ``align``.
    """
    _check_evaluate_inputs(gt, est, max_diff, r_l, align, gt_name, est_name)
    gt_m, est_m = associate_trajectories(gt, est, max_diff=max_diff)
    n = len(gt_m)
    if n < 3:

        def span(t: Trajectory) -> str:
            return f"{t.timestamps.min():.6f}..{t.timestamps.max():.6f}" if len(t) else "empty"

        raise InputError(
            f"only {n} pose(s) of {_who('estimate', est_name)} ({len(est)} poses, t={span(est)}) match "
            f"{_who('ground truth', gt_name)} ({len(gt)} poses, t={span(gt)}) within {_num(max_diff)} — need at "
            "least 3; check that both use the same time base (seconds vs frame indices)"
        )
    if not gt_m.path_length() > 0.0:
        raise InputError(f"the ground truth does not move over the {n} matched poses (zero path length): the RPE "
                         "lengths are undefined", path=gt_name)
    for traj, role, name in ((est_m, "estimate", est_name), (gt_m, "ground truth", gt_name)):
        spread = np.ptp(traj.positions, axis=0).max()
        if align != "none" and not spread > 1e-12 * max(1.0, float(np.abs(traj.positions).max())):
            raise InputError(f"the {role}'s {n} matched positions are all the same, so the {align} alignment is "
                             "undetermined", path=name)
    try:
        a = ate(gt_m, est_m, align)
        r = rpe_paper(gt_m, est_m, r_l)
        rg = rotation_gain(gt_m, est_m)
    except (ValueError, np.linalg.LinAlgError) as e:  # degenerate input the checks above did not foresee
        raise InputError(f"cannot evaluate {_who('estimate', est_name)} against "
                         f"{_who('ground truth', gt_name)}: {e}") from None
    gaps = np.diff(gt_m.timestamps)
    return {
        "ate_rmse": a.rmse,
        "rpe_rot_deg_per_m": r.rot_deg_per_unit,
        "rpe_trans_angle_deg_per_m": r.trans_angle_deg_per_unit,
        "matched_poses": n,
        "ate_mean": a.mean,
        "ate_median": a.median,
        "ate_std": a.std,
        "ate_max": a.max,
        "ate_scale": a.scale,
        "ate_alignment": a.alignment.tolist(),
        "rpe_lengths": r.lengths.tolist(),
        "rpe_rot_per_length": r.per_length_rot.tolist(),
        "rpe_trans_per_length": r.per_length_trans.tolist(),
        "rpe_pairs_per_length": r.pairs_per_length.tolist(),
        "rpe_undefined_trans_pairs": r.undefined_trans_pairs,
        "gt_poses": len(gt),
        "est_poses": len(est),
        "gt_path_length": gt_m.path_length(),
        "max_matched_time_gap": float(gaps.max()) if gaps.size else 0.0,
        "align": align,
        "r_l": r_l,
        "max_diff": max_diff,
        "rotation_gain": [None if not math.isfinite(v) else float(v) for v in rg.gain],
        "rotation_gain_frames": rg.frames,
    }
