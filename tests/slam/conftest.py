"""Keyframes rendered by the synthetic renderer for the SLAM tests: real images, exact inverse depths, and the back
end's own keyframe objects (:class:`~dmtrack.slam.backend.SlamKeyframe` with a
:class:`~dmtrack.slam.constraints.KeyframeView` of their grey images)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from dmtrack.geometry.lie import SO3, Sim3
from dmtrack.odometry.frame import build_frame
from dmtrack.odometry.tracker import TrackingReference
from dmtrack.slam.backend import SlamKeyframe
from dmtrack.slam.constraints import KeyframeView


class Room:
    """The rendered room (``rendered_room``: seed 3, 320 × 240, poses around its first camera) with the back end's
    keyframes."""

    def __init__(self, base: Any) -> None:
        self.seq, self.camera, self.pose, self.render = base.seq, base.camera, base.pose, base.render

    def keyframe(
        self, kf_id: int, T_wc: np.ndarray, norm: float = 1.0, image: np.ndarray | None = None,
        idepth: np.ndarray | None = None,
    ) -> SlamKeyframe:
        """A keyframe seen from ``T_wc`` in units where its inverse depth is ``norm`` × the true one (a keyframe's
        own scale), or with the ``image`` and ``idepth`` (1/metres) given instead of the rendered ones."""
        rendered, true_idepth = self.render(T_wc) if image is None or idepth is None else (None, None)
        image = rendered if image is None else image
        idepth = ((true_idepth if idepth is None else idepth) * norm).astype(np.float32)
        var = np.full_like(idepth, 1e-4 * norm**2)
        views: dict[int, KeyframeView] = {}

        def load(kf: SlamKeyframe) -> KeyframeView:
            if not views:
                frame = build_frame(kf_id, float(kf_id), image, image.astype(np.float32), self.camera, n_levels=5)
                views[0] = KeyframeView(frame, TrackingReference.from_keyframe(frame, idepth, var, levels=()))
            return views[0]

        # the pose maps keyframe units to the world: p_w = norm · R p + t
        pose = Sim3(SO3.from_matrix(T_wc[:3, :3], orthonormalize=True), T_wc[:3, 3], norm)
        return SlamKeyframe(kf_id, kf_id, float(kf_id), pose, image, idepth, var, self.camera, float(idepth.mean()),
                            load_view=load)


@pytest.fixture(scope="session")
def room(rendered_room: Any) -> Room:
    return Room(rendered_room)
