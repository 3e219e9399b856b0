"""Where the network features run: ``device="auto" | "cpu" | "cuda" | "cuda:N"`` (issue 32, paper §3.4).

The learned features (``alexnet``, ``alexnet64``, ``siamese``, ``tfeat``, ``disk``, ``tracknet`` and their
``-pcaK`` reductions) take a ``device`` option:

* ``"cpu"`` – the CPU kernels (FFT / numba / BLAS / oneDNN), exactly as without the option;
* ``"cuda"``, ``"cuda:N"`` – the network on that GPU through PyTorch; a ``-pcaK`` reduction is applied there too,
  as a 1×1 projection *before* the transfer (with the feature scale folded in), and the K-channel result is
  copied into page-locked (pinned) host memory, from which the odometry reads it without another copy;
* ``"auto"`` (the default) – ``"cuda"`` when PyTorch sees a CUDA device, else ``"cpu"``;
* a :class:`torch.device` – the device path on that device; ``torch.device("cpu")`` runs the GPU code path on the
  CPU, which is how the tests check it on machines without a GPU.

GPU and CPU results differ in the last bits of float32 (another summation order), so their trajectories differ;
each is deterministic on its own: :class:`DeviceRunner` switches cuDNN to deterministic algorithms and off TF32.

:func:`cuda_problem` says in one line why CUDA cannot be used (PyTorch missing, a CPU-only build, no device), and
:func:`gpu_status` describes the GPU for ``dmtrack info`` / ``dmtrack features`` and ``metrics.json``.  Resolving
``"auto"`` imports PyTorch only where an NVIDIA driver is present, so CPU machines do not pay its import.
"""

from __future__ import annotations

import importlib.util
import os
import re
import sys
from typing import Any

import numpy as np

from dmtrack.errors import InputError

_SPEC = re.compile(r"^(auto|cpu|cuda(:\d+)?)$")


def check_device(spec: Any) -> Any:
    """``spec`` normalised (lower case, stripped) when it is a valid device spec; :class:`InputError` otherwise."""
    if _is_torch_device(spec):
        return spec
    if not isinstance(spec, str) or not _SPEC.match(spec.strip().lower()):
        raise InputError(f"device must be 'auto', 'cpu', 'cuda' or 'cuda:N', got {spec!r}")
    return spec.strip().lower()


def _is_torch_device(spec: Any) -> bool:
    torch = sys.modules.get("torch")
    return torch is not None and isinstance(spec, torch.device)


def _driver_present() -> bool:
    """Whether an NVIDIA driver may be present (cheap; no PyTorch import): ``device="auto"`` imports PyTorch only
    then. Off Linux: assume it may. WSL2 reaches the Windows driver through ``/dev/dxg``."""
    if not sys.platform.startswith("linux"):
        return True
    return any(os.path.exists(p) for p in ("/proc/driver/nvidia/version", "/dev/nvidiactl", "/dev/dxg"))


def cuda_problem() -> str | None:
    """None when PyTorch can use a CUDA device, else one line saying what is missing."""
    if importlib.util.find_spec("torch") is None:
        return "PyTorch is not installed (pip install 'dmtrack[learned]' with a CUDA build of torch)"
    import torch

    if not torch.version.cuda:
        return f"PyTorch {torch.__version__} is a CPU-only build (install a CUDA build of torch)"
    # PyTorch is asked first: a driver it can use may live where no file below says so (WSL2's is /dev/dxg)
    if torch.cuda.is_available():
        return None
    if not _driver_present():
        return (f"no NVIDIA driver on this machine (PyTorch {torch.__version__} sees no CUDA device; "
                "/proc/driver/nvidia, /dev/nvidiactl and WSL2's /dev/dxg are absent)")
    return f"PyTorch {torch.__version__} (CUDA {torch.version.cuda}) sees no CUDA device"


def resolve_device(spec: Any) -> Any:
    """The device a feature runs on: ``None`` for the CPU kernels, else a :class:`torch.device`.

    ``"auto"`` gives CUDA device 0 when usable, else None; ``"cuda[:N]"`` without a usable CUDA device raises
    :class:`InputError` with :func:`cuda_problem`'s line.
    """
    spec = check_device(spec)
    if _is_torch_device(spec):
        return spec
    if spec == "cpu":
        return None
    if spec == "auto" and not _driver_present():
        return None  # without importing PyTorch
    problem = cuda_problem()
    if spec == "auto":
        if problem is not None:
            return None
        spec = "cuda"
    elif problem is not None:
        raise InputError(f"device={spec}: {problem}")
    import torch

    dev = torch.device(spec)
    index = 0 if dev.index is None else dev.index
    if index >= torch.cuda.device_count():
        raise InputError(f"device={spec}: only {torch.cuda.device_count()} CUDA device(s) visible")
    return torch.device("cuda", index)


def device_label(dev: Any) -> str:
    """``"cpu"`` for the CPU kernels (None), ``"cuda:N"`` for a GPU, ``"cpu-torch"`` for the device path on the
    CPU."""
    if dev is None:
        return "cpu"
    if dev.type == "cpu":
        return "cpu-torch"
    return f"{dev.type}:{0 if dev.index is None else dev.index}"


def gpu_status() -> dict[str, Any]:
    """What ``dmtrack info`` / ``dmtrack features`` report: ``usable`` (bool), ``reason`` (None or why not),
    ``torch`` (version or None), ``cuda`` (the build's CUDA version or None), ``devices`` (names)."""
    problem = cuda_problem()
    status: dict[str, Any] = {"usable": problem is None, "reason": problem, "torch": None, "cuda": None,
                              "devices": []}  # fmt: skip
    if importlib.util.find_spec("torch") is not None:
        import torch

        status["torch"] = torch.__version__
        status["cuda"] = torch.version.cuda
        if problem is None:
            status["devices"] = [torch.cuda.get_device_name(i) for i in range(torch.cuda.device_count())]
    return status


