"""Corners of a reference frame tracked through the following frames (OpenCV's pyramidal KLT).

Each track starts at a corner of the reference frame (``cv2.goodFeaturesToTrack``) and follows it frame to frame
(``cv2.calcOpticalFlowPyrLK``). A track ends for good when the tracker loses it, when tracking it back from the new
frame does not land within ``max_fb_error`` of where it started (the forward-backward check), or when it leaves the
image. A track that ended is never resumed, so every observation of a track is of the same corner.

Corners leave the image fast under forward motion (a car's camera at 10 Hz loses most of them within ten frames).
:meth:`CornerTracks.redetect` then finds new corners in the newest frame, away from the live tracks, and follows
them *back* frame by frame to the reference frame, with the same checks: those that make it (they were in view all
along, as most are when the camera moves forward) become tracks with an observation in every frame, as if they had
been detected in the reference frame.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["CornerTracks", "follow_forward_backward", "grey_u8", "grid_coverage", "klt_parameters"]


def grid_coverage(points: np.ndarray, width: int, height: int, cells: int = 3, per_cell: int = 3) -> float:
    """Fraction of the ``cells`` × ``cells`` cells of the image holding at least ``per_cell`` of ``points`` (n, 2):
    how well a set of corners spans the image."""
    pts = np.asarray(points, np.float64).reshape(-1, 2)
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    if len(pts) == 0:
        return 0.0
    cx = np.clip((pts[:, 0] * cells / max(width, 1)).astype(np.int64), 0, cells - 1)
    cy = np.clip((pts[:, 1] * cells / max(height, 1)).astype(np.int64), 0, cells - 1)
    counts = np.bincount(cy * cells + cx, minlength=cells * cells)
    return float(np.count_nonzero(counts >= per_cell)) / (cells * cells)


class CornerTracks:
    """The corners of a reference frame and where they are in every frame since.

    Parameters
    ----------
    image : (H, W) uint8
        The reference frame, grey (or RGB, converted as the grey feature does).
    corners : int
        Corners to detect (the strongest, at least ``min_distance`` apart).
    min_distance : float
        Smallest distance between two corners, pixels.
    window : int
        KLT window side, pixels.
    levels : int
        KLT pyramid levels above the image.
    max_fb_error : float
        Largest forward-backward error a track may have, pixels.

    Attributes
    ----------
    first : (n, 2) float32
        The corners in the reference frame (x, y).
    alive : (n,) bool
        Tracks still followed.
    redetected : int
        Tracks added by :meth:`redetect`.
    """

    def __init__(
        self,
        image: np.ndarray,
        corners: int = 600,
        min_distance: float = 8.0,
        window: int = 21,
        levels: int = 3,
        max_fb_error: float = 0.5,
    ) -> None:
        grey = grey_u8(image)
        self._corners, self._min_distance = int(corners), float(min_distance)
        self.first = _detect(grey, self._corners, self._min_distance, None)
        self.alive = np.ones(len(self.first), bool)
        self.redetected = 0
        self._obs: list[np.ndarray] = [self.first.copy()]
        self._greys: list[np.ndarray] = [grey]
        self._current = self.first.copy()
        self._lk = klt_parameters(window, levels)
        self._max_fb = float(max_fb_error)

    def __len__(self) -> int:
        """Frames seen, the reference included."""
        return len(self._obs)

    @property
    def n_alive(self) -> int:
        """Tracks still followed."""
        return int(np.count_nonzero(self.alive))

    def _follow(self, a: np.ndarray, b: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``pts`` of image ``a`` in image ``b`` and which survived the KLT, forward-backward and bounds checks."""
        nxt, ok = follow_forward_backward(a, b, pts, self._lk, self._max_fb)
        h, w = b.shape
        ok &= np.all(np.isfinite(nxt), axis=1)
        ok &= (nxt[:, 0] >= 0) & (nxt[:, 0] <= w - 1) & (nxt[:, 1] >= 0) & (nxt[:, 1] <= h - 1)
        return nxt, ok

    def add(self, image: np.ndarray) -> int:
        """Follow the live tracks into the next frame; return how many are still alive."""
        grey = grey_u8(image)
        idx = np.flatnonzero(self.alive)
        obs = np.full_like(self.first, np.nan)
        if len(idx):
            nxt, ok = self._follow(self._greys[-1], grey, np.ascontiguousarray(self._current[idx]))
            self.alive[idx[~ok]] = False
            good = idx[ok]
            self._current[good] = nxt[ok]
            obs[good] = nxt[ok]
        self._obs.append(obs)
        self._greys.append(grey)
        return self.n_alive

    def redetect(self, max_new: int | None = None) -> int:
        """New corners of the newest frame, at least ``min_distance`` from every live track, followed back frame by
        frame to the reference frame; those that make it join the tracks (live, observed in every frame). Returns
        how many joined."""
        if len(self._obs) < 2:
            return 0
        newest = self._greys[-1]
        mask = np.full(newest.shape, 255, np.uint8)
        for x, y in self._current[self.alive]:
            cv2.circle(mask, (int(round(float(x))), int(round(float(y)))), int(np.ceil(self._min_distance)), 0, -1)
        pts = _detect(newest, self._corners if max_new is None else int(max_new), self._min_distance, mask)
        if len(pts) == 0:
            return 0
        path = [pts]
        keep = np.arange(len(pts))
        for j in range(len(self._greys) - 1, 0, -1):  # back to the reference, one frame at a time
            prev, ok = self._follow(self._greys[j], self._greys[j - 1], np.ascontiguousarray(path[-1]))
            keep, path = keep[ok], [p[ok] for p in path]
            path.append(prev[ok])
            if len(keep) == 0:
                return 0
        path.reverse()  # path[j]: the kept corners in frame j (0 = the reference)
        n = len(keep)
        self.first = np.concatenate([self.first, path[0]])
        self.alive = np.concatenate([self.alive, np.ones(n, bool)])
        self._current = np.concatenate([self._current, path[-1]])
        self._obs = [np.concatenate([o, p]) for o, p in zip(self._obs, path, strict=True)]
        self.redetected += n
        return n

    def observations(self, frame: int) -> np.ndarray:
        """(n, 2) float32: where each track is in ``frame`` (0 = the reference), NaN where it had ended."""
        return self._obs[frame]

    def current(self) -> np.ndarray:
        """(n_alive, 2) float32: the live tracks in the newest frame."""
        return self._current[self.alive]


