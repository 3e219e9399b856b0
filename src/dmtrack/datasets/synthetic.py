"""A deterministic synthetic sequence: a textured room rendered by ray casting, with exact depth and poses.

The scene (:func:`make_scene`) is the inside of an axis-aligned room (walls, floor and ceiling) holding a
few boxes (rotated about the vertical axis, standing on the floor or floating) and a few slanted planar
rectangles, at different depths, so that a moving camera sees parallax and occlusion.  Every planar face
carries its own texture image generated once from the seed: band-limited noise octaves from ~0.5 to
~35 cycles per metre, step-edged blobs and rectangles of many sizes, thin lines and windowed stripe
patches — multi-scale and aperiodic, never a checkerboard.  Textures are stored with a texel size in metres
and a mip-map pyramid; :func:`render` samples them trilinearly with a level of detail chosen from the
pixel footprint on the surface, so there is little aliasing from VGA down to small test images.

Rendering (:func:`render`) casts one ray per pixel centre (OpenCV axes, pixel centres at integer
coordinates) through the pinhole camera and keeps the nearest intersection.  The depth it returns is the
exact ``z`` of that intersection in the camera frame (metres).  There are two implementations that must
agree (``tests/datasets/test_synthetic.py`` checks it): a numba kernel (slab tests for the room and the
boxes, parallel over rows) and a plain numpy reference that treats every face as a generic rectangle.

:class:`SyntheticSequence` implements the :class:`~dmtrack.datasets.base.Sequence` protocol: a smooth
6-DoF trajectory (:func:`make_trajectory`) that stays in the free space in the middle of the room and looks
at the textured surfaces, frames rendered lazily and identically whatever the order of access, and
optional photometric disturbances — a global gain/offset following a smooth curve, a moving spotlight
(local illumination change) and per-frame seeded Gaussian sensor noise.

World frame: metres, ``z`` up, the floor at ``z = 0``, the room centred on the ``z`` axis.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numba
import numpy as np
import scipy.fft

from dmtrack.datasets.base import Frame
from dmtrack.errors import InputError
from dmtrack.geometry.camera import PinholeCamera
from dmtrack.io.trajectory import Trajectory

__all__ = [
    "Scene",
    "SyntheticConfig",
    "SyntheticSequence",
    "make_scene",
    "make_trajectory",
    "render",
    "render_numpy",
    "world_points",
]

# Luma weights (ITU-R BT.601) and two chroma directions orthogonal to them: a colour texture is
# ``L + c1·e1 + c2·e2`` so its luma is exactly the grey texture L of the same seed (before clipping).
_LUMA = np.array([0.299, 0.587, 0.114])
_E1 = np.cross(_LUMA, [0.0, 0.0, 1.0])
_E1 /= np.linalg.norm(_E1)
_E2 = np.cross(_LUMA, _E1)
_E2 /= np.linalg.norm(_E2)

_EPS_T = 1e-9  # smallest accepted ray parameter (metres along a z=1 ray)


# ================================================================================================ scene
@dataclass(frozen=True, eq=False)
class Scene:
    """Geometry and textures of a synthetic room (all arrays read-only; build with :func:`make_scene`).

    Faces are planar rectangles ``{o + a·u + b·v : 0 ≤ a ≤ size[0], 0 ≤ b ≤ size[1]}``.  Faces 0..5 are
    the room (face ``2k`` at ``room_lo[k]``, ``2k+1`` at ``room_hi[k]``), then 6 faces per box (face
    ``2k`` / ``2k+1`` at local coordinate ``−half[k]`` / ``+half[k]``), then one face per slanted plane.

    Attributes
    ----------
    room_lo, room_hi : (3,) float64 — corners of the room, metres.
    box_centre : (B, 3) float64 — box centres, metres.
    box_rot : (B, 3, 3) float64 — world-from-box rotations.
    box_half : (B, 3) float64 — half extents, metres.
    box_face0 : (B,) int64 — index of each box's first face.
    quad_faces : (Q,) int64 — indices of the slanted-plane faces.
    face_origin, face_u, face_v, face_normal : (F, 3) float64 — face frames (u, v unit and orthogonal,
        normal = u × v).
    face_size : (F, 2) float64 — extents along u and v, metres.
    tex : (T, C) float32 — all texels of all faces and mip levels, intensity 0..255, C = 1 or 3.
    tex_offset, tex_width, tex_height : (F, L) int64 — where level l of face f starts in ``tex`` and its
        size (columns along u, rows along v); level 0 has a texel at every multiple of ``texel`` metres.
    tex_levels : (F,) int64 — number of mip levels of each face (≤ L).
    texel : float — level-0 texel size, metres.
    free_centre : (3,) float64 — centre of the free space kept clear for the camera, metres.
    free_radius : float — radius (horizontal) of the cylinder around ``free_centre`` holding no objects.
    free_half_height : float — half height of that cylinder, metres.
    view_yaw : float — heading (radians about z, from +x) the trajectories mostly look along; most
        objects stand in that sector.
    seed : int — the seed the scene was generated from.
    """

    room_lo: np.ndarray
    room_hi: np.ndarray
    box_centre: np.ndarray
    box_rot: np.ndarray
    box_half: np.ndarray
    box_face0: np.ndarray
    quad_faces: np.ndarray
    face_origin: np.ndarray
    face_u: np.ndarray
    face_v: np.ndarray
    face_normal: np.ndarray
    face_size: np.ndarray
    tex: np.ndarray
    tex_offset: np.ndarray
    tex_width: np.ndarray
    tex_height: np.ndarray
    tex_levels: np.ndarray
    texel: float
    free_centre: np.ndarray
    free_radius: float
    free_half_height: float
    view_yaw: float
    seed: int

    @property
    def channels(self) -> int:
        """1 (grey) or 3 (RGB)."""
        return int(self.tex.shape[1])

    @property
    def n_faces(self) -> int:
        """Number of planar faces (room, boxes and slanted planes)."""
        return int(self.face_origin.shape[0])

    def face_texture(self, face: int, level: int = 0) -> np.ndarray:
        """Texture of one face at one mip level: (rows along v, columns along u, C) float32 view."""
        o = int(self.tex_offset[face, level])
        w = int(self.tex_width[face, level])
        h = int(self.tex_height[face, level])
        return self.tex[o : o + w * h].reshape(h, w, self.channels)

    def inside_room(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: which of the (N, 3) world points lie strictly inside the room."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        return np.all((p > self.room_lo) & (p < self.room_hi), axis=1)

    def inside_boxes(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: which of the (N, 3) world points lie inside any box."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        out = np.zeros(p.shape[0], dtype=bool)
        for c, R, h in zip(self.box_centre, self.box_rot, self.box_half, strict=True):
            local = (p - c) @ R
            out |= np.all(np.abs(local) < h, axis=1)
        return out

    def clearance(self, points: np.ndarray) -> np.ndarray:
        """(N,) float64: distance (metres) from each (N, 3) world point to the nearest face."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        best = np.full(p.shape[0], np.inf)
        for f in range(self.n_faces):
            d = p - self.face_origin[f]
            a = np.clip(d @ self.face_u[f], 0.0, self.face_size[f, 0])
            b = np.clip(d @ self.face_v[f], 0.0, self.face_size[f, 1])
            q = self.face_origin[f] + a[:, None] * self.face_u[f] + b[:, None] * self.face_v[f]
            best = np.minimum(best, np.linalg.norm(p - q, axis=1))
        return best


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a)
    a.setflags(write=False)
    return a