def gpu_line() -> str:
    """One line for listings: the usable GPUs, or why none is."""
    st = gpu_status()
    if st["usable"]:
        names = ", ".join(st["devices"])
        return f"GPU: usable ({names}; PyTorch {st['torch']}, CUDA {st['cuda']}); --device auto uses it"
    return f"GPU: not usable ({st['reason']}); the network features run on the CPU"


class DeviceRunner:
    """Runs the tensor part of a feature on one torch device and brings the result back.

    It keeps the network's parameters on the device (:meth:`params`), moves inputs there (:meth:`tensor`),
    applies a PCA projection there (:meth:`project`) and copies a ``(1, C, H, W)`` result into a fresh pinned
    host array ``(H, W, C)`` (:meth:`to_host`; PyTorch's caching host allocator reuses the page-locked blocks once
    the odometry drops a frame's map).
    """

    def __init__(self, device: Any) -> None:
        import torch

        self.torch = torch
        self.device = device
        self.cuda = device.type == "cuda"
        self.label = device_label(device)
        self.name = torch.cuda.get_device_name(device) if self.cuda else None
        if self.cuda:  # deterministic: same input, same bits (no autotuned algorithms, no TF32 rounding)
            torch.backends.cudnn.deterministic = True
            torch.backends.cudnn.benchmark = False
            torch.backends.cudnn.allow_tf32 = False
            torch.backends.cuda.matmul.allow_tf32 = False

    def params(self, arrays: dict[str, np.ndarray]) -> dict[str, Any]:
        """numpy weights → float32 tensors on the device (4-D kernels channels-last)."""
        torch = self.torch
        out = {}
        for k, v in arrays.items():
            t = torch.from_numpy(np.ascontiguousarray(v, np.float32)).to(self.device)
            out[k] = t.contiguous(memory_format=torch.channels_last) if t.ndim == 4 else t
        return out

    def tensor(self, array: np.ndarray) -> Any:
        """A host array on the device (same dtype)."""
        return self.torch.from_numpy(np.ascontiguousarray(array)).to(self.device)

    def project(self, y: Any, weight: np.ndarray, bias: np.ndarray) -> Any:
        """``(1, N, H, W)`` → ``(1, K, H, W)``: ``weight (K, N) @ y + bias`` per pixel, on the device."""
        torch = self.torch
        w = torch.from_numpy(np.ascontiguousarray(weight, np.float32)).to(self.device)
        b = torch.from_numpy(np.ascontiguousarray(bias, np.float32)).to(self.device)
        return torch.nn.functional.conv2d(y, w[:, :, None, None].contiguous(memory_format=torch.channels_last), b)

    def to_host(self, y: Any, gain: float = 1.0) -> np.ndarray:
        """``(1, C, H, W)`` (times ``gain``) → ``(H, W, C)`` float32 host array (pinned when on a GPU)."""
        torch = self.torch
        hwc = y[0].permute(1, 2, 0)
        if gain != 1.0:
            hwc = hwc * float(gain)
        if not hwc.is_contiguous():
            hwc = hwc.contiguous()
        if not self.cuda:
            return hwc.numpy() if hwc.dtype == torch.float32 else hwc.float().numpy()
        out = torch.empty(hwc.shape, dtype=torch.float32, pin_memory=True)
        out.copy_(hwc, non_blocking=True)
        torch.cuda.current_stream(self.device).synchronize()
        return out.numpy()


def runner_for(spec: Any) -> DeviceRunner | None:
    """The :class:`DeviceRunner` of a device spec, or None for the CPU kernels."""
    dev = resolve_device(spec)
    return None if dev is None else DeviceRunner(dev)


class DeviceFeatureMixin:
    """The device path of a feature (mixed into its :class:`~dmtrack.features.base.Feature` class).

    The feature calls :meth:`_init_device` in its constructor and, when :attr:`runner` is set, lets :meth:`_on_device`
    produce its map; it implements ``_forward_device(image, gain)``: the ``(1, C, H, W)`` tensor of the prepared
    image times ``gain``, on ``self.runner.device``.
    """

    runner: DeviceRunner | None = None
    device: str = "cpu"
    scale: float
    needs_colour: bool

    def _init_device(self, spec: Any) -> None:
        self.runner = runner_for(spec)
        self.device = "cpu" if self.runner is None else self.runner.label

    def _forward_device(self, image: np.ndarray, gain: float) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError

    def _on_device(self, image: np.ndarray, gain: float) -> np.ndarray:
        runner = self.runner
        assert runner is not None
        with runner.torch.inference_mode():
            return runner.to_host(self._forward_device(image, gain))

    def compute_projected_on_device(self, image: np.ndarray, weight: np.ndarray, bias: np.ndarray) -> np.ndarray:
        """``compute(image) @ weight.T + bias`` per pixel with the projection applied on the device before the
        transfer (:class:`~dmtrack.features.pca.ReducedFeature` on a GPU): ``(H, W, K)`` float32. ``image`` is
        already prepared (:func:`~dmtrack.features.base.prepare_image` for ``self.needs_colour``)."""
        runner = self.runner
        assert runner is not None
        with runner.torch.inference_mode():
            return runner.to_host(runner.project(self._forward_device(image, self.scale), weight, bias))
