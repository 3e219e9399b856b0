"""Training of ``tracknet`` through the tracker's own alignment (issue 15).

One step:

1. sample pairs (keyframe k, frame k + gap) from seeded synthetic sequences (:mod:`dmtrack.datasets.synthetic`:
   exact depth and pose; global/local illumination changes and sensor noise vary per sequence), the same random
   crop of both (the level-0 pixel scale of the 640×480 frames is kept, so the feature learns at the scale it
   runs at);
2. the network's maps of both crops × the training gain G, their pyramids (2×2 box means, as the tracker);
3. reference points as the tracker builds them (:func:`~dmtrack.odometry._tracker_points.idepth_downsample_numpy`,
   :func:`~dmtrack.odometry._tracker_points.make_points_numpy`) from the keyframe's exact inverse depth on a random
   subset of pixels, with random inverse-depth variances and inverse-depth noise of that variance;
4. start from the true pose perturbed by a random twist (or from the identity), unroll a few damped Gauss–Newton
   steps per level, coarse to fine (:func:`dmtrack.training.alignment.lm_step`: the tracker's residuals, weights,
   Huber and normal equations);
5. loss = Σ_levels w_l · mean over points of a robust reprojection distance (level-0 pixels) between the pose after
   level l and the truth (``√(d² + 1) − 1``, capped at 50), plus the *scale term* below;
6. Adam, gradient-norm clipping; pairs whose system is singular or whose loss is not finite are skipped.

The feature scale: the alignment sees G × the network's (−1, 1) output, G a fixed training gain. At run time the
feature is multiplied by its default scale s, calibrated after training with the default-scale machinery (as many
semi-dense pixels — channel-mean gradient > 5 after the 3×3 max — as grey). For the network to run at the magnitudes
it was trained at (where LSD-SLAM's photometric noise, Huber width and minUseGrad keep their meaning) s should be ≈
G. The scale term keeps it there: w_s·(log q − log 5)², q the keyframe crop's (1 − f)-quantile of G × the feature's
channel-mean gradient magnitude (3×3 max), f grey's semi-dense fraction on the same crop — q = 5 is exactly s = G on
that crop (the log is of q + 0.25 against 5.25, so that it stays bounded as q → 0). The fresh network's last layer
is rescaled so that it starts at s ≈ G (:func:`match_gain`). Every ``calibrate_every`` steps the log records the
default scale of the current network on a fixed set of training crops (:func:`calibrated_gain`), to be compared with
G. (Recalibrating G itself during training was tried: the network shrinks its output and G runs away.)

Deterministic: ``torch.manual_seed``, ``torch.use_deterministic_algorithms(True)``, a fixed number of torch threads,
every random draw from one ``numpy.random.Generator`` seeded with the seed. The weights after N steps are a function
of (seed, N, the options); with ``--minutes`` the number of steps depends on the machine's speed, so the log
records it (``--steps N`` reproduces the run).

Real data (``data="7scenes"``/``"both"``, ``data_path``): pairs of a sequence with ground-truth poses, the keyframe's
depth mapped by the odometry itself at those poses (:mod:`dmtrack.training.realdata`; 7-Scenes' depth images are not
registered to the colour camera, so they are not used).

Outputs (every file through :mod:`dmtrack.io.atomic`): ``tracknet.npz`` (the export, also written at every
checkpoint), ``checkpoint.pt`` (model, optimiser, step), ``train_log.csv`` (one row per step), ``train_log.json``
(options, validation, summary) and ``training_curve.png``.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numba
import numpy as np
import torch

from dmtrack.datasets.synthetic import SyntheticConfig, SyntheticSequence
from dmtrack.errors import InputError
from dmtrack.features.device import check_device, resolve_device
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.atomic import atomic_path, prepare_folder, write_bytes, write_text
from dmtrack.odometry._tracker_points import idepth_downsample_numpy, make_points_numpy
from dmtrack.odometry.config import TrackerConfig
from dmtrack.training.alignment import AlignParams, lm_step, pack
from dmtrack.training.log import plot_curve, write_log
from dmtrack.training.model import TrackNet, export_npz
from dmtrack.training.realdata import MixedPairs, Pair, SequencePairs

DATA_CHOICES = ("synthetic", "7scenes", "both")
LR_SCHEDULES = ("constant", "cosine")


def learning_rate(opts: TrainOptions, step: int) -> float:
    """Adam's rate for step ``step`` (0-based) under ``opts.lr_schedule``."""
    if opts.lr_schedule == "constant" or not opts.steps:
        return opts.lr
    t = min(step / opts.steps, 1.0)
    return opts.lr * (opts.lr_final + (1.0 - opts.lr_final) * 0.5 * (1.0 + math.cos(math.pi * t)))


