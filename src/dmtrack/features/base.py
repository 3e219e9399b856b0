"""The :class:`Feature` interface and the feature registry.

A *feature* turns an 8-bit image into a per-pixel N-channel float map that the odometry tracks instead of the
intensity (paper §2.1).  Every feature carries its *default feature scale* (paper §2.4), a global factor already
multiplied into :meth:`Feature.compute`'s output so that LSD-SLAM's 0..255 thresholds keep their meaning.

Registry
--------
Features are looked up by name with :func:`get_feature`; :func:`list_features` describes them without building
them.  An entry's factory may be given as a ``"package.module:attribute"`` string: the module is imported only
when the feature is built, so entries that need PyTorch (``needs_torch=True``) cost nothing until used and
:func:`list_features` never imports torch.

Names of the form ``BASE-pcaK`` (e.g. ``alexnet-pca8``) build a PCA-reduced ``BASE`` with K channels
(:class:`dmtrack.features.pca.ReducedFeature`, through the string factory :data:`PCA_FACTORY`, so that this
module does not import :mod:`dmtrack.features.pca`, which builds on it); they need a basis (``pca=`` a
:class:`PcaBasis` or a ``.npz`` path written by :meth:`PcaBasis.save`, else one fitted into the user's PCA folder;
:func:`pca_variants` lists the ``BASE-pcaK.npz`` ones).

Plug-ins: after the built-in entries, the registry imports the modules named in :data:`PLUGIN_MODULES` if they
exist (``dmtrack.features.learned``).  Such a module must not import torch at import time; it calls
:func:`register` with string factories, e.g.
``register("alexnet", "dmtrack.features.learned.alexnet:AlexNetFeature", channels=96, needs_colour=True,
needs_torch=True, needs_weights=True, scale=1.23, description=...)``.

Default scales
--------------
``default_scales.json`` (packaged next to this file) holds the calibrated default scale of each feature
(:func:`dmtrack.features.scale.calibrate_scale`).  The scale used when ``get_feature`` gets none is, in order:
the user's calibration (``dmtrack calibrate-scale --save``), the table's value, the ``scale`` given to
:func:`register`, 1.

Calibrations belong to options: a table entry records the options it was measured with (the feature's defaults)
and may hold ``variants`` measured with others (``rgb``/``lab`` with ``chroma_sigma=0``); a user calibration records
the options that differ from the defaults. ``get_feature(name, **options)`` takes the scale and the channel counts
N_E, κ of the calibration measured with exactly these options (numbers compare by value), and records the options on
the instance (:attr:`Feature.options`). When none was, it uses the default options' numbers and warns once, naming
the commands that measure them.
"""

from __future__ import annotations

import importlib
import inspect
import json
import os
import re
import threading
import warnings
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, get_args

import numpy as np

from dmtrack.errors import InputError
from dmtrack.features.images import (  # noqa: F401 - re-exported: the image helpers' home before images.py
    downsample_feature,
    downsample_image,
    iter_images,
    prepare_image,
)
from dmtrack.features.tables import (  # noqa: F401 - re-exported: the calibration tables' home before tables.py
    changed_options,
    default_scales_table,
    options_match,
    user_dir,
    user_pca_path,
    user_scales,
    user_scales_path,
)
from dmtrack.io.atomic import write_text

PyramidPolicy = Literal["downsample", "recompute"]
_PYRAMID_POLICIES: tuple[str, ...] = get_args(PyramidPolicy)

#: Optional modules imported once (if present) to register more features, e.g. the learned (torch) ones.
PLUGIN_MODULES: tuple[str, ...] = ("dmtrack.features.learned",)

_NAME_RE = re.compile(r"^[a-z0-9][a-z0-9_.]*(?:-[a-z0-9_.]+)*$")
_PCA_RE = re.compile(r"^(?P<base>.+)-pca(?P<k>[0-9]+)$")
#: Factory of the PCA-reduced features ``BASE-pcaK``, imported when one is built, like every string factory:
#: ``factory(build_base, basis, k=K, scale=...)`` (:func:`dmtrack.features.pca.reduce_feature`).
PCA_FACTORY = "dmtrack.features.pca:reduce_feature"


