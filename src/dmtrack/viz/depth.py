"""Pictures of inverse-depth maps, as LSD-SLAM's debug view and the paper's Figure 4.

Pixels with a depth hypothesis are coloured by inverse depth (near = red, far = blue, through the
rainbow); pixels with a **negative** inverse depth — geometrically impossible, a symptom of a wrong match —
are painted magenta so that they stand out; pixels without a hypothesis show the dimmed grey image.
Pure numpy + OpenCV (one table look-up per pixel): no matplotlib, so it works headless at full speed.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

NEGATIVE_COLOUR = (255, 0, 255)  # magenta, RGB


def inverse_depth_image(
    idepth: np.ndarray,
    valid: np.ndarray,
    image: np.ndarray,
    idepth_range: tuple[float, float] | None = None,
) -> np.ndarray:
    """An (H, W, 3) uint8 RGB picture of an inverse-depth map over its image.

    Parameters
    ----------
    idepth : (H, W) inverse depth (any scale: the keyframe's normalised units).
    valid : (H, W) bool, pixels that carry a hypothesis.
    image : (H, W) or (H, W, 3) uint8, drawn dimmed where there is no hypothesis.
    idepth_range : (near, far) inverse depths mapped to red and blue; default: the 2nd/98th percentiles of
        the valid positive inverse depths.
    """
    grey = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    # one code per pixel, then one table look-up: 0..127 the dimmed grey (g // 2), 128..248 the hue 0..120 of a
    # positive inverse depth, 249 a negative one
    code = grey >> 1
    valid = valid & np.isfinite(idepth)
    positive = valid & (idepth > 0)
    negative = valid & (idepth <= 0)
    if positive.any():
        values = idepth[positive]
        if idepth_range is None:
            lo, hi = np.percentile(values, [2, 98])
        else:
            lo, hi = idepth_range[1], idepth_range[0]
            lo, hi = min(lo, hi), max(lo, hi)
        t = np.clip((values - lo) / max(hi - lo, 1e-12), 0.0, 1.0)
        # hue 120 (blue, far) .. 0 (red, near) in OpenCV's 0..180 hue scale
        code[positive] = _HUE_CODE + np.round((1.0 - t) * 120).astype(np.uint8)
    code[negative] = _NEGATIVE_CODE
    return cv2.LUT(cv2.merge([code, code, code]), _colour_table())


_HUE_CODE = 128
_NEGATIVE_CODE = _HUE_CODE + 121


@functools.cache
def _colour_table() -> np.ndarray:
    """(256, 1, 3) uint8 RGB of each code of :func:`inverse_depth_image` (a table for ``cv2.LUT``)."""
    table = np.zeros((256, 3), np.uint8)
    table[:_HUE_CODE] = np.arange(_HUE_CODE, dtype=np.uint8)[:, None]
    hsv = np.full((121, 1, 3), 255, np.uint8)
    hsv[:, 0, 0] = np.arange(121)
    table[_HUE_CODE:_NEGATIVE_CODE] = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[:, 0, :]
    table[_NEGATIVE_CODE] = NEGATIVE_COLOUR
    table.flags.writeable = False
    return table.reshape(256, 1, 3)


def write_png(path, image_rgb: np.ndarray) -> None:  # noqa: ANN001
    """Write an RGB uint8 image as PNG (OpenCV wants BGR), atomically."""
    from dmtrack.io.atomic import write_bytes

    ok, data = cv2.imencode(".png", cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR))
    if not ok:
        raise ValueError(f"{path}: OpenCV cannot encode this image as PNG ({image_rgb.shape}, {image_rgb.dtype})")
    write_bytes(path, data.tobytes())
