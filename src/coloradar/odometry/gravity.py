"""Initial attitude from gravity: the IMU's mean specific force over the first samples.

At rest the accelerometer reads ``f = Rᵀ(−g) + b_a``: the IMU's *up* axis in its own frame.
When the rig already moves, its own acceleration ``a_b`` (IMU frame) is in the reading too,
``f = a_b − Rᵀg + b_a``; the radar's velocities over the same window give ``a_b ≈ du/dt + ω × u``
(``u`` the IMU origin's velocity in the IMU frame), which is removed before the alignment.
Only roll and pitch are observable; yaw is set to the smallest rotation that makes the
measured up axis the world's z.
"""

from __future__ import annotations

import numpy as np

from ..errors import ColoradarError

__all__ = ["gravity_alignment"]


def gravity_alignment(specific_force: np.ndarray,
                      body_acceleration: np.ndarray | None = None) -> np.ndarray:
    """``world_R_imu`` whose world z is the measured up direction.

    Parameters
    ----------
    specific_force
        float ``(3,)`` or ``(N, 3)`` [m/s²]: (samples of) the accelerometer, IMU frame; a set
        of samples is averaged.
    body_acceleration
        float ``(3,)`` [m/s²]: the IMU's own mean acceleration over the same samples (IMU
        frame), removed first; None: the rig is taken to be at rest.

    Returns
    -------
    numpy.ndarray
        float64 ``(3, 3)`` rotation matrix.
    """
    f = np.asarray(specific_force, dtype=np.float64)
    f = f.reshape(-1, 3).mean(axis=0)
    if body_acceleration is not None:
        f = f - np.asarray(body_acceleration, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(f))
    if not np.isfinite(n) or n < 1.0:
        raise ColoradarError(f"gravity alignment: the mean specific force is {n:.3g} m/s², "
                             "not about 9.8 (are the IMU columns ax ay az gx gy gz in m/s²?)")
    up = f / n
    z = np.array([0.0, 0.0, 1.0])
    # Smallest rotation taking `up` to z (Rodrigues with the cross product as axis).
    c = float(up @ z)
    axis = np.cross(up, z)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    k = axis / s
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * kx + (1 - c) * (kx @ kx)
