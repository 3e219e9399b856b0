"""Reference point cloud of the SE(3) tracker (lsd-slam-spec.md §1).

The keyframe's inverse-depth pyramid (:func:`idepth_downsample`: inverse-variance-weighted 2×2 means) and the
points of one level (:func:`make_points`: interior pixels with a depth estimate, back-projected, with their
feature values and variances), numba kernels each with a plain numpy reference (``*_numpy``).
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, error_model="numpy")
def idepth_downsample(idepth: np.ndarray, var: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
    """Inverse-variance-weighted 2×2 mean of the valid (var > 0) children; none valid → (−1, −1).

    ``idepth = Σ(d_i/σ_i²) / Σ(1/σ_i²)``, ``var = n / Σ(1/σ_i²)``. Inputs (h, w) float32, outputs
    (h//2, w//2) float32.
    """
    h2 = idepth.shape[0] // 2
    w2 = idepth.shape[1] // 2
    out_d = np.empty((h2, w2), np.float32)
    out_v = np.empty((h2, w2), np.float32)
    for y in range(h2):
        for x in range(w2):
            isum = 0.0
            dsum = 0.0
            num = 0
            for dy in range(2):
                for dx in range(2):
                    v = var[2 * y + dy, 2 * x + dx]
                    if v > 0:
                        iv = 1.0 / v
                        isum += iv
                        dsum += iv * idepth[2 * y + dy, 2 * x + dx]
                        num += 1
            if num > 0:
                out_d[y, x] = dsum / isum
                out_v[y, x] = num / isum
            else:
                out_d[y, x] = -1.0
                out_v[y, x] = -1.0
    return out_d, out_v


def idepth_downsample_numpy(idepth: np.ndarray, var: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Numpy reference of :func:`idepth_downsample`."""
    d = idepth.astype(np.float64)
    v = var.astype(np.float64)
    isum = np.zeros((d.shape[0] // 2, d.shape[1] // 2))
    dsum = np.zeros_like(isum)
    num = np.zeros(isum.shape, np.int64)
    for dy in range(2):
        for dx in range(2):
            vv = v[dy::2, dx::2]
            dd = d[dy::2, dx::2]
            ok = vv > 0
            iv = np.where(ok, 1.0 / np.where(ok, vv, 1.0), 0.0)
            isum += iv
            dsum += np.where(ok, iv * dd, 0.0)
            num += ok
    has = num > 0
    safe = np.where(has, isum, 1.0)
    out_d = np.where(has, dsum / safe, -1.0).astype(np.float32)
    out_v = np.where(has, num / safe, -1.0).astype(np.float32)
    return out_d, out_v


@numba.njit(cache=True, nogil=True, error_model="numpy")
def make_points(
    idepth: np.ndarray, var: np.ndarray, feat: np.ndarray, fx: float, fy: float, cx: float, cy: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover
    """Reference point cloud of one level: interior pixels with var > 0 and idepth ≠ 0, row-major order.

    Returns points (n, 3) float32 = (1/d)·K⁻¹(x, y, 1), values (n, N) float32, variances (n,) float32 and the
    flat pixel index y·w + x (n,) int32.
    """
    h, w = idepth.shape
    nch = feat.shape[2]
    n = 0
    for y in range(1, h - 1):
        for x in range(1, w - 1):
            if var[y, x] > 0 and idepth[y, x] != 0:
                n += 1
    pts = np.empty((n, 3), np.float32)
    vals = np.empty((n, nch), np.float32)
    vrs = np.empty(n, np.float32)
    idx = np.empty(n, np.int32)
    fxi = 1.0 / fx
    fyi = 1.0 / fy
    cxi = -cx / fx
    cyi = -cy / fy
    k = 0
    for y in range(1, h - 1):
        for x in range(1, w - 1):
            if var[y, x] > 0 and idepth[y, x] != 0:
                depth = 1.0 / idepth[y, x]
                pts[k, 0] = depth * (fxi * x + cxi)
                pts[k, 1] = depth * (fyi * y + cyi)
                pts[k, 2] = depth
                for c in range(nch):
                    vals[k, c] = feat[y, x, c]
                vrs[k] = var[y, x]
                idx[k] = y * w + x
                k += 1
    return pts, vals, vrs, idx


def make_points_numpy(
    idepth: np.ndarray, var: np.ndarray, feat: np.ndarray, fx: float, fy: float, cx: float, cy: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Numpy reference of :func:`make_points`."""
    h, w = idepth.shape
    mask = np.zeros((h, w), bool)
    mask[1:-1, 1:-1] = (var[1:-1, 1:-1] > 0) & (idepth[1:-1, 1:-1] != 0)
    ys, xs = np.nonzero(mask)  # row-major order
    depth = 1.0 / idepth[ys, xs].astype(np.float64)
    pts = np.stack(
        [depth * (xs * (1.0 / fx) + (-cx / fx)), depth * (ys * (1.0 / fy) + (-cy / fy)), depth], axis=1
    ).astype(np.float32)
    vals = feat[ys, xs, :].astype(np.float32)
    return pts, vals, var[ys, xs].astype(np.float32), (ys * w + xs).astype(np.int32)