# ---------------------------------------------------------------------------------------------- feature
class Feature(ABC):
    """A dense per-pixel feature (paper §2.1).

    Class attributes (instances may override them, e.g. when options change the channel count):

    ``name`` – registry name; ``channels`` – N; ``needs_colour`` – uses the RGB input (grey input is then
    replicated); ``needs_torch`` / ``needs_weights`` – needs PyTorch / downloaded weights; ``pyramid`` – pyramid
    policy: ``"downsample"`` (box-downsample the level-0 feature map) or ``"recompute"`` (compute the feature on
    the 2×2-box-downsampled image); ``affine_brightness`` – the odometry switches on LSD-SLAM's affine
    brightness estimation (Gray-A); ``description`` – one line for listings.

    Subclasses implement :meth:`_compute`.

    Parameters
    ----------
    scale : float
        Default feature scale (paper §2.4) multiplied into the output; must be finite and > 0.
    """

    name: str = ""
    channels: int = 0
    needs_colour: bool = False
    needs_torch: bool = False
    needs_weights: bool = False
    pyramid: PyramidPolicy = "downsample"
    affine_brightness: bool = False
    description: str = ""
    #: Where the map is computed: ``"cpu"`` (the CPU kernels) or ``"cuda:N"`` (:mod:`dmtrack.features.device`).
    device: str = "cpu"

    def __init__(self, scale: float = 1.0) -> None:
        self.scale = check_scale(scale)

    # -- to implement
    @abstractmethod
    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        """Feature map times ``gain``.

        Parameters
        ----------
        image : np.ndarray
            Output of :func:`prepare_image` for ``self.needs_colour``: ``(H, W)`` grey or ``(H, W, 3)`` RGB,
            ``uint8`` or ``float32`` in 0..255.
        gain : float
            Factor to multiply into the result (the scale, or 1 for :meth:`compute_unscaled`).

        Returns
        -------
        np.ndarray
            ``(H, W, channels)`` float32.
        """

    # -- public
    def compute(self, image: np.ndarray) -> np.ndarray:
        """Feature map of ``image`` multiplied by :attr:`scale`.

        Parameters
        ----------
        image : np.ndarray
            ``uint8`` (or float, 0..255) ``(H, W)`` grey or ``(H, W, 3)`` RGB image.

        Returns
        -------
        np.ndarray
            ``(H, W, N)`` float32, C-contiguous.
        """
        return self._run(image, self.scale)

    def compute_unscaled(self, image: np.ndarray) -> np.ndarray:
        """Feature map without the default scale (scale 1); same shapes as :meth:`compute`."""
        return self._run(image, 1.0)

    def compute_pyramid(self, image: np.ndarray, n_levels: int) -> list[np.ndarray]:
        """Feature maps of an ``n_levels`` pyramid following :attr:`pyramid`.

        Level l+1 is the per-channel 2×2 box mean of level l (``"downsample"``) or the feature of the 2×2
        box-downsampled image of level l (``"recompute"``, float input).

        Returns
        -------
        list of np.ndarray
            ``n_levels`` float32 ``(H >> l, W >> l, N)`` maps (scaled).
        """
        if n_levels < 1:
            raise InputError(f"n_levels must be ≥ 1, got {n_levels}")
        img = prepare_image(image, self.needs_colour)
        maps = [self._run(img, self.scale)]
        for _ in range(1, n_levels):
            if self.pyramid == "recompute":
                img = downsample_image(img)
                maps.append(self._run(img, self.scale))
            else:
                maps.append(downsample_feature(maps[-1]))
        return maps

    #: The options this instance was built with, recorded by :func:`get_feature` (defaults filled in); ``None``
    #: for an instance constructed directly, which is then looked up as if built with its defaults.
    options: dict[str, Any] | None = None

    def _channel_stat(self, key: str, power: int) -> float | None:
        if int(self.channels) == 1:
            return 1.0
        cal = channel_calibration(self.name, self.options)
        if cal is None and self.options is not None:  # options measured by nobody: the defaults' (get_feature warns)
            cal = channel_calibration(self.name)
        if cal is None:
            return None
        value = cal.get(key)
        if value is None and key == "noise_energy_channels" and cal.get("noise_var") and cal.get("grey_noise_var"):
            value = int(self.channels) * float(cal["noise_var"]) / float(cal["grey_noise_var"])
        if value is None:
            return None
        return float(value) * (float(self.scale) / float(cal["scale"])) ** power

    @property
    def energy_channels(self) -> float | None:
        """N_E, the gradient-energy channel count E[Σ_c|∇F_c|²]/E[|∇I|²] at this instance's scale (odometry
        ``channel_cost="balanced"``; docs/multichannel-cost.md): 1 for a 1-channel feature, else the value
        measured by :func:`dmtrack.features.scale.measure_channel_statistics` (``default_scales.json``, or the
        registry entry), times (scale / measured scale)². ``None`` when not measured (the odometry uses N)."""
        return self._channel_stat("energy_channels", 2)

    @property
    def info_channels(self) -> float | None:
        """κ, the grey-equivalent number of independent channels at this instance's scale (odometry
        ``channel_cost="balanced"``): 1 for a 1-channel feature, else the measured value (as
        :attr:`energy_channels`) times (measured scale / scale)². ``None`` when not measured (the odometry uses 1)."""
        return self._channel_stat("info_channels", -2)

    @property
    def noise_energy_channels(self) -> float | None:
        """N_σ, the noise-energy channel count Σ_c σ_c² / σ_g² at this instance's scale (odometry
        ``channel_cost="balanced"``'s good/bad test; docs/multichannel-cost.md): 1 for a 1-channel feature, else
        N·noise_var/grey_noise_var as measured by :func:`dmtrack.features.scale.measure_channel_statistics`
        (``default_scales.json``, or the registry entry), times (scale / measured scale)². ``None`` when not
        measured (the odometry then adds no noise term)."""
        return self._channel_stat("noise_energy_channels", 2)

    def info(self) -> dict[str, Any]:
        """Description of this instance (the same keys as :func:`list_features`)."""
        return {
            "name": self.name,
            "channels": int(self.channels),
            "needs_colour": bool(self.needs_colour),
            "needs_torch": bool(self.needs_torch),
            "needs_weights": bool(self.needs_weights),
            "pyramid": self.pyramid,
            "scale": float(self.scale),
            "device": self.device,
            "description": self.description,
        }

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, channels={self.channels}, scale={self.scale:g})"

    # -- internals
    def _run(self, image: np.ndarray, gain: float) -> np.ndarray:
        img = prepare_image(image, self.needs_colour)
        out = self._compute(img, float(gain))
        if out.ndim == 2 and self.channels == 1:
            out = out[:, :, None]
        expected = (img.shape[0], img.shape[1], int(self.channels))
        if out.shape != expected:
            raise RuntimeError(f"feature {self.name!r} returned shape {out.shape}, expected {expected}")
        return np.ascontiguousarray(out, dtype=np.float32)


