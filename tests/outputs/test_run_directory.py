"""The run folder's point cloud, streamed keyframe by keyframe (:class:`~dmtrack.io.ply.PlyStream`): the same bytes as
the cloud of every keyframe joined in memory, a valid file of the finished keyframes after an interrupt or a crash,
and no temporary file left."""

from __future__ import annotations

import json
import signal
from pathlib import Path

import numpy as np
import pytest

from dmtrack.io.ply import VERTEX_DTYPE, read_ply, write_ply
from dmtrack.odometry.sink import KeyframeSnapshot
from dmtrack.outputs import MemorySink
from dmtrack.pipeline import run_to_directory

N_FRAMES = 45  # four keyframes of the sample


class Watcher(MemorySink):
    """Runs after the run folder's sink: checks, at each keyframe, that its points are on disk already (in the
    temporary file, not in memory) while ``pointcloud.ply`` does not exist yet; can stop the run at a keyframe
    (``how``: ``"interrupt"`` sends Ctrl-C, ``"crash"`` raises at the next frame)."""

    def __init__(self, out: Path, stop_at: int | None = None, how: str = "") -> None:
        super().__init__()
        self.out, self.stop_at, self.how = out, stop_at, how
        self.body_sizes: list[tuple[int, int]] = []

    def on_keyframe(self, keyframe_id: int, frame_index: int, timestamp: float, T_wc: np.ndarray,
                    depthmap_snapshot: KeyframeSnapshot) -> None:
        super().on_keyframe(keyframe_id, frame_index, timestamp, T_wc, depthmap_snapshot)
        bodies = list(self.out.glob(".pointcloud.ply.*.tmp"))
        assert len(bodies) == 1 and not (self.out / "pointcloud.ply").exists()
        n = sum(len(k.points_world()[0]) for k in self.keyframes)
        self.body_sizes.append((bodies[0].stat().st_size, n * VERTEX_DTYPE.itemsize))
        if keyframe_id == self.stop_at and self.how == "interrupt":
            signal.raise_signal(signal.SIGINT)  # Ctrl-C: the run stops after this frame

    def on_frame(self, frame_index: int, timestamp: float, T_wc: np.ndarray) -> None:
        super().on_frame(frame_index, timestamp, T_wc)
        if self.how == "crash" and self.keyframes and self.keyframes[-1].keyframe_id == self.stop_at:
            raise RuntimeError("a sink that breaks after a keyframe")


def _cloud_in_memory(sink: MemorySink, path: Path) -> bytes:
    """The point cloud as it was written before streaming: every keyframe's points joined, then written at once."""
    points = [k.points_world() for k in sink.keyframes]
    write_ply(path, np.concatenate([p.astype(np.float32) for p, _ in points]), np.concatenate([c for _, c in points]))
    return path.read_bytes()


def _temporaries(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*") if p.name.endswith(".tmp"))


def test_streamed_cloud_equals_the_cloud_in_memory(tmp_path: Path, sample_dir: Path) -> None:
    out = tmp_path / "run"
    out.mkdir()
    watcher = Watcher(out)
    result = run_to_directory(sample_dir, out, max_frames=N_FRAMES, depth_images=False, extra_sinks=(watcher,),
                              init="random")  # the keyframe cadence these tests were written for
    assert len(watcher.keyframes) >= 3 and result.metrics["keyframes"] == len(watcher.keyframes)
    assert all(size == expected for size, expected in watcher.body_sizes)
    assert (out / "pointcloud.ply").read_bytes() == _cloud_in_memory(watcher, tmp_path / "memory.ply")
    assert result.metrics["points"] == sum(len(k.points_world()[0]) for k in watcher.keyframes)
    assert _temporaries(tmp_path) == []


@pytest.mark.parametrize("how", ["interrupt", "crash"])
def test_a_stopped_run_leaves_the_cloud_of_its_keyframes(tmp_path: Path, sample_dir: Path, how: str) -> None:
    out = tmp_path / "run"
    out.mkdir()
    watcher = Watcher(out, stop_at=1, how=how)
    error = KeyboardInterrupt if how == "interrupt" else RuntimeError
    with pytest.raises(error):
        run_to_directory(sample_dir, out, max_frames=N_FRAMES, depth_images=False, extra_sinks=(watcher,),
                              init="random")  # the keyframe cadence these tests were written for
    # keyframe 1, and the keyframe in progress when the run stopped (finished by the odometry's close)
    assert [k.keyframe_id for k in watcher.keyframes] == [0, 1, 2]
    points, colours = read_ply(out / "pointcloud.ply")
    assert len(points) == sum(len(k.points_world()[0]) for k in watcher.keyframes) and colours is not None
    assert (out / "pointcloud.ply").read_bytes() == _cloud_in_memory(watcher, tmp_path / "memory.ply")
    assert _temporaries(tmp_path) == []
    if how == "interrupt":  # the metrics of the finished frames are written too
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["interrupted"] == "SIGINT" and metrics["points"] == len(points)
        assert metrics["processed_frames"] < N_FRAMES
