"""Siamese ("siam") feature: the authors' binary weight format, and dense / exact evaluation against an independent
per-patch evaluation of each pixel's 64×64 patch (random weights: the real ones cannot be shipped)."""

from __future__ import annotations

import importlib.util
import struct

import numpy as np
import pytest
from numpy.lib.stride_tricks import sliding_window_view

from dmtrack.errors import InputError
from dmtrack.features import get_feature, weights
from dmtrack.features.siamese import SiameseFeature, dense_siam, exact_siam, local_normalise, siam_patches_forward

BACKENDS = ["numpy", pytest.param("torch", marks=pytest.mark.skipif(
    importlib.util.find_spec("torch") is None, reason="PyTorch not installed"))]
PIXELS = np.array([[0, 0], [3, 44], [17, 23], [39, 47], [25, 5], [39, 0]])


@pytest.fixture(scope="module")
def params() -> dict[str, np.ndarray]:
    """Random weights scaled so that roughly half of the units are active in every layer."""
    rng = np.random.default_rng(0)
    p = {}
    for name, shape in weights.SIAM_SHAPES.items():
        if name.endswith("weight"):
            p[name] = (rng.standard_normal(shape) / np.sqrt(np.prod(shape[1:]))).astype(np.float32)
        else:
            p[name] = (rng.standard_normal(shape) * 0.05).astype(np.float32)
    p["conv0.weight"] *= 20  # inputs are ~0.1 after /255 and mean removal
    return p


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    rng = np.random.default_rng(1)
    base = rng.integers(0, 256, (10, 12)).astype(np.float32)
    img = np.kron(base, np.ones((4, 4))) + rng.normal(0, 8, (40, 48))  # blocky structure plus noise
    return np.clip(img, 0, 255).astype(np.uint8)


def write_bin(path, params, net_type: str = "siam", order=(0, 1, 2)) -> None:
    """The cvpr15deepcompare binary format (loader.cpp): int32 type length, type, then per layer int32 module
    index, int32 #weights, int32 #biases, float32 weights, float32 biases; 'siam' adds two decision layers."""
    with open(path, "wb") as f:
        f.write(struct.pack("<i", len(net_type)) + net_type.encode())
        for i in order:
            idx = (2, 5, 8)[i]
            w, b = params[f"conv{i}.weight"], params[f"conv{i}.bias"]
            f.write(struct.pack("<iii", idx, w.size, b.size) + w.astype("<f4").tobytes() + b.astype("<f4").tobytes())
        if net_type == "siam":
            for idx, (n_out, n_in) in ((2, (512, 512)), (4, (1, 512))):
                f.write(struct.pack("<iii", idx, n_out * n_in, n_out) + np.ones(n_out * n_in + n_out, "<f4").tobytes())


# ---------------------------------------------------------------- independent reference (einsum convolutions)
def _conv(x: np.ndarray, w: np.ndarray, b: np.ndarray, stride: int = 1) -> np.ndarray:
    k = w.shape[2]
    win = sliding_window_view(x, (k, k), axis=(1, 2))[:, ::stride, ::stride]  # (C, H', W', k, k)
    return np.einsum("chwuv,ocuv->ohw", win, w, optimize=True) + b[:, None, None]


def _pool(x: np.ndarray) -> np.ndarray:
    c, h, w = x.shape
    return x[:, : h // 2 * 2, : w // 2 * 2].reshape(c, h // 2, 2, w // 2, 2).max(axis=(2, 4))


def reference_siam(patch: np.ndarray, p: dict[str, np.ndarray]) -> np.ndarray:
    x = patch[None].astype(np.float64)
    x = _pool(np.maximum(_conv(x, p["conv0.weight"], p["conv0.bias"], stride=3), 0))
    x = _pool(np.maximum(_conv(x, p["conv1.weight"], p["conv1.bias"]), 0))
    return np.maximum(_conv(x, p["conv2.weight"], p["conv2.bias"]), 0).reshape(-1)


def patch_of(padded: np.ndarray, y: int, x: int) -> np.ndarray:
    return padded[y : y + 64, x : x + 64]


# ---------------------------------------------------------------------------------------------- loaders
@pytest.mark.parametrize("net_type", ["siam", "siam_desc"])
def test_bin_and_npz_loaders(tmp_path, params, net_type):
    write_bin(tmp_path / "siam_liberty.bin", params, net_type)
    np.savez(tmp_path / "siam_liberty.npz", **params)
    for name in ("siam_liberty.bin", "siam_liberty.npz"):
        got = weights.load_siamese(tmp_path / name)
        assert list(got) == list(weights.SIAM_SHAPES)
        for k, v in params.items():
            np.testing.assert_array_equal(got[k], v)


def test_bin_records_are_assigned_by_layer_not_by_position(tmp_path, params):
    write_bin(tmp_path / "s.bin", params, order=(2, 0, 1))
    got = weights.load_siamese(tmp_path / "s.bin")
    for k, v in params.items():
        np.testing.assert_array_equal(got[k], v)


def test_bin_loader_errors(tmp_path, params):
    write_bin(tmp_path / "2ch.bin", params, "2ch")
    with pytest.raises(InputError, match="'2ch' is not the 'siam' descriptor"):
        weights.load_siamese(tmp_path / "2ch.bin")
    write_bin(tmp_path / "t.bin", params)
    data = (tmp_path / "t.bin").read_bytes()
    (tmp_path / "t.bin").write_bytes(data[:1000])
    with pytest.raises(InputError, match="truncated"):
        weights.load_siamese(tmp_path / "t.bin")
    bad = {**params, "conv1.weight": params["conv1.weight"][:, :, :3, :3]}
    np.savez(tmp_path / "bad.npz", **bad)
    with pytest.raises(InputError, match="'conv1.weight' has shape"):
        weights.load_siamese(tmp_path / "bad.npz")
    (tmp_path / "siam.t7").write_bytes(b"")
    with pytest.raises(InputError, match="expected the authors' .bin or .npz"):
        weights.load_siamese(tmp_path / "siam.t7")


# ---------------------------------------------------------------------------------------------- outputs
@pytest.mark.parametrize("backend", BACKENDS)
def test_dense_local_equals_per_patch_evaluation(image, params, backend):
    x = local_normalise(image)
    assert x.shape == (40 + 63, 48 + 63)
    dense = dense_siam(x, params, backend=backend)
    assert dense.shape == (40, 48, 256)
    ref = np.stack([reference_siam(patch_of(x, y, c), params) for y, c in PIXELS])
    got = dense[PIXELS[:, 0], PIXELS[:, 1]]
    np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-5 * np.abs(ref).max())
    assert 0.1 < (ref > 0).mean() < 0.9