def check_scale(scale: float) -> float:
    """Validate a feature scale (finite, > 0) and return it as a float; :class:`InputError` otherwise."""
    try:
        s = float(scale)
    except (TypeError, ValueError):
        raise InputError(f"feature scale must be a number, got {scale!r}") from None
    if not np.isfinite(s) or s <= 0:
        raise InputError(f"feature scale must be finite and > 0, got {scale!r}")
    return s


# -------------------------------------------------------------------------------------- default scales
def save_user_scale(name: str, scale: float, options: dict[str, Any] | None = None, **details: Any) -> Path:
    """Store a calibrated scale for ``name`` built with ``options`` in the user's table (atomically; one entry per
    name, the options that differ from the defaults recorded with it); returns the file."""
    path = user_scales_path()
    scales = user_scales()
    changed = {k: os.fspath(v) if isinstance(v, os.PathLike) else v
               for k, v in changed_options(options, option_defaults(name) if options else {}).items()}
    scales[name] = {"scale": check_scale(scale), **({"options": changed} if changed else {}), **details}
    write_text(path, json.dumps({"scales": scales}, indent=2) + "\n")
    return path


def option_defaults(name: str) -> dict[str, Any]:
    """The options of feature ``name`` with their default values (the factory's keyword defaults, ``scale``
    excluded); imports the feature's module. Empty for an unknown name."""
    entry = _entries().get(name)
    if entry is None:
        return {}
    try:
        sig = inspect.signature(entry.resolve())
    except (TypeError, ValueError):  # pragma: no cover - builtins without signature
        return {}
    return {
        p.name: p.default
        for p in sig.parameters.values()
        if p.name != "scale" and p.default is not inspect.Parameter.empty
        and p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    }


