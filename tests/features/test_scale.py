"""Default feature scale calibration (paper §2.4)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from dmtrack.errors import InputError
from dmtrack.features import get_feature
from dmtrack.features.base import Feature, default_scale, default_scales_table
from dmtrack.features.scale import (
    calibrate_scale,
    calibrate_scale_detailed,
    channel_mean_gradient,
    compute_channel_statistics,
    count_semi_dense,
    measure_channel_statistics,
    solve_scale,
)


def _images(n: int = 3, h: int = 48, w: int = 64) -> list[np.ndarray]:
    rng = np.random.default_rng(11)
    out = []
    for _ in range(n):
        img = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
        out.append(cv2.GaussianBlur(img, (7, 7), 2.0))
    return out


def _numpy_measure(feat: np.ndarray, max_filter: bool) -> np.ndarray:
    f = feat.astype(np.float64)
    gx = np.zeros_like(f)
    gy = np.zeros_like(f)
    gx[1:-1, 1:-1] = 0.5 * (f[1:-1, 2:] - f[1:-1, :-2])
    gy[1:-1, 1:-1] = 0.5 * (f[2:, 1:-1] - f[:-2, 1:-1])
    g = np.sqrt(gx**2 + gy**2).mean(axis=2)
    if not max_filter:
        return g
    m = np.zeros_like(g)
    win = np.lib.stride_tricks.sliding_window_view(g, (3, 3))
    m[1:-1, 1:-1] = win.max(axis=(2, 3))
    return m


@pytest.mark.parametrize("max_filter", [True, False])
def test_channel_mean_gradient_definition(max_filter: bool) -> None:
    rng = np.random.default_rng(0)
    feat = (rng.random((20, 30, 5)) * 50).astype(np.float32)
    np.testing.assert_allclose(channel_mean_gradient(feat, max_filter), _numpy_measure(feat, max_filter),
                               rtol=1e-5, atol=1e-5)


def test_measure_is_the_odometrys_max_grad() -> None:
    frame = pytest.importorskip("dmtrack.odometry.frame")
    rng = np.random.default_rng(1)
    feat = (rng.random((24, 40, 8)) * 255).astype(np.float32)
    _, _, mg = frame.gradients(feat)
    # the odometry's kernel sums the N magnitudes in a vectorised order: equal up to float32 rounding
    np.testing.assert_allclose(channel_mean_gradient(feat), mg, rtol=1e-6)


class _Scaled(Feature):
    """gray × a constant factor (unscaled output)."""

    channels = 1

    def __init__(self, factor: float, scale: float = 1.0) -> None:
        super().__init__(scale)
        self.factor = factor
        self.name = f"gray×{factor}"

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        return (image.astype(np.float32) * np.float32(self.factor * gain))[:, :, None]


def test_gray_against_itself_is_one() -> None:
    imgs = _images()
    cal = calibrate_scale_detailed("gray", imgs)
    assert cal.scale == pytest.approx(1.0, rel=0.02)
    assert cal.achieved_count == cal.target_count
    assert cal.n_images == 3 and cal.reference == "gray" and cal.max_filter


def test_feature_times_two_calibrates_to_half() -> None:
    imgs = _images()
    s1 = calibrate_scale("gray", imgs)
    s2 = calibrate_scale(_Scaled(2.0), imgs)
    assert s2 == pytest.approx(s1 / 2, rel=1e-6)
    assert s2 == pytest.approx(0.5, rel=0.02)
    # the feature's current scale is ignored: the result always multiplies the unscaled output
    assert calibrate_scale(_Scaled(2.0, scale=7.0), imgs) == pytest.approx(s2, rel=1e-9)


def test_calibrated_scale_matches_the_count() -> None:
    imgs = _images()
    target = np.mean([count_semi_dense(get_feature("gray").compute(im)) for im in imgs])
    lab = get_feature("lab", scale=1.0)
    s = calibrate_scale(lab, imgs)
    got = np.mean([count_semi_dense(get_feature("lab", scale=s).compute(im)) for im in imgs])
    assert abs(got - target) <= 1.0  # continuous values: exact up to float32 rounding at the threshold
    # and the count moves away on either side (it is a real match, not a coincidence)
    lo = np.mean([count_semi_dense(get_feature("lab", scale=0.8 * s).compute(im)) for im in imgs])
    hi = np.mean([count_semi_dense(get_feature("lab", scale=1.25 * s).compute(im)) for im in imgs])
    assert lo < target < hi


def test_min_use_grad_and_max_filter_options() -> None:
    imgs = _images()
    a = calibrate_scale_detailed(_Scaled(3.0), imgs, min_use_grad=2.0, max_filter=False)
    assert a.scale == pytest.approx(1 / 3, rel=0.03) and not a.max_filter and a.min_use_grad == 2.0
    b = calibrate_scale_detailed("gray", imgs, max_filter=False)
    c = calibrate_scale_detailed("gray", imgs, max_filter=True)
    assert b.target_count < c.target_count


def test_accepts_paths(tmp_path: Path) -> None:
    imgs = _images(2)
    paths = []
    for i, im in enumerate(imgs):
        p = tmp_path / f"{i}.png"
        cv2.imwrite(str(p), cv2.cvtColor(im, cv2.COLOR_RGB2BGR))
        paths.append(p)
    assert calibrate_scale("rgb", paths) == pytest.approx(calibrate_scale("rgb", imgs), rel=1e-9)


def test_solve_scale_on_steps() -> None:
    # discrete values: 10 at 1.0, 10 at 0.5, 10 at 0.25 → counts 10, 20, 30 at s > t/1, t/0.5, t/0.25
    v = np.repeat([1.0, 0.5, 0.25], 10)
    s = solve_scale(v, 20, 5.0)
    assert 10.0 < s <= 20.0 and np.count_nonzero(v * s > 5.0) == 20
    s = solve_scale(v, 17, 5.0)  # not attainable: nearest step (20)
    assert np.count_nonzero(v * s > 5.0) == 20
    s = solve_scale(v, 30, 5.0)
    assert np.count_nonzero(v * s > 5.0) == 30


def test_errors() -> None:
    flat = [np.full((16, 16), 90, np.uint8)]
    with pytest.raises(InputError, match="no pixel with gradient"):
        calibrate_scale("rgb", flat)
    with pytest.raises(InputError, match="at least one image"):
        calibrate_scale("rgb", [])
    with pytest.raises(InputError, match="min_use_grad"):
        calibrate_scale("rgb", _images(1), min_use_grad=0)


def test_packaged_table() -> None:
    table = default_scales_table()
    assert table["min_use_grad"] == 5.0 and table["max_filter"] is True
    for name in ("gray", "rgb", "lab", "bitplanes", "dsift"):
        assert default_scale(name) > 0
    assert default_scale("gray") == 1.0
    assert default_scale("not-a-feature") is None
    assert get_feature("bitplanes").scale == default_scale("bitplanes")


def _table_images(sample_dir: Path) -> list[Path]:
    return sorted(sample_dir.glob("frame-*.color.jpg"))[::15]


@pytest.mark.parametrize("name", ["rgb", "lab", "bitplanes"])
def test_packaged_scales_are_reproduced_on_the_sample(sample_dir: Path, name: str) -> None:
    """The table's numbers come from the repository's sample (20 frames, every 15th)."""
    entry = default_scales_table()["scales"][name]
    paths = _table_images(sample_dir)
    assert len(paths) == 20
    cal = calibrate_scale_detailed(get_feature(name, **entry["options"]), paths)
    assert cal.scale == pytest.approx(entry["scale"], abs=1e-4)
    assert cal.target_count == pytest.approx(entry["target_count"], abs=0.1)


@pytest.mark.slow
def test_packaged_dsift_scale_is_reproduced(sample_dir: Path) -> None:
    entry = default_scales_table()["scales"]["dsift"]
    cal = calibrate_scale_detailed(get_feature("dsift", **entry["options"]), _table_images(sample_dir))
    assert cal.scale == pytest.approx(entry["scale"], abs=1e-4)


# ------------------------------------------------------------------ channel statistics (docs/multichannel-cost.md)
class _Copies(Feature):
    """The grey image repeated ``n`` times (fully correlated channels)."""

    needs_colour = True

    def __init__(self, n: int, scale: float = 1.0) -> None:
        super().__init__(scale)
        self.channels = n
        self.name = f"copies{n}"

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        g = get_feature("gray", scale=1.0).compute(image)
        return np.repeat(g, self.channels, axis=2) * np.float32(gain)


def test_channel_statistics_of_grey_and_of_copies() -> None:
    imgs = _images(2, 96, 128)
    grey = measure_channel_statistics("gray", imgs, pixels="all")
    assert grey.energy_channels == pytest.approx(1.0, rel=1e-12)
    assert grey.info_channels == pytest.approx(1.0, rel=2e-3)  # the ridge only
    assert grey.noise_var == pytest.approx(grey.grey_noise_var) and grey.noise_channels == pytest.approx(1.0)
    # three copies: three times the gradient energy, the information of one grey image
    three = measure_channel_statistics(_Copies(3), imgs, pixels="all")
    assert three.energy_channels == pytest.approx(3.0, rel=1e-12)
    assert three.info_channels == pytest.approx(1.0, rel=0.01)
    assert three.noise_channels == pytest.approx(1.0, rel=1e-6)
    # scaling the feature by s: N_E × s², κ ÷ s²
    two = measure_channel_statistics(_Copies(3, scale=2.0), imgs, pixels="all")
    assert two.energy_channels == pytest.approx(12.0, rel=1e-9)
    assert two.info_channels == pytest.approx(three.info_channels / 4.0, rel=1e-6)


def test_semi_dense_channel_statistics() -> None:
    """On the semi-dense pixels only: grey and copies of grey keep their exact counts (same pixels, same
    gradients); Bit-Planes' bounded bits carry another gradient energy at the selected pixels than on average; an
    image without semi-dense pixels is skipped, and an unknown pixel set is refused."""
    imgs = _images(2, 96, 128)
    grey = measure_channel_statistics("gray", imgs, pixels="semi-dense")
    assert grey.energy_channels == pytest.approx(1.0, rel=1e-12)
    assert grey.info_channels == pytest.approx(1.0, rel=2e-3)
    three = measure_channel_statistics(_Copies(3), imgs, pixels="semi-dense")
    assert three.energy_channels == pytest.approx(3.0, rel=1e-12)
    assert three.info_channels == pytest.approx(1.0, rel=0.01)
    assert three.n_samples == grey.n_samples < measure_channel_statistics("gray", imgs, pixels="all").n_samples
    bp_all = measure_channel_statistics("bitplanes", imgs, pixels="all")
    bp_sd = measure_channel_statistics("bitplanes", imgs, pixels="semi-dense")
    assert bp_sd.n_samples < bp_all.n_samples and bp_sd.energy_channels != pytest.approx(bp_all.energy_channels)
    with pytest.raises(InputError, match="pixels"):
        measure_channel_statistics("gray", imgs, pixels="edges")
    flat = np.full((48, 64, 3), 90, np.uint8)
    with_flat = measure_channel_statistics("gray", [flat, *imgs], pixels="semi-dense")  # the flat image is skipped
    assert with_flat.energy_channels == pytest.approx(1.0, rel=1e-12) and with_flat.n_samples == grey.n_samples
    with pytest.raises(InputError, match="semi-dense pixels"):
        measure_channel_statistics("bitplanes", [flat], pixels="semi-dense")


def test_rgb_channels_carry_independent_noise() -> None:
    """Independent noise per colour channel: κ = N σ_g²/σ_c² ≈ 3 · (0.299² + 0.587² + 0.114²) / scale² ≈ 1.5 for
    the plain channels; low-passing the chroma (the default) removes most of the chroma noise: the noise is then
    nearly one channel's (the luma's), and κ grows because the luma carries less noise than any one channel."""
    imgs = _images(2, 96, 128)
    plain_rgb = get_feature("rgb", chroma_sigma=0)  # at its own calibrated scale (the table's variant)
    plain = measure_channel_statistics(plain_rgb, imgs, pixels="all")
    assert plain.noise_channels == pytest.approx(3.0, rel=0.02)
    w2 = 0.299**2 + 0.587**2 + 0.114**2
    assert plain.info_channels == pytest.approx(3.0 * w2 / plain_rgb.scale ** 2, rel=0.05)
    smooth = measure_channel_statistics("rgb", imgs, pixels="all")
    assert smooth.noise_channels < 1.3 and smooth.info_channels > 1.3 * plain.info_channels


def test_packaged_channel_statistics_and_feature_properties(sample_dir: Path) -> None:
    table = default_scales_table()["scales"]
    for name in ("rgb", "lab", "bitplanes", "dsift"):
        f = get_feature(name)
        assert f.energy_channels == table[name]["energy_channels"] and f.info_channels == table[name]["info_channels"]
        assert 0 < f.info_channels <= f.channels and 0 < f.energy_channels
        n_sigma = f.channels * table[name]["noise_var"] / table[name]["grey_noise_var"]  # N_σ = Σ_c σ_c² / σ_g²
        assert f.noise_energy_channels == pytest.approx(n_sigma, rel=1e-12)
        assert get_feature(name, scale=2 * f.scale).noise_energy_channels == pytest.approx(4 * n_sigma)
    assert get_feature("gray").energy_channels == 1.0 and get_feature("gray").info_channels == 1.0
    assert get_feature("gray").noise_energy_channels == 1.0
    bp = get_feature("bitplanes", scale=2 * table["bitplanes"]["scale"])
    assert bp.energy_channels == pytest.approx(4 * table["bitplanes"]["energy_channels"])
    assert bp.info_channels == pytest.approx(table["bitplanes"]["info_channels"] / 4)
    # reproduced from the repository's sample (the regeneration command in the table's note)
    got = compute_channel_statistics(_table_images(sample_dir)[:20], ["bitplanes"])["bitplanes"]
    assert got["energy_channels"] == table["bitplanes"]["energy_channels"]
    assert got["info_channels"] == table["bitplanes"]["info_channels"]


# ------------------------------------------------------------------ calibration per options (entries and variants)
def test_packaged_entries_are_measured_with_the_defaults() -> None:
    """Each table entry's recorded options are the feature's defaults (they are what get_feature uses without
    options); the variants' are not."""
    from dmtrack.features.base import option_defaults, options_match

    for name, entry in default_scales_table()["scales"].items():
        defaults = option_defaults(name)
        assert options_match(entry.get("options"), None, defaults), name
        for variant in entry.get("variants", ()):
            assert not options_match(variant["options"], None, defaults), name


