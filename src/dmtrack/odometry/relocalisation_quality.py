"""The test an alignment must pass to count as finding the camera again after a loss (LSD-SLAM's relocaliser).

After a loss the odometry and the relocaliser (:mod:`dmtrack.relocalisation`) accept an alignment of a frame to a
keyframe only when it passes :func:`relocalisation_failure`'s test, stricter than tracking's own: a frame far from
where the odometry thinks it is can converge to a wrong pose with more than half of its points "good" (issue 37's
kidnapped camera: 55 % good at a residual eight times the usual one).
"""

from __future__ import annotations

from dmtrack.odometry.config import RelocConfig
from dmtrack.odometry.tracker import TrackResult

__all__ = ["good_value", "relocalisation_failure"]


def good_value(res: TrackResult) -> float:
    """LSD-SLAM's relocalisation score: point usage × good / (good + bad)."""
    n = res.good_count + res.bad_count
    return float(res.point_usage) * res.good_count / n if n > 0 else 0.0


def relocalisation_failure(res: TrackResult, cfg: RelocConfig, factor: float = 1.0,
                           residual_limit: float | None = None) -> str | None:  # fmt: skip
    """Why ``res`` does not find the camera (None if it does): diverged, or ``point_usage · good ratio`` at most
    ``factor · cfg.good_value``, or a good ratio below ``cfg.min_good_ratio``; or, when no point of it is bad (a
    feature whose good ratio cannot fall, e.g. Bit-Planes), a residual above ``residual_limit``
    (``keyframe.loss_residual_jump_without_bad`` × the tracked frames' median residual)."""
    if res.diverged:
        return f"relocalisation: {res.reason}"
    if residual_limit is not None and res.bad_count == 0 and res.last_residual > residual_limit:
        return (f"relocalisation: residual {res.last_residual:.2f} with no bad point (needs ≤ {residual_limit:.2f}, "
                f"{res.good_count} good points)")  # fmt: skip
    n = res.good_count + res.bad_count
    ratio = res.good_count / n if n > 0 else 0.0
    value = good_value(res)
    if not value > factor * cfg.good_value:
        return (f"relocalisation: usage × good ratio {value:.2f} (needs > {factor * cfg.good_value:.2f}; "
                f"{res.good_count} good / {res.bad_count} bad points)")  # fmt: skip
    if ratio < cfg.min_good_ratio:
        return f"relocalisation: good ratio {ratio:.2f} (needs ≥ {cfg.min_good_ratio:.3f})"
    return None
