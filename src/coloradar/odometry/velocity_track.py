"""Ego-velocities of a whole stream of radar frames, and their CSV table.

The table (``ego_velocity.csv``) has ``#`` comment lines (radar frame, producer), a header,
and one row per radar frame::

    timestamp,vx,vy,vz,cov_xx,cov_yy,cov_zz,cov_xy,cov_xz,cov_yz,num_points,num_inliers,sigma,ok,reason

velocities in the radar frame [m/s], covariance entries [m²/s²], ``ok`` 1 or 0, ``reason``
quoted text (empty when ok). Timestamps are written with 9 decimals (float64 Unix seconds).
"""

from __future__ import annotations

import csv
import io
import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import FormatError, MissingDataError, SettingsError
from ..formats.atomic import atomic_write_text, new_output_path
from ..formats.source import read_file_text
from .ego_velocity import EgoVelocity, EgoVelocityConfig, estimate_ego_velocity

__all__ = [
    "EgoVelocityTrack",
    "estimate_ego_velocities",
    "format_velocity_table",
    "parse_velocity_table",
    "read_velocity_table",
    "write_velocity_table",
]

COLUMNS = ("timestamp", "vx", "vy", "vz", "cov_xx", "cov_yy", "cov_zz", "cov_xy", "cov_xz",
           "cov_yz", "num_points", "num_inliers", "sigma", "ok", "reason")
_COV_INDEX = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


@dataclass(frozen=True, eq=False)
class EgoVelocityTrack:
    """Per-frame ego-velocities of one radar.

    Attributes
    ----------
    timestamps
        float64 ``(M,)`` [s]: the radar frames' timestamps.
    velocity
        float64 ``(M, 3)`` [m/s], sensor frame; NaN rows where not estimated.
    covariance
        float64 ``(M, 3, 3)`` [m²/s²].
    num_points, num_inliers
        int64 ``(M,)``.
    sigma
        float64 ``(M,)`` [m/s]: inlier residual standard deviation.
    ok
        bool ``(M,)``.
    reasons
        ``M`` strings, empty where ok.
    frame
        The sensor frame the velocities are expressed in (``"cascade"``, ``"single_chip"``).
    """

    timestamps: np.ndarray
    velocity: np.ndarray
    covariance: np.ndarray
    num_points: np.ndarray
    num_inliers: np.ndarray
    sigma: np.ndarray
    ok: np.ndarray
    reasons: list[str] = field(default_factory=list)
    frame: str = "radar"

    def __post_init__(self) -> None:
        m = np.asarray(self.timestamps).size
        shapes = {"velocity": (m, 3), "covariance": (m, 3, 3), "num_points": (m,),
                  "num_inliers": (m,), "sigma": (m,), "ok": (m,)}
        for name, shape in shapes.items():
            if np.shape(getattr(self, name)) != shape:
                raise SettingsError(f"EgoVelocityTrack.{name}: expected shape {shape}, "
                                    f"got {np.shape(getattr(self, name))}")
        if not self.reasons and m:
            object.__setattr__(self, "reasons", [""] * m)
        if len(self.reasons) != m:
            raise SettingsError(f"EgoVelocityTrack: {m} frames but {len(self.reasons)} reasons")

    def __len__(self) -> int:
        return int(self.timestamps.size)

    @classmethod
    def from_estimates(cls, timestamps: np.ndarray, estimates: list[EgoVelocity],
                       frame: str = "radar") -> EgoVelocityTrack:
        """Stack per-frame :class:`EgoVelocity` results."""
        t = np.asarray(timestamps, dtype=np.float64).reshape(-1)
        if t.size != len(estimates):
            raise SettingsError(f"{t.size} timestamps but {len(estimates)} estimates")
        cols, reasons = _columns(t.size)
        for k, e in enumerate(estimates):
            _put(cols, reasons, k, e)
        return cls(t, **cols, reasons=reasons, frame=frame)

    def std(self) -> np.ndarray:
        """float64 ``(M, 3)``: standard deviations of vx, vy, vz [m/s]."""
        return np.sqrt(np.diagonal(self.covariance, axis1=1, axis2=2))


def _columns(m: int) -> tuple[dict[str, np.ndarray], list[str]]:
    """Empty columns of an :class:`EgoVelocityTrack` of ``m`` frames, and its reasons."""
    return ({"velocity": np.empty((m, 3)), "covariance": np.empty((m, 3, 3)),
             "num_points": np.empty(m, dtype=np.int64), "num_inliers": np.empty(m, dtype=np.int64),
             "sigma": np.empty(m), "ok": np.empty(m, dtype=bool)}, [""] * m)


def _put(cols: dict[str, np.ndarray], reasons: list[str], k: int, e: EgoVelocity) -> None:
    """Row ``k`` of the columns from one frame's estimate."""
    for name, col in cols.items():
        col[k] = getattr(e, name)
    reasons[k] = e.reason


