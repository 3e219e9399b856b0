"""PCA reduction of features (dmtrack.features.pca)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from dmtrack.errors import InputError
from dmtrack.features import get_feature
from dmtrack.features.base import Feature, register, unregister
from dmtrack.features.pca import PcaBasis, ReducedFeature, fit_pca

MIX = np.array(
    [[1.0, 0.0], [0.5, 2.0], [-1.0, 1.0], [0.0, 3.0], [2.0, -0.5], [0.3, 0.3]], dtype=np.float64
)  # 6 channels spanned by 2 maps
OFFSET = np.array([10.0, -5.0, 3.0, 0.0, 7.0, 1.0])


class _LowRank(Feature):
    """6 channels = MIX @ (intensity, horizontal gradient) + OFFSET: rank 2 around its mean."""

    name = "test-lowrank"
    channels = 6

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        i = image.astype(np.float64)
        gx = np.zeros_like(i)
        gx[:, 1:-1] = 0.5 * (i[:, 2:] - i[:, :-2])
        basis = np.stack([i, gx], axis=-1)
        return ((basis @ MIX.T + OFFSET) * gain).astype(np.float32)


def _images(n: int = 3) -> list[np.ndarray]:
    rng = np.random.default_rng(5)
    return [cv2.GaussianBlur(rng.integers(0, 256, (40, 56), dtype=np.uint8), (5, 5), 1.5) for _ in range(n)]


def test_low_rank_reconstruction() -> None:
    f = _LowRank()
    imgs = _images()
    basis = fit_pca(f, imgs, k=None, n_samples=3000, seed=0)
    assert basis.k == 6 and basis.channels == 6
    ratio = basis.explained_variance_ratio
    assert ratio[:2].sum() > 1 - 1e-9 and ratio[2:].max() < 1e-9
    assert np.all(np.diff(basis.explained_variance) <= 1e-9)
    np.testing.assert_allclose(basis.components @ basis.components.T, np.eye(6), atol=1e-9)
    fm = f.compute(imgs[0])
    rec = basis.truncated(2).inverse_transform(basis.transform(fm, k=2))
    np.testing.assert_allclose(rec, fm, atol=1e-3 * np.abs(fm).max())
    # one component is not enough: the test can fail
    rec1 = basis.inverse_transform(basis.transform(fm, k=1))
    assert np.abs(rec1 - fm).max() > 1.0


def test_deterministic_by_seed() -> None:
    imgs = _images()
    a = fit_pca("rgb", [cv2.cvtColor(i, cv2.COLOR_GRAY2RGB) for i in imgs], k=2, n_samples=500, seed=3)
    b = fit_pca("rgb", [cv2.cvtColor(i, cv2.COLOR_GRAY2RGB) for i in imgs], k=2, n_samples=500, seed=3)
    np.testing.assert_array_equal(a.mean, b.mean)
    np.testing.assert_array_equal(a.components, b.components)
    np.testing.assert_array_equal(a.explained_variance, b.explained_variance)
    c = fit_pca("rgb", [cv2.cvtColor(i, cv2.COLOR_GRAY2RGB) for i in imgs], k=2, n_samples=500, seed=4)
    assert not np.array_equal(a.mean, c.mean)
    # sign convention: the largest-magnitude entry of each component is positive
    for comp in a.components:
        assert comp[np.argmax(np.abs(comp))] > 0


def test_save_load_round_trip(tmp_path: Path) -> None:
    basis = fit_pca(_LowRank(scale=2.0), _images(2), k=3, n_samples=800, seed=1)
    path = basis.save(tmp_path / "lowrank")
    assert path.name == "lowrank.npz" and path.is_file()
    loaded = PcaBasis.load(path)
    for attr in ("mean", "components", "explained_variance"):
        np.testing.assert_array_equal(getattr(loaded, attr), getattr(basis, attr))
    assert loaded.total_variance == basis.total_variance
    assert (loaded.feature, loaded.feature_scale, loaded.n_samples, loaded.seed) == ("test-lowrank", 2.0, 800, 1)


def test_load_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not found") as exc:
        PcaBasis.load(tmp_path / "missing.npz")
    assert exc.value.path == tmp_path / "missing.npz"
    bad = tmp_path / "bad.npz"
    np.savez(bad, mean=np.zeros(3))
    with pytest.raises(InputError, match="missing components") as exc:
        PcaBasis.load(bad)
    assert exc.value.path == bad
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip file")
    with pytest.raises(InputError, match="cannot read") as exc:
        PcaBasis.load(junk)


def test_reduced_feature_is_a_feature() -> None:
    base = _LowRank(scale=1.0)
    imgs = _images(2)
    basis = fit_pca(base, imgs, n_samples=1000, seed=0)
    red = ReducedFeature(base, basis, k=2)
    assert red.name == "test-lowrank-pca2" and red.channels == 2 and red.scale == 1.0
    assert red.pyramid == base.pyramid and red.needs_torch == base.needs_torch
    out = red.compute(imgs[0])
    assert out.shape == (40, 56, 2) and out.dtype == np.float32 and out.flags.c_contiguous
    np.testing.assert_allclose(out, basis.transform(base.compute(imgs[0]), k=2), rtol=1e-5, atol=1e-3)
    # zero-mean projection on the sample distribution
    assert np.abs(out.reshape(-1, 2).mean(axis=0)).max() < 0.2 * out.std()
    # own scale multiplies the output
    red3 = ReducedFeature(base, basis, k=2, scale=3.0)
    np.testing.assert_allclose(red3.compute(imgs[0]), 3.0 * out, rtol=1e-5, atol=1e-3)
    # a base with another scale than at fit time: the output scales with it
    base2 = _LowRank(scale=2.0)
    np.testing.assert_allclose(ReducedFeature(base2, basis, k=2).compute(imgs[0]), 2.0 * out, rtol=1e-4, atol=1e-2)


def test_reduced_feature_validation() -> None:
    base = _LowRank()
    basis = fit_pca(base, _images(1), k=3, n_samples=500)
    with pytest.raises(InputError, match="cannot reduce to 4"):
        ReducedFeature(base, basis, k=4)
    with pytest.raises(InputError, match="input channels"):
        ReducedFeature(get_feature("rgb"), basis)
    other = PcaBasis(basis.mean, basis.components, basis.explained_variance, basis.total_variance, feature="dsift")
    with pytest.raises(InputError, match="fitted on feature 'dsift'"):
        ReducedFeature(base, other)
    with pytest.raises(InputError, match="k must be"):
        fit_pca(base, _images(1), k=7)


def test_compute_projected_hook_is_used() -> None:
    class _Hooked(_LowRank):
        calls = 0

        def compute_projected(self, image: np.ndarray, weight: np.ndarray, bias: np.ndarray) -> np.ndarray:
            type(self).calls += 1
            fm = self.compute(image)
            return np.einsum("kn,hwn->hwk", weight, fm) + bias

    base = _Hooked()
    imgs = _images(1)
    basis = fit_pca(base, imgs, k=2, n_samples=500)
    out = ReducedFeature(base, basis).compute(imgs[0])
    assert _Hooked.calls == 1
    np.testing.assert_allclose(out, basis.transform(base.compute(imgs[0])), rtol=1e-5, atol=1e-3)


def test_get_feature_pca_name(tmp_path: Path) -> None:
    register("test-lowrank", _LowRank, channels=6)
    try:
        imgs = _images(2)
        basis = fit_pca("test-lowrank", imgs, n_samples=1000, seed=0)
        path = basis.save(tmp_path / "b.npz")
        f = get_feature("test-lowrank-pca2", pca=path)
        assert isinstance(f, ReducedFeature) and f.channels == 2 and f.name == "test-lowrank-pca2"
        np.testing.assert_allclose(f.compute(imgs[0]), basis.transform(_LowRank().compute(imgs[0]), k=2),
                                   rtol=1e-5, atol=1e-3)
        g = get_feature("test-lowrank-pca1", pca=basis, scale=2.0, base_scale=1.0)
        assert g.channels == 1 and g.scale == 2.0
        with pytest.raises(InputError, match="cannot reduce to 9|cannot take 9"):
            get_feature("test-lowrank-pca9", pca=basis)
        with pytest.raises(InputError, match="not found"):
            get_feature("test-lowrank-pca2", pca=tmp_path / "nope.npz")
    finally:
        unregister("test-lowrank")


def test_dsift_projects_where_the_descriptor_is_formed() -> None:
    # dsift-pcaK never writes the 128-channel map; the result equals projecting it, within float32 rounding
    dsift = get_feature("dsift")
    rng = np.random.default_rng(2)
    img = cv2.GaussianBlur(rng.integers(0, 256, (48, 64), dtype=np.uint8), (5, 5), 1.2)
    basis = fit_pca(dsift, [img], k=8, n_samples=2000, seed=1)
    weight, bias = basis.projection(input_scale=dsift.scale)
    fm = dsift.compute(img).astype(np.float64)
    expected = fm @ weight.astype(np.float64).T + bias
    got = dsift.compute_projected(img, weight, bias)
    assert got.shape == (48, 64, 8) and got.dtype == np.float32
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=1e-3 * np.abs(expected).max())
    reduced = ReducedFeature(dsift, basis, scale=1.0)
    np.testing.assert_array_equal(reduced.compute(img), got)  # the reduced feature takes this path
    with pytest.raises(InputError, match="projection must be"):
        dsift.compute_projected(img, weight[:, :5], bias)


def test_fit_pca_calibrates_the_reduced_feature(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # dmtrack fit-pca stores the reduced feature's own scale and channel counts with the basis; the reduced
    # feature uses them, and the hint names the file when it is not in the config folder
    from dmtrack.cli import main

    out = tmp_path / "dsift-pca4.npz"
    assert main(["fit-pca", "--feature", "dsift", "--k", "4", "synthetic:n_frames=3,width=128,height=96",
                 "--frames", "3", "--samples", "3000", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"--feature dsift-pca4 --feature-opt pca={out}" in printed
    basis = PcaBasis.load(out)
    cal = basis.calibration
    assert cal is not None and cal.k == 4 and cal.scale > 0 and cal.energy_channels > 0 and cal.info_channels > 0
    reduced = get_feature("dsift-pca4", pca=out)
    assert reduced.scale == cal.scale and reduced.energy_channels == pytest.approx(cal.energy_channels)
    twice = get_feature("dsift-pca4", pca=out, scale=2 * cal.scale)  # the counts follow the scale, as for others
    assert twice.energy_channels == pytest.approx(4 * cal.energy_channels)
    assert twice.info_channels == pytest.approx(cal.info_channels / 4)
    assert get_feature("dsift-pca3", pca=out).scale != cal.scale  # measured for K = 4 only
