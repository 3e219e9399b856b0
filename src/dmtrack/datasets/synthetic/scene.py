"""The synthetic room: geometry and procedural textures (:class:`Scene`, :func:`make_scene`).

The scene (:func:`make_scene`) is the inside of an axis-aligned room (walls, floor and ceiling) holding a
few boxes (rotated about the vertical axis, standing on the floor or floating) and a few slanted planar
rectangles, at different depths, so that a moving camera sees parallax and occlusion.  Every planar face
carries its own texture image generated once from the seed: band-limited noise octaves from ~0.5 to
~35 cycles per metre, step-edged blobs and rectangles of many sizes, thin lines and windowed stripe
patches — multi-scale and aperiodic, never a checkerboard.  Textures are stored with a texel size in metres
and a mip-map pyramid; :func:`~dmtrack.datasets.synthetic.renderer.render` samples them trilinearly with a
level of detail chosen from the pixel footprint on the surface, so there is little aliasing from VGA down to
small test images.

World frame: metres, ``z`` up, the floor at ``z = 0``, the room centred on the ``z`` axis.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numba
import numpy as np
import scipy.fft

from dmtrack.errors import InputError

__all__ = ["Scene", "make_scene"]

# Luma weights (ITU-R BT.601) and two chroma directions orthogonal to them: a colour texture is
# ``L + c1·e1 + c2·e2`` so its luma is exactly the grey texture L of the same seed (before clipping).
_LUMA = np.array([0.299, 0.587, 0.114])
_E1 = np.cross(_LUMA, [0.0, 0.0, 1.0])
_E1 /= np.linalg.norm(_E1)
_E2 = np.cross(_LUMA, _E1)
_E2 /= np.linalg.norm(_E2)


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