def _calibration_entries(name: str) -> Iterator[tuple[str, dict[str, Any]]]:
    """The packaged calibrations of ``name``: its ``default_scales.json`` entry, then that entry's ``variants``
    (the same keys, measured with other options), then the registry's values (measured with the defaults)."""
    entry = default_scales_table()["scales"].get(name)
    if entry:
        yield "default_scales.json", entry
        for variant in entry.get("variants", ()):
            yield "default_scales.json", variant
    reg = _entries().get(name)
    if reg is not None and reg.scale is not None:
        yield "registry", {"scale": reg.scale, "energy_channels": reg.energy_channels,
                           "info_channels": reg.info_channels, "noise_energy_channels": reg.noise_energy_channels}


def channel_calibration(name: str, options: dict[str, Any] | None = None) -> dict[str, Any] | None:
    """The packaged calibration of feature ``name`` built with ``options`` (``None``: its defaults): a dict with
    ``scale`` and, where measured, ``energy_channels`` (N_E) and ``info_channels`` (κ) at that scale; ``None``
    when no packaged calibration was measured with these options."""
    if options is None:  # the defaults: the first entry is measured with them (without importing the feature)
        return next((entry for _, entry in _calibration_entries(name)), None)
    defaults = option_defaults(name)
    for _, entry in _calibration_entries(name):
        if options_match(entry.get("options"), options, defaults):
            return entry
    return None


def default_scale(name: str, options: dict[str, Any] | None = None) -> float | None:
    """Default scale of feature ``name`` built with ``options`` (``None``: its defaults): the user's calibration
    if one was saved for these options, else ``default_scales.json``'s (its entry or a variant measured with these
    options), else None."""
    user = user_scales().get(name)
    if options is None:  # the defaults (without importing the feature: list_features never imports torch)
        found = user if user is not None and not user.get("options") else default_scales_table()["scales"].get(name)
        return None if found is None else float(found["scale"])
    defaults = option_defaults(name)
    if user is not None and options_match(user.get("options"), options, defaults):
        return float(user["scale"])
    for source, candidate in _calibration_entries(name):
        if source == "default_scales.json" and options_match(candidate.get("options"), options, defaults):
            return float(candidate["scale"])
    return None


# --------------------------------------------------------------------------------------------- registry
@dataclass(frozen=True)
class FeatureEntry:
    """A registry entry: how to build a feature and what it is, without building it.

    ``factory`` is a callable ``factory(scale=..., **options) -> Feature`` or a lazily imported
    ``"package.module:attribute"`` string naming one.
    """

    name: str
    factory: Callable[..., Feature] | str
    channels: int
    needs_colour: bool = False
    needs_torch: bool = False
    needs_weights: bool = False
    pyramid: PyramidPolicy = "downsample"
    scale: float | None = None
    description: str = ""
    energy_channels: float | None = None
    info_channels: float | None = None
    noise_energy_channels: float | None = None

    def resolve(self) -> Callable[..., Feature]:
        """The factory callable (imports its module if given as a string)."""
        if not isinstance(self.factory, str):
            return self.factory
        return _import_factory(self.factory, self.name)

    def default_scale(self, options: dict[str, Any] | None = None) -> float:
        """The scale used when none is given, for ``options`` (``None``: the defaults): the user's or the packaged
        table's calibration for these options, else the default options' (the table's, else the registered one),
        else 1."""
        s = default_scale(self.name, options) if options else None
        if s is None:
            s = default_scale(self.name)
        if s is None:
            s = self.scale
        return 1.0 if s is None else float(s)


