"""The start that adapts instead of refusing (issue 37): new corners followed back to the reference frame when
forward motion carries the old ones out of the image, fewer corners when they span the image, a later reference
frame when the first cannot be fitted, and a plane seen by a translating camera told from a rotation."""

from __future__ import annotations

import dataclasses

import numpy as np

import dmtrack
from dmtrack.datasets import open_sequence
from dmtrack.initialization import GeometricInitializer
from dmtrack.initialization.tracks import CornerTracks, grid_coverage
from dmtrack.initialization.twoview import homography_stretch
from dmtrack.odometry.config import VOConfig

#: driving-like forward motion (0.4 m a frame down a 5 m wide hall at 10 Hz): corners leave the image fast
FORWARD = "synthetic:motion=forward,fps=10,speed=4,n_frames=40,width=320,height=240,seed=3"
#: hand-held motion in front of a wall: a homography explains most corners although the camera translates
PLANAR = "synthetic:n_frames=60,width=320,height=240,seed=4"


def _start(seq, config: VOConfig, n: int | None = None) -> GeometricInitializer:  # noqa: ANN001
    g = GeometricInitializer(seq.camera, config)
    for i in range(len(seq) if n is None else n):
        f = seq[i]
        if g.add(i, f.timestamp, f.image):
            break
    return g


def test_forward_driving_is_started_with_corners_followed_back() -> None:
    seq = open_sequence(FORWARD)
    g = _start(seq, VOConfig())
    assert g.state == "accepted" and g.info["accepted_frame"] <= 25 and g.info["references"] == [0]
    assert g.info["redetected"] > 100  # most of the corners it used were found in later frames
    # without following new corners back, the first frame's corners run out: no start within 25 frames
    old = _start(seq, VOConfig().with_overrides("initializer.redetect_below=0"), n=26)
    assert old.state != "accepted"


def test_corners_followed_back_are_the_same_points_in_every_frame() -> None:
    """A corner found in frame 5 and followed back to frame 0 is the same scene point in every frame: its positions
    satisfy the epipolar constraint of the true motion."""
    seq = open_sequence(FORWARD)
    tracks = CornerTracks(seq[0].image)
    for i in range(1, 6):
        tracks.add(seq[i].image)
    n0 = len(tracks.first)
    added = tracks.redetect()
    assert added > 50 and len(tracks.first) == n0 + added and tracks.alive[n0:].all()
    cam = seq.camera
    K = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1.0]])

    def epipolar_px(j: int, rows: slice) -> np.ndarray:  # distance of a track in frame j to its epipolar line
        T = np.linalg.inv(seq.poses[j]) @ seq.poses[0]  # frame 0 → frame j, the true motion
        t = T[:3, 3]
        F = np.linalg.inv(K).T @ np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]]) @ T[:3, :3]
        F = F @ np.linalg.inv(K)
        ok = np.flatnonzero(np.all(np.isfinite(tracks.observations(j)[rows]), axis=1))
        lines = np.c_[tracks.observations(0)[rows][ok], np.ones(len(ok))] @ F.T
        uvj = np.c_[tracks.observations(j)[rows][ok], np.ones(len(ok))]
        return np.abs(np.sum(lines * uvj, axis=1)) / np.hypot(lines[:, 0], lines[:, 1])

    for j in (3, 5):  # as consistent with the true motion as the corners tracked forward from frame 0
        new, old = epipolar_px(j, slice(n0, None)), epipolar_px(j, slice(0, n0))
        assert np.median(new) < 2 * np.median(old) + 0.2 and np.percentile(new, 90) < 5.0


def test_fewer_corners_are_enough_when_they_span_the_image() -> None:
    w, h = 300, 200
    spread = np.array([[x, y] for x in (20, 150, 280) for y in (20, 100, 180) for _ in range(5)], np.float32)
    assert grid_coverage(spread, w, h) == 1.0
    clustered = np.full((45, 2), 10.0, np.float32)
    assert grid_coverage(clustered, w, h) == 1 / 9
    g = GeometricInitializer(dmtrack.geometry.PinholeCamera(200, 200, 150, 100, w, h), VOConfig())
    assert g._enough(spread) and not g._enough(clustered)  # 45 corners: below min_inliers, above min_spread


class _Blank:
    """``seq`` with its first ``n`` frames replaced by a uniform grey image (no corner to track)."""

    def __init__(self, seq, n: int) -> None:  # noqa: ANN001
        self.seq, self.n = seq, n
        for attr in ("camera", "width", "height", "timestamps", "groundtruth", "has_groundtruth", "format", "name"):
            setattr(self, attr, getattr(seq, attr))

    def __len__(self) -> int:
        return len(self.seq)

    def __getitem__(self, i: int):  # noqa: ANN204
        f = self.seq[i]
        return dataclasses.replace(f, image=np.full_like(f.image, 128)) if i < self.n else f


def test_a_reference_that_cannot_be_used_is_replaced_by_a_later_one() -> None:
    seq = _Blank(open_sequence("synthetic:n_frames=40,width=320,height=240,seed=1"), 3)
    r = dmtrack.track(seq, "gray")
    m = r.metrics
    assert m["init_fallback"] is None and m["init_info"]["references"][0] == 0
    assert m["init_info"]["reference_frame"] == 3 and m["init_accepted_frame"] <= 3 + 25
    # the odometry begins at the start's reference frame: the frames before it have no pose, and are counted
    assert m["before_start"] == 3 and m["tracked_frames"] == m["total_frames"] - 3
    assert r.frame_indices[0] == 3 and m["lost_frames"] == 0 and m["ate_rmse"] < 0.01


def test_a_plane_seen_while_translating_is_not_taken_for_a_rotation() -> None:
    seq = open_sequence(PLANAR)
    g = _start(seq, VOConfig())
    assert g.state == "accepted" and g.info["homography_fraction"] > 0.9  # ORB-SLAM's rule would wait forever
    stiff = _start(seq, VOConfig().with_overrides("initializer.min_plane_stretch=1000000.0"))
    assert stiff.state != "accepted"


def test_homography_stretch_of_a_rotation_and_of_a_plane() -> None:
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    R = dmtrack.geometry.SO3.exp([0.02, -0.05, 0.01]).matrix()
    H_rot = K @ R @ np.linalg.inv(K)
    assert homography_stretch(H_rot, K) < 1e-9
    n, d, t = np.array([0.0, 0.0, 1.0]), 2.0, np.array([0.3, 0.0, 0.1])  # a wall 2 m ahead, 0.3 m sideways
    H_plane = K @ (R + np.outer(t, n) / d) @ np.linalg.inv(K)
    assert homography_stretch(H_plane, K) > 0.1
    assert homography_stretch(2.5 * H_plane, K) == homography_stretch(H_plane, K)  # the scale of H does not matter
