"""A Sim(3) pose graph of keyframes, optimised by gtsam (``pip install 'dmtrack[slam]'``).

Poses are camera-to-world :class:`~dmtrack.geometry.lie.Sim3` (``p_w = s R p_c + t``). An edge ``i → j`` measures
``T_ij = T_wi⁻¹ T_wj``, the pose of keyframe ``j`` in keyframe ``i``'s frame, with a 7×7 information matrix in this
package's tangent order ``(υ, ω, σ)`` (translation, rotation, log-scale; :meth:`Sim3.log`). The first keyframe
added is the gauge: a prior holds it (pose and scale) where it is.

gtsam's ``Similarity3(R, t, s)`` maps ``p ↦ s (R p + t)`` and orders its tangent ``(ω, υ, λ)``; the conversions
below are the only place that knows it. The optimiser is gtsam's Levenberg–Marquardt with a fixed ordering of the
variables (the keyframes' ids), so the same graph gives the same bits.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dmtrack.errors import InputError
from dmtrack.geometry.lie import SO3, Sim3

GTSAM_MISSING = "SLAM needs gtsam, which is not installed: pip install 'dmtrack[slam]'"

# (υ, ω, σ) → gtsam's (ω, υ, λ): gtsam_vector = ours[_TO_GTSAM]
_TO_GTSAM = np.array([3, 4, 5, 0, 1, 2, 6])


def gtsam_module() -> Any:
    """gtsam, or an :class:`~dmtrack.errors.InputError` naming the extra that installs it."""
    try:
        import gtsam
    except ImportError as e:
        raise InputError(GTSAM_MISSING) from e
    return gtsam


def to_gtsam(T: Sim3) -> Any:
    """Our Sim3 as a ``gtsam.Similarity3`` (the same map of points)."""
    gtsam = gtsam_module()
    s = T.scale
    return gtsam.Similarity3(gtsam.Rot3(np.array(T.rotation.matrix())), np.asarray(T.translation) / s, s)


def from_gtsam(S: Any) -> Sim3:
    """A ``gtsam.Similarity3`` as our Sim3."""
    s = float(S.scale())
    R = SO3.from_matrix(np.asarray(S.rotation().matrix()), orthonormalize=True)
    return Sim3(R, s * np.asarray(S.translation(), dtype=np.float64), s)


def information_to_gtsam(information: np.ndarray) -> np.ndarray:
    """A 7×7 information matrix in ``(υ, ω, σ)`` order, reordered to gtsam's ``(ω, υ, λ)``."""
    info = np.asarray(information, dtype=np.float64)
    if info.shape != (7, 7) or not np.all(np.isfinite(info)):
        raise InputError(f"an edge's information must be a finite 7×7 matrix, got shape {info.shape}")
    return info[np.ix_(_TO_GTSAM, _TO_GTSAM)]


@dataclass(frozen=True)
class Edge:
    """A relative-pose constraint ``T_ij`` (keyframe ``j`` in keyframe ``i``) with its information."""

    i: int
    j: int
    T_ij: Sim3
    information: np.ndarray
    kind: str = "odometry"


@dataclass(frozen=True)
class Optimisation:
    """What :meth:`PoseGraph.optimise` did: error (gtsam's ½ Σ rᵀ Λ r) before and after, iterations, time."""

    error_before: float
    error_after: float
    iterations: int
    ms: float
    poses: dict[int, Sim3] = field(repr=False)


class PoseGraph:
    """Keyframes (Sim3 camera-to-world) and the edges between them; :meth:`optimise` runs gtsam.

    ``prior_sigma`` is the standard deviation (in each tangent coordinate) of the prior that fixes the first
    keyframe.
    """

    def __init__(self, prior_sigma: float = 1e-6, max_iterations: int = 100) -> None:
        gtsam_module()  # fail here, before any keyframe, when gtsam is missing
        self.poses: dict[int, Sim3] = {}
        self.edges: list[Edge] = []
        self.prior_sigma = float(prior_sigma)
        self.max_iterations = int(max_iterations)

    def add_keyframe(self, kf_id: int, T_wc: Sim3) -> None:
        if kf_id in self.poses:
            raise InputError(f"keyframe {kf_id} is already in the pose graph")
        self.poses[int(kf_id)] = T_wc

    def add_edge(self, i: int, j: int, T_ij: Sim3, information: np.ndarray, kind: str = "odometry") -> Edge:
        for k in (i, j):
            if k not in self.poses:
                raise InputError(f"edge {i}→{j}: keyframe {k} is not in the pose graph")
        if i == j:
            raise InputError(f"edge {i}→{j}: a keyframe cannot constrain itself")
        information_to_gtsam(information)  # checked now, not at optimisation
        edge = Edge(int(i), int(j), T_ij, np.array(information, dtype=np.float64), kind)
        self.edges.append(edge)
        return edge

    def optimise(self) -> Optimisation:
        """Levenberg–Marquardt over every keyframe but the first; the graph's poses become the optimised ones."""
        if not self.poses:
            raise InputError("the pose graph has no keyframe")
        gtsam = gtsam_module()
        t0 = time.perf_counter()
        graph, first = self._factors(gtsam)
        graph.add(gtsam.PriorFactorSimilarity3(first, to_gtsam(self.poses[first]),
                                               gtsam.noiseModel.Isotropic.Sigma(7, self.prior_sigma)))
        initial = self._values(gtsam, self.poses)
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(self.max_iterations)
        ordering = gtsam.Ordering()
        for k in sorted(self.poses):
            ordering.push_back(k)
        params.setOrdering(ordering)
        optimiser = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
        error_before = float(graph.error(initial))
        result = optimiser.optimize()
        poses = {k: from_gtsam(result.atSimilarity3(k)) for k in sorted(self.poses)}
        self.poses = poses
        return Optimisation(error_before, float(graph.error(result)), int(optimiser.iterations()),
                            1e3 * (time.perf_counter() - t0), dict(poses))

    def _factors(self, gtsam: Any) -> tuple[Any, int]:
        graph = gtsam.NonlinearFactorGraph()
        for e in self.edges:
            noise = gtsam.noiseModel.Gaussian.Information(information_to_gtsam(e.information))
            graph.add(gtsam.BetweenFactorSimilarity3(e.i, e.j, to_gtsam(e.T_ij), noise))
        return graph, min(self.poses)

    @staticmethod
    def _values(gtsam: Any, poses: dict[int, Sim3]) -> Any:
        values = gtsam.Values()
        for k in sorted(poses):
            values.insert(k, to_gtsam(poses[k]))
        return values
