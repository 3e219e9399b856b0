"""The sliding window the odometry hands its keyframes to (:class:`~dmtrack.odometry.windowing.KeyframeWindow`).

At each keyframe change the finished keyframe's points are sampled (:func:`~dmtrack.window.bundle.sample_points`)
and the window — the newest ``size`` keyframes, the new current one a target only — is optimised
(:class:`~dmtrack.window.bundle.PhotometricBundle`). Afterwards every finished keyframe's scale is the median ratio of
its depth map's inverse depths to the optimised ones; the finished map is then propagated into the new keyframe along
the optimised relative pose, and the new keyframe's scale is its parent's times the ρ its map was normalised with
(:meth:`SlidingWindow.set_scale`): the next frames are tracked against that map and chained in the corrected scale.
A keyframe that leaves the window keeps its last estimate (``leave = "fixed"``), and the oldest one left is the next
window's anchor.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dmtrack.errors import InputError
from dmtrack.geometry.exact import norm
from dmtrack.initialization.first_map import grey_frame
from dmtrack.odometry.config import ChannelRule, VOConfig, WindowConfig
from dmtrack.odometry.records import _inv_se3
from dmtrack.odometry.windowing import WindowUpdate
from dmtrack.window.bundle import BundleReport, PhotometricBundle, WindowKeyframe, sample_points

__all__ = ["SlidingWindow", "WindowStats"]


@dataclass
class WindowStats:
    """What the window did over a run: optimisations, those rejected (``max_outliers``, ``max_move``: the window began
    anew), keyframes that left it during the run (and how: ``leave``), the
    total time, the cost reduction, and the intrinsics' estimates (one per optimisation, with their standard
    deviations) when they were refined."""

    optimisations: int = 0
    rejected: int = 0
    left: int = 0
    leave: str = "fixed"
    time_ms: float = 0.0
    cost_ratio: list[float] = field(default_factory=list)
    intrinsics: list[np.ndarray] = field(default_factory=list)
    intrinsics_sigma: list[np.ndarray] = field(default_factory=list)

    def intrinsics_estimate(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The inverse-variance weighted mean of the estimates and its standard deviation (each optimisation taken as
        independent, which the windows' overlap makes optimistic), or None."""
        if not self.intrinsics:
            return None
        K = np.array(self.intrinsics)
        s = np.array(self.intrinsics_sigma)
        w = np.where(np.isfinite(s) & (s > 0), 1.0 / np.where(s > 0, s * s, 1.0), 0.0)
        tot = w.sum(0)
        mean = np.where(tot > 0, (w * K).sum(0) / np.where(tot > 0, tot, 1.0), K[-1])
        sigma = np.where(tot > 0, 1.0 / np.sqrt(np.where(tot > 0, tot, 1.0)), np.nan)
        return mean, sigma

    def as_dict(self) -> dict[str, Any]:
        """The numbers for ``metrics.json``."""
        out: dict[str, Any] = {
            "optimisations": self.optimisations,
            "rejected": self.rejected,
            "left": self.left,
            "leave": self.leave,
            "ms_per_optimisation": self.time_ms / self.optimisations if self.optimisations else 0.0,
            "median_cost_ratio": float(np.median(self.cost_ratio)) if self.cost_ratio else None,
        }
        est = self.intrinsics_estimate()
        if est is not None:
            names = ("fx", "fy", "cx", "cy")
            out["intrinsics"] = {k: float(v) for k, v in zip(names, est[0], strict=True)}
            out["intrinsics_sigma"] = {k: (None if not np.isfinite(v) else float(v))
                                       for k, v in zip(names, est[1], strict=True)}  # fmt: skip
        return out


