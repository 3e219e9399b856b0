"""Small dense-network toolkit shared by the learned features: numpy (BLAS) and optional PyTorch backends.

All numpy arrays here are channels-last ``(H, W, C)`` float32.  Convolutions are *valid* cross-correlations (as
in Caffe, Torch7 and PyTorch) with an optional dilation, computed as im2col + one ``sgemm`` per block of rows,
so that they run at BLAS speed without PyTorch.  "Shift-and-stitch" dense evaluation of a strided patch network
(every stride-s layer / pool replaced by a stride-1 one, and every later layer dilated by the accumulated
stride) is built from :func:`conv2d_hwc` and :func:`maxpool_shift`.

PyTorch is imported only by :func:`torch_module` (when the ``torch`` backend is chosen).

:func:`parallel_for` spreads row / tile blocks of the CPU features (dense SIFT, AlexNet's FFT convolution) over a
process-wide thread pool; :func:`scratch` keeps their large per-thread work arrays between calls.
"""

from __future__ import annotations

import importlib.util
import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Literal

import numpy as np

from dmtrack.errors import InputError

Backend = Literal["auto", "numpy", "torch"]

#: Bytes of im2col buffer per block in :func:`conv2d_hwc`.
IM2COL_BLOCK_BYTES = 48 << 20


_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()


