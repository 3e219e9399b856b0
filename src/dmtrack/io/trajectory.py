"""Trajectories (timestamps + camera-to-world poses) and their TUM / KITTI file formats.

* **TUM**: one pose a line, ``timestamp tx ty tz qx qy qz qw`` (quaternion x, y, z, w).
* **KITTI**: one pose a line, the 3×4 matrix ``[R | t]`` row-major (12 numbers), no timestamps
  (they come from ``times.txt`` or default to the line index).

Readers are lenient about what is harmless and strict about what is not:

* any whitespace (spaces, tabs) or commas separate numbers; blank lines and ``#`` comments are skipped;
* rows containing NaN are skipped with one warning (TUM monoVO's ``groundtruthSync.txt`` has them);
* anything else that does not parse — a wrong number of columns, a word, a zero quaternion, a matrix
  that is not a rotation — raises :class:`~dmtrack.errors.InputError` naming the file and the line.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from dmtrack.errors import InputError
from dmtrack.geometry.lie import matrix_to_quaternion, quaternion_to_matrix
from dmtrack.io.atomic import write_text
from dmtrack.io.files import read_text_file

_ROTATION_TOL = 1e-2  # max |RᵀR − I| entry accepted as a rotation (files print ~7 digits)


def _number(value: Any) -> str:
    """A number as plain text (``1.5``, not ``np.float64(1.5)``)."""
    return repr(float(value))


class Trajectory:
    """Timestamps and camera-to-world poses ``T_wc``.

    Parameters
    ----------
    timestamps : (N,) float64, seconds (or the dataset's time unit).
    poses : (N, 4, 4) float64 homogeneous matrices.
    """

    __slots__ = ("timestamps", "poses")

    def __init__(self, timestamps: np.ndarray, poses: np.ndarray) -> None:
        timestamps = np.asarray(timestamps, dtype=np.float64).reshape(-1)
        poses = np.asarray(poses, dtype=np.float64)
        if poses.ndim != 3 or poses.shape[1:] != (4, 4):
            raise ValueError(f"poses must have shape (N, 4, 4), got {poses.shape}")
        if poses.shape[0] != timestamps.shape[0]:
            raise ValueError(f"{timestamps.shape[0]} timestamps but {poses.shape[0]} poses")
        self.timestamps = timestamps
        self.poses = poses

    # -- construction ---------------------------------------------------------------------------
    @classmethod
    def from_tum_array(cls, data: np.ndarray) -> Trajectory:
        """From an (N, 8) array ``t tx ty tz qx qy qz qw``."""
        data = np.asarray(data, dtype=np.float64).reshape(-1, 8)
        poses = np.tile(np.eye(4), (data.shape[0], 1, 1))
        poses[:, :3, :3] = quaternion_to_matrix(data[:, 4:8])
        poses[:, :3, 3] = data[:, 1:4]
        return cls(data[:, 0], poses)

    @classmethod
    def from_positions(cls, timestamps: np.ndarray, positions: np.ndarray) -> Trajectory:
        """Identity rotations at the given (N, 3) positions."""
        positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        poses = np.tile(np.eye(4), (positions.shape[0], 1, 1))
        poses[:, :3, 3] = positions
        return cls(timestamps, poses)

    # -- views ----------------------------------------------------------------------------------
    def __len__(self) -> int:
        return self.timestamps.shape[0]

    def __getitem__(self, index: slice | np.ndarray) -> Trajectory:
        if isinstance(index, (int, np.integer)):
            index = slice(int(index), int(index) + 1 if index != -1 else None)
        return Trajectory(self.timestamps[index], self.poses[index])

    def __repr__(self) -> str:
        if len(self) == 0:
            return "Trajectory(empty)"
        return (
            f"Trajectory({len(self)} poses, t={self.timestamps[0]:.3f}..{self.timestamps[-1]:.3f}, "
            f"path length {self.path_length():.3f})"
        )

    @property
    def positions(self) -> np.ndarray:
        """(N, 3) camera centres in the world frame."""
        return self.poses[:, :3, 3]

    @property
    def rotations(self) -> np.ndarray:
        """(N, 3, 3) camera-to-world rotations."""
        return self.poses[:, :3, :3]

    def quaternions(self) -> np.ndarray:
        """(N, 4) rotations as unit quaternions (x, y, z, w), w ≥ 0."""
        return matrix_to_quaternion(_nearest_rotations(self.rotations))

    def to_tum_array(self) -> np.ndarray:
        """(N, 8) ``t tx ty tz qx qy qz qw``."""
        return np.column_stack([self.timestamps, self.positions, self.quaternions()])

    def distances(self) -> np.ndarray:
        """(N,) cumulative path length from the first pose (same unit as the positions)."""
        if len(self) == 0:
            return np.zeros(0)
        steps = np.linalg.norm(np.diff(self.positions, axis=0), axis=1)
        return np.concatenate([[0.0], np.cumsum(steps)])

    def path_length(self) -> float:
        """Total length of the path through the camera centres."""
        return float(self.distances()[-1]) if len(self) else 0.0

    def transformed(self, T: np.ndarray, right: np.ndarray | None = None) -> Trajectory:
        """``T @ pose (@ right)`` for every pose (4×4 matrices, e.g. a Sim(3) alignment)."""
        poses = np.asarray(T, dtype=np.float64) @ self.poses
        if right is not None:
            poses = poses @ np.asarray(right, dtype=np.float64)
        return Trajectory(self.timestamps.copy(), poses)

    def interpolate(self, times: np.ndarray, max_gap: float) -> np.ndarray:
        """Poses at ``times`` by linear / spherical-linear interpolation.

        A time gets NaN when it lies outside the trajectory or its two neighbours are more than
        ``max_gap`` apart.  Returns (M, 4, 4).
        """
        from scipy.spatial.transform import Rotation, Slerp

        times = np.asarray(times, dtype=np.float64).reshape(-1)
        out = np.full((times.shape[0], 4, 4), np.nan)
        if len(self) < 2:
            if len(self) == 1:
                out[times == self.timestamps[0]] = self.poses[0]
            return out
        order = np.argsort(self.timestamps, kind="stable")
        ts, poses = self.timestamps[order], self.poses[order]
        hi = np.searchsorted(ts, times, side="left")
        exact = (hi < len(ts)) & (ts[np.minimum(hi, len(ts) - 1)] == times)
        inside = (hi > 0) & (hi < len(ts))
        gap_ok = np.zeros_like(inside)
        gap_ok[inside] = ts[hi[inside]] - ts[hi[inside] - 1] <= max_gap
        ok = inside & gap_ok
        if ok.any():
            slerp = Slerp(ts, Rotation.from_matrix(_nearest_rotations(poses[:, :3, :3])))
            out[ok, :3, :3] = slerp(times[ok]).as_matrix()
            w = (times[ok] - ts[hi[ok] - 1]) / (ts[hi[ok]] - ts[hi[ok] - 1])
            out[ok, :3, 3] = (1 - w)[:, None] * poses[hi[ok] - 1, :3, 3] + w[:, None] * poses[hi[ok], :3, 3]
            out[ok, 3] = (0.0, 0.0, 0.0, 1.0)
        if exact.any():
            out[exact] = poses[hi[exact]]
        return out


def _nearest_rotations(R: np.ndarray) -> np.ndarray:
    """Project (N, 3, 3) matrices to the nearest rotations (SVD), fixing printed-digit noise."""
    u, _, vt = np.linalg.svd(R)
    d = np.sign(np.linalg.det(u @ vt))
    u[..., :, 2] *= d[..., None]
    return u @ vt


# -- parsing -------------------------------------------------------------------------------------
def _parse_rows(
    path: Path, ncols: tuple[int, ...], what: str, notes: list[str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Numbers of every data line without NaN; what is worth a warning is appended to ``notes`` (the readers warn
    only once the whole file is accepted, so that a refused file gets one line: its error).

    Returns (rows (M, ncols), 1-based line numbers (M,), index of each row among all data lines (M,),
    number of data lines including the NaN ones).
    """
    text = read_text_file(path, "trajectory")
    rows: list[list[float]] = []
    lines: list[int] = []
    width = None
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].replace(",", " ").strip()
        if not line:
            continue
        fields = line.split()
        try:
            values = [float(f) for f in fields]
        except ValueError:
            bad = next(f for f in fields if not _is_float(f))
            raise InputError(f"{what}: cannot read {bad!r} as a number", path=path, line=lineno) from None
        if len(values) not in ncols:
            expected = " or ".join(str(n) for n in ncols)
            raise InputError(
                f"{what}: expected {expected} numbers per line, found {len(values)}", path=path, line=lineno
            )
        if width is None:
            width = len(values)
        elif len(values) != width:
            raise InputError(
                f"{what}: {len(values)} numbers on this line but {width} on the first", path=path, line=lineno
            )
        if any(math.isinf(v) for v in values):
            raise InputError(f"{what}: infinite value", path=path, line=lineno)
        rows.append(values)
        lines.append(lineno)
    if not rows:
        raise InputError(f"{what}: no poses in the file", path=path)
    data = np.asarray(rows, dtype=np.float64)
    linenos = np.asarray(lines)
    rowidx = np.arange(data.shape[0])
    n_total = data.shape[0]
    nan_rows = np.isnan(data).any(axis=1)
    if nan_rows.any():
        if nan_rows.all():
            raise InputError(f"{what}: every pose in the file is NaN", path=path)
        notes.append(f"{path}: skipped {int(nan_rows.sum())} line(s) with NaN values (first at line "
                     f"{int(linenos[nan_rows][0])})")
        data, linenos, rowidx = data[~nan_rows], linenos[~nan_rows], rowidx[~nan_rows]
    return data, linenos, rowidx, n_total


