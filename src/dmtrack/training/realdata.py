"""Training pairs from a real sequence with ground-truth poses (``dmtrack train-feature --data 7scenes``).

The depth of a training keyframe is the odometry's own semi-dense map: LSD-SLAM's grey stereo and depth filter
(:class:`~dmtrack.odometry.depthmap.DepthMap`, default :class:`~dmtrack.odometry.config.DepthConfig`), started from
the seeded random initialisation and fed the ``mapping_frames`` frames *before* the keyframe at their ground-truth
poses. The depth therefore lives where the tracker's points live (textured pixels) and has the errors the tracker's
depth has. Of the dataset's depth images (for 7-Scenes not registered to the colour camera) only the keyframe's
median is used: it sets the scale of the random initial depth, since the poses, and so the mapped depth, are
metric.

Only pixels that at least one observation updated are kept (the others still hold the random initial depth).

A pair is (keyframe K, frame K + g), g = 1 … ``max_gap``: only frames *after* the keyframe, so that no frame that
made the depth is the frame a pair aligns. Its variance is the map's (the noise is the map's own: nothing is
added, unlike the synthetic pairs' exact depth).

Which sequences: the issue's rule is that the test sequences (tsukuba-150, KITTI 06) are never training data; the
shared 7-Scenes frames (0–699) are the intended input. 7-Scenes is licensed for non-commercial research use only:
weights trained on it inherit that restriction (see ``dmtrack/weights/TRACKNET.md``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dmtrack.errors import InputError
from dmtrack.geometry.camera import PinholeCamera


@dataclass
class Pair:
    """A training pair: grey crops, the keyframe's inverse depth, the crop camera and the true T_fk; ``var``: the
    inverse depth's variance where it is an estimate (real data; NaN depth = none), ``None`` for exact depth."""

    key_image: np.ndarray
    frame_image: np.ndarray
    idepth: np.ndarray
    camera: PinholeCamera
    T_fk: np.ndarray
    var: np.ndarray | None = None


@dataclass
class Keyframe:
    """One training keyframe: its frame index, the map's inverse depth and variance (NaN / −1 where none)."""

    index: int
    idepth: np.ndarray
    var: np.ndarray


@dataclass(frozen=True)
class DepthSummary:
    """How good the mapped depth is, against the dataset's depth images where it has them (unregistered for
    7-Scenes: a rough check, not a ground truth). ``rel_error`` is the median of |d / d_sensor − 1|."""

    keyframes: int
    points_median: float
    rel_error: float | None


