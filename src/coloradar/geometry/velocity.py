"""Rig velocity from the ground truth, expressed in any sensor's frame.

Method: centred finite differences of the *interpolated* trajectory (linear translation, SLERP
rotation; :meth:`Trajectory.interpolate`). For a query time ``t`` and half-window ``h``, the
poses at ``t - h`` and ``t + h`` (clamped to the trajectory's span, which makes the difference
one-sided at the ends) give

- the base origin's world velocity ``(p(t+h) − p(t−h)) / 2h``,
- the body angular velocity ``rotvec(R(t−h)ᵀ R(t+h)) / 2h`` (rotation vector of the relative
  rotation, expressed in the base frame).

Both are exact for motion at constant velocity and constant angular rate, and a ``±h``
average otherwise. The default ``h`` is the median ground-truth knot spacing, so that a
difference spans two segments and does not jump at every knot.

A sensor rigidly mounted at ``base_T_sensor = (R_bs, t_bs)`` moves with
``v_sensor = R_bsᵀ (R(t)ᵀ v_base + ω_base × t_bs)`` and ``ω_sensor = R_bsᵀ ω_base`` (its own
frame). A static point ``x`` seen by that sensor has range rate ``−(x/|x|)·v_sensor``
(:func:`static_range_rate`), the quantity a Doppler radar measures (> 0 receding).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..calib import Calibration
from ..errors import ColoradarError, SettingsError
from .frames import sensor_to_base
from .se3 import SE3, rotate
from .trajectory import Trajectory

__all__ = ["RigVelocity", "rig_velocity", "static_range_rate"]


@dataclass(frozen=True, eq=False)
class RigVelocity:
    """Linear and angular velocity of a frame rigidly attached to the rig.

    Attributes
    ----------
    timestamps
        float64 ``(M,)`` [s].
    linear
        float64 ``(M, 3)`` [m/s]: velocity of the frame's origin.
    angular
        float64 ``(M, 3)`` [rad/s]: angular velocity.
    frame
        The frame both are expressed in: a sensor name, ``"base"`` or ``"world"``.
    """

    timestamps: np.ndarray
    linear: np.ndarray
    angular: np.ndarray
    frame: str


def rig_velocity(trajectory: Trajectory, times: np.ndarray, *,
                 calib: Calibration | None = None, sensor: str = "base",
                 mount: SE3 | None = None, expressed_in: str | None = None,
                 half_window: float | None = None) -> RigVelocity:
    """Velocity of a sensor's origin, from the ground truth ``world_T_base(t)``.

    Parameters
    ----------
    trajectory
        ``world_T_base(t)``.
    times
        float64 ``(M,)`` [s] within the trajectory's span, any order.
    calib, sensor
        Which sensor's origin moves (its ``base_T_sensor`` from ``calib``); ``"base"`` (default)
        is the base frame itself.
    mount
        ``base_T_frame`` given directly instead of ``calib``/``sensor``.
    expressed_in
        ``"world"`` to express the velocities in the world frame; default: the sensor's own
        frame (what a sensor measures, e.g. the cascade radar's ego-velocity for Doppler).
    half_window
        ``h`` [s] of the centred difference; default the median knot spacing.

    Returns
    -------
    RigVelocity
    """
    if mount is None:
        if sensor != "base" and calib is None:
            raise SettingsError("rig_velocity: give calib (or mount) for a sensor other than base")
        mount = SE3.identity() if calib is None else sensor_to_base(calib, sensor)
        name = sensor
    else:
        name = "frame"
    if len(trajectory) < 2:
        raise ColoradarError(f"{trajectory.name}: a velocity needs at least two poses")
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    h = float(np.median(np.diff(trajectory.timestamps))) if half_window is None else half_window
    if not h > 0:
        raise SettingsError(f"rig_velocity: half_window must be positive, got {h}")
    trajectory.check_span(t, 0.0)
    ta = np.maximum(t - h, trajectory.start)
    tb = np.minimum(t + h, trajectory.end)
    dt = (tb - ta)[:, None]
    pa, ra = trajectory.interpolate_arrays(ta)
    pb, rb = trajectory.interpolate_arrays(tb)
    _, rt = trajectory.interpolate_arrays(t)
    v_base_world = (pb - pa) / dt
    w_base = (ra.inv() * rb).as_rotvec() / dt                 # body rates, base frame
    # Lever arm: the sensor origin sits at t_bs in the base frame.
    v_sensor_base = rotate(rt.inv(), v_base_world) + np.cross(w_base, mount.translation)
    if expressed_in == "world":
        return RigVelocity(t, rotate(rt, v_sensor_base), rotate(rt, w_base), "world")
    if expressed_in not in (None, name):
        raise SettingsError(f"rig_velocity: expressed_in must be None or 'world', got "
                            f"{expressed_in!r}")
    inv = mount.rotation.inv()
    return RigVelocity(t, rotate(inv, v_sensor_base), rotate(inv, w_base), name)


def static_range_rate(points: np.ndarray, sensor_velocity: np.ndarray) -> np.ndarray:
    """Range rate of static points seen by a moving sensor.

    Parameters
    ----------
    points
        float ``(N, 3)`` positions in the sensor frame [m].
    sensor_velocity
        float ``(3,)`` velocity of the sensor's origin in its own frame [m/s]
        (:attr:`RigVelocity.linear` with ``expressed_in=None``).

    Returns
    -------
    numpy.ndarray
        float ``(N,)`` [m/s], ``−û·v``: negative when the sensor closes in (docs/conventions.md §3).
    """
    p = np.asarray(points)
    dtype = p.dtype if p.dtype in (np.float32, np.float64) else np.float64
    p = p.astype(dtype, copy=False)
    r = np.linalg.norm(p, axis=-1)
    v = np.asarray(sensor_velocity, dtype=dtype)
    with np.errstate(invalid="ignore", divide="ignore"):
        return -(p @ v) / r
