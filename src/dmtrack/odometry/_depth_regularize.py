"""Regularisation of the depth map: LSD-SLAM's ``regularizeDepthMap`` (radius 2, with and without occlusion
removal) and ``regularizeDepthMapFillHoles``.

Numba kernels (:func:`regularize_numba`, :func:`fill_holes_numba`; serial and row-parallel builds) and their
vectorised numpy references (:func:`regularize_reference`, :func:`fill_holes_reference`). The regularisation
computes in float32, as LSD-SLAM; the hole filling in float64. Conventions and the numba cache caveat:
:mod:`dmtrack.odometry._depth_common`.
"""

from __future__ import annotations

import numba
import numpy as np

from dmtrack.odometry._depth_common import (
    _JIT,
    _JIT_LLVM_INLINE,
    P_MIN_BLACKLIST,
    P_MIN_GRAD,
    P_VAL_SUM_CREATE,
    P_VAL_SUM_UNBL,
    P_VAR_INIT,
    _unzero,
    run_rows,
)

#: ``DIFF_FAC_SMOOTHING`` (1 in LSD-SLAM): factor of the squared difference in the neighbour consistency test.
DIFF_FAC_SMOOTHING = 1.0


# ============================================================================== numba kernels
@numba.njit(**_JIT_LLVM_INLINE)
def _reg_term(vr, di, vi, val, d0, v0, c, fac, sv, ss, si, so, sk):  # pragma: no cover - compiled
    """One neighbour's float32 contribution to a pixel's regularisation sums (validity, Σ d/σ², Σ 1/σ², occluders,
    consistent neighbours), branch-free: ``c`` is its distance term."""
    one = np.float32(1.0)
    zero = np.float32(0.0)
    diff = di - d0
    incons = fac * diff * diff > vi + v0
    use = vr & (not incons)
    iv = one / (vi + c)
    sv += val if use else zero
    ss += di * iv if use else zero
    si += iv if use else zero
    so += one if (vr & incons & (di > d0)) else zero
    sk += one if use else zero
    return sv, ss, si, so, sk


