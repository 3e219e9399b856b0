"""PLY point clouds and inverse-depth pictures."""

from __future__ import annotations

import signal
from pathlib import Path

import cv2
import numpy as np
import pytest

from dmtrack.errors import OutputError
from dmtrack.io.ply import VERTEX_DTYPE, PlyStream, ply_header, read_ply, vertex_records, write_ply
from dmtrack.viz.depth import (
    NEGATIVE_COLOUR,
    colour_table,
    inverse_depth_codes,
    inverse_depth_image,
    palette_png,
    write_depth_png,
)


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
    write_depth_png(tmp_path / "d.png", inverse_depth_codes(idepth, valid, image))
    assert (tmp_path / "d.png").stat().st_size > 0


def test_depth_png_decodes_to_the_rgb_picture(tmp_path: Path) -> None:
    """The run's depth pictures are palette PNGs: OpenCV and Pillow read them back as exactly the RGB picture of
    inverse_depth_image (every code, negative and missing depths, a grey and a colour image)."""
    import cv2
    from PIL import Image

    rng = np.random.default_rng(3)
    h, w = 37, 53
    idepth = rng.uniform(-0.3, 2.0, size=(h, w)).astype(np.float32)
    idepth[0, :3] = (np.nan, np.inf, 0.0)
    valid = rng.random((h, w)) < 0.7
    for image in (rng.integers(0, 256, (h, w), dtype=np.uint8), rng.integers(0, 256, (h, w, 3), dtype=np.uint8)):
        rgb = inverse_depth_image(idepth, valid, image)
        codes = inverse_depth_codes(idepth, valid, image)
        assert np.array_equal(colour_table()[codes], rgb)
        write_depth_png(tmp_path / "d.png", codes)
        assert np.array_equal(cv2.imread(str(tmp_path / "d.png"))[..., ::-1], rgb)
        with Image.open(tmp_path / "d.png") as im:
            assert im.mode == "P" and np.array_equal(np.asarray(im.convert("RGB")), rgb)
    every = np.arange(256, dtype=np.uint8).reshape(16, 16)
    decoded = cv2.imdecode(np.frombuffer(palette_png(every, colour_table()), np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(decoded[..., ::-1], colour_table()[every])
    with pytest.raises(ValueError, match="palette_png"):
        palette_png(every, np.zeros((257, 3), np.uint8))
    with pytest.raises(ValueError, match="code 255 has no colour in a table of 16"):
        palette_png(every, colour_table()[:16])


def _chunks(rng: np.random.Generator) -> list[tuple[np.ndarray, np.ndarray]]:
    sizes = (5, 0, 300, 7)  # an empty chunk too; float64 points, as the keyframes give them
    return [(rng.normal(size=(n, 3)) * 3.0, rng.integers(0, 256, size=(n, 3), dtype=np.uint8)) for n in sizes]


def _joined(chunks: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    return np.concatenate([p.astype(np.float32) for p, _ in chunks]), np.concatenate([c for _, c in chunks])


def _temporaries(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir() if p.name.endswith(".tmp"))


def test_streamed_ply_is_the_file_plyfile_writes(tmp_path: Path) -> None:
    chunks = _chunks(np.random.default_rng(2))
    stream = PlyStream(tmp_path / "s.ply")
    for k, (pts, cols) in enumerate(chunks):
        stream.append(pts, cols)
        # the points so far are in a temporary file; the destination appears only at close
        (body,) = _temporaries(tmp_path)
        assert body.name.startswith(".s.ply.") and not (tmp_path / "s.ply").exists()
        assert body.stat().st_size == VERTEX_DTYPE.itemsize * sum(len(p) for p, _ in chunks[: k + 1])
    stream.close()
    stream.close()  # a second close changes nothing
    write_ply(tmp_path / "m.ply", *_joined(chunks))  # plyfile, from the whole cloud in memory
    assert (tmp_path / "s.ply").read_bytes() == (tmp_path / "m.ply").read_bytes()
    assert stream.n_points == 312 and _temporaries(tmp_path) == []
    with pytest.raises(ValueError, match="closed"):
        stream.append(*chunks[0])


def test_ply_header_is_the_one_plyfile_writes(tmp_path: Path) -> None:
    pts = np.random.default_rng(3).normal(size=(4, 3)).astype(np.float32)
    write_ply(tmp_path / "n.ply", pts)
    data = (tmp_path / "n.ply").read_bytes()
    assert data == ply_header(4, colours=False) + vertex_records(pts).tobytes()


def test_streamed_ply_of_no_points(tmp_path: Path) -> None:
    stream = PlyStream(tmp_path / "e.ply")
    assert _temporaries(tmp_path) == []  # nothing on disk before the first chunk
    stream.close()
    points, colours = read_ply(tmp_path / "e.ply")
    assert points.shape == (0, 3) and colours is not None and colours.shape == (0, 3)
    stream = PlyStream(tmp_path / "d.ply")
    stream.append(np.zeros((3, 3)), np.zeros((3, 3), np.uint8))
    stream.discard()  # thrown away: no file, no temporary
    assert not (tmp_path / "d.ply").exists() and _temporaries(tmp_path) == []


@pytest.mark.skipif(not hasattr(signal, "SIGXFSZ"), reason="POSIX file size limit")
def test_streamed_ply_after_a_failed_chunk(tmp_path: Path) -> None:
    """A chunk the OS refuses half-way (file size limit: EFBIG, as a full disk gives ENOSPC) raises OutputError
    naming the cloud; the chunks before it are kept, a later chunk overwrites its partial bytes."""
    resource = pytest.importorskip("resource")
    chunks = _chunks(np.random.default_rng(4))
    stream = PlyStream(tmp_path / "f.ply")
    stream.append(*chunks[0])
    stream.append(*chunks[1])
    limit = 5 * VERTEX_DTYPE.itemsize + 100  # room for part of the next chunk only
    old_limit = resource.getrlimit(resource.RLIMIT_FSIZE)
    old_handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a failing write, not a killed process
    try:
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, old_limit[1]))
        with pytest.raises(OutputError, match="f.ply") as err:
            stream.append(*chunks[2])
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, old_limit)
        signal.signal(signal.SIGXFSZ, old_handler)
    assert err.value.path == tmp_path / "f.ply"
    (body,) = _temporaries(tmp_path)
    assert body.stat().st_size == limit  # the partial chunk is there...
    stream.append(*chunks[3])
    stream.close()  # ...and overwritten: the file holds chunks 0, 1 and 3
    write_ply(tmp_path / "m.ply", *_joined([chunks[0], chunks[1], chunks[3]]))
    assert (tmp_path / "f.ply").read_bytes() == (tmp_path / "m.ply").read_bytes()
    assert _temporaries(tmp_path) == []