@pytest.mark.parametrize("name", ["rgb", "lab"])
def test_plain_colour_gets_its_own_calibration(name: str) -> None:
    entry = default_scales_table()["scales"][name]
    (plain,) = entry["variants"]
    f = get_feature(name, chroma_sigma=0)
    assert f.scale == plain["scale"] != entry["scale"]
    assert f.energy_channels == plain["energy_channels"] and f.info_channels == plain["info_channels"]
    # the defaults, given explicitly (2 == 2.0), take the entry itself, and no warning
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        d = get_feature(name, chroma_sigma=2)
    assert d.scale == entry["scale"] and d.energy_channels == entry["energy_channels"]
    # an explicit scale rescales the variant's counts (N_E ∝ s², κ ∝ 1/s²)
    g = get_feature(name, chroma_sigma=0.0, scale=2 * plain["scale"])
    assert g.energy_channels == pytest.approx(4 * plain["energy_channels"])
    assert g.info_channels == pytest.approx(plain["info_channels"] / 4)


def test_plain_colour_variant_is_reproduced_on_the_sample(sample_dir: Path) -> None:
    (plain,) = default_scales_table()["scales"]["rgb"]["variants"]
    cal = calibrate_scale_detailed(get_feature("rgb", **plain["options"]), _table_images(sample_dir))
    assert cal.scale == pytest.approx(plain["scale"], abs=1e-4)


