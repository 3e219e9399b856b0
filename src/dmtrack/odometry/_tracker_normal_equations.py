"""Normal equations of the SE(3) tracker and its Levenberg–Marquardt step (lsd-slam-spec.md §2).

:func:`warp_update` accumulates ``A = Σ_p Mᵀ S M`` (6×6) and ``b = Σ_p Mᵀ s`` from the per-point buffer of
:func:`dmtrack.odometry._tracker_residuals.eval_pass` (2×2 sums S, 2-vectors s; M is the 2×6 projection
derivative of the point), so the (NV)×6 Jacobian never exists; blocked like the residual pass (serial and
``prange`` builds are bit-identical), with a numpy reference (:func:`warp_update_numpy`).
:func:`solve_damped` solves the damped system and :func:`se3_exp` turns the step into a pose increment.

The normal equations of a block are formed in two passes per chunk of points (see :func:`_warp_block`): the
27 terms of every point, vectorised over points, then their sums in point order — the same roundings as the
point-by-point loop, about twice as fast.

Numba cache caveat: ``cache=True`` keys a kernel on its own source file only, and the kernels here compile in
:data:`~dmtrack.odometry._tracker_residuals.BLOCK` and the intrinsics ``select`` and ``scratch_f64`` from another
module; after changing them, clear the cache
(``rm -f src/dmtrack/odometry/__pycache__/*.nbi src/dmtrack/odometry/__pycache__/*.nbc``).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dmtrack.odometry._lanes import scratch_f64, select
from dmtrack.odometry._tracker_residuals import BLOCK

# ============================================================================== normal equations
_NA = 27  # 21 upper-triangle entries of A and 6 of b
_CHUNK = 64  # points per pass of _warp_block: its 27 stack rows (13.5 KiB) stay in L1


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _warp_block(blk, buf, part):  # pragma: no cover - compiled
    """Partial sums of block ``blk`` into ``part[blk]``, in two passes per chunk of :data:`_CHUNK` points.

    The first pass forms every point's 27 terms (vectorised over points; a point outside the image, z' = 0,
    gets +0.0 terms), the second adds them to the 27 sums in point order. Adding +0.0 leaves a sum unchanged
    (the sums start at +0.0 and never become −0.0), so the result is bit-identical to skipping those points.
    """
    t00, t01, t02, t03, t04, t05 = (scratch_f64(_CHUNK), scratch_f64(_CHUNK), scratch_f64(_CHUNK),
                                    scratch_f64(_CHUNK), scratch_f64(_CHUNK), scratch_f64(_CHUNK))  # fmt: skip
    t11, t12, t13, t14, t15 = (scratch_f64(_CHUNK), scratch_f64(_CHUNK), scratch_f64(_CHUNK), scratch_f64(_CHUNK),
                               scratch_f64(_CHUNK))  # fmt: skip
    t22, t23, t24, t25 = scratch_f64(_CHUNK), scratch_f64(_CHUNK), scratch_f64(_CHUNK), scratch_f64(_CHUNK)
    t33, t34, t35 = scratch_f64(_CHUNK), scratch_f64(_CHUNK), scratch_f64(_CHUNK)
    t44, t45, t55 = scratch_f64(_CHUNK), scratch_f64(_CHUNK), scratch_f64(_CHUNK)
    tb0, tb1, tb2, tb3, tb4, tb5 = (scratch_f64(_CHUNK), scratch_f64(_CHUNK), scratch_f64(_CHUNK),
                                    scratch_f64(_CHUNK), scratch_f64(_CHUNK), scratch_f64(_CHUNK))  # fmt: skip
    a00 = a01 = a02 = a03 = a04 = a05 = 0.0
    a11 = a12 = a13 = a14 = a15 = 0.0
    a22 = a23 = a24 = a25 = 0.0
    a33 = a34 = a35 = 0.0
    a44 = a45 = 0.0
    a55 = 0.0
    b0 = b1 = b2 = b3 = b4 = b5 = 0.0
    i0 = blk * BLOCK
    i1 = min(buf.shape[0], i0 + BLOCK)
    for c0 in range(i0, i1, _CHUNK):
        c1 = min(i1, c0 + _CHUNK)
        m = c1 - c0
        bf = buf[c0:c1].reshape(8 * m)
        for j in range(m):
            k = 8 * j
            x = bf[k]
            y = bf[k + 1]
            z = bf[k + 2]
            ok = z != 0.0  # inside the image
            iz = 1.0 / z
            sxx = bf[k + 3]
            sxy = bf[k + 4]
            syy = bf[k + 5]
            bx = bf[k + 6]
            by = bf[k + 7]
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
            t00[j] = select(ok, jx0 * u0, 0.0)
            t01[j] = select(ok, jx0 * u1, 0.0)
            t02[j] = select(ok, jx0 * u2, 0.0)
            t03[j] = select(ok, jx0 * u3, 0.0)
            t04[j] = select(ok, jx0 * u4, 0.0)
            t05[j] = select(ok, jx0 * u5, 0.0)
            t11[j] = select(ok, jy1 * q1, 0.0)
            t12[j] = select(ok, jy1 * q2, 0.0)
            t13[j] = select(ok, jy1 * q3, 0.0)
            t14[j] = select(ok, jy1 * q4, 0.0)
            t15[j] = select(ok, jy1 * q5, 0.0)
            t22[j] = select(ok, jx2 * u2 + jy2 * q2, 0.0)
            t23[j] = select(ok, jx2 * u3 + jy2 * q3, 0.0)
            t24[j] = select(ok, jx2 * u4 + jy2 * q4, 0.0)
            t25[j] = select(ok, jx2 * u5 + jy2 * q5, 0.0)
            t33[j] = select(ok, jx3 * u3 + jy3 * q3, 0.0)
            t34[j] = select(ok, jx3 * u4 + jy3 * q4, 0.0)
            t35[j] = select(ok, jx3 * u5 + jy3 * q5, 0.0)
            t44[j] = select(ok, jx4 * u4 + jy4 * q4, 0.0)
            t45[j] = select(ok, jx4 * u5 + jy4 * q5, 0.0)
            t55[j] = select(ok, jx5 * u5 + jy5 * q5, 0.0)
            tb0[j] = select(ok, jx0 * bx, 0.0)
            tb1[j] = select(ok, jy1 * by, 0.0)
            tb2[j] = select(ok, jx2 * bx + jy2 * by, 0.0)
            tb3[j] = select(ok, jx3 * bx + jy3 * by, 0.0)
            tb4[j] = select(ok, jx4 * bx + jy4 * by, 0.0)
            tb5[j] = select(ok, jx5 * bx + jy5 * by, 0.0)
        for j in range(m):
            a00 += t00[j]
            a01 += t01[j]
            a02 += t02[j]
            a03 += t03[j]
            a04 += t04[j]
            a05 += t05[j]
            a11 += t11[j]
            a12 += t12[j]
            a13 += t13[j]
            a14 += t14[j]
            a15 += t15[j]
            a22 += t22[j]
            a23 += t23[j]
            a24 += t24[j]
            a25 += t25[j]
            a33 += t33[j]
            a34 += t34[j]
            a35 += t35[j]
            a44 += t44[j]
            a45 += t45[j]
            a55 += t55[j]
            b0 += tb0[j]
            b1 += tb1[j]
            b2 += tb2[j]
            b3 += tb3[j]
            b4 += tb4[j]
            b5 += tb5[j]
    p = part[blk]
    p[0], p[1], p[2], p[3], p[4], p[5] = a00, a01, a02, a03, a04, a05
    p[6], p[7], p[8], p[9], p[10] = a11, a12, a13, a14, a15
    p[11], p[12], p[13], p[14] = a22, a23, a24, a25
    p[15], p[16], p[17] = a33, a34, a35
    p[18], p[19], p[20] = a44, a45, a55
    p[21], p[22], p[23], p[24], p[25], p[26] = b0, b1, b2, b3, b4, b5


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
    for blk in numba.prange(nb):  # prange's index is unsigned: one compiled block function for both loops
        _warp_block(np.int64(blk), buf, part)
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
    W2 = np.zeros((3, 3))  # W·W by plain loops: numba's ``@`` calls BLAS and costs 1.3 s of compilation
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += W[i, k] * W[k, j]
            W2[i, j] = acc
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
