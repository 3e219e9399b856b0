"""Image helpers of the features: the input a feature gets (:func:`prepare_image`), image iteration, and the 2×2
box downsampling of images and feature maps that the feature pyramids use."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from pathlib import Path

import cv2
import numpy as np

from dmtrack.errors import InputError


def prepare_image(image: np.ndarray, colour: bool) -> np.ndarray:
    """Validate an input image and convert it to what a feature needs.

    Parameters
    ----------
    image : np.ndarray
        ``uint8`` or floating-point (values in 0..255; the "recompute" pyramid passes 2×2 box means, which are
        float) image, ``(H, W)``, ``(H, W, 1)``, ``(H, W, 3)`` RGB or ``(H, W, 4)`` RGBA (alpha dropped).
    colour : bool
        True → return ``(H, W, 3)`` RGB (a grey image is replicated into three channels);
        False → return ``(H, W)`` grey (colour is converted with OpenCV's RGB→grey weights
        0.299 R + 0.587 G + 0.114 B, rounded for ``uint8``).

    Returns
    -------
    np.ndarray
        C-contiguous ``uint8`` (for ``uint8`` input) or ``float32`` array.

    Raises
    ------
    InputError
        Wrong dtype, number of dimensions or channels, or an empty image.
    """
    img = np.asarray(image)
    if img.dtype == np.uint8:
        pass
    elif np.issubdtype(img.dtype, np.floating):
        img = img.astype(np.float32, copy=False)
    else:
        raise InputError(f"feature input must be a uint8 or float image, got dtype {img.dtype}")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    elif img.ndim == 3 and img.shape[2] == 4:
        img = img[:, :, :3]
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
        raise InputError(f"feature input must be (H, W) grey or (H, W, 3) RGB, got shape {img.shape}")
    if img.shape[0] < 1 or img.shape[1] < 1:
        raise InputError(f"feature input image is empty: shape {img.shape}")
    img = np.ascontiguousarray(img)
    if colour and img.ndim == 2:
        img = np.ascontiguousarray(np.repeat(img[:, :, None], 3, axis=2))
    elif not colour and img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    return img


def iter_images(images: Iterable[np.ndarray | str | Path]) -> Iterator[np.ndarray]:
    """Yield arrays from an iterable of arrays or image paths (paths are read as stored: grey or RGB)."""
    from dmtrack.io.images import read_image

    for im in images:
        if isinstance(im, (str, Path)):
            yield read_image(im)
        else:
            yield np.asarray(im)


def downsample_image(image: np.ndarray) -> np.ndarray:
    """2×2 box mean of an image, ``(h, w[, 3])`` → ``(h//2, w//2[, 3])`` float32 (odd last row/column dropped)."""
    f = np.asarray(image, dtype=np.float32)
    h2, w2 = f.shape[0] // 2, f.shape[1] // 2
    f = f[: 2 * h2, : 2 * w2]
    out = (f[0::2, 0::2] + f[0::2, 1::2]) + (f[1::2, 0::2] + f[1::2, 1::2])
    return np.ascontiguousarray(out * np.float32(0.25), dtype=np.float32)


def downsample_feature(feat: np.ndarray) -> np.ndarray:
    """Per-channel 2×2 box mean of a feature map, ``(h, w, N)`` → ``(h//2, w//2, N)`` float32."""
    return downsample_image(feat)
