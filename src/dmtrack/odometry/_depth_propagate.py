"""Depth propagation into a new keyframe: LSD-SLAM's ``propagateDepth``.

Every valid hypothesis of the old keyframe is warped with its smoothed inverse depth into the new keyframe;
collisions keep the closer of two inconsistent hypotheses and fuse consistent ones. The numba kernel
(:func:`propagate_numba`, sequential in row-major order) and its reference (:func:`propagate_reference`).
Conventions and the numba cache caveat: :mod:`dmtrack.odometry._depth_common`.
"""

from __future__ import annotations

import numba
import numpy as np

from dmtrack.geometry.exact import matmul
from dmtrack.odometry._depth_common import (
    _JIT,
    GOOD_LEVEL,
    N_PCOUNTS,
    P_MIN_GRAD,
    P_VAL_MAX,
    P_VAL_MAX_VAR,
    PC_ATTEMPTS,
    PC_CREATED,
    PC_DROPPED_GOOD,
    PC_MERGED,
    PC_OCCLUDED,
    PC_OOB,
    _sample,
    bilinear_reference,
    empty_state,
)

# ------------------------------------------------------------------------------------------ constants
#: ``DIFF_FAC_PROP_MERGE`` (1 in LSD-SLAM): factor of the squared difference in the collision test.
DIFF_FAC_PROP_MERGE = 1.0
#: ``MAX_DIFF_CONSTANT`` and ``MAX_DIFF_GRAD_MULT`` of the propagation colour test (used only when no
#: ``refPixelWasGood`` flags are given).
MAX_DIFF_CONSTANT = 40.0 * 40.0
MAX_DIFF_GRAD_MULT = 0.5 * 0.5


# ============================================================================== numba kernel
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


# ============================================================================== numpy references
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
    pn = matmul(T[:3, :3], rays) / d + T[:3, 3:4]
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
