"""The first keyframe's map from a window of frames with known poses, made by the depth map's own stereo.

The first frame becomes a keyframe with an empty :class:`~dmtrack.odometry.depthmap.DepthMap`; each chosen frame
of the window, in order, is then observed into it with its pose (LSD-SLAM's line stereo creates a hypothesis
where there is none and fuses where there is one), followed by the usual hole filling and regularisation. The
poses come from the bundle adjustment of the corner tracks and are used as they are: re-aligning the window's frames
photometrically to the map and making it again (1–2 rounds) was measured and did not help (docs/initialization.md).

It runs on grey images whatever the run's feature: the start is geometric, and the odometry then tracks every
frame of the window again, with the run's feature, against this map.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from dmtrack.features.images import prepare_image
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.odometry.config import VOConfig
from dmtrack.odometry.initial_map import InitialMap

if TYPE_CHECKING:
    from dmtrack.odometry.frame import Frame

# the depth map's and the frames' modules (numba's kernels) are imported when the first map is made, not with this
# module: a run's start reads and tracks its first frames while the main thread imports them

__all__ = ["grey_frame", "make_first_map"]


def grey_frame(index: int, timestamp: float, image: np.ndarray, camera: PinholeCamera, levels: int,
               use_numba: bool = True) -> Frame:  # fmt: skip
    """A grey :class:`~dmtrack.odometry.frame.Frame` (intensity 0..255, as the ``gray`` feature) of an image."""
    from dmtrack.odometry.frame import build_frame

    grey = prepare_image(image, colour=False).astype(np.float32)
    return build_frame(index, timestamp, image, grey, camera, levels, use_numba)


def make_first_map(
    keyframe: Frame,
    frames: list[Frame],
    poses: list[np.ndarray],
    config: VOConfig,
    *,
    parallel: bool = False,
) -> tuple[InitialMap, list[np.ndarray]]:
    """Make the first map; return it (frame indices filled in, ``info`` empty) and the poses in its units.

    Parameters
    ----------
    keyframe : Frame
        The first frame (grey).
    frames : list of Frame
        The window's frames to observe, in order (grey, same size).
    poses : list of (4, 4)
        Their poses T_i (keyframe → frame i), in any consistent scale.
    config : VOConfig
        ``depth`` (the stereo) and ``initializer.stereo_residual``.

    Returns
    -------
    InitialMap, list of (4, 4)
        The map (mean inverse depth 1) and the same poses with their translations in the map's units.
    """
    from dmtrack.odometry.depthmap import DepthMap

    ic = config.initializer
    poses = [np.array(T, np.float64) for T in poses]
    dm = DepthMap(config.depth, parallel=parallel, channel_cost="sum")
    dm.initialize_from_depth(keyframe, np.full((keyframe.height, keyframe.width), np.nan))
    for frame, T in zip(frames, poses, strict=True):
        dm.observe(frame, T, None, ic.stereo_residual)
        dm.fill_holes()
        dm.regularize(False, config.depth.val_sum_min_for_keep)
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