def _band_noise(
    rng: np.random.Generator, h: int, w: int, texel: float, bands: np.ndarray, amps: np.ndarray
) -> np.ndarray:
    """Sum of band-limited noise octaves, (h, w) float64, band k with standard deviation ≈ ``amps[k]``.

    Each band is a log-Gaussian ring (half an octave wide) around ``bands[k]`` cycles per metre in the
    spectrum of white noise.  The noise is synthesised on a grid 30 % larger and cropped, so the result
    does not wrap around (it is not periodic).
    """
    ph = scipy.fft.next_fast_len(int(h * 1.3) + 16, real=True)
    pw = scipy.fft.next_fast_len(int(w * 1.3) + 16, real=True)
    spec = scipy.fft.rfft2(rng.standard_normal((ph, pw)))
    fy = np.fft.fftfreq(ph, d=texel)
    fx = np.fft.rfftfreq(pw, d=texel)
    lf = 0.5 * np.log2(np.maximum(fx[None, :] ** 2 + fy[:, None] ** 2, 1e-12))
    # the envelope as a function of log2 frequency, tabulated once and interpolated onto the grid
    grid = np.linspace(math.log2(0.5 / max(ph, pw) / texel) - 1.0, math.log2(0.75 / texel), 512)
    table = np.zeros_like(grid)
    for fc, a in zip(bands, amps, strict=True):
        g = np.exp(-0.5 * ((grid - math.log2(fc)) / 0.5) ** 2)
        # variance of a ring = (bins per unit of frequency area = ph·pw·texel²) · ∫ g² 2πf df / (ph·pw)
        power = 2 * math.pi * math.log(2) * np.trapezoid(g**2 * 4.0**grid, grid) * texel**2
        table += a * g / math.sqrt(max(power, 1e-12))
    env = np.interp(lf, grid, table, left=0.0, right=0.0)
    env[0, 0] = 0.0
    return scipy.fft.irfft2(spec * env, s=(ph, pw))[:h, :w]


@numba.njit(cache=True)
def _paint_leaves(lum, chroma, params, texel):  # pragma: no cover - compiled
    """Paint opaque anti-aliased shapes in order ("dead leaves") onto lum (h, w) and chroma (h, w, 2).

    ``params`` rows: kind (0 ellipse, 1 rectangle, 2 stripe patch), centre x, y (m), radii a, b (m),
    angle (rad), value, stripe period (m), stripe phase, stripe amplitude, chroma 1, chroma 2.
    """
    h, w = lum.shape
    use_chroma = chroma.shape[0] == h
    for i in range(params.shape[0]):
        kind = int(params[i, 0])
        cx = params[i, 1]
        cy = params[i, 2]
        ra = params[i, 3]
        rb = params[i, 4]
        c = math.cos(params[i, 5])
        s = math.sin(params[i, 5])
        value = params[i, 6]
        ext = math.sqrt(ra * ra + rb * rb) + 2.0 * texel
        x0 = max(int((cx - ext) / texel), 0)
        x1 = min(int((cx + ext) / texel) + 2, w)
        y0 = max(int((cy - ext) / texel), 0)
        y1 = min(int((cy + ext) / texel) + 2, h)
        rmin = min(ra, rb)
        for yy in range(y0, y1):
            Y = yy * texel - cy
            for xx in range(x0, x1):
                X = xx * texel - cx
                xr = c * X + s * Y
                yr = -s * X + c * Y
                if kind == 0:
                    sd = (math.sqrt((xr / ra) ** 2 + (yr / rb) ** 2) - 1.0) * rmin
                else:
                    sd = max(abs(xr) - ra, abs(yr) - rb)
                cov = 0.5 - sd / texel
                if cov <= 0.0:
                    continue
                if cov > 1.0:
                    cov = 1.0
                v = value
                if kind == 2:
                    v += params[i, 9] * math.sin(2.0 * math.pi * xr / params[i, 7] + params[i, 8])
                lum[yy, xx] += cov * (v - lum[yy, xx])
                if use_chroma:
                    chroma[yy, xx, 0] += cov * (params[i, 10] - chroma[yy, xx, 0])
                    chroma[yy, xx, 1] += cov * (params[i, 11] - chroma[yy, xx, 1])


