"""Intrinsics from a sequence's own images, without a calibration board (``dmtrack calibrate-from-video``).

Three methods (``method``):

* ``"tracks"`` (the default): the odometry runs once with the starting guess; corners are tracked over every
  ``step``-th tracked frame and a self-calibrating bundle adjustment (:mod:`dmtrack.calibration`) moves those
  keyframes' poses, the corners' points and the focal length — and with ``model="f-k1"`` the first radial distortion
  coefficient — together, from the odometry's poses. On rendered sequences it comes back from 10 % off to within
  0.1 % (docs/window.md); the result does not depend on the start.
* ``"groundtruth"``: the same adjustment with the keyframes' poses fixed at the sequence's ground truth (any scale):
  only the points and the intrinsics move. It tells the focal length that a dataset's own poses and images agree on
  — a check of the calibration a dataset documents (on Tsukuba, 622 px where 615 is documented; docs/window.md).
* ``"window"``: the odometry runs with the sliding window estimating the focal length (and, if asked, the principal
  point) from the photometric residuals of its keyframes (:mod:`dmtrack.window`, ``window.refine_intrinsics``). One
  run's estimate is pulled towards the calibration it was tracked with, so the run is repeated with each estimate
  until it changes by less than ``tolerance`` (a fixed point). On rendered sequences it barely moves from where it
  started (docs/window.md).

The result is written as the ``fx fy cx cy`` file that ``dmtrack run --intrinsics FILE`` reads, or, with k1, as a
4-line ``RadTan`` calibration file (DSO's format, which ``--intrinsics`` also reads: the frames are undistorted).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dmtrack.errors import InputError
from dmtrack.io.atomic import write_text
from dmtrack.odometry.config import VOConfig

__all__ = ["SelfCalibration", "calibrate_from_video", "write_intrinsics"]


@dataclass
class SelfCalibration:
    """The estimate (level-0 pixels of the images as stored: ``fx, fy, cx, cy``), its standard deviation from the last
    run's window (optimistic: it takes the windows as independent), whether the iteration converged, and each
    iteration's start, estimate and tracked frames."""

    fx: float
    fy: float
    cx: float
    cy: float
    sigma: dict[str, float | None]
    converged: bool
    width: int
    height: int
    history: list[dict[str, Any]] = field(default_factory=list)
    k1: float = 0.0
    method: str = "window"
    model: str = "f"

    def to_dict(self) -> dict[str, Any]:
        """A plain dict (JSON)."""
        return dataclasses.asdict(self)


def write_intrinsics(calib: SelfCalibration, path: str | Path, source: str) -> Path:
    """Write the estimate: ``fx fy cx cy`` with comment lines saying where they came from (the format
    :func:`~dmtrack.datasets.intrinsics.read_intrinsics_file` reads); with a radial coefficient (model ``"f-k1"``),
    the 4-line ``RadTan`` calibration file of DSO, whose format has no comments, with its output camera written out
    (:func:`_radtan_output`)."""
    p = Path(path)
    if calib.model == "f-k1":
        from dmtrack.datasets.undistort import radtan_text

        model = _radtan_model(calib)
        write_text(p, radtan_text(model, _radtan_output(model)))
        return p
    how = {"tracks": "self-calibrating bundle adjustment of corner tracks",
           "groundtruth": "bundle adjustment of corner tracks on the ground-truth poses"}.get(
        calib.method, "sliding-window photometric bundle adjustment")  # fmt: skip
    runs = f"{len(calib.history)} {'runs' if calib.method == 'window' else 'passes'}"
    text = (f"# dmtrack calibrate-from-video {source}: pinhole intrinsics of the {calib.width}x{calib.height} images\n"
            f"# estimated from the images ({how}), "
            f"{'converged' if calib.converged else 'NOT converged'} after {runs}\n"
            f"{calib.fx:.4f} {calib.fy:.4f} {calib.cx:.4f} {calib.cy:.4f}\n")  # fmt: skip
    write_text(p, text)
    return p


