"""Bundle adjustment of a short window: the poses of its frames and the inverse depths of the first frame's
corners, by Levenberg–Marquardt with the inverse depths eliminated (a Schur complement), under a Huber loss.

Each corner j is a ray of the first camera, f_j = K⁻¹·(u, v, 1), at inverse depth ρ_j; frame i's pose is
T_i = (R_i, t_i), first camera → camera i. In camera i the point is seen at π(K·(R_i·f_j + ρ_j·t_i)) — the
homogeneous form is exact for any depth, far points included. The residual is that minus the tracked corner,
in pixels, under a Huber loss. The first camera is fixed.

The solver (``solver="schur"``, the default) takes Levenberg–Marquardt steps on the normal equations, iteratively
reweighted for the Huber loss: each corner has one unknown, so the inverse depths are eliminated and the reduced
system is 6k × 6k for k frames. Each step updates every pose by (υ, ω), T_i ← (exp(ω)·R_i, exp(ω)·t_i + υ), and
the inverse depths directly. The scale of the window is left to the damping during the iterations and fixed
exactly afterwards: the mean inverse depth of the kept corners is 1 (the depth map's own normalisation), a change of
gauge that leaves every residual as it is. Corners whose largest reprojection error stays above ``outlier_px``
are dropped and the window is adjusted again without them.

``solver="scipy"`` is the reference the tests hold the default to: ``scipy.optimize.least_squares`` (trust region,
analytic sparse Jacobian) on the same residuals and loss, with a stiff residual that holds the mean inverse depth
at 1, re-linearised a few times around the poses of the previous call (about 10× slower).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dmtrack.geometry import exact
from dmtrack.geometry.scipy_rotation import matrix_from_rotvec
from dmtrack.initialization.twoview import bearings

__all__ = ["BundleResult", "bundle_adjust"]

SCALE_WEIGHT = 100.0
"""Weight of the residual mean(ρ) − 1 of the scipy reference (pixels per unit of inverse depth): stiff, it only
fixes the gauge."""


@dataclass(frozen=True)
class BundleResult:
    """The adjusted window.

    Attributes
    ----------
    poses : (k, 4, 4) float64
        T_i (first camera → frame i) of the window's frames, in the order given.
    idepth : (n,) float64
        Inverse depths of the corners in the first camera (mean over the kept ones: 1).
    kept : (n,) bool
        Corners kept (reprojection error below ``outlier_px`` everywhere, in front of the camera).
    error_px : (n,) float64
        Largest reprojection error of each corner over the window's frames, pixels.
    median_error_px : float
        Median over the kept corners' observations of the reprojection error, pixels.
    """

    poses: np.ndarray
    idepth: np.ndarray
    kept: np.ndarray
    error_px: np.ndarray
    median_error_px: float


def bundle_adjust(
    K: np.ndarray,
    first: np.ndarray,
    observations: list[np.ndarray],
    poses: np.ndarray,
    idepth: np.ndarray,
    *,
    huber_px: float = 1.0,
    outlier_px: float = 2.0,
    rounds: int = 4,
    max_nfev: int = 100,
    solver: str = "schur",
) -> BundleResult:
    """Adjust a window.

    Parameters
    ----------
    K : (3, 3)
        Pinhole intrinsics.
    first : (n, 2)
        The corners in the first frame, pixels.
    observations : list of (n, 2)
        The corners in each of the window's other frames (NaN where the track had ended).
    poses : (k, 4, 4)
        Initial T_i of those frames.
    idepth : (n,)
        Initial inverse depths (positive, finite).
    huber_px, outlier_px : float
        Huber threshold and outlier threshold of the reprojection error, pixels.
    rounds, max_nfev : int
        Re-linearisations, and function evaluations per ``least_squares`` call (``solver="scipy"`` only).
    solver : str
        ``"schur"`` (default): Levenberg–Marquardt on the normal equations with the points eliminated (each has
        one unknown, so the reduced system is 6k × 6k), iteratively reweighted for the Huber loss. ``"scipy"``:
        ``scipy.optimize.least_squares`` (trust region, sparse Jacobian) on the same residuals and loss — the
        reference the tests hold the fast solver to; about 10× slower.
    """
    if solver not in ("schur", "scipy"):
        raise ValueError(f"solver must be 'schur' or 'scipy', not {solver!r}")
    K = np.asarray(K, np.float64)
    f = bearings(first, K)
    obs = [np.asarray(o, np.float64) for o in observations]
    T = np.array(poses, np.float64, copy=True).reshape(-1, 4, 4)
    rho = np.array(idepth, np.float64, copy=True)
    kept = np.isfinite(rho) & (rho > 0)
    for _ in range(2):  # adjust, drop the outliers, adjust again
        if solver == "schur":
            T, rho = _adjust_schur(K, f, obs, T, rho, kept, huber_px)
        else:
            T, rho = _adjust(K, f, obs, T, rho, kept, huber_px, rounds, max_nfev)
        err, _ = _errors(K, f, obs, T, rho, kept)
        now = kept & (err < outlier_px) & (rho > 0)
        if np.array_equal(now, kept):
            break
        kept = now
    err, per_obs = _errors(K, f, obs, T, rho, kept)
    if kept.any():  # the exact gauge, mean 1 over the kept corners: ρ/s and s·t see the same images
        s = float(np.mean(rho[kept]))
        rho = rho / s
        T = T.copy()
        T[:, :3, 3] *= s
    med = float(np.median(per_obs)) if per_obs.size else float("inf")
    return BundleResult(poses=T, idepth=rho, kept=kept, error_px=err, median_error_px=med)


def _observation_index(obs: list[np.ndarray], kept: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frame, corner) of every usable observation, and the observed pixels."""
    fi, pj = [], []
    for i, o in enumerate(obs):
        j = np.flatnonzero(kept & np.isfinite(o[:, 0]))
        fi.append(np.full(len(j), i))
        pj.append(j)
    I = np.concatenate(fi) if fi else np.zeros(0, int)
    J = np.concatenate(pj) if pj else np.zeros(0, int)
    U = np.concatenate([obs[i][pj[i]] for i in range(len(obs))]) if obs else np.zeros((0, 2))
    return I, J, U


