"""Numba kernels of the semi-dense depth map, with plain numpy/python references.

This module implements the per-pixel work of LSD-SLAM's ``DepthMap`` (lsd-slam-spec.md §3) for N-channel
feature maps (§4): the 5-sample line stereo along the epipolar line, the observe loop (create / update of
hypotheses with the EKF fusion and the validity / blacklist counters), the radius-2 regularisation (with and
without occlusion removal), hole filling and the depth propagation into a new keyframe.

Each kernel has a reference implementation written independently in plain numpy / python (``*_reference``),
used by :class:`dmtrack.odometry.depthmap.DepthMap` when ``use_numba=False`` and by the tests, which check
that both agree on small images.

Conventions
-----------
* Per-pixel state arrays are (H, W): ``valid`` bool, ``blacklisted`` int32, ``next_id`` int32
  (``nextStereoFrameMinID``), ``validity`` float32 (integer-valued, as LSD-SLAM's ``int validity_counter``),
  ``idepth``, ``var``, ``idepth_s``, ``var_s`` float32 (raw and smoothed inverse depth and variance).
* Feature maps are (H, W, N) float32; ``gx``, ``gy`` are the halved central differences of the frame
  pyramid (so the un-halved LSD-SLAM differences are 2·gx, 2·gy).
* Channel reduction of every SSD-type quantity (stereo cost, its cross terms, ``gradAlongLine``, the
  epipolar-gradient check and the propagation colour test): the sum over channels multiplied by ``cscale``
  (``ChannelRule.residual``: 1 for ``channel_cost="sum"``, 1/N otherwise). Where a gradient sum acts as
  information — the epipolar-gradient gate ``MIN_EPL_GRAD_SQUARED`` and the photometric variance
  ``4σ²/gradAlongLine`` — it is further multiplied by ``prm[P_INFO]`` (``ChannelRule.info``: κ, the feature's
  grey-equivalent channel count, for ``"balanced"``; 1 otherwise). See docs/multichannel-cost.md.
* Scalars are computed in float64 and stored as float32 (note: inside numba, ``float()`` of a float32
  array element stays float32, hence the explicit ``np.float64`` conversions), except the regularisation,
  which runs in float32 like LSD-SLAM (its reference makes the same float32 decisions).
* Constants come packed in a float64 vector ``prm`` (see :func:`make_params` and the ``P_*`` indices); the
  stereo geometry of a (keyframe, frame) pair in ``geo`` (see :func:`stereo_geometry` and ``G_*``).
"""

from __future__ import annotations

import contextlib
import math
import types

import numba
import numpy as np
from numba import prange

from dmtrack.odometry._fastmath import FASTMATH
from dmtrack.odometry.config import UPDATE_VARIANCE_MODES

# ------------------------------------------------------------------------------------------ constants
#: ``GRADIENT_SAMPLE_DIST``: distance (pixels) between the 5 stereo samples.
GRADIENT_SAMPLE_DIST = 1.0
#: ``DIVISION_EPS``.
DIVISION_EPS = 1e-10
#: ``DIFF_FAC_OBSERVE``, ``DIFF_FAC_SMOOTHING``, ``DIFF_FAC_PROP_MERGE`` (all 1 in LSD-SLAM).
DIFF_FAC_OBSERVE = 1.0
DIFF_FAC_SMOOTHING = 1.0
DIFF_FAC_PROP_MERGE = 1.0
#: ``MAX_DIFF_CONSTANT`` and ``MAX_DIFF_GRAD_MULT`` of the propagation colour test (used only when no
#: ``refPixelWasGood`` flags are given).
MAX_DIFF_CONSTANT = 40.0 * 40.0
MAX_DIFF_GRAD_MULT = 0.5 * 0.5
#: Level at which the tracker's ``refPixelWasGood`` flags live (``SE3TRACKING_MIN_LEVEL``).
GOOD_LEVEL = 1

# indices into the parameter vector ``prm``
P_MIN_GRAD = 0  # MIN_ABS_GRAD_CREATE = MIN_ABS_GRAD_DECREASE = minUseGrad
P_MAX_VAR = 1
P_VAR_INIT = 2  # VAR_RANDOM_INIT_INITIAL
P_SUCC_VAR_INC = 3
P_FAIL_VAR_INC = 4
P_VAL_INC = 5
P_VAL_DEC = 6
P_VAL_INIT_OBS = 7
P_VAL_MAX = 8
P_VAL_MAX_VAR = 9
P_VAL_SUM_CREATE = 10
P_VAL_SUM_KEEP = 11
P_VAL_SUM_UNBL = 12
P_MIN_BLACKLIST = 13
P_MIN_DEPTH = 14
P_MAX_EPL_CROP = 15
P_MIN_EPL_CROP = 16
P_BORDER = 17
P_MAX_ERR = 18
P_MIN_DIST_ERR = 19
P_EPL_VAR_FAC = 20
P_MIN_EPL_GRAD2 = 21
P_MIN_EPL_LEN2 = 22
P_MIN_EPL_ANGLE2 = 23
P_REG_DIST_VAR = 24
P_ALLOW_NEG = 25
P_SUBPIXEL = 26
P_PIX_NOISE2 = 27
P_UPDATE_VAR = 28  # 0: smoothed (LSD-SLAM), 1: raw-search, 2: raw (see DepthConfig.update_variance)
P_INFO = 29  # information factor of the channel rule (ChannelRule.info; 1 for N = 1, "sum" and "mean")
N_PARAMS = 30

# indices into the stereo geometry vector ``geo`` (other = keyframe, this = reference frame)
G_FX, G_FY, G_CX, G_CY = 0, 1, 2, 3
G_FXI, G_FYI, G_CXI, G_CYI = 4, 5, 6, 7
G_KR = 8  # K·R_fk, 9 values row-major (K_otherToThis_R)
G_KT = 17  # K·t_fk (K_otherToThis_t)
G_T = 20  # t_fk (otherToThis_t)
G_R = 23  # R_fk row-major (otherToThis_R_row0..2)
G_TINV = 32  # t_kf = −R_fkᵀ t_fk: the frame's centre in keyframe coordinates (thisToOther_t)
G_TRACK_FAC = 35  # 0.25·(1 + initialTrackedResidual)
N_GEO = 36

# observe counters (columns of the per-row count array)
C_INVALIDATED_GRAD = 0
C_CREATE_ATTEMPTED = 1
C_CREATED = 2
C_UPDATE_ATTEMPTED = 3
C_UPDATED = 4
C_SKIP_SCHEDULED = 5
C_SKIP_NOT_GOOD = 6
C_SKIP_EPL = 7
C_OOB = 8
C_FAIL = 9
C_NOT_FOUND = 10
C_INCONSISTENT = 11
C_BLACKLISTED = 12
N_COUNTS = 13
COUNT_NAMES = (
    "invalidated_grad",
    "create_attempted",
    "created",
    "update_attempted",
    "updated",
    "skip_scheduled",
    "skip_not_good",
    "skip_epl",
    "oob",
    "fail_ambiguous",
    "not_found",
    "inconsistent",
    "blacklisted",
)

# propagation counters
PC_ATTEMPTS = 0
PC_OOB = 1
PC_DROPPED_GOOD = 2
PC_OCCLUDED = 3
PC_CREATED = 4
PC_MERGED = 5
N_PCOUNTS = 6
PCOUNT_NAMES = ("attempts", "out_of_bounds", "dropped_not_good", "occluded", "created", "merged")


