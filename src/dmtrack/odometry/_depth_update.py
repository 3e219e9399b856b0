"""Depth update of the keyframe from one tracked frame: LSD-SLAM's ``observeDepth``.

For every keyframe pixel with enough gradient: skip it when blacklisted, scheduled for a later frame, not
"good" in the tracker's last evaluation or failing the epipolar check; otherwise run the line stereo of
:mod:`dmtrack.odometry._epipolar_stereo` and create a hypothesis (no previous one) or fuse the measurement into
the existing one (EKF update within ±2σ, or the validity / variance / blacklist penalties of a failed or
inconsistent search). The numba kernel (:func:`observe_numba`, rows over threads) and the plain-python
reference (:func:`observe_reference`). Conventions and the numba cache caveat (this kernel inlines the line
stereo): :mod:`dmtrack.odometry._depth_common`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dmtrack.odometry._depth_common import (
    _JIT,
    C_BLACKLISTED,
    C_CREATE_ATTEMPTED,
    C_CREATED,
    C_FAIL,
    C_INCONSISTENT,
    C_INVALIDATED_GRAD,
    C_NOT_FOUND,
    C_OOB,
    C_SKIP_EPL,
    C_SKIP_NOT_GOOD,
    C_SKIP_SCHEDULED,
    C_UPDATE_ATTEMPTED,
    C_UPDATED,
    GOOD_LEVEL,
    N_COUNTS,
    P_EPL_VAR_FAC,
    P_FAIL_VAR_INC,
    P_MAX_VAR,
    P_MIN_BLACKLIST,
    P_MIN_DEPTH,
    P_MIN_EPL_CROP,
    P_MIN_GRAD,
    P_SUCC_VAR_INC,
    P_UPDATE_VAR,
    P_VAL_DEC,
    P_VAL_INC,
    P_VAL_INIT_OBS,
    P_VAL_MAX,
    P_VAL_MAX_VAR,
    _unzero,
    run_rows,
)
from dmtrack.odometry._epipolar_stereo import (
    _epl_check,
    _line_stereo,
    epl_check_reference,
    line_stereo_reference,
    padded_channels,
)
from dmtrack.odometry.frame import gradients

#: ``kf_gx`` / ``kf_gy`` of the observe kernel when it forms the keyframe pixels' gradients itself (N > 1).
_NO_GRADIENTS = np.empty(0, np.float32)

#: ``DIFF_FAC_OBSERVE`` (1 in LSD-SLAM): factor of the squared difference in the consistency test of an update.
DIFF_FAC_OBSERVE = 1.0


# ============================================================================== numba kernel
@numba.njit(**_JIT)
def _observe_rows(
    first,
    step,
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
    """observeDepth of the rows 3 + ``first``, 3 + ``first`` + ``step``, … (in place; counters per row).

    Called once per thread by :func:`~dmtrack.odometry._depth_common.run_rows` (rows are independent). ``kf.ndim``
    is a constant here, so the single-channel build — (H, W) maps, see :func:`observe_numba` — is compiled without
    the multichannel code. The line stereo is inlined by LLVM (``_JIT_LLVM_INLINE``).
    """
    h, w = valid.shape
    if kf.ndim == 2:  # one channel as (H, W) (see _line_stereo)
        nch = 1
    else:
        nch = kf.shape[2]
    min_grad = prm[P_MIN_GRAD]
    max_var = prm[P_MAX_VAR]
    max_depth_id = 1.0 / prm[P_MIN_DEPTH]
    kfv = np.zeros((5, padded_channels(nch)), np.float64)  # zero padding: see _epipolar_stereo._window_cost
    ring = np.zeros((6, padded_channels(nch)), np.float64)
    st = np.empty((6, 7), np.float64)
    # N > 1 without gradient maps (kf_gx.ndim == 1, see observe_numba): the keyframe pixel's own gradients, formed
    # here per pixel with the float32 arithmetic of frame.gradients (the same bits as reading the maps)
    on_the_fly = kf.ndim == 3 and kf_gx.ndim == 1
    pgx = np.empty(nch if on_the_fly else 0, np.float32)
    pgy = np.empty(nch if on_the_fly else 0, np.float32)
    half = np.float32(0.5)
    if kf_gx.ndim == 1:
        gxa = pgx
        gya = pgy
    else:
        gxa = kf_gx
        gya = kf_gy
    for y in range(3 + first, h - 3, step):
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
            if on_the_fly:
                for c in range(nch):
                    pgx[c] = half * (kf[y, x + 1, c] - kf[y, x - 1, c])
                    pgy[c] = half * (kf[y + 1, x, c] - kf[y - 1, x, c])
            ok, epxn, epyn = _epl_check(gxa, gya, x, y, geo, prm, cscale)
            if not ok:
                counts[y, C_SKIP_EPL] += 1
                continue
            if not has:
                # ---------------- create
                counts[y, C_CREATE_ATTEMPTED] += 1
                err, rid, rvar, rlen = _line_stereo(
                    kf,
                    ref,
                    gxa,
                    gya,
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
                    kfv,
                    ring,
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
                    kf, ref, gxa, gya, float(x), float(y), epxn, epyn, lo, ids, hi, geo, prm, cscale, kfv, ring, st
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


def observe_numba(
    state: tuple[np.ndarray, ...],
    kf: np.ndarray,
    kf_gx: np.ndarray | None,
    kf_gy: np.ndarray | None,
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
    so ``parallel=True`` (rows over threads, :func:`~dmtrack.odometry._depth_common.run_rows`) gives byte-identical
    results. ``kf_gx``, ``kf_gy`` may be ``None``: for N > 1 the kernel then forms each keyframe pixel's gradients
    from ``kf`` itself (the same bits, without two (H, W, N) maps: 314 MB for 128-channel dense SIFT at 640×480).
    """
    h = state[0].shape[0]
    if kf_gx is None or kf_gy is None:
        if kf.shape[2] == 1:
            kf_gx, kf_gy, _ = gradients(kf)
        else:  # the kernel forms each keyframe pixel's gradients itself (see _observe_rows)
            kf_gx = kf_gy = _NO_GRADIENTS
    if kf.shape[2] == 1:  # one channel: the (H, W) build, without channel loops (the same arithmetic)
        kf, kf_gx, kf_gy, ref = (a.reshape(a.shape[0], a.shape[1]) for a in (kf, kf_gx, kf_gy, ref))
    counts = np.zeros((h, N_COUNTS), np.int64)
    use_good = good is not None
    g = good if use_good else np.ones((1, 1), np.bool_)
    # one compiled row kernel for any thread count: serial and threaded updates run the same machine code
    args = (*state, kf, kf_gx, kf_gy, kf_mg, ref, g, use_good, geo, prm, float(cscale), int(frame_id),
            float(skip_ratio), counts)  # fmt: skip
    run_rows(_observe_rows, args, parallel)
    return counts.sum(axis=0)


# ============================================================================== numpy references
def _unzero_ref(v: float) -> float:
    if v < 0.0:
        return -1e-10 if v > -1e-10 else v
    return 1e-10 if v < 1e-10 else v


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
