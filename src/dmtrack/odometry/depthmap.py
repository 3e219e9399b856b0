"""Semi-dense inverse-depth map of a keyframe (LSD-SLAM ``DepthMap``, lsd-slam-spec.md §3, N channels §4).

One :class:`DepthMap` holds a per-pixel hypothesis for every level-0 pixel of its keyframe: ``valid``,
``blacklisted``, ``next_stereo_frame_min_id``, ``validity_counter``, raw ``idepth`` / ``idepth_var`` and the
regularised ``idepth_smoothed`` / ``idepth_var_smoothed``. Life cycle, as in LSD-SLAM's VO mode with
single-threaded mapping:

1. the first keyframe: :meth:`DepthMap.initialize_random` (seeded; the same random field for every feature);
2. every frame tracked on the keyframe: :meth:`DepthMap.update` = observeDepth (line stereo along the epipolar
   line, create / EKF update) → fill holes → regularize(false, 24); the tracker reads
   :meth:`DepthMap.tracking_depth`;
3. a new keyframe: :meth:`DepthMap.create_keyframe` finalises this map (fill holes, regularize), propagates
   it into the new keyframe, runs regularize(true) / fill holes / regularize(false) there and normalises the
   new map's mean inverse depth to 1 (factor ``scale_from_parent``).

N-channel rule (§4, docs/multichannel-cost.md): every SSD-type quantity is the squared L2 norm over channels,
averaged (``channel_cost="balanced"``, the default, and ``"mean"``) or summed (``"sum"``, the paper's literal
cost); with ``"balanced"`` the gradient sums that act as information (the photometric disparity variance and
the epipolar-gradient gate) count κ = ``info_channels`` grey-equivalent channels. The gradient gate uses the
frame's ``max_grad`` (mean over channels of |∇F_c|, then a 3×3 max). All LSD-SLAM thresholds are kept.

Checked against LSD-SLAM itself (``tools/lsd_oracle``: the same pre-state, pose, flags and residual replayed
through both, ``docs/lsd-slam-fidelity.md``): an update agrees with ``DepthMap::updateKeyframe`` and a keyframe
creation with ``createKeyFrame`` up to float rounding. That includes two behaviours of LSD-SLAM's *release*
build that a literal reading of its source misses: a near end of the search segment outside the image
border makes the pixel out of bounds (its move-and-re-test cannot pass), and a best match at an end of the
segment still goes through the sub-pixel tests (the "at end" test is compiled out with the debug statistics).
Remaining differences, all deliberate:

* an update's stereo search interval is bounded by the larger of the pixel's raw and regularised variances
  (``DepthConfig.update_variance="raw-search"``; LSD-SLAM: the regularised one, ``"smoothed"``): measured more
  accurate and far less dependent on the random initialisation (``docs/lsd-slam-fidelity.md``);
* a single reference frame per update (the single-threaded VO case): a hypothesis scheduled for a later
  frame (``nextStereoFrameMinID`` > frame index) is skipped;
* the N-channel generalisations: ``gradAlongLine``, the epipolar-gradient test and the propagation colour
  test sum (or average) over channels; the geometric variance term is τ²·Σ_c|∇F_c|² / Σ_c(∇F_c·ê)²;
* stereo, observe, fill and propagation compute scalars in float64 (state arrays are float32); the
  regularisation computes in float32, as LSD-SLAM. Decisions that sit exactly on a threshold are settled by
  rounding in both (e.g. whether a padded 3-px search segment ends with its 6th step: ≈ 45 % of the padded
  searches in both, not the same pixels), so about 1 % of a frame's observations differ pixel by pixel;
  statistically the two agree.

Typical cost at 640×480 grey (7-Scenes, numba, one core, ``benchmarks/profile_mapping.py``): ≈ 13 ms per
:meth:`DepthMap.update` (observe ≈ 9.5 ms, ≈ 0.23 µs per stereo search, regularize ≈ 2.6 ms, fill holes
≈ 1 ms), ≈ 19 ms per :meth:`DepthMap.create_keyframe`. With ``parallel=True`` observe, fill holes and
regularize split their rows into interleaved sets, one per numba thread, each run by a nogil kernel on a thread of a
small pool (:func:`~dmtrack.odometry._depth_common.run_rows`); on two idle cores observe takes ≈ 0.5–0.7× and
regularize ≈ 0.6× of the one-core time.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from dmtrack.errors import InputError
from dmtrack.odometry._depth_common import (
    COUNT_NAMES,
    GOOD_LEVEL,
    P_REG_DIST_VAR,
    PCOUNT_NAMES,
    empty_state,
    make_params,
    stereo_geometry,
    tracking_select,
)
from dmtrack.odometry._depth_propagate import propagate_numba, propagate_reference
from dmtrack.odometry._depth_regularize import (
    fill_holes_numba,
    fill_holes_reference,
    regularize_numba,
    regularize_reference,
)
from dmtrack.odometry._depth_update import observe_numba, observe_reference
from dmtrack.odometry.config import ChannelRule, DepthConfig

if TYPE_CHECKING:  # pragma: no cover
    from dmtrack.odometry.frame import Frame
    from dmtrack.odometry.initial_map import InitialMap

__all__ = ["DepthMap"]


class DepthMap:
    """Semi-dense inverse-depth map on a keyframe.

    Parameters
    ----------
    config : DepthConfig, optional
        Depth-map constants (LSD-SLAM defaults).
    use_numba : bool
        Use the numba kernels (default) or the plain numpy/python references (slow; small images only).
    parallel : bool
        Run observe, fill holes and regularize over interleaved row sets on numba's thread count of threads
        (:func:`~dmtrack.odometry._depth_common.run_rows`); pixels are independent, so results are identical either
        way.

    Attributes
    ----------
    keyframe : Frame or None
        The keyframe the map lives on.
    valid : (H, W) bool
    blacklisted : (H, W) int32
        Decremented on failed stereo / regularisation; pixels below ``min_blacklist`` are skipped.
    next_stereo_frame_min_id : (H, W) int32
        First frame index at which a hypothesis is observed again (short epipolar lines postpone it).
    validity_counter : (H, W) float32
        Integer-valued validity counter.
    idepth, idepth_var : (H, W) float32
        Raw inverse depth (1/keyframe units) and its variance.
    idepth_smoothed, idepth_var_smoothed : (H, W) float32
        Regularised inverse depth and variance (−1 where never regularised).
    n_updates : int
        Frames mapped into this keyframe (``numMappedOnThis``).
    scale_from_parent : float
        ρ of the mean-inverse-depth normalisation at creation (1 for a randomly initialised map); the
        keyframe's pose relative to its parent is Sim3(T_new_old⁻¹, ρ).
    T_new_old : (4, 4) float64 or None
        Parent keyframe → this keyframe rigid transform used for the propagation (None for the first).
    last_counts : dict[str, int]
        Counters of the last observe / propagation.
    timings_ms : dict[str, float]
        Wall time of the stages of the last :meth:`update` / :meth:`create_keyframe` (milliseconds).
    """

    def __init__(
        self,
        config: DepthConfig | None = None,
        *,
        use_numba: bool = True,
        parallel: bool = False,
        channel_cost: str = "balanced",
        info_channels: float | None = None,
        energy_channels: float | None = None,
    ):
        self.config = config if config is not None else DepthConfig()
        self.use_numba = bool(use_numba)
        self.parallel = bool(parallel)
        ChannelRule.of(channel_cost, 1)  # validates the name
        self.channel_cost = channel_cost
        self.info_channels = info_channels
        self.energy_channels = energy_channels
        self._prm = make_params(self.config)
        self._prm_by_n: dict[int, np.ndarray] = {}
        self.keyframe: Frame | None = None
        self._set_state(empty_state((0, 0)))
        self.n_updates = 0
        self.scale_from_parent = 1.0
        self.T_new_old: np.ndarray | None = None
        self.last_counts: dict[str, int] = {}
        self.timings_ms: dict[str, float] = {}

    # ------------------------------------------------------------------------------------------ state
    @property
    def state(self) -> tuple[np.ndarray, ...]:
        """The eight per-pixel arrays in kernel order (views, not copies)."""
        return (
            self.valid,
            self.blacklisted,
            self.next_stereo_frame_min_id,
            self.validity_counter,
            self.idepth,
            self.idepth_var,
            self.idepth_smoothed,
            self.idepth_var_smoothed,
        )

    def _set_state(self, state: tuple[np.ndarray, ...]) -> None:
        (
            self.valid,
            self.blacklisted,
            self.next_stereo_frame_min_id,
            self.validity_counter,
            self.idepth,
            self.idepth_var,
            self.idepth_smoothed,
            self.idepth_var_smoothed,
        ) = state
        h, w = self.valid.shape
        self._scratch_bool = np.empty((h, w), np.bool_)
        self._scratch_int = np.zeros((h + 1, w + 1), np.float64)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the map."""
        return (int(self.valid.shape[0]), int(self.valid.shape[1]))

    @property
    def n_valid(self) -> int:
        """Number of valid hypotheses."""
        return int(np.count_nonzero(self.valid))

    def copy(self) -> DepthMap:
        """Deep copy of the per-pixel state (the keyframe is shared)."""
        out = self._sibling()
        out.keyframe = self.keyframe
        out._set_state(tuple(a.copy() for a in self.state))
        out.n_updates = self.n_updates
        out.scale_from_parent = self.scale_from_parent
        out.T_new_old = None if self.T_new_old is None else self.T_new_old.copy()
        return out

    def _sibling(self) -> DepthMap:
        """An empty map with the same configuration."""
        return DepthMap(
            self.config,
            use_numba=self.use_numba,
            parallel=self.parallel,
            channel_cost=self.channel_cost,
            info_channels=self.info_channels,
            energy_channels=self.energy_channels,
        )

    def channel_rule(self, frame: Frame) -> ChannelRule:
        """The channel reductions for ``frame``'s channel count (:class:`ChannelRule`)."""
        return ChannelRule.of(self.channel_cost, frame.n_channels, self.info_channels, self.energy_channels)

    def _cscale(self, frame: Frame) -> float:
        """Residual reduction factor of the channel rule: 1 (sum over channels) or 1/N."""
        return self.channel_rule(frame).residual

    def _params(self, frame: Frame) -> np.ndarray:
        """The kernels' parameter vector, with the channel rule's information factor for ``frame``."""
        n = frame.n_channels
        prm = self._prm_by_n.get(n)
        if prm is None:
            prm = self._prm_by_n[n] = make_params(self.config, self.channel_rule(frame).info)
        return prm

    def _require(self) -> Frame:
        if self.keyframe is None:
            raise RuntimeError("depth map has no keyframe; call initialize_random() first")
        return self.keyframe

    # ------------------------------------------------------------------------------------------ init
    def initialize_random(self, keyframe: Frame, seed: int) -> None:
        """Random initialisation (LSD-SLAM ``initializeRandomly``).

        Every pixel in [1, H−1)×[1, W−1) with maxGrad > minUseGrad gets idepth 0.5 + U, U uniform on
        {0, 1e-5, …, 1} (LSD's ``(rand() % 100001) / 100000``), smoothed idepth equal, variance (raw and
        smoothed) ``VAR_RANDOM_INIT_INITIAL`` and validity 20. The random field depends only on ``seed`` and
        the image size, so every feature gets the same values (as in the paper).
        """
        h, w = keyframe.height, keyframe.width
        rng = np.random.default_rng(seed)
        r = rng.integers(0, 100001, size=(h, w)).astype(np.float64) / 100000.0
        mg = keyframe.levels[0].max_grad
        mask = np.zeros((h, w), bool)
        mask[1 : h - 1, 1 : w - 1] = mg[1 : h - 1, 1 : w - 1] > self.config.min_use_grad
        state = empty_state((h, w))
        valid, _bl, _nx, validity, idepth, var, idepth_s, var_s = state
        d = (0.5 + r).astype(np.float32)
        valid[mask] = True
        idepth[mask] = d[mask]
        idepth_s[mask] = d[mask]
        var[mask] = self.config.var_random_init_initial
        var_s[mask] = self.config.var_random_init_initial
        validity[mask] = self.config.random_init_validity
        self.keyframe = keyframe
        self._set_state(state)
        self.n_updates = 0
        self.scale_from_parent = 1.0
        self.T_new_old = None

    def initialize_from_depth(
        self, keyframe: Frame, idepth: np.ndarray, var: float = 1e-4, validity: float = 20.0
    ) -> None:
        """Initialise from a known inverse-depth image (LSD-SLAM ``initializeFromGTDepth``).

        Pixels with finite idepth > 0 become valid with raw = smoothed idepth, variance ``var``
        (``VAR_GT_INIT_INITIAL`` = 0.01² by default) and the given validity; others invalid.

        Parameters
        ----------
        idepth : (H, W) array
            Inverse depth (1/units); NaN or ≤ 0 marks unknown.
        """
        h, w = keyframe.height, keyframe.width
        d = np.asarray(idepth, np.float64)
        if d.shape != (h, w):
            raise InputError(f"idepth has shape {d.shape}, keyframe is {(h, w)}")
        mask = np.isfinite(d) & (d > 0)
        state = empty_state((h, w))
        valid, _bl, _nx, val, dep, v, dep_s, v_s = state
        valid[mask] = True
        dep[mask] = d[mask]
        dep_s[mask] = d[mask]
        v[mask] = var
        v_s[mask] = var
        val[mask] = validity
        self.keyframe = keyframe
        self._set_state(state)
        self.n_updates = 0
        self.scale_from_parent = 1.0
        self.T_new_old = None

    def initialize_from_map(self, keyframe: Frame, initial: InitialMap) -> None:
        """Initialise from a map made outside the odometry (:class:`~dmtrack.odometry.initial_map.InitialMap`).

        Its hypotheses are taken as they are, on the pixels this keyframe can use (maxGrad > minUseGrad, one
        pixel inside the border, as :meth:`initialize_random`); blacklist and scheduling start afresh.
        """
        h, w = keyframe.height, keyframe.width
        if initial.shape != (h, w):
            raise InputError(f"initial map is {initial.shape[1]}x{initial.shape[0]}, keyframe is {w}x{h}")
        mg = keyframe.levels[0].max_grad
        mask = np.zeros((h, w), bool)
        mask[1 : h - 1, 1 : w - 1] = mg[1 : h - 1, 1 : w - 1] > self.config.min_use_grad
        mask &= np.asarray(initial.valid, bool)
        state = empty_state((h, w))
        valid, _bl, _nx, validity, idepth, var, idepth_s, var_s = state
        valid[mask] = True
        for dst, src in (
            (validity, initial.validity),
            (idepth, initial.idepth),
            (var, initial.idepth_var),
            (idepth_s, initial.idepth_smoothed),
            (var_s, initial.idepth_var_smoothed),
        ):
            dst[mask] = np.asarray(src, np.float32)[mask]
        self.keyframe = keyframe
        self._set_state(state)
        self.n_updates = 0
        self.scale_from_parent = 1.0
        self.T_new_old = None

    # ------------------------------------------------------------------------------------------ stages
    def observe(
        self,
        frame: Frame,
        T_fk: np.ndarray,
        ref_pixel_was_good: np.ndarray | None = None,
        initial_tracked_residual: float = 0.0,
    ) -> dict[str, int]:
        """observeDepth: line stereo of every eligible keyframe pixel against ``frame`` (in place).

        Parameters
        ----------
        frame : Frame
            The tracked reference frame (same size and channel count as the keyframe).
        T_fk : (4, 4) array
            Keyframe → frame rigid transform.
        ref_pixel_was_good : (H>>1, W>>1) bool array, optional
            The tracker's per-keyframe-pixel flags at level 1; pixels flagged False are not observed.
        initial_tracked_residual : float
            The tracker's residual per point usage (scales the geometric variance term).

        Returns
        -------
        dict of counters (created, updated, inconsistent, …).
        """
        kf = self._require()
        self._check_frame(frame)
        lv = kf.levels[0]
        cam = lv.camera
        geo = stereo_geometry(
            float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy), T_fk, initial_tracked_residual
        )
        good = self._check_good(ref_pixel_was_good)
        # numFramesTrackedOnThis / (numMappedOnThis + 5) of LSD-SLAM (one tracked frame per mapping)
        skip_ratio = (self.n_updates + 1) / (self.n_updates + 5.0)
        args = (
            self.state,
            lv.feat,
            # N > 1 with numba: the kernel forms each pixel's gradients itself (no (H, W, N) maps kept)
            None if self.use_numba and lv.feat.shape[2] > 1 else lv.gx,
            None if self.use_numba and lv.feat.shape[2] > 1 else lv.gy,
            lv.max_grad,
            frame.levels[0].feat,
            good,
            geo,
            self._params(kf),
            self._cscale(kf),
            int(frame.index),
            skip_ratio,
        )
        if self.use_numba:
            counts = observe_numba(*args, parallel=self.parallel)
        else:
            counts = observe_reference(*args)
        return {name: int(c) for name, c in zip(COUNT_NAMES, counts, strict=True)}

    def regularize(self, remove_occlusions: bool, validity_th: float | None = None) -> None:
        """regularizeDepthMap (radius 2) in place; ``validity_th`` defaults to ``val_sum_min_for_keep`` (24)."""
        self._require()
        th = self.config.val_sum_min_for_keep if validity_th is None else float(validity_th)
        rdv = float(self._prm[P_REG_DIST_VAR])
        if self.use_numba:
            regularize_numba(self.state, remove_occlusions, th, rdv, self._scratch_bool, self.parallel)
        else:
            regularize_reference(self.state, remove_occlusions, th, rdv)

    def fill_holes(self) -> None:
        """regularizeDepthMapFillHoles in place (reads a copy: no cascading)."""
        kf = self._require()
        mg = kf.levels[0].max_grad
        if self.use_numba:
            fill_holes_numba(self.state, mg, self._prm, self._scratch_bool, self._scratch_int, self.parallel)
        else:
            fill_holes_reference(self.state, mg, self._prm)

    def update(
        self,
        frame: Frame,
        T_fk: np.ndarray,
        ref_pixel_was_good: np.ndarray | None = None,
        initial_tracked_residual: float = 0.0,
    ) -> dict[str, int]:
        """Map one tracked frame into the keyframe: observe → fill holes → regularize(false, 24).

        Parameters are those of :meth:`observe`. Increments :attr:`n_updates`; stage timings go to
        :attr:`timings_ms`. Returns the observe counters.
        """
        t0 = time.perf_counter()
        counts = self.observe(frame, T_fk, ref_pixel_was_good, initial_tracked_residual)
        t1 = time.perf_counter()
        self.fill_holes()
        t2 = time.perf_counter()
        self.regularize(False, self.config.val_sum_min_for_keep)
        t3 = time.perf_counter()
        self.n_updates += 1
        self.last_counts = counts
        self.timings_ms = {
            "observe": 1e3 * (t1 - t0),
            "fill_holes": 1e3 * (t2 - t1),
            "regularize": 1e3 * (t3 - t2),
            "total": 1e3 * (t3 - t0),
        }
        return counts

    def finalize(self) -> None:
        """finalizeKeyFrame: fill holes, then regularize(false, 24)."""
        self.fill_holes()
        self.regularize(False, self.config.val_sum_min_for_keep)

    def create_keyframe(
        self,
        new_keyframe: Frame,
        T_new_old: np.ndarray,
        ref_pixel_was_good: np.ndarray | None = None,
        finalize: bool = True,
    ) -> DepthMap:
        """Finalise this map and propagate it into ``new_keyframe``; return the new keyframe's map.

        Steps (LSD-SLAM ``finalizeKeyFrame`` + ``createKeyFrame``): fill holes and regularize this map; warp
        every valid hypothesis with its smoothed inverse depth into the new keyframe (kept if it lands 2.1 px
        inside, its level-1 ``ref_pixel_was_good`` flag is set and the destination maxGrad ≥ minUseGrad;
        variance × (d_new/d_old)⁴; collisions keep the closer hypothesis if inconsistent, else fuse); then
        regularize(true) → fill holes → regularize(false) on the new map, and multiply its inverse depths by
        ρ = #valid / Σ idepth_smoothed (variances by ρ²) so that the mean smoothed inverse depth is 1.

        Parameters
        ----------
        new_keyframe : Frame
            The frame that becomes the keyframe (tracked on this keyframe).
        T_new_old : (4, 4) array
            This (old) keyframe → new keyframe rigid transform (the new frame's tracked T_fk).
        ref_pixel_was_good : (H>>1, W>>1) bool array, optional
            The tracker's flags from tracking ``new_keyframe`` against this keyframe, indexed by this
            keyframe's pixels at level 1. Without them the colour test |ΔF|²/(40² + 0.25·maxGrad²) ≤ 1 is
            used instead (LSD-SLAM's fallback).
        finalize : bool
            Finalise this map first (default). False when it already is (e.g. a state taken after LSD-SLAM's
            ``finalizeKeyFrame``).

        Returns
        -------
        DepthMap
            The new map, with ``scale_from_parent`` = ρ, ``T_new_old`` and ``last_counts`` (propagation
            counters) set.
        """
        old_kf = self._require()
        self._check_frame(new_keyframe)
        good = self._check_good(ref_pixel_was_good)
        t0 = time.perf_counter()
        if finalize:
            self.finalize()
        t1 = time.perf_counter()
        cam = old_kf.levels[0].camera
        args = (
            self.state,
            new_keyframe.levels[0].max_grad,
            good,
            old_kf.levels[0].feat,
            new_keyframe.levels[0].feat,
            np.asarray(T_new_old, np.float64),
            float(cam.fx),
            float(cam.fy),
            float(cam.cx),
            float(cam.cy),
            self._params(old_kf),
            self._cscale(old_kf),
        )
        if self.use_numba:
            new_state, pcounts = propagate_numba(*args)
        else:
            new_state, pcounts = propagate_reference(*args)
        t2 = time.perf_counter()
        child = self._sibling()
        child.keyframe = new_keyframe
        child._set_state(new_state)
        keep = self.config.val_sum_min_for_keep
        child.regularize(True, keep)
        child.fill_holes()
        child.regularize(False, keep)
        t3 = time.perf_counter()
        child.scale_from_parent = child._normalize_scale()
        child.T_new_old = np.array(T_new_old, np.float64)
        child.last_counts = {name: int(c) for name, c in zip(PCOUNT_NAMES, pcounts, strict=True)}
        t4 = time.perf_counter()
        child.timings_ms = {
            "finalize": 1e3 * (t1 - t0),
            "propagate": 1e3 * (t2 - t1),
            "regularize_fill": 1e3 * (t3 - t2),
            "scale": 1e3 * (t4 - t3),
            "total": 1e3 * (t4 - t0),
        }
        return child

    def normalize_scale(self) -> float:
        """Scale the inverse depths so that the mean smoothed inverse depth of the valid pixels is 1; return ρ
        (see :meth:`_normalize_scale`); lengths in this keyframe's units (depths, translations) scale by 1/ρ."""
        return self._normalize_scale()

    def _normalize_scale(self) -> float:
        """Scale inverse depths so that the mean smoothed idepth of valid pixels is 1; return ρ.

        ρ = #valid / Σ idepth_smoothed over valid pixels (LSD-SLAM ``createKeyFrame``). If there is no valid
        pixel or the sum is not positive, nothing is scaled and 1.0 is returned.
        """
        v = self.valid
        n = int(np.count_nonzero(v))
        s = float(np.sum(self.idepth_smoothed[v], dtype=np.float64))
        if n == 0 or not s > 0.0:
            return 1.0
        rho = n / s
        self.scale_idepth(rho)
        return float(rho)

    def scale_idepth(self, c: float, c2: float | None = None) -> None:
        """Multiply the inverse depths of the valid pixels by ``c`` and their variances by ``c2`` (default c·c,
        formed in float64), in place.

        float32 × float32(c), as ``a[v] * c`` computes it (a Python float is a weak scalar), without the gathered
        copies.
        """
        v = self.valid
        r1, r2 = np.float32(c), np.float32(c * c if c2 is None else c2)
        np.multiply(self.idepth, r1, out=self.idepth, where=v)
        np.multiply(self.idepth_smoothed, r1, out=self.idepth_smoothed, where=v)
        np.multiply(self.idepth_var, r2, out=self.idepth_var, where=v)
        np.multiply(self.idepth_var_smoothed, r2, out=self.idepth_var_smoothed, where=v)

    # ------------------------------------------------------------------------------------------ outputs
    def _tracking_mask(self) -> np.ndarray:
        return self.valid & (self.idepth_smoothed >= self.config.min_tracking_idepth)

    def tracking_depth(self) -> tuple[np.ndarray, np.ndarray]:
        """Level-0 depth for the tracker (LSD-SLAM ``Frame::setDepth``).

        Returns
        -------
        idepth, var : (H, W) float32
            Smoothed inverse depth and variance of valid hypotheses with idepth_smoothed ≥ −0.05; −1 (both)
            elsewhere.
        """
        return self.tracking_snapshot()[:2]

    def tracking_snapshot(self) -> tuple[np.ndarray, np.ndarray, float]:
        """:meth:`tracking_depth` and :attr:`mean_idepth` from one pass over the map (what ``setDepth`` gives the
        tracker and the keyframe test)."""
        if not self.use_numba:
            m = self._tracking_mask()
            d = np.where(m, self.idepth_smoothed, np.float32(-1.0)).astype(np.float32, copy=False)
            v = np.where(m, self.idepth_var_smoothed, np.float32(-1.0)).astype(np.float32, copy=False)
            mean = float(np.mean(d[m], dtype=np.float64)) if m.any() else float("nan")
            return d, v, mean
        th = self.config.min_tracking_idepth
        return tracking_select(self.valid, self.idepth_smoothed, self.idepth_var_smoothed, th)

    @property
    def mean_idepth(self) -> float:
        """Mean smoothed inverse depth of the tracking pixels (``meanIdepth``); NaN if there are none."""
        m = self._tracking_mask()
        if not m.any():
            return float("nan")
        return float(np.mean(self.idepth_smoothed[m], dtype=np.float64))

    # ------------------------------------------------------------------------------------------ checks
    def _check_frame(self, frame: Frame) -> None:
        kf = self._require()
        if (frame.height, frame.width) != (kf.height, kf.width):
            raise InputError(f"frame {frame.index} is {frame.width}x{frame.height}, keyframe is {kf.width}x{kf.height}")
        if frame.n_channels != kf.n_channels:
            raise InputError(f"frame {frame.index} has {frame.n_channels} channels, keyframe has {kf.n_channels}")

    def _check_good(self, good: np.ndarray | None) -> np.ndarray | None:
        if good is None:
            return None
        h, w = self.shape
        g = np.ascontiguousarray(good, dtype=np.bool_)
        need = (h >> GOOD_LEVEL, w >> GOOD_LEVEL)
        if g.shape != need:
            raise InputError(f"ref_pixel_was_good has shape {g.shape}, expected {need}")
        return g
