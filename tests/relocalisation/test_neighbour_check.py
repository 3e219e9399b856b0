"""The relocaliser's neighbour check (LSD-SLAM's): a kept keyframe that looks like the lost frame's view but stands
elsewhere in the map passes a single alignment and is refused because its neighbours do not see the frame where it
says; the true keyframe of that view, with its neighbours, is accepted. Keyframes rendered by the synthetic
renderer (seed 3, 320 × 240), aligned with the odometry's own tracker on the grey feature.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from dmtrack.features import get_feature
from dmtrack.odometry.config import VOConfig
from dmtrack.odometry.frame import build_frame
from dmtrack.odometry.relocalisation_quality import relocalisation_failure
from dmtrack.odometry.tracker import Tracker
from dmtrack.relocalisation import KeyframeStore, Relocaliser
from dmtrack.relocalisation.relocaliser import frame_in_world, pose_on_keyframe
from dmtrack.relocalisation.store import RelocKeyframe

CONFIG = VOConfig()


class _Room:
    """The rendered room (``rendered_room``) with the relocaliser's frames and kept keyframes."""

    def __init__(self, base: Any) -> None:
        self.seq, self.camera, self.pose, self.render = base.seq, base.camera, base.pose, base.render
        self.feature = get_feature("gray")

    def frame(self, index: int, T_wc: np.ndarray):  # noqa: ANN201
        image, _ = self.render(T_wc)
        return build_frame(index, float(index), image, self.feature.compute(image), self.camera,
                           CONFIG.pyramid_levels)  # fmt: skip

    def keep(self, store: KeyframeStore, kf_id: int, T_wc: np.ndarray, parent: int | None,
             image: np.ndarray | None = None, idepth: np.ndarray | None = None) -> None:  # fmt: skip
        """A kept keyframe at ``T_wc`` (world units, scale 1), with its rendered image and depth or the ones given."""
        rendered, true_idepth = self.render(T_wc)
        image = rendered if image is None else image
        idepth = true_idepth if idepth is None else idepth
        var = np.full_like(idepth, 1e-4)
        kf = RelocKeyframe(kf_id, kf_id, float(kf_id), image, idepth, var, self.camera, np.array(T_wc), 1.0,
                           float(idepth.mean()), parent, 0, store._view)  # fmt: skip
        store.keyframes[kf_id] = kf


@pytest.fixture(scope="module")
def room(rendered_room: Any) -> _Room:
    return _Room(rendered_room)


def _relocaliser(room: _Room, store: KeyframeStore) -> Relocaliser:
    tracker = Tracker(CONFIG.tracker, channel_cost=CONFIG.channel_cost)
    return Relocaliser(store, CONFIG, tracker)


LOST = (3.0, (0.3, 0.0, 0.1))  # where the lost frame is: yaw, shift
SEEN = (2.0, (0.25, 0.0, 0.08))  # where the keyframe that saw that view was


def test_a_keyframe_that_looks_alike_passes_one_alignment_but_not_its_neighbours(room: _Room) -> None:
    frame = room.frame(100, room.pose(*LOST))
    store = KeyframeStore(room.feature, CONFIG)
    # the map's keyframes 10, 11, 12 stand a quarter turn away; keyframe 11 holds the lost frame's view (a poster,
    # a repeated corridor) over the depth of where it stands, scaled to the view's median depth
    image, true_idepth = room.render(room.pose(*SEEN))
    _, there = room.render(room.pose(90))
    room.keep(store, 10, room.pose(84), None)
    room.keep(store, 11, room.pose(90), 10, image=image, idepth=there * (np.median(true_idepth) / np.median(there)))
    room.keep(store, 12, room.pose(96), 11)
    reloc = _relocaliser(room, store)
    lookalike = store.keyframes[11]
    # one alignment, from where the keyframe's view is, takes it
    T0 = pose_on_keyframe(room.pose(*SEEN), 1.0, room.pose(*LOST))
    one = reloc._align(lookalike, frame, T0)
    assert relocalisation_failure(one, CONFIG.relocalisation) is None
    # the relocaliser, started from the look-alike (the last pose the odometry had), refuses it: its neighbours do
    # not see the frame where it implies
    assert reloc.find(frame, room.pose(90)) is None
    why = {kf: reason for _, kf, _, reason in reloc.tried}
    assert why[11] == "its neighbours did not confirm it", reloc.tried
    assert all(why[k] is not None for k in why)


def test_the_true_keyframe_of_the_view_is_confirmed_by_its_neighbours(room: _Room) -> None:
    frame = room.frame(100, room.pose(*LOST))
    store = KeyframeStore(room.feature, CONFIG)
    room.keep(store, 0, room.pose(0.0), None)
    room.keep(store, 1, room.pose(*SEEN), 0)
    room.keep(store, 2, room.pose(5.0, (0.35, 0.0, 0.12)), 1)
    reloc = _relocaliser(room, store)
    found = reloc.find(frame, room.pose(*SEEN))
    assert found is not None and found.neighbours_good >= max(1, found.neighbours_bad), reloc.tried
    T_wf = frame_in_world(found.keyframe.T_wc, found.keyframe.scale, found.T_fk)
    truth = room.pose(*LOST)
    assert np.linalg.norm(T_wf[:3, 3] - truth[:3, 3]) < 0.01
    R = T_wf[:3, :3].T @ truth[:3, :3]
    assert np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))) < 0.2