@dataclass(frozen=True)
class TrainOptions:
    """Options of :func:`train` (the CLI's, plus the finer ones).

    Attributes
    ----------
    seed : int
        Seeds the network's initialisation and every random draw.
    minutes : float
        Wall-clock budget of the training loop (checked between steps).
    steps : int, optional
        Stop after this many steps (whichever of the two comes first).
    channels, hidden, kernels
        The network (:class:`~dmtrack.training.model.TrackNet`).
    data : str
        ``"synthetic"``, ``"7scenes"`` (a real sequence with ground-truth poses, ``data_path``; depth from the
        odometry's own mapping at those poses: :mod:`dmtrack.training.realdata`) or ``"both"`` (each pair from
        either with probability ½).
    data_path : str, optional
        The real sequence of ``"7scenes"`` / ``"both"`` (e.g. ``../shared/data/7scenes-0000-0699``).
    intrinsics : str, optional
        Intrinsics replacing the real sequence's (as ``dmtrack run --intrinsics``).
    keyframe_every, mapping_frames
        Real data: frames between two training keyframes, and frames before each mapped into its depth.
    gain : float
        Training gain G (see the module documentation).
    scale_weight : float
        Weight w_s of the scale term.
    calibrate_every : int
        Steps between two measurements of the network's default scale (logged, not used).
    calibration_images : int
        Training crops that default scale is measured on.
    batch : int
        Pairs per step.
    lr : float
        Adam's learning rate.
    lr_schedule : str
        ``"constant"``, or ``"cosine"``: the rate falls from ``lr`` to ``lr_final · lr`` along half a cosine over
        ``steps`` (which must then be given).
    lr_final : float
        Final fraction of ``lr`` of the cosine schedule.
    crop : tuple of int
        (width, height) of the random crop of the 640×480 synthetic frames.
    levels, iterations
        Pyramid levels unrolled (coarse to fine) and Gauss–Newton steps on each.
    lam : float
        LM damping λ of the unrolled steps.
    level_weights : tuple of float
        Loss weight of the pose after each level.
    max_points : int
        Reference points per level (random subset).
    point_fraction : float
        Fraction of the keyframe's pixels that get a depth.
    max_gap : int
        Largest frame distance between keyframe and frame.
    init_trans, init_rot_deg : float
        Std of the random initial pose error (metres, degrees per axis).
    identity_init : float
        Probability of starting from the identity instead (the tracker without a motion prior).
    n_sequences, n_frames : int
        Synthetic training sequences and their length.
    val_pairs : int
        Held-out pairs (other scene seeds) evaluated before and after training.
    threads : int
        torch (and numba) threads; 1 by default: on a CPU shared with other jobs more threads slow torch down
        badly (its OpenMP workers wait for each other).
    checkpoint_every : int
        Steps between checkpoints.
    device : str
        Where the network and the unrolled alignment run: ``"cpu"`` (default), ``"cuda"``, ``"cuda:N"`` or
        ``"auto"`` (:mod:`dmtrack.features.device`; a GPU run is deterministic on its own, not equal to the CPU's).
    """

    seed: int = 0
    minutes: float = 10.0
    steps: int | None = None
    channels: int = 8
    hidden: int = 8
    kernels: tuple[int, ...] = (5, 3)
    data: str = "synthetic"
    data_path: str | None = None
    intrinsics: str | None = None
    keyframe_every: int = 10
    mapping_frames: int = 12
    gain: float = 64.0
    scale_weight: float = 0.5
    calibrate_every: int = 25
    calibration_images: int = 8
    batch: int = 2
    lr: float = 1e-3
    lr_schedule: str = "constant"
    lr_final: float = 0.05
    crop: tuple[int, int] = (320, 240)
    levels: tuple[int, ...] = (3, 2, 1)
    iterations: tuple[int, ...] = (3, 3, 3)
    lam: float = 0.01
    level_weights: tuple[float, ...] = (0.25, 0.5, 1.0)
    max_points: int = 3000
    point_fraction: float = 0.5
    max_gap: int = 8
    init_trans: float = 0.04
    init_rot_deg: float = 2.0
    identity_init: float = 0.25
    n_sequences: int = 8
    n_frames: int = 300
    val_pairs: int = 16
    threads: int = 1
    checkpoint_every: int = 100
    device: str = "cpu"

    def check(self) -> None:
        """:class:`InputError` on impossible options."""
        if self.data not in DATA_CHOICES:
            raise InputError(f"--data must be one of {', '.join(DATA_CHOICES)}, not {self.data!r}")
        if self.data != "synthetic" and not self.data_path:
            raise InputError(f"--data {self.data} needs --data-path DIR: a sequence with ground-truth poses, e.g. "
                             "../shared/data/7scenes-0000-0699")  # fmt: skip
        if self.keyframe_every < 1 or self.mapping_frames < 1:
            raise InputError("keyframe_every and mapping_frames must be ≥ 1")
        if self.lr_schedule not in LR_SCHEDULES:
            raise InputError(f"--lr-schedule must be one of {', '.join(LR_SCHEDULES)}, not {self.lr_schedule!r}")
        if not 0 < self.lr_final <= 1:
            raise InputError(f"lr_final must be in (0, 1], got {self.lr_final}")
        if self.lr_schedule == "cosine" and self.steps is None:
            raise InputError("--lr-schedule cosine needs --steps N: the schedule runs over a known number of steps")
        if not 1 <= self.channels <= 64:
            raise InputError(f"--channels must be in 1..64, got {self.channels}")
        if not (self.minutes > 0 and math.isfinite(self.minutes)):
            raise InputError(f"--minutes must be a positive number, got {self.minutes}")
        if self.steps is not None and self.steps < 0:
            raise InputError(f"--steps must be ≥ 0, got {self.steps}")
        if len(self.iterations) != len(self.levels) or len(self.level_weights) != len(self.levels):
            raise InputError("levels, iterations and level_weights must have the same length")
        check_device(self.device)
        w, h = self.crop
        div = 1 << max(self.levels)
        if w % div or h % div or w > 640 or h > 480:
            raise InputError(f"crop {w}x{h} must fit 640x480 and be divisible by {div}")


