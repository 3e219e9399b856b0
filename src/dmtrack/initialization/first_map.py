"""The first keyframe's map from a window of frames with known poses, made by the depth map's own stereo.

The first frame becomes a keyframe with an empty :class:`~dmtrack.odometry.depthmap.DepthMap`; each chosen frame
of the window, in order, is then observed into it with its pose (LSD-SLAM's line stereo creates a hypothesis
where there is none and fuses where there is one), followed by the usual hole filling and regularisation. The
poses come from the bundle adjustment of the corner tracks. They can then be refined against the map itself:
every chosen frame is re-aligned to the map with the odometry's tracker (direct alignment on all the semi-dense
pixels, not only the corners) and the map is made again from the new poses (``refine_iterations`` times).

It runs on grey images whatever the run's feature: the start is geometric, and the odometry then tracks every
frame of the window again, with the run's feature, against this map.
"""

from __future__ import annotations

import numpy as np

from dmtrack.features.images import prepare_image
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.odometry.config import VOConfig
from dmtrack.odometry.depthmap import DepthMap
from dmtrack.odometry.frame import Frame, build_frame
from dmtrack.odometry.initial_map import InitialMap
from dmtrack.odometry.tracker import Tracker, TrackingReference

__all__ = ["grey_frame", "make_first_map"]


def grey_frame(index: int, timestamp: float, image: np.ndarray, camera: PinholeCamera, levels: int) -> Frame:
    """A grey :class:`~dmtrack.odometry.frame.Frame` (intensity 0..255, as the ``gray`` feature) of an image."""
    grey = prepare_image(image, colour=False).astype(np.float32)
    return build_frame(index, timestamp, image, grey, camera, levels)


def make_first_map(
    keyframe: Frame,
    frames: list[Frame],
    poses: list[np.ndarray],
    config: VOConfig,
    *,
    parallel: bool = False,
) -> tuple[InitialMap, list[np.ndarray]]:
    """Make the first map; return it (frame indices filled in, ``info`` empty) and the final poses.

    Parameters
    ----------
    keyframe : Frame
        The first frame (grey).
    frames : list of Frame
        The window's frames to observe, in order (grey, same size).
    poses : list of (4, 4)
        Their poses T_i (keyframe → frame i), in any consistent scale.
    config : VOConfig
        ``depth`` (the stereo), ``tracker`` (the refinement) and ``initializer`` (iterations, residual).
    """
    ic = config.initializer
    poses = [np.array(T, np.float64) for T in poses]
    tracker = Tracker(config.tracker, parallel=parallel, channel_cost="sum")
    empty = np.full((keyframe.height, keyframe.width), np.nan)
    for it in range(ic.refine_iterations + 1):
        dm = DepthMap(config.depth, parallel=parallel, channel_cost="sum")
        dm.initialize_from_depth(keyframe, empty)
        for frame, T in zip(frames, poses, strict=True):
            dm.observe(frame, T, None, ic.stereo_residual)
            dm.fill_holes()
            dm.regularize(False, config.depth.val_sum_min_for_keep)
        if it == ic.refine_iterations:
            break
        idepth, var = dm.tracking_depth()
        if not np.any(var > 0):
            break
        ref = TrackingReference.from_keyframe(keyframe, idepth, var, tuple(config.tracker.levels))
        refined = []
        for frame, T in zip(frames, poses, strict=True):
            res = tracker.track(ref, frame, T)
            refined.append(T if res.diverged else np.array(res.T_fk, np.float64))
        poses = refined
    rho = dm.normalize_scale()
    for T in poses:
        T[:3, 3] /= rho  # the keyframe's units: inverse depths × ρ, lengths ÷ ρ
    m = InitialMap(
        frame_index=int(keyframe.index),
        accepted_frame=int(frames[-1].index) if frames else int(keyframe.index),
        valid=dm.valid.copy(),
        idepth=dm.idepth.copy(),
        idepth_var=dm.idepth_var.copy(),
        idepth_smoothed=dm.idepth_smoothed.copy(),
        idepth_var_smoothed=dm.idepth_var_smoothed.copy(),
        validity=dm.validity_counter.copy(),
    )
    return m, poses
