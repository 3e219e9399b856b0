"""A first keyframe's depth made outside the odometry (the geometric start of :mod:`dmtrack.initialization`).

The odometry takes it as it takes LSD-SLAM's random or ground-truth initial depth: it becomes keyframe 0's map
(:meth:`~dmtrack.odometry.depthmap.DepthMap.initialize_from_map`), and every frame — those the start looked at
included — is then tracked against it and mapped into it as usual.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dmtrack.errors import InputError

__all__ = ["InitialMap"]


@dataclass(frozen=True, eq=False)
class InitialMap:
    """Per-pixel hypotheses for the first keyframe, in the depth map's own terms.

    Attributes
    ----------
    frame_index : int
        The frame the map belongs to (the run's first frame).
    accepted_frame : int
        The frame at which the start had seen enough to make the map.
    valid : (H, W) bool
        Pixels with a hypothesis.
    idepth, idepth_var : (H, W) float32
        Raw inverse depth (mean inverse depth 1 over the valid pixels) and its variance.
    idepth_smoothed, idepth_var_smoothed : (H, W) float32
        The regularised ones (−1 where never regularised).
    validity : (H, W) float32
        Validity counters.
    info : dict
        What the start measured (window, inliers, parallax, reprojection error, timings), for ``metrics.json``.
    """

    frame_index: int
    accepted_frame: int
    valid: np.ndarray
    idepth: np.ndarray
    idepth_var: np.ndarray
    idepth_smoothed: np.ndarray
    idepth_var_smoothed: np.ndarray
    validity: np.ndarray
    info: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        shape = np.shape(self.valid)
        if len(shape) != 2:
            raise InputError(f"initial map: valid must be (H, W), got shape {shape}")
        for name in ("idepth", "idepth_var", "idepth_smoothed", "idepth_var_smoothed", "validity"):
            if np.shape(getattr(self, name)) != shape:
                raise InputError(f"initial map: {name} has shape {np.shape(getattr(self, name))}, valid has {shape}")

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W)."""
        return (int(self.valid.shape[0]), int(self.valid.shape[1]))

    @property
    def n_valid(self) -> int:
        """Pixels with a hypothesis."""
        return int(np.count_nonzero(self.valid))
