"""Colour-space features: ``rgb`` and ``lab`` (paper §3, "trivial multichannel features").

Both have three channels in a 0..255-like range and use the colour input (a grey image is replicated, which
gives R = G = B, and for Lab a* = b* = 128).

Lab
---
CIE L*a*b* of sRGB (D65) from OpenCV's *float* conversion (``cv2.COLOR_RGB2Lab`` on RGB/255, which applies the
sRGB gamma), mapped to OpenCV's 8-bit ranges without rounding:

    channel 0 = L* · 255/100  (0..255),  channel 1 = a* + 128,  channel 2 = b* + 128  (about 0..255).

The float conversion avoids the 8-bit conversion's quantisation while keeping the same ranges.
"""

from __future__ import annotations

import cv2
import numpy as np

from dmtrack.features.base import Feature


class RgbFeature(Feature):
    """R, G, B in 0..255 (times the scale)."""

    name = "rgb"
    channels = 3
    needs_colour = True
    pyramid = "downsample"
    description = "R, G, B channels 0..255"

    def __init__(self, scale: float = 1.0) -> None:
        super().__init__(scale)

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        out = np.empty(image.shape, np.float32)
        np.multiply(image, np.float32(gain), out=out, dtype=np.float32)
        return out


class LabFeature(Feature):
    """CIE L*a*b* in OpenCV's 8-bit ranges (2.55·L*, a*+128, b*+128), float (see module docs)."""

    name = "lab"
    channels = 3
    needs_colour = True
    pyramid = "downsample"
    description = "CIE L*a*b* (sRGB, D65) in OpenCV's 8-bit ranges: 2.55·L*, a*+128, b*+128 (float)"

    def __init__(self, scale: float = 1.0) -> None:
        super().__init__(scale)

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        rgb = image.astype(np.float32) * np.float32(1.0 / 255.0)
        np.clip(rgb, 0.0, 1.0, out=rgb)
        lab = cv2.cvtColor(rgb, cv2.COLOR_RGB2Lab)
        g = np.float32(gain)
        lab[:, :, 0] *= np.float32(255.0 / 100.0) * g
        lab[:, :, 1:] += np.float32(128.0)
        lab[:, :, 1:] *= g
        return lab
