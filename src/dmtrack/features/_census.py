"""The numba kernel of :func:`dmtrack.features.bitplanes.census_planes`, in a module of its own so that building the
feature (which ``dmtrack run`` does before its run begins) does not import numba: the run imports it beside its
geometric start."""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["census_planes_kernel"]


@numba.njit(cache=True, nogil=True)
def census_planes_kernel(img: np.ndarray, value: np.float32, out: np.ndarray) -> None:  # pragma: no cover
    """Every pixel of ``out`` (h, w, 8): ``value`` where bit b of
    :func:`~dmtrack.features.bitplanes.census_bits` is set, else 0."""
    h, w = img.shape
    zero = np.float32(0.0)
    for y in range(h):
        for x in range(w):
            if y == 0 or y == h - 1 or x == 0 or x == w - 1:
                for b in range(8):
                    out[y, x, b] = zero
                continue
            c = img[y, x]
            out[y, x, 0] = value if img[y - 1, x - 1] >= c else zero
            out[y, x, 1] = value if img[y - 1, x] >= c else zero
            out[y, x, 2] = value if img[y - 1, x + 1] >= c else zero
            out[y, x, 3] = value if img[y, x - 1] >= c else zero
            out[y, x, 4] = value if img[y, x + 1] >= c else zero
            out[y, x, 5] = value if img[y + 1, x - 1] >= c else zero
            out[y, x, 6] = value if img[y + 1, x] >= c else zero
            out[y, x, 7] = value if img[y + 1, x + 1] >= c else zero