def _import_factory(factory: str, name: str) -> Callable[..., Any]:
    """The callable named by a ``"package.module:attribute"`` string (feature ``name``, for messages)."""
    module_name, _, attr = factory.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name and exc.name.split(".")[0] in ("torch", "torchvision"):
            raise InputError(
                f"feature {name!r} needs PyTorch, which is not installed "
                "(pip install 'dmtrack[learned]')"
            ) from exc
        raise
    try:
        return getattr(module, attr)
    except AttributeError:
        raise RuntimeError(f"feature {name!r}: {module_name} has no attribute {attr!r}") from None


_REGISTRY: dict[str, FeatureEntry] = {}
_LOCK = threading.RLock()
_PLUGINS_LOADED = False


def register(
    name: str,
    factory: Callable[..., Feature] | str,
    *,
    channels: int,
    needs_colour: bool = False,
    needs_torch: bool = False,
    needs_weights: bool = False,
    pyramid: PyramidPolicy = "downsample",
    scale: float | None = None,
    description: str = "",
    replace: bool = False,
    energy_channels: float | None = None,
    info_channels: float | None = None,
    noise_energy_channels: float | None = None,
) -> FeatureEntry:
    """Register a feature under ``name``.

    Parameters
    ----------
    name : str
        Lower-case name (letters, digits, ``_``, ``.``, ``-``); must not end in ``-pcaK`` (reserved for PCA).
    factory : callable or str
        ``factory(scale=float, **options) -> Feature``, or ``"package.module:attribute"`` imported on first use
        (use this for features that need torch).
    channels : int
        N (the channels of the default options).
    needs_colour, needs_torch, needs_weights, pyramid, description
        As the :class:`Feature` attributes.
    scale : float, optional
        Default scale used when ``default_scales.json`` has no entry for ``name``.
    energy_channels, info_channels, noise_energy_channels : float, optional
        N_E, κ and N_σ (N·noise_var/grey_noise_var) measured at ``scale``
        (:func:`dmtrack.features.scale.measure_channel_statistics`), used when ``default_scales.json`` has none
        for ``name``.
    replace : bool
        Allow replacing an existing entry.

    Returns
    -------
    FeatureEntry
    """
    if not isinstance(name, str) or not _NAME_RE.match(name) or _PCA_RE.match(name):
        raise ValueError(f"invalid feature name {name!r}")
    if isinstance(factory, str):
        if ":" not in factory:
            raise ValueError(f"a string factory must be 'package.module:attribute', got {factory!r}")
    elif not callable(factory):
        raise ValueError(f"factory for {name!r} must be callable or a 'module:attribute' string")
    if int(channels) < 1:
        raise ValueError(f"channels must be ≥ 1, got {channels}")
    if pyramid not in _PYRAMID_POLICIES:
        raise ValueError(f"pyramid must be one of {_PYRAMID_POLICIES}, got {pyramid!r}")
    if scale is not None:
        scale = check_scale(scale)
    entry = FeatureEntry(
        name=name,
        factory=factory,
        channels=int(channels),
        needs_colour=bool(needs_colour),
        needs_torch=bool(needs_torch),
        needs_weights=bool(needs_weights),
        pyramid=pyramid,
        scale=scale,
        description=description,
        energy_channels=None if energy_channels is None else float(energy_channels),
        info_channels=None if info_channels is None else float(info_channels),
        noise_energy_channels=None if noise_energy_channels is None else float(noise_energy_channels),
    )
    with _LOCK:
        if name in _REGISTRY and not replace:
            raise ValueError(f"feature {name!r} is already registered")
        _REGISTRY[name] = entry
    return entry


def unregister(name: str) -> None:
    """Remove ``name`` from the registry (no error when absent)."""
    with _LOCK:
        _REGISTRY.pop(name, None)