def make_params(cfg, info: float = 1.0) -> np.ndarray:
    """Pack a :class:`~dmtrack.odometry.config.DepthConfig` into the float64 parameter vector ``prm``.

    ``REG_DIST_VAR`` is ``reg_dist_var · depth_smoothing_factor²`` as in LSD-SLAM. ``info`` is the information
    factor of the channel rule (:class:`~dmtrack.odometry.config.ChannelRule`): the epipolar-gradient gate and
    the photometric variance use ``info · cscale · Σ_c`` of their gradient sums.
    """
    p = np.zeros(N_PARAMS, np.float64)
    p[P_MIN_GRAD] = cfg.min_use_grad
    p[P_MAX_VAR] = cfg.max_var
    p[P_VAR_INIT] = cfg.var_random_init_initial
    p[P_SUCC_VAR_INC] = cfg.succ_var_inc_fac
    p[P_FAIL_VAR_INC] = cfg.fail_var_inc_fac
    p[P_VAL_INC] = cfg.validity_counter_inc
    p[P_VAL_DEC] = cfg.validity_counter_dec
    p[P_VAL_INIT_OBS] = cfg.validity_counter_initial_observe
    p[P_VAL_MAX] = cfg.validity_counter_max
    p[P_VAL_MAX_VAR] = cfg.validity_counter_max_variable
    p[P_VAL_SUM_CREATE] = cfg.val_sum_min_for_create
    p[P_VAL_SUM_KEEP] = cfg.val_sum_min_for_keep
    p[P_VAL_SUM_UNBL] = cfg.val_sum_min_for_unblacklist
    p[P_MIN_BLACKLIST] = cfg.min_blacklist
    p[P_MIN_DEPTH] = cfg.min_depth
    p[P_MAX_EPL_CROP] = cfg.max_epl_length_crop
    p[P_MIN_EPL_CROP] = cfg.min_epl_length_crop
    p[P_BORDER] = cfg.sample_point_to_border
    p[P_MAX_ERR] = cfg.max_error_stereo
    p[P_MIN_DIST_ERR] = cfg.min_distance_error_stereo
    p[P_EPL_VAR_FAC] = cfg.stereo_epl_var_fac
    p[P_MIN_EPL_GRAD2] = cfg.min_epl_grad_squared
    p[P_MIN_EPL_LEN2] = cfg.min_epl_length_squared
    p[P_MIN_EPL_ANGLE2] = cfg.min_epl_angle_squared
    p[P_REG_DIST_VAR] = cfg.reg_dist_var * cfg.depth_smoothing_factor**2
    p[P_ALLOW_NEG] = 1.0 if cfg.allow_negative_idepths else 0.0
    p[P_SUBPIXEL] = 1.0 if cfg.use_subpixel_stereo else 0.0
    p[P_PIX_NOISE2] = cfg.camera_pixel_noise2
    p[P_UPDATE_VAR] = UPDATE_VARIANCE_MODES.index(cfg.update_variance)
    p[P_INFO] = float(info)
    return p


def stereo_geometry(
    fx: float, fy: float, cx: float, cy: float, T_fk: np.ndarray, initial_tracked_residual: float
) -> np.ndarray:
    """Stereo geometry vector ``geo`` of a keyframe / reference-frame pair (LSD-SLAM ``prepareForStereoWith``).

    Parameters
    ----------
    fx, fy, cx, cy : float
        Level-0 intrinsics (pixels).
    T_fk : (4, 4) array
        Keyframe → frame rigid transform (``otherToThis``).
    initial_tracked_residual : float
        The tracker's last residual / point usage; sets τ = 0.25·(1 + residual) of the geometric error.

    Returns
    -------
    (N_GEO,) float64 array, indexed by the ``G_*`` constants.
    """
    T = np.asarray(T_fk, np.float64)
    R = T[:3, :3]
    t = T[:3, 3]
    K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    g = np.zeros(N_GEO, np.float64)
    g[G_FX], g[G_FY], g[G_CX], g[G_CY] = fx, fy, cx, cy
    g[G_FXI], g[G_FYI], g[G_CXI], g[G_CYI] = 1.0 / fx, 1.0 / fy, -cx / fx, -cy / fy
    g[G_KR : G_KR + 9] = (K @ R).ravel()
    g[G_KT : G_KT + 3] = K @ t
    g[G_T : G_T + 3] = t
    g[G_R : G_R + 9] = R.ravel()
    g[G_TINV : G_TINV + 3] = -R.T @ t
    g[G_TRACK_FAC] = 0.25 * (1.0 + float(initial_tracked_residual))
    return g


# ============================================================================== numba kernels
def _schedule(parallel: bool):  # noqa: ANN202
    """Context for a kernel call: dynamic scheduling (chunks of one ``prange`` iteration) for the parallel
    builds — a thread that the OS delays does not hold the others up — and nothing for the serial ones."""
    return numba.parallel_chunksize(1) if parallel else contextlib.nullcontext()


@contextlib.contextmanager
def _one_thread():  # noqa: ANN202
    """Run numba's parallel kernels on one thread (in the calling thread) inside the block."""
    prev = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(prev)


def _variant(fn, suffix: str):
    """A copy of the python function ``fn`` named ``fn.__name__ + suffix``.

    numba's on-disk cache is keyed by the function's qualified name and first line, not by the compile flags:
    a serial and a ``parallel=True`` build of the *same* function would share one cache entry, and whichever
    was compiled first would be loaded for both (the parallel build silently running serially). Each build
    therefore gets its own copy with its own name.
    """
    g = types.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + suffix, fn.__defaults__, fn.__closure__)
    g.__qualname__ = fn.__qualname__ + suffix
    g.__doc__ = fn.__doc__
    return g


#: Row chunks of the row-parallel kernels (observe, regularize, fill holes): chunk c takes every
#: ROW_CHUNKS-th row starting at c. Pixels (rows) are independent, so results do not depend on it nor on the
#: thread count; it only balances the work of ``prange``'s static schedule.
ROW_CHUNKS = 32
_JIT = {"cache": True, "error_model": "numpy", "nogil": True}
# small helpers are inlined at numba-IR level: LLVM does not inline across separately compiled (cached)
# numba functions, and a call per bilinear sample costs ~3x the sample itself
_JIT_INLINE = {**_JIT, "inline": "always"}


@numba.njit(**_JIT_INLINE)
def _unzero(v: float) -> float:  # pragma: no cover - compiled
    if v < 0.0:
        return -1e-10 if v > -1e-10 else v
    return 1e-10 if v < 1e-10 else v


@numba.njit(**_JIT_INLINE)
def _bilinear(x, y):  # pragma: no cover - compiled
    """Integer corner (ix, iy) and the weights (w00, w01, w10, w11) of a bilinear sample at (x, y), in LSD-SLAM's
    arithmetic (w01 weighs the pixel below, w10 the one to the right)."""
    ix = int(x)
    iy = int(y)
    dx = x - ix
    dy = y - iy
    dxdy = dx * dy
    return ix, iy, 1.0 - dx - dy + dxdy, dy - dxdy, dx - dxdy, dxdy


