"""The geometric start: when the first frames have shown enough translation, make the first keyframe's map.

:class:`GeometricInitializer` is fed the run's frames one by one, from its first (:meth:`~GeometricInitializer.add`)
and answers, after each, whether it has finished:

1. the corners of a *reference* frame (the run's first, at first) are tracked into every new frame
   (:class:`~dmtrack.initialization.tracks.CornerTracks`); when fewer than ``redetect_below`` are left (forward
   motion carries them out of the image), new corners of the newest frame are followed back to the reference;
2. from ``min_frames`` after the reference on, every quarter of the window so far (8, 10, 12, 15, 18, 22, … by
   default), the two-view geometry of the reference and the newest frame is fitted
   (:func:`~dmtrack.initialization.twoview.two_view`). The window is tried once the corners' median parallax reaches
   ``min_parallax_deg``, a homography no longer explains more than ``max_homography_fraction`` of them, and enough
   corners agree: ``min_inliers``, or ``min_spread_inliers`` when they span the image (``spread_cells``);
3. a try: the poses of up to ``map_frames`` frames of the window (evenly spaced, the newest included) and the
   corners' inverse depths are bundle-adjusted (:func:`~dmtrack.initialization.bundle.bundle_adjust`); the try
   holds when enough corners survive, their median reprojection error is at most ``max_reprojection_px`` and the
   adjusted parallax still reaches ``min_parallax_deg``;
4. a try that holds is accepted only when the next one confirms it: both windows agree on the newest frame of the
   earlier within ``agree_rot_deg`` of rotation and ``agree_tdir_deg`` in the direction of motion (a short
   baseline can fit a wrong motion about as well as the right one; a wrong one does not last);
5. then the first map is made from the later window's frames
   (:func:`~dmtrack.initialization.first_map.make_first_map`) and the start has *accepted*; the odometry begins at
   the reference frame with that map and tracks every frame from there, the window's included.

It tells **waiting** (too little parallax yet, or a motion a homography still explains: the camera has not moved
enough — more frames will do) from **cannot be fitted from this reference** (too few corners left even after new
ones were followed back; ``max_unfit`` tries in a row whose bundle adjustment failed or whose windows disagreed): the
latter starts again from a later reference frame, the newest (DSO's coarse initialiser likewise begins anew). Frames
before the reference the start accepted get no pose from the odometry. It *refuses* — with a message saying what was
missing — only when ``max_frames`` frames have passed since the run's first without an accepted window; the caller
then starts from LSD-SLAM's random map and records the refusal in ``metrics.json``.

Deterministic: OpenCV's MAGSAC++ (and RANSAC) seed their own generators, the rest is plain arithmetic.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from dmtrack.errors import InputError
from dmtrack.features.images import prepare_image
from dmtrack.geometry import exact
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.geometry.scipy_rotation import magnitude_of_matrix, slerp_from_identity
from dmtrack.initialization.bundle import bundle_adjust
from dmtrack.initialization.first_map import grey_frame, make_first_map
from dmtrack.initialization.tracks import CornerTracks, grid_coverage
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
        self._ref = 0  # position of the reference frame in _images
        self._next_check = self.config.initializer.min_frames
        self._last: TwoView | None = None
        self._best_parallax = 0.0
        self._last_try: str | None = None
        self._prev: tuple[list[int], np.ndarray] | None = None  # the last try's window and its adjusted poses
        self._unfit = 0  # tries in a row that could not be fitted from this reference
        self._last_redetect = -1
        self._seconds = 0.0
        self.info: dict[str, Any] = {"checks": 0, "tries": 0, "references": [], "redetected": 0}

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
        # the grey image is all the start uses (corners, the first map): a third of an RGB frame's memory
        self._images.append(prepare_image(image, colour=False))
        self._indices.append(index)
        self._timestamps.append(timestamp)
        k = len(self._indices) - 1
        if self._tracks is None:
            self._new_reference(k)
        else:
            self._follow(k)
            if k >= self._next_check and self._tracks is not None:
                self._next_check = k + max(1, (k - self._ref) // 4)
                if self._check(k) and self._try(k):
                    return
        if k >= ic.max_frames:
            self.refuse(f"no window of frames {self._indices[0]}–{index} gave the start what it needs: "
                         f"{self.motion_summary()}")

    def _new_reference(self, k: int) -> None:
        """Start again from frame k: its corners, a fresh window (the frames before it are no longer used)."""
        ic = self.config.initializer
        self._tracks = CornerTracks(
            self._images[k], ic.corners, ic.corner_distance, ic.klt_window, ic.klt_levels, ic.max_fb_error
        )
        self._ref = k
        self._next_check = k + ic.min_frames
        self._prev = None
        self._unfit = 0
        self._last_redetect = k
        self.info["references"].append(self._indices[k])
        for i in range(k):  # the start no longer needs the frames before its reference
            self._images[i] = None  # type: ignore[call-overload]

    def _follow(self, k: int) -> None:
        """Follow the tracks into frame k; new corners when they run low; a new reference when they are too few."""
        ic = self.config.initializer
        assert self._tracks is not None
        alive = self._tracks.add(self._images[k])
        if alive < ic.redetect_below and k - self._last_redetect >= 2:
            self._last_redetect = k
            self.info["redetected"] += self._tracks.redetect()
        if not self._enough(self._tracks.current()):
            self._last_try = (f"only {self._tracks.n_alive} corners of frame {self._indices[self._ref]} could be "
                              f"followed to frame {self._indices[k]}")  # fmt: skip
            self._new_reference(k)

    def _enough(self, points: np.ndarray) -> bool:
        """Whether corners at ``points`` (n, 2) are enough: ``min_inliers`` of them, or ``min_spread_inliers`` that
        span the image (``spread_cells`` of its 3 × 3 cells hold 3 or more)."""
        ic = self.config.initializer
        n = len(points)
        if n >= ic.min_inliers:
            return True
        cover = grid_coverage(points, self.camera.width, self.camera.height)
        return n >= ic.min_spread_inliers and cover * 9 >= ic.spread_cells - 1e-9

    def _unfit_try(self, k: int, why: str) -> bool:
        """Record a try that could not be fitted; after ``max_unfit`` in a row, start again from frame k."""
        self._last_try = why
        self._unfit += 1
        if self._unfit >= self.config.initializer.max_unfit:
            self._last_try = f"{why}; {self._unfit} tries from frame {self._indices[self._ref]} could not be fitted"
            self._new_reference(k)
        return False

    def _check(self, k: int) -> bool:
        """Fit the two-view geometry of frames 0 and k; whether the window is worth a try."""
        ic = self.config.initializer
        assert self._tracks is not None
        alive = np.flatnonzero(self._tracks.alive)
        obs = self._tracks.observations(k - self._ref)
        tv = two_view(self._tracks.first[alive], obs[alive], self._K, ic.ransac_px, ic.min_spread_inliers,
                      ic.essential)
        self.info["checks"] += 1
        if tv is None:
            return False
        tv = TwoView(tv.R, tv.t, alive[tv.inliers], tv.idepth, tv.parallax_deg, tv.homography_fraction,
                     tv.homography_stretch)
        self._last = tv
        self._best_parallax = max(self._best_parallax, tv.parallax_deg)
        return (
            tv.parallax_deg >= ic.min_parallax_deg
            and (tv.homography_fraction <= ic.max_homography_fraction or tv.homography_stretch >= ic.min_plane_stretch)
            and self._enough(obs[tv.inliers])
        )

    def _try(self, k: int) -> bool:
        """Bundle-adjust the window up to frame k and, if it holds, make the first map; whether it accepted."""
        ic = self.config.initializer
        tv = self._last
        assert tv is not None and self._tracks is not None
        self.info["tries"] += 1
        r = self._ref
        window = [r + i for i in _window(k - r, ic.map_frames, None if self._prev is None else self._prev[0][-1] - r)]
        idx = tv.inliers
        rho = np.array(tv.idepth, np.float64)
        good = np.isfinite(rho)
        if not good.any():
            return False
        med = float(np.median(rho[good]))
        rho = np.clip(np.where(good, rho, med), 1e-2 * med, 1e2 * med)
        s = float(np.mean(rho))
        rho /= s
        poses = np.tile(np.eye(4), (len(window), 1, 1))
        turns = slerp_from_identity(tv.R, np.array([(i - r) / (k - r) for i in window]))
        for n, i in enumerate(window):
            poses[n, :3, :3] = turns[n]
            poses[n, :3, 3] = tv.t * s * ((i - r) / (k - r))
        first = self._tracks.first[idx]
        obs = [self._tracks.observations(i - r)[idx] for i in window]
        ba = bundle_adjust(self._K, first, obs, poses, rho)
        n_kept = int(np.count_nonzero(ba.kept))
        T = ba.poses[-1]
        par = ray_parallax_deg(first[ba.kept], ba.idepth[ba.kept], self._K, T[:3, :3], T[:3, 3])
        par_med = float(np.median(par)) if len(par) else 0.0
        self.info.update(
            ba_corners=n_kept, ba_error_px=round(ba.median_error_px, 4), parallax_deg=round(par_med, 4),
            homography_fraction=round(tv.homography_fraction, 4),
        )  # fmt: skip
        if not self._enough(first[ba.kept]):
            return self._unfit_try(k, f"the bundle adjustment kept {n_kept} corners")
        if not ba.median_error_px <= ic.max_reprojection_px:
            return self._unfit_try(k, f"the bundle adjustment left {ba.median_error_px:.2f} px")
        if par_med < ic.min_parallax_deg:
            self._last_try = f"the adjusted parallax is {par_med:.2f}°"  # waiting: not moved enough yet
            return False
        prev, self._prev = self._prev, (window, ba.poses.copy())
        self._unfit = 0
        if prev is None:
            self._last_try = "a first window held; the start waits for a later one to confirm it"
            return False
        last = prev[0][-1]
        rot, tdir = _disagreement(prev[1][-1], ba.poses[window.index(last)])
        self.info.update(agreement_rot_deg=round(rot, 4), agreement_tdir_deg=round(tdir, 3))
        if rot > ic.agree_rot_deg or tdir > ic.agree_tdir_deg:
            return self._unfit_try(k, f"two windows disagreed on frame {self._indices[last]} by {rot:.2f}° in "
                                      f"rotation and {tdir:.1f}° in the direction of motion")
        self._accept(window, list(ba.poses), k)  # the later, confirmed window makes the map
        return True

    def _accept(self, window: list[int], poses: list[np.ndarray], k: int) -> None:
        levels = self.config.pyramid_levels
        r = self._ref
        kf = grey_frame(self._indices[r], self._timestamps[r], self._images[r], self.camera, levels)
        frames = [grey_frame(self._indices[i], self._timestamps[i], self._images[i], self.camera, levels)
                  for i in window]
        m, _ = make_first_map(kf, frames, poses, self.config, parallel=self.parallel)
        self.info.update(accepted_frame=self._indices[k], reference_frame=self._indices[r],
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
    rot = float(np.degrees(magnitude_of_matrix(exact.matmul(a[:3, :3], b[:3, :3].T))))
    ta, tb = a[:3, 3], b[:3, 3]
    c = exact.dot(ta, tb) / max(exact.norm(ta) * exact.norm(tb), 1e-300)
    return rot, float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))