def _leaf_params(rng: np.random.Generator, h: int, w: int, texel: float) -> np.ndarray:
    """Random "dead leaves" (see :func:`_paint_leaves`) for an (h, w) texture: ~25 shapes per m²."""
    area = h * w * texel * texel
    n = int(rng.poisson(25.0 * area)) + 2
    # radii log-uniform in 1.5 cm .. 60 cm (scale-invariant statistics), aspect up to e:1
    r = np.exp(rng.uniform(math.log(0.015), math.log(0.6), n))
    aspect = np.exp(rng.uniform(-1.0, 1.0, n))
    kind = rng.choice(4, size=n, p=[0.45, 0.35, 0.12, 0.08])  # ellipse, rectangle, line, stripes
    ra, rb = r * np.sqrt(aspect), r / np.sqrt(aspect)
    line = kind == 2
    ra = np.where(line, 1.5 * r, ra)
    rb = np.where(line, rng.uniform(1.0, 3.0, n) * texel, rb)
    out = np.zeros((n, 12))
    out[:, 0] = np.where(kind == 3, 2, np.where(line, 1, kind))
    out[:, 1] = rng.uniform(0.0, w * texel, n)
    out[:, 2] = rng.uniform(0.0, h * texel, n)
    out[:, 3] = ra
    out[:, 4] = rb
    out[:, 5] = rng.uniform(0.0, math.pi, n)
    out[:, 6] = rng.normal(0.0, 1.0, n)
    out[:, 7] = np.maximum(np.exp(rng.uniform(math.log(0.025), math.log(0.12), n)), 4 * texel)
    out[:, 8] = rng.uniform(0.0, 2 * math.pi, n)
    out[:, 9] = rng.uniform(0.4, 0.9, n)
    return out


def _face_texture(seed_seq: np.random.SeedSequence, h: int, w: int, texel: float, colour: bool) -> np.ndarray:
    """Texture of one face: (h, w, C) float32 in 0..255 (C = 3 if ``colour`` else 1).

    Luminance = dead leaves (opaque shapes of log-uniform sizes: step edges at every scale, lines and a
    few stripe patches) + band-limited noise octaves (0.5 .. 32 cycles/m, up to 0.35 cycles/texel).
    Colour adds two chroma channels orthogonal to luma: smooth noise plus a colour per leaf.
    """
    lum_seed, chroma_seed = seed_seq.spawn(2)
    rng = np.random.default_rng(lum_seed)
    bands = np.array([0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0])
    bands = bands[bands <= 0.35 / texel]
    amps = bands**-0.1 * rng.uniform(0.6, 1.4, size=bands.size)
    noise = _band_noise(rng, h, w, texel, bands, amps)
    noise /= max(float(noise.std()), 1e-12)
    params = _leaf_params(rng, h, w, texel)
    crng = np.random.default_rng(chroma_seed)
    if colour:
        params[:, 10:12] = crng.normal(0.0, 1.0, size=(params.shape[0], 2))
    lum = np.zeros((h, w))
    chroma = np.zeros((h, w, 2) if colour else (0, 0, 2))
    _paint_leaves(lum, chroma, params, texel)
    lum = lum + 0.45 * noise
    lum = (lum - lum.mean()) / max(float(lum.std()), 1e-12)
    base = rng.uniform(110.0, 145.0)
    contrast = rng.uniform(38.0, 50.0)
    L = base + contrast * lum
    if not colour:
        return np.clip(L, 8.0, 247.0).astype(np.float32)[..., None]
    cb = np.array([0.5, 1.0, 2.0, 4.0])
    for k in range(2):
        cn = _band_noise(crng, h, w, texel, cb, np.ones(cb.size))
        chroma[..., k] = 0.7 * chroma[..., k] + 0.5 * cn / max(float(cn.std()), 1e-12)
    chroma += crng.normal(0.0, 0.5, size=2)
    k1, k2 = 25.0 * chroma[..., 0], 25.0 * chroma[..., 1]
    rgb = L[..., None] + k1[..., None] * _E1 + k2[..., None] * _E2
    return np.clip(rgb, 4.0, 251.0).astype(np.float32)


def _mip_pyramid(t: np.ndarray) -> list[np.ndarray]:
    """2×2 box-mean pyramid of an (h, w, C) texture down to a 1-texel side (edge-replicated when odd)."""
    levels = [t]
    while min(levels[-1].shape[:2]) > 1 and len(levels) < 12:
        a = levels[-1]
        if a.shape[0] % 2:
            a = np.concatenate([a, a[-1:]], axis=0)
        if a.shape[1] % 2:
            a = np.concatenate([a, a[:, -1:]], axis=1)
        levels.append(0.25 * (a[0::2, 0::2] + a[1::2, 0::2] + a[0::2, 1::2] + a[1::2, 1::2]))
    return levels