def thread_pool(n: int) -> ThreadPoolExecutor:
    """The process-wide worker pool of the CPU features, with at least ``n`` threads (idle workers block)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is None or _POOL._max_workers < n:  # noqa: SLF001 - ThreadPoolExecutor has no public size
            old, _POOL = _POOL, ThreadPoolExecutor(max_workers=n, thread_name_prefix="dmtrack-features")
            if old is not None:
                old.shutdown(wait=False)
        return _POOL


_SCRATCH = threading.local()


def scratch(name: str, shape: tuple[int, ...], dtype: Any) -> np.ndarray:
    """A per-thread scratch array (uninitialised), kept and reused across calls while ``shape``/``dtype`` stay
    the same (saves the page faults of fresh large arrays).  Never return it, or a view of it, to a caller."""
    arrays = getattr(_SCRATCH, "arrays", None)
    if arrays is None:
        arrays = _SCRATCH.arrays = {}
    a = arrays.get(name)
    if a is None or a.shape != tuple(shape) or a.dtype != np.dtype(dtype):
        a = arrays[name] = np.empty(shape, dtype)
    return a


#: Environment variable overriding the default thread count of :func:`parallel_for`.
THREADS_ENV = "DMTRACK_FEATURE_THREADS"


def default_threads() -> int:
    """Threads for :func:`parallel_for` when none are given: ``$DMTRACK_FEATURE_THREADS`` if set, else numba's
    setting in the calling thread."""
    env = os.environ.get(THREADS_ENV, "").strip()
    if env:
        try:
            return max(1, int(env))
        except ValueError:
            raise InputError(f"${THREADS_ENV} must be an integer, got {env!r}") from None
    import numba

    return int(numba.get_num_threads())


def parallel_for(fn: Callable[[int, int], None], n: int, block: int, threads: int | None = None) -> None:
    """Call ``fn(a, b)`` on the blocks ``[a, b)`` of ``range(n)`` (``block`` items each), on up to ``threads``
    threads (default :func:`default_threads`) that take the next block when done (dynamic schedule).

    ``fn`` should release the GIL (nogil numba kernels, numpy FFTs / BLAS) and write disjoint outputs per block,
    so that the result does not depend on the thread count.  The calling thread is one of the workers; runs
    inline with one thread or one block.  Unlike numba's ``prange``, idle threads block instead of spinning,
    which matters on a 2-core machine shared with the odometry's own parallel kernels.
    """
    block = max(1, int(block))
    starts = range(0, max(0, n), block)
    n_threads = min(default_threads() if threads is None else max(1, int(threads)), len(starts))
    if n_threads <= 1:
        for a in starts:
            fn(a, min(n, a + block))
        return
    it = iter(starts)
    lock = threading.Lock()

    def work() -> None:
        while True:
            with lock:
                a = next(it, None)
            if a is None:
                return
            fn(a, min(n, a + block))

    # the calling thread works too; helpers that have not started when it runs out of blocks are cancelled
    # (so that a call from inside a busy pool cannot wait for itself)
    futures = [thread_pool(n_threads).submit(work) for _ in range(n_threads - 1)]
    try:
        work()
    finally:
        for fut in futures:
            if not fut.cancel():
                fut.result()


def have_torch() -> bool:
    """True when PyTorch is installed (checked without importing it)."""
    return importlib.util.find_spec("torch") is not None


def resolve_backend(backend: str) -> str:
    """``"auto"`` → ``"torch"`` when installed, else ``"numpy"``; validates explicit choices.

    Raises
    ------
    InputError
        Unknown backend, or ``"torch"`` requested without PyTorch installed.
    """
    if backend not in ("auto", "numpy", "torch"):
        raise InputError(f"backend must be 'auto', 'numpy' or 'torch', got {backend!r}")
    if backend == "auto":
        return "torch" if have_torch() else "numpy"
    if backend == "torch" and not have_torch():
        raise InputError("backend='torch' needs PyTorch, which is not installed (pip install 'dmtrack[learned]')")
    return backend


def torch_module() -> Any:
    """Import and return :mod:`torch` (with a clear :class:`InputError` when missing)."""
    try:
        import torch
    except ModuleNotFoundError as exc:  # pragma: no cover - depends on the environment
        raise InputError("this feature needs PyTorch, which is not installed (pip install 'dmtrack[learned]')") from exc
    return torch


def torch_params(params: dict[str, np.ndarray]) -> dict[str, Any]:
    """numpy weights → torch tensors, 4-D kernels in channels-last layout (oneDNN then keeps activations
    channels-last, so the ``(H, W, C)`` result needs no copy)."""
    torch = torch_module()
    out = {}
    for k, v in params.items():
        t = torch.from_numpy(np.ascontiguousarray(v, np.float32))
        out[k] = t.contiguous(memory_format=torch.channels_last) if t.ndim == 4 else t
    return out


def conv2d_hwc(
    x: np.ndarray,
    weight: np.ndarray,
    bias: np.ndarray | None = None,
    dilation: int = 1,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Valid 2-D cross-correlation of a channels-last map (numpy, im2col + BLAS).

    Parameters
    ----------
    x
        ``(H, W, C)`` float32 input.
    weight
        ``(O, C, kh, kw)`` kernels (PyTorch/Caffe layout).
    bias
        ``(O,)`` or None.
    dilation
        Spacing of the kernel taps (1 = ordinary convolution).
    out
        Optional ``(H', W', O)`` float32 C-contiguous output buffer.

    Returns
    -------
    np.ndarray
        ``(H - dilation*(kh-1), W - dilation*(kw-1), O)`` float32:
        ``out[i, j, o] = bias[o] + Σ_{c,u,v} weight[o, c, u, v] · x[i + dilation·u, j + dilation·v, c]``.
    """
    x = np.ascontiguousarray(x, dtype=np.float32)
    o_ch, c_in, kh, kw = weight.shape
    if x.ndim != 3 or x.shape[2] != c_in:
        raise ValueError(f"input {x.shape} does not match kernels {weight.shape}")
    eh, ew = dilation * (kh - 1) + 1, dilation * (kw - 1) + 1
    ho, wo = x.shape[0] - eh + 1, x.shape[1] - ew + 1
    if ho < 1 or wo < 1:
        raise ValueError(f"input {x.shape[:2]} smaller than the dilated kernel ({eh}, {ew})")
    # rows of the im2col matrix are ordered (u, v, c) to match a (kh, kw, C, O) weight matrix
    wmat = np.ascontiguousarray(np.transpose(weight, (2, 3, 1, 0)).reshape(kh * kw * c_in, o_ch), dtype=np.float32)
    if out is None:
        out = np.empty((ho, wo, o_ch), np.float32)
    k = kh * kw * c_in
    rows = max(1, min(ho, IM2COL_BLOCK_BYTES // max(1, wo * k * 4)))
    buf = np.empty((rows, wo, kh, kw, c_in), np.float32)
    for r0 in range(0, ho, rows):
        r1 = min(ho, r0 + rows)
        n = r1 - r0
        cols = buf[:n]
        for u in range(kh):
            src = x[r0 + u * dilation : r1 + u * dilation]
            if dilation == 1:
                # the kw taps of a row are one contiguous run of kw*C values of the flattened row
                win = np.lib.stride_tricks.sliding_window_view(src.reshape(n, -1), kw * c_in, axis=1)[:, ::c_in]
                cols[:, :, u].reshape(n, wo, kw * c_in)[...] = win[:, :wo]
            else:
                for v in range(kw):
                    cols[:, :, u, v, :] = src[:, v * dilation : v * dilation + wo, :]
        res = out[r0:r1].reshape(n * wo, o_ch)
        np.matmul(cols.reshape(n * wo, k), wmat, out=res)
    if bias is not None:
        out += np.asarray(bias, np.float32)
    return out


def conv2d_batch_hwc(x: np.ndarray, weight: np.ndarray, bias: np.ndarray | None = None) -> np.ndarray:
    """Valid cross-correlation of a batch of small channels-last maps (numpy, one im2col + one ``sgemm``).

    Parameters
    ----------
    x
        ``(B, H, W, C)`` float32.
    weight
        ``(O, C, kh, kw)``.
    bias
        ``(O,)`` or None.

    Returns
    -------
    np.ndarray
        ``(B, H - kh + 1, W - kw + 1, O)`` float32.
    """
    o_ch, c_in, kh, kw = weight.shape
    b, h, w, c = x.shape
    if c != c_in:
        raise ValueError(f"input {x.shape} does not match kernels {weight.shape}")
    ho, wo = h - kh + 1, w - kw + 1
    win = np.lib.stride_tricks.sliding_window_view(x, (kh, kw), axis=(1, 2))  # (B, ho, wo, C, kh, kw)
    cols = np.ascontiguousarray(win.transpose(0, 1, 2, 4, 5, 3)).reshape(b * ho * wo, kh * kw * c_in)
    wmat = np.ascontiguousarray(np.transpose(weight, (2, 3, 1, 0)).reshape(kh * kw * c_in, o_ch), dtype=np.float32)
    out = (cols @ wmat).reshape(b, ho, wo, o_ch)
    if bias is not None:
        out += np.asarray(bias, np.float32)
    return out


def maxpool_shift(x: np.ndarray, d: int) -> np.ndarray:
    """Dense (stride-1) form of a 2×2 max-pool whose taps are ``d`` apart.

    ``y[i, j] = max(x[i, j], x[i+d, j], x[i, j+d], x[i+d, j+d])``, shape ``(H-d, W-d, C)``.
    """
    h, w = x.shape[0] - d, x.shape[1] - d
    y = np.maximum(x[:h, :w], x[d : d + h, :w])
    np.maximum(y, x[:h, d : d + w], out=y)
    np.maximum(y, x[d : d + h, d : d + w], out=y)
    return y


def box_mean_std(img: np.ndarray, size: int, eps: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation of every ``size``×``size`` window of a padded grey image.

    Parameters
    ----------
    img
        ``(Hp, Wp)`` padded image.
    size
        Window side.
    eps
        Added to the (biased) variance before the square root.

    Returns
    -------
    mean, std
        ``(Hp - size + 1, Wp - size + 1)`` float64: statistics of the window whose top-left corner is at each
        position (biased variance, as InstanceNorm).
    """
    f = np.asarray(img, np.float64)
    ii = np.zeros((f.shape[0] + 1, f.shape[1] + 1))
    ii2 = np.zeros_like(ii)
    ii[1:, 1:] = f.cumsum(0).cumsum(1)
    ii2[1:, 1:] = (f * f).cumsum(0).cumsum(1)
    n = float(size * size)

    def boxsum(a: np.ndarray) -> np.ndarray:
        return a[size:, size:] - a[:-size, size:] - a[size:, :-size] + a[:-size, :-size]

    mean = boxsum(ii) / n
    var = np.maximum(boxsum(ii2) / n - mean * mean, 0.0)
    return mean, np.sqrt(var + eps)
