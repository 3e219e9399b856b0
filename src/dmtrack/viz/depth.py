"""Pictures of inverse-depth maps, as LSD-SLAM's debug view and the paper's Figure 4.

Pixels with a depth hypothesis are coloured by inverse depth (near = red, far = blue, through the
rainbow); pixels with a **negative** inverse depth — geometrically impossible, a symptom of a wrong match —
are painted magenta so that they stand out; pixels without a hypothesis show the dimmed grey image.
Pure numpy + OpenCV (one table look-up per pixel): no matplotlib, so it works headless at full speed.
"""

from __future__ import annotations

import functools
import struct
import zlib

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
    code = inverse_depth_codes(idepth, valid, image, idepth_range)
    return cv2.LUT(cv2.merge([code, code, code]), _colour_table())


def inverse_depth_codes(
    idepth: np.ndarray,
    valid: np.ndarray,
    image: np.ndarray,
    idepth_range: tuple[float, float] | None = None,
) -> np.ndarray:
    """The picture of :func:`inverse_depth_image` as (H, W) uint8 indices into :func:`colour_table` (the arguments
    are the same): what :func:`write_depth_png` writes as a palette PNG."""
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
    return code


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


def colour_table() -> np.ndarray:
    """(256, 3) uint8 RGB of each index of :func:`inverse_depth_codes` (read-only)."""
    return _colour_table().reshape(256, 3)


def _png_chunk(tag: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data))


def palette_png(codes: np.ndarray, table: np.ndarray) -> bytes:
    """A PNG file (colour type 3: 8-bit indices and their RGB palette) of (H, W) uint8 ``codes`` and the (≤ 256, 3)
    uint8 RGB ``table``; every reader decodes it to ``table[codes]``.

    Rows without filtering, deflated at level 1 (zlib, without the GIL): for the depth pictures a third of the bytes
    that OpenCV deflates for the same picture in RGB, in about half the time, and a smaller file."""
    codes = np.ascontiguousarray(codes, dtype=np.uint8)
    table = np.ascontiguousarray(table, dtype=np.uint8)
    if codes.ndim != 2 or table.ndim != 2 or table.shape[1] != 3 or not 1 <= table.shape[0] <= 256:
        raise ValueError(f"palette_png: codes (H, W) and a (≤ 256, 3) table, got {codes.shape} and {table.shape}")
    if codes.size and int(codes.max()) >= len(table):
        raise ValueError(f"palette_png: code {int(codes.max())} has no colour in a table of {len(table)}")
    h, w = codes.shape
    rows = np.zeros((h, w + 1), np.uint8)  # a filter-type byte (0: none) before each row
    rows[:, 1:] = codes
    header = struct.pack(">IIBBBBB", w, h, 8, 3, 0, 0, 0)  # 8 bits, palette, deflate, adaptive filtering, no interlace
    return (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", header) + _png_chunk(b"PLTE", table.tobytes())
            + _png_chunk(b"IDAT", zlib.compress(rows.tobytes(), 1)) + _png_chunk(b"IEND", b""))  # fmt: skip


def write_depth_png(path, codes: np.ndarray) -> None:  # noqa: ANN001
    """Write :func:`inverse_depth_codes`' picture as a palette PNG, atomically (it decodes to the RGB of
    :func:`inverse_depth_image`)."""
    from dmtrack.io.atomic import write_bytes

    write_bytes(path, palette_png(codes, colour_table()))
