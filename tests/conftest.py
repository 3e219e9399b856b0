"""Shared fixtures.

Tests that need the real data in ``../shared`` use the ``shared_dir`` fixture (or the ``SHARED`` path
with ``requires_shared``) and are skipped with a clear reason when it is absent.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("DMTRACK_SHARED", REPO.parent / "shared")).resolve()
SAMPLE = REPO / "data" / "7scenes-redkitchen-0000-0299"

requires_shared = pytest.mark.skipif(
    not (SHARED / "data").is_dir(),
    reason=f"../shared (real datasets) not found at {SHARED}; set DMTRACK_SHARED to its path",
)


@pytest.fixture(autouse=True, scope="session")
def _isolated_user_dir(tmp_path_factory: pytest.TempPathFactory) -> None:
    """The user's calibrated scales / PCA bases (~/.config/dmtrack) must not leak into the tests."""
    os.environ["DMTRACK_HOME"] = str(tmp_path_factory.mktemp("dmtrack-home"))


@pytest.fixture(autouse=True, scope="session")
def _ctrl_c_as_on_a_terminal() -> Iterator[None]:
    """Ctrl-C as a terminal delivers it. A shell without job control starts a background job (``make test &``, a CI
    runner's step) with SIGINT ignored, which Python and every process it starts inherit: the tests of Ctrl-C would
    then see no KeyboardInterrupt, and their ``dmtrack run`` children no SIGINT at all. Python's own handler,
    installed here, is reset to the default when a child process starts, so the children get Ctrl-C too."""
    import signal

    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        yield
        return
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.SIG_IGN)


#: environment variables that numba, BLAS, OpenCV or dmtrack read (some only once, at import or compile time)
_WATCHED_ENV = ("NUMBA_", "DMTRACK_", "OMP_", "OPENBLAS_", "MKL_", "KMP_", "NPY_", "OPENCV_", "PYTHONHASHSEED")


def _watched_state() -> dict[str, object]:
    import signal

    import numba

    env = {k: v for k, v in os.environ.items() if k.startswith(_WATCHED_ENV)}
    home = Path(os.environ.get("DMTRACK_HOME", "")) if os.environ.get("DMTRACK_HOME") else None
    files = sorted(str(p.relative_to(home)) for p in home.rglob("*")) if home is not None and home.is_dir() else []
    handlers = {name: _handler_name(signal.getsignal(getattr(signal, name)))
                for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)}  # fmt: skip
    return {"environment": env, "numba threads": numba.get_num_threads(),
            "numba config": (numba.config.NUMBA_NUM_THREADS, numba.config.CPU_NAME, numba.config.CPU_FEATURES,
                             numba.config.DISABLE_JIT, numba.config.THREADING_LAYER),
            "signal handlers": handlers, "files in DMTRACK_HOME": files}  # fmt: skip


def _handler_name(h: Any) -> str:
    return getattr(h, "__qualname__", None) or repr(h)


@contextlib.contextmanager
def restored_process_state() -> Iterator[None]:
    """Put back, on exit, the watched environment variables and numba's thread count: for fixtures that run code
    that sets them for its own process on purpose (``dmtrack run --threads``, a Dask nanny)."""
    import numba

    env = {k: v for k, v in os.environ.items() if k.startswith(_WATCHED_ENV)}
    threads = numba.get_num_threads()
    try:
        yield
    finally:
        for k in [k for k in os.environ if k.startswith(_WATCHED_ENV) and k not in env]:
            del os.environ[k]
        os.environ.update(env)
        numba.set_num_threads(threads)


@pytest.fixture(scope="session")
def restored_state() -> Any:
    """:func:`restored_process_state`, for fixtures (``with restored_state(): …``)."""
    return restored_process_state


def _check_unchanged(before: dict[str, object], what: str) -> None:
    after = _watched_state()
    changed = {k: (before[k], after[k]) for k in before if before[k] != after[k]}
    if changed:
        pytest.fail(f"{what} left the process changed: {changed}", pytrace=False)


@pytest.fixture(autouse=True)
def _leaves_the_process_as_it_found_it(request: pytest.FixtureRequest) -> Iterator[None]:
    """Every test leaves numba's thread count, numba's configuration and the environment variables the kernels read
    as it found them: a test that changed them would change what the tests after it compile or run (issue 41)."""
    before = _watched_state()
    yield
    _check_unchanged(before, request.node.nodeid)


@pytest.fixture(autouse=True, scope="module")
def _module_leaves_the_process_as_it_found_it(request: pytest.FixtureRequest) -> Iterator[None]:
    """The same for a test module as a whole: its module-scoped fixtures included."""
    before = _watched_state()
    yield
    _check_unchanged(before, f"{request.node.nodeid} (its module fixtures)")


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    if not (SHARED / "data").is_dir():
        pytest.skip(f"../shared (real datasets) not found at {SHARED}; set DMTRACK_SHARED to its path")
    return SHARED


@pytest.fixture(scope="session")
def sample_dir() -> Path:
    """The real 7-Scenes sample shipped in the repository (data/)."""
    assert SAMPLE.is_dir(), f"the sample sequence is missing from the repository: {SAMPLE}"
    return SAMPLE


class RenderedRoom:
    """The renderer's room (seed 3, 320 × 240) seen from poses around its first camera: real images and exact inverse
    depths for the tests that build keyframes by hand (``tests/slam``, ``tests/relocalisation``)."""

    def __init__(self) -> None:
        from dmtrack.datasets.synthetic.sequence import SyntheticConfig, SyntheticSequence

        self.seq = SyntheticSequence(SyntheticConfig(width=320, height=240, n_frames=1, seed=3, texel=0.02))
        self.camera = self.seq.camera

    def pose(self, yaw_deg: float = 0.0, shift: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> Any:
        """T_wc: the first camera turned by ``yaw_deg`` about the vertical through its centre and moved by ``shift``
        (world axes, metres)."""
        import numpy as np

        from dmtrack.geometry.lie import SO3

        T = self.seq.poses[0].copy()
        T[:3, :3] = np.asarray(SO3.exp([0.0, 0.0, np.radians(yaw_deg)]).matrix()) @ T[:3, :3]
        T[:3, 3] += np.asarray(shift, np.float64)
        return T

    def render(self, T_wc: Any) -> tuple[Any, Any]:
        """(uint8 image, float32 inverse depth in 1/metres) seen from ``T_wc``."""
        import numpy as np

        from dmtrack.datasets.synthetic.renderer import render

        radiance, depth = render(self.seq.scene, self.camera, T_wc, blur=self.seq.config.blur)
        return np.clip(np.rint(radiance), 0, 255).astype(np.uint8), (1.0 / depth).astype(np.float32)


@pytest.fixture(scope="session")
def rendered_room() -> RenderedRoom:
    return RenderedRoom()