def klt_parameters(window: int, levels: int) -> dict:
    """OpenCV's pyramidal KLT settings: a ``window`` × ``window`` patch, ``levels`` pyramid levels above the image, at
    most 30 iterations or a step under 0.01 px."""
    return {"winSize": (int(window), int(window)), "maxLevel": int(levels),
            "criteria": (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)}  # fmt: skip


def follow_forward_backward(
    a: np.ndarray, b: np.ndarray, pts: np.ndarray, lk: dict, max_fb_error: float
) -> tuple[np.ndarray, np.ndarray]:
    """``pts`` (float32, (n, 2)) of grey image ``a`` followed into ``b`` by KLT (``lk``: :func:`klt_parameters`), and
    which were found both ways and came back to within ``max_fb_error`` px of where they started."""
    nxt, st, _ = cv2.calcOpticalFlowPyrLK(a, b, pts, None, **lk)
    back, st_back, _ = cv2.calcOpticalFlowPyrLK(b, a, nxt, None, **lk)
    ok = (st[:, 0] == 1) & (st_back[:, 0] == 1) & (np.linalg.norm(back - pts, axis=1) < max_fb_error)
    return nxt, ok


def _detect(grey: np.ndarray, corners: int, min_distance: float, mask: np.ndarray | None) -> np.ndarray:
    found = cv2.goodFeaturesToTrack(grey, int(corners), 0.005, float(min_distance), mask=mask, blockSize=7)
    return np.zeros((0, 2), np.float32) if found is None else found.reshape(-1, 2).astype(np.float32)


def grey_u8(image: np.ndarray) -> np.ndarray:
    """A contiguous uint8 grey image for OpenCV's corner detector and KLT: RGB (an alpha channel ignored) is
    converted as the grey feature does; a float image is rounded, after scaling by 255 when it is on a 0–1 scale
    (its largest value at most 1.5). A sequence's uint8 frames go through unchanged in value."""
    a = np.asarray(image)
    if a.ndim == 3:
        rgb = np.ascontiguousarray(a[..., :3])
        a = cv2.cvtColor(rgb if rgb.dtype == np.uint8 else rgb.astype(np.float32), cv2.COLOR_RGB2GRAY)
    if a.dtype != np.uint8:
        scale = 255.0 if float(np.nanmax(a, initial=0.0)) <= 1.5 else 1.0
        a = np.clip(np.rint(np.nan_to_num(a * scale)), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(a)
