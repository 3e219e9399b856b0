"""Chunked residual pass of the SE(3) tracker for N > 1 channels (the tracker's kernel for 1 < N ≤ 32).

The same evaluation as the general kernel :func:`dmtrack.odometry._tracker_residuals.eval_pass_parallel` (whose
N > 1 branch forms each point's channel sums with
:func:`~dmtrack.odometry._tracker_residuals.point_channel_sums`), in passes over chunks of
:data:`~dmtrack.odometry._tracker_residuals.CHUNK` points per block:

(A) pose, projection, image test, bilinear weights, depth-derivative terms and pixel offsets of the chunk,
    vectorised over points (IEEE float64, the general kernel's operations; outside points are computed on pixel
    (2, 2) and skipped later);
(B) :func:`_chunk_channel_sums`: ``point_channel_sums`` for every in-image point of the chunk, on a flat view of
    the feature map with unsigned offsets — no per-point call, and none of the negative-index handling;
(C) the sums over points (error, good/bad, usage) in point order, the flags and the buffer rows.

Bit-identical to the general kernel by construction: (A) and (C) are IEEE arithmetic in the same order, and (B)
inlines the same function, whose channel sums have an order fixed by the source (the lanes of
:mod:`dmtrack.odometry._lanes`, no fast-math), so no compilation, cached copy or CPU can round them differently.
``tests/odometry/test_tracker_multi.py`` compares the two kernels and the numpy reference byte for byte.

The tracker takes its kernels from :func:`tracker_eval_kernels`. For N > 32 the general kernel is as fast or faster
(the channel loop dominates and the chunk's extra passes do not pay), so it keeps that one (:data:`MAX_CHANNELS`).
"""

from __future__ import annotations

import numba
import numpy as np

from dmtrack.odometry._lanes import ACC32, scratch_f32, scratch_f64, select
from dmtrack.odometry._tracker_residuals import (
    _NE,
    BLOCK,
    BUF_COLS,
    CHUNK,
    P_A,
    P_B,
    P_CX,
    P_CY,
    P_FX,
    P_FY,
    P_GOOD_C,
    P_GOOD_G,
    P_HUBER_HALF,
    P_NOISE2,
    P_VAR_WEIGHT,
    _combine_eval,
    _eval_multi,
    eval_kernels,
    eval_pass_parallel,
    point_channel_sums,
)

#: Largest channel count the chunked kernel is used for (above it the general kernel is as fast or faster).
MAX_CHANNELS = 32

