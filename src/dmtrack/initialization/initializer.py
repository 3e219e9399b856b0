"""The geometric start: when the first frames have shown enough translation, make the first keyframe's map.

:class:`GeometricInitializer` is fed the run's frames one by one, from its first (:meth:`~GeometricInitializer.add`)
and answers, after each, whether it has finished:

1. the first frame's corners are tracked into every new frame (:class:`~dmtrack.initialization.tracks.CornerTracks`);
2. from frame ``min_frames`` on, every quarter of the window so far (8, 10, 12, 15, 18, 22, … by default), the two-view
   geometry of the first and the newest frame is fitted (:func:`~dmtrack.initialization.twoview.two_view`). The
   window is tried once the corners' median parallax reaches ``min_parallax_deg``, a homography no longer explains
   more than ``max_homography_fraction`` of them, and at least ``min_inliers`` agree;
3. a try: the poses of up to ``map_frames`` frames of the window (evenly spaced, the newest included) and the
   corners' inverse depths are bundle-adjusted (:func:`~dmtrack.initialization.bundle.bundle_adjust`); the try
   holds when ``min_inliers`` corners survive, their median reprojection error is at most
   ``max_reprojection_px`` and the adjusted parallax still reaches ``min_parallax_deg``;
4. a try that holds is accepted only when the next one confirms it: both windows agree on the newest frame of the
   earlier within ``agree_rot_deg`` of rotation and ``agree_tdir_deg`` in the direction of motion (a short
   baseline can fit a wrong motion about as well as the right one; a wrong one does not last);
5. then the first map is made from the later window's frames
   (:func:`~dmtrack.initialization.first_map.make_first_map`) and the start has *accepted*; the odometry begins at
   the first frame with that map and tracks every frame, the window's included.

It *refuses* — with a message saying what was missing — when the window reaches ``max_frames`` frames, or when
too few corners are left to track (or were found). The caller then decides what to do (``dmtrack.track`` starts
from LSD-SLAM's random map and records the refusal in ``metrics.json``).

Deterministic: OpenCV's RANSAC seeds its own generator, the rest is plain arithmetic.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from dmtrack.errors import InputError
from dmtrack.geometry import exact
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.initialization.bundle import bundle_adjust
from dmtrack.initialization.first_map import grey_frame, make_first_map
from dmtrack.initialization.tracks import CornerTracks
from dmtrack.initialization.twoview import TwoView, ray_parallax_deg, two_view
from dmtrack.odometry.config import VOConfig
from dmtrack.odometry.initial_map import InitialMap

__all__ = ["GeometricInitializer"]


class GeometricInitializer:
    """Watches the first frames of a run and makes the first keyframe's map from their geometry.

    Parameters
    ----------
    camera : PinholeCamera
        The level-0 camera of the frames given (the odometry's, after cropping).
    config : VOConfig
        ``initializer`` (this start), ``depth`` and ``tracker`` (the first map), ``pyramid_levels``.
    parallel : bool
        Multi-threaded depth-map and tracker kernels for the first map.

    Attributes
    ----------
    state : str
        ``"collecting"``, ``"accepted"`` or ``"refused"``.
    initial_map : InitialMap or None
        The first map, once accepted.
    reason : str or None
        Why it refused.
    info : dict
        What it measured (``metrics.json`` takes it): frames seen, checks, the last two-view numbers, timings.
    """

    def __init__(self, camera: PinholeCamera, config: VOConfig | None = None, *, parallel: bool = False) -> None:
        self.camera = camera
        self.config = config if config is not None else VOConfig()
        self.parallel = bool(parallel)
        self.state = "collecting"
        self.initial_map: InitialMap | None = None
        self.reason: str | None = None
        self._K = np.array([[camera.fx, 0, camera.cx], [0, camera.fy, camera.cy], [0, 0, 1.0]])
        self._tracks: CornerTracks | None = None
        self._images: list[np.ndarray] = []
        self._indices: list[int] = []
        self._timestamps: list[float] = []
        self._next_check = self.config.initializer.min_frames
        self._last: TwoView | None = None
        self._best_parallax = 0.0
        self._last_try: str | None = None
        self._prev: tuple[list[int], np.ndarray] | None = None  # the last try's window and its adjusted poses
        self._seconds = 0.0
        self.info: dict[str, Any] = {"checks": 0, "tries": 0}

    @property
    def done(self) -> bool:
        """Accepted or refused."""
        return self.state != "collecting"

    def add(self, index: int, timestamp: float, image: np.ndarray) -> bool:
        """Take the next frame (uint8 grey or RGB, the camera's size); return :attr:`done`."""
        if self.done:
            raise RuntimeError(f"the start has already {self.state}")
        t0 = time.perf_counter()
        try:
            self._add(int(index), float(timestamp), image)
        finally:
            self._seconds += time.perf_counter() - t0
            self.info["seconds"] = round(self._seconds, 4)
            self.info["frames_seen"] = len(self._indices)
        return self.done

    # ------------------------------------------------------------------ steps
    def _add(self, index: int, timestamp: float, image: np.ndarray) -> None:
        ic = self.config.initializer
        if image.shape[:2] != (self.camera.height, self.camera.width):
            raise InputError(f"frame {index} is {image.shape[1]}x{image.shape[0]}, the camera {self.camera.width}x"
                             f"{self.camera.height}")
        self._images.append(image)
        self._indices.append(index)
        self._timestamps.append(timestamp)
        if self._tracks is None:
            self._tracks = CornerTracks(
                image, ic.corners, ic.corner_distance, ic.klt_window, ic.klt_levels, ic.max_fb_error
            )
            if len(self._tracks.first) < ic.min_inliers:
                self.refuse(f"frame {index} has {len(self._tracks.first)} corners, the start needs "
                             f"{ic.min_inliers}: too little texture")
            return
        alive = self._tracks.add(image)
        k = len(self._indices) - 1
        if alive < ic.min_inliers:
            self.refuse(f"only {alive} of the first frame's {len(self._tracks.first)} corners could be followed to "
                         f"frame {index} (the start needs {ic.min_inliers}): {self.motion_summary()}")
            return
        if k >= self._next_check:
            self._next_check = k + max(1, k // 4)
            if self._check(k) and self._try(k):
                return
        if k >= ic.max_frames:
            self.refuse(f"no window of frames {self._indices[0]}–{index} gave the start what it needs: "
                         f"{self.motion_summary()}")

    def _check(self, k: int) -> bool:
        """Fit the two-view geometry of frames 0 and k; whether the window is worth a try."""
        ic = self.config.initializer
        assert self._tracks is not None
        alive = np.flatnonzero(self._tracks.alive)
        tv = two_view(self._tracks.first[alive], self._tracks.observations(k)[alive], self._K, ic.ransac_px,
                      ic.min_inliers)
        self.info["checks"] += 1
        if tv is None:
            return False
        tv = TwoView(tv.R, tv.t, alive[tv.inliers], tv.idepth, tv.parallax_deg, tv.homography_fraction)
        self._last = tv
        self._best_parallax = max(self._best_parallax, tv.parallax_deg)
        return (
            tv.parallax_deg >= ic.min_parallax_deg
            and tv.homography_fraction <= ic.max_homography_fraction
            and len(tv.inliers) >= ic.min_inliers
        )

    def _try(self, k: int) -> bool:
        """Bundle-adjust the window up to frame k and, if it holds, make the first map; whether it accepted."""
        ic = self.config.initializer
        tv = self._last
        assert tv is not None and self._tracks is not None
        self.info["tries"] += 1
        window = _window(k, ic.map_frames, None if self._prev is None else self._prev[0][-1])
        idx = tv.inliers
        rho = np.array(tv.idepth, np.float64)
        good = np.isfinite(rho)
        if not good.any():
            return False
        med = float(np.median(rho[good]))
        rho = np.clip(np.where(good, rho, med), 1e-2 * med, 1e2 * med)
        s = float(np.mean(rho))
        rho /= s
        slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([np.eye(3), tv.R])))
        poses = np.tile(np.eye(4), (len(window), 1, 1))
        for n, i in enumerate(window):
            poses[n, :3, :3] = slerp(i / k).as_matrix()
            poses[n, :3, 3] = tv.t * s * (i / k)
        first = self._tracks.first[idx]
        obs = [self._tracks.observations(i)[idx] for i in window]
        ba = bundle_adjust(self._K, first, obs, poses, rho)
        n_kept = int(np.count_nonzero(ba.kept))
        T = ba.poses[-1]
        par = ray_parallax_deg(first[ba.kept], ba.idepth[ba.kept], self._K, T[:3, :3], T[:3, 3])
        par_med = float(np.median(par)) if len(par) else 0.0
        self.info.update(
            ba_corners=n_kept, ba_error_px=round(ba.median_error_px, 4), parallax_deg=round(par_med, 4),
            homography_fraction=round(tv.homography_fraction, 4),
        )  # fmt: skip
        if n_kept < ic.min_inliers:
            self._last_try = f"the bundle adjustment kept {n_kept} corners"
            return False
        if not ba.median_error_px <= ic.max_reprojection_px:
            self._last_try = f"the bundle adjustment left {ba.median_error_px:.2f} px"
            return False
        if par_med < ic.min_parallax_deg:
            self._last_try = f"the adjusted parallax is {par_med:.2f}°"
            return False
        prev, self._prev = self._prev, (window, ba.poses.copy())
        if prev is None:
            self._last_try = "a first window held; the start waits for a later one to confirm it"
            return False
        last = prev[0][-1]
        rot, tdir = _disagreement(prev[1][-1], ba.poses[window.index(last)])
        self.info.update(agreement_rot_deg=round(rot, 4), agreement_tdir_deg=round(tdir, 3))
        if rot > ic.agree_rot_deg or tdir > ic.agree_tdir_deg:
            self._last_try = (f"two windows disagreed on frame {self._indices[last]} by {rot:.2f}° in rotation and "
                              f"{tdir:.1f}° in the direction of motion")
            return False
        self._accept(window, list(ba.poses), k)  # the later, confirmed window makes the map
        return True

    def _accept(self, window: list[int], poses: list[np.ndarray], k: int) -> None:
        levels = self.config.pyramid_levels
        kf = grey_frame(self._indices[0], self._timestamps[0], self._images[0], self.camera, levels)
        frames = [grey_frame(self._indices[i], self._timestamps[i], self._images[i], self.camera, levels)
                  for i in window]
        m, _ = make_first_map(kf, frames, poses, self.config, parallel=self.parallel)
        self.info.update(accepted_frame=self._indices[k],
                         window_frames=[self._indices[i] for i in window], map_pixels=m.n_valid)
        self.initial_map = InitialMap(
            m.frame_index, self._indices[k], m.valid, m.idepth, m.idepth_var, m.idepth_smoothed,
            m.idepth_var_smoothed, m.validity, dict(self.info),
        )  # fmt: skip
        self.state = "accepted"
        self._release()

    def refuse(self, reason: str) -> None:
        """Stop collecting: the start refuses, for ``reason``."""
        self.reason = reason
        self.state = "refused"
        self.info["refused"] = reason
        self._release()

    def _release(self) -> None:
        self._images = []
        self._tracks = None

    def motion_summary(self) -> str:
        """What the frames so far have shown (parallax, homography fit, the last try), for a refusal."""
        ic = self.config.initializer
        tv = self._last
        if tv is None:
            if self.info["checks"] == 0:
                return f"it looks at the motion from frame {ic.min_frames} of the run on (initializer.min_frames)"
            return "the two-view geometry could not be fitted"
        parts = [f"median parallax {tv.parallax_deg:.2f}° (best {self._best_parallax:.2f}°, needs "
                 f"{ic.min_parallax_deg:g}°)"]
        if tv.homography_fraction > ic.max_homography_fraction:
            parts.append(f"a homography explains {100 * tv.homography_fraction:.0f} % of the corners (at most "
                         f"{100 * ic.max_homography_fraction:.0f} %): the camera has rotated without moving enough, "
                         "or the scene is a plane")
        if self._last_try:
            parts.append(f"last try: {self._last_try}")
        return "; ".join(parts)


def _window(k: int, n: int, also: int | None = None) -> list[int]:
    """Up to ``n`` frames of 1…k, evenly spaced, k included (and ``also``, if given)."""
    frames = set(range(1, k + 1)) if k <= n else {int(round(k * (j + 1) / n)) for j in range(n)}
    if also is not None:
        frames.add(also)
    return sorted(frames)


def _disagreement(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Rotation angle between two poses of one frame and the angle between their directions of motion, degrees
    (the scale of two windows differs)."""
    rot = float(np.degrees(Rotation.from_matrix(exact.matmul(a[:3, :3], b[:3, :3].T)).magnitude()))
    ta, tb = a[:3, 3], b[:3, 3]
    c = exact.dot(ta, tb) / max(exact.norm(ta) * exact.norm(tb), 1e-300)
    return rot, float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))