@numba.njit(**_JIT_INLINE)
def _sample(img, x, y, out, row):  # pragma: no cover - compiled
    """Bilinear sample of all channels of ``img`` at (x, y) into ``out[row, :]`` (LSD getInterpolatedElement)."""
    ix, iy, w00, w01, w10, w11 = _bilinear(x, y)
    if img.shape[2] == 1:  # grey fast path (same arithmetic)
        out[row, 0] = (
            w11 * img[iy + 1, ix + 1, 0] + w01 * img[iy + 1, ix, 0] + w10 * img[iy, ix + 1, 0] + w00 * img[iy, ix, 0]
        )
        return
    for c in range(img.shape[2]):
        out[row, c] = (
            w11 * img[iy + 1, ix + 1, c] + w01 * img[iy + 1, ix, c] + w10 * img[iy, ix + 1, c] + w00 * img[iy, ix, c]
        )


_JIT_FAST = {**_JIT, "fastmath": set(FASTMATH)}  # see dmtrack.odometry._fastmath


@numba.njit(**_JIT_FAST)
def _epl_sums(gxs, gys, epx, epy):  # pragma: no cover - compiled
    """(Σ_c ((2 gx_c, 2 gy_c)·ep)², Σ_c |2 ∇F_c|²) of one keyframe pixel (N > 1)."""
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


@numba.njit(**_JIT_FAST)
def _window_cost(ring, kfv, loop):  # pragma: no cover - compiled
    """Σ_j ‖s_{L−j} − k_j‖² and Σ_j ⟨s_{L−j} − k_j, s_{L−j−1} − k_j⟩ at step L = ``loop`` directly (N > 1, few
    channels); ``ring`` row t mod 6 holds the sample s_t (see :func:`_line_stereo`). Reads only."""
    nch = ring.shape[1]
    ee = 0.0
    cross = 0.0
    for j in range(5):
        r = (loop + 6 - j) % 6
        rp = (loop + 5 - j) % 6
        for c in range(nch):
            k = kfv[j, c]
            e = ring[r, c] - k
            ee += e * e
            cross += e * (ring[rp, c] - k)
    return ee, cross


@numba.njit(**_JIT_FAST)
def _kf_norms(kfv):  # pragma: no cover - compiled
    """Squared norms of the five keyframe samples (rows of ``kfv``, N > 1)."""
    n0 = n1 = n2 = n3 = n4 = 0.0
    for c in range(kfv.shape[1]):
        n0 += kfv[0, c] * kfv[0, c]
        n1 += kfv[1, c] * kfv[1, c]
        n2 += kfv[2, c] * kfv[2, c]
        n3 += kfv[3, c] * kfv[3, c]
        n4 += kfv[4, c] * kfv[4, c]
    return n0, n1, n2, n3, n4


@numba.njit(**_JIT_FAST)
def _sample_stats(img, x, y, ring, row, prow, kfv, st):  # pragma: no cover - compiled
    """Bilinear sample s of all channels at (x, y) into ``ring[row]`` and its statistics into ``st[row]``:
    (‖s‖², ⟨s, k_0⟩ … ⟨s, k_4⟩, ⟨s, ring[prow]⟩) with k_j the keyframe samples (N > 1).

    With them every 5-sample SSD of the search and its cross term with the previous step are sums of
    scalars (see :func:`_line_stereo`): one pass over the N channels per search step instead of five.
    """
    ix, iy, w00, w01, w10, w11 = _bilinear(x, y)
    nrm = d0 = d1 = d2 = d3 = d4 = ss = 0.0
    for c in range(img.shape[2]):
        v = w11 * img[iy + 1, ix + 1, c] + w01 * img[iy + 1, ix, c] + w10 * img[iy, ix + 1, c] + w00 * img[iy, ix, c]
        ring[row, c] = v
        nrm += v * v
        d0 += v * kfv[0, c]
        d1 += v * kfv[1, c]
        d2 += v * kfv[2, c]
        d3 += v * kfv[3, c]
        d4 += v * kfv[4, c]
        ss += v * ring[prow, c]
    st[row, 0] = nrm
    st[row, 1] = d0
    st[row, 2] = d1
    st[row, 3] = d2
    st[row, 4] = d3
    st[row, 5] = d4
    st[row, 6] = ss


@numba.njit(**_JIT_INLINE)
def _epl_check(kf_gx, kf_gy, x, y, geo, prm, cscale):  # pragma: no cover - compiled
    """``makeAndCheckEPL``: returns (ok, epxn, epyn) with the unit epipolar direction in the keyframe."""
    epx = -geo[G_FX] * geo[G_TINV] + geo[G_TINV + 2] * (x - geo[G_CX])
    epy = -geo[G_FY] * geo[G_TINV + 1] + geo[G_TINV + 2] * (y - geo[G_CY])
    if math.isnan(epx + epy):
        return False, 0.0, 0.0
    len2 = epx * epx + epy * epy
    if len2 < prm[P_MIN_EPL_LEN2]:
        return False, 0.0, 0.0
    if kf_gx.shape[2] == 1:
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


@numba.njit(**_JIT_INLINE)
def _line_stereo(
    kf, ref, kf_gx, kf_gy, u, v, epxn, epyn, min_idepth, prior_idepth, max_idepth, geo, prm, cscale, buf, st
):  # pragma: no cover - compiled
    """LSD-SLAM ``doLineStereo`` for N channels.

    ``buf`` is a (2, 6, N) float64 scratch array (keyframe samples, reference ring), ``st`` a (6, 7) float64
    one (per-sample statistics, N > 1). Returns (err, idepth, var, epl_length): err ≥ 0 is the
    matching cost on success; −1 out of bounds, −2 ambiguous / failed, −3 error too large, −4 arithmetic.
    """
    h = kf.shape[0]
    w = kf.shape[1]
    nch = kf.shape[2]
    nan = np.nan
    kfv = buf[0]  # keyframe samples, rows: p2, p1, 0, m1, m2 (rows 0..4)
    ring = buf[1]  # reference-frame samples around the current search position (6 rows, see below)

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
    # grey fast path: window, keyframe samples and previous residuals in scalars (registers)
    k0 = kfv[0, 0]
    k1 = kfv[1, 0]
    k2 = kfv[2, 0]
    k3 = kfv[3, 0]
    k4 = kfv[4, 0]
    v0 = 0.0
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
    buf = np.empty((2, 6, kf.shape[2]), np.float64)
    st = np.empty((6, 7), np.float64)
    return _line_stereo(
        kf, ref, kf_gx, kf_gy, u, v, epxn, epyn, min_idepth, prior_idepth, max_idepth, geo, prm, cscale, buf, st
    )


