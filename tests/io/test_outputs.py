"""PLY point clouds and inverse-depth pictures."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dmtrack.io.ply import read_ply, write_ply
from dmtrack.viz.depth import NEGATIVE_COLOUR, inverse_depth_image, write_png


def test_ply_round_trip(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    pts = rng.normal(size=(100, 3)).astype(np.float32)
    cols = rng.integers(0, 256, size=(100, 3), dtype=np.uint8)
    write_ply(tmp_path / "c.ply", pts, cols)
    back, back_cols = read_ply(tmp_path / "c.ply")
    np.testing.assert_array_equal(back, pts)
    np.testing.assert_array_equal(back_cols, cols)
    assert (tmp_path / "c.ply").read_bytes().startswith(b"ply\nformat binary_little_endian 1.0")
    write_ply(tmp_path / "n.ply", pts)
    assert read_ply(tmp_path / "n.ply")[1] is None


def test_inverse_depth_image_marks_negative_depths(tmp_path: Path) -> None:
    h, w = 20, 30
    image = np.full((h, w), 200, np.uint8)
    idepth = np.tile(np.linspace(0.2, 2.0, w, dtype=np.float32), (h, 1))
    valid = np.zeros((h, w), bool)
    valid[5:15, 5:25] = True
    idepth[10, 10] = -0.5
    out = inverse_depth_image(idepth, valid, image)
    assert out.shape == (h, w, 3) and out.dtype == np.uint8
    assert tuple(out[10, 10]) == NEGATIVE_COLOUR
    assert tuple(out[0, 0]) == (100, 100, 100)  # no hypothesis: dimmed image
    near, far = out[7, 24], out[7, 5]  # larger inverse depth = nearer = red
    assert near[0] > near[2] and far[2] > far[0]
    write_png(tmp_path / "d.png", out)
    assert (tmp_path / "d.png").stat().st_size > 0