def _rot_z(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


@functools.lru_cache(maxsize=4)
def make_scene(
    seed: int = 0,
    *,
    colour: bool = False,
    room_size: tuple[float, float, float] = (6.0, 5.0, 2.8),
    n_boxes: int = 6,
    n_planes: int = 2,
    texel: float = 0.01,
    free_radius: float = 1.0,
) -> Scene:
    """Generate a textured room deterministically from ``seed``.

    Parameters
    ----------
    seed : any non-negative int; the same arguments always give the same scene (results are cached).
    colour : RGB textures (C = 3) instead of grey (C = 1).  The luma of a colour scene's textures equals the
        grey scene's textures of the same seed (up to clipping).
    room_size : (x, y, z) inside extents of the room, metres (a tuple: arguments are hashed for the
        cache).  The floor is at z = 0.
    n_boxes : boxes inside the room (rotated about z; on the floor or floating).  Fewer are placed if
        they do not fit (2000 random tries).
    n_planes : slanted textured rectangles inside the room (likewise, fewer if they do not fit).
    texel : level-0 texel size of every texture, metres.
    free_radius : radius (metres) of the vertical cylinder around the room centre that is kept free of
        objects for the camera; the room must be larger than it.

    Returns
    -------
    Scene
        Read-only geometry and mip-mapped textures (1.8 M texels per channel for the default
        6 × 5 × 2.8 m room at 1 cm texels; generation takes about a second).
    """
    sx, sy, sz = (float(v) for v in room_size)
    if min(sx, sy) < 2 * free_radius + 1.0 or sz < 1.5:
        raise InputError(
            f"room {sx}x{sy}x{sz} m is too small for a free space of radius {free_radius} m "
            "(needs x, y ≥ 2·free_radius + 1 m and z ≥ 1.5 m)"
        )
    if texel <= 0 or n_boxes < 0 or n_planes < 0:
        raise InputError("texel must be > 0 and n_boxes, n_planes ≥ 0")
    root = np.random.SeedSequence([int(seed), 0x5C3E])
    geom_seed, tex_seed = root.spawn(2)
    rng = np.random.default_rng(geom_seed)
    view_yaw = float(rng.uniform(0.0, 2 * math.pi))
    lo = np.array([-sx / 2, -sy / 2, 0.0])
    hi = np.array([sx / 2, sy / 2, sz])
    eye = np.eye(3)
    origins: list[np.ndarray] = []
    us: list[np.ndarray] = []
    vs: list[np.ndarray] = []
    sizes: list[tuple[float, float]] = []

    # room faces: 2k at lo[k] (normal +e_k, inward), 2k+1 at hi[k] (normal −e_k, inward)
    ext = hi - lo
    for k in range(3):
        k1, k2 = (k + 1) % 3, (k + 2) % 3
        origins.append(lo.copy())
        us.append(eye[k1])
        vs.append(eye[k2])
        sizes.append((ext[k1], ext[k2]))
        o = lo.copy()
        o[k] = hi[k]
        origins.append(o)
        us.append(eye[k2])
        vs.append(eye[k1])
        sizes.append((ext[k2], ext[k1]))

    # boxes, placed outside the free cylinder, inside the room, not overlapping each other
    centres, rots, halves, face0 = [], [], [], []
    placed_xy: list[tuple[np.ndarray, float]] = []
    attempts = 0
    while len(centres) < n_boxes and attempts < 2000:
        attempts += 1
        half = rng.uniform([0.12, 0.12, 0.12], [0.45, 0.45, 0.5])
        rad = float(np.hypot(half[0], half[1]))
        yaw = rng.uniform(0.0, math.pi)
        # three in four boxes in the sector the camera mostly looks at
        ang = view_yaw + rng.uniform(-1.0, 1.0) if rng.uniform() < 0.75 else rng.uniform(0.0, 2 * math.pi)
        d_lo, d_hi = free_radius + rad + 0.1, math.hypot(sx, sy) / 2
        if d_lo >= d_hi:
            continue
        dist = rng.uniform(d_lo, d_hi)
        xy = dist * np.array([math.cos(ang), math.sin(ang)])
        if np.any(xy < lo[:2] + rad + 0.05) or np.any(xy > hi[:2] - rad - 0.05):
            continue
        if any(np.hypot(*(xy - q)) < rad + r + 0.05 for q, r in placed_xy):
            continue
        if rng.uniform() < 0.5:  # on the floor
            z = half[2]
        else:  # floating at 0.3..(top − 0.2) m
            z = rng.uniform(half[2] + 0.3, max(half[2] + 0.31, sz - half[2] - 0.2))
        placed_xy.append((xy, rad))
        R = _rot_z(yaw)
        c = np.array([xy[0], xy[1], z])
        centres.append(c)
        rots.append(R)
        halves.append(half)
        face0.append(len(origins))
        for k in range(3):
            k1, k2 = (k + 1) % 3, (k + 2) % 3
            # face 2k at local −half[k]: u = e_k2, v = e_k1 (u × v = −e_k, outward)
            o_l = -half.copy()
            origins.append(c + R @ o_l)
            us.append(R @ eye[k2])
            vs.append(R @ eye[k1])
            sizes.append((2 * half[k2], 2 * half[k1]))
            # face 2k+1 at local +half[k]: u = e_k1, v = e_k2 (u × v = +e_k, outward)
            o_l = -half.copy()
            o_l[k] = half[k]
            origins.append(c + R @ o_l)
            us.append(R @ eye[k1])
            vs.append(R @ eye[k2])
            sizes.append((2 * half[k1], 2 * half[k2]))

    # slanted planes: rectangles facing roughly the room centre, tilted, outside the free cylinder
    quads = []
    attempts = 0
    while len(quads) < n_planes and attempts < 2000:
        attempts += 1
        su, sv = rng.uniform(0.5, 1.2, size=2)
        ang = view_yaw + rng.uniform(-1.0, 1.0) if rng.uniform() < 0.75 else rng.uniform(0.0, 2 * math.pi)
        dist = rng.uniform(free_radius + 0.4, max(math.hypot(sx, sy) / 2 - 0.3, free_radius + 0.5))
        ctr = np.array([dist * math.cos(ang), dist * math.sin(ang), rng.uniform(0.6, sz - 0.6)])
        if not np.all((ctr > lo + 0.1) & (ctr < hi - 0.1)):
            continue
        towards = -ctr[:2] / np.linalg.norm(ctr[:2])
        yaw = math.atan2(towards[1], towards[0]) + rng.uniform(-0.6, 0.6)
        tilt = rng.uniform(-0.6, 0.6)
        n = np.array([math.cos(yaw) * math.cos(tilt), math.sin(yaw) * math.cos(tilt), math.sin(tilt)])
        u = np.cross([0.0, 0.0, 1.0], n)
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        roll = rng.uniform(-0.4, 0.4)
        u, v = math.cos(roll) * u + math.sin(roll) * v, -math.sin(roll) * u + math.cos(roll) * v
        half_uv = np.array([[-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0], [1.0, 1.0]]) * (su / 2, sv / 2)
        corners = ctr + half_uv @ np.array([u, v])
        if not np.all((corners > lo + 0.05) & (corners < hi - 0.05)):
            continue
        if np.min(np.hypot(corners[:, 0], corners[:, 1])) < free_radius + 0.1:
            continue
        quads.append(len(origins))
        origins.append(ctr - su / 2 * u - sv / 2 * v)
        us.append(u)
        vs.append(v)
        sizes.append((su, sv))

    F = len(origins)
    face_origin = np.array(origins)
    face_u = np.array(us)
    face_v = np.array(vs)
    face_size = np.array(sizes, dtype=np.float64)

    # textures: one SeedSequence child per face, so a face's texture does not depend on other faces
    face_seeds = tex_seed.spawn(F)
    pyramids = []
    for f in range(F):
        w = int(math.ceil(face_size[f, 0] / texel)) + 1
        h = int(math.ceil(face_size[f, 1] / texel)) + 1
        pyramids.append(_mip_pyramid(_face_texture(face_seeds[f], h, w, texel, colour)))
    L = max(len(p) for p in pyramids)
    tex_offset = np.zeros((F, L), np.int64)
    tex_width = np.ones((F, L), np.int64)
    tex_height = np.ones((F, L), np.int64)
    tex_levels = np.array([len(p) for p in pyramids], np.int64)
    chunks = []
    pos = 0
    for f, pyr in enumerate(pyramids):
        for lvl, t in enumerate(pyr):
            tex_offset[f, lvl] = pos
            tex_height[f, lvl], tex_width[f, lvl] = t.shape[:2]
            chunks.append(t.reshape(-1, t.shape[2]))
            pos += t.shape[0] * t.shape[1]
    tex = np.concatenate(chunks, axis=0).astype(np.float32)

    return Scene(
        room_lo=_readonly(lo),
        room_hi=_readonly(hi),
        box_centre=_readonly(np.array(centres, dtype=np.float64).reshape(-1, 3)),
        box_rot=_readonly(np.array(rots, dtype=np.float64).reshape(-1, 3, 3)),
        box_half=_readonly(np.array(halves, dtype=np.float64).reshape(-1, 3)),
        box_face0=_readonly(np.array(face0, dtype=np.int64)),
        quad_faces=_readonly(np.array(quads, dtype=np.int64)),
        face_origin=_readonly(face_origin),
        face_u=_readonly(face_u),
        face_v=_readonly(face_v),
        face_normal=_readonly(np.cross(face_u, face_v)),
        face_size=_readonly(face_size),
        tex=_readonly(tex),
        tex_offset=_readonly(tex_offset),
        tex_width=_readonly(tex_width),
        tex_height=_readonly(tex_height),
        tex_levels=_readonly(tex_levels),
        texel=float(texel),
        free_centre=_readonly(np.array([0.0, 0.0, min(1.3, sz / 2)])),
        free_radius=float(free_radius),
        free_half_height=float(min(0.5, sz / 2 - 0.4)),
        view_yaw=view_yaw,
        seed=int(seed),
    )


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


# =========================================================================================== trajectory
def _look_rotation(yaw: np.ndarray, pitch: np.ndarray, roll: np.ndarray) -> np.ndarray:
    """(N, 3, 3) camera-to-world rotations (OpenCV camera axes, world z up).

    The camera looks along ``(cos p cos y, cos p sin y, sin p)``, its x axis horizontal to the right and
    y axis down when ``roll = 0``; ``roll`` turns it about its optical axis.
    """
    cp, sp = np.cos(pitch), np.sin(pitch)
    cyw, syw = np.cos(yaw), np.sin(yaw)
    fwd = np.stack([cp * cyw, cp * syw, sp], axis=-1)
    right = np.stack([syw, -cyw, np.zeros_like(yaw)], axis=-1)  # fwd × z_up, normalised
    down = np.cross(fwd, right)
    cr, sr = np.cos(roll)[:, None], np.sin(roll)[:, None]
    x_c = cr * right + sr * down
    y_c = -sr * right + cr * down
    return np.stack([x_c, y_c, fwd], axis=-1)


@dataclass(frozen=True)
class _TrajectoryShape:
    """Sinusoid coefficients of a trajectory as a function of the path parameter u (radians)."""

    pos_amp: np.ndarray  # (3, K)
    pos_freq: np.ndarray  # (3, K)
    pos_phase: np.ndarray  # (3, K)
    ang_amp: np.ndarray  # (3, K): yaw, pitch, roll
    ang_freq: np.ndarray
    ang_phase: np.ndarray
    yaw0: float
    pitch0: float


def _trajectory_shape(seed: int, free_radius: float, free_half_height: float, view_yaw: float) -> _TrajectoryShape:
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x7A3C]))
    K = 3
    freq = np.array([1.0, 1.618, 2.414])
    pos_freq = np.stack([freq * rng.uniform(0.85, 1.15, K) for _ in range(3)])
    # horizontal amplitudes sum to ≤ 0.6·free_radius (the path stays well inside the free cylinder)
    w = rng.uniform(0.5, 1.0, size=(2, K)) * np.array([1.0, 0.5, 0.25])
    horiz = 0.6 * free_radius / np.sqrt(2.0) * w / w.sum(axis=1, keepdims=True)
    wz = rng.uniform(0.5, 1.0, size=K) * np.array([1.0, 0.5, 0.25])
    vert = 0.7 * free_half_height * wz / wz.sum()
    pos_amp = np.vstack([horiz, vert[None]])
    pos_phase = rng.uniform(0.0, 2 * math.pi, size=(3, K))
    ang_freq = np.stack([freq * rng.uniform(0.6, 0.9, K) for _ in range(3)])
    ang_amp = np.array([[0.35, 0.15, 0.05], [0.10, 0.04, 0.02], [0.06, 0.03, 0.0]]) * rng.uniform(0.7, 1.0, size=(3, K))
    ang_phase = rng.uniform(0.0, 2 * math.pi, size=(3, K))
    return _TrajectoryShape(
        pos_amp, pos_freq, pos_phase, ang_amp, ang_freq, ang_phase,
        yaw0=view_yaw + float(rng.uniform(-0.2, 0.2)), pitch0=float(rng.uniform(-0.2, -0.05)),
    )  # fmt: skip