def _load_plugins() -> None:
    global _PLUGINS_LOADED
    with _LOCK:
        if _PLUGINS_LOADED:
            return
        _PLUGINS_LOADED = True
        for module_name in PLUGIN_MODULES:
            try:
                importlib.import_module(module_name)
            except ModuleNotFoundError as exc:
                if exc.name is None or not module_name.startswith(exc.name):
                    raise


def _entries() -> dict[str, FeatureEntry]:
    _load_plugins()
    return _REGISTRY


def feature_names() -> list[str]:
    """Registered feature names, in registration order."""
    return list(_entries())


def get_entry(name: str) -> FeatureEntry:
    """The registry entry of ``name``; :class:`InputError` listing the known names otherwise."""
    entries = _entries()
    key = name.strip().lower() if isinstance(name, str) else name
    if key not in entries:
        raise InputError(
            f"unknown feature {name!r}; known features: {', '.join(entries)} "
            "(a PCA-reduced feature is named BASE-pcaK, e.g. alexnet-pca8)"
        )
    return entries[key]


def _accepted_options(factory: Callable[..., Any]) -> tuple[set[str], bool]:
    try:
        sig = inspect.signature(factory)
    except (TypeError, ValueError):  # pragma: no cover - builtins without signature
        return set(), True
    names = {
        p.name
        for p in sig.parameters.values()
        if p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
    }
    var_kw = any(p.kind == inspect.Parameter.VAR_KEYWORD for p in sig.parameters.values())
    return names, var_kw


def _build(entry: FeatureEntry, scale: float | None, options: dict[str, Any]) -> Feature:
    factory = entry.resolve()
    accepted, var_kw = _accepted_options(factory)
    if "device" in options and "device" not in accepted:
        _cpu_only(entry.name, options.pop("device"))
    unknown = sorted(k for k in options if k not in accepted)
    if unknown and not var_kw:
        allowed = sorted(accepted - {"scale"})
        raise InputError(
            f"feature {entry.name!r} has no option(s) {', '.join(unknown)}; "
            f"its options are: {', '.join(allowed) if allowed else '(none)'}"
        )
    if scale is not None:
        s = check_scale(scale)
    elif options:
        s = entry.default_scale(options)
    else:
        s = entry.default_scale()
    try:
        feature = factory(scale=s, **options)
    except InputError:
        raise
    except (TypeError, ValueError) as exc:
        raise InputError(f"feature {entry.name!r}: {exc}") from exc
    if options and isinstance(feature, Feature):
        defaults = option_defaults(entry.name)
        feature.options = {**defaults, **options}
        if not options_match(None, options, defaults):
            _warn_uncalibrated(feature, entry, defaults, given_scale=scale is not None)
    return feature


def _cpu_only(name: str, device: Any) -> None:
    """A feature without a device path asked for ``device``: fine for ``"auto"``/``"cpu"``; for a GPU, the clear
    error when there is none (:func:`~dmtrack.features.device.resolve_device`), else a warning that it runs on the
    CPU."""
    from dmtrack.features.device import check_device, resolve_device

    if check_device(device) in ("auto", "cpu"):
        return
    resolve_device(device)
    warnings.warn(f"feature {name!r} has no GPU path: it runs on the CPU (device= applies to the network features)",
                  UserWarning, stacklevel=4)