# ============================================================================================ data
def _sequence_config(seed: int, rng: np.random.Generator, n_frames: int) -> SyntheticConfig:
    return SyntheticConfig(
        seed=int(seed),
        n_frames=int(n_frames),
        speed=float(rng.uniform(0.2, 0.5)),
        global_illumination=float(rng.choice([0.0, 0.15, 0.3])),
        local_illumination=float(rng.choice([0.0, 0.3, 0.6])),
        noise_sigma=float(rng.uniform(0.5, 3.0)),
    )


class SyntheticPairs:
    """Seeded pairs from ``n`` synthetic sequences (scene seeds ``base_seed`` … ``base_seed + n − 1``).

    Frames are rendered on demand (≈ 50 ms each at 640×480) and the most recent ones kept.
    """

    def __init__(self, base_seed: int, n: int, n_frames: int, rng: np.random.Generator, cache: int = 64):
        self.sequences = [SyntheticSequence(_sequence_config(base_seed + i, rng, n_frames)) for i in range(n)]
        self._cache: OrderedDict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = OrderedDict()
        self._cache_size = cache

    def frame(self, s: int, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(grey uint8 image, depth float32) of frame k of sequence s."""
        key = (s, k)
        hit = self._cache.get(key)
        if hit is not None:
            self._cache.move_to_end(key)
            return hit
        fr = self.sequences[s][k]
        assert fr.depth is not None
        value = (np.asarray(fr.image), np.asarray(fr.depth, np.float32))
        self._cache[key] = value
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return value

    def sample(self, rng: np.random.Generator, crop: tuple[int, int], max_gap: int) -> Pair:
        s = int(rng.integers(len(self.sequences)))
        seq = self.sequences[s]
        gap = int(rng.integers(1, max_gap + 1)) * (1 if rng.random() < 0.5 else -1)
        k = int(rng.integers(max(0, -gap), len(seq) - max(0, gap)))
        key_img, depth = self.frame(s, k)
        frame_img, _ = self.frame(s, k + gap)
        cw, ch = crop
        x0 = int(rng.integers(0, (seq.width - cw) // 8 + 1)) * 8
        y0 = int(rng.integers(0, (seq.height - ch) // 8 + 1)) * 8
        cam = seq.camera
        assert cam is not None
        poses = seq.poses
        T_fk = np.linalg.inv(poses[k + gap]) @ poses[k]
        return Pair(
            key_image=np.ascontiguousarray(key_img[y0 : y0 + ch, x0 : x0 + cw]),
            frame_image=np.ascontiguousarray(frame_img[y0 : y0 + ch, x0 : x0 + cw]),
            idepth=np.ascontiguousarray(1.0 / depth[y0 : y0 + ch, x0 : x0 + cw]).astype(np.float32),
            camera=PinholeCamera(cam.fx, cam.fy, cam.cx - x0, cam.cy - y0, cw, ch),
            T_fk=T_fk,
        )


def training_pairs(opts: TrainOptions, rng: np.random.Generator, say: Callable[[str], None] | None = None) -> Any:
    """The pair source of ``opts.data`` (synthetic pairs draw from ``rng`` first, as before real data existed, so
    a synthetic run reproduces its weights)."""
    synthetic = None
    if opts.data in ("synthetic", "both"):
        synthetic = SyntheticPairs(1000 + 100 * opts.seed, opts.n_sequences, opts.n_frames, rng)
    if opts.data == "synthetic":
        return synthetic
    real = SequencePairs(
        str(opts.data_path), opts.seed, opts.keyframe_every, opts.mapping_frames, opts.max_gap, say=say,
        intrinsics=opts.intrinsics,
    )  # fmt: skip
    if say is not None:
        s = real.summary
        err = "n/a" if s.rel_error is None else f"{100 * s.rel_error:.1f} %"
        say(f"real pairs: {s.keyframes} keyframes of {opts.data_path}, median {s.points_median:.0f} depth points, "
            f"median |d/d_sensor - 1| {err}")  # fmt: skip
    return real if synthetic is None else MixedPairs(synthetic, real, 0.5)


@dataclass
class LevelPoints:
    """Reference points of one level (numpy): points (n, 3), variances (n,), flat pixel index (n,)."""

    points: np.ndarray
    variances: np.ndarray
    index: np.ndarray


def reference_points(
    idepth: np.ndarray,
    camera: PinholeCamera,
    levels: tuple[int, ...],
    rng: np.random.Generator,
    fraction: float,
    max_points: int,
    variance: np.ndarray | None = None,
) -> dict[int, LevelPoints]:
    """The tracker's reference points of each level from a level-0 inverse depth given on a random subset of pixels.

    Exact depth (``variance`` None): variances are drawn log-uniformly in [1e-4, 1e-2] (1/m²) and the inverse depth
    is perturbed by noise of that variance. Estimated depth: its own ``variance``, no noise added. The pyramid and
    the points are built by the tracker's own numpy references.
    """
    h, w = idepth.shape
    mask = rng.random((h, w)) < fraction
    if variance is None:
        var = np.where(mask, 10.0 ** rng.uniform(-4.0, -2.0, (h, w)), -1.0).astype(np.float32)
        noisy = idepth + rng.standard_normal((h, w)) * np.sqrt(np.maximum(var, 0.0))
    else:
        var = np.where(mask & (variance > 0), variance, -1.0).astype(np.float32)
        noisy = np.where(var > 0, idepth, np.nan)
    d = np.where(mask & (noisy > 1e-3), noisy, -1.0).astype(np.float32)
    var = np.where(d > 0, var, -1.0).astype(np.float32)
    pyr = [(d, var)]
    for _ in range(max(levels)):
        pyr.append(idepth_downsample_numpy(*pyr[-1]))
    dummy = np.zeros((1, 1, 1), np.float32)
    out = {}
    for lvl in levels:
        dl, vl = pyr[lvl]
        cam = camera.level(lvl)
        fd = np.broadcast_to(dummy, (dl.shape[0], dl.shape[1], 1))
        pts, _, vrs, idx = make_points_numpy(dl, vl, fd, cam.fx, cam.fy, cam.cx, cam.cy)
        if len(idx) > max_points:
            keep = np.sort(rng.choice(len(idx), max_points, replace=False))
            pts, vrs, idx = pts[keep], vrs[keep], idx[keep]
        out[lvl] = LevelPoints(pts.astype(np.float64), vrs.astype(np.float64), idx.astype(np.int64))
    return out


def perturb(T: np.ndarray, rng: np.random.Generator, trans: float, rot_deg: float, identity: float) -> np.ndarray:
    """The initial pose: ``T`` perturbed on the left by a random twist, or (with probability ``identity``) I."""
    from dmtrack.geometry.lie import SE3

    if rng.random() < identity:
        return np.eye(4)
    xi = np.r_[rng.normal(0.0, trans, 3), np.deg2rad(rng.normal(0.0, rot_deg, 3))]
    return SE3.exp(xi).matrix() @ T


# ============================================================================================ one pair
def pyramid(fmap: torch.Tensor, n_levels: int) -> list[torch.Tensor]:
    """(K, H, W) map → list of (H_l, W_l, K) levels, level l+1 the 2×2 box mean of level l (as the tracker)."""
    out = [fmap]
    for _ in range(1, n_levels):
        out.append(torch.nn.functional.avg_pool2d(out[-1][None], 2)[0])
    return [f.permute(1, 2, 0).contiguous() for f in out]


def reprojection_distance(
    points: torch.Tensor, T: torch.Tensor, T_true: torch.Tensor, cam: PinholeCamera
) -> torch.Tensor:
    """Per point, the distance (pixels) between its projections under ``T`` and ``T_true``."""

    def project(M: torch.Tensor) -> torch.Tensor:
        X = points @ M[:3, :3].T + M[:3, 3]
        z = torch.clamp(X[:, 2], min=1e-3)
        return torch.stack([cam.fx * X[:, 0] / z, cam.fy * X[:, 1] / z], 1)

    return torch.linalg.norm(project(T) - project(T_true), dim=1)


def robust(d: torch.Tensor, cap: float = 50.0) -> torch.Tensor:
    """√(d² + 1) − 1, capped at ``cap`` (a diverged pair contributes a constant, without gradient)."""
    return torch.clamp(torch.sqrt(d * d + 1.0) - 1.0, max=cap)


def calibrated_gain(net: TrackNet, images: list[np.ndarray], min_use_grad: float = 5.0) -> float:
    """The default scale of ``net`` on ``images`` (grey crops): as many semi-dense pixels as grey (paper §2.4);
    inf when the maps have fewer pixels with a gradient than grey has semi-dense ones."""
    from dmtrack.features.scale import channel_mean_gradient, count_semi_dense, solve_scale

    target = sum(count_semi_dense(np.asarray(im, np.float32)[:, :, None], min_use_grad) for im in images)
    values = []
    dev = next(net.parameters()).device
    with torch.no_grad():
        for im in images:
            f = net(to_tensor(im, dev))[0].permute(1, 2, 0).contiguous().cpu().numpy()
            g = channel_mean_gradient(np.ascontiguousarray(f, np.float32)).ravel()
            values.append(g[g > 0])
    v = np.concatenate(values)
    if target == 0 or v.size < target:
        return float("inf")  # (nearly) constant maps: no scale gives grey's count
    return float(solve_scale(v, int(target), min_use_grad))


def match_gain(net: TrackNet, images: list[np.ndarray], gain: float, rounds: int = 6) -> float:
    """Rescale the last layer's weights (and zero its bias) of a fresh ``net`` so that its default scale on
    ``images`` is ≈ ``gain`` (the output is nearly linear while it is small); returns the default scale reached."""
    last = net.convs[-1]
    with torch.no_grad():
        last.bias.zero_()
    scale = calibrated_gain(net, images)
    for _ in range(rounds):
        if not math.isfinite(scale):
            break
        with torch.no_grad():
            last.weight.mul_(scale / gain)
        scale = calibrated_gain(net, images)
    return scale


def scale_term(fmap: torch.Tensor, grey: np.ndarray, min_use_grad: float = 5.0) -> torch.Tensor:
    """(log q − log 5)², q the (1 − f)-quantile of the (K, H, W) map's channel-mean gradient magnitude (3×3 max,
    interior), f the fraction of the grey image's pixels above ``min_use_grad`` (see the module documentation)."""
    from dmtrack.features.scale import count_semi_dense

    f = fmap.permute(1, 2, 0)
    gx = 0.5 * (f[1:-1, 2:] - f[1:-1, :-2])
    gy = 0.5 * (f[2:, 1:-1] - f[:-2, 1:-1])
    mag = torch.sqrt(gx * gx + gy * gy + 1e-12).mean(-1)
    mx = torch.nn.functional.max_pool2d(mag[None, None], 3, 1, 1)[0, 0].reshape(-1)
    n = count_semi_dense(np.asarray(grey, np.float32)[:, :, None], min_use_grad)
    frac = min(max(n / mx.numel(), 1e-3), 1.0 - 1e-3)
    q = torch.quantile(mx, 1.0 - frac)
    return (torch.log(q + 0.05 * min_use_grad) - math.log(1.05 * min_use_grad)) ** 2


