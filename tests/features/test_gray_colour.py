"""gray, gray-affine, rgb and lab features against their definitions."""

from __future__ import annotations

import numpy as np
import pytest

from dmtrack.features import get_feature


def _lab_reference(rgb: np.ndarray) -> np.ndarray:
    """CIE L*a*b* (D65) of sRGB values 0..255 from the textbook formulas, (..., 3) float64."""
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    m = np.array([[0.412453, 0.357580, 0.180423], [0.212671, 0.715160, 0.072169], [0.019334, 0.119193, 0.950227]])
    xyz = lin @ m.T
    xyz = xyz / np.array([0.950456, 1.0, 1.088754])
    eps = (6 / 29) ** 3
    f = np.where(xyz > eps, np.cbrt(xyz), xyz / (3 * (6 / 29) ** 2) + 4 / 29)
    L = 116 * f[..., 1] - 16
    a = 500 * (f[..., 0] - f[..., 1])
    b = 200 * (f[..., 1] - f[..., 2])
    return np.stack([L, a, b], axis=-1)


def test_gray_is_the_intensity_exactly() -> None:
    img = np.arange(256, dtype=np.uint8).reshape(16, 16)
    out = get_feature("gray").compute(img)
    assert out.shape == (16, 16, 1) and out.dtype == np.float32
    np.testing.assert_array_equal(out[:, :, 0], img.astype(np.float32))
    assert get_feature("gray").scale == 1.0
    np.testing.assert_array_equal(get_feature("gray", scale=0.5).compute(img)[:, :, 0], img * np.float32(0.5))


def test_gray_accepts_float_input() -> None:
    img = np.linspace(0, 255, 12, dtype=np.float64).reshape(3, 4)
    np.testing.assert_allclose(get_feature("gray").compute(img)[:, :, 0], img, rtol=1e-6)


def test_rgb_channels() -> None:
    rng = np.random.default_rng(1)
    img = rng.integers(0, 256, size=(10, 12, 3), dtype=np.uint8)
    f = get_feature("rgb", scale=1.0)
    out = f.compute(img)
    assert out.shape == (10, 12, 3) and out.dtype == np.float32
    np.testing.assert_array_equal(out, img.astype(np.float32))


KNOWN = {
    "white": (255, 255, 255),
    "black": (0, 0, 0),
    "red": (255, 0, 0),
    "green": (0, 255, 0),
    "blue": (0, 0, 255),
    "grey128": (128, 128, 128),
    "orange": (255, 128, 0),
}


@pytest.mark.parametrize("colour", list(KNOWN))
def test_lab_known_colours(colour: str) -> None:
    rgb = np.array(KNOWN[colour], dtype=np.uint8).reshape(1, 1, 3)
    out = get_feature("lab", scale=1.0).compute(rgb)[0, 0].astype(np.float64)
    L, a, b = _lab_reference(rgb)[0, 0]
    # channel mapping: 2.55 L*, a* + 128, b* + 128 (OpenCV's 8-bit ranges, float)
    np.testing.assert_allclose(out, [2.55 * L, a + 128, b + 128], atol=0.15)


def test_lab_textbook_values_and_ranges() -> None:
    lab = get_feature("lab", scale=1.0)
    white = lab.compute(np.full((1, 1, 3), 255, np.uint8))[0, 0]
    np.testing.assert_allclose(white, [255, 128, 128], atol=0.05)
    red = lab.compute(np.array([[[255, 0, 0]]], np.uint8))[0, 0]
    np.testing.assert_allclose(red, [53.24 * 2.55, 80.09 + 128, 67.20 + 128], atol=0.1)
    # grey input → a* = b* = 128
    grey = lab.compute(np.full((2, 2), 77, np.uint8))
    np.testing.assert_allclose(grey[..., 1:], 128, atol=0.05)
    rng = np.random.default_rng(2)
    out = lab.compute(rng.integers(0, 256, (32, 32, 3), dtype=np.uint8))
    assert out.min() >= -1 and out.max() <= 256


def test_lab_scale_multiplies_all_channels() -> None:
    rng = np.random.default_rng(4)
    img = rng.integers(0, 256, (8, 8, 3), dtype=np.uint8)
    a = get_feature("lab", scale=1.0).compute(img)
    b = get_feature("lab", scale=2.5).compute(img)
    np.testing.assert_allclose(b, 2.5 * a, rtol=1e-6)
