"""Two-view geometry between the first frame and a later one, from corner tracks (OpenCV).

:func:`two_view` fits an essential matrix with RANSAC (``cv2.findEssentialMat``), recovers the relative pose
(``cv2.recoverPose``: the one of the four decompositions that puts most points in front of both cameras),
triangulates the inliers (``cv2.triangulatePoints``) and measures their parallax — the angle between the two
rays of a point. It also fits a homography to the same inliers (``cv2.findHomography``) and reports the fraction
it explains within 2 px: near 1, the motion so far is a rotation (or the scene a plane), and the translation is
not yet seen in the images (ORB-SLAM's reason to choose between the two models).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from dmtrack.geometry import exact

__all__ = ["ESSENTIAL_METHODS", "TwoView", "bearings", "homography_stretch", "ray_parallax_deg", "two_view"]

HOMOGRAPHY_PX = 2.0
"""Tolerance of the homography test, pixels."""

#: ``method`` of :func:`two_view`: OpenCV's robust estimator of the essential matrix.
ESSENTIAL_METHODS = {"ransac": cv2.RANSAC, "magsac": cv2.USAC_MAGSAC, "accurate": cv2.USAC_ACCURATE}


@dataclass(frozen=True)
class TwoView:
    """The relative pose of a later frame and the points it was estimated from.

    Attributes
    ----------
    R, t : (3, 3), (3,) float64
        Rotation and unit translation of the first camera's frame into the later one's (x_k = R·x_0 + t).
    inliers : (m,) int
        Track indices consistent with the essential matrix and in front of both cameras.
    idepth : (m,) float64
        Their inverse depths in the first camera, in units of the translation (NaN where not triangulable).
    parallax_deg : float
        Median parallax angle of the inliers, degrees.
    homography_fraction : float
        Fraction of the inliers a homography explains within :data:`HOMOGRAPHY_PX`.
    homography_stretch : float
        How far that homography is from a rotation: σ₁/σ₃ − 1 of K⁻¹HK (0 for a rotation about the camera centre,
        which maps rays without changing their angles; a plane seen by a translating camera stretches them).
    """

    R: np.ndarray
    t: np.ndarray
    inliers: np.ndarray
    idepth: np.ndarray
    parallax_deg: float
    homography_fraction: float
    homography_stretch: float = 0.0


def two_view(
    first: np.ndarray, later: np.ndarray, K: np.ndarray, ransac_px: float = 1.0, min_points: int = 8,
    method: str = "ransac",
) -> TwoView | None:
    """The two-view geometry of matched points ``first`` ↔ ``later`` ((n, 2) pixels), or None when it fails.

    Parameters
    ----------
    K : (3, 3)
        The pinhole intrinsics.
    ransac_px : float
        RANSAC threshold of the essential matrix, pixels.
    min_points : int
        Fewest points to try (and fewest inliers to return a result).
    method : str
        The robust estimator of the essential matrix (:data:`ESSENTIAL_METHODS`): ``"ransac"`` (``cv2.RANSAC``),
        ``"magsac"`` (``cv2.USAC_MAGSAC``) or ``"accurate"`` (``cv2.USAC_ACCURATE``).
    """
    a = np.ascontiguousarray(first, np.float64)
    b = np.ascontiguousarray(later, np.float64)
    if len(a) < max(min_points, 8):
        return None
    K = np.asarray(K, np.float64)
    if method not in ESSENTIAL_METHODS:
        raise ValueError(f"essential-matrix method must be one of {', '.join(ESSENTIAL_METHODS)}, got {method!r}")
    E, mask = cv2.findEssentialMat(a, b, K, ESSENTIAL_METHODS[method], 0.999, float(ransac_px))
    if E is None or E.shape != (3, 3) or mask is None:
        return None  # no model, or several stacked: degenerate
    # distanceThresh: keep far points (small parallax) as inliers; they still fix the rotation
    _n, R, t, pose_mask, _X = cv2.recoverPose(E, a, b, K, distanceThresh=1e6, mask=mask.copy())
    inl = np.flatnonzero(pose_mask[:, 0] > 0)
    if len(inl) < min_points:
        return None
    t = t.ravel() / max(exact.norm(t.ravel()), 1e-300)
    idepth = triangulate_idepth(a[inl], b[inl], K, R, t)
    par = ray_parallax_deg(a[inl], idepth, K, R, t)
    H, hmask = cv2.findHomography(a[inl], b[inl], cv2.RANSAC, HOMOGRAPHY_PX)
    h_frac = 1.0 if H is None else float(np.count_nonzero(hmask)) / len(inl)
    finite = np.isfinite(par)
    return TwoView(
        R=R,
        t=t,
        inliers=inl,
        idepth=idepth,
        parallax_deg=float(np.median(par[finite])) if finite.any() else 0.0,
        homography_fraction=h_frac,
        homography_stretch=0.0 if H is None else homography_stretch(H, K),
    )


def homography_stretch(H: np.ndarray, K: np.ndarray) -> float:
    """σ₁/σ₃ − 1 of the normalised homography K⁻¹HK: 0 for a pure rotation, more for a translating camera in front of
    a plane. The singular values come from the eigenvalues of the symmetric 3×3 matrix MᵀM in closed form
    (trigonometric solution, no LAPACK: the same bits on every CPU)."""
    Kinv = np.array([[1.0 / K[0, 0], 0.0, -K[0, 2] / K[0, 0]], [0.0, 1.0 / K[1, 1], -K[1, 2] / K[1, 1]],
                     [0.0, 0.0, 1.0]])  # fmt: skip
    M = exact.matmul(exact.matmul(Kinv, np.asarray(H, np.float64)), np.asarray(K, np.float64))
    A = exact.matmul(M.T, M)
    lam = _symmetric_eigenvalues(A)
    if not lam[0] > 0:
        return float("inf")
    return float(np.sqrt(lam[2] / lam[0])) - 1.0


def _symmetric_eigenvalues(A: np.ndarray) -> tuple[float, float, float]:
    """Eigenvalues, increasing, of a symmetric 3×3 matrix (Smith's closed form)."""
    a = [[float(x) for x in row] for row in A]
    p1 = a[0][1] ** 2 + a[0][2] ** 2 + a[1][2] ** 2
    q = (a[0][0] + a[1][1] + a[2][2]) / 3.0
    if p1 == 0.0:
        return tuple(sorted((a[0][0], a[1][1], a[2][2])))  # type: ignore[return-value]
    p2 = (a[0][0] - q) ** 2 + (a[1][1] - q) ** 2 + (a[2][2] - q) ** 2 + 2.0 * p1
    p = (p2 / 6.0) ** 0.5
    b = [[(a[i][j] - (q if i == j else 0.0)) / p for j in range(3)] for i in range(3)]
    det = (b[0][0] * (b[1][1] * b[2][2] - b[1][2] * b[2][1]) - b[0][1] * (b[1][0] * b[2][2] - b[1][2] * b[2][0])
           + b[0][2] * (b[1][0] * b[2][1] - b[1][1] * b[2][0]))  # fmt: skip
    r = min(1.0, max(-1.0, det / 2.0))
    phi = float(np.arccos(r)) / 3.0
    e1 = q + 2.0 * p * float(np.cos(phi))
    e3 = q + 2.0 * p * float(np.cos(phi + 2.0 * np.pi / 3.0))
    e2 = 3.0 * q - e1 - e3
    return tuple(sorted((e1, e2, e3)))  # type: ignore[return-value]


def bearings(uv: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(n, 3) rays K⁻¹·(u, v, 1) of pixels ``uv`` (z = 1), element by element (no BLAS: the same bits anywhere)."""
    uv = np.asarray(uv, np.float64)
    out = np.ones((len(uv), 3))
    out[:, 0] = (uv[:, 0] - K[0, 2]) / K[0, 0]
    out[:, 1] = (uv[:, 1] - K[1, 2]) / K[1, 1]
    return out


def triangulate_idepth(a: np.ndarray, b: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Inverse depths in the first camera of points seen at ``a`` and ``b`` (DLT, ``cv2.triangulatePoints``); NaN
    for points at infinity or behind the first camera."""
    P0 = exact.matmul(K, np.hstack([np.eye(3), np.zeros((3, 1))]))
    P1 = exact.matmul(K, np.hstack([R, t.reshape(3, 1)]))
    X = cv2.triangulatePoints(P0, P1, np.ascontiguousarray(a.T, np.float64), np.ascontiguousarray(b.T, np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        idepth = X[3] / X[2]  # 1 / z of (X/W)
    idepth[~np.isfinite(idepth) | (idepth <= 0)] = np.nan
    return idepth


def ray_parallax_deg(a: np.ndarray, idepth: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Angle between the two rays of each point (first camera at ``a`` with ``idepth``; the later camera at
    −Rᵀt), degrees; NaN where the inverse depth is."""
    X = bearings(a, K) / idepth[:, None]
    c = -np.einsum("ba,b->a", R, t)
    r0 = X / np.linalg.norm(X, axis=1, keepdims=True)
    d = X - c
    r1 = d / np.linalg.norm(d, axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip(np.sum(r0 * r1, axis=1), -1.0, 1.0)))
