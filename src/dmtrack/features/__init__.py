"""Per-pixel multichannel features (paper §2.1) and their registry.

>>> from dmtrack.features import get_feature, list_features
>>> f = get_feature("bitplanes")            # default feature scale from default_scales.json
>>> fmap = f.compute(image)                 # (H, W, 8) float32, already multiplied by f.scale

Hand-crafted features: ``gray``, ``gray-affine``, ``rgb``, ``lab``, ``bitplanes``, ``dsift``.  Learned features
(torch) register themselves through :func:`register` with lazily imported factories (see
:mod:`dmtrack.features.base`).  ``BASE-pcaK`` names build PCA-reduced features (:mod:`dmtrack.features.pca`).
Default feature scales: :mod:`dmtrack.features.scale`.

Only :mod:`dmtrack.features.base` is imported here; the PCA and scale helpers are imported on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from dmtrack.features.base import (
    Feature,
    FeatureEntry,
    PyramidPolicy,
    as_feature,
    default_scale,
    feature_names,
    get_entry,
    get_feature,
    list_features,
    pca_variants,
    prepare_image,
    register,
    unregister,
)

if TYPE_CHECKING:  # pragma: no cover
    from dmtrack.features.pca import PcaBasis, ReducedFeature, fit_pca
    from dmtrack.features.scale import ScaleCalibration, calibrate_scale, calibrate_scale_detailed

_LAZY = {
    "PcaBasis": "dmtrack.features.pca",
    "ReducedFeature": "dmtrack.features.pca",
    "fit_pca": "dmtrack.features.pca",
    "ScaleCalibration": "dmtrack.features.scale",
    "calibrate_scale": "dmtrack.features.scale",
    "calibrate_scale_detailed": "dmtrack.features.scale",
}

__all__ = [
    "Feature",
    "FeatureEntry",
    "PcaBasis",
    "PyramidPolicy",
    "ReducedFeature",
    "ScaleCalibration",
    "as_feature",
    "calibrate_scale",
    "calibrate_scale_detailed",
    "default_scale",
    "feature_names",
    "fit_pca",
    "get_entry",
    "get_feature",
    "list_features",
    "pca_variants",
    "prepare_image",
    "register",
    "unregister",
]


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'dmtrack.features' has no attribute {name!r}")
    import importlib

    return getattr(importlib.import_module(module), name)
