"""Extrinsics (``transforms/base_to_<sensor>.txt``): the pose of each sensor in the rig's base frame.

``base_to_<sensor>`` maps sensor coordinates into base coordinates:
``p_base = R(q) · p_sensor + t`` (docs/conventions.md §3). The base frame is the ENU-aligned rig frame
(x right, y forward, z up).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError, CalibrationWarning
from ._parse import check_finite, readonly

__all__ = ["Extrinsic", "format_transform", "parse_transform"]


@dataclass(frozen=True, eq=False)
class Extrinsic:
    """Pose of a sensor in the base frame (``base_T_sensor``).

    Attributes
    ----------
    translation
        float64 ``(3,)`` [m].
    quaternion
        float64 ``(4,)`` ``qx qy qz qw`` (scalar last, the convention of
        :class:`scipy.spatial.transform.Rotation`), unit norm.
    """

    translation: np.ndarray
    quaternion: np.ndarray

    def __post_init__(self) -> None:
        t = np.asarray(self.translation, dtype=np.float64).reshape(-1)
        q = np.asarray(self.quaternion, dtype=np.float64).reshape(-1)
        if t.shape != (3,) or q.shape != (4,):
            raise CalibrationError(f"extrinsic: expected 3 + 4 values, got {t.size} + {q.size}")
        n = np.linalg.norm(q)
        if not np.isfinite(n) or n < 1e-6:
            raise CalibrationError(f"extrinsic: quaternion {q.tolist()} has no direction")
        if not np.all(np.isfinite(t)):
            raise CalibrationError(f"extrinsic: translation {t.tolist()} is not finite")
        object.__setattr__(self, "translation", readonly(t))
        object.__setattr__(self, "quaternion", readonly(q / n))

    def matrix(self) -> np.ndarray:
        """The 4x4 homogeneous matrix ``base_T_sensor``."""
        from scipy.spatial.transform import Rotation

        m = np.eye(4)
        m[:3, :3] = Rotation.from_quat(self.quaternion).as_matrix()
        m[:3, 3] = self.translation
        return m


def parse_transform(text: str, name: str = "base_to_sensor.txt") -> Extrinsic:
    """Parse a two-line transform file: ``x y z`` then ``qx qy qz qw``."""
    lines = [ln.split() for ln in text.splitlines() if ln.strip()]
    if len(lines) != 2 or len(lines[0]) != 3 or len(lines[1]) != 4:
        raise CalibrationError(f"{name}: expected two lines, 'x y z' and 'qx qy qz qw'")
    try:
        t = np.array(lines[0], dtype=np.float64)
        q = np.array(lines[1], dtype=np.float64)
    except ValueError:
        raise CalibrationError(f"{name}: expected numbers") from None
    check_finite(t, name, "the translation 'x y z'")
    check_finite(q, name, "the quaternion 'qx qy qz qw'")
    if np.any(np.abs(t) > 1000.0):
        raise CalibrationError(f"{name}: translation {t.tolist()} m; expected a sensor within "
                               "1 km of the rig's base")
    n = float(np.linalg.norm(q))
    if not np.isfinite(n) or n < 1e-6:
        raise CalibrationError(f"{name}: quaternion {q.tolist()} has no direction")
    if abs(n - 1.0) > 1e-3:
        warnings.warn(f"{name}: quaternion norm is {n:.6f}; normalised", CalibrationWarning,
                      stacklevel=2)
    return Extrinsic(t, q)


def format_transform(e: Extrinsic) -> str:
    """The dataset's transform file text for ``e``."""
    return (" ".join(repr(float(v)) for v in e.translation) + "\n"
            + " ".join(repr(float(v)) for v in e.quaternion) + "\n")
