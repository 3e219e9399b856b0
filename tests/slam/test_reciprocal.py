"""The reciprocal test (slam/constraints.py) refuses a false loop that the appearance search proposes and that a
one-way alignment would take: a keyframe whose image shows the place of an earlier keyframe but whose geometry is
another place's. The same view with its own depth, a true loop, passes."""

from __future__ import annotations

import dataclasses

import numpy as np

from dmtrack.odometry.config import TrackerConfig
from dmtrack.slam.candidates import CandidateSearch
from dmtrack.slam.constraints import STAGES, reciprocal_test
from dmtrack.slam.sim3_tracker import Sim3Tracker

STRICTNESS = 1.5  # SlamConfig's


def test_a_place_that_looks_alike_is_refused_where_one_way_alignment_accepts_it(room):  # noqa: ANN001
    earlier = room.keyframe(0, room.pose(0))
    T_wc = room.pose(3, (0.3, 0.0, 0.1))
    image, true_idepth = room.render(T_wc)
    # the look-alike: this view's image over the geometry of another place (the room seen a quarter turn away,
    # scaled to the same median depth) — the images match, the two keyframes' 3-D structures do not
    _, elsewhere = room.render(room.pose(90))
    lookalike = room.keyframe(10, T_wc, image=image, idepth=elsewhere * (np.median(true_idepth) / np.median(elsewhere)))
    true_loop = room.keyframe(11, T_wc)
    tracker = Sim3Tracker(dataclasses.replace(TrackerConfig(), convergence_eps=0.99))  # the back end's
    search = CandidateSearch()
    results = {}
    for kf in (lookalike, true_loop):
        poses = {k.kf_id: k.vo_pose for k in (earlier, kf)}
        assert search.candidates(kf, [earlier], poses) == [earlier]  # proposed by appearance …
        S_init = search.initial_estimate(kf, earlier)  # … and started from the ORB matches' pose, as the back end
        assert S_init is not None
        one_way = tracker.track(earlier.view.reference, kf.view.frame, kf.view.idepth_pyramid, S_init)
        results[kf.kf_id] = (
            reciprocal_test(tracker, earlier.view, kf.view, S_init, STRICTNESS),
            reciprocal_test(tracker, earlier.view, kf.view, S_init, float("inf")),  # no consistency limit
            one_way,
        )
    refused, unchecked, one_way = results[10]
    accepted, _, true_one_way = results[11]
    limits = [limit * STRICTNESS for _, limit in STAGES]
    # the true loop passes with room to spare
    assert accepted.accepted and all(v < 0.1 * lim for v, lim in zip(accepted.consistency, limits, strict=True))
    # one way, the look-alike aligns as well as a true loop's photometry: converged, most points used
    assert not one_way.diverged and one_way.usage > 0.7 and one_way.residual_p < 3 * true_one_way.residual_p
    # and so at every stage both ways, when their agreement is not checked …
    assert unchecked.accepted and len(unchecked.consistency) == len(STAGES)
    # … but the two alignments disagree, far beyond the limits: the reciprocal test refuses the pair
    assert not refused.accepted and "the two alignments disagree" in refused.reason
    assert max(unchecked.consistency) > 3 * limits[-1]
