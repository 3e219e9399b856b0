"""The optional sink method ``on_frame_info``: what the odometry hands out, MultiSink's forwarding, and that a sink
without it sees exactly the same run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dmtrack.api import track
from dmtrack.odometry.sink import FrameInfo
from dmtrack.outputs import MemorySink, MultiSink

N_FRAMES = 12


class InfoSink(MemorySink):
    """A MemorySink that also records the per-frame information (copies of what it keeps)."""

    def __init__(self) -> None:
        super().__init__()
        self.infos: list[FrameInfo] = []
        self.writeable: list[bool] = []
        self.overlays: list[tuple[np.ndarray, np.ndarray]] = []

    def on_frame_info(self, info: FrameInfo) -> None:
        self.infos.append(info)
        arrays = (info.image, info.T_wc, info.keyframe_idepth, info.keyframe_idepth_var, info.keyframe_image)
        self.writeable.append(any(a.flags.writeable for a in arrays if a is not None))
        self.overlays.append((info.keyframe_idepth.copy(), info.keyframe_valid.copy()))


@pytest.fixture(scope="module")
def runs(sample_dir: Path) -> tuple[MemorySink, MemorySink, InfoSink, object]:
    plain = MemorySink()
    r_plain = track(sample_dir, max_frames=N_FRAMES, sink=plain)
    fanned, info = MemorySink(), InfoSink()
    r_info = track(sample_dir, max_frames=N_FRAMES, sink=MultiSink(fanned, info))
    assert r_plain.trajectory.poses.tobytes() == r_info.trajectory.poses.tobytes()
    return plain, fanned, info, r_info


def test_multisink_exposes_frame_info_only_when_a_child_has_it(runs: tuple) -> None:
    assert not hasattr(MultiSink(MemorySink(), MemorySink()), "on_frame_info")
    assert not hasattr(MultiSink(), "on_frame_info")
    got = InfoSink()
    nested = MultiSink(MemorySink(), MultiSink(MemorySink(), got))
    info = runs[2].infos[4]
    nested.on_frame_info(info)
    assert got.infos == [info]


def test_frame_info_per_processed_frame(runs: tuple) -> None:
    plain, fanned, info, result = runs
    # the sink with on_frame_info and the one without saw the same poses and keyframes
    assert [f[0] for f in plain.frames] == [f[0] for f in fanned.frames] == list(range(N_FRAMES))
    for a, b in zip(plain.frames, fanned.frames, strict=True):
        assert a[2].tobytes() == b[2].tobytes()
    assert [k.keyframe_id for k in plain.keyframes] == [k.keyframe_id for k in fanned.keyframes]
    infos = info.infos
    assert [i.frame_index for i in infos] == list(range(N_FRAMES))
    assert all(i.tracked and i.lost_reason is None for i in infos)
    for i, (_, ts, T) in zip(infos, info.frames, strict=True):
        assert i.timestamp == ts and np.array_equal(i.T_wc, T)
    # the first frame: keyframe 0, no tracker result; later frames carry the tracker's numbers
    first = infos[0]
    assert first.is_keyframe and first.keyframe_id == 0 and np.isnan(first.residual) and first.good_count == 0
    assert all(i.good_count > 1000 and 0 < i.point_usage <= 1 and i.residual > 0 for i in infos[1:])
    assert all(i.tracking_ms > 0 and i.mapping_ms > 0 for i in infos[1:])
    # keyframe ids match the odometry's keyframe records
    kf_frames = {k.frame_index: k.keyframe_id for k in result.vo.keyframes}
    for i in infos:
        assert i.is_keyframe == (i.frame_index in kf_frames)
        assert i.keyframe_frame_index == max(f for f in kf_frames if f <= i.frame_index)
    # read-only views, and the keyframe's map changes as frames are mapped into it
    assert not any(info.writeable)
    assert infos[3].image.shape == (480, 640, 3) and infos[3].keyframe_idepth.shape == (480, 640)
    (d1, _), (d2, v2) = info.overlays[1], info.overlays[2]
    assert v2.sum() > 1000 and not np.array_equal(d1, d2)
    assert ((d2 == -1) == ~v2).all()  # no hypothesis: −1 in both arrays


def test_points_world_is_computed_once(runs: tuple) -> None:
    snap = runs[1].keyframes[-1]
    pts, col = snap.points_world()
    again = snap.points_world()
    assert again[0] is pts and again[1] is col and not pts.flags.writeable
    fewer, _ = snap.points_world(max_var=3e-3)
    assert 0 < len(fewer) < len(pts) and snap.points_world()[0] is not pts  # a new max_var replaces the cache
    np.testing.assert_array_equal(snap.points_world()[0], pts)


def test_multisink_closes_every_child_when_one_fails() -> None:
    """A child that fails to close (a full disk, an interrupt) does not leave the others open; its error is raised."""

    class Failing(MemorySink):
        def close(self) -> None:
            super().close()
            raise OSError("disk full")

    first, failing, last = MemorySink(), Failing(), MemorySink()
    with pytest.raises(OSError, match="disk full"):
        MultiSink(first, failing, last).close()
    assert first.closed and failing.closed and last.closed


def test_graph_listeners_are_found_inside_fan_out_sinks() -> None:
    from dmtrack.slam.listener import graph_listeners

    class Viewer(MemorySink):
        def on_graph_optimised(self, graph: object) -> None:
            pass

    viewer, other = Viewer(), Viewer()
    plain = MemorySink()
    assert graph_listeners(MultiSink(plain, MultiSink(viewer, plain), viewer), None, other) == [viewer, other]
    assert graph_listeners(plain, None) == []
