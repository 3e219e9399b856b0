"""Corner tracks over a sequence's keyframes, for :func:`dmtrack.calibration.bundle.self_calibrate`.

Corners (OpenCV's ``goodFeaturesToTrack``) are followed from one keyframe to the next by pyramidal KLT, kept only when
the backward track returns within ``max_fb_error`` pixels. Each position is then refined against the track's *first*
image (KLT from the corner as first seen, started at the forward track's position, and kept within 1 px of it), so a
track does not accumulate the small drift of chained KLT steps; frame-to-frame tracking drifts by about 0.3 px over
20 frames and 1 px over 80 on a rendered sequence with known correspondences, and an outward part of that drift
lengthens the focal length. New corners are detected, away from the live tracks, when fewer than 70 % of ``corners``
are left.
"""

from __future__ import annotations

from collections.abc import Iterable

import cv2
import numpy as np

from dmtrack.calibration.bundle import Observations

__all__ = ["track_keyframes"]


def _grey_u8(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 3:
        rgb = np.ascontiguousarray(img[..., :3])
        img = rgb.mean(axis=2) if img.dtype != np.uint8 else cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    if img.dtype != np.uint8:
        scale = 255.0 if float(np.nanmax(img, initial=0.0)) <= 1.5 else 1.0
        img = np.clip(np.nan_to_num(img * scale), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(img)


def track_keyframes(
    images: Iterable[np.ndarray],
    *,
    corners: int = 400,
    min_distance: int = 10,
    window: int = 21,
    levels: int = 3,
    max_fb_error: float = 0.5,
) -> Observations:
    """Corner tracks through ``images`` (the keyframes, in order: grey or colour, uint8 or float); the observations'
    ``camera`` is the index in ``images``, ``point`` the track."""
    lk = {"winSize": (int(window), int(window)), "maxLevel": int(levels),
          "criteria": (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01)}  # fmt: skip
    greys: list[np.ndarray] = []
    pts = np.zeros((0, 2), np.float32)
    ids = np.zeros(0, np.int64)
    first_pts = np.zeros((0, 2), np.float32)
    first_k = np.zeros(0, np.int64)
    out_p: list[np.ndarray] = []
    out_c: list[np.ndarray] = []
    out_uv: list[np.ndarray] = []
    next_id = 0
    for k, image in enumerate(images):
        grey = _grey_u8(image)
        greys.append(grey)
        h, w = grey.shape
        if k > 0 and len(pts):
            nxt, st, _ = cv2.calcOpticalFlowPyrLK(greys[k - 1], grey, pts, None, **lk)
            back, st_back, _ = cv2.calcOpticalFlowPyrLK(grey, greys[k - 1], nxt, None, **lk)
            ok = (st[:, 0] == 1) & (st_back[:, 0] == 1) & (np.linalg.norm(back - pts, axis=1) < max_fb_error)
            refined = nxt.copy()
            for fk in np.unique(first_k[ok]):
                m = np.flatnonzero(ok & (first_k == fk))
                r, s, _ = cv2.calcOpticalFlowPyrLK(greys[fk], grey, first_pts[m], nxt[m].copy(),
                                                   flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk)  # fmt: skip
                good = (s[:, 0] == 1) & (np.linalg.norm(r - nxt[m], axis=1) < 1.0)
                refined[m[good]] = r[good]
                ok[m[~good]] = False
            ok &= (refined[:, 0] >= 0) & (refined[:, 0] <= w - 1) & (refined[:, 1] >= 0) & (refined[:, 1] <= h - 1)
            pts, ids, first_pts, first_k = refined[ok], ids[ok], first_pts[ok], first_k[ok]
        if len(pts) < 0.7 * corners:
            mask = np.full(grey.shape, 255, np.uint8)
            for x, y in pts:
                cv2.circle(mask, (int(x), int(y)), int(min_distance), 0, -1)
            new = cv2.goodFeaturesToTrack(grey, int(corners) - len(pts), 0.01, float(min_distance), mask=mask)
            if new is not None:
                new = new.reshape(-1, 2).astype(np.float32)
                pts = np.vstack([pts, new])
                ids = np.r_[ids, np.arange(next_id, next_id + len(new))]
                next_id += len(new)
                first_pts = np.vstack([first_pts, new])
                first_k = np.r_[first_k, np.full(len(new), k)]
        out_p.append(ids.copy())
        out_c.append(np.full(len(ids), k, np.int64))
        out_uv.append(pts.astype(np.float64))
    if not out_p:
        return Observations(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 2)))
    return Observations(np.concatenate(out_p), np.concatenate(out_c), np.concatenate(out_uv))
