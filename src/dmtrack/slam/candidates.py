"""Loop-closure candidates for a new keyframe: near it in the graph (LSD-SLAM's ``TrackableKeyFrameSearch``), or
looking like it (ORB descriptors matched by OpenCV).

* **Distance** (LSD-SLAM's ``findEuclideanOverlapFrames``): a keyframe is a candidate when its camera centre lies
  within ``distance²`` of the new one's, in units of its mean depth (the smaller of the two keyframes' factors
  ``mean idepth / scale``), and their optical axes are within ``angle`` × the mean field of view (LSD-SLAM:
  15/KFDistWeight² = 0.94 and 0.75). Where the graph has drifted, the keyframe the camera came back to is
  not near in the graph, so this search alone misses the loops that matter most.
* **Appearance**: ORB features (``cv2.ORB_create``, 300 per keyframe) matched with a brute-force Hamming matcher and
  Lowe's ratio test (0.8); the keyframes with at least ``min_matches`` matches, best first. Their relative pose is
  started from the matches themselves (:meth:`CandidateSearch.initial_estimate`: PnP of the candidate's points at
  its own depth, RANSAC), not from the drifted graph. ORB needs no training
  data and no vocabulary file, which a bag of words (DBoW2, FabMap) would, and a few hundred keyframes are matched
  exhaustively in milliseconds.

Both searches see only the keyframes they are given (the back end passes those at least ``min_gap`` keyframes
back). The order is deterministic: appearance candidates by decreasing matches, then distance candidates by
increasing distance, without repeats.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from dmtrack.geometry.lie import Sim3


def _grey(image: np.ndarray) -> np.ndarray:
    import cv2

    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img[:, :, :3], cv2.COLOR_RGB2GRAY)
    return np.ascontiguousarray(img, dtype=np.uint8)


class CandidateSearch:
    """See the module docstring."""

    def __init__(
        self,
        distance: float = 15.0 / 16.0,
        angle: float = 0.75,
        n_orb: int = 300,
        ratio: float = 0.8,
        min_matches: int = 40,
        max_appearance: int = 3,
    ) -> None:
        self.distance, self.angle = float(distance), float(angle)
        self.n_orb, self.ratio, self.min_matches = int(n_orb), float(ratio), int(min_matches)
        self.max_appearance = int(max_appearance)
        self._orb: dict[int, Any] = {}  # kf_id → (keypoint pixels (n, 2), descriptors) or None

    def candidates(self, kf: Any, older: list[Any], poses: dict[int, Sim3]) -> list[Any]:
        """Candidates for ``kf`` among ``older`` (keyframes with ``kf_id``, ``image``, ``mean_idepth``, ``view``),
        ``poses`` the graph's current poses."""
        found = [c for _, c in self._by_appearance(kf, older)]
        ids = {c.kf_id for c in found}
        found += [c for _, c in self._by_distance(kf, older, poses) if c.kf_id not in ids]
        return found

    def _by_distance(self, kf: Any, older: list[Any], poses: dict[int, Sim3]) -> list[tuple[float, Any]]:
        cam = kf.view.frame.camera
        fov = 2 * math.atan(cam.width / cam.fx / 2) + 2 * math.atan(cam.height / cam.fy / 2)
        cos_th = math.cos(self.angle * 0.5 * fov)
        me = poses[kf.kf_id]
        fac_me = kf.mean_idepth / me.scale
        axis = np.asarray(me.rotation.matrix())[:, 2]
        out = []
        for c in older:
            other = poses.get(c.kf_id)
            if other is None:
                continue
            fac = min(c.mean_idepth / other.scale, fac_me)
            d2 = float(np.sum(((me.translation - other.translation) * fac) ** 2))
            if d2 > self.distance:
                continue
            if float(np.asarray(other.rotation.matrix())[:, 2] @ axis) < cos_th:
                continue
            out.append((d2, c))
        out.sort(key=lambda x: (x[0], x[1].kf_id))
        return out

    def _orb_of(self, kf: Any) -> Any:
        if kf.kf_id not in self._orb:
            import cv2

            found = None
            if kf.image is not None:
                orb = cv2.ORB_create(nfeatures=self.n_orb)
                kps, desc = orb.detectAndCompute(_grey(kf.image), None)
                if desc is not None and len(desc) >= 2:
                    found = (np.array([k.pt for k in kps], dtype=np.float64), desc)
            self._orb[kf.kf_id] = found
        return self._orb[kf.kf_id]

    def _match(self, a: Any, b: Any) -> list[tuple[int, int]]:
        """Ratio-test ORB matches (index in a, index in b)."""
        import cv2

        oa, ob = self._orb_of(a), self._orb_of(b)
        if oa is None or ob is None:
            return []
        pairs = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(oa[1], ob[1], k=2)
        r = self.ratio
        return [(m[0].queryIdx, m[0].trainIdx) for m in pairs if len(m) == 2 and m[0].distance < r * m[1].distance]

    def _by_appearance(self, kf: Any, older: list[Any]) -> list[tuple[int, Any]]:
        scored = []
        for c in older:
            good = len(self._match(kf, c))
            if good >= self.min_matches:
                scored.append((good, c))
        scored.sort(key=lambda x: (-x[0], x[1].kf_id))
        return scored[: self.max_appearance]

    def initial_estimate(self, kf: Any, cand: Any, min_inliers: int = 20) -> Sim3 | None:
        """``cand → kf`` from their ORB matches: PnP (``cv2.solvePnPRansac``) of the candidate's points, at its own
        inverse depth, in the new keyframe's image, and the scale from the new keyframe's inverse depth at the
        inliers; None when too few matches have depth or agree."""
        import cv2

        from dmtrack.geometry.lie import SO3

        pairs = self._match(kf, cand)
        if len(pairs) < min_inliers:
            return None
        pts_kf, pts_c = self._orb_of(kf)[0], self._orb_of(cand)[0]
        cam = cand.view.frame.camera
        d_c, v_c = cand.view.idepth_pyramid[0]
        d_k, v_k = kf.view.idepth_pyramid[0]
        h, w = d_c.shape
        obj, img, d_new = [], [], []
        for i_kf, i_c in pairs:
            xc, yc = (int(round(q)) for q in pts_c[i_c])
            if not (0 <= xc < w and 0 <= yc < h) or v_c[yc, xc] <= 0 or d_c[yc, xc] <= 0.01:
                continue
            z = 1.0 / float(d_c[yc, xc])
            obj.append(((xc - cam.cx) / cam.fx * z, (yc - cam.cy) / cam.fy * z, z))
            img.append(pts_kf[i_kf])
            xk, yk = (int(round(q)) for q in pts_kf[i_kf])
            ok = 0 <= xk < w and 0 <= yk < h and v_k[yk, xk] > 0 and d_k[yk, xk] > 0.01
            d_new.append(float(d_k[yk, xk]) if ok else 0.0)
        if len(obj) < min_inliers:
            return None
        K = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1]], dtype=np.float64)
        ok, rvec, tvec, inliers = cv2.solvePnPRansac(
            np.array(obj, np.float64), np.array(img, np.float64), K, None, iterationsCount=100,
            reprojectionError=3.0, confidence=0.999, flags=cv2.SOLVEPNP_EPNP,
        )
        if not ok or inliers is None or len(inliers) < min_inliers:
            return None
        R = SO3.exp(rvec.ravel())
        t = tvec.ravel()
        inl = inliers.ravel()
        X = np.array(obj)[inl] @ np.asarray(R.matrix()).T + t  # in the new keyframe's camera, candidate units
        dn = np.array(d_new)[inl]
        has = (dn > 0) & (X[:, 2] > 0)
        if has.sum() < 5:
            return None
        scale = float(np.median(1.0 / (dn[has] * X[has, 2])))  # candidate units → new keyframe units
        return Sim3(R, t * scale, scale)
