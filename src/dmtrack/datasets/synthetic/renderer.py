"""Ray casting of a synthetic :class:`~dmtrack.datasets.synthetic.scene.Scene` from a pinhole camera.

Rendering (:func:`render`) casts one ray per pixel centre (OpenCV axes, pixel centres at integer
coordinates) through the pinhole camera and keeps the nearest intersection.  The depth it returns is the
exact ``z`` of that intersection in the camera frame (metres).  There are two implementations that must
agree (``tests/datasets/test_synthetic.py`` checks it): a numba kernel (slab tests for the room and the
boxes, parallel over rows) and a plain numpy reference (:func:`render_numpy`) that treats every face as a
generic rectangle.  :func:`world_points` back-projects a depth map.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from dmtrack.datasets.synthetic.scene import Scene
from dmtrack.errors import InputError
from dmtrack.geometry.camera import PinholeCamera

__all__ = ["render", "render_numpy", "world_points"]

_EPS_T = 1e-9  # smallest accepted ray parameter (metres along a z=1 ray)


# ============================================================================================ rendering
def _camera_params(camera: PinholeCamera) -> tuple[float, float, float, float, int, int]:
    return (
        float(camera.fx),
        float(camera.fy),
        float(camera.cx),
        float(camera.cy),
        int(camera.width),
        int(camera.height),
    )


def _check_pose(T_wc: np.ndarray) -> np.ndarray:
    T = np.asarray(T_wc, dtype=np.float64)
    if T.shape != (4, 4) or not np.isfinite(T).all():
        raise InputError(f"T_wc must be a finite 4x4 matrix, got shape {T.shape}")
    return T


@numba.njit(cache=True)
def _accumulate_level(tex, off, w, h, x, y, weight, out, row, col):  # pragma: no cover - compiled
    """out[row, col, :] += weight · bilinear sample (all channels) of one mip level at texel coords (x, y).

    Coordinates are clamped to the level (edge texels extend to the face borders).
    """
    if x < 0.0:
        x = 0.0
    elif x > w - 1:
        x = w - 1.0
    if y < 0.0:
        y = 0.0
    elif y > h - 1:
        y = h - 1.0
    x0 = int(x)
    y0 = int(y)
    if x0 > w - 2:
        x0 = max(w - 2, 0)
    if y0 > h - 2:
        y0 = max(h - 2, 0)
    x1 = min(x0 + 1, w - 1)
    y1 = min(y0 + 1, h - 1)
    ax = x - x0
    ay = y - y0
    i00 = off + y0 * w + x0
    i01 = off + y0 * w + x1
    i10 = off + y1 * w + x0
    i11 = off + y1 * w + x1
    for c in range(tex.shape[1]):
        top = tex[i00, c] + ax * (tex[i01, c] - tex[i00, c])
        bot = tex[i10, c] + ax * (tex[i11, c] - tex[i10, c])
        out[row, col, c] += weight * (top + ay * (bot - top))


@numba.njit(cache=True, parallel=True)
def _render_kernel(
    R,
    cam_c,
    fx,
    fy,
    cx,
    cy,
    width,
    height,
    room_lo,
    room_hi,
    box_centre,
    box_rot,
    box_half,
    box_face0,
    quad_faces,
    face_origin,
    face_u,
    face_v,
    face_normal,
    face_size,
    tex,
    tex_offset,
    tex_width,
    tex_height,
    tex_levels,
    texel,
    blur,
    out_img,
    out_depth,
):  # pragma: no cover - compiled
    n_boxes = box_centre.shape[0]
    n_quads = quad_faces.shape[0]
    n_ch = tex.shape[1]
    # camera centre in every box frame; bounding spheres (vector camera → centre, |.|² − radius²)
    box_o = np.empty((n_boxes, 3))
    box_oc = np.empty((n_boxes, 3))
    box_c2 = np.empty(n_boxes)
    for b in range(n_boxes):
        r2 = box_half[b, 0] ** 2 + box_half[b, 1] ** 2 + box_half[b, 2] ** 2
        s2 = 0.0
        for k in range(3):
            box_oc[b, k] = box_centre[b, k] - cam_c[k]
            s2 += box_oc[b, k] ** 2
        box_c2[b] = s2 - r2 * (1.0 + 1e-9)
        for k in range(3):
            s = 0.0
            for j in range(3):
                s += box_rot[b, j, k] * (cam_c[j] - box_centre[b, j])
            box_o[b, k] = s
    f_geo = math.sqrt(fx * fy)
    for y in numba.prange(height):
        dl = np.empty(3)
        for x in range(width):
            rx = (x - cx) / fx
            ry = (y - cy) / fy
            d0 = R[0, 0] * rx + R[0, 1] * ry + R[0, 2]
            d1 = R[1, 0] * rx + R[1, 1] * ry + R[1, 2]
            d2 = R[2, 0] * rx + R[2, 1] * ry + R[2, 2]
            best = np.inf
            face = -1
            # room: the ray leaves the room through the nearest exit plane
            for k in range(3):
                dk = d0 if k == 0 else (d1 if k == 1 else d2)
                if dk > 0.0:
                    t = (room_hi[k] - cam_c[k]) / dk
                    if t < best:
                        best = t
                        face = 2 * k + 1
                elif dk < 0.0:
                    t = (room_lo[k] - cam_c[k]) / dk
                    if t < best:
                        best = t
                        face = 2 * k
            # boxes: slab test in the box frame
            dd = d0 * d0 + d1 * d1 + d2 * d2
            for b in range(n_boxes):
                od = box_oc[b, 0] * d0 + box_oc[b, 1] * d1 + box_oc[b, 2] * d2
                if box_c2[b] > 0.0 and (od <= 0.0 or od * od < dd * box_c2[b]):
                    continue  # from outside the bounding sphere, the ray misses it
                for k in range(3):
                    dl[k] = box_rot[b, 0, k] * d0 + box_rot[b, 1, k] * d1 + box_rot[b, 2, k] * d2
                tnear = -np.inf
                tfar = np.inf
                fnear = -1
                miss = False
                for k in range(3):
                    hk = box_half[b, k]
                    ok = box_o[b, k]
                    if dl[k] == 0.0:
                        if ok < -hk or ok > hk:
                            miss = True
                            break
                        continue
                    t1 = (-hk - ok) / dl[k]
                    t2 = (hk - ok) / dl[k]
                    f1 = 2 * k
                    if t1 > t2:
                        t1, t2 = t2, t1
                        f1 = 2 * k + 1
                    if t1 > tnear:
                        tnear = t1
                        fnear = f1
                    if t2 < tfar:
                        tfar = t2
                if miss or fnear < 0 or tnear > tfar or tnear <= 1e-9 or tnear >= best:
                    continue
                best = tnear
                face = box_face0[b] + fnear
            # slanted planes: generic rectangles
            for qi in range(n_quads):
                f = quad_faces[qi]
                den = face_normal[f, 0] * d0 + face_normal[f, 1] * d1 + face_normal[f, 2] * d2
                if abs(den) < 1e-12:
                    continue
                e0 = face_origin[f, 0] - cam_c[0]
                e1 = face_origin[f, 1] - cam_c[1]
                e2 = face_origin[f, 2] - cam_c[2]
                t = (face_normal[f, 0] * e0 + face_normal[f, 1] * e1 + face_normal[f, 2] * e2) / den
                if t <= 1e-9 or t >= best:
                    continue
                q0 = t * d0 - e0
                q1 = t * d1 - e1
                q2 = t * d2 - e2
                a = q0 * face_u[f, 0] + q1 * face_u[f, 1] + q2 * face_u[f, 2]
                bb = q0 * face_v[f, 0] + q1 * face_v[f, 1] + q2 * face_v[f, 2]
                if a < 0.0 or a > face_size[f, 0] or bb < 0.0 or bb > face_size[f, 1]:
                    continue
                best = t
                face = f
            out_depth[y, x] = best
            # texture coordinates of the hit on its face
            f = face
            q0 = cam_c[0] + best * d0 - face_origin[f, 0]
            q1 = cam_c[1] + best * d1 - face_origin[f, 1]
            q2 = cam_c[2] + best * d2 - face_origin[f, 2]
            a = q0 * face_u[f, 0] + q1 * face_u[f, 1] + q2 * face_u[f, 2]
            bb = q0 * face_v[f, 0] + q1 * face_v[f, 1] + q2 * face_v[f, 2]
            # level of detail from the pixel footprint: side = z / sqrt(fx fy |d| cosθ) metres
            dn = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            cos_t = abs(face_normal[f, 0] * d0 + face_normal[f, 1] * d1 + face_normal[f, 2] * d2) / dn
            if cos_t < 0.05:
                cos_t = 0.05
            foot = blur * best / (f_geo * math.sqrt(dn * cos_t)) / texel
            lod = math.log2(foot) if foot > 1.0 else 0.0
            nl = tex_levels[f]
            if lod > nl - 1:
                lod = nl - 1.0
            l0 = int(lod)
            l1 = min(l0 + 1, nl - 1)
            wl = lod - l0
            x0 = a / texel
            y0 = bb / texel
            s0 = 2.0**l0
            s1 = 2.0**l1
            xa = (x0 - 0.5 * (s0 - 1.0)) / s0
            ya = (y0 - 0.5 * (s0 - 1.0)) / s0
            xb = (x0 - 0.5 * (s1 - 1.0)) / s1
            yb = (y0 - 0.5 * (s1 - 1.0)) / s1
            for c in range(n_ch):
                out_img[y, x, c] = 0.0
            _accumulate_level(
                tex, tex_offset[f, l0], tex_width[f, l0], tex_height[f, l0], xa, ya, 1.0 - wl, out_img, y, x
            )
            if wl > 0.0:
                _accumulate_level(
                    tex, tex_offset[f, l1], tex_width[f, l1], tex_height[f, l1], xb, yb, wl, out_img, y, x
                )


def render(
    scene: Scene, camera: PinholeCamera, T_wc: np.ndarray, *, blur: float = 1.5
) -> tuple[np.ndarray, np.ndarray]:
    """Ray-cast the scene from a pinhole camera (numba kernel, parallel over rows).

    Parameters
    ----------
    scene : from :func:`make_scene`.
    camera : intrinsics and image size (pixels; OpenCV axes, pixel centres at integer coordinates).
    T_wc : (4, 4) camera-to-world pose.
    blur : width of the texture pre-filter in pixels: the mip level is chosen for a footprint of ``blur``
        pixels (1 = plain trilinear mip-mapping, sharpest but with some aliasing when the texture is
        minified; the default 1.5 acts like a mild lens blur and makes warps between views consistent
        to ~1 grey level even at 160 × 120).  It only matters where a texel is smaller than a pixel.

    Returns
    -------
    intensity : float32, (H, W) for a grey scene or (H, W, 3) RGB — the texture radiance, 0..255 scale,
        before any illumination change or noise.
    depth : float32 (H, W) — exact z of the nearest surface in the camera frame, metres (> 0 everywhere
        when the camera is inside the room).
    """
    T = _check_pose(T_wc)
    if not blur > 0:
        raise InputError(f"blur must be > 0, got {blur}")
    fx, fy, cx, cy, w, h = _camera_params(camera)
    img = np.empty((h, w, scene.channels), np.float32)
    depth64 = np.empty((h, w), np.float64)
    _render_kernel(
        np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]), fx, fy, cx, cy, w, h,
        scene.room_lo, scene.room_hi, scene.box_centre, scene.box_rot, scene.box_half, scene.box_face0,
        scene.quad_faces, scene.face_origin, scene.face_u, scene.face_v, scene.face_normal, scene.face_size,
        scene.tex, scene.tex_offset, scene.tex_width, scene.tex_height, scene.tex_levels, scene.texel,
        float(blur), img, depth64,
    )  # fmt: skip
    out = img[..., 0] if scene.channels == 1 else img
    return out, depth64.astype(np.float32)


def _sample_level_numpy(level: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear, clamped sampling of an (h, w, C) level at (N,) texel coordinates → (N, C)."""
    h, w = level.shape[:2]
    x = np.clip(x, 0.0, w - 1.0)
    y = np.clip(y, 0.0, h - 1.0)
    x0 = np.minimum(x.astype(np.int64), max(w - 2, 0))
    y0 = np.minimum(y.astype(np.int64), max(h - 2, 0))
    x1 = np.minimum(x0 + 1, w - 1)
    y1 = np.minimum(y0 + 1, h - 1)
    ax = (x - x0)[:, None]
    ay = (y - y0)[:, None]
    top = level[y0, x0] + ax * (level[y0, x1] - level[y0, x0])
    bot = level[y1, x0] + ax * (level[y1, x1] - level[y1, x0])
    return top + ay * (bot - top)


