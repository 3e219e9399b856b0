"""Feature registry and the Feature interface (dmtrack.features.base)."""

from __future__ import annotations

import sys
import textwrap

import numpy as np
import pytest

from dmtrack.errors import InputError
from dmtrack.features import base
from dmtrack.features.base import (
    Feature,
    default_scale,
    get_feature,
    list_features,
    prepare_image,
    register,
    unregister,
)

BUILTIN = {"gray": 1, "gray-affine": 1, "rgb": 3, "lab": 3, "bitplanes": 8, "dsift": 128}


def _image(h: int = 32, w: int = 48, colour: bool = True, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    shape = (h, w, 3) if colour else (h, w)
    return rng.integers(0, 256, size=shape, dtype=np.uint8)


def test_list_features_describes_builtins() -> None:
    listed = {d["name"]: d for d in list_features()}
    for name, n in BUILTIN.items():
        d = listed[name]
        assert d["channels"] == n
        assert set(d) >= {"name", "channels", "needs_torch", "needs_weights", "pyramid", "scale", "description"}
        assert d["needs_torch"] is False and d["needs_weights"] is False
        assert d["description"]
    assert listed["bitplanes"]["pyramid"] == "recompute"
    assert listed["gray"]["pyramid"] == "downsample"
    assert listed["rgb"]["needs_colour"] and listed["lab"]["needs_colour"] and not listed["gray"]["needs_colour"]
    # the listed scale is the packaged default scale
    assert listed["gray"]["scale"] == 1.0
    assert listed["bitplanes"]["scale"] == default_scale("bitplanes") != 1.0
    assert listed["dsift"]["scale"] == default_scale("dsift") != 1.0


def test_unknown_name_error_lists_known_names() -> None:
    with pytest.raises(InputError) as exc:
        get_feature("siftx")
    msg = str(exc.value)
    assert "'siftx'" in msg
    for name in BUILTIN:
        assert name in msg


def test_unknown_option_error_lists_options() -> None:
    with pytest.raises(InputError, match=r"no option\(s\) sigma.*options are: sigma0, sigma1"):
        get_feature("bitplanes", sigma=1.0)
    with pytest.raises(InputError, match=r"options are: \(none\)"):
        get_feature("gray", foo=1)


def test_invalid_option_value_is_input_error() -> None:
    with pytest.raises(InputError, match="cell_size"):
        get_feature("dsift", cell_size=0)
    with pytest.raises(InputError, match="scale"):
        get_feature("gray", scale=-1.0)
    with pytest.raises(InputError, match="scale"):
        get_feature("gray", scale=float("nan"))


def test_options_and_scale_are_applied() -> None:
    f = get_feature("bitplanes", sigma0=0.0, sigma1=1.0, scale=3.0)
    assert f.sigma0 == 0.0 and f.sigma1 == 1.0 and f.scale == 3.0
    g = get_feature("  BitPlanes ")  # case and surrounding blanks are ignored
    assert g.name == "bitplanes" and g.scale == default_scale("bitplanes")
    d = get_feature("dsift", cell_size=4, spatial="bilinear", clamp=0.2)
    assert (d.cell_size, d.spatial, d.clamp) == (4, "bilinear", 0.2)


def test_gray_affine_flag() -> None:
    assert get_feature("gray-affine").affine_brightness is True
    assert get_feature("gray").affine_brightness is False
    img = _image(colour=False)
    np.testing.assert_array_equal(get_feature("gray-affine").compute(img), get_feature("gray").compute(img))


@pytest.mark.parametrize("name", list(BUILTIN))
@pytest.mark.parametrize("colour", [False, True])
def test_compute_contract(name: str, colour: bool) -> None:
    f = get_feature(name)
    img = _image(colour=colour)
    out = f.compute(img)
    assert out.shape == (32, 48, BUILTIN[name]) == (32, 48, f.channels)
    assert out.dtype == np.float32 and out.flags.c_contiguous
    assert np.isfinite(out).all()
    np.testing.assert_allclose(out, f.compute_unscaled(img) * np.float32(f.scale), rtol=1e-6, atol=1e-5)
    info = f.info()
    assert info["name"] == name and info["channels"] == BUILTIN[name] and info["scale"] == f.scale


def test_colour_features_replicate_grey_and_grey_features_convert_colour() -> None:
    grey = _image(colour=False)
    rgb = get_feature("rgb").compute_unscaled(grey)
    for c in range(3):
        np.testing.assert_array_equal(rgb[:, :, c], grey.astype(np.float32))
    colour = _image(colour=True, seed=3)
    import cv2

    expected = cv2.cvtColor(colour, cv2.COLOR_RGB2GRAY).astype(np.float32)
    np.testing.assert_array_equal(get_feature("gray").compute(colour)[:, :, 0], expected)


def test_prepare_image_validation() -> None:
    with pytest.raises(InputError, match="dtype"):
        prepare_image(np.zeros((4, 4), np.int16), colour=False)
    with pytest.raises(InputError, match="shape"):
        prepare_image(np.zeros((4, 4, 2), np.uint8), colour=False)
    with pytest.raises(InputError, match="shape"):
        prepare_image(np.zeros((2, 4, 4, 3), np.uint8), colour=False)
    rgba = np.zeros((4, 5, 4), np.uint8)
    rgba[..., 3] = 255
    assert prepare_image(rgba, colour=True).shape == (4, 5, 3)
    assert prepare_image(np.zeros((4, 5, 1), np.float64), colour=False).dtype == np.float32


def test_compute_pyramid_policies() -> None:
    img = _image(64, 96, colour=False, seed=5)
    gray = get_feature("gray")
    levels = gray.compute_pyramid(img, 3)
    assert [lv.shape for lv in levels] == [(64, 96, 1), (32, 48, 1), (16, 24, 1)]
    box = img.astype(np.float64).reshape(32, 2, 48, 2).mean(axis=(1, 3))
    np.testing.assert_allclose(levels[1][:, :, 0], box, atol=1e-4)
    bp = get_feature("bitplanes", sigma0=0.0)
    bl = bp.compute_pyramid(img, 2)
    # recompute: level 1 is the census of the box-downsampled image, not a box mean of the bits
    np.testing.assert_array_equal(bl[1], bp.compute(box.astype(np.float32)))
    assert set(np.unique(bl[1])) <= {0.0, np.float32(bp.scale)}
    with pytest.raises(InputError):
        gray.compute_pyramid(img, 0)


class _Twice(Feature):
    name = "test-twice"
    channels = 2

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        f = image.astype(np.float32) * np.float32(gain)
        return np.stack([f, 2 * f], axis=2)


def test_register_callable_and_lazy_string() -> None:
    try:
        register("test-twice", _Twice, channels=2, scale=4.0, description="test")
        with pytest.raises(ValueError, match="already registered"):
            register("test-twice", _Twice, channels=2)
        f = get_feature("test-twice")
        assert isinstance(f, _Twice) and f.scale == 4.0  # registered fallback scale (not in the table)
        assert any(d["name"] == "test-twice" and d["scale"] == 4.0 for d in list_features())
        register("test-lazy-gray", "dmtrack.features.gray:GrayFeature", channels=1)
        assert get_feature("test-lazy-gray", scale=2.0).scale == 2.0
    finally:
        unregister("test-twice")
        unregister("test-lazy-gray")
    assert "test-twice" not in base.feature_names()


@pytest.mark.parametrize("bad", ["", "Upper", "x-pca3", "a b", "-x"])
def test_register_rejects_bad_names(bad: str) -> None:
    with pytest.raises(ValueError):
        register(bad, _Twice, channels=2)


def test_register_rejects_bad_metadata() -> None:
    with pytest.raises(ValueError, match="pyramid"):
        register("test-bad", _Twice, channels=2, pyramid="sideways")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="channels"):
        register("test-bad", _Twice, channels=0)
    with pytest.raises(ValueError, match="module:attribute"):
        register("test-bad", "no_colon_here", channels=1)
    assert "test-bad" not in base.feature_names()