@dataclass
class PairResult:
    loss: torch.Tensor
    init_px: float
    final_px: float
    level_px: list[float]
    ok: bool


def align_pair(
    fk: list[torch.Tensor],
    ff: list[torch.Tensor],
    refs: dict[int, LevelPoints],
    pair: Pair,
    T0: np.ndarray,
    opts: TrainOptions,
    tracker: TrackerConfig,
) -> PairResult:
    """Unroll the steps on one pair's feature pyramids; the loss on the poses after each level."""
    dtype, dev = fk[0].dtype, fk[0].device
    T = torch.tensor(T0, dtype=dtype, device=dev)
    T_true = torch.tensor(pair.T_fk, dtype=dtype, device=dev)
    finest = refs[min(opts.levels)]
    eval_pts = torch.tensor(finest.points, dtype=dtype, device=dev)
    loss = torch.zeros((), dtype=dtype, device=dev)
    with torch.no_grad():
        init_px = float(reprojection_distance(eval_pts, T, T_true, pair.camera).mean())
    level_px = []
    ok = True
    for lvl, its, wl in zip(opts.levels, opts.iterations, opts.level_weights, strict=True):
        lp = refs[lvl]
        feat_k, feat_f = fk[lvl], ff[lvl]
        nch = feat_k.shape[2]
        pts = torch.tensor(lp.points, dtype=dtype, device=dev)
        var = torch.tensor(lp.variances, dtype=dtype, device=dev)
        vals = feat_k.reshape(-1, nch)[torch.from_numpy(lp.index).to(dev)]
        prm = AlignParams.of(pair.camera.level(lvl), tracker, nch)
        packed = pack(feat_f)
        for _ in range(its):
            T, _, ev, solved = lm_step(pts, vals, var, feat_f, T, prm, opts.lam, packed)
            if not solved or ev.n_in < 20:
                ok = False
                break
        d = reprojection_distance(eval_pts, T, T_true, pair.camera)
        loss = loss + wl * robust(d).mean()
        level_px.append(float(d.detach().mean()))
    final_px = level_px[-1] if level_px else init_px
    ok = ok and bool(torch.isfinite(loss))
    return PairResult(loss, init_px, final_px, level_px, ok)


