"""Constraints between keyframes: LSD-SLAM's reciprocal Sim(3) test (``SlamSystem::testConstraint``).

Two keyframes A and B are aligned both ways by :class:`~dmtrack.slam.sim3_tracker.Sim3Tracker` (A onto B and B
onto A), first on the coarse levels, then level 2, then level 1. At each stage the two results must agree: with
``S_AB`` (A → B), ``S_BA`` (B → A) and their Hessians ``H_AB``, ``H_BA`` (left perturbations),

    d = log(S_AB · S_BA),   C = H_AB⁻¹ + Ad(S_AB) H_BA⁻¹ Ad(S_AB)ᵀ,   consistency = dᵀ C⁻¹ d,

and a stage fails when its consistency exceeds LSD-SLAM's 3000, 4000, 6000 × ``strictness``. A pair that passes
gives two edges for the pose graph, each measured ``T_ij = T_wi⁻¹ T_wj`` with its information for gtsam's right
perturbation (``Ad(T)ᵀ H Ad(T)``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dmtrack.geometry.lie import Sim3
from dmtrack.odometry.frame import Frame
from dmtrack.odometry.tracker import TrackingReference
from dmtrack.slam.sim3_tracker import Sim3Result, Sim3Tracker

#: (levels, maximum consistency before × strictness) of each stage (LSD-SLAM: SIM3TRACKING_MAX_LEVEL−1 … 3, 2, 1)
STAGES: tuple[tuple[tuple[int, ...], float], ...] = (((4, 3), 3000.0), ((2,), 4000.0), ((1,), 6000.0))


@dataclass
class KeyframeView:
    """What the constraint test needs of a keyframe: its pyramid, its tracking reference and inverse depths."""

    frame: Frame
    reference: TrackingReference

    @property
    def idepth_pyramid(self) -> list[tuple[np.ndarray, np.ndarray]]:
        return self.reference.idepth_pyramid


@dataclass(frozen=True)
class Constraint:
    """The outcome of a reciprocal test of keyframes ``a`` and ``b``.

    ``S_ab`` maps a's coordinates to b's (so the pose of a in b's frame, ``T_ba``); ``S_ba`` the other way.
    ``information_ab`` is the information of the edge ``b → a`` measured ``T_ba = S_ab`` (right perturbation), and
    ``information_ba`` that of ``a → b`` measured ``T_ab = S_ba``. ``accepted`` is False with ``reason`` when a
    stage failed; ``consistency`` lists each stage's value.
    """

    accepted: bool
    reason: str | None
    S_ab: Sim3
    S_ba: Sim3
    information_ab: np.ndarray
    information_ba: np.ndarray
    consistency: tuple[float, ...]
    residual: float


def reciprocal_consistency(S_ab: Sim3, H_ab: np.ndarray, S_ba: Sim3, H_ba: np.ndarray) -> float:
    """LSD-SLAM's Mahalanobis disagreement of two alignments of the same pair (module docstring)."""
    adj = S_ab.adjoint()
    try:
        cov = np.linalg.inv(H_ab) + adj @ np.linalg.inv(H_ba) @ adj.T
        d = (S_ab @ S_ba).log()
        return float(d @ np.linalg.solve(cov, d))
    except np.linalg.LinAlgError:
        return float("inf")


def right_information(S: Sim3, H_left: np.ndarray) -> np.ndarray:
    """The information of ``S = exp(δ) Ŝ`` (Hessian ``H_left`` in δ) for ``S = Ŝ exp(ε)``: ``Ad(Ŝ)ᵀ H Ad(Ŝ)``."""
    adj = S.adjoint()
    info = adj.T @ H_left @ adj
    return 0.5 * (info + info.T)


def reciprocal_test(
    tracker: Sim3Tracker, a: KeyframeView, b: KeyframeView, S_ab_init: Sim3, strictness: float = 1.5,
) -> Constraint:
    """The reciprocal test of keyframes ``a`` and ``b`` from the estimate ``S_ab_init`` (a → b)."""
    S_ab, S_ba = S_ab_init, S_ab_init.inverse()
    values: list[float] = []
    res_ab: Sim3Result | None = None
    res_ba: Sim3Result | None = None
    for levels, limit in STAGES:
        res_ab = tracker.track(a.reference, b.frame, b.idepth_pyramid, S_ab, levels)
        res_ba = tracker.track(b.reference, a.frame, a.idepth_pyramid, S_ba, levels)
        for r in (res_ab, res_ba):
            if r.diverged or r.hessian[0, 0] == 0 or r.hessian[6, 6] == 0:
                return _refused(S_ab, S_ba, values, r.reason or "no depth overlap (the scale is not observed)")
        S_ab, S_ba = res_ab.S, res_ba.S
        values.append(reciprocal_consistency(S_ab, res_ab.hessian, S_ba, res_ba.hessian))
        if not values[-1] <= limit * strictness:
            why = f"the two alignments disagree at levels {levels}: {values[-1]:.4g} > {limit * strictness:g}"
            return _refused(S_ab, S_ba, values, why)
    assert res_ab is not None and res_ba is not None
    return Constraint(True, None, S_ab, S_ba, right_information(S_ab, res_ab.hessian),
                      right_information(S_ba, res_ba.hessian), tuple(values),
                      0.5 * (res_ab.residual + res_ba.residual))


def _refused(S_ab: Sim3, S_ba: Sim3, values: list[float], reason: str) -> Constraint:
    return Constraint(False, reason, S_ab, S_ba, np.zeros((7, 7)), np.zeros((7, 7)), tuple(values), float("inf"))
