"""The files a run writes (``dmtrack run … --out DIR``), as an :class:`~dmtrack.odometry.sink.OutputSink`.

=====================  =====================================================================================
``trajectory.txt``     TUM format, T_wc, one line per tracked frame with the dataset's timestamp. Written
                       line by line and flushed, so a killed run keeps every frame it finished.
``keyframes.txt``      the same for the keyframes (appended when each keyframe's depth map is final).
``pointcloud.ply``     semi-dense points of all keyframes in the world frame, coloured by the image
                       (written when the run closes, also after a tracking loss or an interrupt).
``depth/``             one picture per keyframe: inverse depth over the dimmed image, negative inverse
                       depths in magenta (:func:`dmtrack.viz.depth.inverse_depth_image`).
``metrics.json``       written by the caller (:func:`dmtrack.api.run_to_directory`), not by the sink.
=====================  =====================================================================================
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dmtrack.geometry.lie import matrix_to_quaternion
from dmtrack.io.ply import write_ply
from dmtrack.odometry.sink import KeyframeSnapshot
from dmtrack.viz.depth import inverse_depth_image, write_png


def tum_line(timestamp: float, T_wc: np.ndarray) -> str:
    """One TUM line; the same formatting as :func:`dmtrack.io.trajectory.format_tum` (byte-repeatable)."""
    q = matrix_to_quaternion(T_wc[:3, :3])
    values = (*T_wc[:3, 3], *q)
    return f"{timestamp:.6f} " + " ".join(f"{v:.9g}" for v in values) + "\n"


class RunDirectorySink:
    """Writes a run's outputs into ``out_dir`` (created if needed; earlier outputs are replaced).

    Parameters
    ----------
    depth_images : write ``depth/kf_NNNN_frame_NNNNNN.png`` per keyframe.
    pointcloud : write ``pointcloud.ply``.
    max_point_var : keep only points whose inverse-depth variance is at most this (keyframe units);
        ``None`` keeps every hypothesis.
    """

    def __init__(
        self,
        out_dir: str | Path,
        depth_images: bool = True,
        pointcloud: bool = True,
        max_point_var: float | None = None,
    ) -> None:
        self.out_dir = Path(out_dir)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.depth_dir = self.out_dir / "depth"
        self.depth_images = depth_images
        self.pointcloud = pointcloud
        self.max_point_var = max_point_var
        if depth_images:
            self.depth_dir.mkdir(exist_ok=True)
            for old in self.depth_dir.glob("kf_*.png"):
                old.unlink()
        self._traj = open(self.out_dir / "trajectory.txt", "w", encoding="utf-8")  # noqa: SIM115
        self._kfs = open(self.out_dir / "keyframes.txt", "w", encoding="utf-8")  # noqa: SIM115
        header = "# timestamp tx ty tz qx qy qz qw  (camera-to-world, TUM format)\n"
        self._traj.write(header)
        self._kfs.write(header)
        self._points: list[np.ndarray] = []
        self._colours: list[np.ndarray] = []
        self.n_frames = 0
        self.n_keyframes = 0
        self.lost: list[tuple[int, str]] = []
        self._closed = False

    def on_frame(self, frame_index: int, timestamp: float, T_wc: np.ndarray) -> None:
        self._traj.write(tum_line(timestamp, T_wc))
        self._traj.flush()
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
        self._kfs.flush()
        self.n_keyframes += 1
        if self.pointcloud:
            pts, cols = snap.points_world(self.max_point_var)
            self._points.append(pts.astype(np.float32))
            self._colours.append(cols)
        if self.depth_images and snap.image is not None:
            picture = inverse_depth_image(snap.idepth, snap.valid, snap.image)
            write_png(self.depth_dir / f"kf_{keyframe_id:04d}_frame_{frame_index:06d}.png", picture)

    def on_lost(self, frame_index: int, reason: str) -> None:
        self.lost.append((frame_index, reason))

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._traj.close()
        self._kfs.close()
        if self.pointcloud:
            pts = np.concatenate(self._points) if self._points else np.zeros((0, 3), np.float32)
            cols = np.concatenate(self._colours) if self._colours else np.zeros((0, 3), np.uint8)
            write_ply(self.out_dir / "pointcloud.ply", pts, cols)

    @property
    def n_points(self) -> int:
        return int(sum(p.shape[0] for p in self._points))