def _is_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _check_rotations(R: np.ndarray, path: Path, linenos: np.ndarray) -> None:
    with np.errstate(over="ignore", invalid="ignore"):  # entries near 1e308 overflow: not a rotation either way
        err = np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3)).max(axis=(1, 2))
        # the 3×3 cofactor expansion, not np.linalg.det: its LU divides by a pivot, which warns ("divide by zero")
        # on a subnormal entry such as 1e-320 in an otherwise exact rotation
        det = (R[:, 0, 0] * (R[:, 1, 1] * R[:, 2, 2] - R[:, 1, 2] * R[:, 2, 1])
               - R[:, 0, 1] * (R[:, 1, 0] * R[:, 2, 2] - R[:, 1, 2] * R[:, 2, 0])
               + R[:, 0, 2] * (R[:, 1, 0] * R[:, 2, 1] - R[:, 1, 1] * R[:, 2, 0]))  # fmt: skip
    err = np.where(np.isfinite(err), err, np.inf)
    bad = (err > _ROTATION_TOL) | (det < 0)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(
            f"not a rotation matrix (|RᵀR − I| = {err[i]:.3g}, det = {det[i]:.3g})",
            path=path,
            line=int(linenos[i]),
        )


def _warn(notes: list[str]) -> None:
    """The warnings of a file that was accepted (stack level: the caller of the reader)."""
    for note in notes:
        warnings.warn(note, stacklevel=3)