def _observe_impl(
    valid,
    blacklisted,
    next_id,
    validity,
    idepth,
    var,
    idepth_s,
    var_s,
    kf,
    kf_gx,
    kf_gy,
    kf_mg,
    ref,
    good,
    use_good,
    geo,
    prm,
    cscale,
    frame_id,
    skip_ratio,
    counts,
):  # pragma: no cover - compiled
    h, w = valid.shape
    nch = kf.shape[2]
    min_grad = prm[P_MIN_GRAD]
    max_var = prm[P_MAX_VAR]
    max_depth_id = 1.0 / prm[P_MIN_DEPTH]
    # rows are independent; chunk c takes rows 3 + c, 3 + c + ROW_CHUNKS, … (interleaved, so that the
    # static schedule of prange gives every thread a similar share of the textured rows)
    for chunk in prange(ROW_CHUNKS):
        buf = np.empty((2, 6, nch), np.float64)
        st = np.empty((6, 7), np.float64)
        for y in range(3 + chunk, h - 3, ROW_CHUNKS):
            for x in range(3, w - 3):
                has = valid[y, x]
                mg = kf_mg[y, x]
                if has and mg < min_grad:
                    valid[y, x] = False
                    counts[y, C_INVALIDATED_GRAD] += 1
                    continue
                if mg < min_grad or blacklisted[y, x] < prm[P_MIN_BLACKLIST]:
                    continue
                if has:
                    # single reference frame per update: skip if scheduled for a later frame
                    if next_id[y, x] > frame_id:
                        counts[y, C_SKIP_SCHEDULED] += 1
                        continue
                if use_good and not good[y >> GOOD_LEVEL, x >> GOOD_LEVEL]:
                    counts[y, C_SKIP_NOT_GOOD] += 1
                    continue
                ok, epxn, epyn = _epl_check(kf_gx, kf_gy, x, y, geo, prm, cscale)
                if not ok:
                    counts[y, C_SKIP_EPL] += 1
                    continue
                if not has:
                    # ---------------- create
                    counts[y, C_CREATE_ATTEMPTED] += 1
                    err, rid, rvar, rlen = _line_stereo(
                        kf,
                        ref,
                        kf_gx,
                        kf_gy,
                        float(x),
                        float(y),
                        epxn,
                        epyn,
                        0.0,
                        1.0,
                        max_depth_id,
                        geo,
                        prm,
                        cscale,
                        buf,
                        st,
                    )
                    if err == -3.0 or err == -2.0:
                        blacklisted[y, x] -= 1
                        counts[y, C_BLACKLISTED] += 1
                    if err < 0 or rvar > max_var:
                        continue
                    valid[y, x] = True
                    blacklisted[y, x] = 0
                    next_id[y, x] = 0
                    validity[y, x] = prm[P_VAL_INIT_OBS]
                    idepth[y, x] = _unzero(rid)
                    var[y, x] = rvar
                    idepth_s[y, x] = -1.0
                    var_s[y, x] = -1.0
                    counts[y, C_CREATED] += 1
                else:
                    # ---------------- update
                    # variance bounding the search interval (±2σ around the smoothed idepth) and the consistency
                    # test: LSD-SLAM uses the regularised one; "raw-search" / "raw" take the pixel's own variance
                    # where it is larger (see DepthConfig.update_variance)
                    var_search = np.float64(var_s[y, x])
                    var_test = var_search
                    if prm[P_UPDATE_VAR] != 0.0 and var[y, x] > var_search:
                        var_search = np.float64(var[y, x])
                        if prm[P_UPDATE_VAR] == 2.0:
                            var_test = var_search
                    sv = math.sqrt(var_search)
                    ids = np.float64(idepth_s[y, x])
                    lo = ids - sv * prm[P_EPL_VAR_FAC]
                    hi = ids + sv * prm[P_EPL_VAR_FAC]
                    if lo < 0:
                        lo = 0.0
                    if hi > max_depth_id:
                        hi = max_depth_id
                    counts[y, C_UPDATE_ATTEMPTED] += 1
                    err, rid, rvar, rlen = _line_stereo(
                        kf, ref, kf_gx, kf_gy, float(x), float(y), epxn, epyn, lo, ids, hi, geo, prm, cscale, buf, st
                    )
                    diff = rid - ids
                    if err == -1.0:
                        counts[y, C_OOB] += 1
                    elif err == -2.0:
                        counts[y, C_FAIL] += 1
                        vc = validity[y, x] - prm[P_VAL_DEC]
                        validity[y, x] = vc if vc > 0 else 0.0
                        next_id[y, x] = 0
                        nv = var[y, x] * prm[P_FAIL_VAR_INC]
                        var[y, x] = nv
                        if nv > max_var:
                            valid[y, x] = False
                            blacklisted[y, x] -= 1
                    elif err == -3.0 or err == -4.0:
                        counts[y, C_NOT_FOUND] += 1
                    elif DIFF_FAC_OBSERVE * diff * diff > rvar + var_test:
                        counts[y, C_INCONSISTENT] += 1
                        nv = var[y, x] * prm[P_FAIL_VAR_INC]
                        var[y, x] = nv
                        if nv > max_var:
                            valid[y, x] = False
                    else:
                        counts[y, C_UPDATED] += 1
                        id_var = var[y, x] * prm[P_SUCC_VAR_INC]
                        wgt = rvar / (rvar + id_var)
                        idepth[y, x] = _unzero((1.0 - wgt) * rid + wgt * idepth[y, x])
                        id_var = id_var * wgt
                        if id_var < var[y, x]:
                            var[y, x] = id_var
                        vmax = float(int(prm[P_VAL_MAX] + mg * prm[P_VAL_MAX_VAR] / 255.0))
                        vc = validity[y, x] + prm[P_VAL_INC]
                        validity[y, x] = vmax if vc > vmax else vc
                        if rlen < prm[P_MIN_EPL_CROP]:
                            inc = skip_ratio
                            if inc < 3.0:
                                inc = 3.0
                            inc += int(rlen * 10000.0) % 2
                            if rlen < 0.5 * prm[P_MIN_EPL_CROP]:
                                inc *= 3.0
                            next_id[y, x] = int(frame_id + inc)


_observe_parallel = numba.njit(parallel=True, **_JIT)(_variant(_observe_impl, "_parallel"))


def observe_numba(
    state: tuple[np.ndarray, ...],
    kf: np.ndarray,
    kf_gx: np.ndarray,
    kf_gy: np.ndarray,
    kf_mg: np.ndarray,
    ref: np.ndarray,
    good: np.ndarray | None,
    geo: np.ndarray,
    prm: np.ndarray,
    cscale: float,
    frame_id: int,
    skip_ratio: float,
    parallel: bool = False,
) -> np.ndarray:
    """observeDepth over the keyframe (in place on ``state``); returns the (N_COUNTS,) int64 counters.

    ``state`` = (valid, blacklisted, next_id, validity, idepth, var, idepth_s, var_s). Rows are independent,
    so ``parallel=True`` (numba prange over rows) gives byte-identical results.
    """
    h = state[0].shape[0]
    counts = np.zeros((h, N_COUNTS), np.int64)
    use_good = good is not None
    g = good if use_good else np.ones((1, 1), np.bool_)
    # one compiled kernel for both: the serial call runs the parallel build on one thread, so serial and
    # threaded updates are the same machine code (the fast-math channel loops it calls may otherwise be
    # vectorised with different reduction orders in two separately compiled kernels)
    fn = _observe_parallel
    with _schedule(parallel) if parallel else _one_thread():
        fn(
            *state,
            kf,
            kf_gx,
            kf_gy,
            kf_mg,
            ref,
            g,
            use_good,
            geo,
            prm,
            float(cscale),
            int(frame_id),
            float(skip_ratio),
            counts,
        )
    return counts.sum(axis=0)


