"""Trajectories in the TUM RGB-D format (Sturm et al., IROS 2012), as read by ``evo``.

One pose per line, ``timestamp tx ty tz qx qy qz qw``: Unix seconds, position [m], unit
quaternion with the scalar last; lines starting with ``#`` are comments. The pose is
``world_T_body`` (the body's position and orientation in the world).
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from ..errors import FormatError, MissingDataError
from ..formats.atomic import atomic_write_text, new_output_path
from ..formats.source import read_file_text
from ..formats.text import parse_table
from ..geometry import Trajectory

__all__ = ["format_tum", "parse_tum", "read_tum", "write_tum"]


def format_tum(trajectory: Trajectory, comments: Iterable[str] = ()) -> str:
    """TUM text of a trajectory: timestamps to 1 ns, positions and quaternions at full precision."""
    lines = [f"# {c}\n" for c in comments]
    lines.append("# timestamp tx ty tz qx qy qz qw\n")
    poses = trajectory.poses()
    for t, row in zip(trajectory.timestamps, poses, strict=True):
        lines.append(f"{t:.9f} " + " ".join(repr(float(v)) for v in row) + "\n")
    return "".join(lines)


def write_tum(path: str | os.PathLike[str], trajectory: Trajectory, *,
              comments: Iterable[str] = (), overwrite: bool = False) -> Path:
    """Write ``trajectory`` as a TUM file, atomically.

    Raises :class:`~coloradar.OutputExistsError` when ``path`` exists and not ``overwrite``.
    """
    path = new_output_path(path, overwrite)
    atomic_write_text(path, format_tum(trajectory, comments))
    return path


def parse_tum(text: str, name: str = "<tum>") -> Trajectory:
    """Parse TUM text to a :class:`~coloradar.geometry.Trajectory`.

    Raises :class:`~coloradar.FormatError` naming the line when a line does not hold 8 numbers
    or a quaternion is zero; rows out of time order are sorted with a warning
    (:meth:`Trajectory.from_poses`).
    """
    body = "\n".join("" if ln.lstrip().startswith("#") else ln for ln in text.splitlines())
    rows = parse_table(body, 8, name, "timestamp tx ty tz qx qy qz qw")
    if rows.shape[0] == 0:
        raise FormatError(f"{name}: no poses (expected lines 'timestamp tx ty tz qx qy qz qw')")
    return Trajectory.from_poses(rows[:, 0], rows[:, 1:], name)


def read_tum(path: str | os.PathLike[str]) -> Trajectory:
    """Read a TUM trajectory file."""
    path = Path(path)
    try:
        text = read_file_text(path)
    except MissingDataError:
        raise MissingDataError(f"{path}: trajectory file not found") from None
    return parse_tum(text, str(path))
