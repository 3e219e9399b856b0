"""Shared pieces of the semi-dense depth-map kernels: constants, packed parameters and stereo geometry,
JIT options, threading helpers, inline sampling helpers and the per-pixel state.

The per-pixel work of LSD-SLAM's ``DepthMap`` (lsd-slam-spec.md §3) on N-channel feature maps (§4) is split
by stage; each stage module holds its numba kernel(s) and, next to them, a plain numpy / python reference of
the same stage (``*_reference``), used by :class:`dmtrack.odometry.depthmap.DepthMap` when
``use_numba=False`` and by the tests, which check that both agree on small images:

* :mod:`dmtrack.odometry._epipolar_stereo`: the epipolar-line check and the 5-sample line stereo search;
* :mod:`dmtrack.odometry._depth_update`: the observe loop (create / EKF update of hypotheses, validity and
  blacklist counters);
* :mod:`dmtrack.odometry._depth_propagate`: the depth propagation into a new keyframe;
* :mod:`dmtrack.odometry._depth_regularize`: the radius-2 regularisation (with and without occlusion removal)
  and hole filling.

Numba cache caveat
------------------
``cache=True`` keys a compiled kernel on its *own* source file (modification time and size) and its own
bytecode only. A kernel that inlines or calls a helper defined in another module, or reads a module-level
constant from one (numba freezes global values at compile time), keeps its stale cached machine code after
that helper or constant changes: the stage kernels use the helpers and constants of this module, and the
observe kernel (``_depth_update``) inlines the line stereo of ``_epipolar_stereo``. After editing either of
these two modules (the line stereo and its helpers are inlined by LLVM, see ``_JIT_LLVM_INLINE``), clear the
odometry package's numba cache::

    rm -f src/dmtrack/odometry/__pycache__/*.nbi src/dmtrack/odometry/__pycache__/*.nbc

Inline helpers and constants used by one stage only live in that stage's module.

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

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np

from dmtrack.geometry.exact import matmul
from dmtrack.io.machine import numba_blas_without_scipy_linalg
from dmtrack.odometry.config import UPDATE_VARIANCE_MODES

# before numba sets up its compiler (the first kernel): its BLAS check without all of scipy.linalg (0.1 s, 27 MB)
numba_blas_without_scipy_linalg()

# ------------------------------------------------------------------------------------------ constants
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
    g[G_KR : G_KR + 9] = matmul(K, R).ravel()
    g[G_KT : G_KT + 3] = matmul(K, t)
    g[G_T : G_T + 3] = t
    g[G_R : G_R + 9] = R.ravel()
    g[G_TINV : G_TINV + 3] = -matmul(R.T, t)
    g[G_TRACK_FAC] = 0.25 * (1.0 + float(initial_tracked_residual))
    return g


# ============================================================================== numba helpers
_ROW_POOL: tuple[int, ThreadPoolExecutor] | None = None  # (pid that made it, the pool)
_ROW_POOL_LOCK = threading.Lock()


def _row_pool() -> ThreadPoolExecutor:
    """The process's pool of row threads: numba's largest thread count − 1 of them, started as needed (made again
    after a fork: a forked child has none of its parent's threads). Never replaced within a process, so a caller
    never submits to a pool that another thread shut down."""
    global _ROW_POOL
    with _ROW_POOL_LOCK:
        pid = os.getpid()
        if _ROW_POOL is None or _ROW_POOL[0] != pid:
            workers = max(1, numba.config.NUMBA_NUM_THREADS - 1)
            _ROW_POOL = (pid, ThreadPoolExecutor(max_workers=workers, thread_name_prefix="dmtrack-rows"))
        return _ROW_POOL[1]


def run_rows(fn, args: tuple, parallel: bool) -> None:  # noqa: ANN001
    """``fn(first, step, *args)`` over interleaved row sets: one call ``fn(0, 1, …)`` serially, or with
    ``parallel`` one call ``fn(t, n, …)`` per thread t = 0 … n − 1 (n = numba's thread count of the calling thread;
    t = 0 on the calling thread, the others on the pool's threads; ``fn`` is a ``nogil`` numba kernel).

    The row kernels (observe, regularize, fill holes) write only their own rows and read only what no row writes, so
    the result is byte-identical for every n. Python threads rather than a ``prange``: numba's parallel build of a
    kernel re-optimised the whole row function it calls (2–3.5 s more compilation per kernel, issue 14), and these
    kernels run once per frame, where a pool hand-over (about 0.1 ms measured with the other core busy) is small. An
    exception in any thread is raised here after all threads have finished.
    """
    n = numba.get_num_threads() if parallel else 1
    if n <= 1:
        fn(0, 1, *args)
        return
    pool = _row_pool()
    futures = [pool.submit(fn, t, n, *args) for t in range(1, n)]
    try:
        fn(0, n, *args)
    finally:
        errors = [f.exception() for f in futures]
    for e in errors:
        if e is not None:
            raise e


_JIT = {"cache": True, "error_model": "numpy", "nogil": True}
# small helpers are inlined at numba-IR level: LLVM does not inline across separately compiled (cached)
# numba functions, and a call per bilinear sample costs ~3x the sample itself
_JIT_INLINE = {**_JIT, "inline": "always"}
# the multichannel loops of the stereo search, with their sums in fixed lanes (see dmtrack.odometry._lanes): separately
# compiled calls; ``forceinline`` and ``_nrt`` are set explicitly so that a caller compiled with _JIT_LLVM_INLINE never
# passes its own on to them (numba inherits unset flags from the function being compiled)
_JIT_LANES = {**_JIT, "forceinline": False, "_nrt": True}
# helpers that take arrays and run per pixel or per search step (the line stereo and its samples): inlined by LLVM
# (``alwaysinline``) into the kernel that calls them rather than at numba-IR level, and compiled without reference
# counting (``_nrt=False``; they allocate nothing): an IR-inlined array argument becomes an alias whose reference
# count is updated (atomically) on every call (measured: the observe kernel 1.5–1.8× slower). Compiled once per
# signature (``ndim`` is a compile-time constant there: branches on it are pruned, see ``_line_stereo``); not cached
# on their own, their callers' cache entries hold the inlined code.
_JIT_LLVM_INLINE = {**_JIT, "cache": False, "forceinline": True, "_nrt": False}


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


@numba.njit(**_JIT_LLVM_INLINE)
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


@numba.njit(**_JIT_LLVM_INLINE)
def _sample1(img, x, y):  # pragma: no cover - compiled
    """Bilinear sample of a single-channel (H, W) ``img`` at (x, y): the arithmetic of :func:`_sample`."""
    ix, iy, w00, w01, w10, w11 = _bilinear(x, y)
    return w11 * img[iy + 1, ix + 1] + w01 * img[iy + 1, ix] + w10 * img[iy, ix + 1] + w00 * img[iy, ix]


# ============================================================================== numpy helpers
@numba.njit(cache=True, nogil=True)
def _tracking_select(valid, ids, var, th, d, v, sel):  # pragma: no cover - compiled
    """One pass of :func:`tracking_select`: ``d``/``v`` = ``ids``/``var`` where valid and ``ids`` ≥ ``th``, else −1;
    the selected ``ids`` in row-major order into ``sel``; returns how many."""
    k = 0
    minus1 = np.float32(-1.0)
    for y in range(valid.shape[0]):
        for x in range(valid.shape[1]):
            z = ids[y, x]
            if valid[y, x] and z >= th:
                d[y, x] = z
                v[y, x] = var[y, x]
                sel[k] = z
                k += 1
            else:
                d[y, x] = minus1
                v[y, x] = minus1
    return k


def tracking_select(
    valid: np.ndarray, ids: np.ndarray, var: np.ndarray, threshold: float
) -> tuple[np.ndarray, np.ndarray, float]:
    """The tracker's depth (LSD-SLAM ``Frame::setDepth``) in one pass: (d, v, mean) with d, v = ``ids``, ``var``
    (float32 maps) where ``valid`` and ``ids`` ≥ ``threshold`` and −1 elsewhere, and the float64 mean of the
    selected ``ids`` (NaN if none). The bytes of the numpy expression ``m = valid & (ids >= threshold)``,
    ``np.where(m, ids, −1)``, ``np.mean(ids[m], dtype=float64)`` (NumPy ≥ 2 compares a float32 array with a Python
    float in float32, so the threshold is rounded to float32 here too)."""
    d = np.empty_like(ids)
    v = np.empty_like(var)
    sel = np.empty(ids.size, ids.dtype)
    k = _tracking_select(valid, ids, var, ids.dtype.type(threshold), d, v, sel)
    return d, v, (float(np.mean(sel[:k], dtype=np.float64)) if k else float("nan"))


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
