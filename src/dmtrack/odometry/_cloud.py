"""A keyframe's semi-dense points in the world, with their colours: :meth:`KeyframeSnapshot.points_world
<dmtrack.odometry.sink.KeyframeSnapshot.points_world>`.

:func:`points_world_numpy` is the reference (numpy, a handful of full-size temporaries); :func:`points_world_numba`
gives the same bytes in two passes over the map (count, then fill), without the temporaries: a keyframe has 100,000
to 150,000 points and the run folder writes every keyframe's, so this sat on the odometry's thread for 5–8 ms a
keyframe. The arithmetic is the reference's, in its order: the inverse depth to float64, ``d = 1 / ρ``,
``X = ((x − c_x) / f_x · d, (y − c_y) / f_y · d, d)``, then ``S·X`` summed as numpy's ``einsum`` sums three terms
here — ``(s_j0·X_0 + s_j2·X_2) + s_j1·X_1`` — plus the translation; the variance bound is compared in float32, as
numpy compares a float32 array with a Python float.
"""

from __future__ import annotations

import numba
import numpy as np


def points_world_numpy(idepth: np.ndarray, var: np.ndarray, image: np.ndarray | None, max_var: float | None,
                       K: tuple[float, ...], S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """World points (M, 3) float64 and colours (M, 3) uint8 of the pixels with var > 0, inverse depth > 0 (and var ≤
    ``max_var``), in row-major order. ``K`` = (f_x, f_y, c_x, c_y), ``S`` the (4, 4) Sim(3) keyframe → world."""
    fx, fy, cx, cy = K
    m = (var > 0) & (idepth > 0)
    if max_var is not None:
        m &= var <= max_var
    ys, xs = np.nonzero(m)
    d = 1.0 / idepth[ys, xs].astype(np.float64)
    Xk = np.stack([(xs - cx) / fx * d, (ys - cy) / fy * d, d], axis=1)
    # einsum's own loop, not BLAS: a multi-threaded BLAS call here leaves BLAS threads spinning beside numba's
    # kernels (measured: −17 % fps of a grey run with default outputs on 2 cores)
    pts = np.einsum("nk,jk->nj", Xk, S[:3, :3]) + S[:3, 3]
    if image is None:
        col = np.full((len(xs), 3), 128, np.uint8)
    elif image.ndim == 2:
        col = np.repeat(image[ys, xs][:, None], 3, axis=1).astype(np.uint8)
    else:
        col = image[ys, xs, :3].astype(np.uint8)
    return pts, col


@numba.njit(cache=True, nogil=True)
def _fill(idepth, var, image, bounded, max_var, fx, fy, cx, cy, S):  # pragma: no cover - compiled
    h, w = idepth.shape
    n = 0
    for y in range(h):
        for x in range(w):
            v = var[y, x]
            if v > 0 and idepth[y, x] > 0 and (not bounded or v <= max_var):
                n += 1
    pts = np.empty((n, 3), np.float64)
    col = np.empty((n, 3), np.uint8)
    k = 0
    for y in range(h):
        for x in range(w):
            v = var[y, x]
            rho = idepth[y, x]
            if not (v > 0 and rho > 0 and (not bounded or v <= max_var)):
                continue
            d = 1.0 / np.float64(rho)
            X0 = (x - cx) / fx * d
            X1 = (y - cy) / fy * d
            for j in range(3):
                pts[k, j] = (X0 * S[j, 0] + d * S[j, 2]) + X1 * S[j, 1] + S[j, 3]
            if image.ndim == 3:
                for c in range(3):
                    col[k, c] = image[y, x, c]
            elif image.shape[0] == h:
                g = image[y, x]
                col[k, 0] = g
                col[k, 1] = g
                col[k, 2] = g
            else:  # no image: mid-grey
                col[k, 0] = 128
                col[k, 1] = 128
                col[k, 2] = 128
            k += 1
    return pts, col


def points_world_numba(idepth: np.ndarray, var: np.ndarray, image: np.ndarray | None, max_var: float | None,
                       K: tuple[float, ...], S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """:func:`points_world_numpy`, the same bytes, in one compiled kernel (float32 maps and uint8 images, as the
    odometry makes them; anything else goes to the reference)."""
    if (idepth.dtype != np.float32 or var.dtype != np.float32 or idepth.ndim != 2 or var.shape != idepth.shape
            or (image is not None and (image.dtype != np.uint8 or image.ndim not in (2, 3)
                                       or image.shape[:2] != idepth.shape))):  # fmt: skip
        return points_world_numpy(idepth, var, image, max_var, K, S)
    fx, fy, cx, cy = (float(v) for v in K)
    img = np.zeros((0, 0), np.uint8) if image is None else np.ascontiguousarray(image)
    return _fill(np.ascontiguousarray(idepth), np.ascontiguousarray(var), img, max_var is not None,
                 np.float32(0.0 if max_var is None else max_var), fx, fy, cx, cy,
                 np.ascontiguousarray(S, np.float64))  # fmt: skip


def warm_up() -> None:
    """Load (or compile) the kernel for grey and colour images, so that a timed run does not."""
    d = np.ones((2, 2), np.float32)
    for image in (np.zeros((2, 2), np.uint8), np.zeros((2, 2, 3), np.uint8)):
        points_world_numba(d, d, image, None, (1.0, 1.0, 0.5, 0.5), np.eye(4))
