"""The shared dense patch-descriptor plumbing on a toy network (what a new trained patch feature would write):
dense and exact evaluation against per-patch evaluation of each pixel's patch, both backends."""

from __future__ import annotations

import importlib.util
from typing import Any

import numpy as np
import pytest

from dmtrack.errors import InputError
from dmtrack.features import _nn
from dmtrack.features._dense_patch import PatchNet, Stem, reflect_pad, select_pixels

BACKENDS = ["numpy", pytest.param("torch", marks=pytest.mark.skipif(
    importlib.util.find_spec("torch") is None, reason="PyTorch not installed"))]


class ToyNet(PatchNet):
    """8×8 patch → conv 4×3×3 → ReLU → conv 5×6×6 → 5-D (no stride, so shift-and-stitch needs no dilation)."""

    label = "toy"
    patch = 8
    dim = 5
    exact_grid = (1, 6)
    exact_batch = 7
    exact_chunk = 3

    def patch_torch(self, torch: Any, t: Any, p: dict[str, Any]) -> Any:
        f = torch.nn.functional
        return f.conv2d(f.relu(f.conv2d(t, p["w1"], p["b1"])), p["w2"], p["b2"])

    def patch_numpy(self, patch: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        x = np.maximum(_nn.conv2d_hwc(patch[:, :, None], params["w1"], params["b1"]), 0)
        return _nn.conv2d_hwc(x, params["w2"], params["b2"]).reshape(-1)

    def normalise_windows(self, p: np.ndarray, mean: np.ndarray, std: np.ndarray) -> np.ndarray:
        return (p - mean) / 64.0

    def dense_torch(self, torch: Any, t: Any, p: dict[str, Any], params: dict[str, np.ndarray]) -> Any:
        return self.patch_torch(torch, t, p)

    def dense_numpy(self, x: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        return self.patch_numpy(x, params).reshape(x.shape[0] - 7, x.shape[1] - 7, 5).copy()

    def exact_stem(self, gray: np.ndarray, params: dict[str, np.ndarray]) -> Stem:
        p = reflect_pad(gray, self.patch)
        mean, _ = _nn.box_mean_std(p, self.patch)
        raw = _nn.conv2d_hwc(p[:, :, None], params["w1"], None)
        wsum = params["w1"].reshape(4, -1).sum(axis=1)

        def first(g: np.ndarray, pb: np.ndarray) -> np.ndarray:
            m = mean[pb[:, 0], pb[:, 1]][:, None, None, None]
            return np.maximum((g - m * wsum) / 64.0 + params["b1"], 0).astype(np.float32)

        return raw, first

    def tail_torch(self, torch: Any, t: Any, p: dict[str, Any]) -> Any:
        return torch.nn.functional.conv2d(t, p["w2"], p["b2"])

    def tail_numpy(self, g: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        return _nn.conv2d_batch_hwc(g, params["w2"], params["b2"]).reshape(len(g), -1)


NET = ToyNet()


@pytest.fixture(scope="module")
def params() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    shapes = {"w1": (4, 1, 3, 3), "b1": (4,), "w2": (5, 4, 6, 6), "b2": (5,)}
    return {k: rng.standard_normal(s).astype(np.float32) for k, s in shapes.items()}


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    return np.random.default_rng(1).integers(0, 256, (9, 11)).astype(np.uint8)


def patches_of(padded: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    return np.stack([padded[y : y + 8, x : x + 8] for y, x in pixels]).astype(np.float32)


@pytest.mark.parametrize("backend", BACKENDS)
def test_dense_is_the_per_patch_net_of_the_local_input(image, params, backend):
    x = NET.local_normalise(image)
    assert x.shape == (9 + 7, 11 + 7) and x.dtype == np.float32
    pix = select_pixels(None, 9, 11)
    ref = NET.forward_patches(patches_of(x, pix), params, backend="numpy").reshape(9, 11, 5)
    np.testing.assert_allclose(NET.dense(x, params, backend=backend), ref, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(NET.dense(x, params, gain=2.5, backend=backend), 2.5 * ref, rtol=1e-5, atol=1e-4)


@pytest.mark.parametrize("backend", BACKENDS)
def test_exact_normalises_each_patch_by_its_own_mean(image, params, backend):
    padded = reflect_pad(image, 8)
    pix = np.array([[0, 0], [8, 10], [4, 5], [0, 10], [8, 0]])
    patches = patches_of(padded, pix)
    ref = NET.forward_patches((patches - patches.mean(axis=(1, 2), keepdims=True)) / 64.0, params, backend=backend)
    got = NET.exact(image, params, pixels=pix, gain=3.0, backend=backend)
    np.testing.assert_allclose(got, 3.0 * ref, rtol=1e-4, atol=1e-3)
    full = NET.exact(image, params, backend=backend, batch=4)  # batches and numpy chunks that do not divide 99
    assert full.shape == (9, 11, 5)
    np.testing.assert_allclose(full[pix[:, 0], pix[:, 1]], ref, rtol=1e-4, atol=1e-3)


def test_argument_errors(image, params):
    with pytest.raises(InputError, match=r"toy patches must be \(B, 8, 8\)"):
        NET.forward_patches(np.zeros((2, 7, 8)), params)
    with pytest.raises(InputError, match="pixels must lie inside the 9x11 image"):
        NET.exact(image, params, pixels=[[9, 0]])
