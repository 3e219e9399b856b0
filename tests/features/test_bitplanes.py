"""Bit-Planes (lsd-slam-spec.md §5) against a direct per-pixel census."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from dmtrack.features import get_feature
from dmtrack.features.bitplanes import census_code

# neighbour order of the spec: top-left, top, top-right, left, right, bottom-left, bottom, bottom-right
ORDER = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def _census_reference(img: np.ndarray) -> np.ndarray:
    h, w = img.shape
    out = np.zeros((h, w, 8), np.float64)
    for y in range(1, h - 1):
        for x in range(1, w - 1):
            c = img[y, x]
            for b, (dy, dx) in enumerate(ORDER):
                out[y, x, b] = 1.0 if img[y + dy, x + dx] >= c else 0.0
    return out


def _noise(h: int, w: int, seed: int, levels: int = 256) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(0, levels, size=(h, w), dtype=np.uint8)


@pytest.mark.parametrize("levels", [256, 4])  # 4 levels → many ties (≥ counts equal neighbours as 1)
def test_matches_per_pixel_census(levels: int) -> None:
    img = _noise(9, 11, seed=levels, levels=levels)
    f = get_feature("bitplanes", sigma0=0.0, sigma1=0.0, scale=7.5)
    out = f.compute(img)
    assert out.shape == (9, 11, 8) and out.dtype == np.float32
    np.testing.assert_array_equal(out, _census_reference(img) * 7.5)
    # one-pixel border is zero
    assert not out[0].any() and not out[-1].any() and not out[:, 0].any() and not out[:, -1].any()


def test_bit_order_on_a_hand_made_patch() -> None:
    # centre 50; neighbours ≥ 50 at top-left (b0), right (b4), bottom (b6) and bottom-right (b7, equal)
    patch = np.array([[60, 10, 20], [30, 50, 90], [40, 70, 50]], dtype=np.uint8)
    out = get_feature("bitplanes", sigma0=0.0, scale=1.0).compute(patch)
    np.testing.assert_array_equal(out[1, 1], [1, 0, 0, 0, 1, 0, 1, 1])
    assert census_code(patch)[1, 1] == 1 + 16 + 64 + 128


def test_presmoothing_is_a_3x3_gaussian_of_the_8bit_image() -> None:
    img = _noise(20, 24, seed=7)
    f = get_feature("bitplanes", sigma0=0.8, scale=1.0)
    blurred = cv2.GaussianBlur(img, (3, 3), 0.8, sigmaY=0.8)
    assert blurred.dtype == np.uint8
    np.testing.assert_array_equal(f.compute(img), _census_reference(blurred))


def test_bitplane_smoothing_is_a_5x5_gaussian_per_channel() -> None:
    img = _noise(20, 24, seed=8)
    f = get_feature("bitplanes", sigma0=0.0, sigma1=1.2, scale=2.0)
    bits = _census_reference(img).astype(np.float32) * 2.0
    expected = np.stack([cv2.GaussianBlur(bits[:, :, b], (5, 5), 1.2, sigmaY=1.2) for b in range(8)], axis=2)
    np.testing.assert_allclose(f.compute(img), expected, rtol=1e-6, atol=1e-6)


def test_invariant_to_monotonic_intensity_changes() -> None:
    rng = np.random.default_rng(9)
    img = cv2.GaussianBlur(rng.integers(0, 121, (40, 50), dtype=np.uint8), (5, 5), 1.0)
    f = get_feature("bitplanes", sigma0=0.0, sigma1=0.0)
    ref = f.compute(img)
    assert ref.any()
    # affine with positive gain, exact in uint8 (values ≤ 120 → ≤ 250)
    affine = (2 * img.astype(np.int32) + 10).astype(np.uint8)
    np.testing.assert_array_equal(f.compute(affine), ref)
    # gamma (strictly increasing) in float
    gamma = 255.0 * (img.astype(np.float64) / 255.0) ** 0.45
    np.testing.assert_array_equal(f.compute(gamma.astype(np.float32)), ref)
    # … but not to a decreasing map: the test can fail
    assert not np.array_equal(f.compute((255 - img).astype(np.uint8)), ref)


def test_default_options_and_scale() -> None:
    f = get_feature("bitplanes")
    assert f.channels == 8 and f.pyramid == "recompute"
    assert f.sigma0 == 0.5 and f.sigma1 == 0.0
    out = f.compute(_noise(16, 16, seed=1))
    assert set(np.unique(out).tolist()) <= {0.0, float(np.float32(f.scale))}


def test_colour_input_uses_grey() -> None:
    rng = np.random.default_rng(3)
    rgb = rng.integers(0, 256, (12, 14, 3), dtype=np.uint8)
    f = get_feature("bitplanes", sigma0=0.0, scale=1.0)
    np.testing.assert_array_equal(f.compute(rgb), _census_reference(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)))


@pytest.mark.parametrize("dtype", [np.uint8, np.float32, np.float64, np.int16])
def test_census_planes_kernel_gives_the_bytes_of_census_bits(dtype) -> None:
    """The one-pass numba kernel the feature uses has the bytes of ``census_bits × scale`` (float32), ties included."""
    from dmtrack.features.bitplanes import census_bits, census_planes

    rng = np.random.default_rng(3)
    img = rng.integers(0, 6, (37, 52)).astype(dtype)  # few levels: many ties (≥ counts them as set)
    if dtype == np.float32:
        img = img + rng.random((37, 52)).astype(np.float32) * np.float32(0.5)
    for value in (1.0, 9.77, 0.3):
        expected = census_bits(img).astype(np.float32) * np.float32(value)
        got = census_planes(img, value)
        assert got.dtype == np.float32 and got.shape == (37, 52, 8)
        assert got.tobytes() == expected.tobytes()
