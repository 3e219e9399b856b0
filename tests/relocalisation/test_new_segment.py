"""A loss that no relocalisation ends: without a SLAM back end the odometry begins a new map (a new segment) with a
new geometric start, and the run says so (issue 37).

The sequence is two synthetic rooms one after the other (the camera "teleported" into a room it never saw): the
relocaliser finds nothing on the first room's keyframes; after ``relocalisation.new_map_after`` lost frames a new
start begins, and the frames from its reference frame on are tracked in a second segment, evaluated on its own.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator

import numpy as np

import dmtrack
from dmtrack.datasets import open_sequence
from dmtrack.datasets.base import Frame
from dmtrack.io.trajectory import Trajectory
from dmtrack.odometry.config import VOConfig

N = 60  # frames of each room


class _TwoRooms:
    """Frames 0–59 of room A, then frames 0–59 of room B (timestamps continued)."""

    format = "synthetic"
    name = "two-rooms"

    def __init__(self) -> None:
        self.a = open_sequence("synthetic:n_frames=60,width=320,height=240,seed=1")
        self.b = open_sequence("synthetic:n_frames=60,width=320,height=240,seed=2")
        self.camera = self.a.camera
        self.width, self.height = self.a.width, self.a.height
        self._dt = float(self.a.timestamps[-1]) + 1.0 / 30.0
        self.timestamps = np.concatenate([self.a.timestamps, self.b.timestamps + self._dt])
        # the second room's ground truth is in another world: the segments are evaluated on their own
        self.groundtruth = Trajectory(self.timestamps, np.concatenate([self.a.poses, self.b.poses]))
        self.has_groundtruth = True

    def __len__(self) -> int:
        return 2 * N

    def __getitem__(self, i: int) -> Frame:
        f = self.a[i] if i < N else self.b[i - N]
        return dataclasses.replace(f, index=i, timestamp=float(self.timestamps[i]))

    def __iter__(self) -> Iterator[Frame]:
        return (self[i] for i in range(len(self)))


def test_a_loss_nothing_recovers_from_begins_a_new_map() -> None:
    config = VOConfig(stop_on_loss=False).with_overrides("relocalisation.new_map_after=5")
    r = dmtrack.track(_TwoRooms(), "gray", config)
    m = r.metrics
    assert m["lost_at"] == N and m["relocalisations"] == 0  # nothing of room B is on a keyframe of room A
    assert [s["first_frame"] for s in m["segments"]][0] == 0 and len(m["segments"]) == 2
    second = m["segments"][1]
    assert N + 4 <= second["first_frame"] <= N + 8  # the new start began with the 5th lost frame
    # the frames from the new map's first on all have poses again (the start's window included)
    assert set(range(second["first_frame"], 2 * N)) <= set(r.frame_indices.tolist())
    assert m["lost_frames"] == second["first_frame"] - N
    for seg in m["segments"]:  # each segment is accurate in its own frame of reference
        assert seg["tracked_frames"] > 40 and seg["ate_rmse"] < 0.02
    # the keyframes say which segment they belong to; the second segment's first keyframe has no parent
    kfs = r.vo.keyframes
    first_b = next(k for k in kfs if k.segment == 1)
    assert first_b.parent_id is None and first_b.keyframe_id == second["first_keyframe"]
    assert all(k.parent_id is not None for k in kfs if k.segment == 1 and k is not first_b)


def test_with_a_slam_back_end_there_is_no_new_map() -> None:
    """With --slam the run keeps looking (LSD-SLAM's behaviour): no second segment, the frames stay lost."""
    from dmtrack.pipeline.recovery import Recovery

    rec = Recovery(dmtrack.features.get_feature("gray"), VOConfig(stop_on_loss=False), _TwoRooms().camera,
                   new_maps=False)  # fmt: skip
    assert rec.new_maps is False
