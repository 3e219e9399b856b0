"""Frames and their feature pyramids (lsd-slam-spec.md §1, generalised to N channels, §4.1–4.2).

A :class:`Frame` holds the source image (for point-cloud colours) and a pyramid of :class:`Level` s.
Level 0 is the feature map itself; level l+1 is the per-channel 2×2 box mean of level l (the "down-sample
the feature map" pyramid policy). Per level and channel the gradients are halved central differences, zero
on the one-pixel border; ``max_grad`` is the 3×3 max filter of the channel-mean gradient magnitude (zero on
the border).

Two implementations of the per-level computations exist: a plain numpy reference (``*_numpy``) and numba
kernels (used by :func:`build_frame`); ``tests/odometry/test_frame.py`` checks that they agree. Grey (N = 1) has
its own serial kernels on flat row views, which LLVM vectorises (the same float32 arithmetic, so the same bits).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numba
import numpy as np

from dmtrack.errors import InputError

if TYPE_CHECKING:  # pragma: no cover
    from dmtrack.geometry.camera import PinholeCamera


class Level:
    """One pyramid level of a frame.

    The gradients and ``max_grad`` are computed on first access (tracking never reads level 0's, mapping
    only the keyframe's), with the numba kernels or the numpy reference as chosen in :func:`build_frame`.

    Attributes
    ----------
    feat : np.ndarray
        (h, w, N) float32, C-contiguous feature values (grey: N=1, 0..255).
    gx, gy : np.ndarray
        (h, w, N) float32 halved central differences ½(F[x+1]−F[x−1]) (resp. along y); 0 on the 1-pixel
        border.
    max_grad : np.ndarray
        (h, w) float32: 3×3 max filter of mean_c sqrt(gx_c² + gy_c²); 0 on the 1-pixel border.
    camera : PinholeCamera
        Intrinsics of this level (``camera.level(l)``).
    packed : np.ndarray
        (h, w, 3, N) float32 (F, gx, gy) per pixel, each an N-channel block (built on first use).
    """

    def __init__(
        self,
        feat: np.ndarray,
        camera: Any,
        gx: np.ndarray | None = None,
        gy: np.ndarray | None = None,
        max_grad: np.ndarray | None = None,
        use_numba: bool = True,
    ):
        self.feat = feat
        self.camera = camera
        self._gx = gx
        self._gy = gy
        self._max_grad = max_grad
        self._use_numba = use_numba
        self._packed: np.ndarray | None = None

    def _ensure_gradients(self) -> None:
        if self._gx is None or self._gy is None:
            fn = gradients if self._use_numba else gradients_numpy
            self._gx, self._gy, mg = fn(self.feat)
            if self._max_grad is None:
                self._max_grad = mg

    @property
    def gx(self) -> np.ndarray:
        """(h, w, N) float32 x-gradient."""
        self._ensure_gradients()
        assert self._gx is not None
        return self._gx

    @property
    def gy(self) -> np.ndarray:
        """(h, w, N) float32 y-gradient."""
        self._ensure_gradients()
        assert self._gy is not None
        return self._gy

    @property
    def max_grad(self) -> np.ndarray:
        """(h, w) float32 3×3 max of the channel-mean gradient magnitude.

        With the numba kernels and N > 1 channels it is computed without keeping the (h, w, N) gradients (the
        depth map reads only it and the keyframe pixels' own gradients, which it forms on the fly): for 128-channel
        dense SIFT that saves 314 MB per keyframe."""
        if self._max_grad is None:
            if self._use_numba and self.feat.shape[2] > 1 and self._gx is None:
                self._max_grad = max_gradient(self.feat)
            else:
                self._ensure_gradients()
        assert self._max_grad is not None
        return self._max_grad

    @property
    def height(self) -> int:
        """Rows h of this level."""
        return int(self.feat.shape[0])

    @property
    def width(self) -> int:
        """Columns w of this level."""
        return int(self.feat.shape[1])

    @property
    def packed(self) -> np.ndarray:
        """(h, w, 3, N) float32 array of (F, gx, gy) per pixel, built on first use and cached.

        The tracker samples it bilinearly: one contiguous read of 3N floats per corner, each quantity a
        contiguous run of N channels (so the channel loop vectorises).
        """
        if self._packed is None:
            if self._gx is not None and self._gy is not None:
                self._packed = np.ascontiguousarray(np.stack([self.feat, self._gx, self._gy], axis=-2))
            elif self._use_numba:
                self._packed = pack(self.feat)
            else:
                self._packed = pack_numpy(self.feat)
        return self._packed

    def release_gradients(self) -> None:
        """Let go of the gradients, ``max_grad`` and ``packed`` (computed again, the same bits, if read again): a
        finished keyframe held by the sliding window is read only at its coarser levels (grey: 3.6 MB at 640×480,
        Bit-Planes 21 MB)."""
        self._gx = self._gy = self._max_grad = self._packed = None

    def __repr__(self) -> str:
        return f"Level({self.width}x{self.height}x{self.feat.shape[2]})"


@dataclass
class Frame:
    """A frame: index, timestamp, source image and feature pyramid.

    Attributes
    ----------
    index : int
        Frame index in the sequence.
    timestamp : float
        Timestamp (seconds or dataset units).
    image : np.ndarray
        The source uint8 image, (H, W) grey or (H, W, 3) RGB, used for point-cloud colours.
    levels : list[Level]
        Pyramid, level 0 full resolution.
    """

    index: int
    timestamp: float
    image: np.ndarray
    levels: list[Level]

    @property
    def camera(self) -> PinholeCamera:
        """Level-0 intrinsics."""
        return self.levels[0].camera

    @property
    def n_channels(self) -> int:
        """Number of feature channels N."""
        return int(self.levels[0].feat.shape[2])

    @property
    def height(self) -> int:
        """Level-0 rows H."""
        return self.levels[0].height

    @property
    def width(self) -> int:
        """Level-0 columns W."""
        return self.levels[0].width


# ------------------------------------------------------------------------------------------ numpy reference
def downsample_numpy(feat: np.ndarray) -> np.ndarray:
    """2×2 box mean per channel: (h, w, N) → (h//2, w//2, N) float32 (h, w even). Reference implementation."""
    f = feat.astype(np.float32)
    s = (f[0::2, 0::2] + f[0::2, 1::2]) + (f[1::2, 0::2] + f[1::2, 1::2])
    return (s * np.float32(0.25)).astype(np.float32)


def gradients_numpy(feat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gradients and max-gradient of one level. Reference implementation.

    Parameters
    ----------
    feat : (h, w, N) float32

    Returns
    -------
    gx, gy : (h, w, N) float32
        ½(F[x+1]−F[x−1]), ½(F[y+1]−F[y−1]) at interior pixels, 0 on the 1-pixel border.
    max_grad : (h, w) float32
        3×3 max filter of mean_c sqrt(gx_c²+gy_c²) at interior pixels (border magnitudes are 0); 0 on the
        border.
    """
    f = feat.astype(np.float32)
    h, w, n = f.shape
    gx = np.zeros_like(f)
    gy = np.zeros_like(f)
    half = np.float32(0.5)
    gx[1:-1, 1:-1] = half * (f[1:-1, 2:] - f[1:-1, :-2])
    gy[1:-1, 1:-1] = half * (f[2:, 1:-1] - f[:-2, 1:-1])
    mag = np.sqrt(gx * gx + gy * gy).astype(np.float32)
    # channel mean, summed in channel order then divided (same order as the kernel)
    msum = np.zeros((h, w), np.float32)
    for c in range(n):
        msum += mag[:, :, c]
    gmean = (msum / np.float32(n)).astype(np.float32)
    mg = np.zeros((h, w), np.float32)
    if h >= 3 and w >= 3:
        win = np.lib.stride_tricks.sliding_window_view(gmean, (3, 3))
        mg[1:-1, 1:-1] = win.max(axis=(2, 3))
    return gx, gy, mg


# ------------------------------------------------------------------------------------------ numba kernels
@numba.njit(cache=True, nogil=True)
def _magnitude_sum(gx: np.ndarray, gy: np.ndarray) -> np.float32:  # pragma: no cover - compiled
    """Σ_c sqrt(gx_c² + gy_c²) in float32 (N > 1), in channel order: the same bits as :func:`gradients_numpy`.

    Plain IEEE arithmetic in channel order, like every sum in the odometry (see :mod:`dmtrack.odometry._lanes`).
    """
    s = np.float32(0.0)
    for c in range(gx.shape[0]):
        s += np.sqrt(gx[c] * gx[c] + gy[c] * gy[c])
    return s


@numba.njit(cache=True, nogil=True)
def _magnitude_sum_at(feat: np.ndarray, y: int, x: int) -> np.float32:  # pragma: no cover - compiled
    """:func:`_magnitude_sum` of interior pixel (y, x) with its gradients formed from ``feat`` on the fly (N > 1):
    the same float32 operations in the same order, so the same bits, without (h, w, N) gradient arrays."""
    half = np.float32(0.5)
    s = np.float32(0.0)
    for c in range(feat.shape[2]):
        dx = half * (feat[y, x + 1, c] - feat[y, x - 1, c])
        dy = half * (feat[y + 1, x, c] - feat[y - 1, x, c])
        s += np.sqrt(dx * dx + dy * dy)
    return s


@numba.njit(cache=True, nogil=True)
def _max3x3(gmean: np.ndarray, y: int, x: int) -> np.float32:  # pragma: no cover - compiled
    """Maximum of the 3×3 window of ``gmean`` around interior pixel (y, x), rows then columns in order."""
    m = gmean[y - 1, x - 1]
    for yy in range(y - 1, y + 2):
        for xx in range(x - 1, x + 2):
            v = gmean[yy, xx]
            if v > m:
                m = v
    return m


@numba.njit(cache=True, nogil=True, parallel=True)
def _max_gradient_kernel(feat: np.ndarray, gmean: np.ndarray, max_grad: np.ndarray) -> None:  # pragma: no cover
    """``max_grad`` of :func:`_gradients_kernel` (N > 1) without writing the gradients; rows over threads."""
    h, w, n = feat.shape
    inv_n = np.float32(n)
    for y in numba.prange(h):
        for x in range(w):
            if y == 0 or y == h - 1 or x == 0 or x == w - 1:
                gmean[y, x] = 0.0
            else:
                gmean[y, x] = _magnitude_sum_at(feat, y, x) / inv_n
    for y in numba.prange(h):
        for x in range(w):
            if y == 0 or y == h - 1 or x == 0 or x == w - 1:
                max_grad[y, x] = 0.0
            else:
                max_grad[y, x] = _max3x3(gmean, y, x)


@numba.njit(cache=True, nogil=True, parallel=True)
def _gradients_kernel(
    feat: np.ndarray, gx: np.ndarray, gy: np.ndarray, gmean: np.ndarray, max_grad: np.ndarray
) -> None:  # pragma: no cover - compiled
    # rows over threads (no reductions across pixels: any thread count gives the same bits); per pixel the
    # gradients are written first (a vectorisable loop), then their magnitudes summed in channel order
    h, w, n = feat.shape
    half = np.float32(0.5)
    inv_n = np.float32(n)
    for y in numba.prange(h):
        for x in range(w):
            if y == 0 or y == h - 1 or x == 0 or x == w - 1:
                for c in range(n):
                    gx[y, x, c] = 0.0
                    gy[y, x, c] = 0.0
                gmean[y, x] = 0.0
                continue
            for c in range(n):
                gx[y, x, c] = half * (feat[y, x + 1, c] - feat[y, x - 1, c])
                gy[y, x, c] = half * (feat[y + 1, x, c] - feat[y - 1, x, c])
            if n == 1:
                dx = gx[y, x, 0]
                dy = gy[y, x, 0]
                gmean[y, x] = np.sqrt(dx * dx + dy * dy) / inv_n
            else:
                gmean[y, x] = _magnitude_sum(gx[y, x], gy[y, x]) / inv_n
    for y in numba.prange(h):
        for x in range(w):
            if y == 0 or y == h - 1 or x == 0 or x == w - 1:
                max_grad[y, x] = 0.0
                continue
            max_grad[y, x] = _max3x3(gmean, y, x)


@numba.njit(cache=True, nogil=True, parallel=True)
def _downsample_kernel(feat: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    h2, w2, n = out.shape
    for y in numba.prange(h2):
        for x in range(w2):
            for c in range(n):
                s = (feat[2 * y, 2 * x, c] + feat[2 * y, 2 * x + 1, c]) + (
                    feat[2 * y + 1, 2 * x, c] + feat[2 * y + 1, 2 * x + 1, c]
                )
                out[y, x, c] = s * np.float32(0.25)


@numba.njit(cache=True, nogil=True, parallel=True)
def _pack_kernel(feat: np.ndarray, packed: np.ndarray) -> None:  # pragma: no cover - compiled
    """(F, gx, gy) of every pixel into ``packed`` (h, w, 3, N), rows over threads (no reductions)."""
    h, w, n = feat.shape
    half = np.float32(0.5)
    for y in numba.prange(h):
        for x in range(w):
            for c in range(n):
                packed[y, x, 0, c] = feat[y, x, c]
            if y == 0 or y == h - 1 or x == 0 or x == w - 1:
                for c in range(n):
                    packed[y, x, 1, c] = 0.0
                    packed[y, x, 2, c] = 0.0
            else:
                for c in range(n):
                    packed[y, x, 1, c] = half * (feat[y, x + 1, c] - feat[y, x - 1, c])
                for c in range(n):
                    packed[y, x, 2, c] = half * (feat[y + 1, x, c] - feat[y - 1, x, c])


def pack_numpy(feat: np.ndarray) -> np.ndarray:
    """(h, w, N) → (h, w, 3, N) float32 (F, gx, gy) with the gradients of :func:`gradients_numpy`. Reference."""
    f = np.asarray(feat, np.float32)
    gx, gy, _ = gradients_numpy(f)
    return np.ascontiguousarray(np.stack([f, gx, gy], axis=-2))


@numba.njit(cache=True, nogil=True)
def _pack_grey_kernel(feat: np.ndarray, packed: np.ndarray) -> None:  # pragma: no cover - compiled
    """:func:`_pack_kernel` for N = 1: the same float32 arithmetic on flat row views, which LLVM vectorises."""
    h, w = feat.shape[0], feat.shape[1]
    half = np.float32(0.5)
    for y in range(h):
        f = feat[y].reshape(w)
        p = packed[y].reshape(3 * w)
        if y == 0 or y == h - 1:
            for x in range(w):
                p[3 * x] = f[x]
                p[3 * x + 1] = 0.0
                p[3 * x + 2] = 0.0
            continue
        fu = feat[y - 1].reshape(w)
        fd = feat[y + 1].reshape(w)
        for x in range(w - 2):  # interior pixel x + 1
            p[3 * x + 3] = f[x + 1]
            p[3 * x + 4] = half * (f[x + 2] - f[x])
            p[3 * x + 5] = half * (fd[x + 1] - fu[x + 1])
        for x in (0, w - 1):
            p[3 * x] = f[x]
            p[3 * x + 1] = 0.0
            p[3 * x + 2] = 0.0


def pack(feat: np.ndarray) -> np.ndarray:
    """:func:`pack_numpy` as one numba pass (the tracker's sampling layout; no gradient arrays, no max_grad)."""
    f = np.ascontiguousarray(feat, dtype=np.float32)
    h, w, n = f.shape
    out = np.empty((h, w, 3, n), np.float32)
    if n == 1:
        _pack_grey_kernel(f, out)
    else:
        _pack_kernel(f, out)
    return out


@numba.njit(cache=True, nogil=True)
def _downsample_grey_kernel(feat: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    """:func:`_downsample_kernel` for N = 1 on flat row views (vectorised by LLVM; same float32 arithmetic)."""
    h2, w2 = out.shape[0], out.shape[1]
    w = feat.shape[1]
    quarter = np.float32(0.25)
    for y in range(h2):
        a = feat[2 * y].reshape(w)
        b = feat[2 * y + 1].reshape(w)
        o = out[y].reshape(w2)
        for x in range(w2):
            o[x] = ((a[2 * x] + a[2 * x + 1]) + (b[2 * x] + b[2 * x + 1])) * quarter


def downsample(feat: np.ndarray) -> np.ndarray:
    """2×2 box mean per channel (numba): (h, w, N) float32 → (h//2, w//2, N) float32."""
    h, w, n = feat.shape
    out = np.empty((h // 2, w // 2, n), np.float32)
    kernel = _downsample_grey_kernel if n == 1 else _downsample_kernel
    kernel(np.ascontiguousarray(feat, dtype=np.float32), out)
    return out


@numba.njit(cache=True, nogil=True)
def _gradients_grey_kernel(
    feat: np.ndarray, gx: np.ndarray, gy: np.ndarray, gmean: np.ndarray, max_grad: np.ndarray
) -> None:  # pragma: no cover - compiled
    """:func:`_gradients_kernel` for N = 1 on flat row views (vectorised by LLVM; same float32 arithmetic, and
    the 3×3 maximum taken in the same order)."""
    h, w = feat.shape[0], feat.shape[1]
    half = np.float32(0.5)
    one = np.float32(1)
    for y in range(h):
        ox = gx[y].reshape(w)
        oy = gy[y].reshape(w)
        om = gmean[y].reshape(w)
        if y == 0 or y == h - 1:
            for x in range(w):
                ox[x] = 0.0
                oy[x] = 0.0
                om[x] = 0.0
            continue
        f = feat[y].reshape(w)
        fu = feat[y - 1].reshape(w)
        fd = feat[y + 1].reshape(w)
        for x in range(w - 2):  # interior pixel x + 1
            dx = half * (f[x + 2] - f[x])
            dy = half * (fd[x + 1] - fu[x + 1])
            ox[x + 1] = dx
            oy[x + 1] = dy
            om[x + 1] = np.sqrt(dx * dx + dy * dy) / one
        for x in (0, w - 1):
            ox[x] = 0.0
            oy[x] = 0.0
            om[x] = 0.0
    for y in range(h):
        o = max_grad[y]
        if y == 0 or y == h - 1:
            for x in range(w):
                o[x] = 0.0
            continue
        a = gmean[y - 1]
        b = gmean[y]
        c = gmean[y + 1]
        for x in range(w - 2):  # interior pixel x + 1: window columns x, x + 1, x + 2
            m = a[x]
            m = a[x + 1] if a[x + 1] > m else m
            m = a[x + 2] if a[x + 2] > m else m
            m = b[x] if b[x] > m else m
            m = b[x + 1] if b[x + 1] > m else m
            m = b[x + 2] if b[x + 2] > m else m
            m = c[x] if c[x] > m else m
            m = c[x + 1] if c[x + 1] > m else m
            m = c[x + 2] if c[x + 2] > m else m
            o[x + 1] = m
        o[0] = 0.0
        o[w - 1] = 0.0


def gradients(feat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gradients and max-gradient of one level (numba); same definition as :func:`gradients_numpy`."""
    f = np.ascontiguousarray(feat, dtype=np.float32)
    h, w, n = f.shape
    gx = np.empty_like(f)
    gy = np.empty_like(f)
    gmean = np.empty((h, w), np.float32)
    mg = np.empty((h, w), np.float32)
    kernel = _gradients_grey_kernel if n == 1 else _gradients_kernel
    kernel(f, gx, gy, gmean, mg)
    return gx, gy, mg


def max_gradient(feat: np.ndarray) -> np.ndarray:
    """``max_grad`` of :func:`gradients` (numba) without materialising the per-channel gradients."""
    f = np.ascontiguousarray(feat, dtype=np.float32)
    h, w, n = f.shape
    if n == 1:
        return gradients(f)[2]
    gmean = np.empty((h, w), np.float32)
    mg = np.empty((h, w), np.float32)
    _max_gradient_kernel(f, gmean, mg)
    return mg


def build_frame(
    index: int,
    timestamp: float,
    image: np.ndarray,
    feature_map: np.ndarray | list[np.ndarray],
    camera: PinholeCamera,
    n_levels: int = 5,
    use_numba: bool = True,
) -> Frame:
    """Build a :class:`Frame` with an ``n_levels`` pyramid.

    Parameters
    ----------
    index, timestamp
        Frame index and timestamp.
    image : np.ndarray
        Source uint8 image (H, W) or (H, W, 3), kept for colours.
    feature_map : np.ndarray or list of np.ndarray
        (H, W, N) (or (H, W) for N=1) feature map; converted to float32 C-contiguous. Level l+1 is the 2×2 box
        mean of level l (the "downsample" pyramid policy). A list gives every level's map instead (the
        "recompute" policy, e.g. Bit-Planes computed on each level's image): ``n_levels`` maps of shape
        (H >> l, W >> l, N).
    camera : PinholeCamera
        Level-0 intrinsics; its width/height must equal W/H.
    n_levels : int
        Pyramid levels; H and W must be divisible by 2^(n_levels−1).
    use_numba : bool
        Use the numba kernels (default) or the numpy reference (also for the lazily computed gradients).

    Raises
    ------
    InputError
        If the feature map has the wrong shape or does not fit the camera.
    """
    given: list[np.ndarray] | None = None
    if isinstance(feature_map, (list, tuple)):
        given = [np.asarray(f) for f in feature_map]
        given = [f[:, :, None] if f.ndim == 2 else f for f in given]
        if len(given) != n_levels:
            raise InputError(f"{len(given)} feature maps given for a {n_levels}-level pyramid")
        for lv, f in enumerate(given):
            expected = (given[0].shape[0] >> lv, given[0].shape[1] >> lv, given[0].shape[2])
            if f.shape != expected:
                raise InputError(f"pyramid level {lv} feature map has shape {f.shape}, expected {expected}")
        feature_map = given[0]
    fm = np.asarray(feature_map)
    if fm.ndim == 2:
        fm = fm[:, :, None]
    if fm.ndim != 3 or fm.shape[2] < 1:
        raise InputError(f"feature map must be (H, W, N), got shape {fm.shape}")
    h, w, _ = fm.shape
    if n_levels < 1:
        raise InputError("n_levels must be ≥ 1")
    div = 1 << (n_levels - 1)
    if h % div or w % div:
        raise InputError(f"feature map {w}x{h} is not divisible by {div} (needed for {n_levels} levels)")
    cw, ch = int(camera.width), int(camera.height)
    if (cw, ch) != (w, h):
        raise InputError(f"feature map is {w}x{h} but the camera is {cw}x{ch}")
    feat = np.ascontiguousarray(fm, dtype=np.float32)
    down_fn = downsample if use_numba else downsample_numpy
    levels: list[Level] = []
    for lv in range(n_levels):
        if lv > 0:
            feat = down_fn(feat) if given is None else np.ascontiguousarray(given[lv], dtype=np.float32)
        levels.append(Level(feat, camera.level(lv), use_numba=use_numba))
    return Frame(index=int(index), timestamp=float(timestamp), image=image, levels=levels)
