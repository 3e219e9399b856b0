"""Loop-closure candidates for a new keyframe: near it in the graph (LSD-SLAM's ``TrackableKeyFrameSearch``), or
looking like it (ORB descriptors, an index of every keyframe's, and OpenCV's matcher); and the same appearance
search for an image that is not a keyframe (relocalisation).

* **Distance** (LSD-SLAM's ``findEuclideanOverlapFrames``): a keyframe is a candidate when its camera centre lies
  within ``distance²`` of the new one's, in units of its mean depth (the smaller of the two keyframes' factors
  ``mean idepth / scale``), and their optical axes are within ``angle`` × the mean field of view (LSD-SLAM:
  15/KFDistWeight² = 0.94 and 0.75). Where the graph has drifted, the keyframe the camera came back to is
  not near in the graph, so this search alone misses the loops that matter most.
* **Appearance**: ORB features (``cv2.ORB_create``, 300 per keyframe) matched with a brute-force Hamming matcher and
  Lowe's ratio test (0.8); the keyframes with at least ``min_matches`` matches, best first. ORB needs no training
  data and no vocabulary file, which a bag of words (DBoW2, FabMap) would. Every keyframe's descriptors enter an
  index (:class:`~dmtrack.slam.orb_index.OrbIndex`, a multi-table LSH): a query's descriptors vote for the keyframes
  whose descriptors they meet, and only the ``shortlist`` keyframes with the most votes are matched pairwise, so a
  keyframe costs a bounded number of look-ups and ``shortlist`` matchings however many keyframes the run has
  (matching every older keyframe, ``shortlist=None``, is the reference: about 0.7 ms per keyframe of the run, for
  every new keyframe; ``benchmarks/candidate_search_speed.py``).
  The pairwise matches of the latest queries are kept, so the relative pose (:meth:`CandidateSearch.
  initial_estimate`: PnP of the candidate's points at its own depth, RANSAC, and the scale from the new keyframe's
  depth) is started from the matches already made, not from the drifted graph.

Both searches see only the keyframes they are given (the back end passes those at least ``min_gap`` keyframes
back). The order is deterministic: appearance candidates by decreasing matches (ties: the older keyframe first), then
distance candidates by increasing distance, without repeats.

**Relocalisation.** :meth:`CandidateSearch.by_appearance_of_image` ranks keyframes for any image (the frame at which
tracking was lost), its ORB features computed once and kept under a key of the caller's; :meth:`CandidateSearch.
pose_of_image` then gives the image's pose relative to one of them from their matches.

**Directions.** Both poses place the *candidate* in the other camera. A point ``p`` of the candidate's camera, in
the candidate's units (its inverse depth's: a point at inverse depth ρ is 1/ρ from the camera), is ``s R p + t`` in
the new keyframe's camera, in the new keyframe's units (:meth:`~CandidateSearch.initial_estimate`, a Sim(3) whose
scale ``s`` turns the one's units into the other's), and ``R p + t`` in the image's camera
(:meth:`~CandidateSearch.pose_of_image`, an SE(3): the image has no depth, so ``t`` stays in the candidate's units).
The inverses are the other camera's pose in the candidate.

Keyframes are the back end's (:class:`~dmtrack.slam.backend.SlamKeyframe`): ``kf_id``, ``image``, ``mean_idepth``
and ``view`` (``view.idepth_pyramid[0]``: the inverse depth and its variance at full resolution,
``view.frame.camera``: the pinhole camera).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Hashable
from typing import Any

import numpy as np

from dmtrack.geometry.lie import SE3, SO3, Sim3
from dmtrack.slam.orb_index import OrbIndex

#: an ORB detection: keypoint pixels (n, 2) float64 and descriptors (n, 32) uint8; None when an image has fewer than 2
Orb = tuple[np.ndarray, np.ndarray] | None


def _grey(image: np.ndarray) -> np.ndarray:
    import cv2

    img = np.asarray(image)
    if img.ndim == 3:
        img = cv2.cvtColor(img[:, :, :3], cv2.COLOR_RGB2GRAY)
    return np.ascontiguousarray(img, dtype=np.uint8)


class CandidateSearch:
    """Loop candidates of keyframes and appearance ranking of images (see the module docstring).

    Its caches and index are not guarded: one thread at a time (the back end's, or a caller holding a lock).

    Parameters
    ----------
    distance, angle : float
        The distance search's thresholds (LSD-SLAM's).
    n_orb : int
        ORB features per image.
    ratio : float
        Lowe's ratio of the pairwise matching.
    min_matches : int
        Fewest pairwise matches of an appearance candidate.
    max_appearance : int
        Most appearance candidates of a keyframe (and, by default, of an image).
    shortlist : int or None
        Keyframes, by the index's votes, matched pairwise for each query; None: every keyframe given (the
        exhaustive reference, linear in the keyframes for each query).
    index : OrbIndex or None
        The index of the keyframes' descriptors (default: ``OrbIndex()``).
    cached_queries : int
        Queries (keyframes or images) whose pairwise matches are kept, and images whose ORB features are kept.
    """

    def __init__(
        self,
        distance: float = 15.0 / 16.0,
        angle: float = 0.75,
        n_orb: int = 300,
        ratio: float = 0.8,
        min_matches: int = 40,
        max_appearance: int = 3,
        shortlist: int | None = 12,
        index: OrbIndex | None = None,
        cached_queries: int = 8,
    ) -> None:
        self.distance, self.angle = float(distance), float(angle)
        self.n_orb, self.ratio, self.min_matches = int(n_orb), float(ratio), int(min_matches)
        self.max_appearance = int(max_appearance)
        self.shortlist = None if shortlist is None else int(shortlist)
        self.index = index if index is not None else OrbIndex()
        self.cached_queries = max(int(cached_queries), 1)
        self.pairs_matched = 0  #: pairwise matchings run so far (what the index and the caches save)
        self._orb: dict[int, Orb] = {}  # kf_id → its ORB detection, for the run
        self._images: OrderedDict[Hashable, Orb] = OrderedDict()  # image key → ORB, the newest last
        # ("kf", kf_id) or ("image", key) → {candidate kf_id: (m, 2) matches (index in the query, in the candidate)}
        self._matches: OrderedDict[tuple[str, Hashable], dict[int, np.ndarray]] = OrderedDict()

    # -- keyframes ---------------------------------------------------------------------------------------------------

    def candidates(self, kf: Any, older: list[Any], poses: dict[int, Sim3]) -> list[Any]:
        """Candidates for ``kf`` among ``older`` (keyframes with ``kf_id``, ``image``, ``mean_idepth``, ``view``),
        ``poses`` the graph's current poses: by appearance, best first, then by distance, without repeats."""
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

    def _by_appearance(self, kf: Any, older: list[Any]) -> list[tuple[int, Any]]:
        """(matches, keyframe) of ``kf``'s appearance candidates among ``older``, best first."""
        orb = self._orb_of(kf)
        self._indexed(kf)
        return self._appearance(("kf", kf.kf_id), orb, older, self.max_appearance)

    def initial_estimate(self, kf: Any, cand: Any, min_inliers: int = 20) -> Sim3 | None:
        """The Sim(3) ``cand → kf`` from their ORB matches, or None when too few matches have depth or agree.

        It maps a point of the candidate's camera, in the candidate's units, to the new keyframe's camera in the
        new keyframe's units (``p_kf = s R p_cand + t``: the pose of the candidate in the new keyframe). PnP
        (``cv2.solvePnPRansac``) places the candidate's points, at its own inverse depth, in the new keyframe's
        image; the scale is the median ratio of the new keyframe's depth to theirs at the inliers. The matches are
        those :meth:`candidates` made for this pair when it is among the latest queries (not made again).
        """
        orb = self._orb_of(kf)
        if orb is None:
            return None
        pairs = self._matches_of(("kf", kf.kf_id), orb, cand)
        found, _ = self._pnp(pairs, orb[0], cand, min_inliers)
        if found is None:
            return None
        R, t, obj, query_px = found
        X = obj @ np.asarray(R.matrix()).T + t  # in the new keyframe's camera, candidate units
        d_k, v_k = kf.view.idepth_pyramid[0]
        h, w = d_k.shape
        d_new = np.zeros(len(obj))
        for n, (x, y) in enumerate(query_px):
            xk, yk = int(round(x)), int(round(y))
            if 0 <= xk < w and 0 <= yk < h and v_k[yk, xk] > 0 and d_k[yk, xk] > 0.01:
                d_new[n] = float(d_k[yk, xk])
        has = (d_new > 0) & (X[:, 2] > 0)
        if has.sum() < 5:
            return None
        scale = float(np.median(1.0 / (d_new[has] * X[has, 2])))  # candidate units → new keyframe units
        return Sim3(R, t * scale, scale)

    # -- images (relocalisation) -------------------------------------------------------------------------------------

    def by_appearance_of_image(
        self, key: Hashable, image: np.ndarray, older: list[Any], limit: int | None = None,
    ) -> list[tuple[int, Any]]:
        """The keyframes of ``older`` that look like ``image`` (not a keyframe: e.g. the frame at which tracking was
        lost), as (pairwise ORB matches, keyframe), most matches first (ties: the older keyframe first), each with at
        least ``min_matches``; at most ``limit`` (default ``max_appearance``).

        ``key`` names the image for the caller (a frame index): its ORB features are computed once and kept under
        it, with the matches made, for :meth:`pose_of_image`, for the latest ``cached_queries`` images (a key names
        one image: the same key with another image gives the first one's features while it is cached).
        """
        if key in self._images:
            self._images.move_to_end(key)
        else:
            self._images[key] = self._detect(image)
            while len(self._images) > self.cached_queries:
                old, _ = self._images.popitem(last=False)
                self._matches.pop(("image", old), None)
        limit = self.max_appearance if limit is None else int(limit)
        return self._appearance(("image", key), self._images[key], older, limit)

    def pose_of_image(self, key: Hashable, cand: Any, min_inliers: int = 20) -> tuple[SE3 | None, int]:
        """The pose of the candidate keyframe ``cand`` in the camera of the image cached under ``key`` (by
        :meth:`by_appearance_of_image`), and the PnP inliers it rests on; (None, inliers so far) when too few.

        The SE(3) maps the candidate's camera coordinates to the image's: ``p_image = R p_cand + t``, ``t`` in the
        candidate's units (the image has no depth to give a scale). Its inverse is the image's camera-to-candidate
        pose. It is PnP with RANSAC (``cv2.solvePnPRansac``) of the candidate's points at its own inverse depth on
        their ORB matches in the image, as :meth:`initial_estimate` without the scale.
        """
        if key not in self._images:
            raise KeyError(f"no image is cached under {key!r}: call by_appearance_of_image first")
        orb = self._images[key]
        if orb is None:
            return None, 0
        pairs = self._matches_of(("image", key), orb, cand)
        found, n_inliers = self._pnp(pairs, orb[0], cand, min_inliers)
        if found is None:
            return None, n_inliers
        R, t, _, _ = found
        return SE3(R, t), n_inliers

    # -- ORB, the index and the matches ------------------------------------------------------------------------------

    def _detect(self, image: np.ndarray | None) -> Orb:
        import cv2

        if image is None:
            return None
        kps, desc = cv2.ORB_create(nfeatures=self.n_orb).detectAndCompute(_grey(image), None)
        if desc is None or len(desc) < 2:
            return None
        return np.array([k.pt for k in kps], dtype=np.float64), desc

    def _orb_of(self, kf: Any) -> Orb:
        if kf.kf_id not in self._orb:
            self._orb[kf.kf_id] = self._detect(kf.image)
        return self._orb[kf.kf_id]

    def _indexed(self, kf: Any) -> None:
        """Put ``kf``'s descriptors in the index, once."""
        if self.shortlist is not None and kf.kf_id not in self.index:
            orb = self._orb_of(kf)
            self.index.add(kf.kf_id, orb[1] if orb is not None else np.zeros((0, 32), np.uint8))

    def _appearance(self, query: tuple[str, Hashable], orb: Orb, older: list[Any], limit: int) -> list[tuple[int, Any]]:
        """(matches, keyframe) of the keyframes of ``older`` with at least ``min_matches`` pairwise matches with the
        query's ``orb``, most first, at most ``limit``: among the index's shortlist, or all (``shortlist=None``)."""
        if orb is None or limit <= 0:
            return []
        if self.shortlist is None:
            pool = older
        else:
            for c in older:
                self._indexed(c)
            by_id = {c.kf_id: c for c in older}
            pool = [by_id[k] for k in self.index.shortlist(orb[1], self.shortlist, by_id)]
        scored = []
        for c in pool:
            good = len(self._matches_of(query, orb, c))
            if good >= self.min_matches:
                scored.append((good, c))
        scored.sort(key=lambda x: (-x[0], x[1].kf_id))
        return scored[:limit]

    def _matches_of(self, query: tuple[str, Hashable], orb: Orb, cand: Any) -> np.ndarray:
        """The query's ratio-test matches with ``cand`` ((m, 2): index in the query, in the candidate), from the
        cache of the latest ``cached_queries`` queries or made now."""
        per = self._matches.get(query)
        if per is None:
            per = self._matches[query] = {}
            while len(self._matches) > self.cached_queries:
                self._matches.popitem(last=False)
        else:
            self._matches.move_to_end(query)
        found = per.get(cand.kf_id)
        if found is None:
            other = self._orb_of(cand)
            found = per[cand.kf_id] = self._ratio_matches(orb, other)
        return found

    def _ratio_matches(self, a: Orb, b: Orb) -> np.ndarray:
        """Lowe's ratio-test matches of ``a``'s descriptors among ``b``'s (cv2.BFMatcher, Hamming, k = 2)."""
        import cv2

        if a is None or b is None:
            return np.zeros((0, 2), np.int64)
        self.pairs_matched += 1
        pairs = cv2.BFMatcher(cv2.NORM_HAMMING).knnMatch(a[1], b[1], k=2)
        r = self.ratio
        good = [(m[0].queryIdx, m[0].trainIdx) for m in pairs if len(m) == 2 and m[0].distance < r * m[1].distance]
        return np.array(good, dtype=np.int64).reshape(-1, 2)

    def _pnp(
        self, pairs: np.ndarray, query_px: np.ndarray, cand: Any, min_inliers: int,
    ) -> tuple[tuple[SO3, np.ndarray, np.ndarray, np.ndarray] | None, int]:
        """PnP with RANSAC of the candidate's matched points, at its own inverse depth, in the query's image.

        Returns ((R, t, the inliers' points in the candidate's camera (n, 3), their query pixels (n, 2)), inliers),
        ``p_query = R p_cand + t`` in the candidate's units; (None, inliers so far) when fewer than ``min_inliers``
        matches have depth or agree.
        """
        import cv2

        if len(pairs) < min_inliers:
            return None, 0
        pts_c = self._orb_of(cand)[0]
        cam = cand.view.frame.camera
        d_c, v_c = cand.view.idepth_pyramid[0]
        h, w = d_c.shape
        obj, img = [], []
        for i_q, i_c in pairs:
            xc, yc = (int(round(q)) for q in pts_c[i_c])
            if not (0 <= xc < w and 0 <= yc < h) or v_c[yc, xc] <= 0 or d_c[yc, xc] <= 0.01:
                continue
            z = 1.0 / float(d_c[yc, xc])
            obj.append(((xc - cam.cx) / cam.fx * z, (yc - cam.cy) / cam.fy * z, z))
            img.append(query_px[i_q])
        if len(obj) < min_inliers:
            return None, 0
        K = np.array([[cam.fx, 0, cam.cx], [0, cam.fy, cam.cy], [0, 0, 1]], dtype=np.float64)
        obj_a, img_a = np.array(obj, np.float64), np.array(img, np.float64)
        ok, rvec, tvec, inliers = cv2.solvePnPRansac(
            obj_a, img_a, K, None, iterationsCount=100, reprojectionError=3.0, confidence=0.999,
            flags=cv2.SOLVEPNP_EPNP,
        )
        n_inliers = 0 if inliers is None else len(inliers)
        if not ok or n_inliers < min_inliers:
            return None, n_inliers
        inl = inliers.ravel()
        return (SO3.exp(rvec.ravel()), tvec.ravel(), obj_a[inl], img_a[inl]), n_inliers
