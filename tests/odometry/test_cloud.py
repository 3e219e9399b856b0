"""A keyframe's world points: the numba kernel gives the numpy reference's bytes (dmtrack.odometry._cloud)."""

from __future__ import annotations

import numpy as np
import pytest

from dmtrack.geometry.camera import PinholeCamera
from dmtrack.odometry._cloud import points_world_numba, points_world_numpy
from dmtrack.odometry.sink import KeyframeSnapshot

K = (525.0, 531.5, 319.5, 239.5)


def _maps(seed: int, h: int = 48, w: int = 64) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    idepth = rng.uniform(-0.2, 3.0, (h, w)).astype(np.float32)
    idepth[rng.random((h, w)) < 0.1] = 0.0
    var = rng.uniform(-1e-3, 0.1, (h, w)).astype(np.float32)
    var[rng.random((h, w)) < 0.2] = -1.0
    # values on both sides of the bound 0.05 as float32 (the reference compares in float32)
    b = np.float32(0.05)
    var[0, :4] = [b, np.nextafter(b, np.float32(1)), np.nextafter(b, np.float32(0)), np.float32(0.05000000074505806)]
    idepth[0, :4] = 1.0
    angle, axis = 0.7, np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81])
    W = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(angle) * W + (1 - np.cos(angle)) * W @ W
    S = np.eye(4)
    S[:3, :3] = 1.7 * R
    S[:3, 3] = rng.normal(size=3)
    return idepth, var, S


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("max_var", [None, 0.05, 1e-3])
@pytest.mark.parametrize("image", ["rgb", "rgba", "grey", None])
def test_kernel_gives_the_reference_bytes(seed: int, max_var: float | None, image: str | None) -> None:
    idepth, var, S = _maps(seed)
    rng = np.random.default_rng(10 + seed)
    channels = {"rgb": 3, "rgba": 4, "grey": 0}.get(image) if image else None
    img = None
    if channels is not None:
        shape = idepth.shape if channels == 0 else (*idepth.shape, channels)
        img = rng.integers(0, 256, shape, dtype=np.uint8)
    ref = points_world_numpy(idepth, var, img, max_var, K, S)
    out = points_world_numba(idepth, var, img, max_var, K, S)
    assert len(ref[0]) > 0
    assert out[0].dtype == np.float64 and out[1].dtype == np.uint8
    assert out[0].tobytes() == ref[0].tobytes()
    assert out[1].tobytes() == ref[1].tobytes()


def test_other_dtypes_take_the_reference() -> None:
    idepth, var, S = _maps(3)
    img = np.zeros((*idepth.shape, 3), np.float32)  # not uint8
    for args in ((idepth.astype(np.float64), var, None), (idepth, var, img), (idepth[:, ::2], var[:, ::2], None)):
        ref = points_world_numpy(*args, None, K, S)
        out = points_world_numba(*args, None, K, S)
        assert out[0].tobytes() == ref[0].tobytes() and out[1].tobytes() == ref[1].tobytes()


def test_snapshot_points_are_the_kernels() -> None:
    idepth, var, S = _maps(4)
    h, w = idepth.shape
    cam = PinholeCamera(*K, w, h)
    img = np.random.default_rng(5).integers(0, 256, (h, w, 3), dtype=np.uint8)
    snap = KeyframeSnapshot(keyframe_id=0, frame_index=0, timestamp=0.0, T_wc=np.eye(4), scale=1.0, idepth=idepth,
                            idepth_var=var, image=img, camera=cam, n_updates=1, parent_id=None)  # fmt: skip
    pts, col = snap.points_world(0.05)
    ref = points_world_numpy(idepth, var, img, 0.05, K, snap.T_wc_sim3)
    assert pts.tobytes() == ref[0].tobytes() and col.tobytes() == ref[1].tobytes()