def to_tensor(img: np.ndarray, device: Any = None) -> torch.Tensor:
    """A grey image as a ``(1, 1, H, W)`` float32 tensor (on ``device`` when given)."""
    t = torch.from_numpy(np.asarray(img, np.float32))[None, None]
    return t if device is None else t.to(device)


# ============================================================================================ validation
@dataclass
class ValidationSet:
    pairs: list[Pair]
    refs: list[dict[int, LevelPoints]]
    inits: list[np.ndarray]


def make_validation(opts: TrainOptions) -> ValidationSet:
    """Held-out pairs: other scene seeds (9000 + …), their own generator (independent of the training seed)."""
    rng = np.random.default_rng(9000)
    src = SyntheticPairs(9000, 2, 120, rng, cache=8)
    pairs, refs, inits = [], [], []
    for _ in range(opts.val_pairs):
        p = src.sample(rng, opts.crop, opts.max_gap)
        pairs.append(p)
        refs.append(reference_points(p.idepth, p.camera, opts.levels, rng, opts.point_fraction, opts.max_points))
        inits.append(perturb(p.T_fk, rng, opts.init_trans, opts.init_rot_deg, opts.identity_init))
    return ValidationSet(pairs, refs, inits)


def validate(
    features: Callable[[np.ndarray], torch.Tensor], val: ValidationSet, opts: TrainOptions, tracker: TrackerConfig
) -> dict[str, float]:
    """Mean initial and final reprojection error (pixels) of the unrolled steps on the validation pairs, and the
    fraction of pairs that end within 1 pixel. ``features(image)`` gives the (K, H, W) map of a grey crop."""
    init, final, within = [], [], 0
    n_levels = max(opts.levels) + 1
    with torch.no_grad():
        for p, refs, T0 in zip(val.pairs, val.refs, val.inits, strict=True):
            fk = pyramid(features(p.key_image), n_levels)
            ff = pyramid(features(p.frame_image), n_levels)
            res = align_pair(fk, ff, refs, p, T0, opts, tracker)
            init.append(res.init_px)
            final.append(min(res.final_px, 1e3) if math.isfinite(res.final_px) else 1e3)
            within += res.final_px < 1.0
    n = max(len(init), 1)
    return {
        "init_px": float(np.mean(init)) if init else float("nan"),
        "final_px": float(np.mean(final)) if final else float("nan"),
        "final_px_median": float(np.median(final)) if final else float("nan"),
        "within_1px": within / n,
    }