def _project(K: np.ndarray, R: np.ndarray, t: np.ndarray, f: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """Homogeneous camera coordinates ρ·X_i = R·f + ρ·t of each observation (rows match)."""
    return np.einsum("mab,mb->ma", R, f) + rho[:, None] * t


def _adjust(
    K: np.ndarray,
    f: np.ndarray,
    obs: list[np.ndarray],
    T: np.ndarray,
    rho: np.ndarray,
    kept: np.ndarray,
    huber_px: float,
    rounds: int,
    max_nfev: int,
) -> tuple[np.ndarray, np.ndarray]:
    from scipy.optimize import least_squares  # the reference solver: scipy only when asked for
    from scipy.sparse import csr_matrix
    from scipy.spatial.transform import Rotation

    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    k = len(T)
    I, J, U = _observation_index(obs, kept)
    m, n = len(I), len(rho)
    if m == 0:
        return T, rho
    cols_rho = 6 * k + J
    kept_idx = np.flatnonzero(kept)
    rows2 = np.arange(m)

    def pose_of(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = x[: 6 * k].reshape(k, 6)
        dR = Rotation.from_rotvec(d[:, 3:]).as_matrix()
        R = np.einsum("kab,kbc->kac", dR, T[:, :3, :3])
        t = np.einsum("kab,kb->ka", dR, T[:, :3, 3]) + d[:, :3]
        return R, t

    def fun(x: np.ndarray) -> np.ndarray:
        R, t = pose_of(x)
        r = x[6 * k :]
        Y = _project(K, R[I], t[I], f[J], r[J])
        res = np.empty(2 * m + 1)
        res[0 : 2 * m : 2] = fx * Y[:, 0] / Y[:, 2] + cx - U[:, 0]
        res[1 : 2 * m : 2] = fy * Y[:, 1] / Y[:, 2] + cy - U[:, 1]
        res[2 * m] = SCALE_WEIGHT * (np.mean(r[kept_idx]) - 1.0)
        return res

    def jac(x: np.ndarray) -> csr_matrix:
        R, t = pose_of(x)
        r = x[6 * k :]
        Y = _project(K, R[I], t[I], f[J], r[J])
        iz = 1.0 / Y[:, 2]
        zeros = np.zeros(m)
        rows, cols, vals = [], [], []
        for a, d in enumerate(
            (
                np.stack([fx * iz, zeros, -fx * Y[:, 0] * iz * iz], 1),
                np.stack([zeros, fy * iz, -fy * Y[:, 1] * iz * iz], 1),
            )
        ):
            rr = 2 * rows2 + a
            dv = d * r[J, None]  # ∂Y/∂υ = ρ·I
            dw = np.cross(Y, d)  # d·(ω × Y) = ω·(Y × d)
            for c in range(3):
                rows += [rr, rr]
                cols += [6 * I + c, 6 * I + 3 + c]
                vals += [dv[:, c], dw[:, c]]
            rows.append(rr)
            cols.append(cols_rho)
            vals.append(np.einsum("ma,ma->m", d, t[I]))  # ∂Y/∂ρ = t
        rows.append(np.full(len(kept_idx), 2 * m))
        cols.append(6 * k + kept_idx)
        vals.append(np.full(len(kept_idx), SCALE_WEIGHT / len(kept_idx)))
        return csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * m + 1, 6 * k + n)
        )

    for _ in range(rounds):
        x0 = np.concatenate([np.zeros(6 * k), rho])
        sol = least_squares(
            fun, x0, jac=jac, loss="huber", f_scale=huber_px, method="trf", x_scale="jac",
            tr_solver="lsmr", max_nfev=max_nfev,
        )  # fmt: skip
        R, t = pose_of(sol.x)
        T = T.copy()
        T[:, :3, :3] = R
        T[:, :3, 3] = t
        rho = sol.x[6 * k :].copy()
        if sol.status > 0 and sol.nfev <= 2:  # nothing left to move
            break
    return T, rho