def _regularize_impl(
    valid,
    blacklisted,
    validity,
    idepth,
    var,
    idepth_s,
    var_s,
    valid_read,
    remove_occlusions,
    validity_th,
    reg_dist_var,
):  # pragma: no cover - compiled
    """Row-vectorised regularisation: for each row, 25 branch-free passes (one per neighbour offset)
    accumulate into per-column float32 buffers; then the per-pixel decisions. Rows only read ``valid_read``
    (a copy of ``valid``), ``idepth``, ``var`` and ``validity``, which are not written, so rows are independent
    (interleaved row chunks, ``prange`` in the parallel build)."""
    h, w = valid.shape
    for y in range(h):  # an explicit loop: an array expression would become a (chunked) parfor
        for x in range(w):
            valid_read[y, x] = valid[y, x]
    one = np.float32(1.0)
    zero = np.float32(0.0)
    fac = np.float32(DIFF_FAC_SMOOTHING)
    for chunk in prange(ROW_CHUNKS):
        # separate allocations (not rows of one array) so that LLVM can vectorise the passes
        acc_s = np.empty(w, np.float32)
        acc_i = np.empty(w, np.float32)
        acc_v = np.empty(w, np.float32)
        n_occ = np.empty(w, np.float32)
        n_ok = np.empty(w, np.float32)
        for y in range(2 + chunk, h - 2, ROW_CHUNKS):
            for x in range(w):
                acc_s[x] = zero
                acc_i[x] = zero
                acc_v[x] = zero
                n_occ[x] = zero
                n_ok[x] = zero
            for dy in range(-2, 3):
                for dx in range(-2, 3):
                    c = np.float32((dx * dx + dy * dy) * reg_dist_var)
                    for x in range(2, w - 2):
                        vr = valid_read[y + dy, x + dx]
                        di = idepth[y + dy, x + dx]
                        vi = var[y + dy, x + dx]
                        d0 = idepth[y, x]
                        diff = di - d0
                        incons = fac * diff * diff > vi + var[y, x]
                        use = vr and not incons
                        iv = one / (vi + c)
                        acc_v[x] += validity[y + dy, x + dx] if use else zero
                        acc_s[x] += di * iv if use else zero
                        acc_i[x] += iv if use else zero
                        n_occ[x] += one if (vr and incons and di > d0) else zero
                        n_ok[x] += one if use else zero
            for x in range(2, w - 2):
                if not valid_read[y, x]:
                    continue
                if acc_v[x] < validity_th:
                    valid[y, x] = False
                    blacklisted[y, x] -= 1
                    continue
                if remove_occlusions and n_occ[x] > n_ok[x]:
                    valid[y, x] = False
                    continue
                si = np.float64(acc_i[x])
                idepth_s[y, x] = _unzero(np.float64(acc_s[x]) / si)
                var_s[y, x] = 1.0 / si


_regularize_serial = numba.njit(**_JIT)(_variant(_regularize_impl, "_serial"))
_regularize_parallel = numba.njit(parallel=True, **_JIT)(_variant(_regularize_impl, "_parallel"))


def _fill_holes_impl(
    valid, blacklisted, next_id, validity, idepth, var, idepth_s, var_s, mg, valid_read, integral, prm
):  # pragma: no cover - compiled
    """Hole filling. The integral image is sequential; the fill reads only ``valid_read`` pixels (never
    written: only invalid pixels are filled) and the integral image, so rows are independent."""
    h, w = valid.shape
    for y in range(h):  # an explicit loop: an array expression would become a (chunked) parfor
        for x in range(w):
            valid_read[y, x] = valid[y, x]
    # integral image of the validity of valid pixels: integral[y+1, x+1] = Σ rows ≤ y, cols ≤ x
    for y in range(h):
        row = 0.0
        for x in range(w):
            if valid[y, x]:
                row += validity[y, x]
            integral[y + 1, x + 1] = integral[y, x + 1] + row
    min_grad = prm[P_MIN_GRAD]
    min_bl = prm[P_MIN_BLACKLIST]
    for chunk in prange(ROW_CHUNKS):
        for y in range(3 + chunk, h - 2, ROW_CHUNKS):
            for x in range(3, w - 2):
                if valid_read[y, x]:
                    continue
                if mg[y, x] < min_grad:
                    continue
                val = integral[y + 3, x + 3] - integral[y - 2, x + 3] - integral[y + 3, x - 2] + integral[y - 2, x - 2]
                if (blacklisted[y, x] >= min_bl and val > prm[P_VAL_SUM_CREATE]) or val > prm[P_VAL_SUM_UNBL]:
                    s = 0.0
                    sivar = 0.0
                    for yy in range(y - 2, y + 3):
                        for xx in range(x - 2, x + 3):
                            if not valid_read[yy, xx]:
                                continue
                            iv = 1.0 / np.float64(var[yy, xx])
                            s += np.float64(idepth[yy, xx]) * iv
                            sivar += iv
                    valid[y, x] = True
                    blacklisted[y, x] = 0
                    next_id[y, x] = 0
                    validity[y, x] = 0.0
                    idepth[y, x] = _unzero(s / sivar)
                    var[y, x] = prm[P_VAR_INIT]
                    idepth_s[y, x] = -1.0
                    var_s[y, x] = -1.0


_fill_holes_serial = numba.njit(**_JIT)(_variant(_fill_holes_impl, "_serial"))
_fill_holes_parallel = numba.njit(parallel=True, **_JIT)(_variant(_fill_holes_impl, "_parallel"))


def regularize_numba(
    state: tuple[np.ndarray, ...],
    remove_occlusions: bool,
    validity_th: float,
    reg_dist_var: float,
    scratch: np.ndarray | None = None,
    parallel: bool = False,
) -> None:
    """``regularizeDepthMap`` (radius 2) in place on ``state`` (see :func:`regularize_reference`).

    Float32 arithmetic (as LSD-SLAM); ``scratch`` is an optional (H, W) bool work array. ``parallel``: rows
    over threads (identical results).
    """
    valid, blacklisted, _next_id, validity, idepth, var, idepth_s, var_s = state
    if scratch is None:
        scratch = np.empty(valid.shape, np.bool_)
    fn = _regularize_parallel if parallel else _regularize_serial
    with _schedule(parallel):
        fn(
            valid,
            blacklisted,
            validity,
            idepth,
            var,
            idepth_s,
            var_s,
            scratch,
            bool(remove_occlusions),
            np.float32(validity_th),
            float(reg_dist_var),
        )


def fill_holes_numba(
    state: tuple[np.ndarray, ...],
    max_grad: np.ndarray,
    prm: np.ndarray,
    scratch: np.ndarray | None = None,
    integral: np.ndarray | None = None,
    parallel: bool = False,
) -> None:
    """``regularizeDepthMapFillHoles`` in place on ``state`` (see :func:`fill_holes_reference`).

    ``parallel``: rows of the fill over threads (identical results).
    """
    h, w = state[0].shape
    if scratch is None:
        scratch = np.empty((h, w), np.bool_)
    if integral is None:
        integral = np.zeros((h + 1, w + 1), np.float64)
    fn = _fill_holes_parallel if parallel else _fill_holes_serial
    with _schedule(parallel):
        fn(*state, max_grad, scratch, integral, prm)


