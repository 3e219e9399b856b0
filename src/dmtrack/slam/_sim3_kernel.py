"""The numba kernel of :meth:`dmtrack.slam.sim3_tracker.Sim3Tracker._terms_numpy` (the reference in tests).

One pass over the reference points: warp, bilinear feature and gradient samples, photometric and inverse-depth
residuals with their weights and Huber weight, and the 7×7 normal equations, accumulated in float64.
"""

from __future__ import annotations

import math

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, fastmath=False)
def sim3_terms_kernel(  # pragma: no cover - compiled
    points: np.ndarray,  # (n, 3) float32 reference points (keyframe units)
    values: np.ndarray,  # (n, N) float32 reference feature values
    variances: np.ndarray,  # (n,) float32 reference inverse-depth variances
    feat: np.ndarray,  # (h, w, N) float32 other keyframe's features
    gxm: np.ndarray,  # (h, w, N) float32 its x-gradients
    gym: np.ndarray,  # (h, w, N)
    d_map: np.ndarray,  # (h, w) float32 its inverse depth
    var_map: np.ndarray,  # (h, w) float32 its variance (≤ 0: none)
    M: np.ndarray,  # (3, 3) float64 s·R
    t: np.ndarray,  # (3,) float64
    prm: np.ndarray,  # fx, fy, cx, cy, var_weight, pixel_noise2, huber_d, rule
    A: np.ndarray,  # (7, 7) float64 out
    b: np.ndarray,  # (7,) float64 out
) -> tuple[int, int, float, float, float]:
    fx, fy, cx, cy = prm[0], prm[1], prm[2], prm[3]
    var_weight, noise2, huber_d, rule = prm[4], prm[5], prm[6], prm[7]
    h, w, nch = feat.shape
    A[:] = 0.0
    b[:] = 0.0
    n_in = 0
    n_d = 0
    sum_p = 0.0
    sum_d = 0.0
    usage = 0.0
    F = np.empty(nch)
    GX = np.empty(nch)
    GY = np.empty(nch)
    ju = np.empty(7)
    jv = np.empty(7)
    jd = np.empty(7)
    jc = np.empty(7)
    for i in range(points.shape[0]):
        px, py, pz = float(points[i, 0]), float(points[i, 1]), float(points[i, 2])
        x = M[0, 0] * px + M[0, 1] * py + M[0, 2] * pz + t[0]
        y = M[1, 0] * px + M[1, 1] * py + M[1, 2] * pz + t[1]
        z = M[2, 0] * px + M[2, 1] * py + M[2, 2] * pz + t[2]
        if not z > 0.0:
            continue
        u = x / z * fx + cx
        v = y / z * fy + cy
        if not (u > 1.0 and v > 1.0 and u < w - 2 and v < h - 2):
            continue
        n_in += 1
        x0 = int(math.floor(u))
        y0 = int(math.floor(v))
        ax = u - x0
        ay = v - y0
        w00 = (1.0 - ay) * (1.0 - ax)
        w01 = (1.0 - ay) * ax
        w10 = ay * (1.0 - ax)
        w11 = ay * ax
        for c in range(nch):
            F[c] = (w00 * feat[y0, x0, c] + w01 * feat[y0, x0 + 1, c] + w10 * feat[y0 + 1, x0, c]
                    + w11 * feat[y0 + 1, x0 + 1, c])
            GX[c] = (w00 * gxm[y0, x0, c] + w01 * gxm[y0, x0 + 1, c] + w10 * gxm[y0 + 1, x0, c]
                     + w11 * gxm[y0 + 1, x0 + 1, c]) * fx
            GY[c] = (w00 * gym[y0, x0, c] + w01 * gym[y0, x0 + 1, c] + w10 * gym[y0 + 1, x0, c]
                     + w11 * gym[y0 + 1, x0 + 1, c]) * fy
        d_ref = 1.0 / pz
        zz = z * z * d_ref
        g0 = (t[0] * z - t[2] * x) / zz
        g1 = (t[1] * z - t[2] * y) / zz
        g2 = (z - t[2]) / zz
        s_ref = var_weight * float(variances[i])
        e_p2 = 0.0
        for c in range(nch):
            r = float(values[i, c]) - F[c]
            dd = GX[c] * g0 + GY[c] * g1
            wp = 1.0 / (noise2 + s_ref * dd * dd)
            e_p2 += wp * r * r
        e_p2 *= rule
        e_p = math.sqrt(e_p2)
        ui = int(u + 0.5)
        vi = int(v + 0.5)
        var_d = float(var_map[vi, ui])
        r_d = 0.0
        w_d = 0.0
        if var_d > 0.0:
            r_d = 1.0 / z - float(d_map[vi, ui])
            w_d = 1.0 / (var_weight * var_d + g2 * g2 * s_ref)
            n_d += 1
        e_d = abs(r_d) * math.sqrt(w_d)
        e = e_p + e_d
        hub = 1.0 if e < huber_d else huber_d / max(e, 1e-30)
        sum_p += hub * e_p2
        sum_d += hub * e_d * e_d
        usage += min(1.0, pz / z)
        iz = 1.0 / z
        iz2 = iz * iz
        ju[0] = iz
        ju[1] = 0.0
        ju[2] = -x * iz2
        ju[3] = -x * y * iz2
        ju[4] = 1.0 + x * x * iz2
        ju[5] = -y * iz
        ju[6] = 0.0
        jv[0] = 0.0
        jv[1] = iz
        jv[2] = -y * iz2
        jv[3] = -(1.0 + y * y * iz2)
        jv[4] = x * y * iz2
        jv[5] = x * iz
        jv[6] = 0.0
        for c in range(nch):
            r = float(values[i, c]) - F[c]
            dd = GX[c] * g0 + GY[c] * g1
            wp = hub * rule / (noise2 + s_ref * dd * dd)
            for j in range(7):
                jc[j] = -(GX[c] * ju[j] + GY[c] * jv[j])
            for j in range(7):
                wj = wp * jc[j]
                b[j] += wj * r
                for k in range(j, 7):
                    A[j, k] += wj * jc[k]
        if w_d > 0.0:
            jd[0] = 0.0
            jd[1] = 0.0
            jd[2] = -iz2
            jd[3] = -y * iz2
            jd[4] = x * iz2
            jd[5] = 0.0
            jd[6] = -iz
            wd = hub * w_d
            for j in range(7):
                wj = wd * jd[j]
                b[j] += wj * r_d
                for k in range(j, 7):
                    A[j, k] += wj * jd[k]
    for j in range(7):
        for k in range(j):
            A[j, k] = A[k, j]
    return n_in, n_d, sum_p, sum_d, usage


def warm_up_kernel() -> None:
    """Compile the kernel (or load it from numba's cache) on a tiny input, before a timed run."""
    pts = np.array([[0.0, 0.0, 1.0]], np.float32)
    feat = np.zeros((8, 8, 1), np.float32)
    sim3_terms_kernel(pts, np.zeros((1, 1), np.float32), np.ones(1, np.float32), feat, feat, feat,
                      np.zeros((8, 8), np.float32), np.zeros((8, 8), np.float32), np.eye(3), np.zeros(3),
                      np.array([4.0, 4.0, 3.5, 3.5, 1.0, 16.0, 3.0, 1.0]), np.empty((7, 7)), np.empty(7))
