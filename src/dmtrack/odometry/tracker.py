"""SE(3) coarse-to-fine Levenberg–Marquardt tracking of a frame against a keyframe (lsd-slam-spec.md §2).

A faithful port of LSD-SLAM's ``SE3Tracker::trackFrame`` generalised to N-channel feature maps (§4.3):

* levels ``config.levels`` (4 → 1), ``config.max_its[level]`` iterations each (level 4: 0, it only evaluates);
* per evaluation: warp every reference point, keep it if it projects into 1 < u < w−2, 1 < v < h−2,
  bilinear (F_c, ∂F_c) per channel, residual r_c = (a·F_ref,c + b) − F_c, depth-variance weight and Huber per
  channel, error E = Σ W r² / #in-image points, ÷N too unless ``channel_cost="sum"`` (the error, and with it
  ``initialTrackedResidual``, is a per-channel mean; the step itself does not depend on that factor);
* the 6×6 normal equations are accumulated on the fly through per-point 2×2 sums (see
  :mod:`dmtrack.odometry._tracker_residuals` and :mod:`dmtrack.odometry._tracker_normal_equations`);
* LM schedule: accept if E decreases (stop the level when E_new/E_last > ``convergence_eps``; λ ← 0 if
  λ ≤ 0.2 else λ·``lambda_success_fac``); reject: stop when δ·δ ≤ ``step_size_min``, else λ ← 0.2 if λ = 0
  else λ·``lambda_fail_fac``^tries; update T ← exp(δ)·T;
* diverged when fewer than 1 % of the level's pixels have in-image points;
* good/bad counts, point usage and the per-pixel "was good" flags of the finest level come from the last
  evaluation (which, as in LSD-SLAM, may be a rejected trial step);
* Gray-A: affine brightness (a, b) estimated from weighted sums, reset to (1, 0) per frame, adopted after each
  level's first evaluation and after each accepted step.

About Gray-A: LSD-SLAM computes (a', b') as the map from c1 = a·I_ref + b to I_new and then *replaces*
(a, b) by (a', b'), instead of composing them — so the estimate alternates near convergence.
``TrackerConfig.affine_compose=False`` (the default) reproduces that code, which the paper ran;
``affine_compose=True`` composes (a, b) ← (a'·a, a'·b + b'), which converges to the true gain and offset.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np

from dmtrack.errors import InputError
from dmtrack.geometry.exact import dot, matmul
from dmtrack.odometry._depth_common import GOOD_LEVEL
from dmtrack.odometry._tracker_multi import tracker_eval_kernels
from dmtrack.odometry._tracker_normal_equations import (
    se3_exp,
    solve_damped,
    warp_update,
    warp_update_numpy,
    warp_update_parallel,
)
from dmtrack.odometry._tracker_points import idepth_downsample, idepth_downsample_numpy, make_points, make_points_numpy
from dmtrack.odometry._tracker_residuals import (
    BLOCK,
    BUF_COLS,
    P_A,
    P_B,
    eval_params,
    eval_pass_numpy,
)
from dmtrack.odometry.config import ChannelRule, TrackerConfig
from dmtrack.odometry.frame import Frame

_PLACEHOLDERS: dict[int, np.ndarray] = {}


def _placeholder(nch: int) -> np.ndarray:
    """(1, 1, 3, N) stand-in for the packed map: the N > 1 kernel path samples the feature map itself."""
    ph = _PLACEHOLDERS.get(nch)
    if ph is None:
        ph = _PLACEHOLDERS[nch] = np.zeros((1, 1, 3, nch), np.float32)
    return ph


# ============================================================================== tracking reference
@dataclass
class ReferenceLevel:
    """The keyframe's reference point cloud at one pyramid level (lsd-slam-spec.md §1).

    Attributes
    ----------
    level : int
        Pyramid level.
    points : np.ndarray
        (n, 3) float32 points in keyframe camera coordinates, (1/d)·K_l⁻¹(x, y, 1).
    values : np.ndarray
        (n, N) float32 keyframe feature values at those pixels.
    variances : np.ndarray
        (n,) float32 inverse-depth variances.
    pixel_index : np.ndarray
        (n,) int32 flat pixel index y·w_l + x.
    width, height : int
        Size of the level.
    """

    level: int
    points: np.ndarray
    values: np.ndarray
    variances: np.ndarray
    pixel_index: np.ndarray
    width: int
    height: int

    @property
    def n_points(self) -> int:
        """Number of reference points."""
        return int(self.points.shape[0])


class TrackingReference:
    """A keyframe with its inverse-depth pyramid; point clouds per level are built on first use.

    Use :meth:`from_keyframe`.
    """

    def __init__(self, keyframe: Frame, idepth_pyramid: list[tuple[np.ndarray, np.ndarray]], use_numba: bool):
        self.keyframe = keyframe
        self.idepth_pyramid = idepth_pyramid
        self._use_numba = use_numba
        self._levels: dict[int, ReferenceLevel] = {}

    @classmethod
    def from_keyframe(
        cls,
        keyframe: Frame,
        idepth: np.ndarray,
        idepth_var: np.ndarray,
        levels: Iterable[int] = (1, 2, 3, 4),
        use_numba: bool = True,
    ) -> TrackingReference:
        """Build the tracking reference of a keyframe.

        Parameters
        ----------
        keyframe : Frame
            The keyframe (its pyramid provides the feature values).
        idepth, idepth_var : np.ndarray
            (H, W) float32 level-0 inverse depth and its variance (var ≤ 0 marks invalid pixels), as given by
            ``DepthMap.tracking_depth()``.
        levels : iterable of int
            Levels whose point clouds are built now (others are built on demand).
        use_numba : bool
            Use the numba kernels (default) or the numpy references.
        """
        idepth = np.ascontiguousarray(idepth, dtype=np.float32)
        idepth_var = np.ascontiguousarray(idepth_var, dtype=np.float32)
        shape = (keyframe.height, keyframe.width)
        if idepth.shape != shape or idepth_var.shape != shape:
            raise InputError(
                f"inverse depth {idepth.shape} / variance {idepth_var.shape} do not match the keyframe {shape}"
            )
        down = idepth_downsample if use_numba else idepth_downsample_numpy
        pyr = [(idepth, idepth_var)]
        for _ in range(1, len(keyframe.levels)):
            pyr.append(down(*pyr[-1]))
        ref = cls(keyframe, pyr, use_numba)
        for lv in levels:
            ref.level(lv)
        return ref

    def level(self, lvl: int) -> ReferenceLevel:
        """Point cloud of level ``lvl`` (built and cached on first call)."""
        rl = self._levels.get(lvl)
        if rl is None:
            d, v = self.idepth_pyramid[lvl]
            kl = self.keyframe.levels[lvl]
            cam = kl.camera
            mk = make_points if self._use_numba else make_points_numpy
            fx, fy, cx, cy = float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy)
            pts, vals, vrs, idx = mk(d, v, kl.feat, fx, fy, cx, cy)
            rl = ReferenceLevel(lvl, pts, vals, vrs, idx, kl.width, kl.height)
            self._levels[lvl] = rl
        return rl


# ============================================================================== result
@dataclass
class TrackResult:
    """Outcome of :meth:`Tracker.track`.

    Attributes
    ----------
    T_fk : np.ndarray
        (4, 4) float64 keyframe→frame pose (maps keyframe coordinates to frame coordinates). On divergence the
        last accepted estimate.
    diverged : bool
        Too few points projected into the image at some level.
    good : bool
        LSD-SLAM's tracking-quality test: not diverged, good/((w_l)(h_l)) > min_good_per_pixel and
        good/(good+bad) > min_good_ratio at the finest level.
    reason : str | None
        Why tracking diverged or is not good; None when good.
    good_count, bad_count : int
        Good and bad in-image points of the last evaluation at the finest level, as counted by the test that
        decides ``good``: for ``channel_cost="balanced"`` with a measured N_σ ≠ N_E, the constant N_E·40² +
        (N_σ − N_E)·``camera_pixel_noise2`` (the per-pixel flags keep N_E·40²).
    point_usage : float
        Σ min(1, z_ref/z') / #points of the last evaluation.
    last_residual : float
        Error E of the last accepted step (0 if none was accepted on any level, as in LSD-SLAM).
    initial_tracked_residual : float
        last_residual / point_usage (used by mapping).
    ref_pixel_was_good : np.ndarray
        (h_l, w_l) bool flags of the keyframe's pixels at the finest tracked level (normally 1): False where
        the point left the image or was bad in the last evaluation; True for pixels without a point.
    affine : tuple[float, float]
        Final (a, b) brightness parameters ((1, 0) without Gray-A).
    iterations : dict[int, int]
        Normal-equation builds (LM iterations) per level.
    evaluations : dict[int, int]
        Residual evaluations per level.
    final_error : dict[int, float]
        Last accepted error per level.
    """

    T_fk: np.ndarray
    diverged: bool
    good: bool
    reason: str | None
    good_count: int
    bad_count: int
    point_usage: float
    last_residual: float
    initial_tracked_residual: float
    ref_pixel_was_good: np.ndarray
    affine: tuple[float, float]
    iterations: dict[int, int] = field(default_factory=dict)
    evaluations: dict[int, int] = field(default_factory=dict)
    final_error: dict[int, float] = field(default_factory=dict)


@dataclass
class _LevelEval:
    eval_fn: Any
    update_fn: Any
    arrays: tuple[np.ndarray, ...]
    prm: np.ndarray
    affine: bool
    flags: np.ndarray
    write_flags: bool


@dataclass
class _Eval:
    n_in: int
    error: float
    good: int
    bad: int
    usage: float
    a: float
    b: float
    buf: np.ndarray


# ============================================================================== tracker
class Tracker:
    """SE(3) tracker (LSD-SLAM ``SE3Tracker``) for N-channel frames.

    Parameters
    ----------
    config : TrackerConfig
        Parameters (LSD-SLAM defaults).
    use_numba : bool
        Use the numba kernels (default) or the numpy references (slow; for tests).
    parallel : bool
        Distribute the point blocks of the numba kernels over threads (``prange``) on levels with at least
        ``parallel_min_points`` reference points (coarser levels have too few blocks to gain from threads). The
        partial sums are formed per fixed block and combined in order, so results are bit-identical to
        ``parallel=False``, whatever the thread count.
    parallel_min_points : int
        See ``parallel``.
    channel_cost : str
        :attr:`VOConfig.channel_cost <dmtrack.odometry.config.VOConfig.channel_cost>`: ``"sum"`` sums the
        error over channels, ``"mean"`` averages it, ``"balanced"`` divides it by ``energy_channels`` N_E
        (the good/bad test's constant is N·40² for "sum"/"mean", N_E·40² (+ the noise term below) for
        "balanced"; see
        :class:`~dmtrack.odometry.config.ChannelRule`).
    energy_channels : float, optional
        N_E of the feature (``VOConfig.energy_channels``); N when None.
    noise_energy_channels : float, optional
        N_σ of the feature (``VOConfig.noise_energy_channels``): "balanced" adds (N_σ − N_E)·``camera_pixel_noise2``
        to the good/bad test's constant when it decides whether the tracking is good (one more residual count at
        the final pose; the per-pixel ``ref_pixel_was_good`` flags keep N_E·40²); no term when None.
    """

    def __init__(
        self,
        config: TrackerConfig | None = None,
        use_numba: bool = True,
        parallel: bool = False,
        parallel_min_points: int = 4 * BLOCK,
        channel_cost: str = "balanced",
        energy_channels: float | None = None,
        noise_energy_channels: float | None = None,
    ):
        self.config = config if config is not None else TrackerConfig()
        self.channel_cost = channel_cost
        self.energy_channels = energy_channels
        self.noise_energy_channels = noise_energy_channels
        ChannelRule.of(channel_cost, 1)  # validates the name
        self.use_numba = use_numba
        self.parallel = parallel
        self.parallel_min_points = int(parallel_min_points)

    def _kernels(self, n_points: int, n_channels: int) -> tuple[Any, Any]:
        """(evaluation, normal-equation) functions for a level with ``n_points`` points of ``n_channels``."""
        if not self.use_numba:
            return eval_pass_numpy, warp_update_numpy
        serial, threaded = tracker_eval_kernels(n_channels)
        if self.parallel and n_points >= self.parallel_min_points:
            return threaded, warp_update_parallel
        return serial, warp_update

    # ------------------------------------------------------------------ one evaluation
    def _level_eval(
        self, rl: ReferenceLevel, frame_level: Any, flags: np.ndarray, write_flags: bool, good_const: float
    ) -> _LevelEval:
        """The per-level constant part of every evaluation (kernel, arrays, parameters)."""
        cfg = self.config
        cam = frame_level.camera
        prm = eval_params(
            cam.fx,
            cam.fy,
            cam.cx,
            cam.cy,
            1.0,
            0.0,
            cfg.var_weight,
            cfg.camera_pixel_noise2,
            cfg.huber_d / 2.0,
            good_const,
            cfg.good_grad_weight**2,
            cfg.affine_huber,
        )
        nch = rl.values.shape[1]
        packed = frame_level.packed if (nch == 1 or cfg.affine) else _placeholder(nch)
        eval_fn, update_fn = self._kernels(rl.n_points, nch)
        arrays = (rl.points, rl.values, rl.variances, rl.pixel_index, frame_level.feat, packed)
        return _LevelEval(eval_fn, update_fn, arrays, prm, bool(cfg.affine), flags, write_flags)

    def _evaluate(self, lv: _LevelEval, T: np.ndarray, a: float, b: float, buf: np.ndarray, ch_scale: float) -> _Eval:
        cfg = self.config
        prm = lv.prm
        prm[P_A] = a
        prm[P_B] = b
        n_in, err, good, bad, usage, sxx, syy, sx, sy, sw = lv.eval_fn(
            *lv.arrays, T, prm, lv.affine, lv.flags, lv.write_flags, buf
        )
        a_new, b_new = 1.0, 0.0
        if cfg.affine and sw > 0:
            den = sxx - sx * sx / sw
            num = syy - sy * sy / sw
            a_rel = float(np.sqrt(num / den)) if den > 0 and num >= 0 else 1.0
            b_rel = (sy - a_rel * sx) / sw
            if cfg.affine_compose:
                a_new, b_new = a_rel * a, a_rel * b + b_rel
            else:
                a_new, b_new = a_rel, b_rel
        error = err * ch_scale / n_in if n_in > 0 else float("inf")
        return _Eval(int(n_in), float(error), int(good), int(bad), float(usage), a_new, b_new, buf)

    def _solve(self, A: np.ndarray, bvec: np.ndarray, lam: float) -> np.ndarray:
        x, ok = solve_damped(A, bvec, lam)
        return x if ok else np.zeros(6)

    # ------------------------------------------------------------------ public
    def track(self, reference: TrackingReference, frame: Frame, T_fk_init: np.ndarray) -> TrackResult:
        """Track ``frame`` against ``reference`` starting from ``T_fk_init`` (keyframe→frame, 4×4).

        Raises
        ------
        InputError
            If the frame and keyframe differ in size, channel count or pyramid depth, or Gray-A is requested
            for a multichannel feature.
        """
        if not (self.parallel and self.use_numba):
            return self._track(reference, frame, T_fk_init)
        # dynamic scheduling of the point blocks (chunks of one block): a thread that the OS delays does not
        # hold the others up at every one of the many small parallel regions (results do not depend on it)
        with numba.parallel_chunksize(1):
            return self._track(reference, frame, T_fk_init)

    def _track(self, reference: TrackingReference, frame: Frame, T_fk_init: np.ndarray) -> TrackResult:
        cfg = self.config
        kf = reference.keyframe
        if frame.n_channels != kf.n_channels:
            raise InputError(f"frame has {frame.n_channels} channels, keyframe {kf.n_channels}")
        if (frame.width, frame.height) != (kf.width, kf.height):
            raise InputError(f"frame is {frame.width}x{frame.height}, keyframe {kf.width}x{kf.height}")
        if max(cfg.levels) >= len(frame.levels):
            need = max(cfg.levels) + 1
            raise InputError(f"tracking needs {need} pyramid levels, the frame has {len(frame.levels)}")
        if cfg.affine and frame.n_channels != 1:
            raise InputError("affine brightness estimation (Gray-A) needs a 1-channel feature")
        nch = frame.n_channels
        rule = ChannelRule.of(self.channel_cost, nch, None, self.energy_channels, self.noise_energy_channels)
        ch_scale = rule.residual
        # the good/bad test's constant: good·40² for the per-pixel flags (refPixelWasGood); the tracking-quality
        # decision adds the feature's noise beyond a grey-like one (balanced rule, docs/multichannel-cost.md)
        good_const = rule.good * cfg.good_residual**2
        decision_const = good_const + rule.noise_excess * cfg.camera_pixel_noise2 if rule.noise_excess else None

        T = np.array(T_fk_init, dtype=np.float64, copy=True)
        if T.shape != (4, 4):
            raise InputError(f"T_fk_init must be 4x4, got {T.shape}")
        a, b = 1.0, 0.0
        last_residual = 0.0
        min_level = min(cfg.levels)
        fl_min = frame.levels[min_level]
        flags = np.ones(fl_min.height * fl_min.width, dtype=bool)
        iterations: dict[int, int] = {}
        evaluations: dict[int, int] = {}
        final_error: dict[int, float] = {}
        last: _Eval | None = None

        def diverged_result(lvl: int, ev: _Eval, n_points: int, thr: float) -> TrackResult:
            reason = f"diverged at level {lvl}: {ev.n_in} of {n_points} points in the image (< {thr:g})"
            return TrackResult(
                T_fk=T,
                diverged=True,
                good=False,
                reason=reason,
                good_count=ev.good,
                bad_count=ev.bad,
                point_usage=ev.usage / max(n_points, 1),
                last_residual=last_residual,
                initial_tracked_residual=float("inf"),
                ref_pixel_was_good=flags_at_good_level(flags.reshape(fl_min.height, fl_min.width), min_level, frame),
                affine=(a, b),
                iterations=iterations,
                evaluations=evaluations,
                final_error=final_error,
            )

        for lvl in cfg.levels:
            rl = reference.level(lvl)
            fl = frame.levels[lvl]
            write = lvl == min_level
            thr = cfg.min_inlier_fraction * fl.width * fl.height
            bufs = [np.empty((rl.n_points, BUF_COLS)), np.empty((rl.n_points, BUF_COLS))]
            lv = self._level_eval(rl, fl, flags, write, good_const)
            update_fn = lv.update_fn
            cur = 0
            ev = self._evaluate(lv, T, a, b, bufs[cur], ch_scale)
            evaluations[lvl] = 1
            iterations[lvl] = 0
            last = ev
            if ev.n_in < thr:
                return diverged_result(lvl, ev, rl.n_points, thr)
            if cfg.affine:
                a, b = ev.a, ev.b
            last_err = ev.error
            lam = cfg.lambda_initial
            max_its = cfg.max_its[lvl]
            it = 0
            while it < max_its:
                A, bvec = update_fn(bufs[cur])
                A = A / ev.n_in * ch_scale
                bvec = bvec / ev.n_in * ch_scale
                iterations[lvl] += 1
                inc_try = 0
                while True:
                    inc = self._solve(A, bvec, lam)
                    inc_try += 1
                    T_new = matmul(se3_exp(inc), T)
                    trial = self._evaluate(lv, T_new, a, b, bufs[1 - cur], ch_scale)
                    evaluations[lvl] += 1
                    last = trial
                    if trial.n_in < thr:
                        return diverged_result(lvl, trial, rl.n_points, thr)
                    if trial.error < last_err:
                        T = T_new
                        cur = 1 - cur
                        ev = trial
                        if cfg.affine:
                            a, b = trial.a, trial.b
                        if trial.error / last_err > cfg.convergence_eps:
                            it = max_its
                        last_residual = last_err = trial.error
                        lam = 0.0 if lam <= 0.2 else lam * cfg.lambda_success_fac
                        break
                    if not (dot(inc, inc) > cfg.step_size_min):
                        it = max_its
                        break
                    lam = 0.2 if lam == 0 else lam * cfg.lambda_fail_fac**inc_try
                it += 1
            final_error[lvl] = last_err

        assert last is not None
        n_ref = reference.level(min_level).n_points
        usage = last.usage / n_ref if n_ref > 0 else 0.0
        good_count, bad_count = last.good, last.bad
        if decision_const is not None:  # the same residuals at the final pose, counted against the decision's constant
            rl = reference.level(min_level)
            lv = self._level_eval(rl, fl_min, flags, False, decision_const)
            ev = self._evaluate(lv, T, a, b, np.empty((rl.n_points, BUF_COLS)), ch_scale)
            evaluations[min_level] += 1
            good_count, bad_count = ev.good, ev.bad
        n_pix = fl_min.width * fl_min.height
        ok_density = good_count / n_pix > cfg.min_good_per_pixel
        ok_ratio = good_count + bad_count > 0 and good_count / (good_count + bad_count) > cfg.min_good_ratio
        good = ok_density and ok_ratio
        reason = None
        if not good:
            reason = (
                f"tracking not good: {good_count} good / {bad_count} bad points "
                f"(need > {cfg.min_good_per_pixel * n_pix:g} good and > {cfg.min_good_ratio:g} good ratio)"
            )
        itr = last_residual / usage if usage > 0 else float("inf")
        return TrackResult(
            T_fk=T,
            diverged=False,
            good=bool(good),
            reason=reason,
            good_count=int(good_count),
            bad_count=int(bad_count),
            point_usage=float(usage),
            last_residual=float(last_residual),
            initial_tracked_residual=float(itr),
            ref_pixel_was_good=flags_at_good_level(flags.reshape(fl_min.height, fl_min.width), min_level, frame),
            affine=(float(a), float(b)),
            iterations=iterations,
            evaluations=evaluations,
            final_error=final_error,
        )


def flags_at_good_level(flags: np.ndarray, level: int, frame: Frame) -> np.ndarray:
    """The tracker's per-pixel ``refPixelWasGood`` flags of its finest ``level`` on the grid of
    :data:`~dmtrack.odometry._depth_common.GOOD_LEVEL` (LSD-SLAM's ``SE3TRACKING_MIN_LEVEL``, 1), where the depth
    map reads them: unchanged at that level (the default levels end there); tracked down to a finer level (e.g.
    ``tracker.levels`` ending in 0), a pixel there is good when none of the pixels it covers was bad; ending coarser,
    each pixel takes the flag of the coarse pixel it lies in."""
    if level == GOOD_LEVEL:
        return flags
    h, w = frame.levels[GOOD_LEVEL].height, frame.levels[GOOD_LEVEL].width
    if level < GOOD_LEVEL:
        k = 1 << (GOOD_LEVEL - level)
        return flags[: h * k, : w * k].reshape(h, k, w, k).all(axis=(1, 3))
    k = level - GOOD_LEVEL
    ys = np.minimum(np.arange(h) >> k, flags.shape[0] - 1)
    xs = np.minimum(np.arange(w) >> k, flags.shape[1] - 1)
    return flags[ys[:, None], xs[None, :]]