@numba.njit(**_JIT)
def _regularize_rows(
    first,
    step,
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
    """Row-vectorised regularisation of the rows 2 + ``first``, 2 + ``first`` + ``step``, … (one call per thread,
    :func:`~dmtrack.odometry._depth_common.run_rows`): for each row, five branch-free passes over the columns (one
    per neighbour row dy, its five column offsets dx unrolled) accumulate into per-column float32 buffers, in the
    order (dy, dx) of LSD-SLAM's loops (a pixel's sums are those of 25 passes, one per offset, with a fifth of their
    buffer traffic); then the per-pixel decisions. A row without valid pixels is skipped (it produces nothing).
    Rows only read ``valid_read`` (a copy of ``valid``), ``idepth``, ``var`` and ``validity``, which are not
    written, so rows are independent."""
    h, w = valid.shape
    zero = np.float32(0.0)
    fac = np.float32(DIFF_FAC_SMOOTHING)
    # separate allocations (not rows of one array) so that LLVM can vectorise the passes
    acc_s = np.empty(w, np.float32)
    acc_i = np.empty(w, np.float32)
    acc_v = np.empty(w, np.float32)
    n_occ = np.empty(w, np.float32)
    n_ok = np.empty(w, np.float32)
    for y in range(2 + first, h - 2, step):
        x0 = 2
        while x0 < w - 2 and not valid_read[y, x0]:
            x0 += 1
        if x0 == w - 2:
            continue  # no valid pixel in this row: nothing to do
        for x in range(w):
            acc_s[x] = zero
            acc_i[x] = zero
            acc_v[x] = zero
            n_occ[x] = zero
            n_ok[x] = zero
        for dy in range(-2, 3):
            yy = y + dy
            dy2 = dy * dy
            # the offsets dx = −2 … 2 of this row, each with its distance term
            c0 = np.float32((4 + dy2) * reg_dist_var)
            c1 = np.float32((1 + dy2) * reg_dist_var)
            c2 = np.float32((0 + dy2) * reg_dist_var)
            c3 = np.float32((1 + dy2) * reg_dist_var)
            c4 = np.float32((4 + dy2) * reg_dist_var)
            for x in range(2, w - 2):  # (bounds LLVM can see: the loop is vectorised)
                d0 = idepth[y, x]
                v0 = var[y, x]
                sv = acc_v[x]
                ss = acc_s[x]
                si = acc_i[x]
                so = n_occ[x]
                sk = n_ok[x]
                # dx = −2 … 2, in LSD-SLAM's order (one inlined term each: the loop over x stays vectorised)
                sv, ss, si, so, sk = _reg_term(
                    valid_read[yy, x - 2], idepth[yy, x - 2], var[yy, x - 2], validity[yy, x - 2], d0, v0, c0, fac,
                    sv, ss, si, so, sk,
                )  # fmt: skip
                sv, ss, si, so, sk = _reg_term(
                    valid_read[yy, x - 1], idepth[yy, x - 1], var[yy, x - 1], validity[yy, x - 1], d0, v0, c1, fac,
                    sv, ss, si, so, sk,
                )  # fmt: skip
                sv, ss, si, so, sk = _reg_term(
                    valid_read[yy, x], idepth[yy, x], var[yy, x], validity[yy, x], d0, v0, c2, fac,
                    sv, ss, si, so, sk,
                )  # fmt: skip
                sv, ss, si, so, sk = _reg_term(
                    valid_read[yy, x + 1], idepth[yy, x + 1], var[yy, x + 1], validity[yy, x + 1], d0, v0, c3, fac,
                    sv, ss, si, so, sk,
                )  # fmt: skip
                sv, ss, si, so, sk = _reg_term(
                    valid_read[yy, x + 2], idepth[yy, x + 2], var[yy, x + 2], validity[yy, x + 2], d0, v0, c4, fac,
                    sv, ss, si, so, sk,
                )  # fmt: skip
                acc_v[x] = sv
                acc_s[x] = ss
                acc_i[x] = si
                n_occ[x] = so
                n_ok[x] = sk
        for x in range(x0, w - 2):
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


@numba.njit(**_JIT)
def _fill_integral(valid, validity, integral):  # pragma: no cover - compiled
    """Hole filling, the sequential part: the integral image of the validity of valid pixels,
    integral[y+1, x+1] = Σ rows ≤ y, cols ≤ x."""
    h, w = valid.shape
    for y in range(h):
        row = 0.0
        for x in range(w):
            if valid[y, x]:
                row += validity[y, x]
            integral[y + 1, x + 1] = integral[y, x + 1] + row


@numba.njit(**_JIT)
def _fill_rows(
    first, step, valid, blacklisted, next_id, validity, idepth, var, idepth_s, var_s, mg, valid_read, integral, prm
):  # pragma: no cover - compiled
    """Hole filling of the rows 3 + ``first``, 3 + ``first`` + ``step``, … (one call per thread). The fill reads
    only ``valid_read`` pixels (never written: only invalid pixels are filled) and the integral image, so rows are
    independent."""
    h, w = valid.shape
    min_grad = prm[P_MIN_GRAD]
    min_bl = prm[P_MIN_BLACKLIST]
    for y in range(3 + first, h - 2, step):
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
    over threads (:func:`~dmtrack.odometry._depth_common.run_rows`; identical results).
    """
    valid, blacklisted, _next_id, validity, idepth, var, idepth_s, var_s = state
    if scratch is None:
        scratch = np.empty(valid.shape, np.bool_)
    np.copyto(scratch, valid)  # valid_read: the rows read the validity as it was before any row wrote
    args = (valid, blacklisted, validity, idepth, var, idepth_s, var_s, scratch, bool(remove_occlusions),
            np.float32(validity_th), float(reg_dist_var))  # fmt: skip
    run_rows(_regularize_rows, args, parallel)


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
    np.copyto(scratch, state[0])  # valid_read, as in regularize_numba
    _fill_integral(state[0], state[3], integral)
    run_rows(_fill_rows, (*state, max_grad, scratch, integral, prm), parallel)


# ============================================================================== numpy references
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
