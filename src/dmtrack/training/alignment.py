"""The tracker's objective for one pyramid level, re-implemented in PyTorch (differentiable).

This is :mod:`dmtrack.odometry.tracker`'s residual evaluation and Levenberg–Marquardt step (lsd-slam-spec.md §2,
generalised to N channels, docs/multichannel-cost.md) written with torch tensors, so that a loss on the pose after
a few unrolled steps can be back-propagated into the feature maps (and the network that made them). Per reference
point p (keyframe camera coordinates, inverse depth d = 1/p_z, inverse-depth variance σ_d²) at pose T = T_fk:

* p' = R p + t = (x, y, z), (u, v) = (fx x/z + cx, fy y/z + cy); the point is used when 1 < u < w−2 and
  1 < v < h−2 (the tracker's test, strict);
* F_c, g_c = (∂F_c/∂x, ∂F_c/∂y): bilinear samples at (u, v) of the feature map and of its halved central
  differences (zero on the one-pixel border, :func:`feature_gradients`) — the tracker's (F, gx, gy);
* r_c = F_ref,c − F_c (N > 1; Gray-A's affine a, b are taken as 1, 0 — no affine estimation here);
* weight per channel w_p = 1/(σ_n² + var_weight·σ_d²·(ĝ_c·(g0, g1))²) with ĝ_c = (fx g_c,x, fy g_c,y) and
  (g0, g1) = ∂(u, v)/∂d the derivative of the projection w.r.t. the point's inverse depth (÷ (fx, fy));
  Huber on e = |r_c|√w_p with threshold huber_d/2: W = w_p if e < huber_d/2 else w_p·(huber_d/2)/e;
* Jacobian row of channel c w.r.t. a left perturbation ξ = (υ, ω) of T (T ← exp(ξ)·T):
  J_c = ĝ_c,x·m_x + ĝ_c,y·m_y with m_x = (1/z, 0, −x/z², −xy/z², 1 + x²/z², −y/z) and
  m_y = (0, 1/z, −y/z², −(1 + y²/z²), xy/z², x/z) — with the tracker's sign (r = F_ref − F(warp), so the
  Gauss–Newton step is +H⁻¹b);
* error E = Σ W r² · ρ / n_in, normal equations H = Σ W J Jᵀ · ρ / n_in, b = Σ W r J · ρ / n_in, with ρ the
  channel rule's residual factor (1/N_E for ``"balanced"``, :class:`~dmtrack.odometry.config.ChannelRule`);
* LM step: solve (H with its diagonal × (1 + λ)) δ = b, T ← exp(δ)·T (Sophus' exp, translation first).

What it does not do: the tracker's accept/reject schedule, the Gray-A affine estimation, the per-pixel "was good"
flags. :func:`evaluate` returns, besides the differentiable quantities, the per-point 2×2 sums that the numba kernel
writes into its buffer (``S = Σ_c W ĝ_c ĝ_cᵀ``, ``s = Σ_c W r_c ĝ_c``), the good/bad counts and the point usage,
so that ``tests/training/test_alignment.py`` can compare it with the kernels quantity by quantity.

All functions take and return torch tensors of one dtype (float64 for the agreement tests, float32 for training).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from dmtrack.odometry.config import ChannelRule, TrackerConfig

__all__ = [
    "AlignParams",
    "Evaluation",
    "evaluate",
    "feature_gradients",
    "lm_step",
    "normal_equations",
    "pack",
    "projection_jacobian",
    "se3_exp",
    "solve_damped",
]


@dataclass(frozen=True)
class AlignParams:
    """The scalar parameters of one level's objective.

    Attributes
    ----------
    fx, fy, cx, cy : float
        Intrinsics of the level (``camera.level(l)``).
    var_weight, noise2, huber_half : float
        ``TrackerConfig.var_weight``, ``camera_pixel_noise2``, ``huber_d / 2``.
    good_c, good_g : float
        Good/bad test constants: Σ_c r_c² < good_c + good_g·Σ_c |g_c|² (``good_c`` = rule.good · 40²).
    residual_factor : float
        The channel rule's factor ρ of the error and the normal equations (1/N_E for ``"balanced"``).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    var_weight: float = 1.0
    noise2: float = 16.0
    huber_half: float = 1.5
    good_c: float = 1600.0
    good_g: float = 0.25
    residual_factor: float = 1.0

    @classmethod
    def of(
        cls,
        camera: object,
        config: TrackerConfig | None = None,
        n_channels: int = 1,
        channel_cost: str = "balanced",
        energy_channels: float | None = None,
    ) -> AlignParams:
        """The parameters the tracker uses for a level with intrinsics ``camera`` (fx, fy, cx, cy attributes)."""
        cfg = config if config is not None else TrackerConfig()
        rule = ChannelRule.of(channel_cost, n_channels, None, energy_channels)
        return cls(
            fx=float(camera.fx),  # type: ignore[attr-defined]
            fy=float(camera.fy),  # type: ignore[attr-defined]
            cx=float(camera.cx),  # type: ignore[attr-defined]
            cy=float(camera.cy),  # type: ignore[attr-defined]
            var_weight=float(cfg.var_weight),
            noise2=float(cfg.camera_pixel_noise2),
            huber_half=float(cfg.huber_d) / 2.0,
            good_c=float(rule.good) * float(cfg.good_residual) ** 2,
            good_g=float(cfg.good_grad_weight) ** 2,
            residual_factor=float(rule.residual),
        )