# ============================================================================================ training
@dataclass
class TrainResult:
    """What :func:`train` did: the files, the steps, the validation before/after, the wall time."""

    out: Path
    steps: int
    seconds: float
    validation: dict[str, dict[str, float]] = field(default_factory=dict)
    files: dict[str, str] = field(default_factory=dict)




def _checkpoint(net: TrackNet, optim: torch.optim.Optimizer, step: int, out: Path, meta: dict[str, Any]) -> None:
    with atomic_path(out / "checkpoint.pt") as tmp:
        model = {k: v.detach().cpu() for k, v in net.state_dict().items()}  # loads anywhere, as the CPU's
        torch.save({"model": model, "optimizer": optim.state_dict(), "step": step}, tmp)
    export_npz(net, out / "tracknet.npz", **meta, steps=step)


def train(out: str | Path, opts: TrainOptions, progress: Callable[[str], None] | None = None) -> TrainResult:
    """Train ``tracknet`` into the folder ``out`` (see the module documentation).

    Raises
    ------
    InputError
        Impossible options.
    OutputError
        ``out`` cannot be written.
    """
    opts.check()
    dev = resolve_device(opts.device) or torch.device("cpu")  # one line naming what is missing for "cuda"
    out = prepare_folder(out)
    say = progress or (lambda _msg: None)
    t_start = time.perf_counter()
    prev_threads = torch.get_num_threads()
    prev_det = torch.are_deterministic_algorithms_enabled()
    prev_numba = numba.get_num_threads()
    torch.set_num_threads(int(opts.threads))
    numba.set_num_threads(min(int(opts.threads), numba.config.NUMBA_NUM_THREADS))
    if dev.type == "cuda":
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")  # deterministic cuBLAS (PyTorch's rule)
        torch.backends.cudnn.benchmark = False
        torch.backends.cudnn.allow_tf32 = False
        torch.backends.cuda.matmul.allow_tf32 = False
    torch.use_deterministic_algorithms(True)
    try:
        return _train(out, opts, say, t_start, dev)
    finally:
        torch.set_num_threads(prev_threads)
        numba.set_num_threads(prev_numba)
        torch.use_deterministic_algorithms(prev_det)


