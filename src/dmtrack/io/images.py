"""Image reading with errors that name the file.

OpenCV returns ``None`` for a missing or corrupt file; these helpers turn that into an
:class:`~dmtrack.errors.InputError` naming the file, and return colour images in RGB order.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from dmtrack.errors import InputError
from dmtrack.io.files import read_bytes


def _imread(path: Path, flags: int) -> np.ndarray:
    path = Path(path)
    # reading the bytes + imdecode also handles non-ASCII paths.
    data = np.frombuffer(read_bytes(path, "image file"), dtype=np.uint8)
    if data.size == 0:
        raise InputError("image file is empty", path=path)
    try:
        image = cv2.imdecode(data, flags)
    except cv2.error:  # e.g. a header announcing more pixels than OpenCV accepts
        image = None
    if image is None:
        raise InputError("cannot decode image (corrupt or unsupported format)", path=path)
    return image


def read_image(path: str | Path, grey: bool | None = None) -> np.ndarray:
    """Read an 8-bit image.

    Parameters
    ----------
    path : image file (PNG, JPEG, …).
    grey : True → ``(H, W)`` grey; False → ``(H, W, 3)`` RGB; None → as stored (grey stays grey,
        colour becomes RGB, an alpha channel is dropped).

    Returns
    -------
    uint8 array.  16-bit images are rejected (use :func:`read_depth_png` for depth).
    """
    path = Path(path)
    if grey is True:
        image = _imread(path, cv2.IMREAD_GRAYSCALE)
    else:
        image = _imread(path, cv2.IMREAD_UNCHANGED if grey is None else cv2.IMREAD_COLOR)
        if image.dtype != np.uint8:
            raise InputError(f"expected an 8-bit image, got {image.dtype}", path=path)
        if image.ndim == 3:
            if image.shape[2] == 4:
                image = cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
            elif image.shape[2] == 3:
                image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB)
            else:
                image = image[:, :, 0]
        elif grey is False:
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    return np.ascontiguousarray(image)


def read_depth_png(path: str | Path, scale: float, invalid: int | None = None) -> np.ndarray:
    """Read a 16-bit depth PNG and convert it to metres (float32, 0 where invalid).

    Parameters
    ----------
    scale : metres per stored unit (1/1000 for millimetres, 1/5000 for TUM RGB-D).
    invalid : a stored value besides 0 that means "no measurement" (7-Scenes: 65535).
    """
    path = Path(path)
    raw = _imread(path, cv2.IMREAD_ANYDEPTH)
    if raw.dtype != np.uint16:
        raise InputError(f"expected a 16-bit depth image, got {raw.dtype}", path=path)
    depth = raw.astype(np.float32) * np.float32(scale)
    if invalid is not None:
        depth[raw == invalid] = 0.0
    return depth


def to_grey(image: np.ndarray) -> np.ndarray:
    """uint8 grey from a grey or RGB uint8 image (ITU-R BT.601 weights, as OpenCV)."""
    if image.ndim == 2:
        return image
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
