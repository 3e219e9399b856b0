"""The synthetic sequence: camera trajectory, photometric disturbances and :class:`SyntheticSequence`.

:class:`SyntheticSequence` implements the :class:`~dmtrack.datasets.base.Sequence` protocol: a smooth
6-DoF trajectory (:func:`make_trajectory`) that stays in the free space in the middle of the room and looks
at the textured surfaces, frames rendered lazily and identically whatever the order of access, and
optional photometric disturbances — a global gain/offset following a smooth curve, a moving spotlight
(local illumination change) and per-frame seeded Gaussian sensor noise.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dmtrack.datasets.base import Frame
from dmtrack.datasets.synthetic.renderer import render
from dmtrack.datasets.synthetic.scene import Scene, make_scene
from dmtrack.errors import InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.trajectory import Trajectory

__all__ = ["SyntheticConfig", "SyntheticSequence", "make_forward_trajectory", "make_trajectory"]


# =========================================================================================== trajectory
def _look_rotation(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(N, 3, 3) camera-to-world rotations (OpenCV camera axes, world z up).

    The camera looks along ``(cos p cos y, cos p sin y, sin p)``, its x axis horizontal to the right and
    y axis down when ``roll = 0``; ``roll`` turns it about its optical axis.
    """
    cp, sp = np.cos(pitch), np.sin(pitch)
    cyw, syw = np.cos(yaw), np.sin(yaw)
    fwd = np.stack([cp * cyw, cp * syw, sp], axis=-1)
    right = np.stack([syw, -cyw, np.zeros_like(yaw)], axis=-1)  # fwd × z_up, normalised
    down = np.cross(fwd, right)
    cr, sr = np.cos(roll)[:, None], np.sin(roll)[:, None]
    x_c = cr * right + sr * down
    y_c = -sr * right + cr * down
    return np.stack([x_c, y_c, fwd], axis=-1)


@dataclass(frozen=True)
class _TrajectoryShape:
    """Sinusoid coefficients of a trajectory as a function of the path parameter u (radians)."""

    pos_amp: np.ndarray  # (3, K)
    pos_freq: np.ndarray  # (3, K)
    pos_phase: np.ndarray  # (3, K)
    ang_amp: np.ndarray  # (3, K): yaw, pitch, roll
    ang_freq: np.ndarray
    ang_phase: np.ndarray
    yaw0: float
    pitch0: float


def _trajectory_shape(seed: int, free_radius: float, free_half_height: float, view_yaw: float) -> _TrajectoryShape:
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x7A3C]))
    K = 3
    freq = np.array([1.0, 1.618, 2.414])
    pos_freq = np.stack([freq * rng.uniform(0.85, 1.15, K) for _ in range(3)])
    # horizontal amplitudes sum to ≤ 0.6·free_radius (the path stays well inside the free cylinder)
    w = rng.uniform(0.5, 1.0, size=(2, K)) * np.array([1.0, 0.5, 0.25])
    horiz = 0.6 * free_radius / np.sqrt(2.0) * w / w.sum(axis=1, keepdims=True)
    wz = rng.uniform(0.5, 1.0, size=K) * np.array([1.0, 0.5, 0.25])
    vert = 0.7 * free_half_height * wz / wz.sum()
    pos_amp = np.vstack([horiz, vert[None]])
    pos_phase = rng.uniform(0.0, 2 * math.pi, size=(3, K))
    ang_freq = np.stack([freq * rng.uniform(0.6, 0.9, K) for _ in range(3)])
    ang_amp = np.array([[0.35, 0.15, 0.05], [0.10, 0.04, 0.02], [0.06, 0.03, 0.0]]) * rng.uniform(0.7, 1.0, size=(3, K))
    ang_phase = rng.uniform(0.0, 2 * math.pi, size=(3, K))
    return _TrajectoryShape(
        pos_amp, pos_freq, pos_phase, ang_amp, ang_freq, ang_phase,
        yaw0=view_yaw + float(rng.uniform(-0.2, 0.2)), pitch0=float(rng.uniform(-0.2, -0.05)),
    )  # fmt: skip