def render_numpy(
    scene: Scene, camera: PinholeCamera, T_wc: np.ndarray, *, blur: float = 1.5
) -> tuple[np.ndarray, np.ndarray]:
    """Plain numpy reference of :func:`render`: every face as a generic rectangle, vectorised over pixels.

    Same inputs and outputs as :func:`render`; much slower, used to check the numba kernel.
    """
    T = _check_pose(T_wc)
    fx, fy, cx, cy, w, h = _camera_params(camera)
    ys, xs = np.mgrid[0:h, 0:w]
    rays = np.stack([(xs.ravel() - cx) / fx, (ys.ravel() - cy) / fy, np.ones(h * w)], axis=1)
    d = rays @ T[:3, :3].T
    c = T[:3, 3]
    best = np.full(h * w, np.inf)
    face = np.full(h * w, -1, np.int64)
    for f in range(scene.n_faces):
        n = scene.face_normal[f]
        den = d @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            t = ((scene.face_origin[f] - c) @ n) / den
        q = c + t[:, None] * d - scene.face_origin[f]
        a = q @ scene.face_u[f]
        b = q @ scene.face_v[f]
        tol = 1e-9
        ok = (
            (np.abs(den) > 1e-12)
            & (t > _EPS_T)
            & (t < best)
            & (a >= -tol)
            & (a <= scene.face_size[f, 0] + tol)
            & (b >= -tol)
            & (b <= scene.face_size[f, 1] + tol)
        )
        best[ok] = t[ok]
        face[ok] = f
    if (face < 0).any():
        raise InputError("some rays hit no surface: is the camera inside the room?")
    img = np.empty((h * w, scene.channels))
    p = c + best[:, None] * d
    dn = np.linalg.norm(d, axis=1)
    for f in np.unique(face):
        m = face == f
        q = p[m] - scene.face_origin[f]
        a = q @ scene.face_u[f]
        b = q @ scene.face_v[f]
        cos_t = np.maximum(np.abs(d[m] @ scene.face_normal[f]) / dn[m], 0.05)
        foot = blur * best[m] / (math.sqrt(fx * fy) * np.sqrt(dn[m] * cos_t)) / scene.texel
        nl = int(scene.tex_levels[f])
        lod = np.minimum(np.where(foot > 1.0, np.log2(np.maximum(foot, 1.0)), 0.0), nl - 1.0)
        l0 = lod.astype(np.int64)
        wl = (lod - l0)[:, None]
        x0, y0 = a / scene.texel, b / scene.texel
        va = np.empty((int(m.sum()), scene.channels))
        vb = np.empty_like(va)
        for lvl in np.unique(l0):
            sel = l0 == lvl
            l1 = min(lvl + 1, nl - 1)
            for L, out in ((lvl, va), (l1, vb)):
                s = 2.0**L
                out[sel] = _sample_level_numpy(
                    scene.face_texture(f, L),
                    (x0[sel] - 0.5 * (s - 1.0)) / s,
                    (y0[sel] - 0.5 * (s - 1.0)) / s,
                )
        img[m] = (1.0 - wl) * va + wl * vb
    img32 = img.reshape(h, w, scene.channels).astype(np.float32)
    out = img32[..., 0] if scene.channels == 1 else img32
    return out, best.reshape(h, w).astype(np.float32)


def world_points(depth: np.ndarray, camera: PinholeCamera, T_wc: np.ndarray) -> np.ndarray:
    """Back-project a depth map: (H, W) metres → (H, W, 3) world points (OpenCV axes, integer centres)."""
    fx, fy, cx, cy, w, h = _camera_params(camera)
    ys, xs = np.mgrid[0:h, 0:w]
    z = np.asarray(depth, dtype=np.float64)
    pc = np.stack([(xs - cx) / fx * z, (ys - cy) / fy * z, z], axis=-1)
    T = np.asarray(T_wc, dtype=np.float64)
    return pc @ T[:3, :3].T + T[:3, 3]