def _train(out: Path, opts: TrainOptions, say: Callable[[str], None], t_start: float, dev: Any) -> TrainResult:
    torch.manual_seed(opts.seed)
    rng = np.random.default_rng(opts.seed)
    net = TrackNet(opts.channels, opts.hidden, opts.kernels).to(dev)
    optim = torch.optim.Adam(net.parameters(), lr=opts.lr)
    tracker = TrackerConfig()
    data = training_pairs(opts, rng, say)
    n_levels = max(opts.levels) + 1
    calib = [data.sample(rng, opts.crop, opts.max_gap).key_image for _ in range(opts.calibration_images)]
    gain = float(opts.gain)
    scale = match_gain(net, calib, gain)

    def meta() -> dict[str, Any]:
        return {"seed": opts.seed, "data": opts.data, "gain": gain, "options": asdict(opts)}

    def net_features(img: np.ndarray) -> torch.Tensor:
        return net(to_tensor(img, dev))[0] * gain

    def grey_features(img: np.ndarray) -> torch.Tensor:
        return to_tensor(img, dev)[0]

    val = make_validation(opts) if opts.val_pairs > 0 else None
    validation: dict[str, dict[str, float]] = {}
    if val is not None:
        validation["grey"] = validate(grey_features, val, opts, tracker)
        validation["initial"] = validate(net_features, val, opts, tracker)
        say(f"validation before: {_fmt(validation['initial'])} (grey: {_fmt(validation['grey'])})")
    rows: list[dict[str, Any]] = []
    budget = opts.minutes * 60.0
    t_loop = time.perf_counter()
    step = 0
    while (opts.steps is None or step < opts.steps) and time.perf_counter() - t_loop < budget:
        if step > 0 and step % opts.calibrate_every == 0:
            scale = calibrated_gain(net, calib)
        optim.zero_grad(set_to_none=True)
        losses, inits, finals, scale_terms = [], [], [], []
        skipped = 0
        for _ in range(opts.batch):
            pair = data.sample(rng, opts.crop, opts.max_gap)
            refs = reference_points(
                pair.idepth, pair.camera, opts.levels, rng, opts.point_fraction, opts.max_points, pair.var
            )
            T0 = perturb(pair.T_fk, rng, opts.init_trans, opts.init_rot_deg, opts.identity_init)
            maps = net(torch.cat([to_tensor(pair.key_image, dev), to_tensor(pair.frame_image, dev)])) * gain
            fk = pyramid(maps[0].to(torch.float64), n_levels)
            ff = pyramid(maps[1].to(torch.float64), n_levels)
            res = align_pair(fk, ff, refs, pair, T0, opts, tracker)
            st = scale_term(maps[0], pair.key_image)
            scale_terms.append(float(st.detach()))
            inits.append(res.init_px)
            if not res.ok:
                skipped += 1
                losses.append(opts.scale_weight * st)
                continue
            finals.append(res.final_px)
            losses.append(res.loss.to(torch.float32) + opts.scale_weight * st)
        gnorm = float("nan")
        loss = torch.stack(losses).mean() if losses else None
        if loss is not None:
            loss.backward()
            gnorm = float(torch.nn.utils.clip_grad_norm_(net.parameters(), 1.0))
            if math.isfinite(gnorm):
                for group in optim.param_groups:
                    group["lr"] = learning_rate(opts, step)
                optim.step()
        step += 1
        rows.append(
            {
                "step": step,
                "seconds": round(time.perf_counter() - t_loop, 3),
                "lr": learning_rate(opts, step - 1),
                "loss": float(loss.detach()) if loss is not None else float("nan"),
                "scale_term": float(np.mean(scale_terms)),
                "default_scale": scale,
                "init_px": float(np.mean(inits)),
                "final_px": float(np.mean(finals)) if finals else float("nan"),
                "grad_norm": gnorm,
                "skipped": skipped,
            }
        )
        if step % opts.checkpoint_every == 0:
            _checkpoint(net, optim, step, out, meta())
            write_log(out, rows)
            recent = rows[-opts.checkpoint_every :]
            say(f"step {step}: loss {np.nanmean([r['loss'] for r in recent]):.3f}, final "
                f"{np.nanmean([r['final_px'] for r in recent]):.2f} px, default scale {scale:.1f} (G {gain:g}) "
                f"({time.perf_counter() - t_loop:.0f} s)")
    _checkpoint(net, optim, step, out, meta())
    if val is not None:
        validation["final"] = validate(net_features, val, opts, tracker)
        say(f"validation after {step} steps: {_fmt(validation['final'])}")
    seconds = time.perf_counter() - t_start
    files = {
        "weights": str(out / "tracknet.npz"),
        "checkpoint": str(out / "checkpoint.pt"),
        "log_csv": str(out / "train_log.csv"),
        "log_json": str(out / "train_log.json"),
    }
    write_log(out, rows)
    png = plot_curve(out, rows)
    if png is not None:
        files["curve"] = str(png)
    summary = {
        "options": asdict(opts),
        "steps": step,
        "seconds": round(seconds, 1),
        "loop_seconds": round(time.perf_counter() - t_loop, 1),
        "gain": gain,
        "default_scale_on_training_crops": calibrated_gain(net, calib),
        "validation": validation,
        "files": files,
    }
    write_text(out / "train_log.json", json.dumps(summary, indent=2, allow_nan=True) + "\n")
    return TrainResult(out, step, seconds, validation, files)