def _sinusoids(u: np.ndarray, amp: np.ndarray, freq: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """(N, 3): Σ_k amp[i,k] sin(freq[i,k] u + phase[i,k]) for each row i."""
    return np.einsum("ik,nik->ni", amp, np.sin(freq[None] * u[:, None, None] + phase[None]))


def make_trajectory(seed: int, n_frames: int, fps: float, speed: float, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """A smooth 6-DoF camera trajectory inside the free space of ``scene``.

    Position: sums of three sinusoids per axis of a path parameter u (incommensurate frequencies, seeded
    phases and amplitudes) around ``scene.free_centre``, within 60 % of the free radius horizontally and
    70 % of the free half height vertically.  Orientation: a heading near ``scene.view_yaw`` plus
    sinusoidal yaw (≲ ±30°), pitch (looking slightly down, ±8°) and roll (±5°).  u advances so that the
    mean speed of the camera centre over a long run is ``speed`` (the instantaneous speed varies around it;
    rotation rates scale with it too).

    Parameters
    ----------
    seed : trajectory seed (independent stream from the scene's).
    n_frames : number of poses.
    fps : frames per second; frame i is at time i / fps seconds.
    speed : mean speed of the camera centre, metres per second (0 → a static camera).
    scene : gives the free space.

    Returns
    -------
    timestamps : (N,) float64 seconds.
    poses : (N, 4, 4) float64 camera-to-world T_wc.
    """
    if n_frames < 1 or fps <= 0 or speed < 0:
        raise InputError(f"need n_frames ≥ 1, fps > 0, speed ≥ 0 (got {n_frames}, {fps}, {speed})")
    shape = _trajectory_shape(seed, scene.free_radius, scene.free_half_height, scene.view_yaw)
    # mean |dp/du| over a long stretch of u (numerically; the path is not periodic)
    uu = np.linspace(0.0, 200.0, 20001)
    dp = np.einsum(
        "ik,nik->ni",
        shape.pos_amp * shape.pos_freq,
        np.cos(shape.pos_freq[None] * uu[:, None, None] + shape.pos_phase[None]),
    )
    mean_rate = float(np.linalg.norm(dp, axis=1).mean())
    t = np.arange(n_frames, dtype=np.float64) / fps
    u = t * (speed / mean_rate)
    pos = scene.free_centre + _sinusoids(u, shape.pos_amp, shape.pos_freq, shape.pos_phase)
    ang = _sinusoids(u, shape.ang_amp, shape.ang_freq, shape.ang_phase)
    R = _look_rotation(shape.yaw0 + ang[:, 0], shape.pitch0 + ang[:, 1], ang[:, 2])
    poses = np.tile(np.eye(4), (n_frames, 1, 1))
    poses[:, :3, :3] = R
    poses[:, :3, 3] = pos
    return t, poses


def make_forward_trajectory(
    seed: int, n_frames: int, fps: float, speed: float, scene: Scene
) -> tuple[np.ndarray, np.ndarray]:
    """A driving-like trajectory: the camera moves forward along the room's long (x) axis at ``speed``, looking
    ahead (the focus of expansion near the image centre), with a slow seeded weave of the heading (±3°), a lane
    change-like sideways drift (±0.25 m) and a small bounce — the motion of a car's camera, for which the image
    corners leave the picture within a few frames while the centre shows little parallax.

    It starts 1 m inside the room's −x wall at eye height 1.4 m (or mid-height in a low room) and must stop 2 m
    before the far wall (an :class:`~dmtrack.errors.InputError` otherwise: a longer room or fewer frames).
    Returns (timestamps, poses) as :func:`make_trajectory`.
    """
    if n_frames < 1 or fps <= 0 or speed < 0:
        raise InputError(f"need n_frames ≥ 1, fps > 0, speed ≥ 0 (got {n_frames}, {fps}, {speed})")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0xF0D]))
    t = np.arange(n_frames, dtype=np.float64) / fps
    lo, hi = scene.room_lo, scene.room_hi
    x0 = float(lo[0]) + 1.0
    end = x0 + speed * float(t[-1])
    if end > float(hi[0]) - 2.0:
        raise InputError(
            f"a forward run of {n_frames} frames at {speed} m/s ({fps} fps) needs a room longer than "
            f"{end + 2.0 - float(lo[0]):.1f} m in x (room_size)"
        )
    ph = rng.uniform(0.0, 2 * math.pi, 4)
    fr = rng.uniform(0.8, 1.2, 4)
    half_w = 0.5 * float(hi[1] - lo[1])
    pos = np.zeros((n_frames, 3))
    pos[:, 0] = x0 + speed * t
    pos[:, 1] = 0.5 * (lo[1] + hi[1]) + min(0.25, 0.3 * half_w) * np.sin(0.35 * fr[0] * t + ph[0])
    pos[:, 2] = min(1.4, 0.5 * float(hi[2])) + 0.02 * np.sin(2.1 * fr[1] * t + ph[1])
    yaw = 0.05 * np.sin(0.5 * fr[2] * t + ph[2])
    pitch = -0.03 + 0.01 * np.sin(1.3 * fr[3] * t + ph[3])
    R = _look_rotation(yaw, pitch, np.zeros(n_frames))
    poses = np.tile(np.eye(4), (n_frames, 1, 1))
    poses[:, :3, :3] = R
    poses[:, :3, 3] = pos
    return t, poses


