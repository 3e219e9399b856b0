"""Two-view geometry (initialization/twoview.py) against a known motion: synthetic points in front of a camera,
projected into a second camera at a known R, t, with a little pixel noise; the motion and the inverse depths come
back, and a rotation without translation is told apart by the homography."""

from __future__ import annotations

import numpy as np
import pytest

from dmtrack.geometry.lie import SO3
from dmtrack.initialization.twoview import two_view

K = np.array([[262.5, 0.0, 159.5], [0.0, 262.5, 119.5], [0.0, 0.0, 1.0]])  # the synthetic renderer's at 320 × 240
W, H = 320, 240


def _project(X: np.ndarray) -> np.ndarray:
    return np.stack([K[0, 0] * X[:, 0] / X[:, 2] + K[0, 2], K[1, 1] * X[:, 1] / X[:, 2] + K[1, 2]], axis=1)


def _views(seed: int, R: np.ndarray, t: np.ndarray, noise_px: float, n: int = 300):
    """``n`` points at depths 1.5–6 m seen in both images (first camera, and x_k = R x_0 + t), with Gaussian pixel
    noise; returns the two pixel sets and the points' true depths in the first camera."""
    rng = np.random.default_rng(seed)
    uv = rng.uniform([10, 10], [W - 10, H - 10], size=(n, 2))
    z = rng.uniform(1.5, 6.0, n)
    X = np.stack([(uv[:, 0] - K[0, 2]) / K[0, 0] * z, (uv[:, 1] - K[1, 2]) / K[1, 1] * z, z], axis=1)
    later = _project(X @ R.T + t)
    seen = (later[:, 0] > 0) & (later[:, 0] < W) & (later[:, 1] > 0) & (later[:, 1] < H)
    a = uv[seen] + rng.normal(0.0, noise_px, (int(seen.sum()), 2))
    b = later[seen] + rng.normal(0.0, noise_px, (int(seen.sum()), 2))
    return a, b, z[seen]


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    c = float(a @ b) / (np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


R_TRUE = np.asarray(SO3.exp([0.02, -0.06, 0.015]).matrix())  # 3.7°
T_TRUE = 0.5 * np.array([0.9, -0.2, 0.3]) / np.linalg.norm([0.9, -0.2, 0.3])  # 0.5 m, mostly sideways


def test_exact_correspondences_give_the_exact_motion_and_depths():
    a, b, z = _views(0, R_TRUE, T_TRUE, noise_px=0.0)
    tv = two_view(a, b, K)
    assert tv is not None and len(tv.inliers) == len(a)
    assert np.degrees(SO3.from_matrix(tv.R @ R_TRUE.T, orthonormalize=True).angle()) < 1e-6
    assert _angle_deg(tv.t, T_TRUE) < 1e-6 and abs(np.linalg.norm(tv.t) - 1.0) < 1e-12  # a unit translation
    # inverse depths in units of the translation: ρ / |t| = 1/z
    assert np.allclose(tv.idepth / np.linalg.norm(T_TRUE), 1.0 / z[tv.inliers], rtol=1e-6)


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_noisy_correspondences_give_the_motion_within_a_degree(seed: int):
    # 0.3 px of noise: cv2.findEssentialMat's RANSAC returns its best minimal-sample model, unrefined, which is off
    # by 0.2–0.7° here (a refined model, cv2.USAC_ACCURATE, would be within 0.1°); the bundle adjustment refines it
    a, b, z = _views(seed, R_TRUE, T_TRUE, noise_px=0.3)
    tv = two_view(a, b, K)
    assert tv is not None and len(tv.inliers) > 0.8 * len(a)
    rot = float(np.degrees(SO3.from_matrix(tv.R @ R_TRUE.T, orthonormalize=True).angle()))
    assert rot < 1.0, rot
    assert _angle_deg(tv.t, T_TRUE) < 5.0, _angle_deg(tv.t, T_TRUE)  # the direction of motion, sign included
    est = tv.idepth / np.linalg.norm(T_TRUE)  # from the translation's units to 1/metres
    ok = np.isfinite(est)
    assert ok.mean() > 0.95
    rel = np.abs(est[ok] * z[tv.inliers][ok] - 1.0)
    assert np.median(rel) < 0.15, np.median(rel)
    assert tv.parallax_deg > 2.0 and tv.homography_fraction < 0.9


def test_a_rotation_without_translation_is_all_homography():
    a, b, _ = _views(6, R_TRUE, np.zeros(3), noise_px=0.3)
    tv = two_view(a, b, K)
    # the essential matrix of a pure rotation is degenerate (None is an answer too); when one is fitted, the
    # homography explains the inliers and the parallax is nil: the start's cue that the camera has not moved
    if tv is not None:
        assert tv.homography_fraction > 0.95 and tv.parallax_deg < 0.5
