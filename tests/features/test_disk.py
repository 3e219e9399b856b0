"""DISK feature (shipped weights, needs PyTorch): shape, determinism, padding/cropping, and kornia's DISK."""

from __future__ import annotations

import numpy as np
import pytest

from dmtrack.errors import InputError
from dmtrack.features import get_feature, list_features, weights

torch = pytest.importorskip("torch", reason="the DISK feature needs PyTorch (pip install 'dmtrack[learned]')")

from dmtrack.features.disk import DiskFeature, disk_unet  # noqa: E402


@pytest.fixture(scope="module")
def feature() -> DiskFeature:
    return DiskFeature(scale=1.0)


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    rng = np.random.default_rng(0)
    base = rng.integers(0, 256, (5, 6, 3)).astype(np.uint8)
    return np.kron(base, np.ones((8, 8, 1), np.uint8))  # 40 x 48: not multiples of 16 in height


def test_shape_dtype_determinism(feature, image):
    out = feature.compute(image)
    assert out.shape == (40, 48, 128) and out.dtype == np.float32 and out.flags.c_contiguous
    assert np.isfinite(out).all() and out.std() > 0.1
    np.testing.assert_array_equal(out, feature.compute(image))


def test_padding_is_cropped_back(feature, image):
    """On a multiple-of-16 image the feature is the U-Net output itself (first 128 channels, RGB/255)."""
    img = np.ascontiguousarray(image[:32])
    out = feature.compute(img)
    x = torch.from_numpy(img.astype(np.float32) / 255).permute(2, 0, 1)[None]
    with torch.no_grad():
        ref = disk_unet(x, feature._params)[0, :128].permute(1, 2, 0).numpy()
    np.testing.assert_allclose(out, ref, atol=1e-4 * np.abs(ref).max())
    # the padded 40-row image agrees with the U-Net on its zero-padded 48-row version, cropped
    x = torch.nn.functional.pad(torch.from_numpy(image.astype(np.float32) / 255).permute(2, 0, 1)[None], (0, 0, 0, 8))
    with torch.no_grad():
        ref = disk_unet(x, feature._params)[0, :128, :40].permute(1, 2, 0).numpy()
    np.testing.assert_allclose(feature.compute(image), ref, atol=1e-4 * np.abs(ref).max())


def test_matches_kornia(feature, image):
    kornia = pytest.importorskip("kornia", reason="cross-check with kornia.feature.DISK needs kornia")
    net = kornia.feature.DISK()
    sd = torch.load(weights.package_weights_dir() / "disk-depth-save.pth", map_location="cpu", weights_only=True)
    net.load_state_dict(sd["extractor"])
    net.eval()
    x = torch.from_numpy(image.astype(np.float32) / 255).permute(2, 0, 1)[None]
    x = torch.nn.functional.pad(x, (0, 0, 0, 8))
    with torch.no_grad():
        _, desc = net.heatmap_and_dense_descriptors(x)
    ref = desc[0, :, :40].permute(1, 2, 0).numpy()
    np.testing.assert_allclose(feature.compute(image), ref, atol=1e-4 * np.abs(ref).max())


def test_grey_input_and_registry(image):
    entry = next(e for e in list_features() if e["name"] == "disk")
    assert entry["needs_torch"] and entry["needs_colour"] and entry["channels"] == 128
    f = get_feature("disk", scale=2.0)
    grey = image[:, :, 0]
    ref = DiskFeature(scale=1.0).compute(np.repeat(grey[:, :, None], 3, 2))
    np.testing.assert_allclose(f.compute(grey), 2.0 * ref, rtol=1e-6, atol=1e-6)


def test_wrong_checkpoint(tmp_path):
    sd = weights.load_disk()
    sd.pop("unet.path_up.3.conv.3.weight")
    torch.save({"extractor": {k: torch.from_numpy(v) for k, v in sd.items()}}, tmp_path / "d.pth")
    with pytest.raises(InputError, match="path_up.3.conv.3.weight"):
        DiskFeature(weights=tmp_path / "d.pth")
