"""IMU model: specific force and angular rate in the IMU frame, from the analytic trajectory.

For an IMU mounted at ``base_T_imu = (R_bi, t_bi)`` on a rig with world pose ``(R_wb, p)``,
base-frame angular velocity ``ω`` and angular acceleration ``α``::

    a_imu   = p̈ + R_wb (α × t_bi + ω × (ω × t_bi))          (world acceleration of the IMU)
    f       = R_biᵀ R_wbᵀ (a_imu − g),   g = (0, 0, −9.80665) m/s²   (specific force)
    ω_imu   = R_biᵀ ω

A resting IMU therefore reads ``+9.81 m/s²`` along its own up axis. The errors of a MEMS unit
are added to both (:class:`ImuModel`): a turn-on bias drawn once per run, a bias that then
wanders as a random walk, and white noise. Their defaults are those of the MicroStrain
3DM-GX5-25 that the ColoRadar rig carries (see :data:`GX5_25`); the truth file records the
biases at every sample.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import SettingsError
from .trajectory import RigTrajectory

__all__ = ["GRAVITY", "GX5_25", "ImuModel", "simulate_imu"]

GRAVITY = np.array([0.0, 0.0, -9.80665])
"""Gravity in the world frame (z up) [m/s²]."""

_G0 = 9.80665
_DEG = np.pi / 180.0


@dataclass(frozen=True)
class ImuModel:
    """Noise and bias of a MEMS IMU, in continuous-time densities (independent of the rate).

    Attributes
    ----------
    rate
        Samples per second [Hz].
    accel_noise_density, gyro_noise_density
        White-noise densities [m/s²/√Hz], [rad/s/√Hz]; a sample at rate ``f`` carries noise of
        standard deviation ``density · √f``.
    accel_bias, gyro_bias
        Standard deviation of the turn-on bias drawn per axis for a run [m/s²], [rad/s].
    accel_bias_walk, gyro_bias_walk
        Bias random-walk densities [m/s²/√s], [rad/s/√s]: after ``T`` seconds the bias has
        wandered by ``walk · √T`` (1σ, per axis).
    jitter
        Standard deviation of the timestamps [s].
    """

    rate: float = 300.0
    accel_noise_density: float = 100e-6 * _G0
    gyro_noise_density: float = 0.005 * _DEG
    accel_bias: float = 0.002 * _G0
    gyro_bias: float = 0.04 * _DEG
    accel_bias_walk: float = 0.04e-3 * _G0 / 10.0
    gyro_bias_walk: float = 8.0 * _DEG / 3600.0 / 10.0
    jitter: float = 2.0e-5

    def __post_init__(self) -> None:
        for name in ("accel_noise_density", "gyro_noise_density", "accel_bias", "gyro_bias",
                     "accel_bias_walk", "gyro_bias_walk", "jitter"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise SettingsError(f"ImuModel.{name} must be a finite number >= 0, got {v!r}")
        if not self.rate > 0:
            raise SettingsError(f"ImuModel.rate must be positive, got {self.rate!r}")

    def scaled(self, factor: float) -> ImuModel:
        """The model with every noise and bias term multiplied by ``factor`` (0: ideal IMU;
        the timestamp jitter is kept)."""
        if not (np.isfinite(factor) and factor >= 0):
            raise SettingsError(f"IMU error scale must be a finite number >= 0, got {factor!r}")
        return replace(self, **{k: getattr(self, k) * factor for k in (
            "accel_noise_density", "gyro_noise_density", "accel_bias", "gyro_bias",
            "accel_bias_walk", "gyro_bias_walk")})

    @property
    def accel_noise(self) -> float:
        """Accelerometer white noise per sample [m/s²]."""
        return self.accel_noise_density * float(np.sqrt(self.rate))

    @property
    def gyro_noise(self) -> float:
        """Gyro white noise per sample [rad/s]."""
        return self.gyro_noise_density * float(np.sqrt(self.rate))


GX5_25 = ImuModel()
"""The MicroStrain 3DM-GX5-25 of the ColoRadar rig, from its datasheet (MicroStrain/LORD,
"3DM-GX5-25 Attitude and Heading Reference System", datasheet 8400-0093): accelerometer noise
density 100 µg/√Hz, initial bias ±0.002 g, bias instability ±0.04 mg; gyro noise density
0.005 °/s/√Hz, initial bias ±0.04 °/s, bias instability 8 °/h. The datasheet gives no
random-walk density; the bias-instability values are turned into one as ``instability / √(100 s)``
(the bias wanders by the instability over 100 s), the convention of the ``arpg/goggles``
radar-inertial configuration for this IMU (4e-6 rad/s/√s, 4e-5 m/s²/√s)."""


def _bias_track(rng: np.random.Generator, times: np.ndarray, turn_on: float,
                walk: float) -> np.ndarray:
    n = times.size
    b0 = rng.normal(0.0, turn_on, 3) if turn_on > 0 else np.zeros(3)
    if walk <= 0 or n < 2:
        return np.tile(b0, (n, 1))
    dt = np.diff(times, prepend=times[0])
    steps = rng.normal(0.0, 1.0, (n, 3)) * (walk * np.sqrt(np.maximum(dt, 0.0)))[:, None]
    return b0 + np.cumsum(steps, axis=0)


def simulate_imu(trajectory: RigTrajectory, base_T_imu: np.ndarray, times: np.ndarray,
                 model: ImuModel | None = None, rng: np.random.Generator | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IMU samples at ``times``.

    Parameters
    ----------
    trajectory
        The rig's motion (anything with ``state(times)``; times relative to the run start [s]).
    base_T_imu
        float ``(4, 4)``: the IMU's extrinsic.
    times
        float64 ``(N,)`` sample times [s, run time].
    model
        Error model (default :data:`GX5_25`).
    rng
        Random generator for biases and noise (None: an ideal IMU).

    Returns
    -------
    data : numpy.ndarray
        float64 ``(N, 6)``: ax ay az [m/s²] gx gy gz [rad/s], IMU frame.
    accel_bias, gyro_bias : numpy.ndarray
        float64 ``(N, 3)`` each: the bias in every sample (turn-on bias plus random walk).
    """
    model = model or GX5_25
    times = np.asarray(times, dtype=np.float64)
    st = trajectory.state(times)
    r_bi = base_T_imu[:3, :3]
    t_bi = base_T_imu[:3, 3]
    w, dw = st.angular_velocity, st.angular_acceleration
    lever = np.cross(dw, t_bi) + np.cross(w, np.cross(w, t_bi))                    # base frame
    a_world = st.acceleration + st.rotation.apply(lever)
    f_base = st.rotation.inv().apply(a_world - GRAVITY)
    data = np.hstack([f_base @ r_bi, w @ r_bi])                                    # R_biᵀ x
    n = times.size
    ab = np.zeros((n, 3))
    gb = np.zeros((n, 3))
    if rng is not None:
        ab = _bias_track(rng, times, model.accel_bias, model.accel_bias_walk)
        gb = _bias_track(rng, times, model.gyro_bias, model.gyro_bias_walk)
        data[:, :3] += ab + rng.normal(0.0, model.accel_noise, (n, 3))
        data[:, 3:] += gb + rng.normal(0.0, model.gyro_noise, (n, 3))
    return data, ab, gb