@dataclass
class Evaluation:
    """One residual evaluation (see the module documentation).

    Attributes
    ----------
    inside : torch.Tensor
        (n,) bool: the point projects into 1 < u < w−2, 1 < v < h−2.
    n_in : int
        Number of in-image points m.
    warped : torch.Tensor
        (m, 3) p' of the in-image points.
    residuals, weights : torch.Tensor
        (m, N) r_c and W_c (Huber × variance weight).
    jacobians : torch.Tensor
        (m, N, 6) J_c.
    grad : torch.Tensor
        (m, N, 2) ĝ_c = (fx g_x, fy g_y).
    error : torch.Tensor
        Scalar E = ρ·Σ W r² / m (inf when m = 0).
    good, bad : int
        Good/bad counts of the in-image points.
    usage : float
        Σ min(1, z_ref/z') over the in-image points.
    """

    inside: torch.Tensor
    n_in: int
    warped: torch.Tensor
    residuals: torch.Tensor
    weights: torch.Tensor
    jacobians: torch.Tensor
    grad: torch.Tensor
    error: torch.Tensor
    good: int
    bad: int
    usage: float
    residual_factor: float

    def point_sums(self) -> torch.Tensor:
        """(m, 8) rows (x', y', z', Sxx, Sxy, Syy, sx, sy) as the numba kernel's buffer for in-image points."""
        W, r, g = self.weights, self.residuals, self.grad
        gx, gy = g[..., 0], g[..., 1]
        cols = [
            (W * gx * gx).sum(1),
            (W * gx * gy).sum(1),
            (W * gy * gy).sum(1),
            (W * r * gx).sum(1),
            (W * r * gy).sum(1),
        ]
        return torch.cat([self.warped, torch.stack(cols, 1)], 1)