@numba.njit(**_JIT)
def _propagate_kernel(
    valid_o,
    idepth_o,
    var_o,
    idepth_s_o,
    validity_o,
    valid_n,
    blacklisted_n,
    next_n,
    validity_n,
    idepth_n,
    var_n,
    idepth_s_n,
    var_s_n,
    mg_new,
    good,
    use_good,
    feat_old,
    feat_new,
    R,
    t,
    fx,
    fy,
    cx,
    cy,
    prm,
    cscale,
    counts,
):  # pragma: no cover - compiled
    h, w = valid_o.shape
    nch = feat_old.shape[2]
    fxi = 1.0 / fx
    fyi = 1.0 / fy
    cxi = -cx / fx
    cyi = -cy / fy
    min_grad = prm[P_MIN_GRAD]
    vmax_merge = prm[P_VAL_MAX] + prm[P_VAL_MAX_VAR]
    col = np.empty((1, nch), np.float64)
    for y in range(h):
        for x in range(w):
            if not valid_o[y, x]:
                continue
            counts[PC_ATTEMPTS] += 1
            d_old = np.float64(idepth_s_o[y, x])
            rx = x * fxi + cxi
            ry = y * fyi + cyi
            pn0 = (R[0, 0] * rx + R[0, 1] * ry + R[0, 2]) / d_old + t[0]
            pn1 = (R[1, 0] * rx + R[1, 1] * ry + R[1, 2]) / d_old + t[1]
            pn2 = (R[2, 0] * rx + R[2, 1] * ry + R[2, 2]) / d_old + t[2]
            new_idepth = 1.0 / pn2
            u_new = pn0 * new_idepth * fx + cx
            v_new = pn1 * new_idepth * fy + cy
            if not (u_new > 2.1 and v_new > 2.1 and u_new < w - 3.1 and v_new < h - 3.1):
                counts[PC_OOB] += 1
                continue
            nx = int(u_new + 0.5)
            ny = int(v_new + 0.5)
            dest_grad = mg_new[ny, nx]
            if use_good:
                if not good[y >> GOOD_LEVEL, x >> GOOD_LEVEL] or dest_grad < min_grad:
                    counts[PC_DROPPED_GOOD] += 1
                    continue
            else:
                _sample(feat_new, u_new, v_new, col, 0)
                r2 = 0.0
                for c in range(nch):
                    r = col[0, c] - feat_old[y, x, c]
                    r2 += r * r
                r2 *= cscale
                if r2 / (MAX_DIFF_CONSTANT + MAX_DIFF_GRAD_MULT * dest_grad * dest_grad) > 1.0 or dest_grad < min_grad:
                    counts[PC_DROPPED_GOOD] += 1
                    continue
            ratio = new_idepth / d_old
            ratio *= ratio
            ratio *= ratio
            new_var = ratio * var_o[y, x]
            if valid_n[ny, nx]:
                diff = idepth_n[ny, nx] - new_idepth
                if DIFF_FAC_PROP_MERGE * diff * diff > new_var + var_n[ny, nx]:
                    counts[PC_OCCLUDED] += 1
                    if new_idepth < idepth_n[ny, nx]:
                        continue
                    valid_n[ny, nx] = False
            if not valid_n[ny, nx]:
                counts[PC_CREATED] += 1
                valid_n[ny, nx] = True
                idepth_n[ny, nx] = new_idepth
                var_n[ny, nx] = new_var
                validity_n[ny, nx] = validity_o[y, x]
            else:
                counts[PC_MERGED] += 1
                tv = np.float64(var_n[ny, nx])
                wgt = new_var / (tv + new_var)
                merged = wgt * idepth_n[ny, nx] + (1.0 - wgt) * new_idepth
                mv = validity_o[y, x] + validity_n[ny, nx]
                if mv > vmax_merge:
                    mv = vmax_merge
                idepth_n[ny, nx] = merged
                var_n[ny, nx] = 1.0 / (1.0 / tv + 1.0 / new_var)
                validity_n[ny, nx] = mv
            blacklisted_n[ny, nx] = 0
            next_n[ny, nx] = 0
            idepth_s_n[ny, nx] = -1.0
            var_s_n[ny, nx] = -1.0


def propagate_numba(
    old: tuple[np.ndarray, ...],
    mg_new: np.ndarray,
    good: np.ndarray | None,
    feat_old: np.ndarray,
    feat_new: np.ndarray,
    T_new_old: np.ndarray,
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    prm: np.ndarray,
    cscale: float,
) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
    """``propagateDepth``: warp the old keyframe's hypotheses into the new keyframe.

    Returns the new state tuple (valid, blacklisted, next_id, validity, idepth, var, idepth_s, var_s) and the
    (N_PCOUNTS,) counters. See :func:`propagate_reference`.
    """
    valid_o, _bl, _nx, validity_o, idepth_o, var_o, idepth_s_o, _vs = old
    new = empty_state(valid_o.shape)
    counts = np.zeros(N_PCOUNTS, np.int64)
    use_good = good is not None
    g = good if use_good else np.ones((1, 1), np.bool_)
    T = np.asarray(T_new_old, np.float64)
    _propagate_kernel(
        valid_o,
        idepth_o,
        var_o,
        idepth_s_o,
        validity_o,
        *new,
        mg_new,
        g,
        use_good,
        feat_old,
        feat_new,
        np.ascontiguousarray(T[:3, :3]),
        np.ascontiguousarray(T[:3, 3]),
        float(fx),
        float(fy),
        float(cx),
        float(cy),
        prm,
        float(cscale),
        counts,
    )
    return new, counts


def empty_state(shape: tuple[int, int]) -> tuple[np.ndarray, ...]:
    """A fresh all-invalid state tuple (valid, blacklisted, next_id, validity, idepth, var, idepth_s, var_s)."""
    h, w = shape
    return (
        np.zeros((h, w), np.bool_),
        np.zeros((h, w), np.int32),
        np.zeros((h, w), np.int32),
        np.zeros((h, w), np.float32),
        np.zeros((h, w), np.float32),
        np.zeros((h, w), np.float32),
        np.full((h, w), -1.0, np.float32),
        np.full((h, w), -1.0, np.float32),
    )


# ============================================================================== python / numpy references
def _unzero_ref(v: float) -> float:
    if v < 0.0:
        return -1e-10 if v > -1e-10 else v
    return 1e-10 if v < 1e-10 else v