#: Defaults of the settings that depend on the motion: ``orbit`` (a room) and ``forward`` (a long, empty hall).
_MOTION_DEFAULTS = {
    "orbit": {"room_size": (6.0, 5.0, 2.8), "n_boxes": 6, "n_planes": 2},
    "forward": {"room_size": (30.0, 5.0, 3.0), "n_boxes": 0, "n_planes": 0},
}


# ======================================================================================== the sequence
@dataclass(frozen=True)
class SyntheticConfig:
    """Everything that defines a synthetic sequence (frame i depends on nothing else).

    Attributes
    ----------
    width, height : image size, pixels.
    fx, fy : focal lengths, pixels; ``None`` → 525 · width / 640 (TUM-like field of view at any size).
    cx, cy : principal point, pixels; ``None`` → the image centre ((width − 1)/2, (height − 1)/2).
    n_frames : number of frames.
    fps : frames per second (timestamps are i / fps seconds).
    seed : seeds the scene, the trajectory, the illumination curves and the noise.
    colour : RGB frames (H, W, 3) instead of grey (H, W).
    speed : mean camera speed, metres per second.
    global_illumination : amplitude A of the global change: gain(t) = 1 + A·g(t), offset(t) = 40·A·o(t)
        grey levels, where g, o ∈ [−1, 1] are smooth seeded sums of sinusoids (periods of 2–12 s).
    local_illumination : amplitude L of a spotlight: per-pixel gain 1 − L/2 + L·s, s ∈ [0, 1] the
        near-Gaussian cone profile (σ ≈ 20°) of a light mounted 0.4 m beside the camera, aimed near the
        view direction with a slow seeded wobble, so the lighting of a surface changes as the camera moves.
    noise_sigma : standard deviation of additive Gaussian sensor noise, grey levels (0..255); frame i
        always gets the same noise.
    motion : ``"orbit"`` — a smooth hand-held-like path in the middle of a room (:func:`make_trajectory`) — or
        ``"forward"`` — driving-like forward motion down a long hall (:func:`make_forward_trajectory`; give it
        ``fps=10``, ``speed=1`` for a car's camera in a city at that scale).
    room_size : inside extents of the room, metres (``None``: the motion's default, 6 × 5 × 2.8 m for ``orbit``,
        30 × 5 × 3 m for ``forward``).
    n_boxes, n_planes : objects inside the room (``None``: 6 and 2 for ``orbit``, none in the hall of
        ``forward``, where they would stand in the way).
    texel : texture resolution, metres.
    blur : texture pre-filter width, pixels (see :func:`render`).
    name : sequence name; ``None`` → ``"synthetic-seed<seed>"``.
    """

    width: int = 640
    height: int = 480
    fx: float | None = None
    fy: float | None = None
    cx: float | None = None
    cy: float | None = None
    n_frames: int = 300
    fps: float = 30.0
    seed: int = 0
    colour: bool = False
    speed: float = 0.3
    global_illumination: float = 0.0
    local_illumination: float = 0.0
    noise_sigma: float = 0.0
    motion: str = "orbit"
    room_size: tuple[float, float, float] | None = None
    n_boxes: int | None = None
    n_planes: int | None = None
    texel: float = 0.01
    blur: float = 1.5
    name: str | None = None

    def camera(self) -> PinholeCamera:
        """The pinhole camera of the frames."""
        fx = 525.0 * self.width / 640.0 if self.fx is None else float(self.fx)
        fy = fx if self.fy is None else float(self.fy)
        cx = (self.width - 1) / 2.0 if self.cx is None else float(self.cx)
        cy = (self.height - 1) / 2.0 if self.cy is None else float(self.cy)
        return PinholeCamera(fx, fy, cx, cy, int(self.width), int(self.height))

    def validate(self) -> None:
        """Raise :class:`~dmtrack.errors.InputError` on impossible settings."""
        if self.width < 1 or self.height < 1:
            raise InputError(f"image size must be positive, got {self.width}x{self.height}")
        if self.n_frames < 1 or self.fps <= 0 or self.speed < 0:
            raise InputError("n_frames must be ≥ 1, fps > 0 and speed ≥ 0")
        if self.noise_sigma < 0 or self.global_illumination < 0 or self.local_illumination < 0:
            raise InputError("noise_sigma and the illumination amplitudes must be ≥ 0")
        if self.local_illumination > 2.0:
            raise InputError("local_illumination must be ≤ 2 (the gain 1 − L/2 would go negative)")
        if self.motion not in _MOTION_DEFAULTS:
            raise InputError(f"motion must be one of {', '.join(_MOTION_DEFAULTS)}, got {self.motion!r}")

    def setting(self, name: str) -> Any:
        """``room_size``, ``n_boxes`` or ``n_planes`` as given, or the motion's default."""
        value = getattr(self, name)
        return _MOTION_DEFAULTS[self.motion][name] if value is None else value


