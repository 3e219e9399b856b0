"""Loop candidates (slam/candidates.py) on rendered keyframes: a keyframe near earlier ones finds them by
appearance and one looking elsewhere finds none; the order is by matches and the same every time; the index's
shortlist gives what matching every keyframe gives; the matches are made once; the initial Sim(3) and the pose of a
non-keyframe image come back against the true relative poses."""

from __future__ import annotations

import numpy as np
import pytest

from dmtrack.geometry.lie import SO3, Sim3
from dmtrack.slam.candidates import CandidateSearch

#: (yaw °, shift m, norm) of the earlier keyframes: 0, 1, 2 and 5 look at the same wall, 3 and 4 elsewhere
OLDER = [(0, (0.0, 0.0, 0.0), 0.5), (12, (0.05, 0.0, 0.0), 0.7), (-15, (-0.05, 0.05, 0.0), 0.9),
         (90, (0.0, 0.0, 0.0), 1.0), (180, (0.0, 0.0, 0.0), 1.1), (-6, (0.15, 0.1, 0.05), 1.2)]
SAME_WALL = {0, 1, 2, 5}


@pytest.fixture(scope="module")
def scene(room):  # noqa: ANN001, ANN201
    older = [room.keyframe(i, room.pose(y, s), n) for i, (y, s, n) in enumerate(OLDER)]
    near = room.keyframe(20, room.pose(5, (0.1, -0.05, 0.03)), 1.3)
    far = room.keyframe(21, room.pose(270))  # the wall behind the camera: none of the earlier keyframes saw it
    poses = {k.kf_id: k.vo_pose for k in [*older, near, far]}
    return older, near, far, poses


def _appearance(search: CandidateSearch, kf, older) -> list[tuple[int, int]]:  # noqa: ANN001
    return [(n, c.kf_id) for n, c in search._by_appearance(kf, older)]


def _cam_to_world(k) -> np.ndarray:  # noqa: ANN001
    """A keyframe's true camera-to-world pose, metres (its ``vo_pose`` without the scale)."""
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = k.vo_pose.rotation.matrix(), k.vo_pose.translation
    return T


