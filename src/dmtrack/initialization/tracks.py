"""Corners of the first frame tracked through the following frames (OpenCV's pyramidal KLT).

Each track starts at a corner of the first frame (``cv2.goodFeaturesToTrack``) and follows it frame to frame
(``cv2.calcOpticalFlowPyrLK``). A track ends for good when the tracker loses it, when tracking it back from the new
frame does not land within ``max_fb_error`` of where it started (the forward-backward check), or when it leaves the
image. A track that ended is never resumed, so every observation of a track is of the same corner.
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["CornerTracks"]


class CornerTracks:
    """The corners of a first frame and where they are in every frame since.

    Parameters
    ----------
    image : (H, W) uint8
        The first frame, grey.
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
        The corners in the first frame (x, y).
    alive : (n,) bool
        Tracks still followed.
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
        grey = _grey_u8(image)
        found = cv2.goodFeaturesToTrack(grey, int(corners), 0.005, float(min_distance), blockSize=7)
        self.first = np.zeros((0, 2), np.float32) if found is None else found.reshape(-1, 2).astype(np.float32)
        self.alive = np.ones(len(self.first), bool)
        self._obs: list[np.ndarray] = [self.first.copy()]
        self._prev = grey
        self._current = self.first.copy()
        self._lk = {
            "winSize": (int(window), int(window)),
            "maxLevel": int(levels),
            "criteria": (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01),
        }
        self._max_fb = float(max_fb_error)

    def __len__(self) -> int:
        """Frames seen, the first included."""
        return len(self._obs)

    @property
    def n_alive(self) -> int:
        """Tracks still followed."""
        return int(np.count_nonzero(self.alive))

    def add(self, image: np.ndarray) -> int:
        """Follow the live tracks into the next frame; return how many are still alive."""
        grey = _grey_u8(image)
        idx = np.flatnonzero(self.alive)
        obs = np.full_like(self.first, np.nan)
        if len(idx):
            pts = np.ascontiguousarray(self._current[idx])
            nxt, st, _ = cv2.calcOpticalFlowPyrLK(self._prev, grey, pts, None, **self._lk)
            back, st_back, _ = cv2.calcOpticalFlowPyrLK(grey, self._prev, nxt, None, **self._lk)
            h, w = grey.shape
            ok = (st[:, 0] == 1) & (st_back[:, 0] == 1) & np.all(np.isfinite(nxt), axis=1)
            ok &= np.linalg.norm(back - pts, axis=1) < self._max_fb
            ok &= (nxt[:, 0] >= 0) & (nxt[:, 0] <= w - 1) & (nxt[:, 1] >= 0) & (nxt[:, 1] <= h - 1)
            self.alive[idx[~ok]] = False
            good = idx[ok]
            self._current[good] = nxt[ok]
            obs[good] = nxt[ok]
        self._obs.append(obs)
        self._prev = grey
        return self.n_alive

    def observations(self, frame: int) -> np.ndarray:
        """(n, 2) float32: where each track is in ``frame`` (0 = the first), NaN where it had ended."""
        return self._obs[frame]


def _grey_u8(image: np.ndarray) -> np.ndarray:
    """A contiguous uint8 grey image (RGB is converted as the grey feature does)."""
    a = np.asarray(image)
    if a.ndim == 3:
        a = cv2.cvtColor(np.ascontiguousarray(a), cv2.COLOR_RGB2GRAY)
    if a.dtype != np.uint8:
        a = np.clip(np.rint(a), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(a)