@dataclass(frozen=True)
class _Photometry:
    """Seeded coefficients of the smooth illumination curves."""

    gain_f: np.ndarray = field(repr=False)
    gain_p: np.ndarray = field(repr=False)
    off_f: np.ndarray = field(repr=False)
    off_p: np.ndarray = field(repr=False)
    spot_f: np.ndarray = field(repr=False)
    spot_p: np.ndarray = field(repr=False)


def _photometry(seed: int) -> _Photometry:
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x11AB]))

    # angular frequencies (rad/s) of periods 2..12 s
    def f(n: int) -> np.ndarray:
        return 2 * math.pi / rng.uniform(2.0, 12.0, size=n)

    return _Photometry(
        gain_f=f(3), gain_p=rng.uniform(0, 2 * math.pi, 3),
        off_f=f(3), off_p=rng.uniform(0, 2 * math.pi, 3),
        spot_f=f(4), spot_p=rng.uniform(0, 2 * math.pi, 4),
    )  # fmt: skip


class SyntheticSequence:
    """A lazily rendered synthetic sequence (implements :class:`~dmtrack.datasets.base.Sequence`).

    Parameters
    ----------
    config : what to render; see :class:`SyntheticConfig`.

    Frames carry ``image`` (uint8 grey (H, W) or RGB (H, W, 3)), the exact ``pose`` T_wc and the exact
    ``depth`` (float32 metres, valid > 0 at every pixel).  Frame i is a pure function of the config and
    i: rendering it first or after any others gives identical arrays.

    ``lens`` is the camera the frames are rendered with (the configuration's: ``fx=…`` in a ``synthetic:`` string);
    ``camera`` is the one the odometry is told. They are the same unless ``camera`` is replaced (``--intrinsics``):
    the images stay the same, so a wrong calibration can be tried on them against the known ``lens``.
    """

    format = "synthetic"

    def __init__(self, config: SyntheticConfig | None = None, *, _frames: np.ndarray | None = None) -> None:
        config = SyntheticConfig() if config is None else config
        config.validate()
        self.config = config
        self.name = config.name if config.name is not None else f"synthetic-seed{config.seed}"
        # the camera the images are rendered with (the configuration's) and the one the odometry is told, which
        # ``--intrinsics`` replaces (so a wrong calibration can be tried on the same images)
        self.lens = config.camera()
        self.camera: PinholeCamera | None = self.lens
        self.scene = make_scene(
            config.seed,
            colour=config.colour,
            room_size=tuple(float(v) for v in config.setting("room_size")),
            n_boxes=int(config.setting("n_boxes")),
            n_planes=int(config.setting("n_planes")),
            texel=config.texel,
        )
        trajectory = make_forward_trajectory if config.motion == "forward" else make_trajectory
        t, poses = trajectory(config.seed, config.n_frames, config.fps, config.speed, self.scene)
        # frame indices into the full trajectory (a slice keeps the original timestamps, poses and noise)
        self._frames = np.arange(config.n_frames) if _frames is None else np.asarray(_frames, np.int64)
        self._all_t = t
        self._all_poses = poses
        self._photo = _photometry(config.seed)
        self._rays = self.lens.pixel_grid_rays().astype(np.float32)  # (H, W, 3) z = 1 rays

    # -- protocol -------------------------------------------------------------------------------
    @property
    def width(self) -> int:
        return int(self.config.width)

    @property
    def height(self) -> int:
        return int(self.config.height)

    @property
    def timestamps(self) -> np.ndarray:
        """(N,) float64 seconds."""
        return self._all_t[self._frames].copy()

    @property
    def poses(self) -> np.ndarray:
        """(N, 4, 4) float64 ground-truth T_wc of every frame."""
        return self._all_poses[self._frames].copy()

    @property
    def groundtruth(self) -> Trajectory:
        return Trajectory(self.timestamps, self.poses)

    @property
    def has_groundtruth(self) -> bool:
        return True

    @property
    def has_depth(self) -> bool:
        """Every frame carries its exact depth."""
        return True

    def __len__(self) -> int:
        return int(self._frames.shape[0])

    def _absolute(self, index: int) -> int:
        n = len(self)
        if not isinstance(index, (int, np.integer)):
            raise TypeError(f"frame index must be an int, got {type(index).__name__}")
        if not -n <= index < n:
            raise IndexError(f"frame {index} out of range for a sequence of {n} frames")
        return int(self._frames[int(index) % n])

    def __getitem__(self, index: int) -> Frame:
        k = self._absolute(index)
        radiance, depth = self._render(k)
        image = np.clip(np.rint(radiance), 0, 255).astype(np.uint8)
        return Frame(int(index) % len(self), float(self._all_t[k]), image, self._all_poses[k].copy(), depth)

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self[i]

    def slice(self, start: int = 0, stop: int | None = None) -> SyntheticSequence:
        """Frames ``start:stop`` as a new sequence (indices restart at 0; timestamps, poses, noise kept)."""
        n = len(self)
        stop = n if stop is None else min(stop, n)
        if not 0 <= start < n:
            raise InputError(f"start frame {start} is outside the sequence (0..{n - 1})")
        if stop <= start:
            raise InputError(f"empty frame range {start}:{stop}")
        part = SyntheticSequence(self.config, _frames=self._frames[start:stop])
        part.camera = self.camera  # what the odometry is told stays what it was
        return part

    def __repr__(self) -> str:
        c = self.config
        return (
            f"{type(self).__name__}(name={self.name!r}, frames={len(self)}, size={self.width}x{self.height}, "
            f"colour={c.colour}, speed={c.speed}, global_illumination={c.global_illumination}, "
            f"local_illumination={c.local_illumination}, noise_sigma={c.noise_sigma})"
        )

    # -- extras ---------------------------------------------------------------------------------
    def depth(self, index: int) -> np.ndarray:
        """Exact depth of frame ``index``: (H, W) float32 metres."""
        k = self._absolute(index)
        return render(self.scene, self.lens, self._all_poses[k], blur=self.config.blur)[1]

    def inverse_depth(self, index: int) -> np.ndarray:
        """Exact inverse depth of frame ``index``: (H, W) float32, 1/metres."""
        return (1.0 / self.depth(index)).astype(np.float32)

    def gain_offset(self, index: int) -> tuple[float, float]:
        """Global illumination (gain, offset in grey levels) applied to frame ``index``."""
        return self._gain_offset(self._absolute(index))

    def _gain_offset(self, k: int) -> tuple[float, float]:
        A = self.config.global_illumination
        if A == 0.0:
            return 1.0, 0.0
        t = self._all_t[k]
        p = self._photo
        g = float(np.mean(np.sin(p.gain_f * t + p.gain_p)))
        o = float(np.mean(np.sin(p.off_f * t + p.off_p)))
        return 1.0 + A * g, 40.0 * A * o

    def _spot_gain(self, k: int, depth: np.ndarray) -> np.ndarray:
        """(H, W) float32 local gain of the spotlight at frame k: 1 − L/2 + L·s, s ∈ [0, 1].

        The light rides with the camera (computed in the camera frame): it sits 0.4 m from the optical
        centre in the image plane, at a slowly wobbling angle, and is aimed near the optical axis.  Its
        profile is s = exp(−(1 − cos α)/σ²) ≈ exp(−α²/2σ²) with α the angle off the beam axis and
        σ ≈ 0.35 rad, so a surface point's lighting changes as the camera moves.
        """
        amp = np.float32(self.config.local_illumination)
        t = self._all_t[k]
        p = self._photo
        wob = np.sin(p.spot_f * t + p.spot_p)
        src = np.array([0.4 * math.cos(wob[0]), 0.4 * math.sin(wob[0]), 0.0], np.float32)
        aim = np.array([0.35 * wob[1], 0.25 * wob[2], 1.0])
        aim = (aim / np.linalg.norm(aim)).astype(np.float32)
        v = self._rays * depth[..., None] - src
        cosang = (v @ aim) / np.sqrt(np.einsum("hwc,hwc->hw", v, v))
        sigma = 0.35 * (1.0 + 0.3 * wob[3])
        s = np.exp((cosang - np.float32(1.0)) * np.float32(1.0 / sigma**2))
        return (np.float32(1.0) - amp / 2 + amp * s).astype(np.float32)

    def radiance(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Frame ``index`` before quantisation: float32 (H, W) or (H, W, 3) intensity on the 0..255 scale
        with illumination and noise applied but not rounded or clipped, and the (H, W) float32 depth.

        ``frame.image`` is ``clip(rint(radiance), 0, 255)`` as uint8.
        """
        return self._render(self._absolute(index))

    def _render(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`radiance` of frame ``k`` of the full (unsliced) trajectory."""
        img, depth = render(self.scene, self.lens, self._all_poses[k], blur=self.config.blur)
        if self.config.local_illumination > 0.0:
            g = self._spot_gain(k, depth)
            img = img * (g if img.ndim == 2 else g[..., None])
        gain, offset = self._gain_offset(k)
        if gain != 1.0 or offset != 0.0:
            img = np.float32(gain) * img + np.float32(offset)
        if self.config.noise_sigma > 0.0:
            rng = np.random.default_rng(np.random.SeedSequence([int(self.config.seed), 0x0153, int(k)]))
            img = img + np.float32(self.config.noise_sigma) * rng.standard_normal(img.shape, dtype=np.float32)
        return img.astype(np.float32), depth