def read_tum(path: str | Path) -> Trajectory:
    """Read a TUM trajectory file (``timestamp tx ty tz qx qy qz qw``).

    Quaternions are normalised; a zero quaternion is an error.  Timestamps out of order are sorted
    (with a warning); duplicate timestamps are an error.
    """
    path = Path(path)
    notes: list[str] = []
    data, linenos, _, _ = _parse_rows(path, (8,), "TUM trajectory", notes)
    size = np.abs(data[:, 4:8]).max(axis=1)  # not the norm: that overflows for entries near 1e308
    if (size < 1e-8).any():
        i = int(np.argmax(size < 1e-8))
        raise InputError("TUM trajectory: zero quaternion", path=path, line=int(linenos[i]))
    data[:, 4:8] /= size[:, None]
    order = np.argsort(data[:, 0], kind="stable")
    if (np.diff(order) != 1).any():
        notes.append(f"{path}: timestamps are not in increasing order; sorted them")
        data, linenos = data[order], linenos[order]
    dup = np.flatnonzero(np.diff(data[:, 0]) == 0)
    if dup.size:
        raise InputError(
            f"TUM trajectory: duplicate timestamp {_number(data[dup[0], 0])}", path=path,
            line=int(linenos[dup[0] + 1]),
        )
    traj = Trajectory.from_tum_array(data)
    _warn(notes)
    return traj