def calibrate_from_video(
    sequence: str | Path,
    feature: str = "gray",
    intrinsics: str | None = None,
    *,
    model: str = "f",
    method: str = "tracks",
    step: int = 5,
    start: int = 0,
    max_frames: int | None = None,
    iterations: int = 6,
    tolerance: float = 0.002,
    window: int = 5,
    config: VOConfig | None = None,
    on_iteration: Callable[[dict[str, Any]], None] | None = None,
) -> SelfCalibration:
    """Estimate a sequence's intrinsics from its images (see the module docstring).

    Parameters
    ----------
    sequence
        Anything :func:`dmtrack.track` reads (a video, an image folder, a dataset).
    feature
        The feature tracked with (grey by default).
    intrinsics
        The starting guess ``"fx,fy,cx,cy"`` or a file; None: the sequence's own, or, if it has none, a focal length
        of 0.8 × the width (a field of view of about 64°, a phone's) and the image centre. With a file that
        undistorts (DSO's format), the tracks method estimates the camera of the undistorted images.
    model
        ``"tracks"``, ``"groundtruth"``: ``"f"`` (one focal length, the principal point kept) or ``"f-k1"`` (also
        k1). ``"window"``:
        ``"f"``, ``"f-c"`` or ``"fxfy-c"`` (``WindowConfig``).
    method
        ``"tracks"``, ``"groundtruth"`` or ``"window"`` (see the module docstring).
    step
        ``"tracks"``: every ``step``-th tracked frame is a keyframe of the adjustment; ``"groundtruth"``: every
        ``step``-th frame with a ground-truth pose.
    start, max_frames
        The frames used.
    iterations, tolerance
        ``"window"``: at most this many runs; stop when the focal length changes by less than ``tolerance``.
    window
        ``"window"``: keyframes in the window.
    config
        Odometry parameters (its ``window`` section is replaced).
    on_iteration
        Called with each iteration's record (progress).

    Raises
    ------
    InputError
        If the sequence cannot be read, the odometry could not estimate anything (no keyframe change), or, with
        ``"groundtruth"``, the sequence has too few ground-truth poses.
    """
    from dmtrack.datasets import open_sequence
    from dmtrack.pipeline import track

    seq = open_sequence(str(sequence), intrinsics=intrinsics) if intrinsics else open_sequence(str(sequence))
    width, height = _size(seq)
    if seq.camera is not None:
        K = [seq.camera.fx, seq.camera.fy, seq.camera.cx, seq.camera.cy]
    else:
        K = [0.8 * width, 0.8 * width, (width - 1) / 2.0, (height - 1) / 2.0]
    base = config or VOConfig()
    if method == "tracks":
        given = intrinsics or ",".join(f"{v:.6f}" for v in K)  # a calibration file as it is (it may undistort)
        return _calibrate_tracks(seq, str(sequence), feature, given, K, (width, height), model, step, start,
                                 max_frames, base, on_iteration)  # fmt: skip
    if method == "groundtruth":
        return _calibrate_groundtruth(seq, str(sequence), K, (width, height), model, step, start, max_frames,
                                      on_iteration)  # fmt: skip
    if method != "window":
        raise InputError(f"calibrate-from-video: method must be 'tracks', 'groundtruth' or 'window', not {method!r}")
    cfg = dataclasses.replace(base, window=dataclasses.replace(base.window, size=window, refine_intrinsics=True,
                                                               intrinsics_model=model))  # fmt: skip
    history: list[dict[str, Any]] = []
    sigma: dict[str, float | None] = {}
    converged = False
    for it in range(1, iterations + 1):
        guess = ",".join(f"{v:.6f}" for v in K)
        result = track(str(sequence), feature, cfg, start=start, max_frames=max_frames, intrinsics=guess)
        info = (result.vo.window or {}) if result.vo is not None else {}
        est = info.get("intrinsics")
        if not est:
            raise InputError(f"{sequence}: the odometry made no keyframe change to estimate the intrinsics from "
                             f"(tracked {result.tracked_frames} of {result.total_frames} frames)")  # fmt: skip
        left = (width - result.metrics["width"]) // 2  # the run crops to a multiple of 16, centred
        top = (height - result.metrics["height"]) // 2
        new = [est["fx"], est["fy"], est["cx"] + left, est["cy"] + top]
        change = abs(new[0] / K[0] - 1.0)
        record = {"iteration": it, "start": K, "estimate": new, "change": change,
                  "tracked_frames": result.tracked_frames, "total_frames": result.total_frames}  # fmt: skip
        history.append(record)
        if on_iteration is not None:
            on_iteration(record)
        K = new
        sigma = dict(info.get("intrinsics_sigma") or {})
        if change < tolerance:
            converged = True
            break
    return SelfCalibration(K[0], K[1], K[2], K[3], sigma, converged, width, height, history)


def _radtan_model(calib: SelfCalibration) -> Any:
    """The estimate as a RadTan model (k1 only); an estimate that is not one (not finite) is a clear error, and no
    file is written."""
    from dmtrack.geometry.distortion import RadTanModel

    try:
        return RadTanModel(calib.fx, calib.fy, calib.cx, calib.cy, calib.width, calib.height, calib.k1, 0.0, 0.0, 0.0)
    except ValueError as e:
        raise InputError(f"the estimate is not a camera ({e}): no calibration file written") from None


def _radtan_output(model: Any) -> str:
    """Line 3 of the ``RadTan`` file: ``crop``'s output camera written out (DSO's own ``crop`` folds the image of a
    k1 < 0 lens; :func:`~dmtrack.datasets.undistort.crop_output_line`), or ``crop`` where none is valid."""
    from dmtrack.datasets.undistort import crop_output_line
    from dmtrack.errors import DatasetError

    try:
        return crop_output_line(model, (model.width, model.height))
    except (DatasetError, InputError, ValueError):
        return "crop"  # no valid crop: the reader says why


def _size(seq: Any) -> tuple[int, int]:
    if seq.camera is not None:
        return int(seq.camera.width), int(seq.camera.height)
    frame = seq[0]
    h, w = frame.image.shape[:2]
    return int(w), int(h)


