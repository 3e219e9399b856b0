"""Default feature scale calibration (paper §2.4).

LSD-SLAM's thresholds assume a 0..255 intensity.  Instead of retuning them, each feature is multiplied by one
global factor s chosen so that the average number of *semi-dense* pixels — those whose gradient measure
exceeds ``minUseGrad`` (5) — equals that of the grey image on the same sample images.

Gradient measure (the one the odometry gates on, ``dmtrack.odometry.frame``): per channel the halved central
differences ``½(F[x+1]−F[x−1])``, ``½(F[y+1]−F[y−1])``; the channel mean of ``sqrt(gx²+gy²)``; then LSD-SLAM's
separable 3×3 max filter (``maxGradients``), zero on the one-pixel border.  A pixel counts when that value is
``> min_use_grad`` (as the random depth initialisation's ``maxGrad > MIN_ABS_GRAD_CREATE``).
``max_filter=False`` uses the measure before the max filter.

Solving for s: the measure is positively homogeneous (``g(sF) = s·g(F)``), so the count at scale s is
``#{g(F) > t/s}`` — a monotone step function of s.  Instead of bisecting on log s, the exact solution is read
from the order statistics of the pooled unscaled values v₁ ≥ v₂ ≥ …: any s in ``(t/v_C, t/v_{C+1}]`` gives exactly
the target total count C; the geometric midpoint ``s = t / sqrt(v_C · v_{C+1})`` is returned.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numba
import numpy as np

from dmtrack.errors import InputError
from dmtrack.features.base import Feature, as_feature, default_scale, default_scales_table, iter_images
from dmtrack.io.images import read_image

__all__ = [
    "ScaleCalibration",
    "calibrate_scale",
    "calibrate_scale_detailed",
    "channel_mean_gradient",
    "count_semi_dense",
    "default_scale",
    "default_scales_table",
    "compute_default_scales",
    "ChannelStatistics",
    "compute_channel_statistics",
    "measure_channel_statistics",
]


@numba.njit(cache=True)
def _mean_grad_kernel(feat, gmean, max_grad, do_max):  # pragma: no cover - compiled
    h, w, n = feat.shape
    half = np.float32(0.5)
    fn = np.float32(n)
    gmean[:] = 0
    max_grad[:] = 0
    for y in range(1, h - 1):
        for x in range(1, w - 1):
            s = np.float32(0.0)
            for c in range(n):
                dx = half * (feat[y, x + 1, c] - feat[y, x - 1, c])
                dy = half * (feat[y + 1, x, c] - feat[y - 1, x, c])
                s += np.sqrt(dx * dx + dy * dy)
            gmean[y, x] = s / fn
    if not do_max:
        return
    for y in range(1, h - 1):
        for x in range(1, w - 1):
            m = gmean[y - 1, x - 1]
            for yy in range(y - 1, y + 2):
                for xx in range(x - 1, x + 2):
                    v = gmean[yy, xx]
                    if v > m:
                        m = v
            max_grad[y, x] = m


def channel_mean_gradient(feat: np.ndarray, max_filter: bool = True) -> np.ndarray:
    """The odometry's gradient measure of a feature map.

    Parameters
    ----------
    feat : np.ndarray
        ``(H, W, N)`` (or ``(H, W)``) feature map.
    max_filter : bool
        Apply the 3×3 max filter (LSD-SLAM's ``maxGradients``; the odometry's gates use it).

    Returns
    -------
    np.ndarray
        ``(H, W)`` float32; mean over channels of ``sqrt(gx² + gy²)`` (halved central differences), optionally
        3×3-max-filtered; 0 on the one-pixel border.
    """
    f = np.asarray(feat)
    if f.ndim == 2:
        f = f[:, :, None]
    f = np.ascontiguousarray(f, dtype=np.float32)
    h, w, _ = f.shape
    gmean = np.empty((h, w), np.float32)
    mg = np.empty((h, w), np.float32)
    _mean_grad_kernel(f, gmean, mg, bool(max_filter))
    return mg if max_filter else gmean


def count_semi_dense(feat: np.ndarray, min_use_grad: float = 5.0, max_filter: bool = True) -> int:
    """Number of pixels whose gradient measure (:func:`channel_mean_gradient`) is ``> min_use_grad``."""
    return int(np.count_nonzero(channel_mean_gradient(feat, max_filter) > min_use_grad))


@dataclass(frozen=True)
class ScaleCalibration:
    """Result of :func:`calibrate_scale_detailed`.

    Attributes
    ----------
    feature, reference : str
        Names of the calibrated and the reference feature.
    scale : float
        Default feature scale (multiplies the feature's *unscaled* output).
    target_count : float
        Average semi-dense pixel count per image of the reference.
    achieved_count : float
        The same average for the feature at ``scale``.
    n_images : int
    min_use_grad : float
    max_filter : bool
    """

    feature: str
    reference: str
    scale: float
    target_count: float
    achieved_count: float
    n_images: int
    min_use_grad: float
    max_filter: bool


def solve_scale(values: np.ndarray, target: int, threshold: float) -> float:
    """The scale s whose count ``#{s·v > threshold}`` is closest to ``target``.

    ``count(s)`` is a non-decreasing step function of s: with the distinct positive values u₁ > u₂ > … and
    ``N_i = #{v ≥ u_i}``, every s in ``(t/u_i, t/u_{i+1}]`` gives ``N_i``.  The step i with ``N_i`` closest to the
    target (the smaller s on a tie) is chosen and the geometric midpoint ``t / sqrt(u_i · u_{i+1})`` of its
    interval returned (``2t/u_i`` for the last step).  With continuous values ``N_i`` hits the target exactly;
    with discrete ones (e.g. unsmoothed Bit-Planes) the nearest attainable count is used.

    Parameters
    ----------
    values : np.ndarray
        Unscaled gradient measures (any shape; values ≤ 0 are ignored).
    target : int
        Count to match (≥ 1).
    threshold : float
        t (``min_use_grad``), > 0.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[v > 0]
    if v.size == 0 or target < 1:
        raise ValueError("solve_scale needs positive values and a target ≥ 1")
    u, counts = np.unique(v, return_counts=True)  # ascending
    u = u[::-1]
    cum = np.cumsum(counts[::-1])  # cum[i] = #{v >= u[i]}
    i = int(np.argmin(np.abs(cum - target)))
    if i + 1 < u.size:
        return float(threshold / np.sqrt(u[i] * u[i + 1]))
    return float(2.0 * threshold / u[i])


def calibrate_scale_detailed(
    feature: str | Feature,
    images: Iterable[np.ndarray | str | Path],
    min_use_grad: float = 5.0,
    *,
    reference: str | Feature = "gray",
    max_filter: bool = True,
) -> ScaleCalibration:
    """Default feature scale of ``feature`` with details (see :func:`calibrate_scale`)."""
    from dmtrack.errors import InputError

    feat = as_feature(feature)
    ref = as_feature(reference)
    t = float(min_use_grad)
    if not t > 0:
        raise InputError(f"min_use_grad must be > 0, got {min_use_grad!r}")
    values: list[np.ndarray] = []
    target = 0
    n = 0
    for img in iter_images(images):
        target += count_semi_dense(ref.compute(img), t, max_filter)
        fm = feat.compute_unscaled(img) if hasattr(feat, "compute_unscaled") else feat.compute(img) / feat.scale
        g = channel_mean_gradient(fm, max_filter).ravel()
        values.append(g[g > 0])
        n += 1
    if n == 0:
        raise InputError("calibrate_scale needs at least one image")
    if target == 0:
        raise InputError(f"the reference {getattr(ref, 'name', ref)!r} has no pixel with gradient > {t} in the images")
    v = np.concatenate(values)
    if v.size < target:
        raise InputError(
            f"feature {getattr(feat, 'name', feat)!r} has only {v.size} pixels with a non-zero gradient, fewer than "
            f"the reference's {target} semi-dense pixels: no scale matches"
        )
    s = solve_scale(v, target, t)
    achieved = int(np.count_nonzero(v * np.float32(s) > t))
    return ScaleCalibration(
        feature=str(getattr(feat, "name", type(feat).__name__)),
        reference=str(getattr(ref, "name", type(ref).__name__)),
        scale=float(s),
        target_count=target / n,
        achieved_count=achieved / n,
        n_images=n,
        min_use_grad=t,
        max_filter=bool(max_filter),
    )


def calibrate_scale(
    feature: str | Feature,
    images: Iterable[np.ndarray | str | Path],
    min_use_grad: float = 5.0,
    *,
    reference: str | Feature = "gray",
    max_filter: bool = True,
) -> float:
    """Default feature scale (paper §2.4): the global factor s that makes the average number of semi-dense
    pixels of ``s × feature`` equal to that of ``reference`` (grey) on the same images.

    Parameters
    ----------
    feature : str or Feature
        Registry name or feature instance; its *unscaled* output is calibrated (its current scale is ignored).
    images : iterable of np.ndarray or path
        ``uint8`` images (grey or RGB), or image files.
    min_use_grad : float
        LSD-SLAM's ``minUseGrad`` (5 for the 0..255 intensity).
    reference : str or Feature
        The feature whose count is matched (``"gray"``, at its own scale).
    max_filter : bool
        Count on the 3×3-max-filtered measure (default; what the odometry gates on) or the raw channel mean.

    Returns
    -------
    float
        The scale s (to pass as ``get_feature(name, scale=s)``).
    """
    return calibrate_scale_detailed(
        feature, images, min_use_grad, reference=reference, max_filter=max_filter
    ).scale


def compute_default_scales(
    image_paths: Sequence[str | Path],
    names: Sequence[str] = ("rgb", "lab", "bitplanes", "dsift"),
    min_use_grad: float = 5.0,
    options: dict[str, dict[str, Any]] | None = None,
) -> dict[str, Any]:
    """Calibrate several features on the same images and return a ``default_scales.json``-style table.

    Parameters
    ----------
    image_paths : sequence of paths
        Sample frames (read as RGB; grey features convert them).
    names : sequence of str
        Feature names to calibrate.
    min_use_grad : float
    options : dict, optional
        Per-name feature options (default: each feature's defaults).

    Returns
    -------
    dict
        ``{"scales": {name: {"scale", "target_count", "achieved_count", "options"}}, "images": [...], ...}``.
    """
    images = [read_image(p) for p in image_paths]
    options = options or {}
    scales: dict[str, Any] = {}
    for name in names:
        opts = dict(options.get(name, {}))
        cal = calibrate_scale_detailed(as_feature(name, **opts), images, min_use_grad)
        scales[name] = {
            "scale": round(cal.scale, 4),
            "target_count": round(cal.target_count, 1),
            "achieved_count": round(cal.achieved_count, 1),
            "options": opts,
        }
    return {
        "scales": scales,
        "images": [str(p) for p in image_paths],
        "min_use_grad": min_use_grad,
        "max_filter": True,
    }


@dataclass(frozen=True)
class ChannelStatistics:
    """Result of :func:`measure_channel_statistics`.

    ``info_channels`` is κ, ``energy_channels`` N_E; ``noise_var`` the mean per-channel variance of the feature's
    response to the image
    noise (feature units, at the feature's scale), ``grey_noise_var`` that of the grey image, ``noise_channels``
    the participation ratio (tr C)²/tr(C²) of the noise covariance C (N for independent equal noise, 1 for
    fully correlated channels), ``n_samples`` the number of noise and gradient samples used.
    """

    info_channels: float
    energy_channels: float
    noise_var: float
    grey_noise_var: float
    noise_channels: float
    n_samples: int


def measure_channel_statistics(
    feature: Feature | str,
    images: Iterable[np.ndarray | str | Path],
    sigma: float = 4.0,
    seed: int = 0,
    ridge: float = 1e-3,
    stride: int = 7,
    border: int = 8,
    pixels: str = "semi-dense",
    min_use_grad: float = 5.0,
) -> ChannelStatistics:
    """N_E and κ: the channel counts of the odometry's ``channel_cost="balanced"`` (docs/multichannel-cost.md).

    **N_E**, the gradient-energy channel count: E[Σ_c|∇F_c|²] / E[|∇I|²] over the interior pixels of
    ``images``, with ∇ the halved central differences of the scaled feature F and of the grey image I. Dividing
    the SSD-type sums by N_E makes a given misalignment δ cost what it costs in grey (its SSD is ≈ δ²·Σ_c|∇F_c|²).

    **κ**, how many grey images' worth of independent information a feature's channel sum carries.

    The odometry's information-type quantities (the photometric disparity variance 4σ²/Σ_c g_c² and the
    epipolar-gradient gate; docs/multichannel-cost.md) sum squared feature gradients over channels as if every
    channel carried independent noise of the grey level's variance. The proper information of a gradient
    g ∈ ℝᴺ is gᵀC⁻¹g under the feature's noise covariance C; in grey units (noise variance σ_g² of the grey
    image under the same image noise) that is σ_g²·gᵀC⁻¹g. κ is the factor that makes the channel mean of the
    squared gradients carry that information on average::

        κ = N · σ_g² · E[gᵀC⁻¹g] / E[Σ_c g_c²]

    C is measured by pushing seeded Gaussian image noise (``sigma`` grey levels per colour channel, LSD-SLAM's
    cameraPixelNoise = 4; the noisy image rounded to 8 bit) through the feature and taking the covariance of
    the change over the interior pixels (``border`` pixels excluded) of ``images``; a ridge of
    ``ridge``·tr(C)/N keeps the inverse finite. Gradients g are the halved central differences of the clean
    feature (both directions, every ``stride``-th pixel). κ = 1 for grey by construction and for any feature
    that is one grey image repeated; κ = N for N channels of independent noise and equal information each.
    κ scales as 1/scale² (information is compared with gradients in feature units).

    ``pixels`` chooses where the expectations are taken. ``"all"``: every interior pixel. ``"semi-dense"``:
    only the pixels the odometry maps and tracks — for the feature, those whose gradient measure
    (:func:`channel_mean_gradient`, the one its gates use) exceeds ``min_use_grad``; for the grey reference
    (σ_g², E[|∇I|²]), the grey image's own such pixels. The thresholds the two counts rescale are only ever
    applied there, and a feature's gradient energy and noise there can differ from the image average (Bit-Planes'
    bounded bits: 0.82× grey's gradient energy at the semi-dense pixels, 1.35× over the whole image).
    """
    if pixels not in ("all", "semi-dense"):
        raise InputError(f"pixels must be 'all' or 'semi-dense', not {pixels!r}")
    from dmtrack.features.base import get_feature

    feat = as_feature(feature)
    grey = get_feature("gray", scale=1.0)
    rng = np.random.default_rng(seed)
    n = int(feat.channels)
    b = int(border)
    cov = np.zeros((n, n))
    mean = np.zeros(n)
    count = 0
    grey_d: list[np.ndarray] = []
    g_parts: list[np.ndarray] = []
    energy = grey_energy = 0.0
    for img in iter_images(images):
        noisy = np.clip(np.rint(img.astype(np.float64) + rng.normal(0.0, sigma, img.shape)), 0, 255).astype(np.uint8)
        clean_map = feat.compute(img)
        grey_map = grey.compute(img)
        if pixels == "semi-dense":
            sel = (channel_mean_gradient(clean_map) > min_use_grad)[b:-b, b:-b].ravel()
            sel_g = (channel_mean_gradient(grey_map) > min_use_grad)[b:-b, b:-b].ravel()
            if not (sel.any() and sel_g.any()):
                continue  # a flat image has no semi-dense pixel to measure (for the feature or for grey)
        else:
            sel = sel_g = slice(None)
        clean = clean_map.astype(np.float64)
        d = (feat.compute(noisy).astype(np.float64) - clean)[b:-b, b:-b].reshape(-1, n)[sel]
        cov += d.T @ d
        mean += d.sum(axis=0)
        count += d.shape[0]
        grey_clean = grey_map.astype(np.float64)
        dg = grey.compute(noisy).astype(np.float64) - grey_clean
        grey_d.append(dg[b:-b, b:-b].ravel()[sel_g])
        gx = 0.5 * (clean[b:-b, b + 1 : -b + 1] - clean[b:-b, b - 1 : -b - 1]).reshape(-1, n)[sel]
        gy = 0.5 * (clean[b + 1 : -b + 1, b:-b] - clean[b - 1 : -b - 1, b:-b]).reshape(-1, n)[sel]
        g_parts += [gx[::stride], gy[::stride]]
        energy += float(np.mean(np.sum(gx * gx + gy * gy, axis=-1)))
        gi = grey_clean[..., 0]
        gix = 0.5 * (gi[b:-b, b + 1 : -b + 1] - gi[b:-b, b - 1 : -b - 1]).ravel()[sel_g]
        giy = 0.5 * (gi[b + 1 : -b + 1, b:-b] - gi[b - 1 : -b - 1, b:-b]).ravel()[sel_g]
        grey_energy += float(np.mean(gix * gix + giy * giy))
    if count == 0:
        raise InputError(
            "measure_channel_statistics needs at least one image"
            + (" with semi-dense pixels (gradient measure > min_use_grad)" if pixels == "semi-dense" else "")
        )
    mean /= count
    C = cov / count - np.outer(mean, mean)
    g = np.concatenate(g_parts)
    sg2 = float(np.var(np.concatenate(grey_d)))
    tr = float(np.trace(C))
    Cr = C + ridge * tr / n * np.eye(n)
    info = np.einsum("ij,ij->i", g @ np.linalg.inv(Cr), g)
    kappa = n * sg2 * float(info.mean()) / float((g * g).sum(axis=1).mean())
    return ChannelStatistics(
        info_channels=kappa,
        energy_channels=energy / grey_energy,
        noise_var=tr / n,
        grey_noise_var=sg2,
        noise_channels=tr * tr / float(np.sum(C * C)),
        n_samples=int(count),
    )


def compute_channel_statistics(
    image_paths: Sequence[str | Path],
    names: Sequence[str] = ("rgb", "lab", "bitplanes", "dsift"),
    pixels: str = "semi-dense",
) -> dict[str, dict[str, float]]:
    """:func:`measure_channel_statistics` of several features (each at its default scale for its options) on the same
    images: ``{name: {"energy_channels", "info_channels", "noise_var", "grey_noise_var", "noise_channels"}}``.
    A name may be a spec ``NAME:key=value[:key=value]`` (:func:`parse_feature_spec`); it keys its own row."""
    images = [read_image(p) for p in image_paths]
    out: dict[str, dict[str, float]] = {}
    for name in names:
        base, opts = parse_feature_spec(name)
        cal = measure_channel_statistics(as_feature(base, **opts), images, pixels=pixels)
        out[name] = {
            "energy_channels": round(cal.energy_channels, 3),
            "info_channels": round(cal.info_channels, 3),
            "noise_var": round(cal.noise_var, 3),
            "grey_noise_var": round(cal.grey_noise_var, 3),
            "noise_channels": round(cal.noise_channels, 2),
        }
    return out


def parse_feature_spec(spec: str) -> tuple[str, dict[str, Any]]:
    """``NAME`` or ``NAME:key=value[:key=value...]`` → (name, options); values are YAML scalars (``2``, ``0.5``,
    ``none``, ``box``)."""
    import yaml

    name, *items = spec.split(":")
    options: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"feature {spec!r}: expected NAME:key=value, got {item!r}")
        options[key.strip()] = yaml.safe_load(raw)
    return name.strip(), options


