"""dmtrack — direct multichannel tracking.

Semi-dense monocular visual odometry (LSD-SLAM style) that aligns images directly on per-pixel
multichannel features.  Conventions (poses are camera-to-world, OpenCV camera axes, Lie algebra
tangent order (υ, ω)) are documented in ``docs/conventions.md``.

>>> import dmtrack
>>> result = dmtrack.track("data/7scenes-redkitchen-0000-0299", feature="gray", max_frames=50)  # doctest: +SKIP

The heavy modules (numba kernels, OpenCV) are imported on first use, so ``import dmtrack`` is cheap.
"""

from __future__ import annotations

import os
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__version__ = "0.1.0"

__all__ = ["RunResult", "__version__", "open_sequence", "run_to_directory", "track"]

_LAZY = {
    "track": "dmtrack.api",
    "run_to_directory": "dmtrack.api",
    "RunResult": "dmtrack.api",
    "open_sequence": "dmtrack.datasets",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'dmtrack' has no attribute {name!r}")


def _numba_cache_fallback(folders: Sequence[Path] | None = None) -> None:
    """numba caches the compiled kernels next to the package's sources, else in the user's cache folder; where it can
    write to neither (a read-only installation and a read-only home), it refuses to import a kernel ("no locator
    available"). Then this points ``NUMBA_CACHE_DIR`` at a private folder of the temporary directory instead.

    Runs when ``dmtrack`` is imported (before any of its modules imports numba), so the command line and the Python
    API both work from such an installation. ``folders``: the places to try (default: numba's two).
    """
    if os.environ.get("NUMBA_CACHE_DIR") or "numba" in sys.modules:
        return  # the user's choice, or numba has read its configuration already
    if folders is None:
        home = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        folders = (Path(__file__).resolve().parent / "odometry" / "__pycache__", Path(home) / "numba")
    for folder in folders:
        try:  # numba's own test of a cache folder
            folder.mkdir(parents=True, exist_ok=True)
            tempfile.TemporaryFile(dir=folder).close()
            return
        except OSError:
            continue
    # a private folder (cached kernels are machine code): this user's own, or else a new one for this process
    uid = os.getuid() if hasattr(os, "getuid") else None
    folder = Path(tempfile.gettempdir()) / f"dmtrack-numba-cache-{uid}"
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
        st = folder.stat()
        private = uid is not None and st.st_uid == uid and not st.st_mode & 0o077 and not folder.is_symlink()
    except OSError:
        private = False
    os.environ["NUMBA_CACHE_DIR"] = str(folder) if private else tempfile.mkdtemp(prefix="dmtrack-numba-cache-")


_numba_cache_fallback()


def _passive_omp_waits() -> None:
    """Sets ``OMP_WAIT_POLICY=PASSIVE`` unless the user set it.

    numba's default threading layer here is OpenMP (libgomp). With the policy unset, libgomp's threads spin at the
    end of every parallel region before they sleep; the odometry runs a few dozen short regions per frame. On a
    machine where another process holds a core, the spinning thread and the thread it waits for share that core,
    and grey tracking ran 3.2× slower (benchmarks/studies/2026-11-27-omp-wait: 5.5 against 18.0 fps, 300 frames of
    the shared 7-Scenes with one other busy process). Sleeping threads cost nothing measurable on an idle machine
    (there 25.3–25.9 against 24.4–24.8 fps). libgomp reads the variable when it is loaded, at numba's first parallel
    kernel: set here, before any dmtrack module imports numba. It has no effect where libgomp was loaded earlier in
    the process, or with numba's TBB or workqueue layers; the results never depend on it.
    """
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


_passive_omp_waits()


def _prefer_openmp() -> None:
    """Sets ``NUMBA_THREADING_LAYER_PRIORITY="omp tbb workqueue"`` unless the user set it (or chose a layer).

    numba takes TBB before OpenMP when a TBB library is on the system — an ``apt install libopencv-dev`` brings one.
    TBB's workers spin after each of the odometry's few dozen short parallel regions a frame; on the shared
    7-Scenes (grey, 700 frames, 2 cores) OpenMP with passive waits took 10.2 against 10.8 s and 16.6 against 18.2 s
    of CPU, with the same trajectory (benchmarks/studies/2026-11-29-lean). Without libgomp numba falls back to TBB,
    then to its own workqueue.
    """
    if "NUMBA_THREADING_LAYER" not in os.environ:
        os.environ.setdefault("NUMBA_THREADING_LAYER_PRIORITY", "omp tbb workqueue")


_prefer_openmp()
