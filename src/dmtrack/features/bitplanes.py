"""Bit-Planes (Alismail, Browning, Lucey; code halismai/bpvo) — ``lsd-slam-spec.md`` §5.

1. Optional pre-smoothing of the intensity with a 3×3 Gaussian of std ``sigma0`` (default 0.5, as bpvo's
   ``BitPlanesDescriptor``).  For ``uint8`` input the blurred image is rounded back to ``uint8`` as OpenCV (and
   bpvo) does for an 8-bit image; float input (the "recompute" pyramid's 2×2 box means) stays float.
2. Census transform on the 3×3 neighbourhood: bit b of pixel (x, y) is 1 if the neighbour is ≥ the centre,
   bits in the order top-left (b0), top, top-right, left, right, bottom-left, bottom, bottom-right (b7).
   The one-pixel image border has all bits 0.
3. Channel b = bit b × scale (bpvo uses 255; the paper's default feature scale was 9.77).
4. Optional smoothing of each channel with a 5×5 Gaussian of std ``sigma1`` (off by default, as bpvo's
   descriptor default; its shipped configs use 0.5–1.75).  Border handling: OpenCV's default reflect-101.

Pyramid policy ``"recompute"``: the census is recomputed on each 2×2-box-downsampled level (as bpvo does).
Without pre-smoothing the map is invariant to any strictly increasing intensity change.
"""

from __future__ import annotations

import cv2
import numpy as np

from dmtrack.features.base import Feature

#: (dy, dx) of the neighbour compared with the centre for bits 0..7.
CENSUS_OFFSETS: tuple[tuple[int, int], ...] = (
    (-1, -1), (-1, 0), (-1, 1),
    (0, -1), (0, 1),
    (1, -1), (1, 0), (1, 1),
)


def census_bits(image: np.ndarray) -> np.ndarray:
    """3×3 census bits of a grey image.

    Parameters
    ----------
    image : np.ndarray
        ``(H, W)`` ``uint8`` or float image.

    Returns
    -------
    np.ndarray
        ``(H, W, 8)`` bool; ``[y, x, b]`` = neighbour ``CENSUS_OFFSETS[b]`` ≥ centre; False on the 1-pixel border.
    """
    h, w = image.shape
    bits = np.zeros((h, w, 8), dtype=bool)
    if h < 3 or w < 3:
        return bits
    c = image[1:-1, 1:-1]
    for b, (dy, dx) in enumerate(CENSUS_OFFSETS):
        bits[1:-1, 1:-1, b] = image[1 + dy : h - 1 + dy, 1 + dx : w - 1 + dx] >= c
    return bits


def census_planes(image: np.ndarray, value: float = 1.0) -> np.ndarray:
    """``census_bits(image) × value`` as ``(H, W, 8)`` float32 in one numba pass (the same values: a set bit is
    ``float32(value)``, a clear one 0)."""
    img = np.ascontiguousarray(image)
    if img.ndim != 2:
        raise ValueError(f"census_planes needs an (H, W) image, got shape {img.shape}")
    if img.dtype not in (np.uint8, np.float32, np.float64):
        img = img.astype(np.float64)  # exact for the integer types: the same comparisons
    from dmtrack.features._census import census_planes_kernel  # numba: imported with the first image, not the feature

    out = np.empty(img.shape + (8,), np.float32)
    census_planes_kernel(img, np.float32(value), out)
    return out


def census_code(image: np.ndarray) -> np.ndarray:
    """The 8-bit census signature ``Σ_b bit_b << b`` as ``(H, W)`` uint8 (0 on the 1-pixel border)."""
    bits = census_bits(image)
    weights = (1 << np.arange(8)).astype(np.uint8)
    return (bits.astype(np.uint8) * weights).sum(axis=2, dtype=np.uint16).astype(np.uint8)


class BitPlanesFeature(Feature):
    """The 8 Bit-Planes channels (see module docs).

    Parameters
    ----------
    scale : float
        Value of a set bit (default feature scale).
    sigma0 : float
        Std of the 3×3 Gaussian applied to the intensity before the census; ≤ 0 disables it.
    sigma1 : float
        Std of the 5×5 Gaussian applied to each bit-plane; ≤ 0 (default) disables it.
    """

    name = "bitplanes"
    channels = 8
    pyramid = "recompute"
    description = "Bit-Planes: 8 census-transform bits of the 3x3 neighbourhood (Alismail et al.)"

    def __init__(self, scale: float = 1.0, sigma0: float = 0.5, sigma1: float = 0.0) -> None:
        super().__init__(scale)
        self.sigma0 = float(sigma0)
        self.sigma1 = float(sigma1)
        if not (np.isfinite(self.sigma0) and np.isfinite(self.sigma1)):
            raise ValueError("sigma0 and sigma1 must be finite")

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        img = image
        if self.sigma0 > 0:
            img = cv2.GaussianBlur(img, (3, 3), self.sigma0, sigmaY=self.sigma0)
        out = census_planes(img, gain)  # census_bits(img) × gain, in one pass
        if self.sigma1 > 0:
            out = cv2.GaussianBlur(out, (5, 5), self.sigma1, sigmaY=self.sigma1)
            if out.ndim == 2:  # pragma: no cover - OpenCV keeps 8 channels, defensive
                out = out[:, :, None]
        return out

    def __repr__(self) -> str:
        return f"BitPlanesFeature(scale={self.scale:g}, sigma0={self.sigma0:g}, sigma1={self.sigma1:g})"
