"""The files a run writes (``dmtrack run … --out DIR``), as an :class:`~dmtrack.odometry.sink.OutputSink`.

=====================  =====================================================================================
``trajectory.txt``     TUM format, T_wc, one line per tracked frame with the dataset's timestamp. Written
                       line by line and flushed, so a killed run keeps every frame it finished.
``keyframes.txt``      the same for the keyframes (appended when each keyframe's depth map is final).
``pointcloud.ply``     semi-dense points of all keyframes in the world frame, coloured by the image. Each
                       keyframe's points go to a temporary file as the keyframe comes (memory holds one
                       keyframe's); ``pointcloud.ply`` appears, atomically, when the run closes, also after a
                       tracking loss or an interrupt (:class:`~dmtrack.io.ply.PlyStream`).
``depth/``             one picture per keyframe: inverse depth over the dimmed image, negative inverse
                       depths in magenta (:func:`dmtrack.viz.depth.inverse_depth_image`), each written atomically
                       as a palette PNG (:func:`dmtrack.viz.depth.write_depth_png`: the same RGB when decoded);
                       and ``initial_map.png``, the first keyframe's map as the start left it (random, geometric
                       or ground truth), before any frame was mapped into it.
``metrics.json``       written by the caller (:func:`dmtrack.pipeline.run_to_directory`), not by the sink.
=====================  =====================================================================================

A file that cannot be written (disk full, read-only folder) raises :class:`~dmtrack.errors.OutputError` naming it;
for the point cloud, :meth:`RunDirectorySink.close` raises it (the run goes on, as when the cloud was kept in memory
and written at the end), after writing the keyframes before the failed one if it can.
"""

from __future__ import annotations

from pathlib import Path
from typing import IO

import numpy as np

from dmtrack.errors import OutputError
from dmtrack.io.atomic import output_error, prepare_folder, remove_stale_temporaries
from dmtrack.io.ply import PlyStream
from dmtrack.io.trajectory import tum_line
from dmtrack.odometry.sink import KeyframeSnapshot
from dmtrack.viz.depth import inverse_depth_codes, write_depth_png

TUM_HEADER = "# timestamp tx ty tz qx qy qz qw  (camera-to-world, TUM format)\n"
#: The picture of the first keyframe's map as the start made it, in ``depth/``.
INITIAL_MAP_PNG = "initial_map.png"


class _LineFile:
    """A text file written line by line and flushed after each line; OS errors name the file."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self._f: IO[str] = open(path, "w", encoding="utf-8")  # noqa: SIM115
        except OSError as exc:
            raise output_error(path, exc) from None

    def write(self, text: str) -> None:
        try:
            self._f.write(text)
            self._f.flush()
        except OSError as exc:
            raise output_error(self.path, exc) from None

    def close(self) -> None:
        try:
            self._f.close()
        except OSError as exc:
            raise output_error(self.path, exc) from None


class RunDirectorySink:
    """Writes a run's outputs into ``out_dir`` (created if needed; earlier outputs are replaced).

    Parameters
    ----------
    depth_images : write ``depth/kf_NNNN_frame_NNNNNN.png`` per keyframe.
    pointcloud : write ``pointcloud.ply``.
    max_point_var : keep only points whose inverse-depth variance is at most this (keyframe units);
        ``None`` keeps every hypothesis.
    suffix : appended to the names of ``trajectory``, ``keyframes`` and ``pointcloud`` (``"_vo"`` for a SLAM run,
        whose plain names hold the optimised results; :mod:`dmtrack.outputs.slam_files`).
    """

    def __init__(
        self,
        out_dir: str | Path,
        depth_images: bool = True,
        pointcloud: bool = True,
        max_point_var: float | None = None,
        suffix: str = "",
    ) -> None:
        self.out_dir = prepare_folder(out_dir)
        remove_stale_temporaries(self.out_dir)
        self.depth_dir = self.out_dir / "depth"
        self.depth_images = depth_images
        self.pointcloud = pointcloud
        self.max_point_var = max_point_var
        if depth_images:
            prepare_folder(self.depth_dir)
            remove_stale_temporaries(self.depth_dir)
            for old in [*self.depth_dir.glob("kf_*.png"), *self.depth_dir.glob(INITIAL_MAP_PNG)]:
                old.unlink()
        self._traj = _LineFile(self.out_dir / f"trajectory{suffix}.txt")
        self._kfs = _LineFile(self.out_dir / f"keyframes{suffix}.txt")
        self._traj.write(TUM_HEADER)
        self._kfs.write(TUM_HEADER)
        self._cloud = PlyStream(self.out_dir / f"pointcloud{suffix}.ply") if pointcloud else None
        self._cloud_error: OutputError | None = None  # the first keyframe whose points could not be written
        self.n_frames = 0
        self.n_keyframes = 0
        self.lost: list[tuple[int, str]] = []
        self._closed = False

    def on_frame(self, frame_index: int, timestamp: float, T_wc: np.ndarray) -> None:
        self._traj.write(tum_line(timestamp, T_wc))
        self.n_frames += 1

    def on_keyframe(
        self,
        keyframe_id: int,
        frame_index: int,
        timestamp: float,
        T_wc: np.ndarray,
        depthmap_snapshot: KeyframeSnapshot,
    ) -> None:
        snap = depthmap_snapshot
        self._kfs.write(tum_line(timestamp, T_wc))
        self.n_keyframes += 1
        if self._cloud is not None and self._cloud_error is None:
            try:
                self._cloud.append(*snap.points_world(self.max_point_var))
            except OutputError as e:  # as for a cloud held in memory: the run goes on, close() reports it
                self._cloud_error = e
        if self.depth_images and snap.image is not None:
            codes = inverse_depth_codes(snap.idepth, snap.valid, snap.image)
            write_depth_png(self.depth_dir / f"kf_{keyframe_id:04d}_frame_{frame_index:06d}.png", codes)

    def on_initial_map(self, snapshot: KeyframeSnapshot) -> None:
        """The first keyframe's map as the start made it: ``depth/initial_map.png``."""
        if self.depth_images and snapshot.image is not None:
            codes = inverse_depth_codes(snapshot.idepth, snapshot.valid, snapshot.image)
            write_depth_png(self.depth_dir / INITIAL_MAP_PNG, codes)

    def on_lost(self, frame_index: int, reason: str) -> None:
        self.lost.append((frame_index, reason))

    def close(self) -> None:
        """Close the line files, then write the point cloud (every step is tried; the first error is raised — a
        keyframe whose points could not be written counts as an error of the point cloud)."""
        if self._closed:
            return
        self._closed = True
        errors: list[OutputError] = []
        for f in (self._traj, self._kfs):
            try:
                f.close()
            except OutputError as e:
                errors.append(e)
        if self._cloud_error is not None:
            errors.append(self._cloud_error)
        if self._cloud is not None:
            try:
                self._cloud.close()  # the keyframes before a failed one, if it can
            except OutputError as e:
                errors.append(e)
        if errors:
            raise errors[0]

    @property
    def n_points(self) -> int:
        """Points written to the point cloud so far (0 without one)."""
        return 0 if self._cloud is None else self._cloud.n_points
