"""PCA reduction of a feature to K channels (paper §3.4, Table 7 bottom).

:func:`fit_pca` samples feature vectors (of :meth:`Feature.compute`, i.e. *scaled*) at pixels drawn with a seeded
generator, and returns a :class:`PcaBasis`: the mean, the principal axes sorted by decreasing variance and their
variances.  :class:`ReducedFeature` applies the first K axes as a 1×1 projection

    R(p) = W (F(p) − μ) = W F(p) + b,   W = components[:K] (K × N),  b = −W μ,

then multiplies by its own scale.  A base feature may implement ``compute_projected(image, weight, bias)``
to apply the projection itself (AlexNet fuses it after conv1, dense SIFT where each descriptor is formed); it
receives the prepared image (:func:`~dmtrack.features.base.prepare_image`), ``weight`` (K, N) and ``bias`` (K,)
float32 (the reduced feature's scale already folded in) and must return ``(H, W, K)`` equal to
``base.compute(image) @ weight.T + bias`` — i.e. the projection of the base's *scaled* output.  Otherwise the
projection is a BLAS matrix product on the CPU.  A base feature on a GPU (``runner`` set,
:mod:`dmtrack.features.device`) applies it there, as a 1×1 convolution before the transfer, as in the paper.

Each component's sign is fixed (its largest-magnitude entry is positive) so a basis is reproducible.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dmtrack.errors import InputError
from dmtrack.features.base import Feature, as_feature, default_scale, iter_images
from dmtrack.io.atomic import atomic_open

_FORMAT_VERSION = 1


@dataclass(frozen=True)
class ReducedCalibration:
    """A reduced feature's default scale (paper §2.4, as ``dmtrack calibrate-scale``) and its channel counts N_E, κ,
    N_σ at that scale (:func:`dmtrack.features.scale.measure_channel_statistics`), for K components."""

    k: int
    scale: float
    energy_channels: float
    info_channels: float
    noise_energy_channels: float


@dataclass(frozen=True, eq=False)
class PcaBasis:
    """Principal axes of a feature.

    Attributes
    ----------
    mean : (N,) float64
        Mean feature vector (in the units of the base feature's scaled output at fit time).
    components : (K, N) float64
        Orthonormal principal axes, by decreasing variance.
    explained_variance : (K,) float64
        Variance along each axis.
    total_variance : float
        Total variance of the samples (sum over all N axes), for explained-variance ratios.
    feature : str
        Name of the base feature ("" if unknown).
    feature_scale : float
        The base feature's scale when the basis was fitted.
    n_samples : int
        Number of sampled feature vectors.
    seed : int
        Sampling seed.
    calibration : ReducedCalibration, optional
        The reduced feature's own default scale and channel counts, measured by ``dmtrack fit-pca`` for
        ``calibration.k`` components (:func:`calibrate_reduced`); used by :class:`ReducedFeature` with that K.
    """

    mean: np.ndarray
    components: np.ndarray
    explained_variance: np.ndarray
    total_variance: float
    feature: str = ""
    feature_scale: float = 1.0
    n_samples: int = 0
    seed: int = 0
    calibration: ReducedCalibration | None = None

    def __post_init__(self) -> None:
        mean = np.asarray(self.mean, dtype=np.float64)
        comp = np.asarray(self.components, dtype=np.float64)
        var = np.asarray(self.explained_variance, dtype=np.float64)
        if mean.ndim != 1 or comp.ndim != 2 or comp.shape[1] != mean.shape[0] or var.shape != (comp.shape[0],):
            raise InputError(
                f"inconsistent PCA basis: mean {mean.shape}, components {comp.shape}, variances {var.shape}"
            )
        if comp.shape[0] < 1:
            raise InputError("a PCA basis needs at least one component")
        for name, arr in (("mean", mean), ("components", comp), ("explained_variance", var)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def channels(self) -> int:
        """N, the base feature's channel count."""
        return int(self.mean.shape[0])

    @property
    def k(self) -> int:
        """Number of stored components."""
        return int(self.components.shape[0])

    @property
    def explained_variance_ratio(self) -> np.ndarray:
        """``explained_variance / total_variance``, (K,)."""
        return self.explained_variance / self.total_variance if self.total_variance > 0 else np.zeros(self.k)

    def truncated(self, k: int) -> PcaBasis:
        """The basis with its first ``k`` components."""
        if not 1 <= k <= self.k:
            raise InputError(f"PCA basis of {self.feature or 'feature'!r} has {self.k} components, cannot take {k}")
        return PcaBasis(
            self.mean, self.components[:k], self.explained_variance[:k], self.total_variance, self.feature,
            self.feature_scale, self.n_samples, self.seed, self.calibration,
        )

    def projection(self, k: int | None = None, input_scale: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The 1×1 projection ``(weight (K, N), bias (K,))`` float32 with ``R = weight @ F + bias``.

        ``input_scale``: the base feature's current scale; if it differs from ``feature_scale`` the mean is
        rescaled accordingly (the projection is linear, so the output scales with it).
        """
        k = self.k if k is None else k
        basis = self.truncated(k)
        mean = basis.mean
        if input_scale is not None and self.feature_scale > 0:
            mean = mean * (float(input_scale) / self.feature_scale)
        weight = basis.components.astype(np.float32)
        bias = (-(basis.components @ mean)).astype(np.float32)
        return weight, bias

    def transform(self, feat: np.ndarray, k: int | None = None) -> np.ndarray:
        """Project an ``(..., N)`` feature array onto the first k axes: ``(..., K)`` float32."""
        f = np.asarray(feat, dtype=np.float32)
        if f.shape[-1] != self.channels:
            raise InputError(f"PCA basis expects {self.channels} channels, got {f.shape[-1]}")
        weight, bias = self.projection(k)
        out = f.reshape(-1, self.channels) @ weight.T
        out += bias
        return out.reshape(f.shape[:-1] + (weight.shape[0],))

    def inverse_transform(self, reduced: np.ndarray) -> np.ndarray:
        """Reconstruct ``(..., N)`` from ``(..., K)`` coordinates (K ≤ stored components)."""
        r = np.asarray(reduced, dtype=np.float64)
        k = r.shape[-1]
        return (r @ self.components[:k] + self.mean).astype(np.float32)

    # -- files
    def save(self, path: str | Path) -> Path:
        """Write the basis to a ``.npz`` file (``.npz`` is appended if missing); returns the path written."""
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        with atomic_open(path, "wb") as f:
            np.savez(
                f,
                format_version=np.int64(_FORMAT_VERSION),
                mean=self.mean,
                components=self.components,
                explained_variance=self.explained_variance,
                total_variance=np.float64(self.total_variance),
                feature=np.str_(self.feature),
                feature_scale=np.float64(self.feature_scale),
                n_samples=np.int64(self.n_samples),
                seed=np.int64(self.seed),
                **({} if self.calibration is None else {
                    "calibration": np.array([self.calibration.k, self.calibration.scale,
                                             self.calibration.energy_channels, self.calibration.info_channels,
                                             self.calibration.noise_energy_channels], dtype=np.float64)}),
            )
        return path

    @classmethod
    def load(cls, path: str | Path) -> PcaBasis:
        """Read a basis written by :meth:`save`; :class:`InputError` naming the file if it is missing or invalid."""
        path = Path(path)
        if not path.is_file():
            raise InputError("PCA basis file not found", path=path)
        try:
            with np.load(path, allow_pickle=False) as z:
                keys = set(z.files)
                needed = {"mean", "components", "explained_variance", "total_variance"}
                if not needed <= keys:
                    raise InputError(f"not a PCA basis (missing {', '.join(sorted(needed - keys))})", path=path)
                version = int(z["format_version"]) if "format_version" in keys else _FORMAT_VERSION
                if version > _FORMAT_VERSION:
                    raise InputError(f"PCA basis format version {version} is newer than supported", path=path)
                return cls(
                    mean=z["mean"],
                    components=z["components"],
                    explained_variance=z["explained_variance"],
                    total_variance=float(z["total_variance"]),
                    feature=str(z["feature"]) if "feature" in keys else "",
                    feature_scale=float(z["feature_scale"]) if "feature_scale" in keys else 1.0,
                    n_samples=int(z["n_samples"]) if "n_samples" in keys else 0,
                    seed=int(z["seed"]) if "seed" in keys else 0,
                    calibration=_calibration(z["calibration"]) if "calibration" in keys else None,
                )
        except InputError as exc:
            if exc.path is None:
                raise InputError(exc.reason, path=path) from None
            raise
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(f"cannot read PCA basis: {exc}", path=path) from None


def _calibration(values: np.ndarray) -> ReducedCalibration:
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.shape != (5,) or not np.all(np.isfinite(v)) or v[0] < 1 or v[1] <= 0:
        raise InputError(f"invalid calibration entry {v.tolist()}")
    return ReducedCalibration(int(v[0]), float(v[1]), float(v[2]), float(v[3]), float(v[4]))


def calibrate_reduced(
    base: Feature, basis: PcaBasis, k: int, images: Iterable[np.ndarray | str | Path]
) -> PcaBasis:
    """``basis`` with the calibration of ``BASE-pcaK`` on ``images``: the default scale that gives grey's number of
    semi-dense pixels, then N_E, κ, N_σ at that scale (what ``dmtrack calibrate-scale`` and
    ``python -m dmtrack.features.scale`` measure for a packaged feature)."""
    from dmtrack.features.scale import calibrate_scale, measure_channel_statistics

    imgs = list(iter_images(images))
    scale = calibrate_scale(ReducedFeature(base, basis, k=k, scale=1.0), imgs)
    stats = measure_channel_statistics(ReducedFeature(base, basis, k=k, scale=scale), imgs)
    n_sigma = k * stats.noise_var / stats.grey_noise_var if stats.grey_noise_var > 0 else float(k)
    cal = ReducedCalibration(int(k), float(scale), float(stats.energy_channels), float(stats.info_channels),
                             float(n_sigma))
    return PcaBasis(basis.mean, basis.components, basis.explained_variance, basis.total_variance, basis.feature,
                    basis.feature_scale, basis.n_samples, basis.seed, cal)


def _sample_pixels(shape: tuple[int, int], n: int, border: int, rng: np.random.Generator) -> np.ndarray:
    h, w = shape
    ys = np.arange(border, h - border)
    xs = np.arange(border, w - border)
    if ys.size == 0 or xs.size == 0:
        ys, xs = np.arange(h), np.arange(w)
    total = ys.size * xs.size
    idx = rng.choice(total, size=min(n, total), replace=False)
    return (ys[idx // xs.size] * w + xs[idx % xs.size]).astype(np.int64)


def fit_pca(
    feature: str | Feature,
    images: Iterable[np.ndarray | str | Path],
    k: int | None = None,
    n_samples: int = 200_000,
    seed: int = 0,
    border: int = 8,
) -> PcaBasis:
    """Fit a PCA basis to a feature's vectors sampled on ``images``.

    Parameters
    ----------
    feature : str or Feature
        Registry name or instance; its *scaled* output (:meth:`Feature.compute`) is sampled.
    images : iterable of np.ndarray or path
        ``uint8`` images or image files (materialised as a list).
    k : int, optional
        Components to keep (default: all N).
    n_samples : int
        Total number of sampled pixels, split evenly over the images (without replacement within an image).
    seed : int
        Seed of the ``numpy.random.Generator`` that draws the pixels: same seed, same images → same basis.
    border : int
        Pixels within ``border`` of the image edge are not sampled (padding artefacts).

    Returns
    -------
    PcaBasis
    """
    feat = as_feature(feature)
    imgs = list(iter_images(images))
    if not imgs:
        raise InputError("fit_pca needs at least one image")
    if n_samples < 2:
        raise InputError(f"n_samples must be ≥ 2, got {n_samples}")
    n_ch = int(feat.channels)
    if k is None:
        k = n_ch
    if not 1 <= int(k) <= n_ch:
        raise InputError(f"k must be in 1..{n_ch} for feature {getattr(feat, 'name', feat)!r}, got {k}")
    rng = np.random.default_rng(seed)
    per_image = [n_samples // len(imgs) + (1 if i < n_samples % len(imgs) else 0) for i in range(len(imgs))]
    samples = []
    for img, n in zip(imgs, per_image, strict=True):
        if n == 0:
            continue
        fm = feat.compute(img)
        idx = _sample_pixels(fm.shape[:2], n, border, rng)
        samples.append(fm.reshape(-1, fm.shape[2])[idx].astype(np.float64))
    x = np.concatenate(samples, axis=0)
    mean = x.mean(axis=0)
    xc = x - mean
    cov = (xc.T @ xc) / max(x.shape[0] - 1, 1)
    evals, evecs = np.linalg.eigh(cov)
    order = np.argsort(evals)[::-1]
    evals = np.clip(evals[order], 0.0, None)
    comps = evecs[:, order].T
    # deterministic sign: the largest-magnitude entry of each component is positive
    pivot = np.argmax(np.abs(comps), axis=1)
    signs = np.sign(comps[np.arange(comps.shape[0]), pivot])
    signs[signs == 0] = 1.0
    comps = comps * signs[:, None]
    return PcaBasis(
        mean=mean,
        components=comps[: int(k)],
        explained_variance=evals[: int(k)],
        total_variance=float(evals.sum()),
        feature=str(getattr(feat, "name", "")),
        feature_scale=float(getattr(feat, "scale", 1.0)),
        n_samples=int(x.shape[0]),
        seed=int(seed),
    )


class ReducedFeature(Feature):
    """A feature reduced to its first K principal components (a 1×1 projection); itself a :class:`Feature`.

    Parameters
    ----------
    base : Feature
        The feature to reduce (its scaled output is projected).
    basis : PcaBasis
        Basis fitted on ``base`` (same channel count; same name when the basis records one).
    k : int, optional
        Components to use (default: all in the basis).
    scale : float, optional
        Scale of the reduced output; default: ``default_scales.json``'s entry for the name ``BASE-pcaK``, else 1.

    The name is ``f"{base.name}-pca{K}"``; colour/torch/weights needs and the pyramid policy are the base's.
    """

    def __init__(self, base: Feature, basis: PcaBasis, k: int | None = None, scale: float | None = None) -> None:
        k = basis.k if k is None else int(k)
        if basis.channels != int(base.channels):
            raise InputError(
                f"PCA basis has {basis.channels} input channels but feature {base.name!r} has {base.channels}"
            )
        if basis.feature and basis.feature != base.name:
            raise InputError(f"PCA basis was fitted on feature {basis.feature!r}, not {base.name!r}")
        if not 1 <= k <= basis.k:
            raise InputError(f"PCA basis for {base.name!r} has {basis.k} components, cannot reduce to {k}")
        name = f"{base.name}-pca{k}"
        cal = basis.calibration if basis.calibration is not None and basis.calibration.k == k else None
        if scale is None:
            scale = cal.scale if cal is not None else default_scale(name)
        super().__init__(1.0 if scale is None else scale)
        self._calibration = cal
        self.base = base
        self.basis = basis.truncated(k)
        self.name = name
        self.channels = k
        self.needs_colour = base.needs_colour
        self.needs_torch = base.needs_torch
        self.needs_weights = base.needs_weights
        self.pyramid = base.pyramid
        self.device = base.device
        self.description = f"{base.name} reduced to {k} principal components"

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        weight, bias = self.basis.projection(input_scale=float(self.base.scale))
        if gain != 1.0:
            weight = weight * np.float32(gain)
            bias = bias * np.float32(gain)
        if getattr(self.base, "runner", None) is not None:  # on the device, before the transfer (paper §3.4)
            return self.base.compute_projected_on_device(image, weight, bias)  # type: ignore[attr-defined]
        projected = getattr(self.base, "compute_projected", None)
        if projected is not None:
            return np.asarray(projected(image, weight, bias), dtype=np.float32)
        fm = self.base.compute(image)
        h, w, n = fm.shape
        out = fm.reshape(h * w, n) @ weight.T
        out += bias
        return out.reshape(h, w, weight.shape[0])

    def _channel_stat(self, key: str, power: int) -> float | None:
        # measured by fit-pca for this K (stored with the basis), else the tables' entry for the name, if any
        cal = self._calibration
        if cal is None or int(self.channels) == 1:
            return super()._channel_stat(key, power)
        return float(getattr(cal, key)) * (float(self.scale) / cal.scale) ** power

    def __repr__(self) -> str:
        return f"ReducedFeature(base={self.base!r}, k={self.channels}, scale={self.scale:g})"


def reduce_feature(
    build_base: Callable[[], Feature],
    basis: PcaBasis | str | os.PathLike[str],
    k: int,
    scale: float | None = None,
) -> ReducedFeature:
    """The registry's factory of ``BASE-pcaK`` (:data:`dmtrack.features.base.PCA_FACTORY`).

    ``basis`` is a :class:`PcaBasis` or a ``.npz`` written by :meth:`PcaBasis.save` (read first, so that a bad
    file is reported before the base feature is built); ``build_base()`` builds the base feature.
    """
    if not isinstance(basis, PcaBasis):
        basis = PcaBasis.load(basis)
    return ReducedFeature(build_base(), basis, k=k, scale=scale)