def estimate_ego_velocities(clouds: Iterable[np.ndarray], timestamps: np.ndarray,
                            config: EgoVelocityConfig | None = None, *, seed: int = 0,
                            frame: str = "radar",
                            progress: Callable[[int, int], None] | None = None,
                            on_frame: Callable[[int, np.ndarray, EgoVelocity], None] | None = None
                            ) -> EgoVelocityTrack:
    """:func:`~coloradar.odometry.estimate_ego_velocity` for every cloud of a stream.

    The track is filled column by column: nothing of a frame (its cloud, its estimate with
    the inlier mask) is kept once read, so memory holds about 140 bytes a frame whatever the
    clouds' sizes.

    Parameters
    ----------
    clouds
        float ``(N_k, 5)`` clouds ``x y z intensity range_rate``, one per timestamp (a
        :class:`~coloradar.dataset.FrameStream` of point clouds works directly).
    timestamps
        float64 ``(M,)`` [s].
    config
        Estimator settings.
    seed
        The ``k``-th cloud draws its minimal sets with ``SeedSequence([seed, k])``, so each
        frame's result is reproducible on its own (e.g. when frames are split across workers).
    frame
        Name of the sensor frame, stored with the track.
    progress
        Called as ``progress(done, total)`` after each frame.
    on_frame
        Called as ``on_frame(k, cloud, estimate)`` after each frame, for a caller that keeps
        something of the cloud or of the estimate (SLAM: the static points, on disk).
    """
    t = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    cols, reasons = _columns(t.size)
    n = 0
    for k, cloud in enumerate(clouds):
        if k >= t.size:
            raise SettingsError(f"more clouds than the {t.size} timestamps")
        rng = np.random.default_rng(np.random.SeedSequence([seed, k]))
        e = estimate_ego_velocity(cloud, config=config, rng=rng)
        _put(cols, reasons, k, e)
        n = k + 1
        if on_frame is not None:
            on_frame(k, cloud, e)
        if progress is not None:
            progress(n, t.size)
    if n != t.size:
        raise SettingsError(f"{t.size} timestamps but {n} clouds")
    return EgoVelocityTrack(t, **cols, reasons=reasons, frame=frame)


def format_velocity_table(track: EgoVelocityTrack, comments: Iterable[str] = ()) -> str:
    """The CSV text of ``track`` (see the module docstring)."""
    buf = io.StringIO()
    buf.write(f"# ego-velocity of the {track.frame} radar origin in its own frame "
              "(x boresight, y left, z up), m/s\n")
    buf.write(f"# frame: {track.frame}\n")
    for c in comments:
        buf.write(f"# {c}\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(COLUMNS)
    cov = np.stack([track.covariance[:, i, j] for i, j in _COV_INDEX], axis=1)
    for k in range(len(track)):
        w.writerow([f"{track.timestamps[k]:.9f}",
                    *(repr(float(x)) for x in track.velocity[k]),
                    *(repr(float(x)) for x in cov[k]),
                    int(track.num_points[k]), int(track.num_inliers[k]),
                    repr(float(track.sigma[k])), int(track.ok[k]), track.reasons[k]])
    return buf.getvalue()


def write_velocity_table(path: str | os.PathLike[str], track: EgoVelocityTrack, *,
                         comments: Iterable[str] = (), overwrite: bool = False) -> Path:
    """Write ``track`` as CSV, atomically; :class:`~coloradar.OutputExistsError` if it exists."""
    path = new_output_path(path, overwrite)
    atomic_write_text(path, format_velocity_table(track, comments))
    return path


def parse_velocity_table(text: str, name: str = "<ego_velocity.csv>") -> EgoVelocityTrack:
    """Parse the CSV text written by :func:`format_velocity_table`."""
    frame = "radar"
    lines = []
    for ln in text.splitlines():
        if ln.startswith("#"):
            if ln.startswith("# frame:"):
                frame = ln.split(":", 1)[1].strip()
            continue
        if ln.strip():
            lines.append(ln)
    rows = list(csv.reader(lines))
    if not rows or tuple(rows[0]) != COLUMNS:
        raise FormatError(f"{name}: expected a header line '{','.join(COLUMNS)}'")
    body = rows[1:]
    m = len(body)
    num = np.empty((m, len(COLUMNS) - 1))
    reasons = []
    for k, row in enumerate(body):
        if len(row) != len(COLUMNS):
            raise FormatError(f"{name}, data row {k + 1}: expected {len(COLUMNS)} fields, "
                              f"found {len(row)}")
        try:
            num[k] = [float(x) for x in row[:-1]]
        except ValueError:
            raise FormatError(f"{name}, data row {k + 1}: expected numbers in the first "
                              f"{len(COLUMNS) - 1} fields") from None
        reasons.append(row[-1])
    cov = np.zeros((m, 3, 3))
    for c, (i, j) in enumerate(_COV_INDEX):
        cov[:, i, j] = cov[:, j, i] = num[:, 4 + c]
    if m and np.any(np.diff(num[:, 0]) <= 0):
        raise FormatError(f"{name}: timestamps must be strictly increasing")
    return EgoVelocityTrack(num[:, 0].copy(), num[:, 1:4].copy(), cov,
                            num[:, 10].astype(np.int64), num[:, 11].astype(np.int64),
                            num[:, 12].copy(), num[:, 13] != 0, reasons, frame)


def read_velocity_table(path: str | os.PathLike[str]) -> EgoVelocityTrack:
    """Read an ``ego_velocity.csv`` table."""
    path = Path(path)
    try:
        text = read_file_text(path)
    except MissingDataError:
        raise MissingDataError(f"{path}: ego-velocity table not found") from None
    return parse_velocity_table(text, str(path))
