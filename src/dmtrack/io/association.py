"""Timestamp association of two trajectories (as TUM's ``associate.py``).

The matching is the *greedy* one of TUM's ``associate.py``: of all pairs ``(a, b)`` with
``|t_a − (t_b + offset)| ≤ max_diff``, take the pair with the smallest difference, remove both stamps,
repeat.  Each stamp is used at most once.  (evo 1.38 matches every stamp of the shorter
trajectory to its nearest neighbour instead, which may use a stamp twice; on real data with
``max_diff`` below half the frame period both give the same pairs.)

Implementation: with a strict total order on the pairs — ``(difference, t_a, t_b)``, ties going to the
earlier stamp — the greedy matching equals the result of repeatedly matching every pair of *mutual*
best partners among the stamps still free (a "locally dominant" pair is always taken by greedy, and the
globally best pair is always locally dominant).  Each round is a ``searchsorted`` over the free
stamps, O(N log N); real data needs one or two rounds (the worst case, stamps spaced in a geometric
progression, needs O(N) rounds).

Frame-index timestamps (integers, e.g. KITTI without ``times.txt``) match exactly with the same
function and any ``max_diff`` below 0.5.
"""

from __future__ import annotations

import numpy as np

from dmtrack.io.trajectory import Trajectory


def _best_partner(src: np.ndarray, dst: np.ndarray, max_diff: float) -> np.ndarray:
    """For each value of ``src`` the index in sorted ``dst`` of its best partner, or -1.

    Best = smallest ``|dst − src|``; on a tie the smaller ``dst`` value, and among equal ``dst``
    values the smallest index.  Partners farther than ``max_diff`` give -1.
    """
    out = np.full(src.shape[0], -1, dtype=np.int64)
    if dst.shape[0] == 0 or src.shape[0] == 0:
        return out
    k = np.searchsorted(dst, src, side="right")  # dst[k-1] <= src < dst[k]
    has_left = k > 0
    has_right = k < dst.shape[0]
    left_val = dst[np.maximum(k - 1, 0)]
    left = np.searchsorted(dst, left_val, side="left")  # first of equal values
    right = np.minimum(k, dst.shape[0] - 1)
    d_left = np.where(has_left, src - left_val, np.inf)
    d_right = np.where(has_right, dst[right] - src, np.inf)
    use_left = d_left <= d_right
    best = np.where(use_left, left, right)
    d_best = np.where(use_left, d_left, d_right)
    ok = d_best <= max_diff
    out[ok] = best[ok]
    return out


def associate(
    t_a: np.ndarray, t_b: np.ndarray, max_diff: float, offset: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Match timestamps of two sequences one-to-one, greedily by smallest difference.

    Parameters
    ----------
    t_a : (N,) timestamps of the first sequence (any order).
    t_b : (M,) timestamps of the second sequence (any order).
    max_diff : largest accepted ``|t_a − (t_b + offset)|`` (same unit as the stamps); inclusive.
    offset : added to ``t_b`` before matching.

    Returns
    -------
    idx_a, idx_b : (K,) int64 indices into ``t_a`` and ``t_b``; ``t_a[idx_a[k]]`` matches
        ``t_b[idx_b[k]]``; sorted by ``t_a[idx_a]`` (ties by index).
    """
    t_a = np.asarray(t_a, dtype=np.float64).reshape(-1)
    t_b = np.asarray(t_b, dtype=np.float64).reshape(-1) + float(offset)
    if not np.isfinite(max_diff) or max_diff < 0:
        raise ValueError(f"max_diff must be a finite number >= 0, got {max_diff!r}")
    if not (np.isfinite(t_a).all() and np.isfinite(t_b).all()):
        raise ValueError("timestamps must be finite (no NaN or inf)")
    order_a = np.argsort(t_a, kind="stable")
    order_b = np.argsort(t_b, kind="stable")
    a_sorted = t_a[order_a]
    b_sorted = t_b[order_b]
    free_a = np.arange(a_sorted.shape[0])  # positions in the sorted arrays still unmatched
    free_b = np.arange(b_sorted.shape[0])
    matched_a: list[np.ndarray] = []
    matched_b: list[np.ndarray] = []
    while free_a.size and free_b.size:
        av, bv = a_sorted[free_a], b_sorted[free_b]
        best_b = _best_partner(av, bv, max_diff)  # index into free_b
        best_a = _best_partner(bv, av, max_diff)  # index into free_a
        ia = np.flatnonzero(best_b >= 0)
        mutual = ia[best_a[best_b[ia]] == ia]
        if mutual.size == 0:
            break
        jb = best_b[mutual]
        matched_a.append(free_a[mutual])
        matched_b.append(free_b[jb])
        keep_a = np.ones(free_a.size, dtype=bool)
        keep_a[mutual] = False
        keep_b = np.ones(free_b.size, dtype=bool)
        keep_b[jb] = False
        free_a, free_b = free_a[keep_a], free_b[keep_b]
    if not matched_a:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    pos_a = np.concatenate(matched_a)
    pos_b = np.concatenate(matched_b)
    srt = np.argsort(pos_a, kind="stable")  # sorted position in a == order of t_a
    return order_a[pos_a[srt]].astype(np.int64), order_b[pos_b[srt]].astype(np.int64)


def associate_trajectories(
    gt: Trajectory, est: Trajectory, max_diff: float = 0.01, offset: float = 0.0
) -> tuple[Trajectory, Trajectory]:
    """The matched sub-trajectories of ``gt`` and ``est`` (equal length, in ``gt`` time order).

    Parameters
    ----------
    gt, est : trajectories; timestamps in seconds (or frame indices — then any ``max_diff < 0.5``
        matches exactly).
    max_diff : largest accepted time difference (inclusive).
    offset : added to the estimate's timestamps before matching.

    Returns
    -------
    (gt_matched, est_matched) : trajectories of equal length K; each keeps its own timestamps.
    """
    idx_gt, idx_est = associate(gt.timestamps, est.timestamps, max_diff, offset)
    return gt[idx_gt], est[idx_est]
