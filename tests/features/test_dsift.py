"""Dense SIFT against a straightforward per-pixel reference implementation."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from dmtrack.features import get_feature


def _weight(t: np.ndarray, c: float, spatial: str) -> np.ndarray:
    t = np.abs(t)
    if spatial == "bilinear":
        return np.maximum(0.0, 1.0 - t / c)
    return np.maximum(0.0, np.minimum(t + 0.5, c / 2) - np.maximum(t - 0.5, -c / 2))  # box cell of width c


def dsift_reference(img: np.ndarray, cs: int = 3, alpha: float = 9.0, spatial: str = "box",
                    clamp: float | None = None, eps: float = 0.01) -> np.ndarray:
    """Per pixel: loop over the 4×4 cells and the pixels around each cell centre; 255 × normalised histogram."""
    I = img.astype(np.float64)
    H, W = I.shape
    gx = np.zeros_like(I)
    gy = np.zeros_like(I)
    gx[1:-1, 1:-1] = 0.5 * (I[1:-1, 2:] - I[1:-1, :-2])
    gy[1:-1, 1:-1] = 0.5 * (I[2:, 1:-1] - I[:-2, 1:-1])
    mag = np.hypot(gx, gy)
    theta = np.arctan2(gy, gx)
    energy = np.stack([mag * np.maximum(np.cos(theta - 2 * math.pi * k / 8), 0.0) ** alpha for k in range(8)], -1)
    reach = cs + 1
    out = np.zeros((H, W, 128))
    for y in range(H):
        for x in range(W):
            hist = np.zeros((4, 4, 8))
            for i in range(4):
                cy = y + (i - 1.5) * cs
                v0, v1 = max(0, math.floor(cy - reach)), min(H, math.ceil(cy + reach) + 1)
                for j in range(4):
                    cx = x + (j - 1.5) * cs
                    u0, u1 = max(0, math.floor(cx - reach)), min(W, math.ceil(cx + reach) + 1)
                    if v0 >= v1 or u0 >= u1:
                        continue
                    wy = _weight(np.arange(v0, v1) - cy, cs, spatial)
                    wx = _weight(np.arange(u0, u1) - cx, cs, spatial)
                    hist[i, j] = np.einsum("v,u,vuk->k", wy, wx, energy[v0:v1, u0:u1])
            h = hist.ravel()
            d = h / (np.linalg.norm(h) + eps)
            if clamp is not None:
                d = np.minimum(d, clamp)
                n = np.linalg.norm(d)
                d = d / n if n > 0 else d
            out[y, x] = 255.0 * d
    return out


def _textured(h: int, w: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return cv2.GaussianBlur(rng.integers(0, 256, (h, w), dtype=np.uint8), (5, 5), 1.0)


def test_default_matches_reference_40x30() -> None:
    img = _textured(30, 40, seed=0)
    f = get_feature("dsift", scale=1.0)
    out = f.compute(img)
    assert out.shape == (30, 40, 128) and out.dtype == np.float32 and out.flags.c_contiguous
    ref = dsift_reference(img)
    np.testing.assert_allclose(out, ref, rtol=0, atol=2e-3 * np.abs(ref).max())


@pytest.mark.parametrize(
    ("cs", "spatial", "clamp"),
    [(3, "bilinear", 0.2), (4, "box", 0.2), (2, "bilinear", None), (4, "bilinear", None)],
)
def test_options_match_reference(cs: int, spatial: str, clamp: float | None) -> None:
    img = _textured(18, 22, seed=cs)
    out = get_feature("dsift", scale=1.0, cell_size=cs, spatial=spatial, clamp=clamp).compute(img)
    ref = dsift_reference(img, cs=cs, spatial=spatial, clamp=clamp)
    np.testing.assert_allclose(out, ref, rtol=0, atol=2e-3 * np.abs(ref).max())


def test_descriptor_norms() -> None:
    img = _textured(40, 48, seed=5)
    h = get_feature("dsift", scale=1.0).compute(img)
    norms = np.linalg.norm(h.astype(np.float64), axis=2)
    assert (h >= 0).all()
    assert norms.max() <= 255.0 + 1e-3
    assert np.median(norms) > 254.0  # ‖h‖/(‖h‖+0.01)·255 with ‖h‖ ≫ 0.01 on texture
    hc = get_feature("dsift", scale=1.0, clamp=0.2).compute(img)
    np.testing.assert_allclose(np.linalg.norm(hc.astype(np.float64), axis=2), 255.0, rtol=1e-5)
    # scaled output
    s = get_feature("dsift", scale=0.5).compute(img)
    np.testing.assert_allclose(s, 0.5 * h, rtol=1e-6, atol=1e-5)


def test_flat_image_gives_zero_descriptors() -> None:
    out = get_feature("dsift").compute(np.full((20, 20), 100, np.uint8))
    assert not out.any()


def test_vertical_edge_fills_orientation_bin_zero() -> None:
    img = np.zeros((24, 24), np.uint8)
    img[:, 12:] = 200  # intensity increases along +x → gradient direction θ = 0
    d = get_feature("dsift", scale=1.0).compute(img)[12, 12].reshape(4, 4, 8)
    per_bin = d.sum(axis=(0, 1))
    assert per_bin.argmax() == 0
    # soft binning: neighbouring bins at ±45° get cos(45°)^9 of bin 0, the others nothing
    np.testing.assert_allclose(per_bin[[1, 7]] / per_bin[0], math.cos(math.pi / 4) ** 9, rtol=1e-4)
    assert not per_bin[2:7].any()
    # the edge lies between columns 11 and 12: only the two middle cell columns see it
    per_col = d.sum(axis=(0, 2))
    assert per_col[0] == 0 and per_col[3] == 0 and per_col[1] > 0 and per_col[2] > 0


def test_brightness_offset_invariance() -> None:
    img = _textured(20, 26, seed=9)
    low = np.clip(img.astype(np.int32), 0, 200).astype(np.uint8)
    f = get_feature("dsift")
    np.testing.assert_array_equal(f.compute(low), f.compute((low + 40).astype(np.uint8)))


@pytest.mark.parametrize("clamp", [None, 0.2])
def test_result_does_not_depend_on_thread_count(clamp: float | None) -> None:
    img = _textured(70, 53, seed=11).astype(np.float32)
    f = get_feature("dsift", clamp=clamp)
    one = f.compute_threads(img, f.scale, threads=1)
    for n in (2, 3):
        np.testing.assert_array_equal(f.compute_threads(img, f.scale, threads=n), one)
    np.testing.assert_array_equal(f.compute(img), one)


def test_cell_histograms_are_not_overwritten_by_the_next_call() -> None:
    f = get_feature("dsift")
    a = f.cell_histograms(_textured(30, 40, seed=12))
    a_copy = a.copy()
    f.cell_histograms(_textured(30, 40, seed=13))
    np.testing.assert_array_equal(a, a_copy)


def test_feature_threads_environment_variable(monkeypatch: pytest.MonkeyPatch) -> None:
    from dmtrack.errors import InputError
    from dmtrack.features import _nn

    img = _textured(40, 37, seed=14)
    f = get_feature("dsift")
    ref = f.compute_threads(img, f.scale, threads=1)
    monkeypatch.setenv(_nn.THREADS_ENV, "3")
    assert _nn.default_threads() == 3
    np.testing.assert_array_equal(f.compute(img), ref)
    monkeypatch.setenv(_nn.THREADS_ENV, "many")
    with pytest.raises(InputError, match="DMTRACK_FEATURE_THREADS"):
        f.compute(img)