def test_inverse_depth_image_matches_the_colour_rule() -> None:
    """Every pixel as the module docstring says, computed pixel by pixel: dimmed grey (g // 2) without a
    hypothesis, magenta for a negative inverse depth, else the hue 120·(1 − t) (OpenCV HSV, full saturation and
    value) of t = (d − p2) / (p98 − p2) clipped to 0..1, p2 / p98 the percentiles of the positive inverse depths."""
    rng = np.random.default_rng(5)
    h, w = 24, 32
    image = rng.integers(0, 256, size=(h, w, 3), dtype=np.uint8)
    idepth = rng.uniform(-0.3, 2.0, size=(h, w)).astype(np.float32)
    idepth[0, :3] = (np.nan, np.inf, 0.0)
    valid = rng.random((h, w)) > 0.3
    valid[0, :3] = True
    out = inverse_depth_image(idepth, valid, image)
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    positive = valid & np.isfinite(idepth) & (idepth > 0)
    lo, hi = np.percentile(idepth[positive], [2, 98])
    for y in range(h):
        for x in range(w):
            d = idepth[y, x]
            if not (valid[y, x] and np.isfinite(d)):
                expected = (grey[y, x] // 2,) * 3
            elif d <= 0:
                expected = NEGATIVE_COLOUR
            else:
                t = min(max((d - lo) / (hi - lo), 0.0), 1.0)
                hsv = np.array([[[round((1.0 - t) * 120), 255, 255]]], np.uint8)
                expected = tuple(cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[0, 0])
            assert tuple(out[y, x]) == tuple(expected), (y, x)
    assert tuple(out[0, 0]) == (grey[0, 0] // 2,) * 3 and tuple(out[0, 2]) == NEGATIVE_COLOUR