def test_uncalibrated_options_warn_and_use_the_defaults_calibration() -> None:
    from dmtrack.features import base

    base._WARNED.clear()
    entry = default_scales_table()["scales"]["lab"]
    with pytest.warns(UserWarning, match=r"'lab' with chroma_sigma=1\.5 has no calibration of its own.*"
                      r"default scale.*N_E, κ.*--feature-opt chroma_sigma=1\.5.*--features lab:chroma_sigma=1\.5"):
        f = get_feature("lab", chroma_sigma=1.5)
    assert f.scale == entry["scale"] and f.energy_channels == entry["energy_channels"]
    with pytest.warns(UserWarning, match="N_E, κ") as record:  # with a scale, only the counts are missing
        get_feature("rgb", chroma_sigma=3, scale=1.0)
    assert "default scale" not in str(record[0].message)
    import warnings

    with warnings.catch_warnings():  # once per feature and options
        warnings.simplefilter("error")
        get_feature("lab", chroma_sigma=1.5)
        get_feature("gray")


def test_user_calibration_is_kept_per_options(monkeypatch, tmp_path: Path) -> None:
    from dmtrack.features.base import save_user_scale, user_scales

    monkeypatch.setenv("DMTRACK_HOME", str(tmp_path))
    packaged = default_scales_table()["scales"]["rgb"]
    save_user_scale("rgb", 1.7, {"chroma_sigma": 0.0})
    assert user_scales()["rgb"]["options"] == {"chroma_sigma": 0.0}
    assert get_feature("rgb", chroma_sigma=0).scale == 1.7
    assert get_feature("rgb").scale == packaged["scale"]  # the defaults are not what was calibrated
    save_user_scale("rgb", 1.1, {"chroma_sigma": 2.0})  # the defaults: recorded without options
    assert "options" not in user_scales()["rgb"]
    assert get_feature("rgb").scale == 1.1 and default_scale("rgb") == 1.1
    assert get_feature("rgb", chroma_sigma=0).scale == packaged["variants"][0]["scale"]


def test_a_feature_with_its_own_counts_is_warned_only_about_the_scale() -> None:
    """tracknet with another weights file: its N_E, κ, N_σ come from the file, so only a missing scale is warned."""
    import warnings

    from dmtrack.features import base
    from dmtrack.features.tracknet import packaged_weights

    base._WARNED.clear()
    path = str(packaged_weights())  # the packaged file, named explicitly: an option value that differs from None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        get_feature("tracknet", weights=path, scale=50.0)
    with pytest.warns(UserWarning, match="default scale") as record:
        get_feature("tracknet", weights=path)
    assert "N_E" not in str(record[0].message)
