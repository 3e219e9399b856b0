"""Colour-space features: ``rgb`` and ``lab`` (paper §3, "trivial multichannel features").

Both have three channels in a 0..255-like range and use the colour input (a grey image is replicated, which
gives R = G = B, and for Lab a* = b* = 128).

Lab
---
CIE L*a*b* of sRGB (D65) from OpenCV's *float* conversion (``cv2.COLOR_RGB2Lab`` on RGB/255, which applies the
sRGB gamma), mapped to OpenCV's 8-bit ranges without rounding:

    channel 0 = L* · 255/100  (0..255),  channel 1 = a* + 128,  channel 2 = b* + 128  (about 0..255).

The float conversion avoids the 8-bit conversion's quantisation while keeping the same ranges.

Chroma smoothing (option ``chroma_sigma``)
------------------------------------------
Most colour sources store chroma at half resolution: JPEG 4:2:0 (the shared 7-Scenes frames: 16×16-pixel chroma
blocks), video codecs, and every Bayer camera's demosaicing. At full resolution such chroma carries fixed-pattern
edges that do not move with the scene: on the shared 7-Scenes frames the a* differences between columns 16k−1 and
16k are 2.5× those elsewhere, and alternate columns differ by 40 % (docs/multichannel-cost.md, "Colour from
subsampled chroma"). A direct method aligns those patterns too, and they pull towards the identity motion.
``chroma_sigma = σ > 0`` low-passes the chroma with a Gaussian of σ pixels before the feature is formed, and keeps
the luminance as it is:

* ``lab``: a* and b* are blurred; L* is untouched.
* ``rgb``: the image is split into JPEG's luma Y = 0.299 R + 0.587 G + 0.114 B and the colour differences R − Y,
  B − Y; the differences are blurred and R, G, B rebuilt (G from Y). Y, and hence the grey image, is unchanged.

The default is σ = 2 px, chosen by measurement (docs/multichannel-cost.md): on the shared 7-Scenes it takes ``lab``
from 12.3 to 7.2 °/m median rotation drift over seeds 0–9, and it leaves Tsukuba (rendered, full-resolution
chroma) as it was. ``chroma_sigma = 0`` is the paper's plain colour feature.
"""

from __future__ import annotations

import cv2
import numpy as np

from dmtrack.errors import InputError
from dmtrack.features.base import Feature

LUMA = (0.299, 0.587, 0.114)  #: JPEG's (and OpenCV's RGB→grey) luma weights
CHROMA_SIGMA = 2.0  #: default ``chroma_sigma`` of rgb and lab (pixels; 0 = the paper's plain colour)


def _check_sigma(chroma_sigma: float) -> float:
    try:
        s = float(chroma_sigma)
    except (TypeError, ValueError):
        raise InputError(f"chroma_sigma must be a number, got {chroma_sigma!r}") from None
    if not (s >= 0 and np.isfinite(s)):
        raise InputError(f"chroma_sigma must be finite and >= 0, got {chroma_sigma!r}")
    return s


def _blur(channel: np.ndarray, sigma: float) -> np.ndarray:
    return cv2.GaussianBlur(np.ascontiguousarray(channel), (0, 0), sigma, borderType=cv2.BORDER_REFLECT_101)


def smooth_rgb_chroma(rgb: np.ndarray, sigma: float) -> np.ndarray:
    """``(H, W, 3)`` float32 RGB with the colour differences R − Y and B − Y Gaussian-blurred (σ pixels) and the
    luma Y = 0.299 R + 0.587 G + 0.114 B kept; ``sigma = 0`` and a grey image (R = G = B) return the input as
    float32."""
    f = np.asarray(rgb, dtype=np.float32)
    if sigma <= 0 or (np.array_equal(rgb[..., 0], rgb[..., 1]) and np.array_equal(rgb[..., 1], rgb[..., 2])):
        return f  # a grey image has no chroma: returned exactly, not rebuilt through Y with its roundings
    wr, wg, wb = (np.float32(w) for w in LUMA)
    y = wr * f[:, :, 0] + wg * f[:, :, 1] + wb * f[:, :, 2]
    cr = _blur(f[:, :, 0] - y, sigma)
    cb = _blur(f[:, :, 2] - y, sigma)
    out = np.empty(f.shape, np.float32)
    out[:, :, 0] = y + cr
    out[:, :, 2] = y + cb
    out[:, :, 1] = (y - wr * out[:, :, 0] - wb * out[:, :, 2]) / wg
    return out


class RgbFeature(Feature):
    """R, G, B in 0..255 (times the scale); ``chroma_sigma`` > 0 blurs the chroma first (module docs)."""

    name = "rgb"
    channels = 3
    needs_colour = True
    pyramid = "downsample"
    description = "R, G, B channels 0..255, chroma low-passed (Gaussian 2 px; chroma_sigma=0: plain)"

    def __init__(self, scale: float = 1.0, chroma_sigma: float = CHROMA_SIGMA) -> None:
        super().__init__(scale)
        self.chroma_sigma = _check_sigma(chroma_sigma)

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        if self.chroma_sigma > 0:
            # a new array: smooth_rgb_chroma returns a float32 input itself when there is nothing to smooth
            return smooth_rgb_chroma(image, self.chroma_sigma) * np.float32(gain)
        out = np.empty(image.shape, np.float32)
        np.multiply(image, np.float32(gain), out=out, dtype=np.float32)
        return out


class LabFeature(Feature):
    """CIE L*a*b* in OpenCV's 8-bit ranges (2.55·L*, a*+128, b*+128), float; ``chroma_sigma`` > 0 blurs a*, b*
    (module docs)."""

    name = "lab"
    channels = 3
    needs_colour = True
    pyramid = "downsample"
    description = (
        "CIE L*a*b* (sRGB, D65) in OpenCV's 8-bit ranges: 2.55·L*, a*+128, b*+128 (float), a*/b* low-passed "
        "(Gaussian 2 px; chroma_sigma=0: plain)"
    )

    def __init__(self, scale: float = 1.0, chroma_sigma: float = CHROMA_SIGMA) -> None:
        super().__init__(scale)
        self.chroma_sigma = _check_sigma(chroma_sigma)

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        rgb = image.astype(np.float32) * np.float32(1.0 / 255.0)
        np.clip(rgb, 0.0, 1.0, out=rgb)
        lab = cv2.cvtColor(rgb, cv2.COLOR_RGB2Lab)
        g = np.float32(gain)
        lab[:, :, 0] *= np.float32(255.0 / 100.0) * g
        lab[:, :, 1:] += np.float32(128.0)
        if self.chroma_sigma > 0:
            for c in (1, 2):
                lab[:, :, c] = _blur(lab[:, :, c], self.chroma_sigma)
        lab[:, :, 1:] *= g
        return lab
