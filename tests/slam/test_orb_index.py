"""The ORB descriptor index (slam/orb_index.py) on the descriptors of rendered views: its votes never exceed the
exhaustive comparison's and equal them when every pair is looked up, they do not depend on the order of the
keyframes, and the shortlist is the keyframes of the same place, best first."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from dmtrack.slam.orb_index import OrbIndex, hamming

#: yaw (°) and shift (m) of the views: 0–2 see one wall, 3 and 4 others
VIEWS = [(0, (0.0, 0.0, 0.0)), (10, (0.1, 0.0, 0.0)), (-8, (0.0, 0.1, 0.05)), (90, (0.0, 0.0, 0.0)),
         (180, (0.0, 0.0, 0.0))]


@pytest.fixture(scope="module")
def descriptors(room) -> dict[int, np.ndarray]:  # noqa: ANN001
    orb = cv2.ORB_create(nfeatures=300)
    out = {}
    for k, (yaw, shift) in enumerate([*VIEWS, (4, (0.05, -0.05, 0.0))]):
        image, _ = room.render(room.pose(yaw, shift))
        out[k] = orb.detectAndCompute(image, None)[1]
    return out  # 5 is the query: near 0–2


def _index(descriptors: dict[int, np.ndarray], order: list[int], **kw) -> OrbIndex:  # noqa: ANN003
    index = OrbIndex(**kw)
    for k in order:
        index.add(k, descriptors[k])
    return index


def test_hamming_counts_the_differing_bits():
    rng = np.random.default_rng(0)
    a, b = rng.integers(0, 256, (50, 32), dtype=np.uint8), rng.integers(0, 256, (50, 32), dtype=np.uint8)
    bits = np.unpackbits(a, axis=1) != np.unpackbits(b, axis=1)
    assert np.array_equal(hamming(a, b), bits.sum(axis=1))


def test_the_votes_are_the_exhaustive_ones_or_fewer(descriptors: dict[int, np.ndarray]):
    index = _index(descriptors, [0, 1, 2, 3, 4])
    votes, every = index.votes(descriptors[5]), index.votes_exhaustive(descriptors[5])
    q = descriptors[5]
    for k in range(5):  # a vote: a query descriptor with one of the keyframe's within max_distance
        near = hamming(q[:, None, :], descriptors[k][None, :, :]) <= index.max_distance
        assert every.get(k, 0) == int(near.any(axis=1).sum())
    assert set(votes) <= set(every) and all(votes[k] <= every[k] for k in votes)
    assert sum(votes.values()) > 0.5 * sum(every[k] for k in (0, 1, 2))  # the hash finds most of the same place's
    # one bit per key and 32 tables: two descriptors within 48 bits miss every key with probability ≤ (48/256)³²,
    # so every pair is looked up and the votes are the exhaustive comparison's
    dense = _index(descriptors, [0, 1, 2, 3, 4], bits=1, n_tables=32, max_bucket=None, rows_per_key=None)
    assert dense.votes(descriptors[5]) == every
    allowed = [1, 3]
    assert index.votes_exhaustive(descriptors[5], allowed) == {k: every[k] for k in allowed if k in every}
    assert set(index.votes(descriptors[5], allowed)) <= set(allowed)


def test_the_shortlist_is_the_same_place_best_first_whatever_the_order(descriptors: dict[int, np.ndarray]):
    a = _index(descriptors, [0, 1, 2, 3, 4])
    b = _index(descriptors, [4, 2, 0, 3, 1])
    assert a.votes(descriptors[5]) == b.votes(descriptors[5])
    short = a.shortlist(descriptors[5], 3)
    assert short == b.shortlist(descriptors[5], 3) and set(short) == {0, 1, 2}
    votes = a.votes(descriptors[5])
    assert [votes[k] for k in short] == sorted((votes[k] for k in short), reverse=True)
    assert min(votes[k] for k in (0, 1, 2)) > 3 * max(votes.get(k, 0) for k in (3, 4))
    assert a.shortlist(descriptors[5], 0) == [] and len(a.shortlist(descriptors[5], 10)) <= 5
    assert np.array_equal(OrbIndex().positions, OrbIndex().positions)  # the tables come from a fixed seed
    assert not np.array_equal(OrbIndex(seed=1).positions, OrbIndex(seed=2).positions)


def test_the_keys_grow_with_the_index_as_if_it_had_been_built_with_them(descriptors: dict[int, np.ndarray]):
    # at most 2 rows per key: 5 × ~300 rows take the keys from 4 bits to 10, the tables built again each time
    grown = _index(descriptors, [0, 1, 2, 3, 4], bits=4, rows_per_key=2.0, max_bucket=None)
    assert grown.bits == 10 and grown.n_descriptors <= 2 * 2**10
    built = _index(descriptors, [0, 1, 2, 3, 4], bits=10, rows_per_key=None, max_bucket=None)
    for t in range(grown.n_tables):
        assert grown._tables[t] == built._tables[t]
    assert grown.votes(descriptors[5]) == built.votes(descriptors[5])
    fixed = _index(descriptors, [0, 1, 2, 3, 4], bits=4, rows_per_key=None, max_bucket=None)
    assert fixed.bits == 4 and fixed.votes(descriptors[5]) != built.votes(descriptors[5])


def test_queries_pass_by_the_buckets_of_common_descriptors(descriptors: dict[int, np.ndarray]):
    # a descriptor in 100 keyframes (a pattern seen everywhere) fills a bucket in every table: no vote for them …
    common = descriptors[5][:1]
    index = OrbIndex(max_bucket=64)
    for k in range(100):
        index.add(k, common)
    index.add(100, descriptors[0])
    votes = index.votes(descriptors[5])
    assert not any(k < 100 for k in votes) and votes[100] > 50  # … while the keyframe of the same place keeps its
    every = OrbIndex(max_bucket=None)
    for k in range(100):
        every.add(k, common)
    assert set(every.votes(common)) == set(range(100))


def test_bad_input_is_refused(descriptors: dict[int, np.ndarray]):
    index = _index(descriptors, [0])
    with pytest.raises(ValueError, match="already in the index"):
        index.add(0, descriptors[1])
    with pytest.raises(ValueError, match=r"\(n, 32\) uint8"):
        index.add(7, np.zeros((5, 16), np.uint8))
    index.add(8, np.zeros((0, 32), np.uint8))  # a keyframe without features: indexed, never voted for
    assert 8 in index and len(index) == 2 and 8 not in index.votes(descriptors[5])
    assert OrbIndex().votes(descriptors[5]) == {}
