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
    f = get_feature("rgb", scale=1.0, chroma_sigma=0)  # the plain channels (the default low-passes the chroma)
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


# ------------------------------------------------------------------ chroma smoothing (option chroma_sigma)
def _colour_step(h: int = 24, w: int = 32) -> np.ndarray:
    """Left half reddish, right half bluish, equal luma, plus a luma ramp: a pure chroma edge at x = w/2."""
    img = np.zeros((h, w, 3), np.uint8)
    img[:, : w // 2] = (180, 90, 60)
    img[:, w // 2 :] = (60, 114, 239)  # luma 0.299·60 + 0.587·114 + 0.114·239 ≈ that of the left half
    img[..., :] = np.clip(img.astype(int) + np.arange(h)[:, None, None], 0, 255).astype(np.uint8)
    return img


def test_chroma_sigma_default_and_zero() -> None:
    from dmtrack.features.colour import CHROMA_SIGMA

    img = np.random.default_rng(5).integers(0, 256, (20, 24, 3), dtype=np.uint8)
    assert CHROMA_SIGMA == 2.0
    for name in ("rgb", "lab"):
        assert get_feature(name).chroma_sigma == CHROMA_SIGMA
        default = get_feature(name, scale=1.3).compute(img)
        np.testing.assert_array_equal(get_feature(name, scale=1.3, chroma_sigma=2.0).compute(img), default)
        plain = get_feature(name, scale=1.3, chroma_sigma=0).compute(img)
        assert not np.array_equal(plain, default)
    plain_rgb = get_feature("rgb", scale=1.3, chroma_sigma=0).compute(img)
    np.testing.assert_allclose(plain_rgb, 1.3 * img.astype(np.float32), rtol=1e-6)


def test_rgb_chroma_smoothing_keeps_luma_and_blurs_the_colour_differences() -> None:
    import cv2

    img = _colour_step()
    out = get_feature("rgb", scale=1.0, chroma_sigma=2.0).compute(img).astype(np.float64)
    f = img.astype(np.float64)
    luma = f @ np.array([0.299, 0.587, 0.114])
    np.testing.assert_allclose(out @ np.array([0.299, 0.587, 0.114]), luma, atol=1e-3)  # grey image unchanged
    cr = cv2.GaussianBlur((f[..., 0] - luma).astype(np.float32), (0, 0), 2.0, borderType=cv2.BORDER_REFLECT_101)
    np.testing.assert_allclose(out[..., 0] - luma, cr, atol=1e-3)
    # the chroma step is spread: its largest x-difference drops, and far from it the colours are kept
    step = np.abs(np.diff(f[..., 0], axis=1)).max()
    assert np.abs(np.diff(out[..., 0], axis=1)).max() < 0.4 * step
    np.testing.assert_allclose(out[:, :3], f[:, :3], atol=1.0)
    # a grey input has no chroma: returned exactly
    grey = np.repeat(np.random.default_rng(6).integers(0, 256, (16, 16, 1), dtype=np.uint8), 3, axis=2)
    np.testing.assert_array_equal(get_feature("rgb", scale=1.0, chroma_sigma=3.0).compute(grey), grey)
    grey_f = grey.astype(np.float32)  # a float input is not modified in place
    np.testing.assert_array_equal(get_feature("rgb", scale=2.0).compute(grey_f), 2 * grey.astype(np.float32))
    np.testing.assert_array_equal(grey_f, grey)


def test_lab_chroma_smoothing_blurs_a_and_b_only() -> None:
    import cv2

    img = _colour_step()
    plain = get_feature("lab", scale=2.0, chroma_sigma=0).compute(img)
    out = get_feature("lab", scale=2.0, chroma_sigma=1.5).compute(img)
    np.testing.assert_array_equal(out[..., 0], plain[..., 0])  # L* untouched
    for c in (1, 2):
        ref = cv2.GaussianBlur(np.ascontiguousarray(plain[..., c]), (0, 0), 1.5, borderType=cv2.BORDER_REFLECT_101)
        np.testing.assert_allclose(out[..., c], ref, rtol=1e-5, atol=1e-3)
    assert np.abs(np.diff(out[..., 1], axis=1)).max() < 0.5 * np.abs(np.diff(plain[..., 1], axis=1)).max()


@pytest.mark.parametrize("bad", [-1.0, float("nan"), float("inf"), "wide"])
def test_bad_chroma_sigma_is_an_input_error(bad) -> None:
    from dmtrack.errors import InputError

    for name in ("rgb", "lab"):
        with pytest.raises(InputError, match="chroma_sigma"):
            get_feature(name, chroma_sigma=bad)
