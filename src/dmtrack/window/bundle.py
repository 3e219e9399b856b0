"""Photometric bundle adjustment over a window of keyframes (N channels), solved by Levenberg–Marquardt with the
point depths eliminated by the Schur complement; the kernels are in :mod:`dmtrack.window._kernels`.

Gauge: the window's oldest keyframe keeps its pose and its points' depths (they carry the monocular scale); every
other keyframe's pose, the inverse depth of every other point and, optionally, the level-0 intrinsics are estimated.
Each point's inverse depth from the depth map is a prior (weight ``depth_prior``/variance, around its value when the
optimisation starts); the intrinsics have the given calibration as their prior (``intrinsics_prior``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dmtrack.geometry.exact import dot, matmul
from dmtrack.odometry.config import WindowConfig
from dmtrack.odometry.records import _inv_se3
from dmtrack.window import _kernels as kern

__all__ = ["BundleReport", "HostPoints", "PhotometricBundle", "WindowKeyframe", "sample_points"]


@dataclass
class HostPoints:
    """A keyframe's sampled points: level-0 pixel position, inverse depth in the keyframe's map units and its
    variance (the depth map's), the current inverse depth in world units, and reference values per level."""

    x0: np.ndarray
    y0: np.ndarray
    d_map: np.ndarray
    var_map: np.ndarray
    d: np.ndarray
    ref: dict[int, np.ndarray] = field(default_factory=dict)

    @property
    def count(self) -> int:
        """Number of points."""
        return int(self.x0.shape[0])

    def at_level(self, level: int) -> tuple[np.ndarray, np.ndarray]:
        """The points' pixel positions at pyramid ``level`` (LSD-SLAM's level cameras: (x + ½)·2⁻ˡ − ½)."""
        f = 0.5**level
        return (self.x0 + 0.5) * f - 0.5, (self.y0 + 0.5) * f - 0.5


@dataclass
class WindowKeyframe:
    """A keyframe in the window: its frame (feature pyramid), world → camera pose T_cw (world units), the scale of
    its depth map's units in world units, and its points (None: a target only)."""

    keyframe_id: int
    frame: Any  # dmtrack.odometry.frame.Frame
    T_cw: np.ndarray
    scale: float
    points: HostPoints | None = None


@dataclass
class BundleReport:
    """What one optimisation did: cost before and after (both at the finest level), accepted iterations, residuals
    used (inliers) and outliers at the end, and the intrinsics with their standard deviations when they were
    estimated."""

    cost_before: float
    cost_after: float
    iterations: int
    inliers: int
    outliers: int
    intrinsics: np.ndarray | None = None
    intrinsics_sigma: np.ndarray | None = None


def sample_points(frame: Any, idepth: np.ndarray, var: np.ndarray, config: WindowConfig) -> HostPoints | None:
    """Up to ``config.points`` points of a finished keyframe: on the sampling level, in each ``cell`` × ``cell``
    cell the valid pixel (positive inverse depth with a variance) of largest gradient, then the strongest cells.

    ``idepth``, ``var``: the level-0 tracking depth (``DepthMap.tracking_depth``). Deterministic (ties by index).
    None when the keyframe has no usable point."""
    from dmtrack.odometry._tracker_points import idepth_downsample

    lv = config.sample_level
    d, v = np.ascontiguousarray(idepth, np.float32), np.ascontiguousarray(var, np.float32)
    for _ in range(lv):
        d, v = idepth_downsample(d, v)
    grad = frame.levels[lv].max_grad
    h, w = d.shape
    ok = (v > 0) & (d > 0) & np.isfinite(d)
    ok[:2, :] = False
    ok[-2:, :] = False
    ok[:, :2] = False
    ok[:, -2:] = False
    ys, xs = np.nonzero(ok)
    if ys.size == 0:
        return None
    score = grad[ys, xs].astype(np.float64)
    c = config.cell
    cell = (ys // c) * ((w + c - 1) // c) + xs // c
    order = np.lexsort((np.arange(ys.size), -score, cell))  # by cell, strongest first, then by index
    _, first = np.unique(cell[order], return_index=True)
    best = order[first]
    best = best[np.lexsort((best, -score[best]))][: config.points]  # strongest cells, ties by index
    best.sort()
    ys, xs = ys[best], xs[best]
    f = float(2**lv)
    x0 = (xs + 0.5) * f - 0.5
    y0 = (ys + 0.5) * f - 0.5
    dm = d[ys, xs].astype(np.float64)
    return HostPoints(x0, y0, dm, v[ys, xs].astype(np.float64), dm.copy())


class MarginalPrior:
    """The Gaussian prior that keyframes which left the window leave on the others' poses: cost 2bᵀδ + δᵀHδ (the
    quadratic model of the photometric cost has this form), δ = log(T_cw T0⁻¹) per keyframe, against the poses T0 at
    which it was linearised."""

    def __init__(self, ids: list[int], T0: list[np.ndarray], H: np.ndarray, b: np.ndarray):
        self.ids, self.T0, self.H, self.b = ids, T0, H, b

    def add(self, kfs: list[WindowKeyframe], poses: list[np.ndarray], pose_cols: Any,
            system: tuple[Any, ...] | None) -> float:  # fmt: skip
        """Add the prior at ``poses`` to ``system`` (its H and b, if given); return its cost."""
        where = {kf.keyframe_id: i for i, kf in enumerate(kfs)}
        idx = [(k, where[kid]) for k, kid in enumerate(self.ids) if kid in where]
        delta = np.zeros(self.b.size)
        for k, i in idx:
            delta[6 * k : 6 * k + 6] = kern.se3_log(matmul(poses[i], _inv_se3(self.T0[k])))
        Hd = matmul(self.H, delta)
        cost = 2.0 * dot(self.b, delta) + dot(delta, Hd)
        if system is not None:
            g = self.b + Hd
            for k, i in idx:
                ci = pose_cols(i)[0]
                system[1][ci : ci + 6] += g[6 * k : 6 * k + 6]
                for m, j in idx:
                    cj = pose_cols(j)[0]
                    system[0][ci : ci + 6, cj : cj + 6] += self.H[6 * k : 6 * k + 6, 6 * m : 6 * m + 6]
        return cost


def _eliminate_first(A: np.ndarray, r: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """The Schur complement of (A, r) over its first ``m`` variables (LDLᵀ; a block that nothing constrains is
    damped by 1e-9 of its trace)."""
    Amm = A[:m, :m].copy()
    eps = 1e-9 * max(float(np.trace(Amm)), 1e-300)
    for k in range(m):
        Amm[k, k] += eps
    Arm = np.ascontiguousarray(A[m:, :m])
    X = np.empty((m, A.shape[0] - m))  # Amm⁻¹ Amr
    for j in range(A.shape[0] - m):
        X[:, j], _ = kern.cholesky_solve(Amm, np.ascontiguousarray(Arm[j]))
    y, _ = kern.cholesky_solve(Amm, np.ascontiguousarray(r[:m]))
    return A[m:, m:] - matmul(Arm, X), r[m:] - matmul(Arm, y)


class PhotometricBundle:
    """Levenberg–Marquardt photometric bundle adjustment of a window (see the module docstring).

    Parameters
    ----------
    config : WindowConfig
        Levels, iterations, robust thresholds, priors, whether the intrinsics are estimated.
    intrinsics : sequence of 4 floats
        The given level-0 (f_x, f_y, c_x, c_y): the intrinsics' prior (and their start).
    size : (width, height)
        Level-0 image size (scales the prior of the principal point).
    residual_factor : float
        The channel rule's factor of Σ_c r_c² (:class:`~dmtrack.odometry.config.ChannelRule`; 1 for grey).
    noise2 : float
        Photometric noise variance σ² in grey levels² (the tracker's ``camera_pixel_noise2``).
    use_numba : bool
        Numba kernels (default) or the numpy reference (tests).
    """

    def __init__(self, config: WindowConfig, intrinsics: Any, size: tuple[int, int], residual_factor: float = 1.0,
                 noise2: float = 16.0, use_numba: bool = True):  # fmt: skip
        self.config = config
        self.prior = np.asarray(intrinsics, np.float64).reshape(4).copy()  # fx, fy, cx, cy
        self.intrinsics = self.prior.copy()
        w, h = size
        p = config.intrinsics_prior
        self.prior_sigma = np.array([p * self.prior[0], p * self.prior[1], p * w, p * h])
        basis = {"f": [[1.0], [self.prior[1] / self.prior[0]], [0.0], [0.0]],
                 "f-c": [[1.0, 0, 0], [self.prior[1] / self.prior[0], 0, 0], [0, 1, 0], [0, 0, 1]],
                 "fxfy-c": np.eye(4)}[config.intrinsics_model]  # fmt: skip
        self.basis = np.asarray(basis, np.float64)  # δK = B δθ
        self.params = np.array([residual_factor, 1.0 / noise2, config.huber, config.outlier,
                                config.gradient_weight**2], np.float64)  # fmt: skip
        self.use_numba = use_numba
        self.marginal: MarginalPrior | None = None  # with leave = "marginalise", once a keyframe has left

    # ------------------------------------------------------------------ layout
    def anchored(self) -> bool:
        """Whether the window's oldest keyframe is held fixed with its points (the gauge): always with
        ``leave = "fixed"``; with ``"marginalise"`` until a keyframe has left and its prior holds the gauge."""
        return self.marginal is None

    def _n_pose(self, n_kf: int) -> int:
        return 6 * (n_kf - 1) if self.anchored() else 6 * n_kf

    def _pose_cols(self, i: int) -> list[int]:
        if self.anchored():
            return list(range(6 * (i - 1), 6 * i)) if i > 0 else [-1] * 6
        return list(range(6 * i, 6 * i + 6))

    def _free_points(self, i: int) -> bool:
        return i > 0 or not self.anchored()

    # ------------------------------------------------------------------ one evaluation
    def _system(self, kfs: list[WindowKeyframe], poses: list[np.ndarray], depths: list[np.ndarray | None],
                K: np.ndarray, level: int, cost_only: bool,
                hosts: set[int] | None = None) -> tuple[Any, ...]:  # fmt: skip
        refine = self.config.refine_intrinsics
        n_pose = self._n_pose(len(kfs))
        n = n_pose + (4 if refine else 0)
        offsets = []
        rows = 0
        for i, kf in enumerate(kfs):
            offsets.append(rows)
            if self._free_points(i) and kf.points is not None:
                rows += kf.points.count
        H, b = np.zeros((n, n)), np.zeros(n)
        hpp, bp, Hcp = np.zeros(rows), np.zeros(rows), np.zeros((rows, n))
        stats = np.zeros(3)
        f = 0.5**level
        fx, fy, cx, cy = K
        cam = np.array([fx * f, fy * f, (cx + 0.5) * f - 0.5, (cy + 0.5) * f - 0.5, f])
        k_cols = [n_pose + k for k in (0, 2, 1, 3)] if refine else [-1] * 4  # local order fx, cx, fy, cy
        fn = kern.pair_normal_equations if self.use_numba else kern.pair_normal_equations_numpy
        for i, host in enumerate(kfs):
            pts = host.points
            if pts is None or pts.count == 0 or (hosts is not None and i not in hosts):
                continue
            ref = pts.ref.get(level)
            xs, ys = pts.at_level(level)
            if ref is None:
                ref = kern.sample_values(host.frame.levels[level].packed, xs, ys)
                pts.ref[level] = ref
            free = self._free_points(i)
            prow = (np.arange(pts.count, dtype=np.int64) + offsets[i]) if free else np.full(pts.count, -1, np.int64)
            T_hw_inv = _inv_se3(poses[i])
            d = depths[i]
            assert d is not None
            for j, target in enumerate(kfs):
                if j == i:
                    continue
                T_th = matmul(poses[j], T_hw_inv)
                cols = np.array(self._pose_cols(i) + self._pose_cols(j) + k_cols, np.int64)
                fn(target.frame.levels[level].packed, xs, ys, d, ref, prow, T_th, cam, cols, self.params,
                   H, b, hpp, bp, Hcp, stats, cost_only)  # fmt: skip
        return H, b, hpp, bp, Hcp, stats, offsets

    def _priors(self, kfs: list[WindowKeyframe], poses: list[np.ndarray], depths: list[np.ndarray | None],
                d_start: list[np.ndarray | None], K: np.ndarray, system: tuple[Any, ...] | None,
                hosts: set[int] | None = None) -> float:  # fmt: skip
        """Add the depth, intrinsics and marginal priors to ``system`` (if given); return their cost. With ``hosts``
        only the depth priors of those keyframes' points."""
        cost = 0.0
        w0 = self.config.depth_prior
        for i, kf in enumerate(kfs):
            if not self._free_points(i) or kf.points is None or w0 <= 0 or (hosts is not None and i not in hosts):
                continue
            d, d0 = depths[i], d_start[i]
            assert d is not None and d0 is not None
            wp = w0 * (kf.scale * kf.scale) / np.maximum(kf.points.var_map, 1e-12)  # 1/var in world units
            r = d - d0
            cost += float(np.sum(wp * r * r))
            if system is not None:
                off = system[6][i]
                system[2][off : off + d.size] += wp
                system[3][off : off + d.size] += wp * r
        if hosts is not None:
            return cost
        n_pose = self._n_pose(len(kfs))
        if self.config.refine_intrinsics:
            iv = 1.0 / (self.prior_sigma * self.prior_sigma)
            r = K - self.prior
            cost += float(np.sum(iv * r * r))
            if system is not None:
                for k in range(4):
                    system[0][n_pose + k, n_pose + k] += iv[k]
                    system[1][n_pose + k] += iv[k] * r[k]
        if self.marginal is not None:
            cost += self.marginal.add(kfs, poses, self._pose_cols, system)
        return cost

    # ------------------------------------------------------------------ the optimisation
    def optimise(self, kfs: list[WindowKeyframe]) -> BundleReport:
        """Optimise the window in place — ``T_cw`` and ``points.d`` of every keyframe but an anchor (see
        :meth:`anchored`), and :attr:`intrinsics` when they are estimated — coarse to fine over ``config.levels``."""
        poses = [np.array(kf.T_cw, np.float64) for kf in kfs]
        depths = [None if kf.points is None else kf.points.d.copy() for kf in kfs]
        d_start = [None if d is None else d.copy() for d in depths]
        K = self.intrinsics.copy()
        first_cost = None
        if len(self.config.levels) > 1:  # the cost before at the finest level, where the cost after is taken: the
            # levels' costs are not comparable (other residuals, other scales; Bit-Planes' coarse cost is lower)
            start = self._system(kfs, poses, depths, K, self.config.levels[-1], True)
            first_cost = float(start[5][kern.S_COST]) + self._priors(kfs, poses, depths, d_start, K, None)
        its = 0
        last = None
        n_pose = self._n_pose(len(kfs))
        for level in self.config.levels:
            lam = 1e-2
            sysm = self._system(kfs, poses, depths, K, level, False)
            cost = float(sysm[5][kern.S_COST]) + self._priors(kfs, poses, depths, d_start, K, sysm)
            if first_cost is None:
                first_cost = cost
            for _ in range(self.config.iterations):
                dc, dp, ok = kern.schur_solve(*self._in_basis(sysm, n_pose), lam)
                if not ok:
                    lam *= 10.0
                    continue
                if self.config.refine_intrinsics:
                    dc = np.concatenate([dc[:n_pose], matmul(self.basis, dc[n_pose:])])
                new_poses, new_depths, new_K = self._step(kfs, poses, depths, K, dc, dp, sysm[6])
                trial = self._system(kfs, new_poses, new_depths, new_K, level, True)
                new_cost = float(trial[5][kern.S_COST]) + self._priors(kfs, new_poses, new_depths, d_start, new_K,
                                                                       None)  # fmt: skip
                if new_cost < cost:
                    converged = cost - new_cost < 1e-4 * abs(cost)
                    poses, depths, K = new_poses, new_depths, new_K
                    lam = max(lam * 0.5, 1e-6)
                    its += 1
                    sysm = self._system(kfs, poses, depths, K, level, False)
                    cost = float(sysm[5][kern.S_COST]) + self._priors(kfs, poses, depths, d_start, K, sysm)
                    if converged:
                        break
                else:
                    lam *= 4.0
            last = (sysm, cost)
        assert last is not None and first_cost is not None
        sysm, cost = last
        for i, (kf, T, d) in enumerate(zip(kfs, poses, depths, strict=True)):
            kf.T_cw = T
            if kf.points is not None and d is not None and self._free_points(i):
                kf.points.d = d
        report = BundleReport(first_cost, cost, its, int(sysm[5][kern.S_IN]), int(sysm[5][kern.S_OUT]))
        if self.config.refine_intrinsics:
            self.intrinsics = K
            report.intrinsics = K.copy()
            report.intrinsics_sigma = self._intrinsics_sigma(sysm, n_pose)
        return report

    def marginalise(self, kfs: list[WindowKeyframe]) -> None:
        """The oldest keyframe ``kfs[0]`` leaves with ``leave = "marginalise"``: the residuals of its points (at the
        finest level, with their depth prior) and the marginal prior so far are linearised at the current estimate,
        its points and its pose eliminated (Schur complement), and what is left becomes the Gaussian prior on the other
        keyframes' poses, each linearised at its pose now and kept there (first-estimate Jacobians for the prior). The
        residuals of other points in the leaving keyframe are dropped, as DSO drops them. The intrinsics are held at
        their estimate."""
        if self.config.leave != "marginalise" or len(kfs) < 2:
            return
        poses = [np.array(kf.T_cw, np.float64) for kf in kfs]
        depths = [None if kf.points is None else kf.points.d.copy() for kf in kfs]
        n_pose = self._n_pose(len(kfs))
        sysm = self._system(kfs, poses, depths, self.intrinsics, self.config.levels[-1], False, hosts={0})
        self._priors(kfs, poses, depths, depths, self.intrinsics, sysm, hosts={0})
        H = np.ascontiguousarray(sysm[0][:n_pose, :n_pose])
        b = sysm[1][:n_pose].copy()
        if self.marginal is not None:
            self.marginal.add(kfs, poses, self._pose_cols, (H, b))
        A, r = kern.schur_reduce(H, b, sysm[2], sysm[3], np.ascontiguousarray(sysm[4][:, :n_pose]))
        if not self.anchored():  # the leaving keyframe's pose: the first six columns
            A, r = _eliminate_first(A, r, 6)
        self.marginal = MarginalPrior([kf.keyframe_id for kf in kfs[1:]], [p.copy() for p in poses[1:]], A, r)

    def _step(self, kfs: list[WindowKeyframe], poses: list[np.ndarray], depths: list[np.ndarray | None],
              K: np.ndarray, dc: np.ndarray, dp: np.ndarray, offsets: list[int]) -> tuple[Any, Any, Any]:  # fmt: skip
        new_poses = []
        new_depths: list[np.ndarray | None] = []
        for i in range(len(kfs)):
            cols = self._pose_cols(i)
            new_poses.append(poses[i] if cols[0] < 0 else kern.se3_left_update(poses[i], dc[cols[0] : cols[0] + 6]))
            d = depths[i]
            if d is None or not self._free_points(i):
                new_depths.append(d)
                continue
            nd = d + dp[offsets[i] : offsets[i] + d.size]
            new_depths.append(np.where(nd > 1e-3 * d, nd, 1e-3 * d))  # an inverse depth stays positive
        new_K = K + dc[self._n_pose(len(kfs)) :] if self.config.refine_intrinsics else K
        return new_poses, new_depths, new_K

    def _in_basis(self, sysm: tuple[Any, ...], n_pose: int) -> tuple[np.ndarray, ...]:
        """(H, b, hpp, bp, Hcp) with the intrinsics' four columns replaced by those of the estimated parameters θ
        (δK = B δθ, :attr:`basis`)."""
        H, b, hpp, bp, Hcp = sysm[:5]
        if not self.config.refine_intrinsics:
            return H, b, hpp, bp, Hcp
        B = self.basis
        nk = B.shape[1]
        T = np.zeros((n_pose + 4, n_pose + nk))
        T[:n_pose, :n_pose] = np.eye(n_pose)
        T[n_pose:, n_pose:] = B
        Ht = matmul(matmul(T.T, H), T)
        return Ht, matmul(T.T, b), hpp, bp, np.ascontiguousarray(matmul(Hcp, T))

    def _intrinsics_sigma(self, sysm: tuple[Any, ...], n_pose: int) -> np.ndarray:
        """Standard deviations of the intrinsics: B Σ_θ Bᵀ, Σ_θ the θ block of the inverse of the Schur-reduced
        system."""
        H, b, hpp, bp, Hcp = self._in_basis(sysm, n_pose)
        n = H.shape[0]
        nk = n - n_pose
        A, _ = kern.schur_reduce(np.ascontiguousarray(H), b, hpp, bp, np.ascontiguousarray(Hcp))
        cov = np.full((nk, nk), np.nan)
        for k in range(nk):
            e = np.zeros(n)
            e[n_pose + k] = 1.0
            x, ok = kern.cholesky_solve(A, e)
            if ok:
                cov[:, k] = x[n_pose:]
        var = np.einsum("ij,jk,ik->i", self.basis, cov, self.basis)
        return np.sqrt(np.where(var > 0, var, np.nan))