# rows of the per-chunk geometry passed to _chunk_channel_sums
_G_W00, _G_W01, _G_W10, _G_W11, _G_G0, _G_G1, _G_S2 = range(7)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _chunk_channel_sums(
    ff, row, nchu, ref_vals, c0, m, pix, geo, aff_a, aff_b, fx, fy, noise2, huber_half, huber2, out
):  # pragma: no cover - compiled
    """:func:`~dmtrack.odometry._tracker_residuals.point_channel_sums` for the in-image points of a chunk
    (``pix[1, j] != 0``) into ``out[:, j]``.

    ``ff`` is the flat (h·w·N) feature map, ``pix[0, j]`` the offset of the point's pixel (ix, iy) in it, ``row``
    = w·N and ``nchu`` = N, ``geo`` the rows ``_G_*`` of the chunk; ``out`` rows: Σ W r², Sxx, Sxy, Syy, sx, sy,
    Σ r², Σ |∇F|².
    """
    acc = scratch_f32(ACC32)
    res = scratch_f32(8)
    for j in range(m):
        if pix[1, j] == 0:
            continue
        sums = point_channel_sums(
            ff, np.uint64(pix[0, j]), row, nchu, ref_vals[c0 + j], geo[_G_W00, j], geo[_G_W01, j], geo[_G_W10, j],
            geo[_G_W11, j], geo[_G_G0, j], geo[_G_G1, j], geo[_G_S2, j], aff_a, aff_b, fx, fy, noise2, huber_half,
            huber2, acc, res,
        )  # fmt: skip
        for k in range(8):
            out[k, j] = sums[k]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _multi_block(
    blk, points, ref_vals, ref_vars, ref_idx, feat, T, prm, flags, write_flags, buf, part
):  # pragma: no cover - compiled
    """Block ``blk`` of the chunked N > 1 evaluation into ``part[blk]`` (passes (A)–(C) of the module docstring)."""
    n = points.shape[0]
    h, w, nch = feat.shape
    fx, fy, cx, cy, aff_a, aff_b = prm[P_FX], prm[P_FY], prm[P_CX], prm[P_CY], prm[P_A], prm[P_B]
    var_weight, noise2, huber_half = prm[P_VAR_WEIGHT], prm[P_NOISE2], prm[P_HUBER_HALF]
    good_den_c, good_g = prm[P_GOOD_C], prm[P_GOOD_G]
    huber2 = huber_half * huber_half
    r00, r01, r02, tx = T[0, 0], T[0, 1], T[0, 2], T[0, 3]
    r10, r11, r12, ty = T[1, 0], T[1, 1], T[1, 2], T[1, 3]
    r20, r21, r22, tz = T[2, 0], T[2, 1], T[2, 2], T[2, 3]
    umax = w - 2.0
    vmax = h - 2.0
    ff = feat.reshape(h * w * nch)
    row = np.uint64(w * nch)
    nchu = np.uint64(nch)
    s_wx = scratch_f64(CHUNK)
    s_wy = scratch_f64(CHUNK)
    s_wz = scratch_f64(CHUNK)
    s_dc = scratch_f64(CHUNK)
    pix = np.empty((2, CHUNK), np.int64)
    geo = np.empty((7, CHUNK))
    out = np.empty((8, CHUNK))
    n_in = 0
    err = 0.0
    good = 0
    bad = 0
    usage = 0.0
    i0 = blk * BLOCK
    i1 = min(n, i0 + BLOCK)
    for c0 in range(i0, i1, CHUNK):
        c1 = min(i1, c0 + CHUNK)
        m = c1 - c0
        pts = points[c0:c1].reshape(3 * m)
        vrs = ref_vars[c0:c1]
        # (A) projection; outside points are computed at pixel (2, 2) and skipped in (B) and (C)
        for j in range(m):
            px = np.float64(pts[3 * j])
            py = np.float64(pts[3 * j + 1])
            pz = np.float64(pts[3 * j + 2])
            wx = r00 * px + r01 * py + r02 * pz + tx
            wy = r10 * px + r11 * py + r12 * pz + ty
            wz = r20 * px + r21 * py + r22 * pz + tz
            iz = 1.0 / wz
            u = (wx * iz) * fx + cx
            v = (wy * iz) * fy + cy
            inside = (u > 1.0) & (v > 1.0) & (u < umax) & (v < vmax)
            u = select(inside, u, 2.0)
            v = select(inside, v, 2.0)
            ix = int(u)
            iy = int(v)
            dx = u - ix
            dy = v - iy
            dxdy = dx * dy
            zd = pz * iz * iz  # 1 / (z'² d) with d = 1/z_ref
            s_wx[j] = wx
            s_wy[j] = wy
            s_wz[j] = wz
            s_dc[j] = pz * iz
            geo[_G_W11, j] = dxdy
            geo[_G_W01, j] = dy - dxdy
            geo[_G_W10, j] = dx - dxdy
            geo[_G_W00, j] = 1.0 - dx - dy + dxdy
            geo[_G_G0, j] = (tx * wz - tz * wx) * zd
            geo[_G_G1, j] = (ty * wz - tz * wy) * zd
            geo[_G_S2, j] = var_weight * vrs[j]
            pix[0, j] = (iy * w + ix) * nch
            pix[1, j] = inside
        # (B) the channel sums of the in-image points
        _chunk_channel_sums(ff, row, nchu, ref_vals, c0, m, pix, geo, aff_a, aff_b, fx, fy, noise2, huber_half,
                            huber2, out)  # fmt: skip
        # (C) sums in point order, flags, buffer rows
        for j in range(m):
            i = c0 + j
            bi = buf[i]
            if pix[1, j] == 0:
                if write_flags:
                    flags[ref_idx[i]] = False
                for k in range(BUF_COLS):
                    bi[k] = 0.0
                continue
            err += out[0, j]
            is_good = out[6, j] < good_den_c + good_g * out[7, j]
            if write_flags:
                flags[ref_idx[i]] = is_good
            good += is_good
            bad += not is_good
            dc = s_dc[j]
            usage += dc if dc < 1.0 else 1.0
            bi[0] = s_wx[j]
            bi[1] = s_wy[j]
            bi[2] = s_wz[j]
            for k in range(5):
                bi[3 + k] = out[1 + k, j]
            n_in += 1
    p = part[blk]
    p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8], p[9] = n_in, err, good, bad, usage, 0.0, 0.0, 0.0, 0.0, 0.0


@numba.njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def eval_multi_parallel(
    points, ref_vals, ref_vars, ref_idx, feat, packed, T, prm, affine_sums, flags, write_flags, buf
):  # pragma: no cover - compiled
    """The chunked N > 1 evaluation (called like :func:`~dmtrack.odometry._tracker_residuals.eval_pass`, without
    affine sums: ``affine_sums`` and ``packed`` are not read), blocks over numba's threads (``prange``)."""
    nb = (points.shape[0] + BLOCK - 1) // BLOCK
    part = np.empty((nb, _NE))
    for blk in numba.prange(nb):  # prange's index is unsigned: one compiled block function for both loops
        _multi_block(np.int64(blk), points, ref_vals, ref_vars, ref_idx, feat, T, prm, flags, write_flags, buf, part)
    return _combine_eval(part)


def eval_multi(*args):  # type: ignore[no-untyped-def]
    """The tracker's serial N > 1 evaluation: :func:`eval_multi_parallel` on one thread (the same compiled code as
    the threaded one); with ``affine_sums`` the general kernel's
    (:func:`~dmtrack.odometry._tracker_residuals._eval_multi`)."""
    if args[8]:
        return _eval_multi(*args)
    prev = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        return eval_multi_parallel(*args)
    finally:
        numba.set_num_threads(prev)


def eval_multi_threaded(*args):  # type: ignore[no-untyped-def]
    """The tracker's threaded N > 1 evaluation: :func:`eval_multi_parallel`; with ``affine_sums`` the general
    kernel (:func:`~dmtrack.odometry._tracker_residuals.eval_pass_parallel`)."""
    if args[8]:
        return eval_pass_parallel(*args)
    return eval_multi_parallel(*args)


def tracker_eval_kernels(n_channels: int) -> tuple:
    """(serial, threaded) evaluation the tracker runs for ``n_channels`` channels, each called like
    :func:`~dmtrack.odometry._tracker_residuals.eval_pass`.

    1 < N ≤ :data:`MAX_CHANNELS`: the chunked kernel of this module (:func:`eval_multi`, :func:`eval_multi_threaded`);
    otherwise :func:`~dmtrack.odometry._tracker_residuals.eval_kernels` (grey's kernel, the general multichannel
    kernel for N > 32). All of them give the general kernel's bytes.
    """
    if 1 < n_channels <= MAX_CHANNELS:
        return eval_multi, eval_multi_threaded
    return eval_kernels(n_channels)
