"""Dense per-pixel evaluation of a patch-descriptor CNN: the plumbing shared by the Siamese and TFeat features.

A patch descriptor maps the P×P grey patch around a pixel to a D-dimensional vector. Evaluating it at every
pixel of an image is the same job for every such network; a network only says what its layers are. This module
holds the job, :class:`PatchNet` the description (a subclass per network, e.g. :mod:`dmtrack.features.siamese`,
:mod:`dmtrack.features.tfeat`) and :class:`DensePatchFeature` the :class:`~dmtrack.features.base.Feature` built on
it.

Patch geometry: the patch of pixel (y, x) covers rows ``y - P//2 .. y + P - P//2 - 1`` (and the same columns);
the image is extended by reflection (OpenCV's BORDER_REFLECT_101) for patches that leave it.

Three evaluations, each with a numpy (BLAS) and an optional PyTorch backend:

* :meth:`PatchNet.forward_patches` – the reference per-patch forward pass of a batch of patches;
* :meth:`PatchNet.dense` – "shift-and-stitch": every strided layer / pool becomes a stride-1 one and the later
  layers are dilated by the accumulated stride, so that one pass over the (already normalised, padded) image
  gives the per-patch output at every pixel; the input is :meth:`PatchNet.local_normalise`, every pixel
  normalised with the statistics of *its own* P×P window (the ``"local"`` mode of the features);
* :meth:`PatchNet.exact` – the per-patch normalisation (each patch by its own statistics, the ``"patch"`` mode):
  the first convolution (and its pool) is computed once for the whole image by the network's
  :meth:`PatchNet.exact_stem`, its per-patch part is finished for a batch of pixels at a time, and the
  remaining layers (:meth:`PatchNet.tail_torch` / :meth:`PatchNet.tail_numpy`) run per pixel.
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any

import cv2
import numpy as np

from dmtrack.errors import InputError
from dmtrack.features import _nn
from dmtrack.features.base import Feature
from dmtrack.features.device import DeviceFeatureMixin
from dmtrack.features.weights import find_weights, load_weights

#: The two evaluation modes of a :class:`DensePatchFeature` (``normalise=``).
MODES = ("local", "patch")

#: What :meth:`PatchNet.exact_stem` returns: the pooled first-layer map of the whole image and the function
#: ``first(g, pixels)`` that finishes the first layer (per-patch normalisation, bias, activation) on the
#: ``(B, n, n, C)`` samples ``g`` of that map for the ``(B, 2)`` pixels.
Stem = tuple[np.ndarray, Callable[[np.ndarray, np.ndarray], np.ndarray]]


def reflect_pad(gray: np.ndarray, patch: int) -> np.ndarray:
    """``gray`` as float32, extended by reflection by the rows/columns a ``patch``-sized patch reaches outside it
    (``patch // 2`` before, ``patch - patch // 2 - 1`` after)."""
    before, after = patch // 2, patch - patch // 2 - 1
    return cv2.copyMakeBorder(np.asarray(gray, np.float32), before, after, before, after, cv2.BORDER_REFLECT_101)


def select_pixels(pixels: np.ndarray | None, h: int, w: int) -> np.ndarray:
    """``(M, 2)`` integer ``(row, col)`` pixels to evaluate: all pixels of an ``h``×``w`` image in row-major
    order when ``pixels`` is None, else ``pixels`` (checked to lie inside the image)."""
    if pixels is None:
        rows, cols = np.mgrid[0:h, 0:w]
        return np.stack([rows.ravel(), cols.ravel()], axis=1)
    pix = np.asarray(pixels, np.int64).reshape(-1, 2)
    if pix.size and (pix.min() < 0 or (pix[:, 0] >= h).any() or (pix[:, 1] >= w).any()):
        raise InputError(f"pixels must lie inside the {h}x{w} image")
    return pix


class PatchNet(ABC):
    """A patch-descriptor network as the dense evaluator needs it (subclass per network; stateless).

    Class attributes: ``label`` (its name in messages), ``patch`` (P), ``dim`` (D), ``window_eps`` (added to the
    windows' biased variance of :meth:`local_normalise`), ``exact_grid`` (``(step, count)``: the per-pixel layers
    read ``count``×``count`` samples, ``step`` apart, of the stem's pooled map), ``exact_batch`` (pixels per batch
    of :meth:`exact`) and ``exact_chunk`` (pixels per call of :meth:`tail_numpy`, to keep its im2col buffer small).
    """

    label: str = ""
    patch: int = 0
    dim: int = 0
    window_eps: float = 0.0
    exact_grid: tuple[int, int] = (1, 1)
    exact_batch: int = 1024
    exact_chunk: int = 64

    # -- the network's layers
    @abstractmethod
    def patch_torch(self, torch: Any, t: Any, p: dict[str, Any]) -> Any:
        """Per-patch forward pass of the ``(B, 1, P, P)`` tensor ``t`` (weights ``p`` as tensors): ``(B, D, ...)``."""

    @abstractmethod
    def patch_numpy(self, patch: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        """Forward pass of one ``(P, P)`` float32 patch: the ``(D,)`` descriptor."""

    @abstractmethod
    def normalise_windows(self, p: np.ndarray, mean: np.ndarray, std: np.ndarray) -> np.ndarray:
        """The ``"local"`` input from the padded image ``p`` and the mean / std of each pixel's window."""

    @abstractmethod
    def dense_torch(self, torch: Any, t: Any, p: dict[str, Any], params: dict[str, np.ndarray]) -> Any:
        """Shift-and-stitch pass of the ``(1, 1, H + P - 1, W + P - 1)`` tensor ``t``: ``(1, D, H, W)``."""

    def dense_params(self, params: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Arrays :meth:`dense_torch` reads from ``p`` besides the weights (kept on the device with them); it
        builds them from ``params`` when ``p`` lacks them."""
        return {}

    @abstractmethod
    def dense_numpy(self, x: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        """Shift-and-stitch pass of the ``(H + P - 1, W + P - 1)`` input: a new ``(H, W, D)`` float32 array."""

    @abstractmethod
    def exact_stem(self, gray: np.ndarray, params: dict[str, np.ndarray]) -> Stem:
        """First layer of :meth:`exact` on the ``(H, W)`` float32 image (see :data:`Stem`)."""

    @abstractmethod
    def tail_torch(self, torch: Any, t: Any, p: dict[str, Any]) -> Any:
        """The layers after the stem on the ``(B, C, n, n)`` tensor ``t``: ``(B, D, ...)``."""

    @abstractmethod
    def tail_numpy(self, g: np.ndarray, params: dict[str, np.ndarray]) -> np.ndarray:
        """The layers after the stem on ``(b, n, n, C)`` float32 samples: ``(b, D)``."""

    # -- evaluation
    def check_patches(self, patches: np.ndarray) -> np.ndarray:
        """``patches`` as a ``(B, P, P)`` float32 array; :class:`InputError` for another shape."""
        x = np.asarray(patches, np.float32)
        if x.ndim != 3 or x.shape[1:] != (self.patch, self.patch):
            raise InputError(f"{self.label} patches must be (B, {self.patch}, {self.patch}), got {x.shape}")
        return x

    def forward_patches(self, patches: np.ndarray, params: dict[str, np.ndarray], backend: str = "auto") -> np.ndarray:
        """Reference per-patch forward pass: ``(B, P, P)`` (as the network expects them) → ``(B, D)`` float32."""
        x = self.check_patches(patches)
        if _nn.resolve_backend(backend) == "torch":
            torch = _nn.torch_module()
            p = _nn.torch_params(params)
            with torch.inference_mode():
                t = self.patch_torch(torch, torch.from_numpy(np.ascontiguousarray(x))[:, None], p)
                return t.reshape(t.shape[0], -1).numpy().copy()
        out = np.empty((x.shape[0], self.dim), np.float32)
        for i, patch in enumerate(x):
            out[i] = self.patch_numpy(patch, params)
        return out

    def local_normalise(self, gray: np.ndarray) -> np.ndarray:
        """The ``"local"`` mode's input: the reflect-padded image, ``(H + P - 1, W + P - 1)`` float32, every value
        normalised (:meth:`normalise_windows`) with the statistics of its own P×P window."""
        p = reflect_pad(gray, self.patch)
        pp = reflect_pad(p, self.patch)
        mean, std = _nn.box_mean_std(pp, self.patch, self.window_eps)
        return self.normalise_windows(p, mean, std).astype(np.float32)

    def dense(
        self, x: np.ndarray, params: dict[str, np.ndarray], gain: float = 1.0, backend: str = "auto"
    ) -> np.ndarray:
        """Shift-and-stitch evaluation at every P×P window of the normalised input ``x``: ``(H, W, D)`` float32
        times ``gain``, ``out[y, x] = net(x[y : y + P, x : x + P])``."""
        if _nn.resolve_backend(backend) == "torch":
            torch = _nn.torch_module()
            p = _nn.torch_params(params)
            with torch.inference_mode():
                t = torch.from_numpy(np.ascontiguousarray(x, np.float32))[None, None]
                t = self.dense_torch(torch, t, p, params)
                if gain != 1.0:
                    t.mul_(gain)
                return np.ascontiguousarray(t[0].permute(1, 2, 0).numpy())
        out = self.dense_numpy(x, params)
        if gain != 1.0:
            out *= np.float32(gain)
        return out

    def exact(
        self,
        gray: np.ndarray,
        params: dict[str, np.ndarray],
        pixels: np.ndarray | None = None,
        gain: float = 1.0,
        backend: str = "auto",
        batch: int | None = None,
    ) -> np.ndarray:
        """Per-patch normalised evaluation at every pixel (``(H, W, D)``) or at ``pixels`` (``(M, D)``), float32
        times ``gain``; ``batch`` pixels at a time (default :attr:`exact_batch`)."""
        batch = self.exact_batch if batch is None else batch
        gray = np.asarray(gray, np.float32)
        h, w = gray.shape
        rmax, first = self.exact_stem(gray, params)
        pix = select_pixels(pixels, h, w)
        step, count = self.exact_grid
        grid = step * np.arange(count)
        out = np.empty((len(pix), self.dim), np.float32)
        use_torch = _nn.resolve_backend(backend) == "torch"
        if use_torch:
            torch = _nn.torch_module()
            tp = _nn.torch_params(params)
        for s in range(0, len(pix), batch):
            pb = pix[s : s + batch]
            g = first(rmax[pb[:, 0, None, None] + grid[None, :, None], pb[:, 1, None, None] + grid[None, None, :]], pb)
            if use_torch:
                with torch.inference_mode():
                    t = self.tail_torch(torch, torch.from_numpy(np.ascontiguousarray(g)).permute(0, 3, 1, 2), tp)
                    out[s : s + len(pb)] = t.reshape(len(pb), -1).numpy()
            else:
                for i in range(0, len(pb), self.exact_chunk):
                    y = self.tail_numpy(g[i : i + self.exact_chunk], params)
                    out[s + i : s + i + len(y)] = y
        if gain != 1.0:
            out *= np.float32(gain)
        return out.reshape(h, w, self.dim) if pixels is None else out


class DensePatchFeature(DeviceFeatureMixin, Feature):
    """A :class:`~dmtrack.features.base.Feature` evaluating a :class:`PatchNet` at every pixel.

    Subclasses set ``net`` (the :class:`PatchNet`), ``weights_key`` (the catalogue key of its weights,
    :mod:`dmtrack.features.weights`) and the :class:`Feature` attributes.

    Parameters
    ----------
    scale
        Default feature scale.
    weights
        Weight file; default: the catalogue entry ``weights_key`` found by
        :func:`~dmtrack.features.weights.find_weights`.
    normalise
        ``"local"`` (dense, fast; default) or ``"patch"`` (exact per-patch normalisation, slow).
    backend
        ``"auto"`` (PyTorch when installed, else numpy), ``"torch"`` or ``"numpy"``: the CPU kernels.
    device
        ``"auto"`` (a CUDA GPU when PyTorch sees one, else the CPU kernels), ``"cpu"``, ``"cuda"``, ``"cuda:N"``
        (:mod:`dmtrack.features.device`); the device path evaluates the ``"local"`` mode.
    """

    net: PatchNet
    weights_key: str = ""
    needs_colour = False

    def __init__(
        self,
        scale: float,
        weights: str | os.PathLike[str] | None = None,
        normalise: str = "local",
        backend: str = "auto",
        device: Any = "auto",
    ) -> None:
        super().__init__(scale)
        if normalise not in MODES:
            raise InputError(f"normalise must be one of {MODES}, got {normalise!r}")
        self.normalise = normalise
        self.backend = _nn.resolve_backend(backend)
        self.weights_path = find_weights(self.weights_key, weights)
        self.params = load_weights(self.weights_key, self.weights_path)
        self._init_device("cpu" if normalise == "patch" and device == "auto" else device)
        if self.runner is not None:
            if normalise == "patch":
                raise InputError(f"{self.net.label}: normalise='patch' runs on the CPU only (device='cpu')")
            self._device_params = self.runner.params({**self.params, **self.net.dense_params(self.params)})

    def _forward_device(self, image: np.ndarray, gain: float) -> Any:
        """The ``"local"`` mode on the device: ``(1, D, H, W)`` times ``gain`` (the normalisation on the host)."""
        runner = self.runner
        assert runner is not None
        t = runner.tensor(self.net.local_normalise(image))[None, None]
        t = self.net.dense_torch(runner.torch, t, self._device_params, self.params)
        return t.mul_(float(gain)) if gain != 1.0 else t

    def _compute(self, image: np.ndarray, gain: float) -> np.ndarray:
        if self.runner is not None:
            return self._on_device(image, gain)
        if self.normalise == "patch":
            return self.net.exact(image, self.params, gain=gain, backend=self.backend)
        return self.net.dense(self.net.local_normalise(image), self.params, gain, self.backend)
