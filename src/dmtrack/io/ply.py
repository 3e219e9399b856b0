"""Point clouds as PLY files (binary little-endian, x y z float32 + red green blue uint8)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dmtrack.io.atomic import atomic_path


def write_ply(path: str | Path, points: np.ndarray, colours: np.ndarray | None = None) -> None:
    """Write an (N, 3) point cloud with optional (N, 3) uint8 RGB colours, atomically.

    Uses :mod:`plyfile`; readable by MeshLab, CloudCompare, Open3D.
    """
    from plyfile import PlyData, PlyElement

    points = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    fields = [("x", "f4"), ("y", "f4"), ("z", "f4")]
    if colours is not None:
        colours = np.asarray(colours, dtype=np.uint8).reshape(-1, 3)
        if colours.shape[0] != points.shape[0]:
            raise ValueError(f"{points.shape[0]} points but {colours.shape[0]} colours")
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    vertex = np.empty(points.shape[0], dtype=fields)
    vertex["x"], vertex["y"], vertex["z"] = points.T
    if colours is not None:
        vertex["red"], vertex["green"], vertex["blue"] = colours.T
    with atomic_path(path) as tmp:
        PlyData([PlyElement.describe(vertex, "vertex")], text=False, byte_order="<").write(str(tmp))


def read_ply(path: str | Path) -> tuple[np.ndarray, np.ndarray | None]:
    """(N, 3) float32 points and (N, 3) uint8 colours (or None) of a PLY file."""
    from plyfile import PlyData

    v = PlyData.read(str(path))["vertex"].data
    points = np.column_stack([v["x"], v["y"], v["z"]]).astype(np.float32)
    names = v.dtype.names or ()
    colours = np.column_stack([v["red"], v["green"], v["blue"]]) if "red" in names else None
    return points, colours