def feature_gradients(feat: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Halved central differences of an (h, w, N) map, zero on the one-pixel border (as ``odometry.frame``)."""
    gx = torch.zeros_like(feat)
    gy = torch.zeros_like(feat)
    gx[1:-1, 1:-1] = 0.5 * (feat[1:-1, 2:] - feat[1:-1, :-2])
    gy[1:-1, 1:-1] = 0.5 * (feat[2:, 1:-1] - feat[:-2, 1:-1])
    return gx, gy


def pack(feat: torch.Tensor) -> torch.Tensor:
    """(h·w, 3N) rows (F, gx, gy) of an (h, w, N) map: what :func:`evaluate` samples (as the tracker's ``packed``)."""
    h, w, nch = feat.shape
    gx, gy = feature_gradients(feat)
    return torch.cat([feat, gx, gy], -1).reshape(h * w, 3 * nch)


def projection_jacobian(warped: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(m_x, m_y), each (m, 6): ∂(x/z, y/z)/∂ξ of p' = (x, y, z) under a left perturbation ξ = (υ, ω)."""
    x, y, z = warped[:, 0], warped[:, 1], warped[:, 2]
    iz = 1.0 / z
    xz, yz = x * iz, y * iz
    zero = torch.zeros_like(x)
    mx = torch.stack([iz, zero, -xz * iz, -xz * yz, 1.0 + xz * xz, -yz], 1)
    my = torch.stack([zero, iz, -yz * iz, -(1.0 + yz * yz), xz * yz, xz], 1)
    return mx, my


def _bilinear(flat: torch.Tensor, w: int, ix: torch.Tensor, iy: torch.Tensor, w00, w01, w10, w11) -> torch.Tensor:
    """Bilinear sample of an (h·w, N) map at integer corners (ix, iy) with the tracker's corner weights."""
    i00 = iy * w + ix
    return (
        w11[:, None] * flat[i00 + w + 1]
        + w01[:, None] * flat[i00 + w]
        + w10[:, None] * flat[i00 + 1]
        + w00[:, None] * flat[i00]
    )


def evaluate(
    points: torch.Tensor,
    ref_values: torch.Tensor,
    variances: torch.Tensor,
    feat: torch.Tensor,
    T: torch.Tensor,
    prm: AlignParams,
    packed: torch.Tensor | None = None,
) -> Evaluation:
    """Evaluate the level's objective at pose ``T`` (keyframe → frame, 4×4).

    Parameters
    ----------
    points : torch.Tensor
        (n, 3) reference points in keyframe coordinates ((1/d)·K⁻¹(x, y, 1), ``ReferenceLevel.points``).
    ref_values : torch.Tensor
        (n, N) keyframe feature values at the points' pixels.
    variances : torch.Tensor
        (n,) inverse-depth variances.
    feat : torch.Tensor
        (h, w, N) frame feature map of the level.
    T : torch.Tensor
        (4, 4) pose T_fk.
    prm : AlignParams
        The level's parameters.
    packed : torch.Tensor, optional
        :func:`pack` of ``feat``, when already computed (it is the same for every evaluation on a level).

    Returns
    -------
    Evaluation
    """
    h, w, nch = feat.shape
    if packed is None:
        packed = pack(feat)
    R, t = T[:3, :3], T[:3, 3]
    X = points @ R.T + t
    with torch.no_grad():
        z_ok = X[:, 2] != 0
        zs = torch.where(z_ok, X[:, 2], torch.ones_like(X[:, 2]))
        u0 = (X[:, 0] / zs) * prm.fx + prm.cx
        v0 = (X[:, 1] / zs) * prm.fy + prm.cy
        inside = z_ok & (u0 > 1.0) & (v0 > 1.0) & (u0 < w - 2.0) & (v0 < h - 2.0)
    Xi = X[inside]
    P = points[inside]
    iz = 1.0 / Xi[:, 2]
    u = (Xi[:, 0] * iz) * prm.fx + prm.cx
    v = (Xi[:, 1] * iz) * prm.fy + prm.cy
    ix = u.detach().floor().long()
    iy = v.detach().floor().long()
    dx = u - ix.to(u.dtype)
    dy = v - iy.to(v.dtype)
    dxdy = dx * dy
    w11, w01, w10, w00 = dxdy, dy - dxdy, dx - dxdy, 1.0 - dx - dy + dxdy
    s = _bilinear(packed, w, ix, iy, w00, w01, w10, w11)
    F, gxs, gys = s[:, :nch], s[:, nch : 2 * nch], s[:, 2 * nch :]
    r = ref_values[inside] - F
    gxf = prm.fx * gxs
    gyf = prm.fy * gys
    # ∂(u/fx, v/fy)/∂d at the point: (t_x z' − t_z x', t_y z' − t_z y') · z_ref / z'²
    zd = P[:, 2] * iz * iz
    g0 = ((t[0] * Xi[:, 2] - t[2] * Xi[:, 0]) * zd)[:, None]
    g1 = ((t[1] * Xi[:, 2] - t[2] * Xi[:, 1]) * zd)[:, None]
    drpdd = gxf * g0 + gyf * g1
    s2 = (prm.var_weight * variances[inside])[:, None]
    wp = 1.0 / (prm.noise2 + s2 * drpdd * drpdd)
    e2 = r * r * wp
    hh = prm.huber_half
    W = torch.where(e2 < hh * hh, wp, wp * hh / torch.sqrt(torch.clamp(e2, min=1e-30)))
    mx, my = projection_jacobian(Xi)
    J = gxf[..., None] * mx[:, None, :] + gyf[..., None] * my[:, None, :]
    m = int(Xi.shape[0])
    err_sum = (W * r * r).sum()
    error = err_sum * prm.residual_factor / m if m > 0 else torch.full((), float("inf"), dtype=feat.dtype)
    with torch.no_grad():
        r2sum = (r * r).sum(1)
        g2sum = (gxs * gxs + gys * gys).sum(1)
        good = int((r2sum < prm.good_c + prm.good_g * g2sum).sum())
        usage = float(torch.clamp(P[:, 2] * iz, max=1.0).sum())
    return Evaluation(
        inside=inside,
        n_in=m,
        warped=Xi,
        residuals=r,
        weights=W,
        jacobians=J,
        grad=torch.stack([gxf, gyf], -1),
        error=error,
        good=good,
        bad=m - good,
        usage=usage,
        residual_factor=prm.residual_factor,
    )


def normal_equations(ev: Evaluation) -> tuple[torch.Tensor, torch.Tensor]:
    """(H, b) = (ρ/m)·(Σ W J Jᵀ, Σ W r J) over points and channels, from the explicit Jacobians."""
    J = ev.jacobians.reshape(-1, 6)
    Wf = ev.weights.reshape(-1)
    rf = ev.residuals.reshape(-1)
    scale = ev.residual_factor / max(ev.n_in, 1)
    H = (J * Wf[:, None]).T @ J * scale
    b = J.T @ (Wf * rf) * scale
    return H, b


def solve_damped(H: torch.Tensor, b: torch.Tensor, lam: float) -> tuple[torch.Tensor, bool]:
    """Solve (H with its diagonal × (1 + λ)) δ = b; (δ, ok), δ zero and ok False when it is singular."""
    M = H + torch.diag(torch.diagonal(H) * lam)
    x, info = torch.linalg.solve_ex(M, b)
    ok = bool(info == 0) and bool(torch.isfinite(x).all())
    return (x if ok else torch.zeros_like(b)), ok


def se3_exp(xi: torch.Tensor) -> torch.Tensor:
    """exp of a twist (υ, ω) as a 4×4 matrix (Sophus; as the tracker's ``se3_exp``); differentiable at 0."""
    v, w = xi[:3], xi[3:]
    th2 = (w * w).sum()
    small = th2 < 1e-10
    th2s = torch.where(small, torch.ones_like(th2), th2)
    th = torch.sqrt(th2s)
    a = torch.where(small, 1.0 - th2 / 6.0, torch.sin(th) / th)
    bb = torch.where(small, 0.5 - th2 / 24.0, (1.0 - torch.cos(th)) / th2s)
    cc = torch.where(small, 1.0 / 6.0 - th2 / 120.0, (th - torch.sin(th)) / (th2s * th))
    zero = torch.zeros_like(w[0])
    Wm = torch.stack(
        [
            torch.stack([zero, -w[2], w[1]]),
            torch.stack([w[2], zero, -w[0]]),
            torch.stack([-w[1], w[0], zero]),
        ]
    )
    W2 = Wm @ Wm
    eye = torch.eye(3, dtype=xi.dtype, device=xi.device)
    R = eye + a * Wm + bb * W2
    V = eye + bb * Wm + cc * W2
    top = torch.cat([R, (V @ v)[:, None]], 1)
    bottom = torch.tensor([[0.0, 0.0, 0.0, 1.0]], dtype=xi.dtype, device=xi.device)
    return torch.cat([top, bottom], 0)


def lm_step(
    points: torch.Tensor,
    ref_values: torch.Tensor,
    variances: torch.Tensor,
    feat: torch.Tensor,
    T: torch.Tensor,
    prm: AlignParams,
    lam: float = 0.0,
    packed: torch.Tensor | None = None,
) -> tuple[torch.Tensor, torch.Tensor, Evaluation, bool]:
    """One damped Gauss–Newton step from ``T``: (T_new = exp(δ)·T, δ, the evaluation at T, solved ok).

    Unlike the tracker the step is always taken (no accept/reject test): this is what training unrolls.
    When the system is singular (or no point is in the image) δ = 0 and T_new = T.
    """
    ev = evaluate(points, ref_values, variances, feat, T, prm, packed)
    if ev.n_in == 0:
        return T, torch.zeros(6, dtype=feat.dtype, device=feat.device), ev, False
    H, b = normal_equations(ev)
    delta, ok = solve_damped(H, b, lam)
    return se3_exp(delta) @ T, delta, ev, ok
