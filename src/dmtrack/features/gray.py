"""Grey intensity features: ``gray`` (LSD-SLAM's baseline) and ``gray-affine`` (Gray-A)."""

from __future__ import annotations

import numpy as np

from dmtrack.features.base import Feature


class GrayFeature(Feature):
    """The grey intensity, one channel in 0..255 (times the scale, 1 by default).

    Colour input is converted with OpenCV's RGB→grey weights (rounded to ``uint8`` for ``uint8`` input).
    """

    name = "gray"
    channels = 1
    pyramid = "downsample"
    description = "grey intensity 0..255 (LSD-SLAM baseline)"

    def __init__(self, scale: float = 1.0) -> None:
        super().__init__(scale)

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        out = np.empty((image.shape[0], image.shape[1], 1), np.float32)
        np.multiply(image, np.float32(gain), out=out[:, :, 0], dtype=np.float32)
        return out


class GrayAffineFeature(GrayFeature):
    """The same map as :class:`GrayFeature`; ``affine_brightness = True`` tells the odometry to estimate
    LSD-SLAM's affine brightness (a, b) per frame (``useAffineLightningEstimation``, the paper's Gray-A)."""

    name = "gray-affine"
    affine_brightness = True
    description = "grey intensity with LSD-SLAM's affine brightness estimation (Gray-A)"
