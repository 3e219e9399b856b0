"""Reference point cloud of the SE(3) tracker (lsd-slam-spec.md §1).

The keyframe's inverse-depth pyramid (:func:`idepth_downsample`: inverse-variance-weighted 2×2 means) and the
points of one level (:func:`make_points`: interior pixels with a depth estimate, back-projected, with their
feature values and variances), numba kernels each with a plain numpy reference (``*_numpy``).
"""

from __future__ import annotations

import numba
import numpy as np

from dmtrack.odometry._lanes import select


@numba.njit(cache=True, nogil=True, error_model="numpy")
def idepth_downsample(idepth: np.ndarray, var: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
    """Inverse-variance-weighted 2×2 mean of the valid (var > 0) children; none valid → (−1, −1).

    ``idepth = Σ(d_i/σ_i²) / Σ(1/σ_i²)``, ``var = n / Σ(1/σ_i²)``. Inputs (h, w) float32, outputs
    (h//2, w//2) float32. Children in the order (0, 0), (0, 1), (1, 0), (1, 1), float64 sums from +0.0; an
    invalid child adds +0.0 (computed, then masked with ``select``), which leaves a sum unchanged, so the row
    loop vectorises and gives the bytes of skipping the invalid children.
    """
    h2 = idepth.shape[0] // 2
    w2 = idepth.shape[1] // 2
    out_d = np.empty((h2, w2), np.float32)
    out_v = np.empty((h2, w2), np.float32)
    for y in range(h2):
        d0, d1 = idepth[2 * y], idepth[2 * y + 1]
        v0, v1 = var[2 * y], var[2 * y + 1]
        od, ov = out_d[y], out_v[y]
        for x in range(w2):
            isum = 0.0
            dsum = 0.0
            num = 0
            for vr, dr, k in ((v0, d0, 2 * x), (v0, d0, 2 * x + 1), (v1, d1, 2 * x), (v1, d1, 2 * x + 1)):
                v = vr[k]
                ok = v > 0
                iv = 1.0 / v
                isum += select(ok, iv, 0.0)
                dsum += select(ok, iv * dr[k], 0.0)
                num += ok
            has = num > 0
            od[x] = select(has, dsum / isum, -1.0)
            ov[x] = select(has, num / isum, -1.0)
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
        dr, vr = idepth[y], var[y]
        for x in range(1, w - 1):
            n += (vr[x] > 0) & (dr[x] != 0)
    pts = np.empty((n, 3), np.float32)
    vals = np.empty((n, nch), np.float32)
    vrs = np.empty(n, np.float32)
    idx = np.empty(n, np.int32)
    xs = np.empty(w, np.int64)
    fxi = 1.0 / fx
    fyi = 1.0 / fy
    cxi = -cx / fx
    cyi = -cy / fy
    k = 0
    for y in range(1, h - 1):
        dr, vr, fr = idepth[y], var[y], feat[y]
        m = 0
        for x in range(1, w - 1):  # the row's kept columns, without a branch per pixel
            xs[m] = x
            m += (vr[x] > 0) & (dr[x] != 0)
        py = fyi * y + cyi
        for j in range(m):
            x = xs[j]
            depth = 1.0 / dr[x]
            pts[k + j, 0] = depth * (fxi * x + cxi)
            pts[k + j, 1] = depth * py
            pts[k + j, 2] = depth
            vrs[k + j] = vr[x]
            idx[k + j] = y * w + x
            for c in range(nch):
                vals[k + j, c] = fr[x, c]
        k += m
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