def _warn_uncalibrated(feature: Feature, entry: FeatureEntry, defaults: dict[str, Any], given_scale: bool) -> None:
    """Warn once per (feature, options) when non-default options have no calibration of their own, so that the
    defaults' scale (without ``scale=``) and N_E, κ (multichannel) stand in for it. ``defaults``: the feature's
    option defaults (:func:`option_defaults`)."""
    options = feature.options or {}
    changed = changed_options(options, defaults)
    missing = []
    scale_missing = not given_scale and default_scale(entry.name, options) is None \
        and (default_scale(entry.name) is not None or entry.scale is not None)
    if scale_missing:
        missing.append(f"default scale (using the default options' {entry.default_scale():g})")
    # a class that overrides the channel-count properties brings its own numbers (tracknet: its weights file's)
    own_counts = type(feature).energy_channels is not Feature.energy_channels
    counts = int(feature.channels) > 1 and not own_counts and channel_calibration(entry.name, options) is None \
        and channel_calibration(entry.name) is not None
    if counts:
        missing.append("channel counts N_E, κ (using the default options', rescaled to its scale)")
    if not missing:
        return
    key = (entry.name, tuple(sorted((k, repr(v)) for k, v in changed.items())))
    if key in _WARNED:
        return
    _WARNED.add(key)
    opts = ", ".join(f"{k}={v!r}" for k, v in sorted(changed.items()))
    cli_opts = " ".join(f"--feature-opt {k}={v}" for k, v in sorted(changed.items()))
    how = []
    if scale_missing:
        how.append(f"`dmtrack calibrate-scale --feature {entry.name} {cli_opts} SEQUENCE... --save` (or pass scale=)")
    if counts:
        spec = ":".join([entry.name, *(f"{k}={v}" for k, v in sorted(changed.items()))])
        how.append(f"`python -m dmtrack.features.scale --channels --features {spec} FRAMES...`, then "
                   "--set energy_channels=N_E --set info_channels=κ")
    warnings.warn(
        f"feature {entry.name!r} with {opts} has no calibration of its own: {'; '.join(missing)}. "
        f"Measure it with {' and '.join(how)}.",
        UserWarning,
        stacklevel=4,
    )


_WARNED: set[tuple[str, tuple[tuple[str, str], ...]]] = set()


def get_feature(name: str, **options: Any) -> Feature:
    """Build the feature registered as ``name``.

    Parameters
    ----------
    name : str
        A registered name (see :func:`list_features`), or ``BASE-pcaK`` for the first K principal components
        of ``BASE`` (needs ``pca=``).
    **options
        ``scale`` (float; default: the calibrated default scale, see module docs) and the feature's own
        options (e.g. ``sigma0``/``sigma1`` for bitplanes, ``cell_size`` for dsift).  For ``BASE-pcaK``:
        ``pca`` (a :class:`~dmtrack.features.pca.PcaBasis` or a ``.npz`` path), ``base_scale`` (scale of the
        base feature) and the base feature's options; ``scale`` then scales the reduced output.

    Returns
    -------
    Feature

    Raises
    ------
    InputError
        Unknown name (the message lists the known ones), unknown option, missing PCA basis, missing torch.
    """
    if not isinstance(name, str) or not name.strip():
        raise InputError(f"feature name must be a non-empty string, got {name!r}")
    key = name.strip().lower()
    scale = options.pop("scale", None)
    entries = _entries()
    m = _PCA_RE.match(key)
    if m is not None and key not in entries:
        base_entry = get_entry(m.group("base"))
        k = int(m.group("k"))
        basis = options.pop("pca", None)
        base_scale = options.pop("base_scale", None)
        if basis is None:
            for candidate in (user_pca_path(base_entry.name, k), user_pca_path(base_entry.name)):
                if candidate.is_file():
                    basis = candidate
                    break
        if basis is None:
            raise InputError(
                f"feature {name!r} needs a PCA basis: none in {user_pca_path(base_entry.name, k).parent}; fit one with "
                f"`dmtrack fit-pca --feature {base_entry.name} --k {k} SEQUENCE...` or pass pca=PATH to a .npz"
            )
        reduce = _import_factory(PCA_FACTORY, key)
        return reduce(lambda: _build(base_entry, base_scale, options), basis, k=k, scale=scale)
    return _build(get_entry(key), scale, options)


def as_feature(feature: str | Feature, **options: Any) -> Feature:
    """``feature`` itself if it is a :class:`Feature` (or has ``compute``), else ``get_feature(feature, **options)``."""
    if isinstance(feature, str):
        return get_feature(feature, **options)
    if options:
        raise InputError("feature options can only be given with a feature name")
    if not hasattr(feature, "compute"):
        raise InputError(f"not a feature: {feature!r}")
    return feature