def _sinusoids(u: np.ndarray, amp: np.ndarray, freq: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """(N, 3): Σ_k amp[i,k] sin(freq[i,k] u + phase[i,k]) for each row i."""
    return np.einsum("ik,nik->ni", amp, np.sin(freq[None] * u[:, None, None] + phase[None]))


def make_trajectory(seed: int, n_frames: int, fps: float, speed: float, scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """A smooth 6-DoF camera trajectory inside the free space of ``scene``.

    Position: sums of three sinusoids per axis of a path parameter u (incommensurate frequencies, seeded
    phases and amplitudes) around ``scene.free_centre``, within 60 % of the free radius horizontally and
    70 % of the free half height vertically.  Orientation: a heading near ``scene.view_yaw`` plus
    sinusoidal yaw (≲ ±30°), pitch (looking slightly down, ±8°) and roll (±5°).  u advances so that the
    mean speed of the camera centre over a long run is ``speed`` (the instantaneous speed varies around it;
    rotation rates scale with it too).

    Parameters
    ----------
    seed : trajectory seed (independent stream from the scene's).
    n_frames : number of poses.
    fps : frames per second; frame i is at time i / fps seconds.
    speed : mean speed of the camera centre, metres per second (0 → a static camera).
    scene : gives the free space.

    Returns
    -------
    timestamps : (N,) float64 seconds.
    poses : (N, 4, 4) float64 camera-to-world T_wc.
    """
    if n_frames < 1 or fps <= 0 or speed < 0:
        raise InputError(f"need n_frames ≥ 1, fps > 0, speed ≥ 0 (got {n_frames}, {fps}, {speed})")
    shape = _trajectory_shape(seed, scene.free_radius, scene.free_half_height, scene.view_yaw)
    # mean |dp/du| over a long stretch of u (numerically; the path is not periodic)
    uu = np.linspace(0.0, 200.0, 20001)
    dp = np.einsum(
        "ik,nik->ni",
        shape.pos_amp * shape.pos_freq,
        np.cos(shape.pos_freq[None] * uu[:, None, None] + shape.pos_phase[None]),
    )
    mean_rate = float(np.linalg.norm(dp, axis=1).mean())
    t = np.arange(n_frames, dtype=np.float64) / fps
    u = t * (speed / mean_rate)
    pos = scene.free_centre + _sinusoids(u, shape.pos_amp, shape.pos_freq, shape.pos_phase)
    ang = _sinusoids(u, shape.ang_amp, shape.ang_freq, shape.ang_phase)
    R = _look_rotation(shape.yaw0 + ang[:, 0], shape.pitch0 + ang[:, 1], ang[:, 2])
    poses = np.tile(np.eye(4), (n_frames, 1, 1))
    poses[:, :3, :3] = R
    poses[:, :3, 3] = pos
    return t, poses


# ======================================================================================== the sequence
@dataclass(frozen=True)
class SyntheticConfig:
    """Everything that defines a synthetic sequence (frame i depends on nothing else).

    Attributes
    ----------
    width, height : image size, pixels.
    fx, fy : focal lengths, pixels; ``None`` → 525 · width / 640 (TUM-like field of view at any size).
    cx, cy : principal point, pixels; ``None`` → the image centre ((width − 1)/2, (height − 1)/2).
    n_frames : number of frames.
    fps : frames per second (timestamps are i / fps seconds).
    seed : seeds the scene, the trajectory, the illumination curves and the noise.
    colour : RGB frames (H, W, 3) instead of grey (H, W).
    speed : mean camera speed, metres per second.
    global_illumination : amplitude A of the global change: gain(t) = 1 + A·g(t), offset(t) = 40·A·o(t)
        grey levels, where g, o ∈ [−1, 1] are smooth seeded sums of sinusoids (periods of 2–12 s).
    local_illumination : amplitude L of a spotlight: per-pixel gain 1 − L/2 + L·s, s ∈ [0, 1] the
        near-Gaussian cone profile (σ ≈ 20°) of a light mounted 0.4 m beside the camera, aimed near the
        view direction with a slow seeded wobble, so the lighting of a surface changes as the camera moves.
    noise_sigma : standard deviation of additive Gaussian sensor noise, grey levels (0..255); frame i
        always gets the same noise.
    room_size : inside extents of the room, metres.
    n_boxes, n_planes : objects inside the room.
    texel : texture resolution, metres.
    blur : texture pre-filter width, pixels (see :func:`render`).
    name : sequence name; ``None`` → ``"synthetic-seed<seed>"``.
    """

    width: int = 640
    height: int = 480
    fx: float | None = None
    fy: float | None = None
    cx: float | None = None
    cy: float | None = None
    n_frames: int = 300
    fps: float = 30.0
    seed: int = 0
    colour: bool = False
    speed: float = 0.3
    global_illumination: float = 0.0
    local_illumination: float = 0.0
    noise_sigma: float = 0.0
    room_size: tuple[float, float, float] = (6.0, 5.0, 2.8)
    n_boxes: int = 6
    n_planes: int = 2
    texel: float = 0.01
    blur: float = 1.5
    name: str | None = None

    def camera(self) -> PinholeCamera:
        """The pinhole camera of the frames."""
        fx = 525.0 * self.width / 640.0 if self.fx is None else float(self.fx)
        fy = fx if self.fy is None else float(self.fy)
        cx = (self.width - 1) / 2.0 if self.cx is None else float(self.cx)
        cy = (self.height - 1) / 2.0 if self.cy is None else float(self.cy)
        return PinholeCamera(fx, fy, cx, cy, int(self.width), int(self.height))

    def validate(self) -> None:
        """Raise :class:`~dmtrack.errors.InputError` on impossible settings."""
        if self.width < 1 or self.height < 1:
            raise InputError(f"image size must be positive, got {self.width}x{self.height}")
        if self.n_frames < 1 or self.fps <= 0 or self.speed < 0:
            raise InputError("n_frames must be ≥ 1, fps > 0 and speed ≥ 0")
        if self.noise_sigma < 0 or self.global_illumination < 0 or self.local_illumination < 0:
            raise InputError("noise_sigma and the illumination amplitudes must be ≥ 0")
        if self.local_illumination > 2.0:
            raise InputError("local_illumination must be ≤ 2 (the gain 1 − L/2 would go negative)")


@dataclass(frozen=True)
class _Photometry:
    """Seeded coefficients of the smooth illumination curves."""

    gain_f: np.ndarray = field(repr=False)
    gain_p: np.ndarray = field(repr=False)
    off_f: np.ndarray = field(repr=False)
    off_p: np.ndarray = field(repr=False)
    spot_f: np.ndarray = field(repr=False)
    spot_p: np.ndarray = field(repr=False)


def _photometry(seed: int) -> _Photometry:
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x11AB]))

    # angular frequencies (rad/s) of periods 2..12 s
    def f(n: int) -> np.ndarray:
        return 2 * math.pi / rng.uniform(2.0, 12.0, size=n)

    return _Photometry(
        gain_f=f(3), gain_p=rng.uniform(0, 2 * math.pi, 3),
        off_f=f(3), off_p=rng.uniform(0, 2 * math.pi, 3),
        spot_f=f(4), spot_p=rng.uniform(0, 2 * math.pi, 4),
    )  # fmt: skip


