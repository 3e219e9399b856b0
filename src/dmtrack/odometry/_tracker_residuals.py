"""Residual pass of the SE(3) tracker (lsd-slam-spec.md §2, generalised to N channels §4.3).

:func:`eval_pass` warps every reference point into the frame and forms the per-channel residual, its weights
and Huber; instead of the (NV)×6 Jacobian it writes per point the 2×2 sums ``S = Σ_c W_c g_c g_cᵀ`` and
2-vectors ``s = Σ_c W_c r_c g_c`` with ``g_c = (fx·∂F_c/∂x, fy·∂F_c/∂y)``, from which
:mod:`dmtrack.odometry._tracker_normal_equations` accumulates the 6×6 system. Numba kernels (serial and
``prange``) with a vectorised numpy reference (:func:`eval_pass_numpy`).

Sums are formed per fixed block of :data:`BLOCK` points and combined in block order (no parallel reductions),
so the serial and the ``prange`` kernels give bit-identical results for any thread count. Arithmetic is
float64 on float32 storage; ``error_model="numpy"`` (a division by zero gives inf/nan — e.g. a point with
z' = 0 fails the image test — instead of raising).

Grey (N = 1) has its own kernel (:func:`_grey_block`): the same IEEE arithmetic, point by point, split into
passes over chunks of :data:`CHUNK` points so that LLVM vectorises all but the sums — the projection, the
bilinear samples (gathers), the weights and the buffer rows are computed for 4 points at once, and only the
sums over points (error, usage, Gray-A's affine sums) run point by point in the original order. Outside points
are computed too (on a clamped pixel) and masked with :func:`select`; a masked point adds +0.0 to the sums,
which leaves them unchanged (they start at +0.0 and never become −0.0), so every result is bit-identical to
the point-by-point loop of :func:`_eval_block`. The chunk's intermediate rows live on the stack
(:func:`scratch_f64`), one small array per row, which tells LLVM that they cannot alias the input arrays.

N > 1: a point's channel sums are :func:`point_channel_sums`, float32 in the fixed lane order of
:mod:`dmtrack.odometry._lanes` (no fast-math anywhere): every kernel that inlines it — this module's general kernel
and the tracker's chunked kernel (:mod:`dmtrack.odometry._tracker_multi`) — gives the same bits, whichever process
compiled it, for any thread count and on every CPU; :func:`point_channel_sums_numpy` is its bit-exact reference.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dmtrack.odometry._lanes import ACC32, LANES32, fold8x8, scratch_f32, scratch_f64, scratch_i64, select

#: Columns of the per-point buffer written by :func:`eval_pass`: x', y', z' (point in the frame's camera),
#: Sxx, Sxy, Syy (Σ_c W g gᵀ), sx, sy (Σ_c W r g); all zero for points outside the image.
BUF_COLS = 8


#: Points per block of the blocked kernels. Partial sums are formed per block and combined in block order, so
#: the serial and the parallel (prange) kernels give bit-identical results, whatever the thread count.
BLOCK = 1024

#: Indices into the float64 parameter vector of :func:`eval_pass`.
P_FX, P_FY, P_CX, P_CY, P_A, P_B, P_VAR_WEIGHT, P_NOISE2, P_HUBER_HALF, P_GOOD_C, P_GOOD_G, P_AFF_THR = range(12)
N_PARAMS = 12

#: Columns of the per-block partial sums of :func:`eval_pass`.
_NE = 10

#: Points per pass of the grey kernel (a divisor of :data:`BLOCK`): its 17 stack rows (17 KiB) stay in L1.
CHUNK = 128


def eval_params(
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    aff_a: float,
    aff_b: float,
    var_weight: float,
    noise2: float,
    huber_half: float,
    good_c: float,
    good_g: float,
    aff_thr: float,
) -> np.ndarray:
    """Pack the scalar parameters of :func:`eval_pass` into a float64 vector (order of the ``P_*`` indices)."""
    return np.array([fx, fy, cx, cy, aff_a, aff_b, var_weight, noise2, huber_half, good_c, good_g, aff_thr], np.float64)


@numba.njit(nogil=True, error_model="numpy", inline="always")
def _channel_terms(ff, o, row, nchu, rv, c, f00, f01, f10, f11, fa, fb, kx, ky, fn2, fhh, fh2):  # pragma: no cover
    """The eight float32 terms of channel ``c`` of one point (see :func:`point_channel_sums`)."""
    # corners A = (ix, iy), B = (ix+1, iy), C = (ix, iy+1), D = (ix+1, iy+1); 2·gradient = central difference
    pa = ff[o + c]
    pb = ff[o + nchu + c]
    pc = ff[o + row + c]
    pd = ff[o + row + nchu + c]
    r = fa * rv[c] + fb - (f11 * pd + f01 * pc + f10 * pb + f00 * pa)
    gx = (f11 * (ff[o + row + nchu + nchu + c] - pc) + f01 * (pd - ff[o + row - nchu + c])
          + f10 * (ff[o + nchu + nchu + c] - pa) + f00 * (pb - ff[o - nchu + c]))  # fmt: skip
    gy = (f11 * (ff[o + row + row + nchu + c] - pb) + f01 * (ff[o + row + row + c] - pa)
          + f10 * (pd - ff[o - row + nchu + c]) + f00 * (pc - ff[o - row + c]))  # fmt: skip
    r2 = r * r
    d = kx * gx + ky * gy
    wp = np.float32(1.0) / (fn2 + d * d)
    e2 = r2 * wp
    ww = select(e2 < fh2, wp, wp * fhh / np.sqrt(e2))
    wgx = ww * gx
    wgy = ww * gy
    return ww * r2, wgx * gx, wgx * gy, wgy * gy, wgx * r, wgy * r, r2, gx * gx + gy * gy


@numba.njit(nogil=True, error_model="numpy", inline="always")
def point_channel_sums(
    ff, o, row, nchu, rv, w00, w01, w10, w11, g0, g1, s2, aff_a, aff_b, fx, fy, noise2, huber_half, huber2, acc, res
):  # pragma: no cover - compiled
    """The channel sums of one in-image point (N > 1, no affine sums), in the fixed lane order of
    :mod:`dmtrack.odometry._lanes`: (Σ W r², Sxx, Sxy, Syy, sx, sy, Σ r², Σ |∇F|²).

    ``ff`` is the flat (h·w·N) feature map, ``o`` the offset of the point's pixel (ix, iy) in it, ``row`` = w·N and
    ``nchu`` = N (unsigned, so that the neighbours' offsets need no negative-index handling), ``rv`` the point's N
    reference values; ``acc`` (64) and ``res`` (8) are float32 scratch arrays of the caller. The central differences
    at the four corners are formed on the fly from the 12 surrounding pixels (all inside the image, since
    1 < u < w−2 and 1 < v < h−2), which reads a third of the memory of the packed (F, gx, gy) layout. The constant
    factors (½ of the central differences, fx, fy, the depth variance) are folded into two coefficients or applied
    once after the sums. float32 per channel (the storage precision of the maps), eight lanes per sum
    (:data:`~dmtrack.odometry._lanes.LANES32`) folded by :func:`~dmtrack.odometry._lanes.fold8x8`; the results in
    float64. The one definition for every kernel: the general kernel and the tracker's chunked kernel inline it,
    and its numpy reference (:func:`point_channel_sums_numpy`) gives the same bits.
    """
    f00 = np.float32(w00)
    f01 = np.float32(w01)
    f10 = np.float32(w10)
    f11 = np.float32(w11)
    fa = np.float32(aff_a)
    fb = np.float32(aff_b)
    # W_p = 1 / (noise² + s2·(g·(fx g0, fy g1))²) with g = ½ (gx, gy), (gx, gy) the central differences
    rs = math.sqrt(s2) if s2 > 0.0 else 0.0
    kx = np.float32(0.5 * rs * fx * g0)
    ky = np.float32(0.5 * rs * fy * g1)
    fn2 = np.float32(noise2)
    fhh = np.float32(huber_half)
    fh2 = np.float32(huber2)
    for k in range(ACC32):
        acc[k] = np.float32(0.0)
    lanes = np.uint64(LANES32)
    nfull = (nchu // lanes) * lanes
    for cb in range(np.uint64(0), nfull, lanes):  # whole blocks of LANES32 channels
        for lane in range(LANES32):
            t = _channel_terms(ff, o, row, nchu, rv, cb + np.uint64(lane), f00, f01, f10, f11, fa, fb, kx, ky, fn2,
                               fhh, fh2)  # fmt: skip
            for k in range(8):
                acc[k * LANES32 + lane] += t[k]
    rem = nchu - nfull
    if rem > 0:  # the last N mod LANES32 channels, into lanes 0, 1, ...
        for lane in range(LANES32):
            if np.uint64(lane) < rem:
                t = _channel_terms(ff, o, row, nchu, rv, nfull + np.uint64(lane), f00, f01, f10, f11, fa, fb, kx, ky,
                                   fn2, fhh, fh2)  # fmt: skip
                for k in range(8):
                    acc[k * LANES32 + lane] += t[k]
    fold8x8(acc, res)
    return (np.float64(res[0]), 0.25 * fx * fx * np.float64(res[1]), 0.25 * fx * fy * np.float64(res[2]),
            0.25 * fy * fy * np.float64(res[3]), 0.5 * fx * np.float64(res[4]), 0.5 * fy * np.float64(res[5]),
            np.float64(res[6]), 0.25 * np.float64(res[7]))  # fmt: skip


def point_channel_sums_numpy(
    feat: np.ndarray, ix: np.ndarray, iy: np.ndarray, rv: np.ndarray, w: tuple[np.ndarray, ...], g0: np.ndarray,
    g1: np.ndarray, s2: np.ndarray, prm: np.ndarray,
) -> np.ndarray:
    """numpy reference of :func:`point_channel_sums` for m points at pixels (ix, iy) (integer arrays) with reference
    values ``rv`` (m, N), bilinear weights ``w`` = (w00, w01, w10, w11) and depth terms g0, g1, s2 (float64 arrays
    of m): the same float32 operations per channel and the same lane order
    (:func:`~dmtrack.odometry._lanes.lane_sum_numpy`), so the same bits. Returns (m, 8) float64, the columns of
    :func:`point_channel_sums`."""
    from dmtrack.odometry._lanes import lane_sum_numpy

    f32 = np.float32
    f00, f01, f10, f11 = (np.asarray(x, np.float64).astype(f32)[:, None] for x in w)
    fx, fy = float(prm[P_FX]), float(prm[P_FY])
    fa, fb = f32(prm[P_A]), f32(prm[P_B])
    s2 = np.asarray(s2, np.float64)
    rs = np.sqrt(np.where(s2 > 0.0, s2, 0.0))
    kx = (0.5 * rs * fx * np.asarray(g0, np.float64)).astype(f32)[:, None]
    ky = (0.5 * rs * fy * np.asarray(g1, np.float64)).astype(f32)[:, None]
    fn2, fhh = f32(prm[P_NOISE2]), f32(prm[P_HUBER_HALF])
    fh2 = f32(float(prm[P_HUBER_HALF]) * float(prm[P_HUBER_HALF]))
    F = np.asarray(feat, f32)
    ix = np.asarray(ix, np.int64)
    iy = np.asarray(iy, np.int64)
    pa, pb, pc, pd = F[iy, ix], F[iy, ix + 1], F[iy + 1, ix], F[iy + 1, ix + 1]  # (m, N)
    r = fa * np.asarray(rv, f32) + fb - (f11 * pd + f01 * pc + f10 * pb + f00 * pa)
    gx = (f11 * (F[iy + 1, ix + 2] - pc) + f01 * (pd - F[iy + 1, ix - 1])
          + f10 * (F[iy, ix + 2] - pa) + f00 * (pb - F[iy, ix - 1]))  # fmt: skip
    gy = (f11 * (F[iy + 2, ix + 1] - pb) + f01 * (F[iy + 2, ix] - pa)
          + f10 * (pd - F[iy - 1, ix + 1]) + f00 * (pc - F[iy - 1, ix]))  # fmt: skip
    r2 = r * r
    d = kx * gx + ky * gy
    wp = f32(1.0) / (fn2 + d * d)
    e2 = r2 * wp
    with np.errstate(divide="ignore", invalid="ignore"):
        ww = np.where(e2 < fh2, wp, wp * fhh / np.sqrt(e2))
    wgx, wgy = ww * gx, ww * gy
    terms = np.stack([ww * r2, wgx * gx, wgx * gy, wgy * gy, wgx * r, wgy * r, r2, gx * gx + gy * gy])  # (8, m, N)
    sums = lane_sum_numpy(np.moveaxis(terms, 2, 0), LANES32).astype(np.float64)  # (8, m)
    scale = np.array([1.0, 0.25 * fx * fx, 0.25 * fx * fy, 0.25 * fy * fy, 0.5 * fx, 0.5 * fy, 1.0, 0.25])
    return (scale[:, None] * sums).T


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _eval_block(
    blk, points, ref_vals, ref_vars, ref_idx, feat, packed, T, prm, affine_sums, flags, write_flags, buf, part
):  # pragma: no cover - compiled
    n = points.shape[0]
    nch = ref_vals.shape[1]
    h = feat.shape[0]
    w = feat.shape[1]
    fx = prm[P_FX]
    fy = prm[P_FY]
    cx = prm[P_CX]
    cy = prm[P_CY]
    aff_a = prm[P_A]
    aff_b = prm[P_B]
    var_weight = prm[P_VAR_WEIGHT]
    noise2 = prm[P_NOISE2]
    huber_half = prm[P_HUBER_HALF]
    huber2 = huber_half * huber_half
    good_den_c = prm[P_GOOD_C]
    good_g = prm[P_GOOD_G]
    aff_thr = prm[P_AFF_THR]
    r00 = T[0, 0]
    r01 = T[0, 1]
    r02 = T[0, 2]
    r10 = T[1, 0]
    r11 = T[1, 1]
    r12 = T[1, 2]
    r20 = T[2, 0]
    r21 = T[2, 1]
    r22 = T[2, 2]
    tx = T[0, 3]
    ty = T[1, 3]
    tz = T[2, 3]
    umax = w - 2.0
    vmax = h - 2.0
    ff = feat.reshape(h * w * nch)
    row = np.uint64(w * nch)
    nchu = np.uint64(nch)
    acc = scratch_f32(ACC32)
    res = scratch_f32(8)
    n_in = 0
    err = 0.0
    good = 0
    bad = 0
    usage = 0.0
    a_xx = 0.0
    a_yy = 0.0
    a_x = 0.0
    a_y = 0.0
    a_w = 0.0
    i0 = blk * BLOCK
    i1 = min(n, i0 + BLOCK)
    for i in range(i0, i1):
        px = np.float64(points[i, 0])
        py = np.float64(points[i, 1])
        pz = np.float64(points[i, 2])
        wx = r00 * px + r01 * py + r02 * pz + tx
        wy = r10 * px + r11 * py + r12 * pz + ty
        wz = r20 * px + r21 * py + r22 * pz + tz
        iz = 1.0 / wz
        u = (wx * iz) * fx + cx
        v = (wy * iz) * fy + cy
        if not (u > 1.0 and v > 1.0 and u < umax and v < vmax):
            if write_flags:
                flags[ref_idx[i]] = False
            for k in range(8):
                buf[i, k] = 0.0
            continue
        ix = int(u)
        iy = int(v)
        dx = u - ix
        dy = v - iy
        dxdy = dx * dy
        w11 = dxdy
        w01 = dy - dxdy
        w10 = dx - dxdy
        w00 = 1.0 - dx - dy + dxdy
        s2 = var_weight * ref_vars[i]
        zd = pz * iz * iz  # 1 / (z'² d) with d = 1/z_ref
        g0 = (tx * wz - tz * wx) * zd
        g1 = (ty * wz - tz * wy) * zd
        sxx = 0.0
        sxy = 0.0
        syy = 0.0
        bx = 0.0
        by = 0.0
        r2sum = 0.0
        g2sum = 0.0
        if nch > 1 and not affine_sums:
            e_p, sxx, sxy, syy, bx, by, r2sum, g2sum = point_channel_sums(
                ff, np.uint64((iy * w + ix) * nch), row, nchu, ref_vals[i], w00, w01, w10, w11, g0, g1, s2, aff_a,
                aff_b, fx, fy, noise2, huber_half, huber2, acc, res,
            )  # fmt: skip
            err += e_p
        for c in range(nch if (nch == 1 or affine_sums) else 0):
            iv = (
                w11 * packed[iy + 1, ix + 1, 0, c]
                + w01 * packed[iy + 1, ix, 0, c]
                + w10 * packed[iy, ix + 1, 0, c]
                + w00 * packed[iy, ix, 0, c]
            )
            gx = (
                w11 * packed[iy + 1, ix + 1, 1, c]
                + w01 * packed[iy + 1, ix, 1, c]
                + w10 * packed[iy, ix + 1, 1, c]
                + w00 * packed[iy, ix, 1, c]
            )
            gy = (
                w11 * packed[iy + 1, ix + 1, 2, c]
                + w01 * packed[iy + 1, ix, 2, c]
                + w10 * packed[iy, ix + 1, 2, c]
                + w00 * packed[iy, ix, 2, c]
            )
            c1 = aff_a * ref_vals[i, c] + aff_b
            r = c1 - iv
            if affine_sums:
                ar = abs(r)
                aw = 1.0 if ar < aff_thr else aff_thr / ar
                a_xx += c1 * c1 * aw
                a_yy += iv * iv * aw
                a_x += c1 * aw
                a_y += iv * aw
                a_w += aw
            r2sum += r * r
            g2sum += gx * gx + gy * gy
            gxf = fx * gx
            gyf = fy * gy
            drpdd = gxf * g0 + gyf * g1
            wp = 1.0 / (noise2 + s2 * drpdd * drpdd)
            e2 = r * r * wp
            ww = wp if e2 < huber2 else wp * huber_half / math.sqrt(e2)
            err += ww * r * r
            sxx += ww * gxf * gxf
            sxy += ww * gxf * gyf
            syy += ww * gyf * gyf
            bx += ww * r * gxf
            by += ww * r * gyf
        is_good = r2sum < good_den_c + good_g * g2sum
        if write_flags:
            flags[ref_idx[i]] = is_good
        if is_good:
            good += 1
        else:
            bad += 1
        dc = pz * iz
        usage += dc if dc < 1.0 else 1.0
        buf[i, 0] = wx
        buf[i, 1] = wy
        buf[i, 2] = wz
        buf[i, 3] = sxx
        buf[i, 4] = sxy
        buf[i, 5] = syy
        buf[i, 6] = bx
        buf[i, 7] = by
        n_in += 1
    part[blk, 0] = n_in
    part[blk, 1] = err
    part[blk, 2] = good
    part[blk, 3] = bad
    part[blk, 4] = usage
    part[blk, 5] = a_xx
    part[blk, 6] = a_yy
    part[blk, 7] = a_x
    part[blk, 8] = a_y
    part[blk, 9] = a_w


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _combine_eval(part: np.ndarray) -> tuple[int, float, int, int, float, float, float, float, float, float]:
    tot = np.zeros(_NE)
    for blk in range(part.shape[0]):
        for k in range(_NE):
            tot[k] += part[blk, k]
    return (int(tot[0]), tot[1], int(tot[2]), int(tot[3]), tot[4], tot[5], tot[6], tot[7], tot[8], tot[9])


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _grey_block(
    blk, points, ref_vals, ref_vars, ref_idx, packed, T, prm, affine_sums, flags, write_flags, buf, part
):  # pragma: no cover - compiled
    """:func:`_eval_block` for N = 1 (``packed`` (h, w, 3, 1) C-contiguous), in vectorised passes per chunk.

    Per chunk of :data:`CHUNK` points: (A) pose, projection, image test, bilinear weights and pixel offsets;
    (B) the bilinear samples (F, gx, gy); (C) residual, weights, Huber, good test and the buffer rows (zero
    outside the image); (D) the sums, point by point in order. Same operations on the same values as
    :func:`_eval_block`, so bit-identical results. Indices into the chunk's views count from 0 and the pixel
    offsets are unsigned, so that numba's negative-index handling does not hide the access pattern from LLVM.
    """
    n = points.shape[0]
    h, w = packed.shape[0], packed.shape[1]
    fx, fy, cx, cy, aff_a, aff_b = prm[P_FX], prm[P_FY], prm[P_CX], prm[P_CY], prm[P_A], prm[P_B]
    var_weight, noise2, huber_half = prm[P_VAR_WEIGHT], prm[P_NOISE2], prm[P_HUBER_HALF]
    good_den_c, good_g, aff_thr = prm[P_GOOD_C], prm[P_GOOD_G], prm[P_AFF_THR]
    huber2 = huber_half * huber_half
    r00, r01, r02, tx = T[0, 0], T[0, 1], T[0, 2], T[0, 3]
    r10, r11, r12, ty = T[1, 0], T[1, 1], T[1, 2], T[1, 3]
    r20, r21, r22, tz = T[2, 0], T[2, 1], T[2, 2], T[2, 3]
    umax = w - 2.0
    vmax = h - 2.0
    row = np.uint64(3 * w)  # floats per image row of packed
    u1, u2, u3, u4, u5 = np.uint64(1), np.uint64(2), np.uint64(3), np.uint64(4), np.uint64(5)
    pk = packed.reshape(h * w * 3)
    # stack rows of one chunk (see scratch_f64)
    s_wx = scratch_f64(CHUNK)
    s_wy = scratch_f64(CHUNK)
    s_wz = scratch_f64(CHUNK)
    s_w11 = scratch_f64(CHUNK)
    s_w01 = scratch_f64(CHUNK)
    s_w10 = scratch_f64(CHUNK)
    s_w00 = scratch_f64(CHUNK)
    s_g0 = scratch_f64(CHUNK)
    s_g1 = scratch_f64(CHUNK)
    s_dc = scratch_f64(CHUNK)
    s_in = scratch_f64(CHUNK)
    s_iv = scratch_f64(CHUNK)
    s_gx = scratch_f64(CHUNK)
    s_gy = scratch_f64(CHUNK)
    s_err = scratch_f64(CHUNK)
    s_good = scratch_f64(CHUNK)
    s_c1 = scratch_f64(CHUNK)
    s_off = scratch_i64(CHUNK)
    n_in = 0
    err = 0.0
    good = 0
    bad = 0
    usage = 0.0
    a_xx = 0.0
    a_yy = 0.0
    a_x = 0.0
    a_y = 0.0
    a_w = 0.0
    i0 = blk * BLOCK
    i1 = min(n, i0 + BLOCK)
    for c0 in range(i0, i1, CHUNK):
        c1 = min(i1, c0 + CHUNK)
        m = c1 - c0
        pts = points[c0:c1].reshape(3 * m)
        vals = ref_vals[c0:c1].reshape(m)
        vrs = ref_vars[c0:c1]
        bf = buf[c0:c1].reshape(BUF_COLS * m)
        # (A) projection; outside points are sampled at pixel (2, 2) and masked later
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
            s_w11[j] = dxdy
            s_w01[j] = dy - dxdy
            s_w10[j] = dx - dxdy
            s_w00[j] = 1.0 - dx - dy + dxdy
            s_g0[j] = (tx * wz - tz * wx) * zd
            s_g1[j] = (ty * wz - tz * wy) * zd
            s_dc[j] = pz * iz
            s_in[j] = select(inside, 1.0, 0.0)
            s_off[j] = (iy * w + ix) * 3
        # (B) bilinear (F, gx, gy)
        for j in range(m):
            o = np.uint64(s_off[j])
            o1 = o + row
            w11 = s_w11[j]
            w01 = s_w01[j]
            w10 = s_w10[j]
            w00 = s_w00[j]
            s_iv[j] = w11 * pk[o1 + u3] + w01 * pk[o1] + w10 * pk[o + u3] + w00 * pk[o]
            s_gx[j] = w11 * pk[o1 + u4] + w01 * pk[o1 + u1] + w10 * pk[o + u4] + w00 * pk[o + u1]
            s_gy[j] = w11 * pk[o1 + u5] + w01 * pk[o1 + u2] + w10 * pk[o + u5] + w00 * pk[o + u2]
        # (C) residual, weights, Huber, good test, buffer rows
        for j in range(m):
            iv = s_iv[j]
            gx = s_gx[j]
            gy = s_gy[j]
            c1v = aff_a * vals[j] + aff_b
            r = c1v - iv
            r2sum = 0.0 + r * r
            g2sum = 0.0 + (gx * gx + gy * gy)
            gxf = fx * gx
            gyf = fy * gy
            drpdd = gxf * s_g0[j] + gyf * s_g1[j]
            s2 = var_weight * vrs[j]
            wp = 1.0 / (noise2 + s2 * drpdd * drpdd)
            e2 = r * r * wp
            ww = select(e2 < huber2, wp, wp * huber_half / math.sqrt(e2))
            ins = s_in[j] != 0.0
            k = BUF_COLS * j
            bf[k] = select(ins, s_wx[j], 0.0)
            bf[k + 1] = select(ins, s_wy[j], 0.0)
            bf[k + 2] = select(ins, s_wz[j], 0.0)
            bf[k + 3] = select(ins, 0.0 + ww * gxf * gxf, 0.0)
            bf[k + 4] = select(ins, 0.0 + ww * gxf * gyf, 0.0)
            bf[k + 5] = select(ins, 0.0 + ww * gyf * gyf, 0.0)
            bf[k + 6] = select(ins, 0.0 + ww * r * gxf, 0.0)
            bf[k + 7] = select(ins, 0.0 + ww * r * gyf, 0.0)
            s_err[j] = select(ins, ww * r * r, 0.0)
            s_good[j] = select(r2sum < good_den_c + good_g * g2sum, 1.0, 0.0)
            s_c1[j] = c1v
        # (D) sums in point order; a masked point adds +0.0 (no change)
        if affine_sums:
            for j in range(m):
                if s_in[j] != 0.0:
                    c1v = s_c1[j]
                    iv = s_iv[j]
                    ar = abs(c1v - iv)
                    aw = 1.0 if ar < aff_thr else aff_thr / ar
                    a_xx += c1v * c1v * aw
                    a_yy += iv * iv * aw
                    a_x += c1v * aw
                    a_y += iv * aw
                    a_w += aw
        for j in range(m):
            ins = s_in[j] != 0.0
            is_good = s_good[j] != 0.0
            n_in += ins
            good += ins & is_good
            bad += ins & (not is_good)
        for j in range(m):
            dc = s_dc[j]
            err += s_err[j]
            usage += select(s_in[j] != 0.0, select(dc < 1.0, dc, 1.0), 0.0)
        if write_flags:
            fi = ref_idx[c0:c1]
            for j in range(m):
                flags[fi[j]] = (s_in[j] != 0.0) & (s_good[j] != 0.0)
    p = part[blk]
    p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8], p[9] = n_in, err, good, bad, usage, a_xx, a_yy, a_x, a_y, a_w


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _eval_grey(
    points, ref_vals, ref_vars, ref_idx, feat, packed, T, prm, affine_sums, flags, write_flags, buf
):  # pragma: no cover - compiled
    """The grey evaluation, blocks in order on the calling thread."""
    nb = (points.shape[0] + BLOCK - 1) // BLOCK
    part = np.empty((nb, _NE))
    for blk in range(nb):
        _grey_block(blk, points, ref_vals, ref_vars, ref_idx, packed, T, prm, affine_sums, flags, write_flags,
                    buf, part)  # fmt: skip
    return _combine_eval(part)


@numba.njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def _eval_grey_parallel(
    points, ref_vals, ref_vars, ref_idx, feat, packed, T, prm, affine_sums, flags, write_flags, buf
):  # pragma: no cover - compiled
    """The grey evaluation, blocks over numba's threads (``prange``)."""
    nb = (points.shape[0] + BLOCK - 1) // BLOCK
    part = np.empty((nb, _NE))
    for blk in numba.prange(nb):  # prange's index is unsigned: one compiled block function for both loops
        _grey_block(np.int64(blk), points, ref_vals, ref_vars, ref_idx, packed, T, prm, affine_sums, flags, write_flags,
                    buf, part)  # fmt: skip
    return _combine_eval(part)


@numba.njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def eval_pass_parallel(
    points: np.ndarray,
    ref_vals: np.ndarray,
    ref_vars: np.ndarray,
    ref_idx: np.ndarray,
    feat: np.ndarray,
    packed: np.ndarray,
    T: np.ndarray,
    prm: np.ndarray,
    affine_sums: bool,
    flags: np.ndarray,
    write_flags: bool,
    buf: np.ndarray,
) -> tuple[int, float, int, int, float, float, float, float, float, float]:  # pragma: no cover
    """:func:`eval_pass` with the blocks distributed over numba's threads (``prange``); the result does not
    depend on the thread count (fixed blocks, combined in order). The general kernel, for any N (for N = 1
    bit-identical to the grey kernel of :func:`eval_kernels`, which the tracker runs instead)."""
    nb = (points.shape[0] + BLOCK - 1) // BLOCK
    part = np.empty((nb, _NE))
    for blk in numba.prange(nb):
        _eval_block(blk, points, ref_vals, ref_vars, ref_idx, feat, packed, T, prm, affine_sums, flags,
                    write_flags, buf, part)  # fmt: skip
    return _combine_eval(part)


def _eval_multi(*args):  # type: ignore[no-untyped-def]
    """:func:`eval_pass_parallel` on one thread: the serial multichannel evaluation (one compiled kernel for
    both; fixed blocks and fixed lanes make its result independent of the thread count)."""
    prev = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        return eval_pass_parallel(*args)
    finally:
        numba.set_num_threads(prev)


def eval_kernels(n_channels: int) -> tuple:
    """(serial, threaded) compiled evaluation for ``n_channels`` channels, each called like :func:`eval_pass`.

    The tracker takes its kernels from :func:`dmtrack.odometry._tracker_multi.tracker_eval_kernels` (the chunked
    multichannel kernel for 1 < N ≤ 32, bit-identical to these).

    Grey has its own vectorised kernel (IEEE arithmetic: its serial and ``prange`` builds agree bit for bit);
    the others run the multichannel kernel, the serial one on a single thread. Only the kernel a run uses is
    compiled.
    """
    if n_channels == 1:
        return _eval_grey, _eval_grey_parallel
    return _eval_multi, eval_pass_parallel


def eval_pass(
    points: np.ndarray,
    ref_vals: np.ndarray,
    ref_vars: np.ndarray,
    ref_idx: np.ndarray,
    feat: np.ndarray,
    packed: np.ndarray,
    T: np.ndarray,
    prm: np.ndarray,
    affine_sums: bool,
    flags: np.ndarray,
    write_flags: bool,
    buf: np.ndarray,
) -> tuple[int, float, int, int, float, float, float, float, float, float]:
    """One residual evaluation of the reference against the frame at pose T (4×4, keyframe→frame).

    Per point p (reference coordinates, float32 (n, 3)): p' = R p + t, (u, v) its projection; kept if
    1 < u < w−2 and 1 < v < h−2 (otherwise, when ``write_flags``, ``flags[ref_idx] = False``). Bilinear
    (F_c, gx_c, gy_c) from ``packed`` (h, w, 3, N) for N = 1 or with ``affine_sums``; otherwise from the
    feature map ``feat`` (h, w, N) directly (gradients formed on the fly, float32; ``packed`` is then not
    read and may be a (1, 1, 3, N) placeholder). r_c = (a·F_ref,c + b) − F_c.

    Good/bad: Σ_c r_c² < good_c + good_g·Σ_c |∇F_c|² (LSD-SLAM's r²/(40² + 0.25|∇I|²) < 1 for N=1; the
    caller scales good_c by the channel rule's ``good`` factor, N·40² for the channel mean). Weights per
    channel: w_p = 1/(noise2 + var_weight·σ_d²·(g_c·(g0, g1))²), Huber on e = |r_c|√w_p with threshold
    ``huber_half``; W = w_h·w_p. ``prm`` holds the scalars (see ``P_*``).

    Writes ``buf[i] = (x', y', z', Sxx, Sxy, Syy, sx, sy)`` for every in-image point i and zeros for the
    others (z' = 0 marks them). Sums are formed per block of :data:`BLOCK` points and combined in order.
    All arrays C-contiguous.

    Returns
    -------
    (n_in, Σ W r², good, bad, Σ min(1, z/z'), affine sums sxx, syy, sx, sy, sw)

    Runs on the calling thread, with the kernel for ``ref_vals.shape[1]`` channels (see :func:`eval_kernels`);
    :func:`eval_pass_parallel` gives bit-identical results on numba's threads.
    """
    return eval_kernels(ref_vals.shape[1])[0](points, ref_vals, ref_vars, ref_idx, feat, packed, T, prm,
                                              affine_sums, flags, write_flags, buf)  # fmt: skip


def eval_pass_numpy(
    points: np.ndarray,
    ref_vals: np.ndarray,
    ref_vars: np.ndarray,
    ref_idx: np.ndarray,
    feat: np.ndarray,
    packed: np.ndarray,
    T: np.ndarray,
    prm: np.ndarray,
    affine_sums: bool,
    flags: np.ndarray,
    write_flags: bool,
    buf: np.ndarray,
) -> tuple[int, float, int, int, float, float, float, float, float, float]:
    """Vectorised numpy reference of :func:`eval_pass` (same arguments, same outputs up to rounding).

    Always float64 on the (F, gx, gy) of :func:`dmtrack.odometry.frame.pack_numpy` when ``packed`` is a
    placeholder.
    """
    fx, fy, cx, cy, aff_a, aff_b, var_weight, noise2, huber_half, good_c, good_g, aff_thr = (
        float(x) for x in prm[:N_PARAMS]
    )
    h, w = feat.shape[:2]
    if packed.shape[:2] != (h, w):
        from dmtrack.odometry.frame import pack_numpy

        packed = pack_numpy(feat)
    P = points.astype(np.float64)
    T = np.asarray(T, np.float64)
    X = P @ T[:3, :3].T + T[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        izz = 1.0 / X[:, 2]
        u = (X[:, 0] * izz) * fx + cx
        v = (X[:, 1] * izz) * fy + cy
        inside = (u > 1.0) & (v > 1.0) & (u < w - 2.0) & (v < h - 2.0)
    if write_flags:
        flags[ref_idx[~inside]] = False
    X = X[inside]
    u = u[inside]
    v = v[inside]
    pz = P[inside, 2]
    ix = u.astype(np.int64)
    iy = v.astype(np.int64)
    dx = (u - ix)[:, None, None]
    dy = (v - iy)[:, None, None]
    dxdy = dx * dy
    s = (
        dxdy * packed[iy + 1, ix + 1]
        + (dy - dxdy) * packed[iy + 1, ix]
        + (dx - dxdy) * packed[iy, ix + 1]
        + (1.0 - dx - dy + dxdy) * packed[iy, ix]
    )  # (m, 3, N)
    iv, gx, gy = s[:, 0], s[:, 1], s[:, 2]
    c1 = aff_a * ref_vals[inside].astype(np.float64) + aff_b
    r = c1 - iv
    if affine_sums:
        ar = np.abs(r)
        aw = np.where(ar < aff_thr, 1.0, aff_thr / np.maximum(ar, 1e-300))
        aff = (
            float(np.sum(c1 * c1 * aw)),
            float(np.sum(iv * iv * aw)),
            float(np.sum(c1 * aw)),
            float(np.sum(iv * aw)),
            float(np.sum(aw)),
        )
    else:
        aff = (0.0, 0.0, 0.0, 0.0, 0.0)
    r2sum = np.sum(r * r, axis=1)
    g2sum = np.sum(gx * gx + gy * gy, axis=1)
    is_good = r2sum < good_c + good_g * g2sum
    if write_flags:
        flags[ref_idx[inside]] = is_good
    wx, wy, wz = X[:, 0], X[:, 1], X[:, 2]
    tx, ty, tz = (float(x) for x in T[:3, 3])
    iz = 1.0 / wz
    zd = pz * iz * iz
    g0 = ((tx * wz - tz * wx) * zd)[:, None]
    g1 = ((ty * wz - tz * wy) * zd)[:, None]
    gxf = fx * gx
    gyf = fy * gy
    drpdd = gxf * g0 + gyf * g1
    s2 = (var_weight * ref_vars[inside].astype(np.float64))[:, None]
    wp = 1.0 / (noise2 + s2 * drpdd * drpdd)
    e2 = r * r * wp
    ww = np.where(e2 < huber_half * huber_half, wp, wp * huber_half / np.sqrt(np.maximum(e2, 1e-300)))
    buf[:] = 0.0
    rows = np.nonzero(inside)[0]
    buf[rows, 0] = wx
    buf[rows, 1] = wy
    buf[rows, 2] = wz
    buf[rows, 3] = np.sum(ww * gxf * gxf, axis=1)
    buf[rows, 4] = np.sum(ww * gxf * gyf, axis=1)
    buf[rows, 5] = np.sum(ww * gyf * gyf, axis=1)
    buf[rows, 6] = np.sum(ww * r * gxf, axis=1)
    buf[rows, 7] = np.sum(ww * r * gyf, axis=1)
    usage = float(np.sum(np.minimum(pz * iz, 1.0)))
    good = int(is_good.sum())
    m = len(rows)
    return (m, float(np.sum(ww * r * r)), good, m - good, usage, *aff)