def _fmt(v: dict[str, float]) -> str:
    return (f"{v['init_px']:.2f} px -> mean {v['final_px']:.2f} px, median {v['final_px_median']:.2f} px, "
            f"{100 * v['within_1px']:.0f}% within 1 px")  # fmt: skip


# ============================================================================================ after training
def calibrate_weights(path: str | Path, images: list[np.ndarray | str | Path]) -> dict[str, float]:
    """Calibrate an exported ``tracknet.npz`` like every feature and record the result in its ``meta``.

    The default scale (:func:`dmtrack.features.scale.calibrate_scale_detailed`: as many semi-dense pixels as grey on
    ``images``) and, at that scale, the channel statistics N_E, κ and N_σ of the balanced cost rule
    (:func:`dmtrack.features.scale.measure_channel_statistics`). ``meta`` gets ``scale``, ``energy_channels``,
    ``info_channels``, ``noise_energy_channels`` and ``calibration`` (counts, image count);
    :class:`dmtrack.features.tracknet.TrackNetFeature` reads N_E, κ and N_σ from there. The file is rewritten
    atomically.
    """
    from dmtrack.features.scale import calibrate_scale_detailed, measure_channel_statistics
    from dmtrack.features.tracknet import TrackNetFeature
    from dmtrack.io.images import read_image
    from dmtrack.training.model import npz_bytes

    path = Path(path)
    imgs = [read_image(p) if isinstance(p, (str, Path)) else np.asarray(p) for p in images]
    cal = calibrate_scale_detailed(TrackNetFeature(weights=path), imgs)
    feature = TrackNetFeature(scale=cal.scale, weights=path)
    stats = measure_channel_statistics(feature, imgs)
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: np.asarray(z[k]) for k in z.files}
    meta = json.loads(str(arrays.pop("meta")))
    result = {
        "scale": round(cal.scale, 4),
        "energy_channels": round(stats.energy_channels, 3),
        "info_channels": round(stats.info_channels, 3),
        "noise_energy_channels": round(feature.channels * stats.noise_var / stats.grey_noise_var, 3),
    }
    meta.update(result)
    meta["calibration"] = {"target_count": round(cal.target_count, 1), "achieved_count": round(cal.achieved_count, 1),
                           "images": len(imgs), "noise_channels": round(stats.noise_channels, 2)}  # fmt: skip
    write_bytes(path, npz_bytes(arrays, meta))
    return result

