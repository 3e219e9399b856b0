"""Normal equations of the SE(3) tracker and its Levenberg–Marquardt step (lsd-slam-spec.md §2).

:func:`warp_update` accumulates ``A = Σ_p Mᵀ S M`` (6×6) and ``b = Σ_p Mᵀ s`` from the per-point buffer of
:func:`dmtrack.odometry._tracker_residuals.eval_pass` (2×2 sums S, 2-vectors s; M is the 2×6 projection
derivative of the point), so the (NV)×6 Jacobian never exists; blocked like the residual pass (serial and
``prange`` builds are bit-identical), with a numpy reference (:func:`warp_update_numpy`).
:func:`solve_damped` solves the damped system and :func:`se3_exp` turns the step into a pose increment.

Numba cache caveat: ``cache=True`` keys a kernel on its own source file only, and the kernels here compile in
:data:`~dmtrack.odometry._tracker_residuals.BLOCK` from another module; after changing it, clear the cache
(``rm -f src/dmtrack/odometry/__pycache__/*.nbi src/dmtrack/odometry/__pycache__/*.nbc``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dmtrack.odometry._tracker_residuals import BLOCK

# ============================================================================== normal equations
_NA = 27  # 21 upper-triangle entries of A and 6 of b


@numba.njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _warp_block(blk, buf, part):  # pragma: no cover - compiled
    a00 = a01 = a02 = a03 = a04 = a05 = 0.0
    a11 = a12 = a13 = a14 = a15 = 0.0
    a22 = a23 = a24 = a25 = 0.0
    a33 = a34 = a35 = 0.0
    a44 = a45 = 0.0
    a55 = 0.0
    b0 = b1 = b2 = b3 = b4 = b5 = 0.0
    i0 = blk * BLOCK
    i1 = min(buf.shape[0], i0 + BLOCK)
    for k in range(i0, i1):
        z = buf[k, 2]
        if z == 0.0:  # point outside the image
            continue
        x = buf[k, 0]
        y = buf[k, 1]
        iz = 1.0 / z
        sxx = buf[k, 3]
        sxy = buf[k, 4]
        syy = buf[k, 5]
        bx = buf[k, 6]
        by = buf[k, 7]
        xz = x * iz
        yz = y * iz
        # jx = (iz, 0, -xz*iz, -xz*yz, 1 + xz*xz, -yz); jy = (0, iz, -yz*iz, -(1 + yz*yz), xz*yz, xz)
        jx0 = iz
        jx2 = -xz * iz
        jx3 = -xz * yz
        jx4 = 1.0 + xz * xz
        jx5 = -yz
        jy1 = iz
        jy2 = -yz * iz
        jy3 = -(1.0 + yz * yz)
        jy4 = xz * yz
        jy5 = xz
        # u = S_xx jx + S_xy jy ; q = S_xy jx + S_yy jy
        u0 = sxx * jx0
        u1 = sxy * jy1
        u2 = sxx * jx2 + sxy * jy2
        u3 = sxx * jx3 + sxy * jy3
        u4 = sxx * jx4 + sxy * jy4
        u5 = sxx * jx5 + sxy * jy5
        q1 = syy * jy1
        q2 = sxy * jx2 + syy * jy2
        q3 = sxy * jx3 + syy * jy3
        q4 = sxy * jx4 + syy * jy4
        q5 = sxy * jx5 + syy * jy5
        a00 += jx0 * u0
        a01 += jx0 * u1
        a02 += jx0 * u2
        a03 += jx0 * u3
        a04 += jx0 * u4
        a05 += jx0 * u5
        a11 += jy1 * q1
        a12 += jy1 * q2
        a13 += jy1 * q3
        a14 += jy1 * q4
        a15 += jy1 * q5
        a22 += jx2 * u2 + jy2 * q2
        a23 += jx2 * u3 + jy2 * q3
        a24 += jx2 * u4 + jy2 * q4
        a25 += jx2 * u5 + jy2 * q5
        a33 += jx3 * u3 + jy3 * q3
        a34 += jx3 * u4 + jy3 * q4
        a35 += jx3 * u5 + jy3 * q5
        a44 += jx4 * u4 + jy4 * q4
        a45 += jx4 * u5 + jy4 * q5
        a55 += jx5 * u5 + jy5 * q5
        b0 += jx0 * bx
        b1 += jy1 * by
        b2 += jx2 * bx + jy2 * by
        b3 += jx3 * bx + jy3 * by
        b4 += jx4 * bx + jy4 * by
        b5 += jx5 * bx + jy5 * by
    p = part[blk]
    p[0] = a00
    p[1] = a01
    p[2] = a02
    p[3] = a03
    p[4] = a04
    p[5] = a05
    p[6] = a11
    p[7] = a12
    p[8] = a13
    p[9] = a14
    p[10] = a15
    p[11] = a22
    p[12] = a23
    p[13] = a24
    p[14] = a25
    p[15] = a33
    p[16] = a34
    p[17] = a35
    p[18] = a44
    p[19] = a45
    p[20] = a55
    p[21] = b0
    p[22] = b1
    p[23] = b2
    p[24] = b3
    p[25] = b4
    p[26] = b5


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _combine_warp(part: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    tot = np.zeros(_NA)
    for blk in range(part.shape[0]):
        for k in range(_NA):
            tot[k] += part[blk, k]
    A = np.empty((6, 6))
    k = 0
    for i in range(6):
        for j in range(i, 6):
            A[i, j] = tot[k]
            A[j, i] = tot[k]
            k += 1
    return A, tot[21:27].copy()


@numba.njit(cache=True, nogil=True, error_model="numpy")
def warp_update(buf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
    """Accumulate A = Σ Mᵀ S M (6×6) and b = Σ Mᵀ s (6) over the in-image rows (z' ≠ 0) of ``buf``.

    M (2×6) is the derivative of the projection (in units where g already holds fx, fy) w.r.t. a left
    perturbation (υ, ω) of the point p' = (x, y, z):
    row x = (1/z, 0, −x/z², −xy/z², 1 + x²/z², −y/z), row y = (0, 1/z, −y/z², −(1 + y²/z²), xy/z², x/z),
    so A_ij += jx_i·(S j)_x,j + jy_i·(S j)_y,j (written out with scalar accumulators, upper triangle).
    Blocked like :func:`~dmtrack.odometry._tracker_residuals.eval_pass`. Not divided by the number of points.
    """
    nb = (buf.shape[0] + BLOCK - 1) // BLOCK
    part = np.empty((nb, _NA))
    for blk in range(nb):
        _warp_block(blk, buf, part)
    return _combine_warp(part)


@numba.njit(cache=True, nogil=True, error_model="numpy", parallel=True)
def warp_update_parallel(buf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
    """:func:`warp_update` with the blocks distributed over threads; bit-identical results."""
    nb = (buf.shape[0] + BLOCK - 1) // BLOCK
    part = np.empty((nb, _NA))
    for blk in numba.prange(nb):
        _warp_block(blk, buf, part)
    return _combine_warp(part)


def warp_update_numpy(buf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Numpy reference of :func:`warp_update`: builds the per-point 2×6 M explicitly."""
    B = buf[buf[:, 2] != 0.0]
    x, y, z = B[:, 0], B[:, 1], B[:, 2]
    iz = 1.0 / z
    iz2 = iz * iz
    zero = np.zeros_like(x)
    jx = np.stack([iz, zero, -x * iz2, -x * y * iz2, 1.0 + x * x * iz2, -y * iz], axis=1)
    jy = np.stack([zero, iz, -y * iz2, -(1.0 + y * y * iz2), x * y * iz2, x * iz], axis=1)
    M = np.stack([jx, jy], axis=1)  # (n, 2, 6)
    S = np.empty((len(B), 2, 2))
    S[:, 0, 0] = B[:, 3]
    S[:, 0, 1] = S[:, 1, 0] = B[:, 4]
    S[:, 1, 1] = B[:, 5]
    A = np.einsum("nki,nkl,nlj->ij", M, S, M)
    b = np.einsum("nki,nk->i", M, B[:, 6:8])
    return A, b


# ============================================================================== small linear algebra
@numba.njit(cache=True, nogil=True, error_model="numpy")
def solve_damped(A: np.ndarray, b: np.ndarray, lam: float) -> tuple[np.ndarray, bool]:  # pragma: no cover
    """Solve (A with its diagonal multiplied by 1+λ) x = b by an LDLᵀ factorisation (6×6, no pivoting).

    Returns (x, ok); ok is False (and x zero) when a pivot is not positive and finite.
    """
    n = A.shape[0]
    M = A.copy()
    for i in range(n):
        M[i, i] *= 1.0 + lam
    L = np.eye(n)
    D = np.zeros(n)
    x = np.zeros(n)
    for j in range(n):
        dj = M[j, j]
        for k in range(j):
            dj -= L[j, k] * L[j, k] * D[k]
        if not (dj > 0.0) or not math.isfinite(dj):
            return x, False
        D[j] = dj
        for i in range(j + 1, n):
            s = M[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k] * D[k]
            L[i, j] = s / dj
    y = np.zeros(n)
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s
    for i in range(n):
        y[i] /= D[i]
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * x[k]
        x[i] = s
    return x, True


@numba.njit(cache=True, nogil=True, error_model="numpy")
def se3_exp(xi: np.ndarray) -> np.ndarray:  # pragma: no cover
    """exp of a twist (υ, ω) (translation first) as a 4×4 float64 matrix (Sophus convention)."""
    wx = xi[3]
    wy = xi[4]
    wz = xi[5]
    th2 = wx * wx + wy * wy + wz * wz
    if th2 < 1e-10:
        a = 1.0 - th2 / 6.0
        bb = 0.5 - th2 / 24.0
        cc = 1.0 / 6.0 - th2 / 120.0
    else:
        th = math.sqrt(th2)
        a = math.sin(th) / th
        bb = (1.0 - math.cos(th)) / th2
        cc = (th - math.sin(th)) / (th2 * th)
    W = np.zeros((3, 3))
    W[0, 1] = -wz
    W[0, 2] = wy
    W[1, 0] = wz
    W[1, 2] = -wx
    W[2, 0] = -wy
    W[2, 1] = wx
    W2 = W @ W
    T = np.eye(4)
    for i in range(3):
        for j in range(3):
            e = 1.0 if i == j else 0.0
            T[i, j] = e + a * W[i, j] + bb * W2[i, j]
    for i in range(3):
        s = 0.0
        for j in range(3):
            e = 1.0 if i == j else 0.0
            s += (e + bb * W[i, j] + cc * W2[i, j]) * xi[j]
        T[i, 3] = s
    return T