def _adjust_schur(
    K: np.ndarray,
    f: np.ndarray,
    obs: list[np.ndarray],
    T: np.ndarray,
    rho: np.ndarray,
    kept: np.ndarray,
    huber_px: float,
    max_iterations: int = 30,
) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg–Marquardt with the inverse depths eliminated (Schur complement), Huber by reweighting.

    The scale is left to the damping during the iterations and fixed exactly afterwards (mean ρ = 1), a gauge
    change that leaves every residual as it is."""
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    k = len(T)
    I, J, U = _observation_index(obs, kept)
    m, n = len(I), len(rho)
    if m == 0:
        return T, rho
    T = T.copy()
    rho = rho.copy()
    by_frame = [np.flatnonzero(I == i) for i in range(k)]

    def residuals(T: np.ndarray, rho: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Y = _project(K, T[I, :3, :3], T[I, :3, 3], f[J], rho[J])
        r = np.stack([fx * Y[:, 0] / Y[:, 2] + cx - U[:, 0], fy * Y[:, 1] / Y[:, 2] + cy - U[:, 1]], 1)
        return r, Y

    def cost(r: np.ndarray) -> float:  # Huber, as least_squares' loss="huber" with f_scale = huber_px
        a = np.abs(r)
        q = np.where(a <= huber_px, 0.5 * a * a, huber_px * a - 0.5 * huber_px * huber_px)
        return float(np.sum(q))

    r, Y = residuals(T, rho)
    if not np.all(np.isfinite(r)):
        return T, rho
    c = cost(r)
    lam = 1e-4
    for _ in range(max_iterations):
        a = np.abs(r)
        w = np.where(a <= huber_px, 1.0, huber_px / np.maximum(a, 1e-300))  # (m, 2) IRLS weights
        iz = 1.0 / Y[:, 2]
        du = np.stack([fx * iz, np.zeros(m), -fx * Y[:, 0] * iz * iz], 1)
        dv = np.stack([np.zeros(m), fy * iz, -fy * Y[:, 1] * iz * iz], 1)
        t_obs = T[I, :3, 3]
        Jc = np.empty((m, 2, 6))
        Jp = np.empty((m, 2))
        for a_, d in enumerate((du, dv)):
            Jc[:, a_, :3] = d * rho[J, None]
            Jc[:, a_, 3:] = np.cross(Y, d)
            Jp[:, a_] = np.einsum("ma,ma->m", d, t_obs)
        WJc = Jc * w[:, :, None]
        Hcc_obs = np.einsum("mai,maj->mij", WJc, Jc)  # (m, 6, 6)
        hcp = np.einsum("mai,ma->mi", WJc, Jp)  # (m, 6)
        hpp_obs = np.einsum("ma,ma->m", w * Jp, Jp)
        bc_obs = -np.einsum("mai,ma->mi", WJc, r)
        bp_obs = -np.einsum("ma,ma->m", w * Jp, r)
        Hbig = np.zeros((6 * k, 6 * k))  # block diagonal: an observation involves one frame
        bc = np.zeros(6 * k)
        for i, rows in enumerate(by_frame):
            Hbig[6 * i : 6 * i + 6, 6 * i : 6 * i + 6] = Hcc_obs[rows].sum(axis=0)
            bc[6 * i : 6 * i + 6] = bc_obs[rows].sum(axis=0)
        Hpp = np.bincount(J, hpp_obs, minlength=n)
        bp = np.bincount(J, bp_obs, minlength=n)
        Hcp = np.zeros((n, k, 6))
        Hcp[J, I] = hcp  # one observation per (corner, frame)
        Hcp = Hcp.reshape(n, 6 * k)
        improved = False
        for _try in range(10):
            Hpp_d = Hpp * (1.0 + lam) + 1e-12
            # einsum, not BLAS: its sums go in one order whatever the BLAS thread count (the same bits anywhere)
            W = Hcp / Hpp_d[:, None]
            S = Hbig + lam * np.diag(np.diag(Hbig)) - np.einsum("na,nb->ab", W, Hcp)
            g = bc - np.einsum("na,n->a", W, bp)
            try:
                dc = exact.solve(S + 1e-12 * np.eye(6 * k), g)  # not LAPACK: the same bits on every CPU
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            dp = (bp - np.einsum("na,a->n", Hcp, dc)) / Hpp_d
            d = dc.reshape(k, 6)
            dR = matrix_from_rotvec(d[:, 3:])  # scipy's Rotation.from_rotvec, bit for bit
            Tn = T.copy()
            Tn[:, :3, :3] = np.einsum("kab,kbc->kac", dR, T[:, :3, :3])
            Tn[:, :3, 3] = np.einsum("kab,kb->ka", dR, T[:, :3, 3]) + d[:, :3]
            rn = rho + dp
            r_new, Y_new = residuals(Tn, rn)
            c_new = cost(r_new) if np.all(np.isfinite(r_new)) and np.all(Y_new[:, 2] > 0) else np.inf
            if c_new < c:
                step = float(np.max(np.abs(dc))) + float(np.max(np.abs(dp)) if n else 0.0)
                T, rho, r, Y = Tn, rn, r_new, Y_new
                converged = c - c_new < 1e-6 * c or step < 1e-10
                c = c_new
                lam = max(lam / 3.0, 1e-9)
                improved = True
                break
            lam *= 4.0
        if not improved or converged:
            break
    return T, rho


def _errors(
    K: np.ndarray, f: np.ndarray, obs: list[np.ndarray], T: np.ndarray, rho: np.ndarray, kept: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Largest reprojection error of every corner (over all its observations, inf if behind a camera) and the
    errors of the kept corners' observations."""
    every = np.ones(len(rho), bool)
    I, J, U = _observation_index(obs, every)
    Y = _project(K, T[I, :3, :3], T[I, :3, 3], f[J], rho[J])
    with np.errstate(divide="ignore", invalid="ignore"):
        uv = np.stack([K[0, 0] * Y[:, 0] / Y[:, 2] + K[0, 2], K[1, 1] * Y[:, 1] / Y[:, 2] + K[1, 2]], 1)
        e = np.linalg.norm(uv - U, axis=1)
    e[~(Y[:, 2] > 0) | ~np.isfinite(e)] = np.inf
    err = np.zeros(len(rho))
    np.maximum.at(err, J, e)
    return err, e[kept[J]]
