"""The Sim(3) pose graph on gtsam: conventions against our Sim3, a closed loop, determinism, clear errors."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from dmtrack.errors import InputError
from dmtrack.geometry.lie import SO3, Sim3

gtsam = pytest.importorskip("gtsam", reason="gtsam is not installed (pip install 'dmtrack[slam]')")

from dmtrack.slam.pose_graph import (  # noqa: E402
    GTSAM_MISSING,
    PoseGraph,
    from_gtsam,
    information_to_gtsam,
    to_gtsam,
)


def _random_sim3(rng: np.random.Generator) -> Sim3:
    return Sim3(SO3.sample_uniform(rng), rng.normal(size=3), float(np.exp(rng.normal(scale=0.5))))


def test_conversion_keeps_the_map_of_points_and_composition():
    rng = np.random.default_rng(0)
    for _ in range(20):
        a, b = _random_sim3(rng), _random_sim3(rng)
        p = rng.normal(size=3)
        assert np.allclose(to_gtsam(a).transformFrom(p), a.act(p), atol=1e-12)
        assert from_gtsam(to_gtsam(a)).allclose(a, atol=1e-12)
        # gtsam's between factor measures a⁻¹ b as our Sim3 composes it: zero error there, not elsewhere
        values = gtsam.Values()
        values.insert(0, to_gtsam(a))
        values.insert(1, to_gtsam(b))
        noise = gtsam.noiseModel.Isotropic.Sigma(7, 1.0)
        assert gtsam.BetweenFactorSimilarity3(0, 1, to_gtsam(a.inverse() @ b), noise).error(values) < 1e-18
        assert gtsam.BetweenFactorSimilarity3(0, 1, to_gtsam(b @ a.inverse()), noise).error(values) > 1e-6


def test_tangent_order_matches_to_first_order():
    # gtsam orders (ω, υ, λ) and parameterises translation differently; near identity both agree to first order,
    # which is where an edge's information applies (its residual)
    rng = np.random.default_rng(1)
    v = 1e-4 * rng.normal(size=7)
    g = np.asarray(gtsam.Similarity3.Logmap(to_gtsam(Sim3.exp(v))))
    assert np.allclose(g, information_to_gtsam(np.diag(v))[np.diag_indices(7)], atol=1e-7)
    assert not np.allclose(g, v, atol=1e-6)  # the orders differ: the permutation is needed


def _circle(n: int) -> list[Sim3]:
    """Keyframes on a circle of radius 2, looking outward, the last one next to the first."""
    poses = []
    for k in range(n):
        a = 2 * np.pi * k / n
        R = SO3.exp([0.0, -a, 0.0])
        poses.append(Sim3(R, [2 * np.sin(a), 0.1 * np.sin(3 * a), 2 * np.cos(a)], 1.0))
    return poses


def _drifting_graph(n: int = 40, loop: bool = True) -> tuple[PoseGraph, list[Sim3]]:
    truth = _circle(n)
    bias = Sim3.exp([0.01, 0.0, 0.005, 0.0, np.radians(0.5), np.radians(0.2), 0.01])  # per edge
    graph = PoseGraph()
    info = np.diag([1e3] * 6 + [1e3])
    pose = truth[0]
    graph.add_keyframe(0, pose)
    for k in range(1, n):
        rel = truth[k - 1].inverse() @ truth[k] @ bias  # what a drifting odometry measures
        pose = pose @ rel
        graph.add_keyframe(k, pose)
        graph.add_edge(k - 1, k, rel, info)
    if loop:
        graph.add_edge(n - 1, 0, truth[n - 1].inverse() @ truth[0], 10 * info, kind="loop")
    return graph, truth


def _end_to_start(poses: dict[int, Sim3], truth: list[Sim3]) -> tuple[float, float]:
    """Rotation (°) and translation error of the last keyframe seen from the first, against the truth."""
    n = len(truth)
    est = poses[0].inverse() @ poses[n - 1]
    true = truth[0].inverse() @ truth[n - 1]
    d = est.inverse() @ true
    return float(np.degrees(d.rotation.angle())), float(np.linalg.norm(est.translation - true.translation))


def test_a_loop_edge_removes_the_drift():
    graph, truth = _drifting_graph()
    rot0, trans0 = _end_to_start(graph.poses, truth)
    result = graph.optimise()
    rot1, trans1 = _end_to_start(result.poses, truth)
    assert rot0 > 10 and trans0 > 0.5  # the chain has drifted
    assert rot1 < rot0 / 5 and trans1 < trans0 / 5
    assert result.error_after < 1e-3 * result.error_before
    assert result.poses[0].allclose(truth[0], atol=1e-6)  # the gauge stays where it was
    # without the loop edge the optimum is the chain itself
    chain, _ = _drifting_graph(loop=False)
    assert _end_to_start(chain.optimise().poses, truth)[0] == pytest.approx(rot0, rel=1e-6)


def test_same_graph_same_bits():
    a = _drifting_graph()[0].optimise().poses
    b = _drifting_graph()[0].optimise().poses
    for k in a:
        assert np.array_equal(a[k].matrix(), b[k].matrix())


def test_bad_edges_are_refused_with_the_reason():
    graph = PoseGraph()
    graph.add_keyframe(0, Sim3.identity())
    with pytest.raises(InputError, match="keyframe 3 is not in the pose graph"):
        graph.add_edge(0, 3, Sim3.identity(), np.eye(7))
    graph.add_keyframe(1, Sim3.identity())
    with pytest.raises(InputError, match="finite 7×7"):
        graph.add_edge(0, 1, Sim3.identity(), np.eye(6))
    with pytest.raises(InputError, match="already in the pose graph"):
        graph.add_keyframe(1, Sim3.identity())


def test_without_gtsam_one_line_names_the_extra(monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setitem(sys.modules, "gtsam", None)  # import gtsam now raises ImportError
    with pytest.raises(InputError) as e:
        PoseGraph()
    assert str(e.value) == GTSAM_MISSING and "pip install 'dmtrack[slam]'" in str(e.value)
