"""Sim(3) direct alignment of one keyframe to another, on N-channel feature maps (LSD-SLAM's ``Sim3Tracker``).

The reference keyframe's points (its :class:`~dmtrack.odometry.tracker.TrackingReference`: inverse depth,
variance and feature values per level) are warped into the other keyframe by ``S = referenceToFrame`` (a
:class:`~dmtrack.geometry.lie.Sim3`, ``p' = s R p + t``) and compared with two residuals per point:

* **photometric**, per channel c: ``r_c = F_ref,c − F_c(π(p'))`` (bilinear), weighted by
  ``w_c = 1 / (σ_I² + var_weight · var_ref · (∂r_c/∂d)²)`` — the odometry's depth-variance weight — and scaled
  by the feature's channel rule (÷ N_E for ``channel_cost="balanced"``, as the SE(3) tracker), so that grey
  (N = 1) is LSD-SLAM's residual;
* **inverse depth**: ``r_d = 1/z' − D(π(p'))`` against the other keyframe's inverse depth at the nearest pixel,
  weighted by ``w_d = 1 / (var_weight · var_D + (∂r_d/∂d)² · var_weight · var_ref)``, where the other keyframe
  has a hypothesis. It is what makes the scale observable: the photometric residual does not depend on it.

Each point gets one Huber weight on ``|r_d|√w_d + √(Σ_c w_c r_c² · rule)`` (LSD-SLAM's ``huber_d``); the 7×7
Gauss–Newton system in the tangent ``(υ, ω, σ)`` is solved with LSD-SLAM's Levenberg–Marquardt schedule (the SE(3)
tracker's settings), coarse to fine, ``S ← exp(δ) S``. Its final Hessian is the constraint's information.

:meth:`Sim3Tracker._terms_numpy` is the clear numpy version of one evaluation, kept as the reference of the numba
kernel (:mod:`dmtrack.slam._sim3_kernel`) that runs by default.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from dmtrack.errors import InputError
from dmtrack.geometry.lie import Sim3
from dmtrack.odometry.config import ChannelRule, TrackerConfig
from dmtrack.odometry.frame import Frame
from dmtrack.odometry.tracker import TrackingReference
from dmtrack.slam._sim3_kernel import sim3_terms_kernel


@dataclass(frozen=True)
class Sim3Result:
    """Outcome of :meth:`Sim3Tracker.track`.

    ``S`` maps reference-keyframe coordinates to the other keyframe's (reference → frame); ``hessian`` is the 7×7
    Gauss–Newton matrix Σ Jᵀ W J of the last level in ``(υ, ω, σ)`` order, not divided by the number of terms
    (LSD-SLAM's ``lastSim3Hessian``: the information of the constraint);
    ``residual`` the mean weighted error of the last level, ``residual_p``/``residual_d`` its photometric and
    depth parts; ``usage`` Σ min(1, z/z')/#points; ``n_depth`` the points with a depth residual.
    """

    S: Sim3
    diverged: bool
    reason: str | None
    hessian: np.ndarray
    residual: float
    residual_p: float
    residual_d: float
    usage: float
    n_in: int
    n_depth: int
    iterations: dict[int, int] = field(default_factory=dict)


@dataclass
class _Terms:
    n_in: int
    error: float
    error_p: float
    error_d: float
    usage: float
    A: np.ndarray
    b: np.ndarray
    n_depth: int


def _bilinear(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n, N) bilinear samples of an (h, w, N) array at float pixel positions (inside the image)."""
    x0 = np.floor(u).astype(np.int64)
    y0 = np.floor(v).astype(np.int64)
    fx = (u - x0)[:, None]
    fy = (v - y0)[:, None]
    a = img[y0, x0]
    b = img[y0, x0 + 1]
    c = img[y0 + 1, x0]
    d = img[y0 + 1, x0 + 1]
    return (1 - fy) * ((1 - fx) * a + fx * b) + fy * ((1 - fx) * c + fx * d)


class Sim3Tracker:
    """Sim(3) alignment of keyframes (see the module docstring).

    Parameters
    ----------
    config : TrackerConfig
        The odometry's tracker settings: LM schedule, ``var_weight``, ``camera_pixel_noise2``, ``huber_d``,
        ``max_its``, ``min_inlier_fraction``.
    channel_cost, energy_channels : as :class:`~dmtrack.odometry.tracker.Tracker` (the photometric sum's scale).
    use_numba : the compiled kernel (default) or the numpy reference.
    """

    def __init__(
        self,
        config: TrackerConfig | None = None,
        channel_cost: str = "balanced",
        energy_channels: float | None = None,
        use_numba: bool = True,
    ) -> None:
        self.config = config if config is not None else TrackerConfig()
        self.channel_cost = channel_cost
        self.energy_channels = energy_channels
        self.use_numba = bool(use_numba)
        self._terms = self._terms_numba if use_numba else self._terms_numpy
        ChannelRule.of(channel_cost, 1)  # validates the name

    def track(
        self,
        reference: TrackingReference,
        frame: Frame,
        frame_idepth: list[tuple[np.ndarray, np.ndarray]],
        S_init: Sim3,
        levels: tuple[int, ...] = (4, 3, 2, 1),
    ) -> Sim3Result:
        """Align ``reference`` to ``frame`` from ``S_init`` (reference → frame), over ``levels`` coarse to fine.

        ``frame_idepth`` is the other keyframe's inverse-depth pyramid ``[(idepth, var), …]`` per level (var ≤ 0:
        no hypothesis), e.g. its own :attr:`TrackingReference.idepth_pyramid`.
        """
        cfg = self.config
        kf = reference.keyframe
        if frame.n_channels != kf.n_channels or (frame.width, frame.height) != (kf.width, kf.height):
            raise InputError(
                f"Sim(3) alignment needs keyframes of the same size and channels: {kf.width}x{kf.height}x"
                f"{kf.n_channels} against {frame.width}x{frame.height}x{frame.n_channels}"
            )
        rule = ChannelRule.of(self.channel_cost, frame.n_channels, None, self.energy_channels, None).residual
        S = S_init
        iterations: dict[int, int] = {}
        terms: _Terms | None = None
        for lvl in levels:
            rl = reference.level(lvl)
            fl = frame.levels[lvl]
            d_l, var_l = frame_idepth[lvl]
            thr = max(cfg.min_inlier_fraction * fl.width * fl.height, 10)
            terms = self._terms(rl, fl, d_l, var_l, S, rule)
            iterations[lvl] = 0
            if terms.n_in < thr:
                return self._diverged(S, terms, iterations, f"level {lvl}: {terms.n_in} points in the image")
            lam = cfg.lambda_initial
            last = terms
            it = 0
            while it < max(cfg.max_its[lvl], 1):
                iterations[lvl] += 1
                inc_try = 0
                while True:
                    n_terms = last.n_in + last.n_depth
                    A = last.A / n_terms
                    A[np.diag_indices(7)] *= 1.0 + lam
                    try:
                        inc = np.linalg.solve(A, -last.b / n_terms)
                    except np.linalg.LinAlgError:
                        return self._diverged(S, last, iterations, f"level {lvl}: singular normal equations")
                    inc_try += 1
                    if not (float(inc @ inc) < 1.0):
                        return self._diverged(S, last, iterations, f"level {lvl}: step {float(inc @ inc):.3g} ≥ 1")
                    S_new = Sim3.exp(inc) @ S
                    trial = self._terms(rl, fl, d_l, var_l, S_new, rule)
                    if trial.n_in < thr:
                        return self._diverged(S, trial, iterations, f"level {lvl}: {trial.n_in} points in the image")
                    if trial.error < last.error:
                        converged = trial.error / last.error > cfg.convergence_eps
                        S, last = S_new, trial
                        lam = 0.0 if lam <= 0.2 else lam * cfg.lambda_success_fac
                        if converged:
                            it = max(cfg.max_its[lvl], 1)
                        break
                    if not (float(inc @ inc) > cfg.step_size_min):
                        it = max(cfg.max_its[lvl], 1)
                        break
                    lam = 0.2 if lam == 0 else lam * cfg.lambda_fail_fac**inc_try
                it += 1
            terms = last
        assert terms is not None
        if not (0.0 < S.scale < 1e6):
            return self._diverged(S, terms, iterations, f"scale {S.scale:g} out of range")
        return Sim3Result(S, False, None, terms.A, terms.error, terms.error_p, terms.error_d, terms.usage,
                          terms.n_in, terms.n_depth, iterations)

    def information(
        self, reference: TrackingReference, frame: Frame, frame_idepth: list[tuple[np.ndarray, np.ndarray]], S: Sim3,
        level: int = 1,
    ) -> np.ndarray:
        """The 7×7 Hessian Σ Jᵀ W J (left perturbation of ``S``) of one evaluation at ``S`` on ``level``."""
        rule = ChannelRule.of(self.channel_cost, frame.n_channels, None, self.energy_channels, None).residual
        d, v = frame_idepth[level]
        return self._terms(reference.level(level), frame.levels[level], d, v, S, rule).A

    @staticmethod
    def _diverged(S: Sim3, t: _Terms, iterations: dict[int, int], why: str) -> Sim3Result:
        return Sim3Result(S, True, f"Sim(3) alignment diverged at {why}", np.zeros((7, 7)), float("inf"),
                          float("inf"), float("inf"), t.usage, t.n_in, t.n_depth, iterations)

    def _terms_numba(self, rl, fl, d_map: np.ndarray, var_map: np.ndarray, S: Sim3, rule: float) -> _Terms:  # noqa: ANN001
        """:meth:`_terms_numpy` by the compiled kernel (the same sums in another order)."""
        cfg = self.config
        cam = fl.camera
        prm = np.array([cam.fx, cam.fy, cam.cx, cam.cy, cfg.var_weight, cfg.camera_pixel_noise2, cfg.huber_d, rule])
        A = np.empty((7, 7))
        b = np.empty(7)
        M = S.scale * np.asarray(S.rotation.matrix())
        n_in, n_d, sum_p, sum_d, usage = sim3_terms_kernel(
            rl.points, rl.values, rl.variances, fl.feat, fl.gx, fl.gy, np.ascontiguousarray(d_map, np.float32),
            np.ascontiguousarray(var_map, np.float32), np.ascontiguousarray(M), np.asarray(S.translation, np.float64),
            prm, A, b,
        )
        if n_in == 0:
            return _Terms(0, float("inf"), float("inf"), float("inf"), 0.0, np.zeros((7, 7)), np.zeros(7), 0)
        return _Terms(n_in, (sum_p + sum_d) / (n_in + n_d), sum_p / n_in, sum_d / max(n_d, 1),
                      usage / max(rl.n_points, 1), A, b, n_d)

    def _terms_numpy(self, rl, fl, d_map: np.ndarray, var_map: np.ndarray, S: Sim3, rule: float) -> _Terms:  # noqa: ANN001
        """Residuals, weights and the 7×7 normal equations of every point at ``S``."""
        cfg = self.config
        cam = fl.camera
        h, w = fl.height, fl.width
        p = rl.points.astype(np.float64)
        M = S.scale * np.asarray(S.rotation.matrix())
        t = np.asarray(S.translation)
        q = p @ M.T + t
        x, y, z = q[:, 0], q[:, 1], q[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = x / z * cam.fx + cam.cx
            v = y / z * cam.fy + cam.cy
        inside = (z > 0) & (u > 1) & (v > 1) & (u < w - 2) & (v < h - 2)
        idx = np.nonzero(inside)[0]
        n_in = int(idx.size)
        if n_in == 0:
            return _Terms(0, float("inf"), float("inf"), float("inf"), 0.0, np.zeros((7, 7)), np.zeros(7), 0)
        p, x, y, z, u, v = p[idx], x[idx], y[idx], z[idx], u[idx], v[idx]
        var_ref = rl.variances[idx].astype(np.float64)
        d_ref = 1.0 / p[:, 2]  # the reference point's inverse depth
        F = _bilinear(fl.feat, u, v)
        gx = _bilinear(fl.gx, u, v) * cam.fx  # ∂F/∂x' per unit of x/z, per channel
        gy = _bilinear(fl.gy, u, v) * cam.fy
        r = rl.values[idx].astype(np.float64) - F  # (n, N)
        # ∂(u, v)/∂d of the reference point's inverse depth (LSD-SLAM's g0, g1; pixel units after × f)
        zz = z * z * d_ref
        g0 = (t[0] * z - t[2] * x) / zz
        g1 = (t[1] * z - t[2] * y) / zz
        g2 = (z - t[2]) / zz  # ∂(1/z')/∂d
        drpdd = gx * g0[:, None] + gy * g1[:, None]
        s_ref = cfg.var_weight * var_ref
        w_p = 1.0 / (cfg.camera_pixel_noise2 + s_ref[:, None] * drpdd * drpdd)  # (n, N)
        # inverse-depth residual at the nearest pixel of the other keyframe's map
        ui = (u + 0.5).astype(np.int64)
        vi = (v + 0.5).astype(np.int64)
        var_d = var_map[vi, ui].astype(np.float64)
        has_d = var_d > 0
        r_d = np.where(has_d, 1.0 / z - d_map[vi, ui], 0.0)
        w_d = np.where(has_d, 1.0 / (cfg.var_weight * np.where(has_d, var_d, 1.0) + g2 * g2 * s_ref), 0.0)
        e_p = np.sqrt(rule * (w_p * r * r).sum(axis=1))
        e_d = np.abs(r_d) * np.sqrt(w_d)
        e = e_p + e_d
        huber = np.where(e < cfg.huber_d, 1.0, cfg.huber_d / np.maximum(e, 1e-30))
        sum_p = float((huber * e_p * e_p).sum())
        sum_d = float((huber * e_d * e_d).sum())
        n_d = int(has_d.sum())
        # Jacobians in (υ, ω, σ) of S ← exp(δ) S: ∂q/∂δ = [I, −[q]×, q]
        iz, iz2 = 1.0 / z, 1.0 / (z * z)
        ju = np.stack([iz, np.zeros_like(z), -x * iz2, -x * y * iz2, 1 + x * x * iz2, -y * iz, np.zeros_like(z)], 1)
        jv = np.stack([np.zeros_like(z), iz, -y * iz2, -(1 + y * y * iz2), x * y * iz2, x * iz, np.zeros_like(z)], 1)
        # photometric: ∂r_c/∂δ = −(gx_c ∂(x/z)/∂δ + gy_c ∂(y/z)/∂δ); none along σ
        J = -(gx[:, :, None] * ju[:, None, :] + gy[:, :, None] * jv[:, None, :])  # (n, N, 7)
        wp = (huber[:, None] * w_p * rule)[:, :, None]
        A = np.einsum("ncj,nck->jk", J * wp, J)
        b = np.einsum("ncj,nc->j", J * wp, r)
        # depth: ∂(1/z')/∂δ = −(1/z'²) ∂z'/∂δ, ∂z'/∂δ = [0, 0, 1, y', −x', 0, z']
        jd = -np.stack([np.zeros_like(z), np.zeros_like(z), iz2, y * iz2, -x * iz2, np.zeros_like(z), iz], 1)
        wd = huber * w_d
        A += np.einsum("nj,nk->jk", jd * wd[:, None], jd)
        b += np.einsum("nj,n->j", jd * wd[:, None], r_d)
        usage = float(np.minimum(1.0, p[:, 2] / z).sum()) / max(rl.n_points, 1)
        n_terms = n_in + n_d
        return _Terms(n_in, (sum_p + sum_d) / n_terms, sum_p / n_in, sum_d / max(n_d, 1), usage, A, b, n_d)
