"""Text files of ColoRadar: timestamps, IMU samples, poses.

Timestamps are float64 Unix seconds (never float32: 1.6e9 s would lose ~100 s of resolution).
"""

from __future__ import annotations

import io
import os

import numpy as np

from ..errors import FormatError, SettingsError
from .atomic import atomic_write_text

__all__ = [
    "format_imu",
    "format_poses",
    "format_timestamps",
    "parse_imu",
    "parse_poses",
    "parse_table",
    "parse_timestamps",
    "write_imu",
    "write_poses",
    "write_timestamps",
]


def parse_table(text: str, ncols: int, name: str, what: str) -> np.ndarray:
    """Parse whitespace-separated numbers, ``ncols`` per non-empty line, to float64 ``(N, ncols)``.

    Raises :class:`FormatError` naming the file, the line number and what was expected.
    """
    if not text.strip():
        return np.zeros((0, ncols))
    # np.loadtxt checks that every line has the same number of columns, in C.
    try:
        values = np.loadtxt(io.StringIO(text), dtype=np.float64, ndmin=2)
    except ValueError:
        values = None
    if values is not None and values.shape[1] == ncols:
        return values
    # Slow path, only to say precisely where the file is wrong.
    for lineno, ln in enumerate(text.splitlines(), start=1):
        if not ln.strip():
            continue
        parts = ln.split()
        if len(parts) != ncols:
            raise FormatError(f"{name}, line {lineno}: expected {ncols} numbers ({what}), "
                              f"found {len(parts)}: {ln.strip()[:80]!r}")
        for p in parts:
            try:
                float(p)
            except ValueError:
                raise FormatError(f"{name}, line {lineno}: expected a number ({what}), "
                                  f"found {p[:40]!r}") from None
    raise FormatError(f"{name}: could not parse as {ncols} numbers per line")  # pragma: no cover


def parse_timestamps(text: str, name: str = "<timestamps>") -> np.ndarray:
    """Parse a timestamps file (one Unix time in seconds per line) to float64 ``(N,)``."""
    return parse_table(text, 1, name, "a timestamp in seconds")[:, 0].copy()


def parse_imu(text: str, name: str = "<imu_data>") -> np.ndarray:
    """Parse ``imu_data.txt``: float64 ``(N, 6)`` ax ay az [m/s²] gx gy gz [rad/s]."""
    return parse_table(text, 6, name, "ax ay az gx gy gz")


def parse_poses(text: str, name: str = "<poses>") -> np.ndarray:
    """Parse a poses file: float64 ``(N, 7)`` x y z [m] qx qy qz qw."""
    return parse_table(text, 7, name, "x y z qx qy qz qw")


def format_timestamps(t: np.ndarray) -> str:
    """Timestamps as text, full float64 precision (about 1 µs at Unix times), one per line."""
    t = np.asarray(t, dtype=np.float64).ravel()
    return "".join(f"{v:.9f}\n" for v in t)


def _format_rows(a: np.ndarray, ncols: int) -> str:
    a = np.asarray(a, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != ncols:
        raise SettingsError(f"expected an (N, {ncols}) array, got shape {a.shape}")
    return "".join(" ".join(repr(float(v)) for v in row) + "\n" for row in a)


def format_imu(data: np.ndarray) -> str:
    """IMU samples ``(N, 6)`` as text."""
    return _format_rows(data, 6)


def format_poses(poses: np.ndarray) -> str:
    """Poses ``(N, 7)`` as text."""
    return _format_rows(poses, 7)


def write_timestamps(path: str | os.PathLike[str], t: np.ndarray) -> None:
    """Write a timestamps file atomically."""
    atomic_write_text(path, format_timestamps(t))


def write_imu(path: str | os.PathLike[str], data: np.ndarray) -> None:
    """Write ``imu_data.txt`` atomically."""
    atomic_write_text(path, format_imu(data))


def write_poses(path: str | os.PathLike[str], poses: np.ndarray) -> None:
    """Write a poses file atomically."""
    atomic_write_text(path, format_poses(poses))
