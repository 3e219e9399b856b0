"""Intrinsics from a sequence's own images, without a calibration board (``dmtrack calibrate-from-video``).

The odometry runs with the sliding window estimating the focal length (and, if asked, the principal point) from the
photometric residuals of its keyframes (:mod:`dmtrack.window`, ``window.refine_intrinsics``). One run's estimate is
pulled towards the calibration it was tracked with — the keyframes' poses and depth maps were made with it — so the
run is repeated with each estimate until it changes by less than ``tolerance`` (a fixed point; on 7-Scenes, started at
525 and at 585, both ends meet at 579.3–579.6: docs/window.md). The result is written as the ``fx fy cx cy`` file that
``dmtrack run --intrinsics FILE`` reads.
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

    def to_dict(self) -> dict[str, Any]:
        """A plain dict (JSON)."""
        return dataclasses.asdict(self)


def write_intrinsics(calib: SelfCalibration, path: str | Path, source: str) -> Path:
    """Write ``fx fy cx cy`` (the format :func:`~dmtrack.datasets.intrinsics.read_intrinsics_file` reads), with
    comment lines saying where they came from."""
    p = Path(path)
    text = (f"# dmtrack calibrate-from-video {source}: pinhole intrinsics of the {calib.width}x{calib.height} images\n"
            f"# estimated from the images (sliding-window photometric bundle adjustment), "
            f"{'converged' if calib.converged else 'NOT converged'} after {len(calib.history)} runs\n"
            f"{calib.fx:.4f} {calib.fy:.4f} {calib.cx:.4f} {calib.cy:.4f}\n")  # fmt: skip
    write_text(p, text)
    return p


def calibrate_from_video(
    sequence: str | Path,
    feature: str = "gray",
    intrinsics: str | None = None,
    *,
    model: str = "f",
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
        of 0.8 × the width (a field of view of about 64°, a phone's) and the image centre.
    model
        ``"f"`` (one focal length, the principal point kept), ``"f-c"`` or ``"fxfy-c"`` (``WindowConfig``).
    start, max_frames
        The frames used.
    iterations, tolerance
        At most this many runs; stop when the focal length changes by less than ``tolerance`` (relative).
    window
        Keyframes in the window.
    config
        Odometry parameters (its ``window`` section is replaced).
    on_iteration
        Called with each iteration's record (progress).

    Raises
    ------
    InputError
        If the sequence cannot be read or the odometry could not estimate anything (no keyframe change).
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


def _size(seq: Any) -> tuple[int, int]:
    if seq.camera is not None:
        return int(seq.camera.width), int(seq.camera.height)
    frame = seq[0]
    h, w = frame.image.shape[:2]
    return int(w), int(h)
