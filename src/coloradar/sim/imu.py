"""IMU model: specific force and angular rate in the IMU frame, from the analytic trajectory.

For an IMU mounted at ``base_T_imu = (R_bi, t_bi)`` on a rig with world pose ``(R_wb, p)``,
base-frame angular velocity ``ω`` and angular acceleration ``α``::

    a_imu   = p̈ + R_wb (α × t_bi + ω × (ω × t_bi))          (world acceleration of the IMU)
    f       = R_biᵀ R_wbᵀ (a_imu − g),   g = (0, 0, −9.80665) m/s²   (specific force)
    ω_imu   = R_biᵀ ω

A resting IMU therefore reads ``+9.81 m/s²`` along its own up axis. A constant bias per axis
and white noise are added to both (the truth file records the biases).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .trajectory import RigTrajectory

__all__ = ["GRAVITY", "ImuModel", "simulate_imu"]

GRAVITY = np.array([0.0, 0.0, -9.80665])
"""Gravity in the world frame (z up) [m/s²]."""


@dataclass(frozen=True)
class ImuModel:
    """Noise and bias of a MEMS IMU (a 3DM-GX5-class unit sampled at 300 Hz).

    Attributes
    ----------
    rate
        Samples per second [Hz].
    accel_noise, gyro_noise
        White noise per sample [m/s², rad/s].
    accel_bias, gyro_bias
        Standard deviation of the constant per-axis bias drawn for a run [m/s², rad/s].
    jitter
        Standard deviation of the timestamps [s].
    """

    rate: float = 300.0
    accel_noise: float = 0.02
    gyro_noise: float = 0.002
    accel_bias: float = 0.02
    gyro_bias: float = 0.002
    jitter: float = 2.0e-5


def simulate_imu(trajectory: RigTrajectory, base_T_imu: np.ndarray, times: np.ndarray,
                 model: ImuModel | None = None, rng: np.random.Generator | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IMU samples at ``times``.

    Parameters
    ----------
    trajectory
        The rig's motion (times relative to the run start [s]).
    base_T_imu
        float ``(4, 4)``: the IMU's extrinsic.
    times
        float64 ``(N,)`` sample times [s, run time].
    model
        Noise model (default :class:`ImuModel`).
    rng
        Random generator for biases and noise (None: an ideal IMU).

    Returns
    -------
    data : numpy.ndarray
        float64 ``(N, 6)``: ax ay az [m/s²] gx gy gz [rad/s], IMU frame.
    accel_bias, gyro_bias : numpy.ndarray
        float64 ``(3,)`` each: the biases that were added.
    """
    model = model or ImuModel()
    st = trajectory.state(times)
    r_bi = base_T_imu[:3, :3]
    t_bi = base_T_imu[:3, 3]
    w, dw = st.angular_velocity, st.angular_acceleration
    lever = np.cross(dw, t_bi) + np.cross(w, np.cross(w, t_bi))                    # base frame
    a_world = st.acceleration + st.rotation.apply(lever)
    f_base = st.rotation.inv().apply(a_world - GRAVITY)
    data = np.hstack([f_base @ r_bi, w @ r_bi])                                    # R_biᵀ x
    ab = np.zeros(3)
    gb = np.zeros(3)
    if rng is not None:
        ab = rng.normal(0.0, model.accel_bias, 3)
        gb = rng.normal(0.0, model.gyro_bias, 3)
        n = len(times)
        data[:, :3] += ab + rng.normal(0.0, model.accel_noise, (n, 3))
        data[:, 3:] += gb + rng.normal(0.0, model.gyro_noise, (n, 3))
    return data, ab, gb
