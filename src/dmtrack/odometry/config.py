"""Configuration of the semi-dense visual odometry (frozen dataclasses).

Every default is the LSD-SLAM value that users effectively ran (the ROS dynamic-reconfigure defaults, see
``lsd-slam-spec.md`` §0). Thresholds tied to the 0..255 intensity range are kept as in LSD-SLAM; features are
expected to be scaled so that their gradients are comparable to grey-level gradients.

Use :meth:`VOConfig.from_dict`, :meth:`VOConfig.from_yaml` and :meth:`VOConfig.with_overrides` to build
non-default configurations, e.g.
``VOConfig().with_overrides("tracker.huber_d=2", "keyframe.kf_dist_weight=4")``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from dmtrack.errors import InputError


@dataclass(frozen=True)
class TrackerConfig:
    """SE(3) coarse-to-fine Levenberg–Marquardt tracker (LSD-SLAM ``SE3Tracker``), lsd-slam-spec.md §2."""

    levels: tuple[int, ...] = (4, 3, 2, 1)
    """Pyramid levels visited, coarse to fine (``SE3TRACKING_MAX_LEVEL``-1 … ``SE3TRACKING_MIN_LEVEL``)."""
    max_its: tuple[int, ...] = (5, 20, 50, 100, 0)
    """LM iterations per level, indexed by level: SE3Tracker's ``maxItsPerLvl`` = {5, 20, 50, 100, 100} with
    level 4 set to 0 by ``SlamSystem``'s constructor ("do not use more than 4 levels for odometry tracking"), so
    level 4 only evaluates the residual; level 0 is not tracked."""
    lambda_initial: float = 0.0
    """Initial LM damping (``lambdaInitial``)."""
    step_size_min: float = 1e-8
    """Stop a level when a rejected step has δ·δ ≤ this (``stepSizeMin``)."""
    convergence_eps: float = 0.999
    """Stop a level when an accepted step has E_new/E_last > this (``convergenceEps``)."""
    lambda_success_fac: float = 0.5
    """λ ← λ·fac after an accepted step when λ > 0.2 (``lambdaSuccessFac``)."""
    lambda_fail_fac: float = 2.0
    """λ ← λ·fac^(tries) after a rejected step (``lambdaFailFac``)."""
    var_weight: float = 1.0
    """Weight of the depth variance in the residual weight (``var_weight``)."""
    huber_d: float = 3.0
    """Huber threshold: e = |r|·√w_p, w_h = 1 if e < huber_d/2 else (huber_d/2)/e (``huber_d``)."""
    camera_pixel_noise2: float = 16.0
    """Photometric noise variance in grey levels² (``cameraPixelNoise2``)."""
    affine: bool = False
    """Estimate affine brightness a·I_ref + b (Gray-A, ``useAffineLightningEstimation``); grey (N=1) only."""
    affine_compose: bool = False
    """Gray-A update rule. False (LSD-SLAM's code): the new (a, b) *replace* the old ones although they were
    estimated against a·I_ref + b, so the estimate alternates. True: compose (a, b) ← (a'·a, a'·b + b')."""
    affine_huber: float = 5.0
    """Weight threshold of the affine estimation: w = 1 if |r| < 5 else 5/|r|."""
    good_residual: float = 40.0
    """Good/bad test: r²/(good_residual² + good_grad_weight²·|∇I|²) < 1 is good."""
    good_grad_weight: float = 0.5
    """Gradient factor of the good/bad test (0.5 in LSD-SLAM)."""
    min_good_per_pixel: float = 0.04
    """Tracking good only if good/((w/2)(h/2)) > this."""
    min_good_ratio: float = 0.5
    """Tracking good only if good/(good+bad) > this."""
    min_inlier_fraction: float = 0.01
    """Diverged if in-image points < fraction·(w>>l)(h>>l) at a level."""

    def __post_init__(self) -> None:
        if not self.levels:
            raise InputError("tracker.levels must not be empty")
        if list(self.levels) != sorted(set(self.levels), reverse=True):
            raise InputError(f"tracker.levels {self.levels} must be strictly decreasing (coarse to fine)")
        if any(lv < 0 or lv >= len(self.max_its) for lv in self.levels):
            raise InputError(f"tracker.levels {self.levels} outside 0..{len(self.max_its) - 1}")
        if any(n < 0 for n in self.max_its):
            raise InputError(f"tracker.max_its {self.max_its} must not be negative")
        if self.huber_d <= 0 or self.camera_pixel_noise2 <= 0:
            raise InputError("tracker.huber_d and tracker.camera_pixel_noise2 must be positive")


#: Most pyramid levels: level 16 of any image that fits in memory is a single pixel.
MAX_PYRAMID_LEVELS = 16

#: Values of ``VOConfig.channel_cost``.
CHANNEL_COSTS = ("balanced", "sum", "mean")

#: Keys that were replaced, with the message that says by what.
RENAMED_KEYS = {
    "tracker.channel_weight": "tracker.channel_weight was replaced by channel_cost (balanced, sum or mean)",
    "depth.ssd_reduction": "depth.ssd_reduction was replaced by channel_cost (balanced, sum or mean)",
    "initializer.refine_iterations": "initializer.refine_iterations is no longer supported (re-aligning the start's "
    "frames to its map did not help: docs/initialization.md)",
}

#: Keys that were removed, with the value they always had: a config.yaml written before still reads with it.
REMOVED_KEYS = {"initializer.refine_iterations": 0}


#: The measured channel statistics of a feature that :class:`VOConfig` takes (``None``: the feature's).
CHANNEL_STAT_KEYS = ("info_channels", "energy_channels", "noise_energy_channels")


@dataclass(frozen=True)
class ChannelRule:
    """The channel reductions of :attr:`VOConfig.channel_cost` for an N-channel feature map.

    ``residual``: factor applied to every sum over channels of squared residuals or squared differences (the
    tracker's error, the stereo SSD, the propagation colour test). ``info``: factor applied, on top of
    ``residual``, to the gradient sums that act as information (the photometric disparity variance and the
    epipolar-gradient gate), so that information = Σ_c g_c² · residual · info. ``good``: factor of the
    constant of the tracker's good/bad test Σ_c r_c² < good·40² + ¼Σ_c|∇F_c|²; the count that decides whether
    the tracking is good adds noise_excess·σ², σ² the tracker's ``camera_pixel_noise2``. All are exactly 1
    (``noise_excess`` 0) for N = 1 in every mode.

    ``"sum"``: (1, 1, N); ``"mean"``: (1/N, 1, N); ``"balanced"``: (1/N_E, κ·N_E/N, N_E) with N_E =
    ``energy_channels`` and κ = ``info_channels`` (N and 1 when unknown), and ``noise_excess`` = N_σ − N_E with
    N_σ = ``noise_energy_channels`` (0 when unknown): the residual noise Σ_c σ_c² that the feature carries beyond
    the grey-equivalent N_E·σ² (docs/multichannel-cost.md, "The good/bad test and the feature's own noise"). The
    good/bad test of ``"sum"`` and ``"mean"`` is the channel mean (N·40²), as it always was.
    """

    residual: float
    info: float
    good: float = 1.0
    noise_excess: float = 0.0

    @classmethod
    def of(
        cls,
        channel_cost: str,
        n_channels: int,
        info_channels: float | None = None,
        energy_channels: float | None = None,
        noise_energy_channels: float | None = None,
    ) -> ChannelRule:
        if channel_cost not in CHANNEL_COSTS:
            raise InputError(f"channel_cost must be one of {', '.join(CHANNEL_COSTS)}, not {_short(channel_cost)}")
        n = int(n_channels)
        if n <= 1:
            return cls(1.0, 1.0, 1.0)
        if channel_cost == "sum":
            return cls(1.0, 1.0, float(n))
        if channel_cost == "mean":
            return cls(1.0 / n, 1.0, float(n))
        n_e = float(n) if energy_channels is None else float(energy_channels)
        kappa = 1.0 if info_channels is None else float(info_channels)
        excess = 0.0 if noise_energy_channels is None else float(noise_energy_channels) - n_e
        return cls(1.0 / n_e, kappa * n_e / n, n_e, excess)


#: Values of ``DepthConfig.update_variance`` (the kernels encode them by position).
UPDATE_VARIANCE_MODES = ("smoothed", "raw-search", "raw")


@dataclass(frozen=True)
class DepthConfig:
    """Semi-dense inverse-depth map on the keyframe (LSD-SLAM ``DepthMap``), lsd-slam-spec.md §3."""

    min_use_grad: float = 5.0
    """``minUseGrad``: mapping gradient gate; also ``MIN_ABS_GRAD_CREATE`` and ``MIN_ABS_GRAD_DECREASE``."""
    camera_pixel_noise2: float = 16.0
    """``cameraPixelNoise2``: photometric noise variance used in the stereo variance."""
    max_var: float = 0.5 * 0.5
    """``MAX_VAR``: hypotheses with larger inverse-depth variance are invalid."""
    var_random_init_initial: float = 0.125
    """``VAR_RANDOM_INIT_INITIAL``: variance of random init and hole filling."""
    random_init_validity: float = 20.0
    """Validity counter given by the random initialisation (LSD-SLAM uses 20)."""
    succ_var_inc_fac: float = 1.01
    """``SUCC_VAR_INC_FAC``: prediction variance inflation before an EKF update."""
    fail_var_inc_fac: float = 1.1
    """``FAIL_VAR_INC_FAC``: variance inflation after a failed/inconsistent observation."""
    validity_counter_inc: float = 5.0
    """``VALIDITY_COUNTER_INC``."""
    validity_counter_dec: float = 5.0
    """``VALIDITY_COUNTER_DEC``."""
    validity_counter_initial_observe: float = 5.0
    """``VALIDITY_COUNTER_INITIAL_OBSERVE``."""
    validity_counter_max: float = 5.0
    """``VALIDITY_COUNTER_MAX``."""
    validity_counter_max_variable: float = 250.0
    """``VALIDITY_COUNTER_MAX_VARIABLE``: cap is max + maxGrad·this/255."""
    val_sum_min_for_create: float = 30.0
    """``VAL_SUM_MIN_FOR_CREATE``: hole filling needs a 5×5 validity sum above this."""
    val_sum_min_for_keep: float = 24.0
    """``VAL_SUM_MIN_FOR_KEEP``: regularisation drops pixels whose neighbourhood validity sum is lower."""
    val_sum_min_for_unblacklist: float = 100.0
    """``VAL_SUM_MIN_FOR_UNBLACKLIST``: hole filling of a blacklisted pixel needs a sum above this."""
    min_blacklist: int = -1
    """``MIN_BLACKLIST``: pixels with blacklisted < this are skipped."""
    min_depth: float = 0.05
    """``MIN_DEPTH``."""
    max_epl_length_crop: float = 30.0
    """``MAX_EPL_LENGTH_CROP`` (pixels)."""
    min_epl_length_crop: float = 3.0
    """``MIN_EPL_LENGTH_CROP`` (pixels)."""
    sample_point_to_border: float = 7.0
    """``SAMPLE_POINT_TO_BORDER`` (pixels)."""
    max_error_stereo: float = 1300.0
    """``MAX_ERROR_STEREO``: SSD threshold of the 5-sample line stereo."""
    min_distance_error_stereo: float = 1.5
    """``MIN_DISTANCE_ERROR_STEREO``: best·this must not exceed a non-adjacent second best."""
    stereo_epl_var_fac: float = 2.0
    """``STEREO_EPL_VAR_FAC``: search interval is ±this·σ."""
    min_epl_grad_squared: float = 2.0 * 2.0
    """``MIN_EPL_GRAD_SQUARED``."""
    min_epl_length_squared: float = 1.0
    """``MIN_EPL_LENGTH_SQUARED``."""
    min_epl_angle_squared: float = 0.3 * 0.3
    """``MIN_EPL_ANGLE_SQUARED``."""
    reg_dist_var: float = 0.075 * 0.075
    """``REG_DIST_VAR``: regularisation distance weight."""
    depth_smoothing_factor: float = 1.0
    """``depthSmoothingFactor``."""
    allow_negative_idepths: bool = True
    """``allowNegativeIdepths``."""
    use_subpixel_stereo: bool = True
    """``useSubpixelStereo``."""
    min_tracking_idepth: float = -0.05
    """Hypotheses with idepth_smoothed below this are not used for tracking."""
    update_variance: Literal["smoothed", "raw-search", "raw"] = "raw-search"
    """Which inverse-depth variance of a hypothesis bounds its update's stereo search (idepth_smoothed ± 2σ) and the
    consistency test of the result. ``"smoothed"``: the regularised variance, as LSD-SLAM. It is 1/Σ of the
    inverse variances of up to 25 neighbours, as if they were independent observations, although they come
    from the same frames and poses; after one small-baseline observation it narrows the search to a few
    hundredths of inverse depth around an estimate made with a still poor pose, and the map can lock into a
    wrong structure (on 7-Scenes 4–6 of 10 random initialisations, in LSD-SLAM as in dmtrack).
    ``"raw-search"`` (default): the search interval uses the pixel's own (raw) variance where it is larger; the
    consistency test stays LSD-SLAM's. ``"raw"``: both use it. Measured over 10 seeds in
    docs/lsd-slam-fidelity.md; the tracker's point weights always use the smoothed variance."""

    def __post_init__(self) -> None:
        if self.update_variance not in UPDATE_VARIANCE_MODES:
            raise InputError(
                f"depth.update_variance must be 'smoothed', 'raw-search' or 'raw', not {_short(self.update_variance)}"
            )


@dataclass(frozen=True)
class KeyframeConfig:
    """Keyframe selection (LSD-SLAM ``SlamSystem`` new-keyframe test), lsd-slam-spec.md §3 "New keyframe"."""

    kf_dist_weight: float = 3.0
    """``KFDistWeight`` (ROS default 3)."""
    kf_usage_weight: float = 4.0
    """``KFUsageWeight`` (ROS default 4)."""
    threshold: float = 0.14
    """New keyframe when (|t|·meanIdepth)²·dist_w² + (1 − usage)²·usage_w² exceeds this."""
    min_mapped: int = 5
    """The current keyframe must have been mapped more than this many times (``MIN_NUM_MAPPED`` 5)."""
    loss_not_good_after: int | None = 5
    """Once more than this many keyframes exist, a frame whose tracking is not good (besides diverged) counts
    as lost (LSD-SLAM ``INITIALIZATION_PHASE_COUNT`` 5). ``None``: only divergence counts, which is what
    LSD-SLAM does in pure VO mode, where its keyframe graph stays empty (lsd-slam-spec.md §6)."""
    loss_residual_jump: float | None = 5.0
    """A frame also counts as lost when its tracking residual exceeds this many times the median of the last
    ``loss_history`` tracked frames' *and* fewer than ``loss_jump_good_ratio`` of its points are good: the camera
    jumped, or the view changed at once, and the tracker settled on a wrong pose that still explains half of the
    points (issue 37's kidnapped cameras: residual ×8 to ×19 with 52–55 % good points, which LSD-SLAM's own test
    passes). None: off, as in LSD-SLAM."""
    loss_jump_good_ratio: float = 0.75
    """See ``loss_residual_jump``."""
    loss_residual_jump_without_bad: float | None = 1.7
    """In a run that goes on after a loss (``stop_on_loss`` off) whose frames have never had a bad point — a feature
    whose residuals stay below the "good" threshold, as Bit-Planes' always do, has a good ratio of 1 that cannot
    show a jump — a frame counts as lost when its residual exceeds this many times the median of the last
    ``loss_history`` tracked frames; and after a loss a frame is found again only below that residual. Bit-Planes,
    issue 37: at most 1.38× on the tracked frames of every shared sequence, 2.08–2.22× where 7-Scenes was cut
    (chosen there), 3.4× on a rendered kidnapping. A run that stops at a loss does not use it (a false loss would
    end it). None: off."""
    loss_history: int = 10
    """Tracked frames whose residuals ``loss_residual_jump`` compares with (the test waits until it has half of
    them)."""


@dataclass(frozen=True)
class RelocConfig:
    """Finding the camera again after tracking was lost (runs that go on after a loss: ``stop_on_loss`` off;
    :mod:`dmtrack.relocalisation`), with LSD-SLAM's relocaliser's tests.

    An alignment of the lost frame to a keyframe counts only when ``point_usage · good/(good + bad)`` exceeds
    ``good_value`` and ``good/(good + bad)`` reaches ``min_good_ratio`` — stricter than tracking's own test, which a
    frame far from where the odometry thinks it is can pass on a wrong pose; and it is confirmed only when most of the
    keyframe's neighbours also align within ``neighbour_factor`` × ``good_value`` at a pose that agrees (the twist
    between the two estimates below ``consistency``).

    LSD-SLAM's values (``relocalizationTH`` 0.7, 1 − 0.75·(1 − ``MIN_GOODPERGOODBAD_PIXEL``) = 0.625) were never
    reached on issue 37's kidnapped 7-Scenes cameras: there the right keyframe aligns with a good ratio of 0.79–0.90
    and a point usage of 0.63–0.81 (usage × ratio 0.54–0.69), a wrong one with a good ratio of 0.46–0.49. Hence
    0.5 and 0.75 (the ratio below which a residual jump counts as a loss, ``KeyframeConfig.loss_jump_good_ratio``),
    chosen on four cuts of that recording (``benchmarks/kidnap.py``; docs/relocalisation.md).
    """

    good_value: float = 0.5
    """Point usage × good ratio an alignment must exceed (LSD-SLAM's ``relocalizationTH``: 0.7)."""
    min_good_ratio: float = 0.75
    """Good / (good + bad) of the alignment the odometry resumes from (LSD-SLAM: 0.625)."""
    neighbour_factor: float = 0.8
    """A neighbour keyframe confirms at ``neighbour_factor · good_value`` (LSD-SLAM: 0.8)."""
    consistency: float = 0.1
    """Largest norm of the twist between the pose found on a keyframe and on its neighbour (LSD-SLAM: 0.1)."""
    max_candidates: int = 4
    """Keyframes aligned per lost frame: the current one, those that look alike (ORB) and those near the last pose."""
    new_map_after: int = 30
    """Without a SLAM back end: frames lost before the odometry starts a new map (a new segment) with a new start
    (0: never). With one it keeps looking, as LSD-SLAM does."""
    store_mb: float = 1024.0
    """Memory for the keyframes kept to relocalise on (their images, pyramids and depth); the oldest go first."""

    def __post_init__(self) -> None:
        for name in ("good_value", "min_good_ratio", "neighbour_factor", "consistency", "store_mb"):
            if not getattr(self, name) > 0:
                raise InputError(f"relocalisation.{name} must be > 0, got {getattr(self, name)}")
        if self.max_candidates < 1 or self.new_map_after < 0:
            raise InputError("relocalisation.max_candidates must be ≥ 1 and new_map_after ≥ 0")


#: Values of ``WindowConfig.channels``.
WINDOW_CHANNELS = ("feature", "grey")
#: Values of ``WindowConfig.leave``.
WINDOW_LEAVE_MODES = ("fixed", "marginalise")

#: Values of ``WindowConfig.intrinsics_model``.
INTRINSICS_MODELS = ("f", "f-c", "fxfy-c")


@dataclass(frozen=True)
class WindowConfig:
    """The sliding window of keyframes optimised jointly (photometric bundle adjustment, :mod:`dmtrack.window`).

    At every new keyframe the newest ``size`` keyframes (the one just made among them) are optimised together: the
    poses of all but the oldest, the inverse depths of up to ``points`` sampled semi-dense points of each finished
    keyframe (the oldest's stay fixed: they hold the monocular scale), and with ``refine_intrinsics`` the camera's
    fx, fy, cx, cy, by Levenberg–Marquardt on the N-channel photometric residuals of each point in every other
    keyframe of the window, the point depths eliminated by the Schur complement. ``size = 0``: no window (the
    odometry of LSD-SLAM, byte-identical to dmtrack before the window)."""

    size: int = 0
    """Keyframes in the window (the current one included); 0 = off; DSO keeps 5–7."""
    points: int = 600
    """Points sampled per finished keyframe (the strongest gradient of each ``cell`` × ``cell`` cell)."""
    cell: int = 4
    """Cell size in pixels of the sampling level."""
    sample_level: int = 1
    """Pyramid level whose pixels are sampled (their level-0 position is kept)."""
    levels: tuple[int, ...] = (2, 1)
    """Pyramid levels optimised, coarse to fine."""
    iterations: int = 6
    """Levenberg–Marquardt iterations per level."""
    huber: float = 9.0
    """Huber threshold of a point's residual norm √(Σ_c r_c² · residual factor), grey levels (DSO: 9)."""
    outlier: float = 40.0
    """A residual norm above this counts as an outlier (no weight, a constant cost); grey levels."""
    gradient_weight: float = 0.0
    """DSO's gradient weight c: each residual's weight × √(c² / (c² + κ Σ_c |∇F_c|²)) (DSO: 50); 0: none."""
    depth_prior: float = 1.0
    """Weight of each point's inverse depth from the depth map as a prior (× 1/variance); 0: none."""
    max_outliers: float = 0.5
    """An optimisation is rejected — its result dropped and the window begun anew at the new keyframe — when more than
    this fraction of its residuals end as outliers (on the chosen-on frames at most 0.39), …"""
    max_move: float = 1.0
    """… or when it moves the new keyframe away from its tracked pose by more than this many times the distance from
    the finished keyframe to it (at most 0.48 on the chosen-on frames): a window that no longer explains its images
    must not steer the odometry."""
    leave: str = "fixed"
    """What happens to a keyframe that leaves the window: ``"fixed"`` (it keeps its last estimate and no longer
    changes; the oldest keyframe in the window, with its points, is the fixed anchor) or ``"marginalise"`` (its
    points and pose are eliminated from the linearised problem and leave a Gaussian prior on the other poses, as DSO;
    after the first keyframe has left nothing is held fixed)."""
    channels: str = "feature"
    """What the residuals compare: ``"feature"`` the tracked feature's N channels (with its channel rule) or
    ``"grey"`` the keyframes' grey images (DSO's residual), whatever feature tracks."""
    refine_intrinsics: bool = False
    """Also estimate fx, fy, cx, cy from the images, with the given calibration as a prior."""
    intrinsics_model: str = "f"
    """Which intrinsics ``refine_intrinsics`` estimates: ``"f"`` one focal length (f_x/f_y kept at the given ratio,
    the principal point fixed: COLMAP's default, ``refine_principal_point`` off), ``"f-c"`` also the principal point,
    ``"fxfy-c"`` all four."""
    intrinsics_prior: float = 0.2
    """Standard deviation of that prior, relative to the focal length (fx, fy) and to the image size (cx, cy)."""

    def __post_init__(self) -> None:
        if self.size < 0 or self.size == 1:
            raise InputError(f"window.size must be 0 (off) or ≥ 2, got {self.size}")
        if self.points < 1 or self.cell < 1 or self.iterations < 0 or self.sample_level < 0:
            raise InputError("window.points and window.cell must be ≥ 1, window.iterations and sample_level ≥ 0")
        if not self.levels or list(self.levels) != sorted(set(self.levels), reverse=True) or min(self.levels) < 0:
            raise InputError(f"window.levels {self.levels} must be non-negative and strictly decreasing")
        if not (self.huber > 0 and self.outlier > 0 and self.depth_prior >= 0 and self.intrinsics_prior > 0
                and 0 < self.max_outliers <= 1 and self.max_move > 0 and self.gradient_weight >= 0):
            raise InputError("window.huber, outlier, intrinsics_prior and max_move must be > 0, depth_prior ≥ 0, "
                             "max_outliers in (0, 1]")
        if self.intrinsics_model not in INTRINSICS_MODELS:
            raise InputError(f"window.intrinsics_model must be one of {', '.join(INTRINSICS_MODELS)}, "
                             f"not {_short(self.intrinsics_model)}")  # fmt: skip
        if self.leave not in WINDOW_LEAVE_MODES:
            raise InputError(f"window.leave must be one of {', '.join(WINDOW_LEAVE_MODES)}, not {_short(self.leave)}")
        if self.channels not in WINDOW_CHANNELS:
            raise InputError(f"window.channels must be one of {', '.join(WINDOW_CHANNELS)}, "
                             f"not {_short(self.channels)}")  # fmt: skip


INIT_MODES = ("random", "geometric", "groundtruth")


@dataclass(frozen=True)
class InitConfig:
    """The geometric start (``VOConfig.init = "geometric"``, :mod:`dmtrack.initialization`, docs/initialization.md).

    Corners of a reference frame (the first, until it cannot be fitted) are tracked (KLT) through the following
    frames, new ones followed back to it when they leave the image; at each check an essential matrix (MAGSAC++)
    and a homography are fitted; once the translation gives enough parallax, a bundle adjustment over the window
    fixes the poses, the first keyframe's map is made by the depth map's own stereo from the window's frames."""

    corners: int = 600
    """Corners detected in the first frame (``cv2.goodFeaturesToTrack``)."""
    corner_distance: float = 8.0
    """Smallest distance between two corners, pixels."""
    klt_window: int = 21
    """KLT window side, pixels (``cv2.calcOpticalFlowPyrLK``)."""
    klt_levels: int = 3
    """KLT pyramid levels above the image."""
    max_fb_error: float = 0.5
    """A track is dropped when tracking it back lands farther than this from where it started, pixels."""
    ransac_px: float = 1.0
    """RANSAC threshold of the essential matrix, pixels."""
    essential: str = "magsac"
    """Robust estimator of the essential matrix: ``magsac`` (``cv2.USAC_MAGSAC``, MAGSAC++ with its fixed seed),
    ``ransac`` (``cv2.RANSAC``, before issue 37) or ``accurate`` (``cv2.USAC_ACCURATE``). MAGSAC++ was chosen on
    the start scan's KITTI 06 and forward-driving starts (rotation of the two-view fit 0.01–0.08° against RANSAC's
    0.4–1.4°); benchmarks/studies/2026-11-28-start/ gives it on the others."""
    min_parallax_deg: float = 0.5
    """Median parallax angle of the triangulated corners, degrees, before the window is tried."""
    max_homography_fraction: float = 0.9
    """The window is tried only when at most this fraction of the essential matrix's inliers also fits one
    homography within 2 px (more: the motion is a rotation or the scene a plane, so far) — or when that homography
    is no rotation (``min_plane_stretch``)."""
    min_plane_stretch: float = 0.03
    """A homography that explains the corners but stretches the normalised image by this much (σ₁/σ₃ − 1 of
    K⁻¹HK; 0 for a pure rotation) is a plane seen by a translating camera: the motion can be fitted, the window is
    tried (measured: 0.04–0.10 for a camera moving in front of a wall, at most 0.016 for 7-Scenes' turning start)."""
    min_inliers: int = 80
    """Fewest corners consistent with the two-view geometry (and kept by the bundle adjustment)."""
    min_spread_inliers: int = 40
    """Fewer corners than ``min_inliers`` are enough, down to this many, when they span the image: at least
    ``spread_cells`` of its 3 × 3 cells hold 3 or more of them (forward motion leaves few corners, spread out)."""
    spread_cells: int = 6
    """Cells of the 3 × 3 grid the corners must occupy for ``min_spread_inliers`` to be enough."""
    redetect_below: int = 300
    """When fewer tracks than this are left, new corners of the newest frame are followed back to the reference
    frame (0: never)."""
    max_unfit: int = 3
    """Tries in a row that cannot be fitted from the reference frame (the bundle adjustment fails, or two windows
    disagree) before the start begins again from a later reference frame, the newest."""
    min_frames: int = 8
    """Fewest frames after the first in the window."""
    max_frames: int = 90
    """Frames after the run's first before the start gives up, whatever its reference frames (then it refuses and
    the odometry starts from a random map: see ``VOConfig.init``). 90 frames are 3 s at 30 Hz and 9 s at 10 Hz:
    every start measured on the shared and synthetic sequences was accepted within 41 frames, and a camera that
    has not translated by then is better served by the random map than by frames it cannot pose."""
    max_reprojection_px: float = 1.0
    """Median reprojection error the bundle adjustment must reach for the window to be accepted, pixels."""
    agree_rot_deg: float = 0.75
    """Two successive tries must agree on the newest frame of the earlier one within this rotation, degrees (a
    short baseline can fit a wrong motion as well as the right one; a wrong one does not last)."""
    agree_tdir_deg: float = 20.0
    """... and within this angle between their directions of motion, degrees."""
    map_frames: int = 6
    """Frames of the window (evenly spaced, the last included) whose stereo makes the first map."""
    stereo_residual: float = 0.0
    """Tracking residual the first map's stereo assumes (0: the poses are taken as exact)."""

    def __post_init__(self) -> None:
        positive = ("corners", "klt_window", "min_inliers", "min_spread_inliers", "min_frames", "max_frames",
                    "map_frames", "max_unfit")
        for name in positive:
            if int(getattr(self, name)) < 1:
                raise InputError(f"initializer.{name} must be ≥ 1, got {getattr(self, name)}")
        if self.klt_levels < 0 or self.redetect_below < 0:
            raise InputError("initializer.klt_levels and initializer.redetect_below must be ≥ 0")
        if self.min_spread_inliers > self.min_inliers:
            raise InputError(f"initializer.min_spread_inliers {self.min_spread_inliers} > min_inliers "
                             f"{self.min_inliers}")
        if self.essential not in ("ransac", "magsac", "accurate"):
            raise InputError(f"initializer.essential must be ransac, magsac or accurate, got {self.essential!r}")
        if not 1 <= self.spread_cells <= 9:
            raise InputError(f"initializer.spread_cells must be in 1..9, got {self.spread_cells}")
        for name in ("corner_distance", "max_fb_error", "ransac_px", "max_reprojection_px", "agree_rot_deg",
                     "agree_tdir_deg"):
            if not getattr(self, name) > 0:
                raise InputError(f"initializer.{name} must be > 0, got {getattr(self, name)}")
        if not 0 <= self.min_parallax_deg < 90:
            raise InputError(f"initializer.min_parallax_deg must be in [0, 90), got {self.min_parallax_deg}")
        if not 0 < self.max_homography_fraction <= 1:
            raise InputError(
                f"initializer.max_homography_fraction must be in (0, 1], got {self.max_homography_fraction}"
            )
        if self.min_frames > self.max_frames:
            raise InputError(f"initializer.min_frames {self.min_frames} > max_frames {self.max_frames}")
        if self.stereo_residual < 0:
            raise InputError(f"initializer.stereo_residual must be ≥ 0, got {self.stereo_residual}")


@dataclass(frozen=True)
class VOConfig:
    """Whole odometry configuration."""

    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    depth: DepthConfig = field(default_factory=DepthConfig)
    keyframe: KeyframeConfig = field(default_factory=KeyframeConfig)
    initializer: InitConfig = field(default_factory=InitConfig)
    relocalisation: RelocConfig = field(default_factory=RelocConfig)
    window: WindowConfig = field(default_factory=WindowConfig)
    pyramid_levels: int = 5
    """Number of pyramid levels built per frame (0..pyramid_levels−1)."""
    seed: int = 0
    """Seed of the random depth initialisation (``init="random"``, or a geometric start that refused)."""
    map_lag: int = 1
    """Frames by which the map the tracker uses lags the mapping: frame n is tracked against (and its keyframe
    test sees numMapped and meanIdepth of) the keyframe's depth map as mapped through frame n − 1 − map_lag, or
    as created if the keyframe is younger. 1 is what LSD-SLAM's VO does with single-threaded, blocking mapping
    (its tracker runs while the previous frame is still being mapped); 0 is strictly sequential."""
    stop_on_loss: bool = True
    """Stop processing at the first tracking loss (the paper counts tracked frames until failure)."""
    channel_cost: Literal["balanced", "sum", "mean"] = "balanced"
    """How the N channels of a feature enter every grey-tuned quantity (docs/multichannel-cost.md).
    ``"balanced"`` (default): residual-type quantities (the tracker's error and its ``initialTrackedResidual``,
    the stereo SSD and its acceptance, the propagation colour test) are means over channels, so LSD-SLAM's
    thresholds keep their per-channel meaning; information-type quantities (the photometric disparity variance
    ``4σ²/gradAlongLine`` and the epipolar-gradient gate) count ``info_channels`` grey-equivalent observations.
    ``"sum"``: the paper's literal squared L2 norm over channels everywhere. ``"mean"``: ÷N everywhere. All three
    are the same for N = 1."""
    info_channels: float | None = None
    """Grey-equivalent number of independent channels κ of the feature, used by ``channel_cost="balanced"``:
    the information σ_g²·gᵀC⁻¹g of a feature gradient g under the feature's noise covariance C (image noise
    pushed through the feature), relative to the channel mean of |g|², measured once per feature
    (:func:`dmtrack.features.scale.measure_info_channels`, ``default_scales.json``). ``None``: the feature's
    calibrated value (:func:`dmtrack.track` fills it in), or 1 for a feature map of unknown origin."""
    energy_channels: float | None = None
    """Gradient-energy channel count N_E of the feature, used by ``channel_cost="balanced"``: E[Σ_c|∇F_c|²] /
    E[|∇I|²] on the calibration images (grey = 1). The SSD-type sums are divided by N_E, so that a given
    misalignment costs what it costs in grey — LSD-SLAM's stereo and residual thresholds are set in those units
    (``MAX_ERROR_STEREO`` + 20·√gradAlongLine). ``None``: the feature's calibrated value (filled in by
    :func:`dmtrack.track`), or N for a feature map of unknown origin."""
    noise_energy_channels: float | None = None
    """Noise-energy channel count N_σ = Σ_c σ_c² / σ_g² of the feature, used by ``channel_cost="balanced"``'s
    tracking-quality decision: the residual variance that image noise leaves in the N channels, relative to
    grey's, measured once per feature like N_E (``default_scales.json``: N·noise_var/grey_noise_var). The good/bad
    count that decides whether a frame's tracking is good (hence a loss) uses the constant N_E·40² +
    (N_σ − N_E)·``tracker.camera_pixel_noise2``: the grey allowance for appearance change, in feature units, plus
    the noise the feature has beyond a grey-like one; the per-pixel flags keep N_E·40². ``None``: the feature's
    calibrated value (filled in by :func:`dmtrack.track`), or N_E (no extra noise) when it has none."""
    init: str = "geometric"
    """How the first keyframe's depth starts: ``"geometric"`` (default: the first map from the frames' own
    geometry, :class:`InitConfig`, made by :mod:`dmtrack.initialization` before the odometry starts —
    ``dmtrack.track`` does it; the seed plays no part; if the motion never gives the parallax it needs, the run
    starts from the random map and says so in ``metrics.json``), ``"random"`` (LSD-SLAM's seeded random inverse
    depth, the paper's setting, byte-identical to dmtrack before the geometric start) or ``"groundtruth"`` (the
    dataset's depth of the first frame, as LSD-SLAM's ``gtDepthInit``: variance 0.01², metric scale; needs a depth
    image registered to the camera)."""

    def __post_init__(self) -> None:
        if self.channel_cost not in CHANNEL_COSTS:
            raise InputError(f"channel_cost must be one of {', '.join(CHANNEL_COSTS)}, not {_short(self.channel_cost)}")
        for key in CHANNEL_STAT_KEYS:
            v = getattr(self, key)
            if v is not None and not (isinstance(v, (int, float)) and not isinstance(v, bool) and 0 < v < float("inf")):
                raise InputError(f"{key} must be a positive number, not {_short(v)}")
        if self.init not in INIT_MODES:
            raise InputError(f"init must be one of {', '.join(INIT_MODES)}, not {_short(self.init)}")
        if self.map_lag < 0:
            raise InputError(f"map_lag must be ≥ 0, got {self.map_lag}")
        if not 1 <= self.pyramid_levels <= MAX_PYRAMID_LEVELS:
            raise InputError(f"pyramid_levels must be 1..{MAX_PYRAMID_LEVELS}, got {self.pyramid_levels}")
        if self.seed < 0:
            raise InputError(f"seed must be ≥ 0, got {self.seed}")
        if max(self.tracker.levels) >= self.pyramid_levels:
            raise InputError(f"tracker.levels {self.tracker.levels} need > {self.pyramid_levels} levels")
        if self.window.size and max(*self.window.levels, self.window.sample_level) >= self.pyramid_levels:
            raise InputError(f"window.levels {self.window.levels} need > {self.pyramid_levels} levels")

    # ------------------------------------------------------------------ construction helpers
    def to_dict(self) -> dict[str, Any]:
        """Nested plain dict (tuples stay tuples)."""
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any], path: str | Path | None = None) -> VOConfig:
        """Build from a nested dict; unknown keys raise :class:`InputError` (naming ``path`` if given)."""
        if not isinstance(data, dict):
            raise InputError("configuration must be a mapping", path=path)
        sub_types = {
            "tracker": TrackerConfig,
            "depth": DepthConfig,
            "keyframe": KeyframeConfig,
            "initializer": InitConfig,
            "relocalisation": RelocConfig,
            "window": WindowConfig,
        }
        kwargs: dict[str, Any] = {}
        top_fields = {f.name for f in dataclasses.fields(cls)}
        for key, value in data.items():
            if key not in top_fields:
                raise InputError(f"unknown configuration key {_short(key)}", path=path)
            if key in sub_types:
                if isinstance(value, sub_types[key]):
                    kwargs[key] = value
                    continue
                if value is None:  # an empty section ("tracker:" with every key commented out)
                    value = {}
                if not isinstance(value, dict):
                    raise InputError(f"configuration section {_short(key)} must be a mapping", path=path)
                kwargs[key] = _build(sub_types[key], value, key, path)
            else:
                kwargs[key] = _coerce(cls, key, value, key, path)
        try:
            return cls(**kwargs)
        except InputError as exc:
            raise InputError(exc.reason, path=path) from None

    @classmethod
    def from_yaml(cls, path: str | Path) -> VOConfig:
        """Read a YAML file with optional sections ``tracker``, ``depth``, ``keyframe`` and top-level keys."""
        from dmtrack.io.files import read_text_file

        p = Path(path)
        text = read_text_file(p, "configuration file")
        data = _load_yaml(text, p)
        return cls.from_dict({} if data is None else data, path=p)

    def with_overrides(self, *overrides: str) -> VOConfig:
        """Return a copy with ``"section.key=value"`` (or ``"key=value"``) overrides applied.

        Values are parsed as YAML scalars/sequences (``"tracker.levels=[3,2,1]"``, ``"tracker.affine=true"``).
        """
        import yaml

        data = self.to_dict()
        for item in overrides:
            if "=" not in item:
                raise InputError(f"override {_short(item)} is not of the form key=value")
            key, raw = item.split("=", 1)
            parts = key.strip().split(".")
            try:
                value = yaml.safe_load(raw)
            except (yaml.YAMLError, ValueError, TypeError, OverflowError, RecursionError):
                raise InputError(f"override {_short(item)}: cannot parse value") from None
            node = data
            for part in parts[:-1]:
                if part not in node or not isinstance(node[part], dict):
                    raise InputError(f"override {_short(item)}: unknown section {_short(part)}")
                node = node[part]
            if parts[-1] not in node:
                hint = RENAMED_KEYS.get(".".join(p.strip() for p in parts))
                raise InputError(f"override {_short(item)}: {hint or f'unknown key {_short(parts[-1])}'}")
            node[parts[-1]] = value
        return VOConfig.from_dict(data)