def test_local_normalisation_is_the_window_mean():
    img = np.random.default_rng(3).integers(0, 256, (20, 26)).astype(np.uint8)
    x = local_normalise(img)
    padded = np.pad(img.astype(np.float64), ((32, 31), (32, 31)), mode="reflect")  # numpy 'reflect' = REFLECT_101
    twice = np.pad(padded, ((32, 31), (32, 31)), mode="reflect")
    for y, c in [(0, 0), (32, 32), (40, 50), (82, 88)]:
        window = twice[y : y + 64, c : c + 64]
        assert x[y, c] == pytest.approx((padded[y, c] - window.mean()) / 255, abs=1e-5)


@pytest.mark.parametrize("backend", BACKENDS)
def test_exact_patch_mode_equals_per_patch_with_patch_mean(image, params, backend):
    padded = np.pad(image.astype(np.float64), ((32, 31), (32, 31)), mode="reflect") / 255
    ref = []
    for y, c in PIXELS:
        patch = patch_of(padded, y, c)
        ref.append(reference_siam(patch - patch.mean(), params))
    ref = np.stack(ref)
    got = exact_siam(image, params, pixels=PIXELS, backend=backend)
    np.testing.assert_allclose(got, ref, rtol=1e-4, atol=1e-5 * np.abs(ref).max())


def test_patch_forward_matches_reference(params):
    rng = np.random.default_rng(4)
    patches = rng.normal(0, 0.1, (3, 64, 64)).astype(np.float32)
    got = siam_patches_forward(patches, params, backend="numpy")
    np.testing.assert_allclose(got, np.stack([reference_siam(p, params) for p in patches]), rtol=1e-4, atol=1e-5)
    with pytest.raises(InputError):
        siam_patches_forward(patches[:, :32], params)


@pytest.mark.skipif(importlib.util.find_spec("torch") is None, reason="PyTorch not installed")
def test_backends_agree(image, params):
    x = local_normalise(image)
    ref = dense_siam(x, params, backend="numpy")
    np.testing.assert_allclose(dense_siam(x, params, backend="torch"), ref, rtol=1e-4, atol=1e-5 * np.abs(ref).max())


def test_feature_through_registry(tmp_path, image, params, monkeypatch):
    write_bin(tmp_path / "siam_liberty.bin", params)
    monkeypatch.setenv(weights.WEIGHTS_ENV, str(tmp_path))
    f = get_feature("siamese", backend="numpy")
    assert isinstance(f, SiameseFeature)
    assert (f.channels, f.needs_colour, f.scale) == (256, False, pytest.approx(347.5))
    out = f.compute(image)
    assert out.shape == (40, 48, 256) and out.dtype == np.float32 and out.flags.c_contiguous
    np.testing.assert_allclose(out, 347.5 * dense_siam(local_normalise(image), params, backend="numpy"), rtol=1e-5)
    rgb = np.repeat(image[:, :, None], 3, axis=2)
    np.testing.assert_array_equal(f.compute(rgb), out)
    with pytest.raises(InputError, match="normalise must be one of"):
        get_feature("siamese", normalise="global")


def test_exact_mode_through_the_feature(tmp_path, params):
    write_bin(tmp_path / "s.bin", params)
    img = np.random.default_rng(5).integers(0, 256, (6, 7), dtype=np.uint8)
    out = SiameseFeature(scale=2.0, weights=tmp_path / "s.bin", normalise="patch", backend="numpy").compute(img)
    assert out.shape == (6, 7, 256)
    pix = np.array([[0, 0], [5, 6], [2, 3]])
    ref = 2.0 * exact_siam(img, params, pixels=pix, backend="numpy")
    np.testing.assert_allclose(out[pix[:, 0], pix[:, 1]], ref, rtol=1e-4, atol=1e-5 * np.abs(ref).max())


def test_missing_weights_error(tmp_path, monkeypatch):
    monkeypatch.delenv(weights.WEIGHTS_ENV, raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    with pytest.raises(InputError) as exc:
        get_feature("siamese")
    msg = str(exc.value)
    assert "cvpr2015matching_networks.tar.gz" in msg and "siam_liberty.bin" in msg and "$DMTRACK_WEIGHTS" in msg