def _rotation_error_deg(R: SO3, T: np.ndarray) -> float:
    return float(np.degrees((R.inverse() @ SO3.from_matrix(T[:3, :3], orthonormalize=True)).angle()))


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    c = float(a @ b) / (np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def test_a_keyframe_near_earlier_ones_finds_them_and_one_looking_elsewhere_finds_none(scene):  # noqa: ANN001
    older, near, far, poses = scene
    search = CandidateSearch()
    found = _appearance(search, near, older)
    assert len(found) == search.max_appearance == 3
    assert {k for _, k in found} <= SAME_WALL and all(n >= search.min_matches for n, _ in found)
    assert _appearance(search, far, older) == []
    # far from every earlier keyframe in the graph too: no candidate at all
    assert search.candidates(far, older, poses) == []


def test_candidates_come_by_decreasing_matches_then_by_distance_and_the_same_every_time(scene):  # noqa: ANN001
    older, near, _, poses = scene
    runs = []
    for _ in range(2):
        search = CandidateSearch()
        runs.append((_appearance(search, near, older), [c.kf_id for c in search.candidates(near, older, poses)]))
    (found, ids), again = runs[0], runs[1]
    assert again == runs[0]  # a fresh search: the same candidates, matches and order
    counts = [n for n, _ in found]
    assert counts == sorted(counts, reverse=True) and len(set(counts)) == len(counts)
    assert ids[: len(found)] == [k for _, k in found]  # appearance first, best first …
    assert len(ids) == len(set(ids)) and len(ids) > len(found)  # … then distance ones, none twice
    assert set(ids) <= SAME_WALL


def test_the_index_shortlists_what_matching_every_keyframe_finds(scene):  # noqa: ANN001
    older, near, far, _ = scene
    for query in (near, far, *older):
        others = [c for c in older if c is not query]
        exhaustive, indexed = CandidateSearch(shortlist=None), CandidateSearch(shortlist=3)
        assert _appearance(indexed, query, others) == _appearance(exhaustive, query, others), query.kf_id
        assert exhaustive.pairs_matched == len(others) and indexed.pairs_matched <= 3


def test_the_initial_estimate_uses_the_matches_the_search_made(scene):  # noqa: ANN001
    older, near, far, poses = scene
    search = CandidateSearch(shortlist=3, cached_queries=1)
    cands = search.candidates(near, older, poses)
    matched = search.pairs_matched
    assert matched == 3
    appearance = [c for _, c in search._by_appearance(near, older)]
    for cand in appearance:
        assert search.initial_estimate(near, cand) is not None
    assert search.pairs_matched == matched  # no pair matched again
    distance_only = [c for c in cands if c not in appearance]
    search.initial_estimate(near, distance_only[0])  # a pair the index did not shortlist: matched now, once
    search.initial_estimate(near, distance_only[0])
    assert search.pairs_matched == matched + 1
    search.candidates(far, older, poses)  # the cache holds one query: near's matches leave it
    before = search.pairs_matched
    search.initial_estimate(near, appearance[0])
    assert search.pairs_matched == before + 1


@pytest.mark.parametrize("shift", [(0.3, 0.0, 0.0), (0.0, 0.0, 0.3)])
def test_the_initial_estimate_recovers_the_relative_pose_and_scale(room, scene, shift):  # noqa: ANN001
    older = scene[0]
    kf = room.keyframe(30 + int(10 * shift[0]), room.pose(3, shift), norm=0.8)
    search = CandidateSearch()
    for cand in older[:2]:
        S = search.initial_estimate(kf, cand)
        assert S is not None
        T = np.linalg.inv(_cam_to_world(kf)) @ _cam_to_world(cand)  # cand → kf, metres
        # in the keyframes' units (metres ÷ their norms c): p_kf = (c_cand / c_kf) R p_cand + t / c_kf
        c_cand, c_kf = cand.vo_pose.scale, kf.vo_pose.scale
        truth = Sim3(SO3.from_matrix(T[:3, :3], orthonormalize=True), T[:3, 3] / c_kf, c_cand / c_kf)
        assert _rotation_error_deg(S.rotation, T) < 1.0
        assert _angle_deg(S.translation, truth.translation) < 5.0
        assert abs(S.scale / truth.scale - 1.0) < 0.02
        assert abs(np.linalg.norm(S.translation) / np.linalg.norm(truth.translation) - 1.0) < 0.1


def test_an_image_is_ranked_and_placed_against_the_keyframes(room, scene):  # noqa: ANN001
    older, _, _, _ = scene
    T_wc = room.pose(3, (0.3, 0.0, 0.0))
    image, _ = room.render(T_wc)  # a lost frame: an image without depth
    search = CandidateSearch(cached_queries=2)
    ranked = search.by_appearance_of_image("lost-1", image, older, limit=4)
    assert [n for n, _ in ranked] == sorted((n for n, _ in ranked), reverse=True)
    assert len(ranked) == 4 and {c.kf_id for _, c in ranked} == SAME_WALL
    matched = search.pairs_matched
    assert search.by_appearance_of_image("lost-1", image, older, limit=4) == ranked
    for _, cand in ranked:
        pose, inliers = search.pose_of_image("lost-1", cand)
        assert pose is not None and inliers >= 20
        T = np.linalg.inv(T_wc) @ _cam_to_world(cand)  # cand → image, metres
        assert _rotation_error_deg(pose.rotation, T) < 1.0
        if np.linalg.norm(T[:3, 3]) < 0.25:
            continue  # keyframe 5, 0.19 m away: the direction of so short a baseline is 13° off (EPnP, 320 × 240)
        assert _angle_deg(pose.translation, T[:3, 3]) < 5.0
        # the translation is in the candidate's units (its inverse depth × norm): metres ÷ norm
        t_units = T[:3, 3] / cand.vo_pose.scale
        assert abs(np.linalg.norm(pose.translation) / np.linalg.norm(t_units) - 1.0) < 0.1
    assert search.pairs_matched == matched  # the ranking's matches, not made again
    assert search.pose_of_image("lost-1", older[3]) == (None, 0)  # another wall: too few matches
    search.by_appearance_of_image("lost-2", image, older)
    search.by_appearance_of_image("lost-3", image, older)  # two images cached: lost-1 leaves
    with pytest.raises(KeyError, match="lost-1"):
        search.pose_of_image("lost-1", ranked[0][1])

