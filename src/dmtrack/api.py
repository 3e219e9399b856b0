"""The Python API: track a sequence with a feature and get poses, keyframes, timings and metrics.

>>> import dmtrack
>>> result = dmtrack.track("data/7scenes-redkitchen-0000-0299", feature="gray", max_frames=100)  # doctest: +SKIP
>>> result.trajectory, result.tracked_frames, result.metrics["rpe_rot_deg_per_m"]                # doctest: +SKIP

:func:`track` runs the odometry and returns a :class:`RunResult`; :func:`run_to_directory` also writes the
files of ``dmtrack run`` (``trajectory.txt``, ``keyframes.txt``, ``pointcloud.ply``, ``depth/``,
``metrics.json``).
"""

from __future__ import annotations

from dmtrack.datasets import open_sequence
from dmtrack.pipeline import RunResult, metrics_dict, run_to_directory, track, track_many

__all__ = ["RunResult", "metrics_dict", "open_sequence", "run_to_directory", "track", "track_many"]