def test_lazy_torch_entry_reports_missing_torch(tmp_path, monkeypatch) -> None:
    (tmp_path / "dmtrack_test_fake_learned.py").write_text(
        textwrap.dedent(
            """
            import torch  # noqa: F401

            class Fake:
                pass
            """
        )
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(sys.modules, "torch", None)  # makes "import torch" fail
    register("test-fake-learned", "dmtrack_test_fake_learned:Fake", channels=4, needs_torch=True, needs_weights=True)
    try:
        listed = {d["name"]: d for d in list_features()}  # listing does not import the module
        assert listed["test-fake-learned"]["needs_torch"] is True
        assert "dmtrack_test_fake_learned" not in sys.modules
        with pytest.raises(InputError, match="needs PyTorch"):
            get_feature("test-fake-learned")
    finally:
        unregister("test-fake-learned")


def test_pca_name_needs_basis() -> None:
    with pytest.raises(InputError, match="needs a PCA basis"):
        get_feature("dsift-pca8")
    with pytest.raises(InputError, match="unknown feature 'nothing'"):
        get_feature("nothing-pca8")


def test_pca_variants_are_the_fitted_bases(monkeypatch, tmp_path) -> None:
    monkeypatch.setenv("DMTRACK_HOME", str(tmp_path))
    assert base.pca_variants() == []
    folder = base.user_pca_path("dsift", 8).parent
    folder.mkdir(parents=True)
    for name in ("dsift-pca8.npz", "gray-pca1.npz", "nothing-pca3.npz", "dsift.npz", "dsift-pca2.txt"):
        (folder / name).write_bytes(b"")
    assert base.pca_variants() == ["dsift-pca8", "gray-pca1"]


def test_listing_does_not_import_torch() -> None:
    """In a fresh interpreter (other tests of this process import torch): listing and core features stay torch-free."""
    import subprocess

    code = (
        "import sys, numpy as np; from dmtrack.features import list_features, get_feature; list_features(); "
        "get_feature('dsift').compute(np.zeros((32, 32), np.uint8)); "
        "assert 'torch' not in sys.modules, 'torch imported'; print('ok')"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "ok"