def pca_variants() -> list[str]:
    """The ``BASE-pcaK`` names :func:`get_feature` builds without ``pca=``: those of the bases fitted for a
    registered ``BASE`` in the user's PCA folder (``BASE-pcaK.npz``, :func:`user_pca_path`), sorted."""
    folder = user_pca_path("").parent
    if not folder.is_dir():
        return []
    entries = _entries()
    names = []
    for path in folder.glob("*-pca*.npz"):
        m = _PCA_RE.match(path.stem)
        if m is not None and m.group("base") in entries and path.is_file():
            names.append(path.stem)
    return sorted(names)


def list_features() -> list[dict[str, Any]]:
    """Every selectable feature name (without building them or importing torch).

    The registered features, then the PCA-reduced ``BASE-pcaK`` whose basis is fitted in the user's PCA folder
    (:func:`pca_variants`; they also have ``pca_of`` = BASE). Any other ``BASE-pcaK`` needs ``pca=FILE.npz``.

    Returns
    -------
    list of dict
        Keys ``name``, ``channels``, ``needs_colour``, ``needs_torch``, ``needs_weights``, ``pyramid``,
        ``scale`` (the default scale; None for PCA variants), ``description``.
    """
    entries = _entries()
    out = []
    for e in entries.values():
        out.append(
            {
                "name": e.name,
                "channels": e.channels,
                "needs_colour": e.needs_colour,
                "needs_torch": e.needs_torch,
                "needs_weights": e.needs_weights,
                "pyramid": e.pyramid,
                "scale": e.default_scale(),
                "description": e.description,
            }
        )
    for name in pca_variants():
        m = _PCA_RE.match(name)
        assert m is not None  # pca_variants only returns matching names
        base = entries[m.group("base")]
        out.append(
            {
                "name": name,
                "channels": int(m.group("k")),
                "needs_colour": base.needs_colour,
                "needs_torch": base.needs_torch,
                "needs_weights": base.needs_weights,
                "pyramid": base.pyramid,
                "scale": None,
                "description": f"{base.name} reduced to its first {m.group('k')} principal components "
                f"(basis {user_pca_path(base.name, int(m.group('k')))})",
                "pca_of": base.name,
            }
        )
    return out


# ------------------------------------------------------------------------------------ built-in entries
register(
    "gray", "dmtrack.features.gray:GrayFeature", channels=1, scale=1.0,
    description="grey intensity 0..255 (LSD-SLAM baseline)",
)
register(
    "gray-affine", "dmtrack.features.gray:GrayAffineFeature", channels=1, scale=1.0,
    description="grey intensity with LSD-SLAM's affine brightness estimation (Gray-A)",
)
register(
    "rgb", "dmtrack.features.colour:RgbFeature", channels=3, needs_colour=True,
    description="R, G, B channels 0..255, chroma low-passed (Gaussian 2 px; chroma_sigma=0: plain)",
)
register(
    "lab", "dmtrack.features.colour:LabFeature", channels=3, needs_colour=True,
    description="CIE L*a*b* (sRGB, D65) in OpenCV's 8-bit ranges: 2.55·L*, a*+128, b*+128 (float), a*/b* low-passed "
    "(Gaussian 2 px; chroma_sigma=0: plain)",
)
register(
    "bitplanes", "dmtrack.features.bitplanes:BitPlanesFeature", channels=8, pyramid="recompute",
    description="Bit-Planes: 8 census-transform bits of the 3x3 neighbourhood (Alismail et al.)",
)
register(
    "dsift", "dmtrack.features.dsift:DenseSiftFeature", channels=128,
    description="dense SIFT at every pixel, single scale, no orientation (SIFT flow style, 4x4 cells x 8 bins)",
)
register(  # scale, N_E, κ and N_σ measured like default_scales.json's on its 20 sample frames (weights/TRACKNET.md)
    "tracknet", "dmtrack.features.tracknet:TrackNetFeature", channels=8, scale=78.403, energy_channels=3.348,
    info_channels=2.755, noise_energy_channels=27.432,
    description="small CNN trained through the tracker's alignment (synthetic + 7-Scenes pairs: weights/TRACKNET.md)",
)
