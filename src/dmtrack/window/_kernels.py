"""Kernels of the window's photometric bundle adjustment: the normal equations of one (host, target) pair of
keyframes, the Schur complement over the point depths and a small LDLᵀ solve.

Each point ``p`` of a host keyframe h (level-l pixel ``(x, y)``, inverse depth ``d`` in world units, its N feature
values ``F_h``) is warped into a target keyframe t: ``m = ((x − c_x)/f_x, (y − c_y)/f_y, 1)``, ``q = R_th m + t_th d``
(the point in t's camera, times d), ``(u, v) = (f_x q_0/q_2 + c_x, f_y q_1/q_2 + c_y)``. Its residual is the N-vector
``r_c = F_t,c(u, v) − F_h,c`` (bilinear samples). Poses are world → camera, perturbed on the left,
``T_cw ← exp(ξ) T_cw`` with ξ = (υ, ω); the 17 local parameters of a residual are the host's ξ (6), the target's
ξ (6), the level-0 intrinsics (f_x, c_x, f_y, c_y) and d. Only the 2×2 sums ``G = Σ_c ∇F_c ∇F_cᵀ`` and the 2-vector
``g = Σ_c ∇F_c r_c`` (target gradients) enter the normal equations, so N channels cost N samples and no more.

Robust weight: e = √(κ Σ_c r_c²) with κ the channel rule's residual factor (the odometry's ``channel_cost``); Huber
with threshold k: w = 1 for e ≤ k, k/e above; cost ρ(e) = e² or 2ke − k², divided by σ² (the photometric noise); with
a gradient weight c > 0 both are multiplied by √(c² / (c² + κ Σ_c |∇F_c|²)) (DSO's, c = 50), which trusts a residual
on a strong edge less, where a fraction of a pixel changes it most.
A residual whose e exceeds ``outlier``, or whose warp leaves the image (a 2-pixel border), gets no weight and the
constant cost ρ(outlier), so that costs stay comparable while the set of visible points changes.

All arithmetic is float64 in loops written out in a fixed order (no fast-math, no BLAS): the same bits on every CPU
and for any thread count. :func:`pair_normal_equations_numpy` is the vectorised numpy reference (tests).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dmtrack.odometry._tracker_normal_equations import se3_exp, solve_damped

#: Local parameter columns: host ξ 0–5, target ξ 6–11, intrinsics (f_x, c_x, f_y, c_y) 12–15, inverse depth 16.
N_LOCAL = 17
#: Columns of ``stats``: total cost, residuals inside the image and under the outlier threshold, outliers.
S_COST, S_IN, S_OUT = range(3)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def sample_values(packed: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:  # pragma: no cover
    """Bilinear samples (P, N) float32 of the feature values (``packed[..., 0, :]``) at ``(xs, ys)``; points outside
    ``[0, w − 1) × [0, h − 1)`` get the nearest inside pixel's value."""
    h, w, _, n = packed.shape
    out = np.empty((xs.shape[0], n), np.float32)
    for i in range(xs.shape[0]):
        x = min(max(xs[i], 0.0), w - 1.000001)
        y = min(max(ys[i], 0.0), h - 1.000001)
        ix, iy = int(x), int(y)
        ax, ay = x - ix, y - iy
        w00, w01, w10, w11 = (1 - ax) * (1 - ay), ax * (1 - ay), (1 - ax) * ay, ax * ay
        for c in range(n):
            out[i, c] = (w00 * packed[iy, ix, 0, c] + w01 * packed[iy, ix + 1, 0, c]
                         + w10 * packed[iy + 1, ix, 0, c] + w11 * packed[iy + 1, ix + 1, 0, c])  # fmt: skip
    return out