def read_kitti(path: str | Path, timestamps: np.ndarray | str | Path | None = None) -> Trajectory:
    """Read a KITTI pose file (3×4 row-major ``[R | t]`` per line).

    Parameters
    ----------
    timestamps : an (N,) array, a ``times.txt`` path, or ``None`` for the line index 0, 1, 2, ….
        NaN rows are skipped, so with NaN rows the timestamps of the remaining rows are used.
    """
    path = Path(path)
    notes: list[str] = []
    data, linenos, rowidx, n_total = _parse_rows(path, (12,), "KITTI trajectory", notes)
    poses = np.tile(np.eye(4), (data.shape[0], 1, 1))
    poses[:, :3, :4] = data.reshape(-1, 3, 4)
    _check_rotations(poses[:, :3, :3], path, linenos)
    if timestamps is None:
        _warn(notes)
        return Trajectory(rowidx.astype(np.float64), poses)
    source = ""
    if isinstance(timestamps, (str, Path)):
        source = f" in {timestamps}"
        timestamps = read_times(timestamps)
    timestamps = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    if timestamps.shape[0] != n_total:
        raise InputError(f"KITTI trajectory has {n_total} poses but {timestamps.shape[0]} timestamps{source}",
                         path=path)
    _warn(notes)
    return Trajectory(timestamps[rowidx], poses)


def data_lines(path: Path) -> list[str]:
    out = []
    for raw in read_text_file(path, "trajectory").splitlines():
        line = raw.split("#", 1)[0].strip()
        if line:
            out.append(line)
    return out


def read_times(path: str | Path) -> np.ndarray:
    """Read a KITTI / TUM-monoVO style ``times.txt``: one timestamp per line (first column)."""
    path = Path(path)
    out = []
    for lineno, raw in enumerate(read_text_file(path, "timestamps file").splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        fields = line.replace(",", " ").split()
        if not fields:
            raise InputError("no timestamp on this line", path=path, line=lineno)
        first = fields[0]
        try:
            t = float(first)
        except ValueError:
            raise InputError(f"cannot read timestamp {first!r}", path=path, line=lineno) from None
        if not math.isfinite(t):
            raise InputError(f"timestamp {first!r} is not a finite number", path=path, line=lineno)
        out.append(t)
    if not out:
        raise InputError("no timestamps in the file", path=path)
    return np.asarray(out)


def read_trajectory(path: str | Path, format: str | None = None, times: str | Path | None = None) -> Trajectory:
    """Read a TUM or KITTI trajectory; ``format=None`` guesses from the number of columns (8 vs 12).

    ``times`` (a ``times.txt``) gives KITTI-format files their timestamps; TUM files carry their own.
    """
    path = Path(path)
    if format is None:
        lines = data_lines(path) if path.exists() else []
        n = len(lines[0].replace(",", " ").split()) if lines else 8
        format = "kitti" if n == 12 else "tum"
    if format == "tum":
        return read_tum(path)
    if format == "kitti":
        return read_kitti(path, timestamps=times)
    raise ValueError(f"unknown trajectory format {format!r} (use 'tum' or 'kitti')")


# -- writing -------------------------------------------------------------------------------------
def tum_row_text(timestamp: float, values: Any) -> str:
    """One TUM line without its newline: ``%.6f`` timestamp, ``%.9g`` for tx ty tz qx qy qz qw (byte-repeatable)."""
    return f"{timestamp:.6f} " + " ".join(f"{v:.9g}" for v in values)


def tum_line(timestamp: float, T_wc: np.ndarray) -> str:
    """The TUM line (with newline) of one 4×4 camera-to-world pose, formatted like :func:`format_tum`."""
    q = matrix_to_quaternion(T_wc[:3, :3])
    return tum_row_text(timestamp, (*T_wc[:3, 3], *q)) + "\n"


def format_tum(traj: Trajectory, header: str | None = None) -> str:
    """The TUM text of a trajectory (``%.6f`` timestamps, ``%.9g`` numbers — repeatable to the byte)."""
    lines = [] if header is None else [f"# {h}" for h in header.splitlines()]
    for row in traj.to_tum_array():
        lines.append(tum_row_text(row[0], row[1:]))
    return "\n".join(lines) + "\n"


def write_tum(path: str | Path, traj: Trajectory, header: str | None = None) -> None:
    """Write ``timestamp tx ty tz qx qy qz qw`` lines (atomically)."""
    write_text(Path(path), format_tum(traj, header))


def write_kitti(path: str | Path, traj: Trajectory) -> None:
    """Write 3×4 row-major pose lines (atomically); timestamps are not stored in this format."""
    lines = [" ".join(f"{v:.9e}" for v in pose[:3, :4].reshape(-1)) for pose in traj.poses]
    write_text(Path(path), "\n".join(lines) + "\n")