def _load_yaml(text: str, path: Path) -> Any:
    """``yaml.safe_load`` with every failure as one line naming the file (and the line where YAML knows it)."""
    import yaml

    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = None if mark is None else mark.line + 1
        problem = getattr(exc, "problem", None) or str(exc)
        context = getattr(exc, "context", None)
        reason = " ".join(f"{problem}{f' ({context})' if context else ''}".split())
        raise InputError(f"invalid YAML: {reason}", path=path, line=line) from None
    except RecursionError:
        raise InputError("invalid YAML: nested too deeply", path=path) from None
    except (ValueError, TypeError, OverflowError) as exc:  # e.g. a date that does not exist, 2001-02-30
        raise InputError(f"invalid YAML: {' '.join(str(exc).split())[:100]}", path=path) from None


def _coerce(cls: type, name: str, value: Any, where: str, path: str | Path | None) -> Any:
    """Coerce ``value`` to the type of field ``name`` of ``cls`` (lists → tuples, ints → floats)."""
    fld = {f.name: f for f in dataclasses.fields(cls)}[name]
    default = fld.default
    if default is dataclasses.MISSING:
        return value
    if value is None and "None" in str(fld.type):
        return None
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise InputError(f"{where} must be true/false, not {_short(value)}", path=path)
        return value
    if isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise InputError(f"{where} must be an integer, not {_short(value)}", path=path)
        return value
    if isinstance(default, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InputError(f"{where} must be a number, not {_short(value)}", path=path)
        try:
            number = float(value)
        except OverflowError:  # an integer beyond the float range
            number = math.inf
        if not math.isfinite(number):
            raise InputError(f"{where} must be a finite number, not {_short(value)}", path=path)
        return number
    if isinstance(default, tuple):
        if not isinstance(value, (list, tuple)):
            raise InputError(f"{where} must be a list, not {_short(value)}", path=path)
        if all(isinstance(d, int) for d in default) and not all(
            isinstance(v, int) and not isinstance(v, bool) for v in value
        ):
            raise InputError(f"{where} must be a list of integers, not {_short(value)}", path=path)
        return tuple(value)
    return value


def _short(value: Any, n: int = 60) -> str:
    """``repr(value)`` cut to ``n`` characters (a message stays one short line)."""
    if type(value).__module__ == "numpy" and hasattr(value, "item"):  # np.float64(2.0) → 2.0
        value = value.item()
    text = repr(value)
    return text if len(text) <= n else text[: n - 1] + "…"


def _build(cls: type, data: dict[str, Any], section: str, path: str | Path | None) -> Any:
    names = {f.name for f in dataclasses.fields(cls)}
    kwargs = {}
    for key, value in data.items():
        if f"{section}.{key}" in REMOVED_KEYS and value == REMOVED_KEYS[f"{section}.{key}"]:
            continue  # a config.yaml of an earlier version: the key had this value, which is now the only behaviour
        if key not in names:
            hint = RENAMED_KEYS.get(f"{section}.{key}")
            raise InputError(hint or f"unknown configuration key {section}.{key}", path=path)
        kwargs[key] = _coerce(cls, key, value, f"{section}.{key}", path)
    try:
        return cls(**kwargs)
    except InputError as exc:
        raise InputError(exc.reason, path=path) from None
