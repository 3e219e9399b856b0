"""Point clouds as PLY files (binary little-endian, x y z float32 + red green blue uint8).

:func:`write_ply` writes a cloud held in memory; :class:`PlyStream` builds the same file from chunks of points as
they come (a run's keyframes), so that the whole cloud never sits in memory. Both write the bytes :mod:`plyfile`
writes, atomically.
"""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path
from typing import BinaryIO

import numpy as np

from dmtrack.io.atomic import TMP_SUFFIX, atomic_path, output_error

#: One vertex record of a coloured cloud (15 bytes, packed, little-endian).
VERTEX_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
_XYZ_DTYPE = np.dtype(VERTEX_DTYPE.descr[:3])


def ply_header(n_vertices: int, colours: bool = True) -> bytes:
    """The header :mod:`plyfile` writes for ``n_vertices`` vertices (x y z float, and red green blue uchar)."""
    props = ["x", "y", "z"] if not colours else ["x", "y", "z", "red", "green", "blue"]
    lines = ["ply", "format binary_little_endian 1.0", f"element vertex {int(n_vertices)}"]
    lines += [f"property {'float' if p in 'xyz' else 'uchar'} {p}" for p in props]
    return ("\n".join(lines) + "\nend_header\n").encode("ascii")


def vertex_records(points: np.ndarray, colours: np.ndarray | None = None) -> np.ndarray:
    """(N,) records of :data:`VERTEX_DTYPE` (x y z only when ``colours`` is None): the body of a PLY file."""
    points = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    if colours is None:
        vertex = np.empty(points.shape[0], dtype=_XYZ_DTYPE)
    else:
        colours = np.asarray(colours, dtype=np.uint8).reshape(-1, 3)
        if colours.shape[0] != points.shape[0]:
            raise ValueError(f"{points.shape[0]} points but {colours.shape[0]} colours")
        vertex = np.empty(points.shape[0], dtype=VERTEX_DTYPE)
        vertex["red"], vertex["green"], vertex["blue"] = colours.T
    vertex["x"], vertex["y"], vertex["z"] = points.T
    return vertex


def write_ply(path: str | Path, points: np.ndarray, colours: np.ndarray | None = None) -> None:
    """Write an (N, 3) point cloud with optional (N, 3) uint8 RGB colours, atomically.

    Uses :mod:`plyfile`; readable by MeshLab, CloudCompare, Open3D.
    """
    from plyfile import PlyData, PlyElement

    vertex = vertex_records(points, colours)
    with atomic_path(path) as tmp:
        PlyData([PlyElement.describe(vertex, "vertex")], text=False, byte_order="<").write(str(tmp))


class PlyStream:
    """A coloured point cloud written chunk by chunk: the same file as :func:`write_ply` of all chunks joined.

    Each :meth:`append` writes its vertex records to a temporary body file next to ``path`` (``.NAME.XXXX.tmp``,
    which :func:`~dmtrack.io.atomic.remove_stale_temporaries` cleans up after a ``kill -9``); :meth:`close` writes
    the header, which carries the vertex count, and copies the body after it into ``path`` atomically, then removes
    the body (created by the first :meth:`append`: a cloud that gets no chunk leaves no temporary file). Memory
    stays at one chunk whatever the cloud's size.

    A chunk that cannot be written raises :class:`~dmtrack.errors.OutputError` naming ``path``; the chunks
    written before it are kept, and :meth:`close` still writes them (unless it fails too: the error names
    ``path``). :meth:`discard` removes the body without writing ``path``.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.n_points = 0
        self._body_path: Path | None = None  # created by the first append
        self._body: BinaryIO | None = None
        self._closed = False

    def _open_body(self) -> BinaryIO:
        try:
            fd, body = tempfile.mkstemp(dir=self.path.parent, prefix=f".{self.path.name}.", suffix=TMP_SUFFIX)
            os.close(fd)
            self._body_path = Path(body)
            self._body = open(body, "wb", buffering=0)  # noqa: SIM115 - unbuffered: append's bytes are in the file
        except OSError as exc:
            raise output_error(self.path, exc) from None
        return self._body

    def append(self, points: np.ndarray, colours: np.ndarray) -> None:
        """Add (N, 3) points (float32 or float64, written as float32) with (N, 3) uint8 RGB colours."""
        if self._closed:
            raise ValueError(f"{self.path}: the point cloud is closed")
        data = memoryview(vertex_records(points, colours)).cast("B")
        f = self._body or self._open_body()
        try:
            # after the records written so far: a chunk that failed half-way is overwritten
            f.seek(self.n_points * VERTEX_DTYPE.itemsize)
            done = 0
            while done < len(data):
                done += f.write(data[done:])
        except OSError as exc:
            raise output_error(self.path, exc) from None
        self.n_points += len(data) // VERTEX_DTYPE.itemsize

    def close(self) -> None:
        """Write ``path`` (header + the chunks appended), atomically, and remove the body file."""
        if self._closed:
            return
        self._closed = True
        try:  # atomic_path reports an OS error of this block as an OutputError naming path
            with atomic_path(self.path) as tmp, open(tmp, "wb") as out:
                out.write(ply_header(self.n_points))
                if self._body is not None and self._body_path is not None:
                    self._body.close()
                    with open(self._body_path, "rb") as body:
                        _copy(body, out, self.n_points * VERTEX_DTYPE.itemsize)
        finally:
            self.discard()

    def discard(self) -> None:
        """Remove the body file; ``path`` is not written if :meth:`close` has not written it."""
        self._closed = True
        body, self._body_path = self._body_path, None
        if self._body is not None:
            try:
                self._body.close()
            except OSError:
                pass  # the body is thrown away: its data does not matter
        if body is not None:
            body.unlink(missing_ok=True)


def _copy(src: BinaryIO, dst: BinaryIO, n_bytes: int) -> None:
    """Copy the first ``n_bytes`` of ``src`` to ``dst``."""
    while n_bytes > 0:
        chunk = src.read(min(n_bytes, 1 << 20))
        if not chunk:
            raise OSError(errno.EIO, "the temporary file of the points is shorter than the points written")
        dst.write(chunk)
        n_bytes -= len(chunk)


def read_ply(path: str | Path) -> tuple[np.ndarray, np.ndarray | None]:
    """(N, 3) float32 points and (N, 3) uint8 colours (or None) of a PLY file."""
    from plyfile import PlyData

    v = PlyData.read(str(path))["vertex"].data
    points = np.column_stack([v["x"], v["y"], v["z"]]).astype(np.float32)
    names = v.dtype.names or ()
    colours = np.column_stack([v["red"], v["green"], v["blue"]]) if "red" in names else None
    return points, colours
