"""Stereo search of the depth map: the epipolar-line check and the line stereo along the epipolar line.

LSD-SLAM's ``makeAndCheckEPL`` (is the keyframe gradient along the epipolar line strong enough, and the unit
epipolar direction) and ``doLineStereo`` (the 5-sample SSD search between the near and the far end of the
inverse-depth interval in the reference frame, sub-pixel refinement, the inverse depth of the match and its
variance) for N-channel feature maps: numba kernels (``_epl_check`` and ``_line_stereo``, inlined into the
observe kernel of :mod:`dmtrack.odometry._depth_update`; ``line_stereo_numba`` for single pixels) and their
numpy references (:func:`epl_check_reference`, :func:`line_stereo_reference`). Conventions and the numba cache
caveat: :mod:`dmtrack.odometry._depth_common`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dmtrack.odometry._depth_common import (
    _JIT,
    _JIT_INLINE,
    _JIT_LANES,
    _JIT_LLVM_INLINE,
    G_CX,
    G_CXI,
    G_CY,
    G_CYI,
    G_FX,
    G_FXI,
    G_FY,
    G_FYI,
    G_KR,
    G_KT,
    G_R,
    G_T,
    G_TINV,
    G_TRACK_FAC,
    P_ALLOW_NEG,
    P_BORDER,
    P_INFO,
    P_MAX_EPL_CROP,
    P_MAX_ERR,
    P_MIN_DIST_ERR,
    P_MIN_EPL_ANGLE2,
    P_MIN_EPL_CROP,
    P_MIN_EPL_GRAD2,
    P_MIN_EPL_LEN2,
    P_PIX_NOISE2,
    P_SUBPIXEL,
    _bilinear,
    _sample,
    _sample1,
    bilinear_reference,
)
from dmtrack.odometry._lanes import LANES64, lane_dots4, lane_sample_stats4, lane_window4, scratch_f64

# ------------------------------------------------------------------------------------------ constants
#: ``GRADIENT_SAMPLE_DIST``: distance (pixels) between the 5 stereo samples.
GRADIENT_SAMPLE_DIST = 1.0
#: ``DIVISION_EPS``.
DIVISION_EPS = 1e-10


# ============================================================================== numba kernels
@numba.njit(**_JIT)
def _epl_sums(gxs, gys, epx, epy):  # pragma: no cover - compiled
    """(Σ_c ((2 gx_c, 2 gy_c)·ep)², Σ_c |2 ∇F_c|²) of one keyframe pixel (N > 1), in channel order.

    Plain IEEE arithmetic in channel order, like every sum in the odometry (see :mod:`dmtrack.odometry._lanes`).
    """
    dot2 = 0.0
    g2 = 0.0
    for c in range(gxs.shape[0]):
        gx = 2.0 * gxs[c]
        gy = 2.0 * gys[c]
        d = gx * epx + gy * epy
        dot2 += d * d
        g2 += gx * gx + gy * gy
    return dot2, g2


#: From this many channels on, the line search forms its 5-sample SSDs from per-sample dot products
#: (:func:`_sample_stats`, one pass over the channels per step); below it, directly (:func:`_window_cost`),
#: which costs fewer horizontal reductions when a step is only a vector or two of channels.
DOT_MIN_CHANNELS = 24


_ACC2 = 2 * LANES64  # scratch sizes (compile-time constants): two, five and seven float64 sums in lanes
_ACC5 = 5 * LANES64
_ACC7 = 7 * LANES64


@numba.njit(**_JIT_INLINE)
def _fold4(acc, k):  # pragma: no cover - compiled
    """``(a0 + a1) + (a2 + a3)`` of the four lanes of sum ``k`` in the scratch array ``acc``."""
    o = k * LANES64
    return (acc[o] + acc[o + 1]) + (acc[o + 2] + acc[o + 3])


@numba.njit(**_JIT_INLINE)
def _padded(n):  # pragma: no cover - compiled
    """``n``, the columns of a stereo scratch row, which must be a multiple of the lanes (see :func:`_window_cost`)."""
    if n % LANES64 != 0:
        raise ValueError("the stereo search's scratch rows must be zero-padded to a multiple of LANES64 columns")
    return n


@numba.njit(**_JIT)
def padded_channels(n):  # pragma: no cover - compiled
    """``n`` rounded up to a multiple of :data:`~dmtrack.odometry._lanes.LANES64`: the columns of the stereo search's
    float64 scratch rows (the padding stays zero)."""
    return (n + LANES64 - 1) // LANES64 * LANES64


@numba.njit(**_JIT_LANES)
def _window_cost(ring, kfv, loop):  # pragma: no cover - compiled
    """Σ_j ‖s_{L−j} − k_j‖² and Σ_j ⟨s_{L−j} − k_j, s_{L−j−1} − k_j⟩ at step L = ``loop`` directly (N > 1, few
    channels); ``ring`` row t mod 6 holds the sample s_t (see :func:`_line_stereo`). Reads only.

    ``ring`` (6, N') and ``kfv`` (5, N') are padded with zero columns to N' = a multiple of
    :data:`~dmtrack.odometry._lanes.LANES64` (a padded channel adds +0.0, which changes no sum). Each sum in four
    lanes (lane l: the channels c ≡ l mod 4, for j = 0 … 4 in turn; :func:`~dmtrack.odometry._lanes.lane_window4`),
    folded ``(a0 + a1) + (a2 + a3)``: an order fixed by the source (see :mod:`dmtrack.odometry._lanes`).
    """
    acc = scratch_f64(_ACC2)
    for k in range(_ACC2):
        acc[k] = 0.0
    n = _padded(ring.shape[1])
    for j in range(5):
        lane_window4(acc, ring[(loop + 6 - j) % 6], ring[(loop + 5 - j) % 6], kfv[j], n)
    return (acc[0] + acc[1]) + (acc[2] + acc[3]), (acc[4] + acc[5]) + (acc[6] + acc[7])


@numba.njit(**_JIT_LANES)
def _kf_norms(kfv):  # pragma: no cover - compiled
    """Squared norms of the five keyframe samples (rows of ``kfv``, (5, N') zero-padded, N > 1), each in four lanes
    (see :func:`_window_cost`)."""
    acc = scratch_f64(_ACC5)
    for k in range(_ACC5):
        acc[k] = 0.0
    rows = (kfv[0], kfv[1], kfv[2], kfv[3], kfv[4])
    lane_dots4(acc, rows, rows, _padded(kfv.shape[1]))
    return (_fold4(acc, 0), _fold4(acc, 1), _fold4(acc, 2), _fold4(acc, 3), _fold4(acc, 4))


@numba.njit(**_JIT_INLINE)
def _stats_lane(img, ix, iy, w00, w01, w10, w11, c, ring, row, prow, kfv, acc, lane):  # pragma: no cover - compiled
    """Channel ``c`` of :func:`_sample_stats` into lane ``lane`` of its seven sums (the last N mod 4 channels)."""
    v = w11 * img[iy + 1, ix + 1, c] + w01 * img[iy + 1, ix, c] + w10 * img[iy, ix + 1, c] + w00 * img[iy, ix, c]
    ring[row, c] = v
    acc[lane] += v * v
    for j in range(5):
        acc[(j + 1) * LANES64 + lane] += v * kfv[j, c]
    acc[6 * LANES64 + lane] += v * ring[prow, c]


@numba.njit(**_JIT_LANES)
def _sample_stats(img, x, y, ring, row, prow, kfv, st):  # pragma: no cover - compiled
    """Bilinear sample s of all channels at (x, y) into ``ring[row]`` and its statistics into ``st[row]``:
    (‖s‖², ⟨s, k_0⟩ … ⟨s, k_4⟩, ⟨s, ring[prow]⟩) with k_j the keyframe samples (N > 1; ``ring`` and ``kfv``
    zero-padded as in :func:`_window_cost`), each in four lanes (:func:`~dmtrack.odometry._lanes.lane_sample_stats4`
    for the whole blocks of channels, the rest here).

    With them every 5-sample SSD of the search and its cross term with the previous step are sums of
    scalars (see :func:`_line_stereo`): one pass over the N channels per search step instead of five.
    """
    ix, iy, w00, w01, w10, w11 = _bilinear(x, y)
    nch = img.shape[2]
    nfull = (nch // LANES64) * LANES64
    _padded(ring.shape[1])
    acc = scratch_f64(_ACC7)
    for k in range(_ACC7):
        acc[k] = 0.0
    lane_sample_stats4(acc, img, ix, iy, (w00, w01, w10, w11), ring, row, prow, kfv, nfull)
    for c in range(nfull, nch):
        _stats_lane(img, ix, iy, w00, w01, w10, w11, c, ring, row, prow, kfv, acc, c - nfull)
    for k in range(7):
        st[row, k] = _fold4(acc, k)


@numba.njit(**_JIT_LLVM_INLINE)
def _epl_check(kf_gx, kf_gy, x, y, geo, prm, cscale):  # pragma: no cover - compiled
    """``makeAndCheckEPL``: returns (ok, epxn, epyn) with the unit epipolar direction in the keyframe.

    ``kf_gx``, ``kf_gy``: the keyframe's gradient maps, (H, W) or (H, W, N), or for N > 1 the (N,) gradient
    vectors of pixel (x, y) itself (the observe kernel forms them on the fly instead of keeping the maps)."""
    epx = -geo[G_FX] * geo[G_TINV] + geo[G_TINV + 2] * (x - geo[G_CX])
    epy = -geo[G_FY] * geo[G_TINV + 1] + geo[G_TINV + 2] * (y - geo[G_CY])
    if math.isnan(epx + epy):
        return False, 0.0, 0.0
    len2 = epx * epx + epy * epy
    if len2 < prm[P_MIN_EPL_LEN2]:
        return False, 0.0, 0.0
    if kf_gx.ndim == 2:  # single channel as (H, W): the build for it has no channel loops
        gx = 2.0 * kf_gx[y, x]
        gy = 2.0 * kf_gy[y, x]
        d = gx * epx + gy * epy
        dot2 = d * d
        g2 = gx * gx + gy * gy
    elif kf_gx.ndim == 1:  # N > 1: the gradients of pixel (x, y) itself, (N,) vectors (see _observe_rows)
        dot2, g2 = _epl_sums(kf_gx, kf_gy, epx, epy)
    elif kf_gx.shape[2] == 1:
        gx = 2.0 * kf_gx[y, x, 0]
        gy = 2.0 * kf_gy[y, x, 0]
        d = gx * epx + gy * epy
        dot2 = d * d
        g2 = gx * gx + gy * gy
    else:
        dot2, g2 = _epl_sums(kf_gx[y, x], kf_gy[y, x], epx, epy)
    epl_grad2 = cscale * dot2 / len2
    if epl_grad2 * prm[P_INFO] < prm[P_MIN_EPL_GRAD2]:
        return False, 0.0, 0.0
    if epl_grad2 / (cscale * g2) < prm[P_MIN_EPL_ANGLE2]:
        return False, 0.0, 0.0
    fac = GRADIENT_SAMPLE_DIST / math.sqrt(len2)
    return True, epx * fac, epy * fac


@numba.njit(**_JIT_LLVM_INLINE)
def _line_stereo(
    kf, ref, kf_gx, kf_gy, u, v, epxn, epyn, min_idepth, prior_idepth, max_idepth, geo, prm, cscale, kfv, ring, st
):  # pragma: no cover - compiled
    """LSD-SLAM ``doLineStereo`` for N channels.

    ``kf``, ``ref``, ``kf_gx``, ``kf_gy`` are (H, W, N) float32 maps, or (H, W) for one channel (``kf_gx``,
    ``kf_gy`` may also be the (N,) gradient vectors of pixel (u, v), see :func:`_epl_check`): numba compiles a
    build per dimensionality and prunes the other's branches (``ndim`` is a compile-time constant), so the
    single-channel build keeps every sample in a register. ``kfv`` (5, N) and ``ring`` (6, N) are float64 scratch
    arrays (keyframe samples, reference ring; unused by the (H, W) build), ``st`` a (6, 7) float64 one
    (per-sample statistics, N > 1). Returns (err, idepth, var, epl_length): err ≥ 0 is the matching cost on
    success; −1 out of bounds, −2 ambiguous / failed, −3 error too large, −4 arithmetic.
    """
    h = kf.shape[0]
    w = kf.shape[1]
    if kf.ndim == 2:
        nch = 1
    else:
        nch = kf.shape[2]
    nan = np.nan
    # kfv: keyframe samples, rows p2, p1, 0, m1, m2 (rows 0..4); ring: reference-frame samples around the current
    # search position (6 rows, see below)

    kx = geo[G_FXI] * u + geo[G_CXI]
    ky = geo[G_FYI] * v + geo[G_CYI]
    # pInf = K R KinvP ; pReal = pInf / prior + K t
    pinf0 = geo[G_KR + 0] * kx + geo[G_KR + 1] * ky + geo[G_KR + 2]
    pinf1 = geo[G_KR + 3] * kx + geo[G_KR + 4] * ky + geo[G_KR + 5]
    pinf2 = geo[G_KR + 6] * kx + geo[G_KR + 7] * ky + geo[G_KR + 8]
    kt0 = geo[G_KT]
    kt1 = geo[G_KT + 1]
    kt2 = geo[G_KT + 2]
    preal2 = pinf2 / prior_idepth + kt2
    rescale = preal2 * prior_idepth

    first_x = u - 2.0 * epxn * rescale
    first_y = v - 2.0 * epyn * rescale
    last_x = u + 2.0 * epxn * rescale
    last_y = v + 2.0 * epyn * rescale
    if (
        first_x <= 0
        or first_x >= w - 2
        or first_y <= 0
        or first_y >= h - 2
        or last_x <= 0
        or last_x >= w - 2
        or last_y <= 0
        or last_y >= h - 2
    ):
        return -1.0, nan, nan, nan
    if not (rescale > 0.7 and rescale < 1.4):
        return -1.0, nan, nan, nan

    if kf.ndim == 2:  # the offsets s = 2, 1, 0, −1, −2 of the loop below, in the same arithmetic
        k0 = _sample1(kf, u + 2.0 * epxn * rescale, v + 2.0 * epyn * rescale)
        k1 = _sample1(kf, u + 1.0 * epxn * rescale, v + 1.0 * epyn * rescale)
        k2 = _sample1(kf, u + 0.0 * epxn * rescale, v + 0.0 * epyn * rescale)
        k3 = _sample1(kf, u + -1.0 * epxn * rescale, v + -1.0 * epyn * rescale)
        k4 = _sample1(kf, u + -2.0 * epxn * rescale, v + -2.0 * epyn * rescale)
    else:
        for k in range(5):
            s = float(2 - k)  # p2, p1, 0, m1, m2
            _sample(kf, u + s * epxn * rescale, v + s * epyn * rescale, kfv, k)

    # near point (max idepth) and far point (min idepth) in the reference frame
    pc0 = pinf0 + kt0 * max_idepth
    pc1 = pinf1 + kt1 * max_idepth
    pc2 = pinf2 + kt2 * max_idepth
    if pc2 < 0.001:
        max_idepth = (0.001 - pinf2) / kt2
        pc0 = pinf0 + kt0 * max_idepth
        pc1 = pinf1 + kt1 * max_idepth
        pc2 = pinf2 + kt2 * max_idepth
    pclose_x = pc0 / pc2
    pclose_y = pc1 / pc2
    pf0 = pinf0 + kt0 * min_idepth
    pf1 = pinf1 + kt1 * min_idepth
    pf2 = pinf2 + kt2 * min_idepth
    if pf2 < 0.001 or max_idepth < min_idepth:
        return -1.0, nan, nan, nan
    pfar_x = pf0 / pf2
    pfar_y = pf1 / pf2
    if math.isnan(pfar_x + pclose_x):
        return -4.0, nan, nan, nan

    incx = pclose_x - pfar_x
    incy = pclose_y - pfar_y
    epl_length = math.sqrt(incx * incx + incy * incy)
    if epl_length == 0.0 or math.isinf(epl_length):
        return -4.0, nan, nan, nan
    max_crop = prm[P_MAX_EPL_CROP]
    if epl_length > max_crop:
        pclose_x = pfar_x + incx * max_crop / epl_length
        pclose_y = pfar_y + incy * max_crop / epl_length
    incx *= GRADIENT_SAMPLE_DIST / epl_length
    incy *= GRADIENT_SAMPLE_DIST / epl_length
    # extend one sample distance on both sides
    pfar_x -= incx
    pfar_y -= incy
    pclose_x += incx
    pclose_y += incy
    min_crop = prm[P_MIN_EPL_CROP]
    if epl_length < min_crop:
        pad = (min_crop - epl_length) / 2.0
        pfar_x -= incx * pad
        pfar_y -= incy * pad
        pclose_x += incx * pad
        pclose_y += incy * pad

    b = prm[P_BORDER]
    if pfar_x <= b or pfar_x >= w - b or pfar_y <= b or pfar_y >= h - b:
        return -1.0, nan, nan, nan
    if pclose_x <= b or pclose_x >= w - b or pclose_y <= b or pclose_y >= h - b:
        # LSD-SLAM moves the near point back along the line onto the border and re-tests it with the same strict
        # test (≤ border / ≥ size − border): the moved coordinate lands on the border value itself (up to float32
        # rounding of a step it cannot overshoot), so the re-test fails — in effect the pixel is out of bounds
        return -1.0, nan, nan, nan

    # search along the line, starting at infinity (pFar). win[j] holds the reference-frame sample at
    # offset 2 − j from cp (j = 0: +2 … j = 4: −2), the same order as the keyframe samples kfv.
    cpx = pfar_x
    cpy = pfar_y
    # grey: rows 1..4 hold offsets +1..−2 and row 0 the newest sample. N > 1: the sample s_t taken at step t
    # (offset +2 of that step; s_−1 … s_−4 are the offsets +1 … −2 of step 0) lives in ring row t mod 6 with its
    # statistics in st (see _sample_stats); at step L the window holds s_L … s_{L−4} (row j of the keyframe
    # samples pairs with s_{L−j}), so with k_j the keyframe samples
    #   SSD   = Σ_j ‖s_{L−j}‖² − 2⟨s_{L−j}, k_j⟩ + ‖k_j‖²
    #   cross = Σ_j ⟨s_{L−j}, s_{L−j−1}⟩ − ⟨s_{L−j}, k_j⟩ − ⟨s_{L−j−1}, k_j⟩ + ‖k_j‖²
    # (the same sums as Σ_j ‖s_{L−j} − k_j‖² and Σ_j ⟨s_{L−j} − k_j, s_{L−j−1} − k_j⟩, in float64); with fewer
    # than DOT_MIN_CHANNELS channels those are formed directly instead (_window_cost)
    win = ring
    grey = nch == 1
    dots = nch >= DOT_MIN_CHANNELS
    # grey fast path: window, keyframe samples and previous residuals in scalars (registers)
    v0 = 0.0
    if kf.ndim == 2:  # offsets 1, 0, −1, −2 as in the loop below
        v1 = _sample1(ref, cpx + 1.0 * incx, cpy + 1.0 * incy)
        v2 = _sample1(ref, cpx + 0.0 * incx, cpy + 0.0 * incy)
        v3 = _sample1(ref, cpx + -1.0 * incx, cpy + -1.0 * incy)
        v4 = _sample1(ref, cpx + -2.0 * incx, cpy + -2.0 * incy)
        kk0 = kk1 = kk2 = kk3 = kk4 = 0.0
    else:
        if not dots:
            for j in range(1, 5):
                off = float(2 - j)
                _sample(ref, cpx + off * incx, cpy + off * incy, win, j if grey else 6 - j)
            kk0 = kk1 = kk2 = kk3 = kk4 = 0.0
        else:
            kk0, kk1, kk2, kk3, kk4 = _kf_norms(kfv)
            for j in range(4, 0, -1):
                off = float(2 - j)
                _sample_stats(ref, cpx + off * incx, cpy + off * incy, win, 6 - j, 5 - j, kfv, st)
        k0 = kfv[0, 0]
        k1 = kfv[1, 0]
        k2 = kfv[2, 0]
        k3 = kfv[3, 0]
        k4 = kfv[4, 0]
        v1 = win[1, 0]
        v2 = win[2, 0]
        v3 = win[3, 0]
        v4 = win[4, 0]
    q0 = q1 = q2 = q3 = q4 = 0.0

    loop = 0
    best_x = -1.0
    best_y = -1.0
    best_err = 1e50
    second_err = 1e50
    best_pre = nan
    best_post = nan
    best_diff_pre = nan
    best_diff_post = nan
    best_was_last = False
    ee_last = -1.0
    loop_best = -1
    loop_second = -1
    while ((incx < 0) == (cpx > pclose_x) and (incy < 0) == (cpy > pclose_y)) or loop == 0:
        if grey:
            if loop > 0:
                v4 = v3
                v3 = v2
                v2 = v1
                v1 = v0
            if kf.ndim == 2:
                v0 = _sample1(ref, cpx + 2.0 * incx, cpy + 2.0 * incy)
            else:
                _sample(ref, cpx + 2.0 * incx, cpy + 2.0 * incy, win, 0)
                v0 = win[0, 0]
            e0 = v0 - k0
            e1 = v1 - k1
            e2 = v2 - k2
            e3 = v3 - k3
            e4 = v4 - k4
            ee = e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3 + e4 * e4
            cross = e0 * q0 + e1 * q1 + e2 * q2 + e3 * q3 + e4 * q4
            q0 = e0
            q1 = e1
            q2 = e2
            q3 = e3
            q4 = e4
        elif not dots:
            _sample(ref, cpx + 2.0 * incx, cpy + 2.0 * incy, win, loop % 6)
            ee, cross = _window_cost(win, kfv, loop)
        else:
            r0 = loop % 6
            r1 = (loop + 5) % 6
            r2 = (loop + 4) % 6
            r3 = (loop + 3) % 6
            r4 = (loop + 2) % 6
            r5 = (loop + 1) % 6
            _sample_stats(ref, cpx + 2.0 * incx, cpy + 2.0 * incy, win, r0, r1, kfv, st)
            ee = (st[r0, 0] - 2.0 * st[r0, 1] + kk0 + st[r1, 0] - 2.0 * st[r1, 2] + kk1
                  + st[r2, 0] - 2.0 * st[r2, 3] + kk2 + st[r3, 0] - 2.0 * st[r3, 4] + kk3
                  + st[r4, 0] - 2.0 * st[r4, 5] + kk4)  # fmt: skip
            cross = (st[r0, 6] - st[r0, 1] - st[r1, 1] + kk0 + st[r1, 6] - st[r1, 2] - st[r2, 2] + kk1
                     + st[r2, 6] - st[r2, 3] - st[r3, 3] + kk2 + st[r3, 6] - st[r3, 4] - st[r4, 4] + kk3
                     + st[r4, 6] - st[r4, 5] - st[r5, 5] + kk4)  # fmt: skip
        ee *= cscale
        cross = cscale * cross if loop > 0 else nan
        if ee < best_err:
            second_err = best_err
            loop_second = loop_best
            best_err = ee
            loop_best = loop
            best_pre = ee_last
            best_diff_pre = cross
            best_post = -1.0
            best_diff_post = -1.0
            best_x = cpx
            best_y = cpy
            best_was_last = True
        else:
            if best_was_last:
                best_post = ee
                best_diff_post = cross
                best_was_last = False
            if ee < second_err:
                second_err = ee
                loop_second = loop
        ee_last = ee
        cpx += incx
        cpy += incy
        loop += 1

    if best_err > 4.0 * prm[P_MAX_ERR]:
        return -3.0, nan, nan, nan
    if abs(loop_best - loop_second) > 1 and prm[P_MIN_DIST_ERR] * best_err > second_err:
        return -2.0, nan, nan, nan

    did_subpixel = False
    if prm[P_SUBPIXEL] != 0.0:
        grad_pre_pre = -(best_pre - best_diff_pre)
        grad_pre_this = best_err - best_diff_pre
        grad_post_this = -(best_err - best_diff_post)
        grad_post_post = best_post - best_diff_post
        interp_pre = False
        interp_post = False
        # LSD-SLAM's release build: a best match at an end of the segment has no real neighbour on that side
        # (errPre = −1 and DiffErrPre = NaN at the first step; errPost = DiffErrPost = −1 at the last); its
        # test for that case is compiled out with the debug statistics, so the gradient tests below run on
        # those values (NaN compares false). At the first step this can interpolate towards the second sample;
        # at the last step it can give interpPost with d = 1 and an error of exactly −1, which the callers
        # treat as "out of bounds".
        if (grad_post_this < 0) ^ (grad_pre_this < 0):
            pass  # zero crossing exactly in between
        elif (grad_pre_pre < 0) ^ (grad_pre_this < 0):
            if not ((grad_post_post < 0) ^ (grad_post_this < 0)):
                interp_pre = True
        elif (grad_post_post < 0) ^ (grad_post_this < 0):
            interp_post = True
        if interp_pre:
            d = grad_pre_this / (grad_pre_this - grad_pre_pre)
            best_x -= d * incx
            best_y -= d * incy
            best_err = best_err - 2.0 * d * grad_pre_this - (grad_pre_pre - grad_pre_this) * d * d
            did_subpixel = True
        elif interp_post:
            d = grad_post_this / (grad_post_this - grad_post_post)
            best_x += d * incx
            best_y += d * incy
            best_err = best_err + 2.0 * d * grad_post_this + (grad_post_post - grad_post_this) * d * d
            did_subpixel = True

    sample_dist = GRADIENT_SAMPLE_DIST * rescale
    gal = 0.0
    if kf.ndim == 2:  # the loop below for one channel
        t = k0 - k1
        gal += t * t
        t = k1 - k2
        gal += t * t
        t = k2 - k3
        gal += t * t
        t = k3 - k4
        gal += t * t
    else:
        for k in range(4):
            for c in range(nch):
                t = kfv[k, c] - kfv[k + 1, c]
                gal += t * t
    gal = cscale * gal / (sample_dist * sample_dist)
    if best_err > prm[P_MAX_ERR] + math.sqrt(gal) * 20.0:
        return -3.0, nan, nan, nan

    # inverse depth from the match along the dominant axis
    t0 = geo[G_T]
    t1 = geo[G_T + 1]
    t2 = geo[G_T + 2]
    dot2 = kx * geo[G_R + 6] + ky * geo[G_R + 7] + geo[G_R + 8]
    if incx * incx > incy * incy:
        old_x = geo[G_FXI] * best_x + geo[G_CXI]
        nom = old_x * t2 - t0
        dot0 = kx * geo[G_R + 0] + ky * geo[G_R + 1] + geo[G_R + 2]
        idnew = (dot0 - old_x * dot2) / nom
        alpha = incx * geo[G_FXI] * (dot0 * t2 - dot2 * t0) / (nom * nom)
    else:
        old_y = geo[G_FYI] * best_y + geo[G_CYI]
        nom = old_y * t2 - t1
        dot1 = kx * geo[G_R + 3] + ky * geo[G_R + 4] + geo[G_R + 5]
        idnew = (dot1 - old_y * dot2) / nom
        alpha = incy * geo[G_FYI] * (dot1 * t2 - dot2 * t1) / (nom * nom)
    if idnew < 0 and prm[P_ALLOW_NEG] == 0.0:
        return -2.0, nan, nan, nan

    photo = 4.0 * prm[P_PIX_NOISE2] / (gal * prm[P_INFO] + DIVISION_EPS)
    tau = geo[G_TRACK_FAC]
    iu = int(u)
    iv = int(v)
    gg = 0.0
    ge = 0.0
    if kf.ndim == 2:  # the loop below for one channel (float32 squares, as there)
        gxc = kf_gx[iv, iu]
        gyc = kf_gy[iv, iu]
        gg += gxc * gxc + gyc * gyc
        d = gxc * epxn + gyc * epyn
        ge += d * d
    elif kf_gx.ndim == 1:  # the gradients of pixel (u, v) as (N,) vectors (see _epl_check)
        for c in range(nch):
            gxc = kf_gx[c]
            gyc = kf_gy[c]
            gg += gxc * gxc + gyc * gyc
            d = gxc * epxn + gyc * epyn
            ge += d * d
    else:
        for c in range(nch):
            gxc = kf_gx[iv, iu, c]
            gyc = kf_gy[iv, iu, c]
            gg += gxc * gxc + gyc * gyc
            d = gxc * epxn + gyc * epyn
            ge += d * d
    geo_err = tau * tau * (cscale * gg) / (cscale * ge + DIVISION_EPS)
    disc = 0.05 if did_subpixel else 0.5
    var = alpha * alpha * (disc * sample_dist * sample_dist + geo_err + photo)
    return best_err, idnew, var, epl_length


@numba.njit(**_JIT)
def line_stereo_numba(
    kf, ref, kf_gx, kf_gy, u, v, epxn, epyn, min_idepth, prior_idepth, max_idepth, geo, prm, cscale
):  # pragma: no cover - compiled
    """Single-pixel line stereo (allocates its own scratch). See :func:`line_stereo_reference`."""
    if kf.ndim == 2:
        nch = 1
    else:
        nch = kf.shape[2]
    kfv = np.zeros((5, padded_channels(nch)), np.float64)  # zero padding: see _window_cost
    ring = np.zeros((6, padded_channels(nch)), np.float64)
    st = np.empty((6, 7), np.float64)
    return _line_stereo(
        kf, ref, kf_gx, kf_gy, u, v, epxn, epyn, min_idepth, prior_idepth, max_idepth, geo, prm, cscale, kfv, ring, st
    )


# ============================================================================== numpy references
def epl_check_reference(
    kf_gx: np.ndarray, kf_gy: np.ndarray, x: int, y: int, geo: np.ndarray, prm: np.ndarray, cscale: float
) -> tuple[bool, float, float]:
    """Reference of ``makeAndCheckEPL``: (ok, epxn, epyn)."""
    tinv = geo[G_TINV : G_TINV + 3]
    e = np.array([-geo[G_FX] * tinv[0] + tinv[2] * (x - geo[G_CX]), -geo[G_FY] * tinv[1] + tinv[2] * (y - geo[G_CY])])
    if np.isnan(e).any():
        return False, 0.0, 0.0
    len2 = float(e @ e)
    if len2 < prm[P_MIN_EPL_LEN2]:
        return False, 0.0, 0.0
    g = 2.0 * np.stack([kf_gx[y, x].astype(np.float64), kf_gy[y, x].astype(np.float64)], axis=1)  # (N, 2)
    epl_grad2 = cscale * float(np.sum((g @ e) ** 2)) / len2
    if epl_grad2 * prm[P_INFO] < prm[P_MIN_EPL_GRAD2]:
        return False, 0.0, 0.0
    if epl_grad2 / (cscale * float(np.sum(g * g))) < prm[P_MIN_EPL_ANGLE2]:
        return False, 0.0, 0.0
    e = e * (GRADIENT_SAMPLE_DIST / np.sqrt(len2))
    return True, float(e[0]), float(e[1])


def line_stereo_reference(
    kf: np.ndarray,
    ref: np.ndarray,
    kf_gx: np.ndarray,
    kf_gy: np.ndarray,
    u: float,
    v: float,
    epxn: float,
    epyn: float,
    min_idepth: float,
    prior_idepth: float,
    max_idepth: float,
    geo: np.ndarray,
    prm: np.ndarray,
    cscale: float,
) -> tuple[float, float, float, float]:
    """Line stereo of one keyframe pixel along its epipolar line in the reference frame (numpy reference).

    Parameters
    ----------
    kf, ref : (H, W, N) float32
        Keyframe and reference-frame feature maps.
    kf_gx, kf_gy : (H, W, N) float32
        Keyframe halved gradients.
    u, v : float
        Keyframe pixel.
    epxn, epyn : float
        Unit epipolar direction in the keyframe (from :func:`epl_check_reference`).
    min_idepth, prior_idepth, max_idepth : float
        Search interval and prior of the inverse depth (keyframe units).
    geo, prm : np.ndarray
        Stereo geometry and parameters (:func:`~dmtrack.odometry._depth_common.stereo_geometry`,
        :func:`~dmtrack.odometry._depth_common.make_params`).
    cscale : float
        Channel reduction factor (1 = sum over channels, 1/N = mean).

    Returns
    -------
    (err, idepth, var, epl_length)
        err ≥ 0: matching cost (sum over the 5 samples of the squared L2 over channels, × cscale), idepth the
        keyframe inverse depth of the match, var its variance, epl_length the uncropped search length
        (pixels). err < 0: −1 out of bounds, −2 ambiguous, −3 error too large, −4 arithmetic failure; the
        other values are NaN.
    """
    h, w = kf.shape[:2]
    fail = (np.nan, np.nan, np.nan)
    kinvp = np.array([geo[G_FXI] * u + geo[G_CXI], geo[G_FYI] * v + geo[G_CYI], 1.0])
    KR = geo[G_KR : G_KR + 9].reshape(3, 3)
    Kt = geo[G_KT : G_KT + 3]
    pinf = KR @ kinvp
    rescale = (pinf[2] / prior_idepth + Kt[2]) * prior_idepth
    offs = np.array([2.0, 1.0, 0.0, -1.0, -2.0])
    kx = u + offs * epxn * rescale
    ky = v + offs * epyn * rescale
    if not (kx.min() > 0 and kx.max() < w - 2 and ky.min() > 0 and ky.max() < h - 2):
        return (-1.0, *fail)
    if not 0.7 < rescale < 1.4:
        return (-1.0, *fail)
    kfv = bilinear_reference(kf, kx, ky)  # (5, N)

    pclose = pinf + Kt * max_idepth
    if pclose[2] < 0.001:
        max_idepth = (0.001 - pinf[2]) / Kt[2]
        pclose = pinf + Kt * max_idepth
    pclose = pclose[:2] / pclose[2]
    pfar = pinf + Kt * min_idepth
    if pfar[2] < 0.001 or max_idepth < min_idepth:
        return (-1.0, *fail)
    pfar = pfar[:2] / pfar[2]
    if not np.isfinite(pfar[0] + pclose[0]):
        return (-4.0, *fail)
    inc = pclose - pfar
    epl_length = float(np.hypot(inc[0], inc[1]))
    if epl_length == 0.0 or not np.isfinite(epl_length):
        return (-4.0, *fail)
    if epl_length > prm[P_MAX_EPL_CROP]:
        pclose = pfar + inc * (prm[P_MAX_EPL_CROP] / epl_length)
    inc = inc * (GRADIENT_SAMPLE_DIST / epl_length)
    pfar = pfar - inc
    pclose = pclose + inc
    if epl_length < prm[P_MIN_EPL_CROP]:
        pad = (prm[P_MIN_EPL_CROP] - epl_length) / 2.0
        pfar = pfar - inc * pad
        pclose = pclose + inc * pad
    b = prm[P_BORDER]
    lo = np.array([b, b])
    hi = np.array([w - b, h - b])
    if np.any(pfar <= lo) or np.any(pfar >= hi):
        return (-1.0, *fail)
    if np.any(pclose <= lo) or np.any(pclose >= hi):
        return (-1.0, *fail)  # the near point is outside (LSD-SLAM's move-and-re-test fails, see the kernel)

    # search positions: start at pFar, step inc, while still before pClose (always at least one)
    positions = []
    cp = pfar.copy()
    while ((inc[0] < 0) == (cp[0] > pclose[0]) and (inc[1] < 0) == (cp[1] > pclose[1])) or not positions:
        positions.append(cp.copy())
        cp[0] += inc[0]
        cp[1] += inc[1]
    cps = np.array(positions)  # (S, 2)
    # sample at cp + j·inc for j = +2..−2 (same order as the keyframe samples)
    sx = cps[:, 0:1] + offs[None, :] * inc[0]
    sy = cps[:, 1:2] + offs[None, :] * inc[1]
    # positions of the 5 samples are cp + j·inc computed once per step (the kernel re-uses them
    # from previous steps; the values agree up to the rounding of the accumulated position)
    vals = bilinear_reference(ref, sx, sy)  # (S, 5, N)
    res = vals - kfv[None]
    cost = cscale * np.sum(res * res, axis=(1, 2))  # (S,)
    cross = np.full(len(cost), np.nan)
    cross[1:] = cscale * np.sum(res[1:] * res[:-1], axis=(1, 2))  # Σ e_k·e_{k−1}

    ib = int(np.argmin(cost))
    best_err = float(cost[ib])
    masked = cost.copy()
    masked[ib] = np.inf
    if len(cost) > 1:
        isec = int(np.argmin(masked))
        second_err = float(masked[isec])
    else:
        isec, second_err = -1, 1e50
    if best_err > 4.0 * prm[P_MAX_ERR]:
        return (-3.0, *fail)
    if abs(ib - isec) > 1 and prm[P_MIN_DIST_ERR] * best_err > second_err:
        return (-2.0, *fail)

    best = cps[ib].copy()
    did_subpixel = False
    if prm[P_SUBPIXEL] != 0.0:
        # the neighbours of the best step; at an end of the segment the values LSD-SLAM's loop leaves there
        # (see the kernel): before the first step errPre = −1, DiffErrPre = NaN; after the last errPost =
        # DiffErrPost = −1
        e_pre, c_pre = (cost[ib - 1], cross[ib]) if ib > 0 else (-1.0, np.nan)
        e_post, c_post = (cost[ib + 1], cross[ib + 1]) if ib < len(cost) - 1 else (-1.0, -1.0)
        g_pre_pre = -(e_pre - c_pre)
        g_pre_this = best_err - c_pre
        g_post_this = -(best_err - c_post)
        g_post_post = e_post - c_post
        cross_pre = bool(g_pre_pre < 0) != bool(g_pre_this < 0)
        cross_post = bool(g_post_post < 0) != bool(g_post_this < 0)
        between = bool(g_post_this < 0) != bool(g_pre_this < 0)
        if not between and cross_pre and not cross_post:
            d = g_pre_this / (g_pre_this - g_pre_pre)
            best -= d * inc
            best_err = best_err - 2 * d * g_pre_this - (g_pre_pre - g_pre_this) * d * d
            did_subpixel = True
        elif not between and not cross_pre and cross_post:
            d = g_post_this / (g_post_this - g_post_post)
            best += d * inc
            best_err = best_err + 2 * d * g_post_this + (g_post_post - g_post_this) * d * d
            did_subpixel = True

    sample_dist = GRADIENT_SAMPLE_DIST * rescale
    gal = cscale * float(np.sum(np.diff(kfv, axis=0) ** 2)) / sample_dist**2
    if best_err > prm[P_MAX_ERR] + np.sqrt(gal) * 20.0:
        return (-3.0, *fail)

    Rm = geo[G_R : G_R + 9].reshape(3, 3)
    t = geo[G_T : G_T + 3]
    dots = Rm @ kinvp
    axis = 0 if inc[0] ** 2 > inc[1] ** 2 else 1
    fi = geo[G_FXI] if axis == 0 else geo[G_FYI]
    ci = geo[G_CXI] if axis == 0 else geo[G_CYI]
    old = fi * best[axis] + ci
    nom = old * t[2] - t[axis]
    idnew = (dots[axis] - old * dots[2]) / nom
    alpha = inc[axis] * fi * (dots[axis] * t[2] - dots[2] * t[axis]) / (nom * nom)
    if idnew < 0 and prm[P_ALLOW_NEG] == 0.0:
        return (-2.0, *fail)

    photo = 4.0 * prm[P_PIX_NOISE2] / (gal * prm[P_INFO] + DIVISION_EPS)
    g = np.stack([kf_gx[int(v), int(u)], kf_gy[int(v), int(u)]], axis=1).astype(np.float64)  # (N, 2)
    tau = geo[G_TRACK_FAC]
    geo_err = (
        tau
        * tau
        * cscale
        * float(np.sum(g * g))
        / (cscale * float(np.sum((g @ np.array([epxn, epyn])) ** 2)) + DIVISION_EPS)
    )
    disc = 0.05 if did_subpixel else 0.5
    var = alpha * alpha * (disc * sample_dist**2 + geo_err + photo)
    return best_err, float(idnew), float(var), epl_length
