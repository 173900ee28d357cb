"""A small, frozen rigid transform type.

Naming convention used throughout coloradar: ``a_T_b`` is the transform that maps the
coordinates of a point in frame ``b`` to its coordinates in frame ``a``
(``p_a = a_T_b.apply(p_b)``), which is also the pose of frame ``b`` expressed in frame ``a``.
Composition chains the inner names: ``world_T_sensor = world_T_base @ base_T_sensor``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from .._arrays import readonly
from ..errors import SettingsError

if TYPE_CHECKING:
    from ..calib import Extrinsic

__all__ = ["SE3", "transform_points"]


def rotate(rotation: Rotation, vectors: np.ndarray) -> np.ndarray:
    """``rotation.apply(vectors)`` in float64; accepts read-only arrays (scipy's does not)."""
    return rotation.apply(np.array(vectors, dtype=np.float64))


def transform_points(rotation: np.ndarray, translation: np.ndarray,
                     points: np.ndarray) -> np.ndarray:
    """``R · p + t`` for every row of ``points``, in the points' floating dtype.

    Parameters
    ----------
    rotation
        float ``(3, 3)`` rotation matrix.
    translation
        float ``(3,)`` [m].
    points
        float ``(N, 3)`` or ``(3,)`` [m]. float32 input stays float32 (point clouds are float32;
        run-relative coordinates of a few hundred metres keep ~10 µm resolution).

    Returns
    -------
    numpy.ndarray
        Same shape as ``points``; float32 for float32 input, else float64.
    """
    p = np.asarray(points)
    dtype = p.dtype if p.dtype in (np.float32, np.float64) else np.float64
    p = p.astype(dtype, copy=False)
    if p.shape[-1] != 3:
        raise SettingsError(f"expected points of shape (N, 3) or (3,), got {p.shape}")
    return p @ rotation.T.astype(dtype) + translation.astype(dtype)


@dataclass(frozen=True, eq=False)
class SE3:
    """A rigid transform ``a_T_b``: ``p_a = R · p_b + t``.

    Attributes
    ----------
    rotation
        A single :class:`scipy.spatial.transform.Rotation`.
    translation
        float64 ``(3,)`` [m], read-only: the origin of frame ``b`` in frame ``a``.

    Examples
    --------
    >>> world_T_cascade = world_T_base @ SE3.from_extrinsic(calib.transforms["cascade"])
    >>> points_world = world_T_cascade.apply(points_cascade)
    """

    rotation: Rotation
    translation: np.ndarray

    def __post_init__(self) -> None:
        if not isinstance(self.rotation, Rotation) or not self.rotation.single:
            raise SettingsError("SE3.rotation must be a single scipy Rotation")
        t = np.array(self.translation, dtype=np.float64).reshape(-1)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise SettingsError(f"SE3.translation must be 3 finite numbers, got {t.tolist()}")
        object.__setattr__(self, "translation", readonly(t))

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def identity(cls) -> SE3:
        """The identity transform."""
        return cls(Rotation.identity(), np.zeros(3))

    @classmethod
    def from_matrix(cls, matrix: np.ndarray) -> SE3:
        """From a 4x4 homogeneous matrix (the rotation block is orthonormalised by scipy)."""
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape != (4, 4) or not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0]):
            raise SettingsError(f"expected a 4x4 homogeneous matrix, got shape {m.shape}")
        return cls(Rotation.from_matrix(m[:3, :3]), m[:3, 3])

    @classmethod
    def from_pose(cls, pose: np.ndarray) -> SE3:
        """From a pose row ``x y z qx qy qz qw`` (the dataset's pose files)."""
        p = np.asarray(pose, dtype=np.float64).reshape(-1)
        if p.shape != (7,):
            raise SettingsError(f"expected a pose row of 7 values (x y z qx qy qz qw), got {p.size}")
        return cls(Rotation.from_quat(p[3:]), p[:3])

    @classmethod
    def from_extrinsic(cls, extrinsic: Extrinsic) -> SE3:
        """From a calibration :class:`~coloradar.calib.Extrinsic` (``base_T_sensor``)."""
        return cls(Rotation.from_quat(extrinsic.quaternion), extrinsic.translation)

    # -- views --------------------------------------------------------------------------------
    def matrix(self) -> np.ndarray:
        """float64 ``(4, 4)`` homogeneous matrix."""
        m = np.eye(4)
        m[:3, :3] = self.rotation.as_matrix()
        m[:3, 3] = self.translation
        return m

    def as_pose(self) -> np.ndarray:
        """float64 ``(7,)`` pose row ``x y z qx qy qz qw`` (``qw >= 0``)."""
        return np.concatenate([self.translation, self.rotation.as_quat(canonical=True)])

    # -- algebra ------------------------------------------------------------------------------
    def inverse(self) -> SE3:
        """``b_T_a`` from ``a_T_b``."""
        inv = self.rotation.inv()
        return SE3(inv, -rotate(inv, self.translation))

    def __matmul__(self, other: SE3) -> SE3:
        """``a_T_c = a_T_b @ b_T_c``; with a :class:`~coloradar.geometry.Trajectory` on the
        right, every pose (``Trajectory.__rmatmul__`` answers: this module knows nothing of
        trajectories)."""
        if isinstance(other, SE3):
            return SE3(self.rotation * other.rotation,
                       rotate(self.rotation, other.translation) + self.translation)
        return NotImplemented

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Map points from frame ``b`` to frame ``a``.

        Parameters
        ----------
        points
            float ``(N, 3)`` or ``(3,)`` [m].

        Returns
        -------
        numpy.ndarray
            Same shape; float32 stays float32, anything else becomes float64.
        """
        return transform_points(self.rotation.as_matrix(), self.translation, points)

    def apply_to_cloud(self, cloud: np.ndarray) -> np.ndarray:
        """Map a point cloud ``(N, C)``, ``C >= 3``: columns 0-2 are x y z, the rest is copied.

        Intensity and range-rate columns are frame-independent scalars and keep their values.
        """
        c = np.asarray(cloud)
        if c.ndim != 2 or c.shape[1] < 3:
            raise SettingsError(f"expected a point cloud of shape (N, C>=3), got {c.shape}")
        out = np.array(c, dtype=c.dtype if c.dtype in (np.float32, np.float64) else np.float64)
        out[:, :3] = self.apply(out[:, :3])
        return out

    def rotate(self, vectors: np.ndarray) -> np.ndarray:
        """Rotate direction or velocity vectors ``(N, 3)`` or ``(3,)`` (no translation)."""
        return transform_points(self.rotation.as_matrix(), np.zeros(3), vectors)

    def __repr__(self) -> str:
        t = ", ".join(f"{v:.4f}" for v in self.translation)
        q = ", ".join(f"{v:.4f}" for v in self.rotation.as_quat(canonical=True))
        return f"SE3(t=[{t}], q_xyzw=[{q}])"
