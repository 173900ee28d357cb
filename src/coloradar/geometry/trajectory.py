"""Timestamped pose sequences (``world_T_body(t)``) and their interpolation.

Interpolation between two knots is linear in translation and spherical-linear (SLERP, scipy's
:class:`~scipy.spatial.transform.Slerp`) in rotation, so it is exact at the knots and continuous
between them. Asking for a time outside the knots' span raises :class:`ExtrapolationError`
unless the time lies within ``tolerance`` seconds of an end, where the end pose is used.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import cached_property
from typing import overload

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from .._arrays import readonly
from ..errors import DataWarning, ExtrapolationError, FormatError, SettingsError
from .se3 import SE3, rotate

__all__ = ["ExtrapolationError", "Trajectory", "trajectory_from_groundtruth"]


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Poses ``frame_T_body`` at strictly increasing times.

    Attributes
    ----------
    timestamps
        float64 ``(N,)`` [s], strictly increasing.
    translations
        float64 ``(N, 3)`` [m]: the body origin in ``frame``.
    rotations
        :class:`~scipy.spatial.transform.Rotation` of length N.
    name
        What the poses are (for error messages), e.g. ``"groundtruth"``.
    """

    timestamps: np.ndarray
    translations: np.ndarray
    rotations: Rotation
    name: str = "trajectory"

    def __post_init__(self) -> None:
        t = np.array(self.timestamps, dtype=np.float64).reshape(-1)
        p = np.array(self.translations, dtype=np.float64)
        r = self.rotations
        if r.single:
            r = Rotation.concatenate([r])
        if p.shape != (t.size, 3) or len(r) != t.size:
            raise SettingsError(f"{self.name}: {t.size} timestamps, translations {p.shape}, "
                                f"{len(r)} rotations")
        if t.size == 0:
            raise FormatError(f"{self.name}: a trajectory needs at least one pose")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p))):
            raise FormatError(f"{self.name}: timestamps and positions must be finite")
        if np.any(np.diff(t) <= 0):
            raise FormatError(f"{self.name}: timestamps must be strictly increasing "
                              "(use Trajectory.from_poses to sort and drop duplicates)")
        object.__setattr__(self, "timestamps", readonly(t))
        object.__setattr__(self, "translations", readonly(p))
        object.__setattr__(self, "rotations", r)

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def from_poses(cls, timestamps: np.ndarray, poses: np.ndarray,
                   name: str = "poses") -> Trajectory:
        """From the dataset's pose rows ``x y z qx qy qz qw``, cleaning the time axis.

        Rows out of time order are sorted and rows repeating an earlier timestamp are dropped,
        each with a :class:`~coloradar.DataWarning`; both occur in recorded pose files.

        Parameters
        ----------
        timestamps
            float64 ``(N,)`` [s].
        poses
            float ``(N, 7)``: x y z [m], qx qy qz qw.
        name
            For messages (e.g. the file name).
        """
        t = np.asarray(timestamps, dtype=np.float64).reshape(-1)
        p = np.asarray(poses, dtype=np.float64)
        if p.ndim != 2 or p.shape[1] != 7 or p.shape[0] != t.size:
            raise FormatError(f"{name}: expected {t.size} pose rows of 7 values "
                              f"(x y z qx qy qz qw), got an array of shape {p.shape}")
        norms = np.linalg.norm(p[:, 3:], axis=1)
        if t.size and not np.all(norms > 1e-6):
            bad = int(np.argmin(norms > 1e-6))
            raise FormatError(f"{name}: pose row {bad} has a zero quaternion")
        order = np.argsort(t, kind="stable")
        if np.any(order != np.arange(t.size)):
            warnings.warn(f"{name}: timestamps out of order; sorted", DataWarning, stacklevel=2)
            t, p = t[order], p[order]
        keep = np.concatenate([[True], np.diff(t) > 0]) if t.size else np.ones(0, bool)
        if not keep.all():
            warnings.warn(f"{name}: {int((~keep).sum())} repeated timestamps; kept the first "
                          "pose of each", DataWarning, stacklevel=2)
            t, p = t[keep], p[keep]
        if t.size == 0:
            raise FormatError(f"{name}: no poses")
        return cls(t, p[:, :3], Rotation.from_quat(p[:, 3:]), name)

    @classmethod
    def from_se3(cls, timestamps: np.ndarray, poses: list[SE3],
                 name: str = "trajectory") -> Trajectory:
        """From a list of :class:`SE3` poses at ``timestamps``."""
        return cls(np.asarray(timestamps, dtype=np.float64),
                   np.array([p.translation for p in poses]).reshape(-1, 3),
                   Rotation.concatenate([p.rotation for p in poses]), name)

    # -- container ----------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(self.timestamps.size)

    @overload
    def __getitem__(self, key: int | np.integer) -> SE3: ...
    @overload
    def __getitem__(self, key: slice | np.ndarray) -> Trajectory: ...
    def __getitem__(self, key: int | np.integer | slice | np.ndarray) -> SE3 | Trajectory:
        """An int gives the :class:`SE3` pose at that knot; a slice or index array a Trajectory."""
        if isinstance(key, (int, np.integer)):
            return SE3(self.rotations[int(key)], self.translations[int(key)])
        return Trajectory(self.timestamps[key], self.translations[key], self.rotations[key],
                          self.name)

    def __repr__(self) -> str:
        return (f"<Trajectory {self.name}: {len(self)} poses over {self.duration:.3f} s "
                f"from t={self.start:.6f}>")

    @property
    def start(self) -> float:
        """First timestamp [s]."""
        return float(self.timestamps[0])

    @property
    def end(self) -> float:
        """Last timestamp [s]."""
        return float(self.timestamps[-1])

    @property
    def duration(self) -> float:
        """``end - start`` [s]."""
        return self.end - self.start

    def poses(self) -> np.ndarray:
        """float64 ``(N, 7)`` rows ``x y z qx qy qz qw`` (``qw >= 0``)."""
        return np.concatenate([self.translations, self.rotations.as_quat(canonical=True)], axis=1)

    def matrices(self) -> np.ndarray:
        """float64 ``(N, 4, 4)`` homogeneous matrices."""
        m = np.zeros((len(self), 4, 4))
        m[:, :3, :3] = self.rotations.as_matrix()
        m[:, :3, 3] = self.translations
        m[:, 3, 3] = 1.0
        return m

    # -- algebra ------------------------------------------------------------------------------
    def __matmul__(self, other: SE3) -> Trajectory:
        """``frame_T_sensor(t) = frame_T_body(t) @ body_T_sensor`` for every pose."""
        if not isinstance(other, SE3):
            return NotImplemented
        return Trajectory(self.timestamps,
                          rotate(self.rotations, other.translation) + self.translations,
                          self.rotations * other.rotation, self.name)

    def __rmatmul__(self, other: SE3) -> Trajectory:
        """``new_T_body(t) = new_T_frame @ frame_T_body(t)`` for every pose."""
        if not isinstance(other, SE3):
            return NotImplemented
        return Trajectory(self.timestamps, rotate(other.rotation, self.translations)
                          + other.translation, other.rotation * self.rotations, self.name)

    def inverse(self) -> Trajectory:
        """``body_T_frame(t)`` for every pose."""
        inv = self.rotations.inv()
        return Trajectory(self.timestamps, -rotate(inv, self.translations), inv, self.name)

    def relative_to_first(self) -> Trajectory:
        """The same motion expressed in the first pose's body frame (first pose = identity)."""
        return self[0].inverse() @ self

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Map point ``i`` with pose ``i``: ``(N, 3)`` body points -> ``(N, 3)`` frame points.

        Useful with :meth:`interpolate` at per-point timestamps (e.g. de-skewing a sweep).
        """
        p = np.asarray(points, dtype=np.float64)
        if p.shape != (len(self), 3):
            raise SettingsError(f"expected ({len(self)}, 3) points, one per pose, got {p.shape}")
        return rotate(self.rotations, p) + self.translations

    # -- interpolation ------------------------------------------------------------------------
    @cached_property
    def _slerp(self) -> Slerp:
        # Times relative to the first knot: Slerp divides differences of Unix times otherwise.
        return Slerp(self.timestamps - self.timestamps[0], self.rotations)

    def check_span(self, t: np.ndarray, tolerance: float) -> np.ndarray:
        """``t`` clipped to the trajectory's span; :class:`ExtrapolationError` when some time
        lies more than ``tolerance`` [s] outside it (or is not finite).

        Parameters
        ----------
        t
            float64 ``(N,)`` times [s].
        tolerance
            Allowed distance outside the span [s].
        """
        lo, hi = self.start - tolerance, self.end + tolerance
        outside = (t < lo) | (t > hi) | ~np.isfinite(t)
        if np.any(outside):
            bad = t[outside]
            raise ExtrapolationError(
                f"{self.name}: {bad.size} of {t.size} requested times lie outside the poses' "
                f"span [{self.start:.6f}, {self.end:.6f}] s (tolerance {tolerance:g} s); "
                f"e.g. t={bad[0]:.6f} s, {_offset(bad[0], self.start, self.end)}")
        return np.clip(t, self.start, self.end)

    def interpolate(self, times: np.ndarray, tolerance: float = 0.0) -> Trajectory:
        """Poses at arbitrary ``times``.

        Parameters
        ----------
        times
            float64 ``(M,)`` [s], strictly increasing (as any stream's timestamps are).
            Use :meth:`at` for a single time and :meth:`interpolate_arrays` for unordered times.
        tolerance
            Times up to this many seconds before the first or after the last knot get the end
            pose instead of raising.

        Returns
        -------
        Trajectory
            M poses at ``times``: linear translation, SLERP rotation, exact at the knots.

        Raises
        ------
        ExtrapolationError
            A time lies outside ``[start - tolerance, end + tolerance]``.
        """
        t = np.asarray(times, dtype=np.float64).reshape(-1)
        if np.any(np.diff(t) <= 0):
            raise SettingsError("interpolate: times must be strictly increasing; use "
                                "interpolate_arrays for times in any order")
        trans, rot = self.interpolate_arrays(t, tolerance)
        return Trajectory(t, trans, rot, self.name)

    def interpolate_arrays(self, times: np.ndarray,
                           tolerance: float = 0.0) -> tuple[np.ndarray, Rotation]:
        """Like :meth:`interpolate`, for times in any order: float64 ``(M, 3)`` and a Rotation."""
        t = self.check_span(np.asarray(times, dtype=np.float64).reshape(-1), tolerance)
        if len(self) == 1:
            zeros = np.zeros(t.size, dtype=np.intp)
            return self.translations[zeros], self.rotations[zeros]
        k = self.timestamps
        i = np.clip(np.searchsorted(k, t, side="right") - 1, 0, len(k) - 2)
        alpha = ((t - k[i]) / (k[i + 1] - k[i]))[:, None]
        trans = (1.0 - alpha) * self.translations[i] + alpha * self.translations[i + 1]
        rot = self._slerp(t - k[0])
        return trans, rot

    def at(self, time: float, tolerance: float = 0.0) -> SE3:
        """The interpolated pose at one ``time`` [s] (see :meth:`interpolate`)."""
        trans, rot = self.interpolate_arrays(np.array([time], dtype=np.float64), tolerance)
        return SE3(rot[0], trans[0])

    def covers(self, times: np.ndarray, tolerance: float = 0.0) -> np.ndarray:
        """bool ``(M,)``: which ``times`` can be interpolated without extrapolating."""
        t = np.asarray(times, dtype=np.float64)
        return (t >= self.start - tolerance) & (t <= self.end + tolerance)


def _offset(t: float, start: float, end: float) -> str:
    if t < start:
        return f"{start - t:.3f} s before the first pose"
    if t > end:
        return f"{t - end:.3f} s after the last pose"
    return "not a finite time"


def trajectory_from_groundtruth(seq, source: str = "groundtruth") -> Trajectory:
    """``world_T_base(t)`` of a run from its ground truth (or ``source="vicon"``).

    The dataset's ground-truth poses are the rig's base frame in a world frame fixed at the
    run's start pose (docs/conventions.md §1).

    Parameters
    ----------
    seq
        A :class:`coloradar.dataset` sequence (anything with ``.groundtruth.timestamps`` and
        ``.groundtruth.poses``).
    source
        ``"groundtruth"`` or ``"vicon"``.
    """
    from ..errors import MissingDataError

    track = getattr(seq, source, None)
    if track is None:
        raise MissingDataError(f"{getattr(seq, 'name', 'run')}: no {source} poses in this run")
    return Trajectory.from_poses(track.timestamps, track.poses,
                                 f"{getattr(seq, 'name', 'run')}/{source}")