class SyntheticSequence:
    """A lazily rendered synthetic sequence (implements :class:`~dmtrack.datasets.base.Sequence`).

    Parameters
    ----------
    config : what to render; see :class:`SyntheticConfig`.

    Frames carry ``image`` (uint8 grey (H, W) or RGB (H, W, 3)), the exact ``pose`` T_wc and the exact
    ``depth`` (float32 metres, valid > 0 at every pixel).  Frame i is a pure function of the config and
    i: rendering it first or after any others gives identical arrays.
    """

    format = "synthetic"

    def __init__(self, config: SyntheticConfig | None = None, *, _frames: np.ndarray | None = None) -> None:
        config = SyntheticConfig() if config is None else config
        config.validate()
        self.config = config
        self.name = config.name if config.name is not None else f"synthetic-seed{config.seed}"
        self.camera: PinholeCamera | None = config.camera()
        self.scene = make_scene(
            config.seed,
            colour=config.colour,
            room_size=tuple(float(v) for v in config.room_size),
            n_boxes=config.n_boxes,
            n_planes=config.n_planes,
            texel=config.texel,
        )
        t, poses = make_trajectory(config.seed, config.n_frames, config.fps, config.speed, self.scene)
        # frame indices into the full trajectory (a slice keeps the original timestamps, poses and noise)
        self._frames = np.arange(config.n_frames) if _frames is None else np.asarray(_frames, np.int64)
        self._all_t = t
        self._all_poses = poses
        self._photo = _photometry(config.seed)
        self._rays = self.camera.pixel_grid_rays().astype(np.float32)  # (H, W, 3) z = 1 rays

    # -- protocol -------------------------------------------------------------------------------
    @property
    def width(self) -> int:
        return int(self.config.width)

    @property
    def height(self) -> int:
        return int(self.config.height)

    @property
    def timestamps(self) -> np.ndarray:
        """(N,) float64 seconds."""
        return self._all_t[self._frames].copy()

    @property
    def poses(self) -> np.ndarray:
        """(N, 4, 4) float64 ground-truth T_wc of every frame."""
        return self._all_poses[self._frames].copy()

    @property
    def groundtruth(self) -> Trajectory:
        return Trajectory(self.timestamps, self.poses)

    @property
    def has_groundtruth(self) -> bool:
        return True

    @property
    def has_depth(self) -> bool:
        """Every frame carries its exact depth."""
        return True

    def __len__(self) -> int:
        return int(self._frames.shape[0])

    def _absolute(self, index: int) -> int:
        n = len(self)
        if not isinstance(index, (int, np.integer)):
            raise TypeError(f"frame index must be an int, got {type(index).__name__}")
        if not -n <= index < n:
            raise IndexError(f"frame {index} out of range for a sequence of {n} frames")
        return int(self._frames[int(index) % n])

    def __getitem__(self, index: int) -> Frame:
        k = self._absolute(index)
        radiance, depth = self._render(k)
        image = np.clip(np.rint(radiance), 0, 255).astype(np.uint8)
        return Frame(int(index) % len(self), float(self._all_t[k]), image, self._all_poses[k].copy(), depth)

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self[i]

    def slice(self, start: int = 0, stop: int | None = None) -> SyntheticSequence:
        """Frames ``start:stop`` as a new sequence (indices restart at 0; timestamps, poses, noise kept)."""
        n = len(self)
        stop = n if stop is None else min(stop, n)
        if not 0 <= start < n:
            raise InputError(f"start frame {start} is outside the sequence (0..{n - 1})")
        if stop <= start:
            raise InputError(f"empty frame range {start}:{stop}")
        return SyntheticSequence(self.config, _frames=self._frames[start:stop])

    def __repr__(self) -> str:
        c = self.config
        return (
            f"{type(self).__name__}(name={self.name!r}, frames={len(self)}, size={self.width}x{self.height}, "
            f"colour={c.colour}, speed={c.speed}, global_illumination={c.global_illumination}, "
            f"local_illumination={c.local_illumination}, noise_sigma={c.noise_sigma})"
        )

    # -- extras ---------------------------------------------------------------------------------
    def depth(self, index: int) -> np.ndarray:
        """Exact depth of frame ``index``: (H, W) float32 metres."""
        k = self._absolute(index)
        assert self.camera is not None
        return render(self.scene, self.camera, self._all_poses[k], blur=self.config.blur)[1]

    def inverse_depth(self, index: int) -> np.ndarray:
        """Exact inverse depth of frame ``index``: (H, W) float32, 1/metres."""
        return (1.0 / self.depth(index)).astype(np.float32)

    def gain_offset(self, index: int) -> tuple[float, float]:
        """Global illumination (gain, offset in grey levels) applied to frame ``index``."""
        return self._gain_offset(self._absolute(index))

    def _gain_offset(self, k: int) -> tuple[float, float]:
        A = self.config.global_illumination
        if A == 0.0:
            return 1.0, 0.0
        t = self._all_t[k]
        p = self._photo
        g = float(np.mean(np.sin(p.gain_f * t + p.gain_p)))
        o = float(np.mean(np.sin(p.off_f * t + p.off_p)))
        return 1.0 + A * g, 40.0 * A * o

    def _spot_gain(self, k: int, depth: np.ndarray) -> np.ndarray:
        """(H, W) float32 local gain of the spotlight at frame k: 1 − L/2 + L·s, s ∈ [0, 1].

        The light rides with the camera (computed in the camera frame): it sits 0.4 m from the optical
        centre in the image plane, at a slowly wobbling angle, and is aimed near the optical axis.  Its
        profile is s = exp(−(1 − cos α)/σ²) ≈ exp(−α²/2σ²) with α the angle off the beam axis and
        σ ≈ 0.35 rad, so a surface point's lighting changes as the camera moves.
        """
        amp = np.float32(self.config.local_illumination)
        assert self.camera is not None
        t = self._all_t[k]
        p = self._photo
        wob = np.sin(p.spot_f * t + p.spot_p)
        src = np.array([0.4 * math.cos(wob[0]), 0.4 * math.sin(wob[0]), 0.0], np.float32)
        aim = np.array([0.35 * wob[1], 0.25 * wob[2], 1.0])
        aim = (aim / np.linalg.norm(aim)).astype(np.float32)
        v = self._rays * depth[..., None] - src
        cosang = (v @ aim) / np.sqrt(np.einsum("hwc,hwc->hw", v, v))
        sigma = 0.35 * (1.0 + 0.3 * wob[3])
        s = np.exp((cosang - np.float32(1.0)) * np.float32(1.0 / sigma**2))
        return (np.float32(1.0) - amp / 2 + amp * s).astype(np.float32)

    def radiance(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Frame ``index`` before quantisation: float32 (H, W) or (H, W, 3) intensity on the 0..255 scale
        with illumination and noise applied but not rounded or clipped, and the (H, W) float32 depth.

        ``frame.image`` is ``clip(rint(radiance), 0, 255)`` as uint8.
        """
        return self._render(self._absolute(index))

    def _render(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`radiance` of frame ``k`` of the full (unsliced) trajectory."""
        assert self.camera is not None
        img, depth = render(self.scene, self.camera, self._all_poses[k], blur=self.config.blur)
        if self.config.local_illumination > 0.0:
            g = self._spot_gain(k, depth)
            img = img * (g if img.ndim == 2 else g[..., None])
        gain, offset = self._gain_offset(k)
        if gain != 1.0 or offset != 0.0:
            img = np.float32(gain) * img + np.float32(offset)
        if self.config.noise_sigma > 0.0:
            rng = np.random.default_rng(np.random.SeedSequence([int(self.config.seed), 0x0153, int(k)]))
            img = img + np.float32(self.config.noise_sigma) * rng.standard_normal(img.shape, dtype=np.float32)
        return img.astype(np.float32), depth