def bilinear_reference(img: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Vectorised bilinear sampling of an (H, W, N) image at float coordinates → (..., N) float64."""
    xs = np.asarray(xs, np.float64)
    ys = np.asarray(ys, np.float64)
    ix = np.trunc(xs).astype(np.int64)
    iy = np.trunc(ys).astype(np.int64)
    dx = (xs - ix)[..., None]
    dy = (ys - iy)[..., None]
    f = img.astype(np.float64)
    return (
        dx * dy * f[iy + 1, ix + 1]
        + (dy - dx * dy) * f[iy + 1, ix]
        + (dx - dx * dy) * f[iy, ix + 1]
        + (1.0 - dx - dy + dx * dy) * f[iy, ix]
    )


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
        Stereo geometry (:func:`stereo_geometry`) and parameters (:func:`make_params`).
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


def observe_reference(
    state: tuple[np.ndarray, ...],
    kf: np.ndarray,
    kf_gx: np.ndarray,
    kf_gy: np.ndarray,
    kf_mg: np.ndarray,
    ref: np.ndarray,
    good: np.ndarray | None,
    geo: np.ndarray,
    prm: np.ndarray,
    cscale: float,
    frame_id: int,
    skip_ratio: float,
) -> np.ndarray:
    """Plain-python reference of the observe loop (in place on ``state``); slow, for small images only."""
    valid, blacklisted, next_id, validity, idepth, var, idepth_s, var_s = state
    h, w = valid.shape
    counts = np.zeros(N_COUNTS, np.int64)
    max_id = 1.0 / prm[P_MIN_DEPTH]
    for y in range(3, h - 3):
        for x in range(3, w - 3):
            has = bool(valid[y, x])
            mg = float(kf_mg[y, x])
            if has and mg < prm[P_MIN_GRAD]:
                valid[y, x] = False
                counts[C_INVALIDATED_GRAD] += 1
                continue
            if mg < prm[P_MIN_GRAD] or blacklisted[y, x] < prm[P_MIN_BLACKLIST]:
                continue
            if has and next_id[y, x] > frame_id:
                counts[C_SKIP_SCHEDULED] += 1
                continue
            if good is not None and not good[y >> GOOD_LEVEL, x >> GOOD_LEVEL]:
                counts[C_SKIP_NOT_GOOD] += 1
                continue
            ok, epxn, epyn = epl_check_reference(kf_gx, kf_gy, x, y, geo, prm, cscale)
            if not ok:
                counts[C_SKIP_EPL] += 1
                continue
            if not has:
                counts[C_CREATE_ATTEMPTED] += 1
                err, rid, rvar, _ = line_stereo_reference(
                    kf, ref, kf_gx, kf_gy, float(x), float(y), epxn, epyn, 0.0, 1.0, max_id, geo, prm, cscale
                )
                if err in (-2.0, -3.0):
                    blacklisted[y, x] -= 1
                    counts[C_BLACKLISTED] += 1
                if err < 0 or rvar > prm[P_MAX_VAR]:
                    continue
                valid[y, x] = True
                blacklisted[y, x] = 0
                next_id[y, x] = 0
                validity[y, x] = prm[P_VAL_INIT_OBS]
                idepth[y, x] = _unzero_ref(rid)
                var[y, x] = rvar
                idepth_s[y, x] = -1.0
                var_s[y, x] = -1.0
                counts[C_CREATED] += 1
                continue
            ids = float(idepth_s[y, x])
            var_search = var_test = float(var_s[y, x])
            if prm[P_UPDATE_VAR] != 0.0 and float(var[y, x]) > var_search:  # see DepthConfig.update_variance
                var_search = float(var[y, x])
                if prm[P_UPDATE_VAR] == 2.0:
                    var_test = var_search
            sv = float(np.sqrt(var_search))
            lo = max(0.0, ids - sv * prm[P_EPL_VAR_FAC])
            hi = min(max_id, ids + sv * prm[P_EPL_VAR_FAC])
            counts[C_UPDATE_ATTEMPTED] += 1
            err, rid, rvar, rlen = line_stereo_reference(
                kf, ref, kf_gx, kf_gy, float(x), float(y), epxn, epyn, lo, ids, hi, geo, prm, cscale
            )
            if err == -1.0:
                counts[C_OOB] += 1
            elif err == -2.0:
                counts[C_FAIL] += 1
                validity[y, x] = max(0.0, float(validity[y, x]) - prm[P_VAL_DEC])
                next_id[y, x] = 0
                nv = float(var[y, x]) * prm[P_FAIL_VAR_INC]
                var[y, x] = nv
                if nv > prm[P_MAX_VAR]:
                    valid[y, x] = False
                    blacklisted[y, x] -= 1
            elif err in (-3.0, -4.0):
                counts[C_NOT_FOUND] += 1
            elif DIFF_FAC_OBSERVE * (rid - ids) ** 2 > rvar + var_test:
                counts[C_INCONSISTENT] += 1
                nv = float(var[y, x]) * prm[P_FAIL_VAR_INC]
                var[y, x] = nv
                if nv > prm[P_MAX_VAR]:
                    valid[y, x] = False
            else:
                counts[C_UPDATED] += 1
                old_var = float(var[y, x])
                id_var = old_var * prm[P_SUCC_VAR_INC]
                wgt = rvar / (rvar + id_var)
                idepth[y, x] = _unzero_ref((1.0 - wgt) * rid + wgt * float(idepth[y, x]))
                var[y, x] = min(old_var, id_var * wgt)
                cap = float(int(prm[P_VAL_MAX] + mg * prm[P_VAL_MAX_VAR] / 255.0))
                validity[y, x] = min(cap, float(validity[y, x]) + prm[P_VAL_INC])
                if rlen < prm[P_MIN_EPL_CROP]:
                    inc = max(3.0, skip_ratio) + int(rlen * 10000.0) % 2
                    if rlen < 0.5 * prm[P_MIN_EPL_CROP]:
                        inc *= 3.0
                    next_id[y, x] = int(frame_id + inc)
    return counts


def _shifted(a: np.ndarray, dy: int, dx: int, fill) -> np.ndarray:
    """b[y, x] = a[y+dy, x+dx] where inside, ``fill`` outside."""
    h, w = a.shape
    out = np.full_like(a, fill)
    ys = slice(max(0, -dy), min(h, h - dy))
    xs = slice(max(0, -dx), min(w, w - dx))
    ys2 = slice(max(0, dy), min(h, h + dy))
    xs2 = slice(max(0, dx), min(w, w + dx))
    out[ys, xs] = a[ys2, xs2]
    return out


def regularize_reference(
    state: tuple[np.ndarray, ...], remove_occlusions: bool, validity_th: float, reg_dist_var: float
) -> None:
    """Vectorised numpy reference of ``regularizeDepthMap`` (radius 2), in place on ``state``.

    For every valid pixel at least 2 px from the border: neighbours in the 5×5 window that are valid and
    consistent (Δidepth² ≤ σ_n² + σ²) contribute their validity to a sum and their raw idepth with weight
    1/(σ_n² + dist²·REG_DIST_VAR). Sum < ``validity_th`` → invalid and blacklisted −1. With
    ``remove_occlusions``, more inconsistent closer neighbours than consistent ones → invalid. Otherwise
    idepth_smoothed = weighted mean, var_smoothed = 1/Σw.
    """
    valid, blacklisted, _next_id, validity, idepth, var, idepth_s, var_s = state
    h, w = valid.shape
    # the consistency test in float32, as the kernel (and LSD-SLAM); the sums in float64
    d0 = idepth.astype(np.float32)
    v0 = var.astype(np.float32)
    val = validity.astype(np.float64)
    s = np.zeros((h, w))
    sivar = np.zeros((h, w))
    vsum = np.zeros((h, w))
    n_occ = np.zeros((h, w), np.int64)
    n_ok = np.zeros((h, w), np.int64)
    fac = np.float32(DIFF_FAC_SMOOTHING)
    for dx in range(-2, 3):
        for dy in range(-2, 3):
            nv = _shifted(valid, dy, dx, False)
            nd = _shifted(d0, dy, dx, np.float32(0.0))
            nvar = _shifted(v0, dy, dx, np.float32(1.0))
            nval = _shifted(val, dy, dx, 0.0)
            diff = nd - d0
            inconsistent = fac * diff * diff > nvar + v0
            use = nv & ~inconsistent
            n_occ += nv & inconsistent & (nd > d0)
            n_ok += use
            vsum += np.where(use, nval, 0.0)
            with np.errstate(divide="ignore"):
                ivar = np.where(use, 1.0 / (nvar.astype(np.float64) + (dx * dx + dy * dy) * reg_dist_var), 0.0)
            s += ivar * nd
            sivar += ivar
    interior = np.zeros((h, w), bool)
    interior[2 : h - 2, 2 : w - 2] = True
    target = valid & interior
    drop = target & (vsum < validity_th)
    occl = target & ~drop & (n_occ > n_ok) if remove_occlusions else np.zeros_like(target)
    keep = target & ~drop & ~occl
    with np.errstate(divide="ignore", invalid="ignore"):
        sm = s / sivar
    sm = np.where(sm < 0, np.minimum(sm, -1e-10), np.maximum(sm, 1e-10))
    idepth_s[keep] = sm[keep]
    var_s[keep] = 1.0 / sivar[keep]
    blacklisted[drop] -= 1
    valid[drop | occl] = False


def fill_holes_reference(state: tuple[np.ndarray, ...], max_grad: np.ndarray, prm: np.ndarray) -> None:
    """Vectorised numpy reference of ``regularizeDepthMapFillHoles``, in place on ``state``.

    Reads a copy (no cascading): an invalid pixel in [3, H−2)×[3, W−2) with maxGrad ≥ minUseGrad whose 5×5
    validity sum (of valid pixels) exceeds ``VAL_SUM_MIN_FOR_CREATE`` (not blacklisted) or
    ``VAL_SUM_MIN_FOR_UNBLACKLIST`` (any) becomes valid with the inverse-variance mean of its valid
    neighbours, variance ``VAR_RANDOM_INIT_INITIAL`` and validity 0.
    """
    valid, blacklisted, next_id, validity, idepth, var, idepth_s, var_s = state
    h, w = valid.shape
    v_read = valid.copy()
    val = np.where(v_read, validity.astype(np.float64), 0.0)
    iv = np.where(v_read, 1.0 / np.where(v_read, var.astype(np.float64), 1.0), 0.0)
    sd = iv * np.where(v_read, idepth.astype(np.float64), 0.0)
    vsum = np.zeros((h, w))
    ssum = np.zeros((h, w))
    isum = np.zeros((h, w))
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            vsum += _shifted(val, dy, dx, 0.0)
            ssum += _shifted(sd, dy, dx, 0.0)
            isum += _shifted(iv, dy, dx, 0.0)
    region = np.zeros((h, w), bool)
    region[3 : h - 2, 3 : w - 2] = True
    cand = region & ~v_read & (max_grad >= prm[P_MIN_GRAD])
    ok = ((blacklisted >= prm[P_MIN_BLACKLIST]) & (vsum > prm[P_VAL_SUM_CREATE])) | (vsum > prm[P_VAL_SUM_UNBL])
    fill = cand & ok
    with np.errstate(divide="ignore", invalid="ignore"):
        m = ssum / isum
    m = np.where(m < 0, np.minimum(m, -1e-10), np.maximum(m, 1e-10))
    valid[fill] = True
    blacklisted[fill] = 0
    next_id[fill] = 0
    validity[fill] = 0.0
    idepth[fill] = m[fill]
    var[fill] = prm[P_VAR_INIT]
    idepth_s[fill] = -1.0
    var_s[fill] = -1.0


def propagate_reference(
    old: tuple[np.ndarray, ...],
    mg_new: np.ndarray,
    good: np.ndarray | None,
    feat_old: np.ndarray,
    feat_new: np.ndarray,
    T_new_old: np.ndarray,
    fx: float,
    fy: float,
    cx: float,
    cy: float,
    prm: np.ndarray,
    cscale: float,
) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
    """Reference of ``propagateDepth`` (vectorised warp, sequential collision handling in row-major order).

    Every valid old pixel is warped with its smoothed inverse depth d: X_new = R·K⁻¹(x, y, 1)/d + t; it is
    kept if it lands in (2.1, W−3.1)×(2.1, H−3.1), and (with ``good`` flags, indexed by the old pixel at
    level 1) the flag is set and the destination maxGrad ≥ minUseGrad — without flags, the colour test
    |ΔF|²/(40² + 0.25·maxGrad²) ≤ 1 replaces the flag. New variance (d_new/d)⁴·σ²; a collision with an
    inconsistent hypothesis keeps the closer one, a consistent one is fused (inverse-variance, validity
    summed and capped).
    """
    valid_o, _bl, _nx, validity_o, idepth_o, var_o, idepth_s_o, _vs = old
    h, w = valid_o.shape
    T = np.asarray(T_new_old, np.float64)
    ys, xs = np.nonzero(valid_o)  # row-major order
    d = idepth_s_o[ys, xs].astype(np.float64)
    rays = np.stack([(xs - cx) / fx, (ys - cy) / fy, np.ones(len(xs))])
    pn = (T[:3, :3] @ rays) / d + T[:3, 3:4]
    nid = 1.0 / pn[2]
    un = pn[0] * nid * fx + cx
    vn = pn[1] * nid * fy + cy
    counts = np.zeros(N_PCOUNTS, np.int64)
    counts[PC_ATTEMPTS] = len(xs)
    inside = (un > 2.1) & (vn > 2.1) & (un < w - 3.1) & (vn < h - 3.1)
    counts[PC_OOB] = int(np.sum(~inside))
    nx = np.where(inside, np.trunc(un + 0.5), 0).astype(np.int64)
    ny = np.where(inside, np.trunc(vn + 0.5), 0).astype(np.int64)
    dest_grad = mg_new[ny, nx].astype(np.float64)
    if good is not None:
        keep = inside & good[ys >> GOOD_LEVEL, xs >> GOOD_LEVEL] & (dest_grad >= prm[P_MIN_GRAD])
    else:
        col = bilinear_reference(feat_new, np.where(inside, un, 3.0), np.where(inside, vn, 3.0))
        r2 = cscale * np.sum((col - feat_old[ys, xs].astype(np.float64)) ** 2, axis=-1)
        keep = inside & ~(r2 / (MAX_DIFF_CONSTANT + MAX_DIFF_GRAD_MULT * dest_grad**2) > 1.0)
        keep &= dest_grad >= prm[P_MIN_GRAD]
    counts[PC_DROPPED_GOOD] = int(np.sum(inside & ~keep))
    new_var = (nid / d) ** 4 * var_o[ys, xs].astype(np.float64)
    new = empty_state((h, w))
    valid_n, blacklisted_n, next_n, validity_n, idepth_n, var_n, idepth_s_n, var_s_n = new
    vmax = prm[P_VAL_MAX] + prm[P_VAL_MAX_VAR]
    for i in np.nonzero(keep)[0]:
        py, px = ny[i], nx[i]
        if valid_n[py, px]:
            diff = float(idepth_n[py, px]) - nid[i]
            if DIFF_FAC_PROP_MERGE * diff * diff > new_var[i] + float(var_n[py, px]):
                counts[PC_OCCLUDED] += 1
                if nid[i] < idepth_n[py, px]:
                    continue
                valid_n[py, px] = False
        if not valid_n[py, px]:
            counts[PC_CREATED] += 1
            valid_n[py, px] = True
            idepth_n[py, px] = nid[i]
            var_n[py, px] = new_var[i]
            validity_n[py, px] = validity_o[ys[i], xs[i]]
        else:
            counts[PC_MERGED] += 1
            tv = float(var_n[py, px])
            wgt = new_var[i] / (tv + new_var[i])
            idepth_n[py, px] = wgt * float(idepth_n[py, px]) + (1.0 - wgt) * nid[i]
            var_n[py, px] = 1.0 / (1.0 / tv + 1.0 / new_var[i])
            validity_n[py, px] = min(vmax, float(validity_o[ys[i], xs[i]]) + float(validity_n[py, px]))
    return new, counts