@numba.njit(nogil=True, error_model="numpy", inline="always")
def _dq_columns(R: np.ndarray, t: np.ndarray, m0: float, m1: float, d: float, q: np.ndarray, fx: float, fy: float,
                dq: np.ndarray) -> None:  # fmt: skip  # pragma: no cover
    """∂q/∂(local parameter) for the 17 columns, into ``dq`` (3, 17)."""
    for k in range(3):  # host υ: −d R e_k; target υ: d e_k
        for i in range(3):
            dq[i, k] = -d * R[i, k]
            dq[i, 6 + k] = d if i == k else 0.0
    # host ω: R (m × e_k), m = (m0, m1, 1)
    for i in range(3):
        dq[i, 3] = R[i, 1] - R[i, 2] * m1  # m × e_x = (0, 1, −m1)
        dq[i, 4] = R[i, 2] * m0 - R[i, 0]  # m × e_y = (−1, 0, m0)
        dq[i, 5] = R[i, 0] * m1 - R[i, 1] * m0  # m × e_z = (m1, −m0, 0)
    # target ω: e_k × q
    dq[0, 9], dq[1, 9], dq[2, 9] = 0.0, -q[2], q[1]
    dq[0, 10], dq[1, 10], dq[2, 10] = q[2], 0.0, -q[0]
    dq[0, 11], dq[1, 11], dq[2, 11] = -q[1], q[0], 0.0
    # intrinsics through m (the direct terms are added to the pixel Jacobian)
    for i in range(3):
        dq[i, 12] = R[i, 0] * (-m0 / fx)
        dq[i, 13] = R[i, 0] * (-1.0 / fx)
        dq[i, 14] = R[i, 1] * (-m1 / fy)
        dq[i, 15] = R[i, 1] * (-1.0 / fy)
        dq[i, 16] = t[i]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def pair_normal_equations(
    packed: np.ndarray,
    xs: np.ndarray,
    ys: np.ndarray,
    ds: np.ndarray,
    ref: np.ndarray,
    point_rows: np.ndarray,
    T_th: np.ndarray,
    cam: np.ndarray,
    cols: np.ndarray,
    params: np.ndarray,
    H: np.ndarray,
    b: np.ndarray,
    hpp: np.ndarray,
    bp: np.ndarray,
    Hcp: np.ndarray,
    stats: np.ndarray,
    cost_only: bool,
) -> None:  # pragma: no cover - compiled
    """Add one (host, target) pair's residuals to the normal equations (see the module docstring).

    ``packed`` (h, w, 3, N) float32: the target level's (F, ∂F/∂x, ∂F/∂y); ``xs, ys`` (P,) level pixels of the host's
    points, ``ds`` (P,) their inverse depths, ``ref`` (P, N) float32 their values; ``point_rows`` (P,) each point's row
    in ``hpp``/``bp``/``Hcp`` (−1: its depth is fixed); ``T_th`` (4, 4) host → target; ``cam`` (f_x, f_y, c_x, c_y,
    s) of the level, s = 2^−level (the chain to level-0 intrinsics); ``cols`` (16,) the global column of each local
    pose/intrinsics parameter (−1: fixed); ``params`` (κ, 1/σ², Huber k, outlier e, c² of the gradient weight or 0).
    Adds into ``H`` (n, n), ``b`` (n,), ``hpp``, ``bp``, ``Hcp`` (rows, n) and ``stats`` (cost, inliers, outliers);
    with ``cost_only`` only ``stats``.
    """
    h, w, _, n = packed.shape
    fx, fy, cx, cy, s = cam[0], cam[1], cam[2], cam[3], cam[4]
    kappa, inv_s2, hk, out_e, c2 = params[0], params[1], params[2], params[3], params[4]
    cost_out = (2.0 * hk * out_e - hk * hk) * inv_s2 if out_e > hk else out_e * out_e * inv_s2
    R = T_th[:3, :3]
    t = T_th[:3, 3]
    q = np.empty(3)
    dq = np.empty((3, N_LOCAL))
    J = np.empty((2, N_LOCAL))
    M = np.empty((2, N_LOCAL))
    bl = np.empty(N_LOCAL)
    for i in range(xs.shape[0]):
        d = ds[i]
        m0 = (xs[i] - cx) / fx
        m1 = (ys[i] - cy) / fy
        for k in range(3):
            q[k] = R[k, 0] * m0 + R[k, 1] * m1 + R[k, 2] + t[k] * d
        iz = 1.0 / q[2]
        u = fx * q[0] * iz + cx
        v = fy * q[1] * iz + cy
        if not (q[2] > 0.0 and u >= 2.0 and v >= 2.0 and u < w - 3.0 and v < h - 3.0):
            stats[S_COST] += cost_out
            stats[S_OUT] += 1.0
            continue
        ix, iy = int(u), int(v)
        ax, ay = u - ix, v - iy
        w00, w01, w10, w11 = (1 - ax) * (1 - ay), ax * (1 - ay), (1 - ax) * ay, ax * ay
        rr = 0.0
        gxr = 0.0
        gyr = 0.0
        gxx = 0.0
        gxy = 0.0
        gyy = 0.0
        for c in range(n):
            f = (w00 * packed[iy, ix, 0, c] + w01 * packed[iy, ix + 1, 0, c]
                 + w10 * packed[iy + 1, ix, 0, c] + w11 * packed[iy + 1, ix + 1, 0, c])  # fmt: skip
            gx = (w00 * packed[iy, ix, 1, c] + w01 * packed[iy, ix + 1, 1, c]
                  + w10 * packed[iy + 1, ix, 1, c] + w11 * packed[iy + 1, ix + 1, 1, c])  # fmt: skip
            gy = (w00 * packed[iy, ix, 2, c] + w01 * packed[iy, ix + 1, 2, c]
                  + w10 * packed[iy + 1, ix, 2, c] + w11 * packed[iy + 1, ix + 1, 2, c])  # fmt: skip
            r = f - ref[i, c]
            rr += r * r
            gxr += gx * r
            gyr += gy * r
            gxx += gx * gx
            gxy += gx * gy
            gyy += gy * gy
        e = math.sqrt(kappa * rr)
        if e > out_e:
            stats[S_COST] += cost_out
            stats[S_OUT] += 1.0
            continue
        stats[S_IN] += 1.0
        wg = math.sqrt(c2 / (c2 + kappa * (gxx + gyy))) if c2 > 0.0 else 1.0
        if e <= hk:
            stats[S_COST] += wg * e * e * inv_s2
            wt = wg * kappa * inv_s2
        else:
            stats[S_COST] += wg * (2.0 * hk * e - hk * hk) * inv_s2
            wt = wg * kappa * inv_s2 * hk / e
        if cost_only:
            continue
        _dq_columns(R, t, m0, m1, d, q, fx, fy, dq)
        a0 = fx * iz
        a2 = -fx * q[0] * iz * iz
        b1 = fy * iz
        b2 = -fy * q[1] * iz * iz
        for k in range(N_LOCAL):
            J[0, k] = a0 * dq[0, k] + a2 * dq[2, k]
            J[1, k] = b1 * dq[1, k] + b2 * dq[2, k]
        J[0, 12] += q[0] * iz
        J[0, 13] += 1.0
        J[1, 14] += q[1] * iz
        J[1, 15] += 1.0
        for k in range(12, 16):
            J[0, k] *= s
            J[1, k] *= s
        for k in range(N_LOCAL):
            M[0, k] = wt * (gxx * J[0, k] + gxy * J[1, k])
            M[1, k] = wt * (gxy * J[0, k] + gyy * J[1, k])
            bl[k] = wt * (J[0, k] * gxr + J[1, k] * gyr)
        row = point_rows[i]
        for j in range(16):
            cj = cols[j]
            if cj < 0:
                continue
            b[cj] += bl[j]
            for k in range(16):
                ck = cols[k]
                if ck >= 0:
                    H[cj, ck] += J[0, j] * M[0, k] + J[1, j] * M[1, k]
            if row >= 0:
                Hcp[row, cj] += J[0, j] * M[0, 16] + J[1, j] * M[1, 16]
        if row >= 0:
            hpp[row] += J[0, 16] * M[0, 16] + J[1, 16] * M[1, 16]
            bp[row] += bl[16]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def schur_reduce(
    H: np.ndarray, b: np.ndarray, hpp: np.ndarray, bp: np.ndarray, Hcp: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """The reduced system (H − Σ_p Hcp_p Hcp_pᵀ / hpp_p, b − Σ_p Hcp_p bp_p / hpp_p) over the points with information
    (hpp > 0), in a fixed order."""
    n = H.shape[0]
    A = H.copy()
    r = b.copy()
    for p in range(hpp.shape[0]):
        if not hpp[p] > 0.0:
            continue
        inv = 1.0 / hpp[p]
        for j in range(n):
            hj = Hcp[p, j]
            if hj == 0.0:
                continue
            f = hj * inv
            r[j] -= f * bp[p]
            for k in range(n):
                A[j, k] -= f * Hcp[p, k]
    return A, r


@numba.njit(cache=True, nogil=True, error_model="numpy")
def schur_solve(
    H: np.ndarray, b: np.ndarray, hpp: np.ndarray, bp: np.ndarray, Hcp: np.ndarray, lam: float
) -> tuple[np.ndarray, np.ndarray, bool]:  # pragma: no cover - compiled
    """Solve the damped normal equations for the steps (δc, δp) = −H⁻¹b with the point block eliminated.

    Damping: every diagonal entry × (1 + λ). Points with no information (hpp ≤ 0) get no step. Returns δc, δp and
    whether the reduced system was positive definite (its LDLᵀ factor exists)."""
    n = H.shape[0]
    Hd = H.copy()
    for j in range(n):
        Hd[j, j] *= 1.0 + lam
    hd = np.empty(hpp.shape[0])
    for p in range(hpp.shape[0]):
        hd[p] = hpp[p] * (1.0 + lam)
    A, r = schur_reduce(Hd, b, hd, bp, Hcp)
    x, ok = cholesky_solve(A, -r)
    dp = np.zeros(hpp.shape[0])
    for p in range(hpp.shape[0]):
        if hd[p] > 0.0:
            acc = bp[p]
            for j in range(n):
                acc += Hcp[p, j] * x[j]
            dp[p] = -acc / hd[p]
    return x, dp, ok


@numba.njit(cache=True, nogil=True, error_model="numpy")
def cholesky_solve(A: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, bool]:  # pragma: no cover - compiled
    """x with A x = y for a symmetric positive definite A (the tracker's LDLᵀ :func:`solve_damped`, undamped);
    (zeros, False) if A is not positive definite."""
    return solve_damped(A, y, 0.0)


@numba.njit(cache=True, nogil=True, error_model="numpy")
def se3_left_update(T: np.ndarray, xi: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """exp(ξ) · T for a 4×4 rigid transform T and ξ = (υ, ω) (the tracker's :func:`se3_exp`; a product in a fixed
    order)."""
    E = se3_exp(xi)
    out = np.zeros((4, 4))
    for i in range(4):
        for j in range(4):
            acc = 0.0
            for k in range(4):
                acc += E[i, k] * T[k, j]
            out[i, j] = acc
    return out


def pair_normal_equations_numpy(
    packed: np.ndarray,
    xs: np.ndarray,
    ys: np.ndarray,
    ds: np.ndarray,
    ref: np.ndarray,
    point_rows: np.ndarray,
    T_th: np.ndarray,
    cam: np.ndarray,
    cols: np.ndarray,
    params: np.ndarray,
    H: np.ndarray,
    b: np.ndarray,
    hpp: np.ndarray,
    bp: np.ndarray,
    Hcp: np.ndarray,
    stats: np.ndarray,
    cost_only: bool,
) -> None:
    """Vectorised numpy reference of :func:`pair_normal_equations` (equal up to the order of float64 sums)."""
    h, w, _, _ = packed.shape
    fx, fy, cx, cy, s = (float(v) for v in cam)
    kappa, inv_s2, hk, out_e, c2 = (float(v) for v in params)
    cost_out = (2.0 * hk * out_e - hk * hk) * inv_s2 if out_e > hk else out_e * out_e * inv_s2
    R, t = T_th[:3, :3], T_th[:3, 3]
    m = np.stack([(xs - cx) / fx, (ys - cy) / fy, np.ones_like(xs)], axis=1)
    q = m @ R.T + ds[:, None] * t[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        iz = 1.0 / q[:, 2]
        u = fx * q[:, 0] * iz + cx
        v = fy * q[:, 1] * iz + cy
    inside = (q[:, 2] > 0) & (u >= 2.0) & (v >= 2.0) & (u < w - 3.0) & (v < h - 3.0)
    ui, vi = np.where(inside, u, 2.0), np.where(inside, v, 2.0)
    ix, iy = ui.astype(np.int64), vi.astype(np.int64)
    ax, ay = (ui - ix)[:, None], (vi - iy)[:, None]

    def bil(k: int) -> np.ndarray:
        p = packed[..., k, :].astype(np.float64)
        return ((1 - ax) * (1 - ay) * p[iy, ix] + ax * (1 - ay) * p[iy, ix + 1]
                + (1 - ax) * ay * p[iy + 1, ix] + ax * ay * p[iy + 1, ix + 1])  # fmt: skip

    r = bil(0) - ref.astype(np.float64)
    gx, gy = bil(1), bil(2)
    e = np.sqrt(kappa * np.sum(r * r, axis=1))
    use = inside & (e <= out_e)
    stats[S_OUT] += np.count_nonzero(~use)
    stats[S_IN] += np.count_nonzero(use)
    huber = e <= hk
    g2 = kappa * (np.sum(gx * gx, 1) + np.sum(gy * gy, 1))
    wg = np.sqrt(c2 / (c2 + g2)) if c2 > 0 else np.ones_like(e)
    cost = wg * np.where(huber, e * e, 2.0 * hk * e - hk * hk) * inv_s2
    stats[S_COST] += float(np.sum(np.where(use, cost, cost_out)))
    if cost_only:
        return
    wt = np.where(use, wg * kappa * inv_s2 * np.where(huber, 1.0, hk / np.where(e > 0, e, 1.0)), 0.0)
    n_pts = xs.shape[0]
    dq = np.zeros((n_pts, 3, N_LOCAL))
    d = ds[:, None]
    dq[:, :, 0:3] = -d[:, :, None] * R[None]
    mx = np.cross(m[:, None, :], np.eye(3)[None, :, :])  # (P, k, 3): m × e_k
    dq[:, :, 3:6] = np.einsum("ij,pkj->pik", R, mx)
    dq[:, :, 6:9] = d[:, :, None] * np.eye(3)[None]
    dq[:, :, 9:12] = np.cross(np.eye(3)[None, :, :], q[:, None, :]).transpose(0, 2, 1)  # e_k × q
    dq[:, :, 12] = R[None, :, 0] * (-m[:, 0:1] / fx)
    dq[:, :, 13] = R[None, :, 0] * (-1.0 / fx)
    dq[:, :, 14] = R[None, :, 1] * (-m[:, 1:2] / fy)
    dq[:, :, 15] = R[None, :, 1] * (-1.0 / fy)
    dq[:, :, 16] = t[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        A = np.zeros((n_pts, 2, 3))
        A[:, 0, 0], A[:, 0, 2] = fx * iz, -fx * q[:, 0] * iz * iz
        A[:, 1, 1], A[:, 1, 2] = fy * iz, -fy * q[:, 1] * iz * iz
        J = np.einsum("pij,pjk->pik", A, dq)
        J[:, 0, 12] += q[:, 0] * iz
        J[:, 1, 14] += q[:, 1] * iz
    J[:, 0, 13] += 1.0
    J[:, 1, 15] += 1.0
    J[:, :, 12:16] *= s
    J = np.where(use[:, None, None], J, 0.0)
    G = np.stack([np.sum(gx * gx, 1), np.sum(gx * gy, 1), np.sum(gy * gy, 1)], 1)
    g = np.stack([np.sum(gx * r, 1), np.sum(gy * r, 1)], 1)
    Gm = np.stack([np.stack([G[:, 0], G[:, 1]], 1), np.stack([G[:, 1], G[:, 2]], 1)], 1) * wt[:, None, None]
    Hl = np.einsum("pik,pij,pjl->pkl", J, Gm, J)
    bl = np.einsum("pik,pi->pk", J, g * wt[:, None])
    sel = np.nonzero(cols >= 0)[0]
    gc = cols[sel]
    H[np.ix_(gc, gc)] += Hl[:, sel][:, :, sel].sum(0)
    b[gc] += bl[:, sel].sum(0)
    rows = point_rows
    has = rows >= 0
    np.add.at(hpp, rows[has], Hl[has, 16, 16])
    np.add.at(bp, rows[has], bl[has, 16])
    for j, c in zip(sel, gc, strict=True):
        np.add.at(Hcp[:, c], rows[has], Hl[has, j, 16])


@numba.njit(cache=True, nogil=True, error_model="numpy")
def se3_log(T: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """ξ = (υ, ω) with exp(ξ) = T for a 4×4 rigid transform (rotation angle below π; loops in a fixed order)."""
    R = T[:3, :3]
    c = (R[0, 0] + R[1, 1] + R[2, 2] - 1.0) * 0.5
    c = min(max(c, -1.0), 1.0)
    th = math.acos(c)
    if th < 1e-10:
        f = 0.5
    else:
        f = th / (2.0 * math.sin(th))
    w = np.array([f * (R[2, 1] - R[1, 2]), f * (R[0, 2] - R[2, 0]), f * (R[1, 0] - R[0, 1])])
    W = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    W2 = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += W[i, k] * W[k, j]
            W2[i, j] = acc
    th2 = th * th
    if th < 1e-5:
        g = 1.0 / 12.0
    else:
        g = (1.0 - th * math.sin(th) / (2.0 * (1.0 - math.cos(th)))) / th2
    out = np.empty(6)
    for i in range(3):  # V⁻¹ = I − ½W + g W²
        acc = 0.0
        for j in range(3):
            Vi = (1.0 if i == j else 0.0) - 0.5 * W[i, j] + g * W2[i, j]
            acc += Vi * T[j, 3]
        out[i] = acc
    out[3], out[4], out[5] = w[0], w[1], w[2]
    return out