def _calibrate_tracks(
    seq: Any, source: str, feature: str, given: str, K: list[float], size: tuple[int, int], model: str, step: int,
    start: int, max_frames: int | None, config: VOConfig, on_iteration: Callable[[dict[str, Any]], None] | None,
) -> SelfCalibration:  # fmt: skip
    """The ``"tracks"`` method: the odometry's poses once (on ``seq``'s images, with the calibration ``given``, whose
    pinhole part is ``K``), then :func:`dmtrack.calibration.self_calibrate` on the same images."""
    import numpy as np

    from dmtrack.calibration import MODELS
    from dmtrack.pipeline import track

    if model not in MODELS:
        raise InputError(f"calibrate-from-video: the tracks method estimates {' or '.join(MODELS)}, not {model!r}")
    if step < 1:
        raise InputError(f"calibrate-from-video: step must be at least 1, not {step}")
    result = track(source, feature, dataclasses.replace(config, window=dataclasses.replace(config.window, size=0)),
                   start=start, max_frames=max_frames, intrinsics=given)  # fmt: skip
    frames = np.asarray(result.frame_indices)[::step]
    poses = np.asarray(result.trajectory.poses)[::step]
    if len(frames) < 3:
        raise InputError(f"{source}: the odometry tracked {result.tracked_frames} of {result.total_frames} frames, "
                         f"too few for 3 keyframes {step} frames apart")  # fmt: skip
    extra = {"tracked_frames": result.tracked_frames, "total_frames": result.total_frames}
    return _adjust(seq, source, frames, poses, K, size, model, on_iteration, extra)


def _calibrate_groundtruth(
    seq: Any, source: str, K: list[float], size: tuple[int, int], model: str, step: int, start: int,
    max_frames: int | None, on_iteration: Callable[[dict[str, Any]], None] | None,
) -> SelfCalibration:  # fmt: skip
    """The ``"groundtruth"`` method: every ``step``-th frame of ``start …`` that has a ground-truth pose (timed within
    10 ms), those poses fixed, :func:`dmtrack.calibration.self_calibrate` on the points and the intrinsics."""
    import numpy as np

    from dmtrack.calibration import MODELS
    from dmtrack.io.association import associate

    if model not in MODELS:
        raise InputError(f"calibrate-from-video: the groundtruth method estimates {' or '.join(MODELS)}, not "
                         f"{model!r}")  # fmt: skip
    if step < 1:
        raise InputError(f"calibrate-from-video: step must be at least 1, not {step}")
    gt = seq.groundtruth
    if gt is None or len(gt) == 0:
        raise InputError(f"{source}: no ground-truth poses, which the groundtruth method needs (--method tracks "
                         "estimates the intrinsics from the images alone)")  # fmt: skip
    stop = len(seq) if max_frames is None else min(len(seq), start + max_frames)
    # each frame with the pose timed nearest to it within 10 ms, one to one (the evaluation's association, TUM's)
    i_frame, i_gt = associate(np.asarray(seq.timestamps, np.float64)[start:stop], np.asarray(gt.timestamps), 0.01)
    frames = (start + i_frame)[::step]
    poses = np.asarray(gt.poses)[i_gt][::step]
    if len(frames) < 3:
        raise InputError(f"{source}: {len(frames)} frames {step} apart with a ground-truth pose in frames {start}–"
                         f"{stop - 1}; the groundtruth method needs 3")  # fmt: skip
    extra = {"groundtruth_frames": len(frames)}
    return _adjust(seq, source, frames, poses, K, size, model, on_iteration, extra, fixed_poses=True)


def _adjust(
    seq: Any, source: str, frames: Any, poses: Any, K: list[float], size: tuple[int, int], model: str,
    on_iteration: Callable[[dict[str, Any]], None] | None, extra: dict[str, Any], fixed_poses: bool = False,
) -> SelfCalibration:  # fmt: skip
    """Corner tracks over ``frames`` (camera-to-world ``poses``: the first guess, or fixed) and the adjustment."""
    import numpy as np

    from dmtrack.calibration import self_calibrate, track_keyframes

    obs = track_keyframes(seq[int(i)].image for i in frames)
    R = np.swapaxes(poses[:, :3, :3], 1, 2)  # camera from world
    t = -np.einsum("nij,nj->ni", R, poses[:, :3, 3])
    try:
        bundle = self_calibrate(R, t, obs, K[0], K[2], K[3], model=model, fixed_poses=fixed_poses)
    except ValueError as e:
        raise InputError(f"{source}: {e} ({len(frames)} keyframes, {len(obs)} corner observations)") from None
    history = [{**rec, "iteration": rec["pass"], "start": K, "keyframes": len(frames), **extra}
               for rec in bundle.passes]  # fmt: skip
    for rec in history:
        if on_iteration is not None:
            on_iteration(rec)
    sigma = {"fx": bundle.sigma_f, "fy": bundle.sigma_f}
    if bundle.sigma_k1 is not None:
        sigma["k1"] = bundle.sigma_k1
    return SelfCalibration(bundle.f, bundle.f, K[2], K[3], sigma, bundle.converged, size[0], size[1], history,
                           k1=bundle.k1, method="groundtruth" if fixed_poses else "tracks", model=model)  # fmt: skip