class SlidingWindow:
    """The newest keyframes optimised jointly (see the module docstring).

    Parameters
    ----------
    config : VOConfig
        The odometry's configuration: its ``window`` section, and the channel rule and photometric noise the
        residuals are weighted with (``channel_cost`` and the feature's channel statistics, the tracker's
        ``camera_pixel_noise2``).
    camera : PinholeCamera
        Level-0 calibration (the intrinsics' prior and start).
    use_numba : bool
        Numba kernels (default) or the numpy reference.
    """

    def __init__(self, config: VOConfig, camera: Any, use_numba: bool = True):
        self.vo_config = config
        self.config: WindowConfig = config.window
        self.bundle = PhotometricBundle(self.config, (camera.fx, camera.fy, camera.cx, camera.cy),
                                        (camera.width, camera.height), 1.0, config.tracker.camera_pixel_noise2,
                                        use_numba)  # fmt: skip
        self._channels: int | None = None
        self._use_numba = use_numba
        self.keyframes: list[WindowKeyframe] = []
        self.stats = WindowStats(leave=self.config.leave)
        self.last_report: BundleReport | None = None

    @property
    def keyframe_ids(self) -> list[int]:
        """Ids of the keyframes in the window, oldest first."""
        return [kf.keyframe_id for kf in self.keyframes]

    def summary(self) -> dict[str, Any]:
        """:attr:`stats` for ``metrics.json``."""
        return self.stats.as_dict()

    def clear(self) -> WindowUpdate:
        """Every keyframe leaves."""
        left = [kf.keyframe_id for kf in self.keyframes]
        self.keyframes = []
        self.bundle.marginal = None
        return WindowUpdate({}, left)

    def start(self, keyframe_id: int, frame: Any, T_wc: np.ndarray, scale: float) -> WindowUpdate:
        """Begin anew with this keyframe."""
        update = self.clear()
        self.keyframes.append(WindowKeyframe(keyframe_id, self._view(frame), _inv_se3(np.asarray(T_wc, np.float64)),
                                             float(scale)))  # fmt: skip
        return update

    def _view(self, frame: Any) -> Any:
        """What the window reads of a keyframe: its frame, or with ``channels = "grey"`` a grey pyramid of the
        frame's image (the same levels; the tracked feature's pyramid is not held by the window then)."""
        if self.config.channels != "grey":
            return frame
        if frame.image is None:
            raise InputError(f"window.channels=grey: frame {frame.index} has no image to take the grey levels from "
                             "(give the odometry its images, or keep window.channels=feature)")  # fmt: skip
        return grey_frame(frame.index, frame.timestamp, frame.image, frame.camera, len(frame.levels), self._use_numba)

    def advance(self, finished_id: int, idepth: np.ndarray, var: np.ndarray, keyframe_id: int, frame: Any,
                T_wc: np.ndarray) -> WindowUpdate:  # fmt: skip
        """Sample the finished keyframe's points, add ``frame`` as the new keyframe (a target), optimise, let the
        oldest leave. The new keyframe's scale is set by :meth:`set_scale` once its map is made."""
        if not self.keyframes or self.keyframes[-1].keyframe_id != finished_id:  # not the window's: begin anew
            update = self.start(keyframe_id, frame, T_wc, float("nan"))
            update.left.append(finished_id)  # it leaves at once
            return update
        t0 = time.perf_counter()
        host = self.keyframes[-1]
        if self._channels != host.frame.n_channels:  # the channel rule's factor of Σ_c r_c² for this feature
            c = self.vo_config
            self._channels = host.frame.n_channels
            self.bundle.params[0] = ChannelRule.of(c.channel_cost, self._channels, c.info_channels, c.energy_channels,
                                                   c.noise_energy_channels).residual  # fmt: skip
        pts = sample_points(host.frame, idepth, var, self.config)
        if pts is not None:
            pts.d = pts.d_map / host.scale
        host.points = pts
        self.keyframes.append(WindowKeyframe(keyframe_id, self._view(frame), _inv_se3(np.asarray(T_wc, np.float64)),
                                             float("nan")))  # fmt: skip
        update = WindowUpdate()
        if any(kf.points is not None for kf in self.keyframes):
            saved = [(kf.T_cw, None if kf.points is None else kf.points.d.copy()) for kf in self.keyframes]
            marginal, intrinsics = self.bundle.marginal, self.bundle.intrinsics.copy()
            report = self.bundle.optimise(self.keyframes)
            self.last_report = report
            self.stats.optimisations += 1
            if self._implausible(report, T_wc):
                for kf, (T, d) in zip(self.keyframes, saved, strict=True):
                    kf.T_cw = T
                    if d is not None and kf.points is not None:
                        kf.points.d = d
                self.bundle.marginal, self.bundle.intrinsics = marginal, intrinsics
                self.stats.rejected += 1
                self.stats.time_ms += 1e3 * (time.perf_counter() - t0)
                return self._restart_at_newest()
            if report.cost_before > 0:
                self.stats.cost_ratio.append(report.cost_after / report.cost_before)
            if report.intrinsics is not None and report.intrinsics_sigma is not None:
                self.stats.intrinsics.append(report.intrinsics)
                self.stats.intrinsics_sigma.append(report.intrinsics_sigma)
            moved = self.keyframes if not self.bundle.anchored() else self.keyframes[1:]
            for kf in moved[:-1]:  # a finished keyframe's units: its map's inverse depths over the optimised ones
                if kf.points is not None and kf.points.count:
                    kf.scale = float(np.median(kf.points.d_map / kf.points.d))
            update.poses = {kf.keyframe_id: (_inv_se3(kf.T_cw), kf.scale) for kf in moved}
        while len(self.keyframes) > self.config.size:
            self.bundle.marginalise(self.keyframes)
            update.left.append(self.keyframes.pop(0).keyframe_id)
            self.stats.left += 1
        self.stats.time_ms += 1e3 * (time.perf_counter() - t0)
        return update

    def _implausible(self, report: BundleReport, T_wc_tracked: np.ndarray) -> bool:
        """Whether an optimisation's result must not be used (see ``max_outliers`` and ``max_move``)."""
        n = report.inliers + report.outliers
        if n == 0 or report.outliers > self.config.max_outliers * n:
            return True
        new, finished = self.keyframes[-1], self.keyframes[-2]
        moved = _inv_se3(new.T_cw)[:3, 3] - np.asarray(T_wc_tracked, np.float64)[:3, 3]
        baseline = np.asarray(T_wc_tracked, np.float64)[:3, 3] - _inv_se3(finished.T_cw)[:3, 3]
        return bool(norm(moved) > self.config.max_move * norm(baseline))

    def _restart_at_newest(self) -> WindowUpdate:
        """Every keyframe but the newest leaves with the estimate it had; the window begins anew from the newest."""
        newest = self.keyframes[-1]
        update = WindowUpdate({}, [kf.keyframe_id for kf in self.keyframes[:-1]])
        self.stats.left += len(update.left)
        self.keyframes = [newest]
        self.bundle.marginal = None
        return update

    def set_scale(self, keyframe_id: int, scale: float) -> None:
        """The current keyframe's map units in world units (its parent's scale times the ρ its map was normalised
        with)."""
        if self.keyframes and self.keyframes[-1].keyframe_id == keyframe_id:
            self.keyframes[-1].scale = float(scale)
