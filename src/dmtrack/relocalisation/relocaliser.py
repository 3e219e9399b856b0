"""Where is a lost frame? Direct alignment to the keyframes it most likely sees, under LSD-SLAM's relocaliser's tests
(with thresholds measured for dmtrack's tracker).

For a frame at which tracking is lost (or any frame after it, until one is found) :meth:`Relocaliser.find` takes at
most ``relocalisation.max_candidates`` keyframes, in this order and without repeats:

1. the odometry's current keyframe, from its last pose on it (the camera may only have shaken);
2. kept keyframes that look like the frame: ORB matches (:class:`~dmtrack.slam.candidates.CandidateSearch`), their
   relative pose started from the matches (PnP of the keyframe's points at its own depth);
3. kept keyframes near the last pose the odometry had (the camera may not have gone far), nearest first.

Each is aligned coarse to fine with the odometry's own tracker (:class:`~dmtrack.odometry.tracker.Tracker`) and must
pass :func:`~dmtrack.odometry.relocalisation_quality.relocalisation_failure` (point usage × good ratio > 0.5,
good ratio ≥ 0.75: ``RelocConfig``; LSD-SLAM's are 0.7 and 0.625). A keyframe that passes is confirmed as LSD-SLAM
does: the frame is aligned to each of the keyframe's neighbours (its parent and the keyframes made next to it),
starting from the pose the first alignment implies, and at least as many neighbours must agree (score > 0.8 × 0.5,
the two poses within a twist of 0.1) as disagree, one at least. The best-scoring of the keyframe and its agreeing
neighbours is where the odometry resumes. A wrong place that looks alike fails there: the neighbours see the frame
elsewhere, or not at all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from dmtrack.geometry.exact import matmul
from dmtrack.odometry.config import VOConfig
from dmtrack.odometry.frame import Frame
from dmtrack.odometry.records import StoredKeyframe
from dmtrack.odometry.relocalisation_quality import good_value, relocalisation_failure
from dmtrack.odometry.tracker import Tracker, TrackingReference, TrackResult
from dmtrack.relocalisation.store import KeyframeStore, RelocKeyframe

__all__ = ["Found", "Relocaliser", "frame_in_world", "pose_on_keyframe"]


def _inv(T: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -matmul(T[:3, :3].T, T[:3, 3])
    return out


def frame_in_world(kf_T_wc: np.ndarray, kf_scale: float, T_fk: np.ndarray) -> np.ndarray:
    """The frame's SE(3) camera-to-world pose (world units) from its pose ``T_fk`` (keyframe → frame, keyframe units)
    on a keyframe at ``kf_T_wc`` with Sim(3) scale ``kf_scale``."""
    T_kf = _inv(np.asarray(T_fk, np.float64))  # frame → keyframe (keyframe units)
    out = np.eye(4)
    out[:3, :3] = matmul(kf_T_wc[:3, :3], T_kf[:3, :3])
    out[:3, 3] = kf_scale * matmul(kf_T_wc[:3, :3], T_kf[:3, 3]) + kf_T_wc[:3, 3]
    return out


def pose_on_keyframe(kf_T_wc: np.ndarray, kf_scale: float, T_wf: np.ndarray) -> np.ndarray:
    """``T_fk`` (keyframe → frame, keyframe units) of a frame at ``T_wf`` (world) on a keyframe at ``kf_T_wc`` with
    scale ``kf_scale``: the inverse of :func:`frame_in_world`."""
    T_kf = np.eye(4)
    T_kf[:3, :3] = matmul(kf_T_wc[:3, :3].T, T_wf[:3, :3])
    T_kf[:3, 3] = matmul(kf_T_wc[:3, :3].T, T_wf[:3, 3] - kf_T_wc[:3, 3]) / kf_scale
    return _inv(T_kf)


def _twist_norm(T: np.ndarray) -> float:
    """‖log T‖ of an SE(3) matrix: the rotation angle and the translation (as LSD-SLAM's ``log().norm()``)."""
    c = float(np.clip((np.trace(T[:3, :3]) - 1.0) / 2.0, -1.0, 1.0))
    return math.hypot(math.acos(c), float(np.sqrt(np.sum(np.asarray(T[:3, 3]) ** 2))))


@dataclass(frozen=True)
class Found:
    """A relocalisation: the keyframe the frame was found on, ``T_fk`` (keyframe → frame, keyframe units), the
    tracker's level-1 flags, its score and how the neighbours voted; ``via`` says how the keyframe was proposed
    (``current``, ``appearance``, ``distance``)."""

    keyframe: StoredKeyframe
    T_fk: np.ndarray
    good: np.ndarray
    value: float
    neighbours_good: int
    neighbours_bad: int
    via: str


class Relocaliser:
    """Finds lost frames on kept keyframes (see the module docstring).

    Parameters
    ----------
    store : the run's :class:`~dmtrack.relocalisation.store.KeyframeStore`.
    config : the run's odometry configuration (``relocalisation``, ``tracker``).
    tracker : the odometry's :class:`~dmtrack.odometry.tracker.Tracker` (its kernels and settings).
    search : the appearance search (:class:`~dmtrack.slam.candidates.CandidateSearch`); None: no appearance
        candidates.
    """

    def __init__(self, store: KeyframeStore, config: VOConfig, tracker: Tracker, search: Any = None) -> None:
        self.store = store
        self.config = config
        self.cfg = config.relocalisation
        self.tracker = tracker
        self.search = search
        self.tried: list[tuple[int, int, str, str | None]] = []  # (frame, keyframe, via, why not)

    def candidates(self, frame: Frame, last_T_wc: np.ndarray | None,
                   current: tuple[Any, np.ndarray] | None) -> list[tuple[str, Any, np.ndarray]]:  # fmt: skip
        """(via, keyframe, T_fk to start from) in the order they are tried."""
        out: list[tuple[str, Any, np.ndarray]] = []
        seen: set[int] = set()
        if current is not None:
            out.append(("current", current[0], current[1]))
            seen.add(current[0].keyframe_id)
        kept = [k for k in self.store.keyframes.values() if k.kf_id not in seen]
        if self.search is not None and frame.image is not None and kept:
            for _, kf in self.search.by_appearance_of_image(frame.index, frame.image, kept):
                if kf.kf_id in seen:
                    continue
                T_ck, _n = self.search.pose_of_image(frame.index, kf)
                T0 = (np.asarray(T_ck.matrix(), np.float64) if T_ck is not None
                      else pose_on_keyframe(kf.T_wc, kf.scale, last_T_wc) if last_T_wc is not None else np.eye(4))
                out.append(("appearance", kf, T0))
                seen.add(kf.kf_id)
        if last_T_wc is not None:
            near = sorted((k for k in kept if k.kf_id not in seen),
                          key=lambda k: (float(np.sum((k.T_wc[:3, 3] - last_T_wc[:3, 3]) ** 2)) / k.scale**2, k.kf_id))
            out += [("distance", k, pose_on_keyframe(k.T_wc, k.scale, last_T_wc)) for k in near]
        return out[: self.cfg.max_candidates]

    def _align(self, kf: Any, frame: Frame, T0: np.ndarray) -> TrackResult:
        ref: TrackingReference = kf.view.reference if isinstance(kf, RelocKeyframe) else kf.reference
        return self.tracker.track(ref, frame, T0)

    def find(self, frame: Frame, last_T_wc: np.ndarray | None,
             current: tuple[StoredKeyframe, TrackingReference, np.ndarray] | None = None,
             residual_limit: float | None = None) -> Found | None:  # fmt: skip
        """The keyframe ``frame`` is on, or None. ``current``: the odometry's current keyframe, its tracking
        reference and the last ``T_fk`` on it; ``residual_limit``: the largest residual of an alignment with no bad
        point (the odometry's :meth:`~dmtrack.odometry.losses.LossHandling.residual_limit`)."""
        cur = None
        if current is not None:
            stored, ref, T_last = current
            cur = (_Current(stored, ref), T_last)
        for via, kf, T0 in self.candidates(frame, last_T_wc, None if cur is None else (cur[0], cur[1])):
            res = self._align(kf, frame, T0)
            why = relocalisation_failure(res, self.cfg, residual_limit=residual_limit)
            kf_id = kf.keyframe_id if isinstance(kf, _Current) else kf.kf_id
            if why is None:
                found = self._confirm(via, kf, res, frame, residual_limit)
                if found is not None:
                    self.tried.append((int(frame.index), kf_id, via, None))
                    return found
                why = "its neighbours did not confirm it"
            self.tried.append((int(frame.index), kf_id, via, why))
        return None

    def _confirm(self, via: str, kf: Any, res: TrackResult, frame: Frame,
                 residual_limit: float | None) -> Found | None:  # fmt: skip
        """LSD-SLAM's neighbour check; the best-scoring of the keyframe and its agreeing neighbours."""
        stored = kf.stored if isinstance(kf, _Current) else kf.stored()
        kf_id = stored.keyframe_id
        T_wf = frame_in_world(stored.T_wc, stored.scale, res.T_fk)
        best = (good_value(res), stored, res)
        good = bad = 0
        for nkf in self.store.neighbours(kf_id):
            T0 = pose_on_keyframe(nkf.T_wc, nkf.scale, T_wf)
            r = self._align(nkf, frame, T0)
            value = good_value(r)
            agree = (relocalisation_failure(r, self.cfg, self.cfg.neighbour_factor, residual_limit) is None
                     and _twist_norm(matmul(r.T_fk, _inv(T0))) < self.cfg.consistency)  # fmt: skip
            if agree:
                good += 1
                if value > best[0]:
                    best = (value, nkf.stored(), r)
            else:
                bad += 1
        if good < max(1, bad):
            return None
        value, stored_best, r = best
        return Found(stored_best, np.array(r.T_fk, np.float64), r.ref_pixel_was_good, value, good, bad, via)


@dataclass(frozen=True)
class _Current:
    """The odometry's current keyframe as a candidate."""

    stored: StoredKeyframe
    reference: TrackingReference

    @property
    def keyframe_id(self) -> int:
        return self.stored.keyframe_id