class SequencePairs:
    """Seeded training pairs from a real sequence (see the module documentation).

    Parameters
    ----------
    path : str
        A sequence folder :func:`~dmtrack.datasets.open_sequence` reads, with ground-truth poses.
    seed : int
        Seeds the random initial depth of every keyframe's map.
    keyframe_every : int
        Frames between two training keyframes.
    mapping_frames : int
        Frames before a keyframe mapped into its depth.
    max_gap : int
        Largest distance from the keyframe to the pair's other frame.
    max_frames : int, optional
        Use only the first ``max_frames`` frames.
    intrinsics : str, optional
        Intrinsics replacing the dataset's (as ``dmtrack run --intrinsics``).
    say : callable, optional
        Progress lines.
    """

    def __init__(
        self,
        path: str,
        seed: int,
        keyframe_every: int = 10,
        mapping_frames: int = 12,
        max_gap: int = 8,
        max_frames: int | None = None,
        say: Callable[[str], None] | None = None,
        intrinsics: str | None = None,
    ):
        from dmtrack.datasets import open_sequence
        from dmtrack.features import get_feature
        from dmtrack.features.images import prepare_image
        from dmtrack.odometry.config import DepthConfig, VOConfig
        from dmtrack.odometry.depthmap import DepthMap
        from dmtrack.odometry.frame import build_frame

        seq = open_sequence(path, intrinsics=intrinsics)
        if not seq.has_groundtruth:
            raise InputError("training pairs need ground-truth poses; this sequence has none", path=path)
        if seq.camera is None:
            raise InputError("training pairs need the camera intrinsics; this sequence has none", path=path)
        n = len(seq) if max_frames is None else min(len(seq), int(max_frames))
        if n < mapping_frames + max_gap + 1:
            raise InputError(f"{n} frames: too few for {mapping_frames} mapping frames and gaps up to {max_gap}",
                             path=path)  # fmt: skip
        self.camera: PinholeCamera = seq.camera
        self.max_gap = int(max_gap)
        grey = get_feature("gray")
        levels = VOConfig().pyramid_levels
        self.images: list[np.ndarray] = []
        poses: list[np.ndarray | None] = []
        read = getattr(seq, "read_frame", None)  # a loader reads the image alone (no depth PNG decoded)
        for i in range(n):
            fr = read(i, depth=False) if read is not None else seq[i]
            self.images.append(prepare_image(fr.image, colour=False))
            ok = fr.pose is not None and np.all(np.isfinite(fr.pose))
            poses.append(np.asarray(fr.pose, np.float64) if ok else None)
        self.poses = poses

        def frame(i: int):  # noqa: ANN202
            img = self.images[i]
            return build_frame(i, float(i), img, grey.compute(img), self.camera, levels, True)

        self.keyframes: list[Keyframe] = []
        rel_errors: list[float] = []
        counts: list[int] = []
        for k in range(mapping_frames, n - max_gap, keyframe_every):
            need = range(k - mapping_frames, k + max_gap + 1)
            if any(poses[i] is None for i in need):
                continue
            sensor = seq[k].depth
            have = None if sensor is None else np.isfinite(sensor) & (sensor > 0)
            if have is None or have.sum() < 100:
                raise InputError(f"frame {k} has no depth image: its median sets the scale of the initial map",
                                 path=path)  # fmt: skip
            sensor = np.asarray(sensor, np.float64)
            dm = DepthMap(DepthConfig())
            dm.initialize_random(frame(k), seed * 100_003 + k)
            # LSD-SLAM's random initial inverse depth (0.5 … 1.5) is meant for a world whose scale the odometry
            # chooses; mapped at metric ground-truth poses it must start at the scene's scale, or the depth filter
            # rejects the observations as inconsistent
            c = 1.0 / float(np.median(sensor[have]))
            c32 = np.float32(c)
            dm.scale_idepth(c, float(c32 * c32))  # variances × float32(c)·float32(c): as the packaged weights were made
            T_wk = poses[k]
            for f in range(k - mapping_frames, k):
                T_fk = np.linalg.inv(poses[f]) @ T_wk  # type: ignore[operator]
                dm.update(frame(f), T_fk)
            d, v = dm.tracking_depth()
            # pixels no observation reached still hold their random initial depth: not a depth estimate
            observed = dm.idepth_var < 0.5 * c * c * dm.config.var_random_init_initial
            keep = (d > 0) & observed
            idepth = np.where(keep, d, np.nan).astype(np.float32)
            var = np.where(keep, v, -1.0).astype(np.float32)
            self.keyframes.append(Keyframe(k, idepth, var))
            counts.append(int(keep.sum()))
            m = keep & have
            if m.sum() > 100:
                rel_errors.append(float(np.median(np.abs(1.0 / (d[m] * sensor[m]) - 1.0))))
            if say is not None and len(self.keyframes) % 10 == 0:
                say(f"training depth: {len(self.keyframes)} keyframes mapped")
        if not self.keyframes:
            raise InputError("no frame has ground-truth poses for itself and its neighbours", path=path)
        self.summary = DepthSummary(
            len(self.keyframes),
            float(np.median(counts)),
            float(np.median(rel_errors)) if rel_errors else None,
        )

    @property
    def width(self) -> int:
        return self.camera.width

    @property
    def height(self) -> int:
        return self.camera.height

    def sample(self, rng: np.random.Generator, crop: tuple[int, int], max_gap: int) -> Pair:
        """A :class:`Pair` (random keyframe, gap and crop; ``max_gap`` at most the one
        the depth was built for)."""
        kf = self.keyframes[int(rng.integers(len(self.keyframes)))]
        gap = int(rng.integers(1, min(max_gap, self.max_gap) + 1))
        k = kf.index
        cw, ch = crop
        x0 = int(rng.integers(0, (self.width - cw) // 8 + 1)) * 8
        y0 = int(rng.integers(0, (self.height - ch) // 8 + 1)) * 8
        T_fk = np.linalg.inv(self.poses[k + gap]) @ self.poses[k]  # type: ignore[operator]
        cam = self.camera
        win = (slice(y0, y0 + ch), slice(x0, x0 + cw))
        return Pair(
            key_image=np.ascontiguousarray(self.images[k][win]),
            frame_image=np.ascontiguousarray(self.images[k + gap][win]),
            idepth=np.ascontiguousarray(kf.idepth[win]),
            camera=PinholeCamera(cam.fx, cam.fy, cam.cx - x0, cam.cy - y0, cw, ch),
            T_fk=T_fk,
            var=np.ascontiguousarray(kf.var[win]),
        )


class MixedPairs:
    """Pairs drawn from ``a`` with probability ``p_a``, else from ``b`` (one random draw decides)."""

    def __init__(self, a, b, p_a: float = 0.5):  # noqa: ANN001
        self.a, self.b, self.p_a = a, b, float(p_a)

    def sample(self, rng: np.random.Generator, crop: tuple[int, int], max_gap: int):  # noqa: ANN201
        src = self.a if rng.random() < self.p_a else self.b
        return src.sample(rng, crop, max_gap)