def _main(argv: Sequence[str] | None = None) -> None:
    """Maintenance entry point: ``python -m dmtrack.features.scale [--channels] [--features SPECS] FRAMES...``."""
    import argparse
    import warnings

    parser = argparse.ArgumentParser(
        prog="python -m dmtrack.features.scale",
        description="Print default_scales.json's numbers for the sample frames: the calibrated default scales, or "
        "with --channels N_E and κ (each feature at its packaged default scale for its options).",
    )
    parser.add_argument("frames", nargs="+", metavar="FRAME", help="image files (the table: 20 sample frames)")
    parser.add_argument("--channels", action="store_true",
                        help="measure N_E and κ instead of the scales")
    parser.add_argument("--features", default=None, metavar="SPECS",
                        help="comma-separated NAME or NAME:key=value[:key=value] (e.g. rgb:chroma_sigma=0); "
                        "default rgb,lab,bitplanes,dsift")
    parser.add_argument("--pixels", choices=("semi-dense", "all"), default="semi-dense",
                        help="pixels the channel statistics average over (default semi-dense)")
    args = parser.parse_args(argv)
    warnings.simplefilter("ignore", UserWarning)  # "no calibration of its own": what this measures
    specs = (args.features or "rgb,lab,bitplanes,dsift").split(",")
    if args.channels:
        print(json.dumps(compute_channel_statistics(args.frames, specs, pixels=args.pixels), indent=2))
        return
    table: dict[str, Any] = {}
    for spec in specs:
        name, opts = parse_feature_spec(spec)
        table[spec] = compute_default_scales(args.frames, [name], options={name: opts})["scales"][name]
    print(json.dumps({"scales": table, "images": list(args.frames)}, indent=2))


if __name__ == "__main__":  # pragma: no cover
    _main()
