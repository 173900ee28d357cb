"""Radar point clouds drawn at the detection level: fast runs for odometry Monte Carlo.

The full simulator (:mod:`.run`) ray-casts a scene and synthesises ADC samples; a Monte Carlo
of radar-inertial odometry needs hundreds of minutes of data and only what the estimator sees:
per frame a few dozen detections, each a direction and a range rate. :func:`simulate_clouds`
draws them directly from the rig's analytic motion:

- **static points** in random directions of the field of view (elevations around
  ``elevation_mean``, i.e. not centred on boresight when it is not 0, as a radar mounted
  low sees more above than below), range rate ``ṙ = −uᵀ y`` (``y`` the radar origin's
  velocity, radar frame) plus Gaussian Doppler noise, the reported direction the true one
  turned by Gaussian azimuth and elevation errors;
- **ghosts** (multipath, false alarms): random directions, range rates uniform over
  ``±(speed + 1 m/s)``, the span static points and near movers occupy;
- **movers**: a compact cluster moving with its own velocity.

Range rates are folded into ``[−v_max, v_max)`` when ``max_velocity`` is set. Clouds are
``(N, 5)`` ``x y z intensity range_rate`` as the dataset's; ``intensity`` is 1 for static
points, 0 for ghosts, 2 for movers (ground truth for tests; no estimator reads it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SettingsError

__all__ = ["CloudModel", "radar_velocities", "simulate_clouds"]

_DEG = np.pi / 180.0


@dataclass(frozen=True)
class CloudModel:
    """What one radar's detections look like.

    Attributes
    ----------
    points
        ``(min, max)`` detections per frame (uniform).
    azimuth_fov, elevation_fov
        Half-widths of the field of view [rad].
    elevation_mean, elevation_spread
        Mean and standard deviation of the static points' true elevation [rad].
    ranges
        ``(min, max)`` range [m].
    range_rate_std
        Doppler error [m/s].
    azimuth_std, elevation_std
        Direction errors [rad].
    ghost_fraction, mover_fraction
        Fractions of the detections that are ghosts and points of a moving object.
    max_velocity
        Fold range rates into ``[−v_max, v_max)`` [m/s] (None: unwrapped).
    """

    points: tuple[int, int] = (10, 40)
    azimuth_fov: float = 60.0 * _DEG
    elevation_fov: float = 20.0 * _DEG
    elevation_mean: float = 4.0 * _DEG
    elevation_spread: float = 8.0 * _DEG
    ranges: tuple[float, float] = (1.0, 20.0)
    range_rate_std: float = 0.05
    azimuth_std: float = 3.0 * _DEG
    elevation_std: float = 4.0 * _DEG
    ghost_fraction: float = 0.1
    mover_fraction: float = 0.05
    max_velocity: float | None = None

    def __post_init__(self) -> None:
        if not 1 <= self.points[0] <= self.points[1]:
            raise SettingsError(f"CloudModel.points must be 1 <= min <= max, got {self.points}")
        if not 0 <= self.ghost_fraction + self.mover_fraction < 1:
            raise SettingsError("CloudModel: ghost and mover fractions must add up to < 1")
        for name in ("range_rate_std", "azimuth_std", "elevation_std", "elevation_spread"):
            if not getattr(self, name) >= 0:
                raise SettingsError(f"CloudModel.{name} must be >= 0")


def radar_velocities(trajectory, base_T_radar: np.ndarray, times: np.ndarray) -> np.ndarray:
    """float64 ``(M, 3)``: the radar origin's velocity in its own frame at ``times`` [m/s].

    ``y = R_brᵀ (R_wbᵀ v_b + ω_b × t_br)`` from the rig's state (``trajectory.state``).
    """
    st = trajectory.state(np.asarray(times, dtype=np.float64))
    vb = st.rotation.inv().apply(st.velocity) + np.cross(st.angular_velocity, base_T_radar[:3, 3])
    return vb @ base_T_radar[:3, :3]


def _directions(az: np.ndarray, el: np.ndarray) -> np.ndarray:
    return np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def _frame(y: np.ndarray, model: CloudModel, rng: np.random.Generator) -> np.ndarray:
    """One ``(N, 5)`` cloud of a radar moving with ``y`` (radar frame)."""
    n = int(rng.integers(model.points[0], model.points[1] + 1))
    n_ghost = int(rng.binomial(n, model.ghost_fraction))
    n_mover = int(rng.binomial(n - n_ghost, model.mover_fraction / (1 - model.ghost_fraction)))
    n_static = n - n_ghost - n_mover
    az = rng.uniform(-model.azimuth_fov, model.azimuth_fov, n)
    el = np.clip(rng.normal(model.elevation_mean, model.elevation_spread, n),
                 -model.elevation_fov, model.elevation_fov)
    # Movers: a compact cluster (±3°) with its own velocity (radar frame).
    c_az, c_el = az[0], el[0]
    sl = slice(n_static + n_ghost, n)
    az[sl] = c_az + rng.normal(0, 3 * _DEG, n_mover)
    el[sl] = c_el + rng.normal(0, 3 * _DEG, n_mover)
    u = _directions(az, el)
    rate = -(u @ y)
    speed = float(np.linalg.norm(y))
    rate[n_static:n_static + n_ghost] = rng.uniform(-speed - 1.0, speed + 1.0, n_ghost)
    v_obj = rng.normal(0, 1.0, 3) * np.array([1.0, 1.0, 0.1])
    rate[sl] = u[sl] @ (v_obj - y)
    rate = rate + rng.normal(0, model.range_rate_std, n)
    if model.max_velocity:
        span = 2 * model.max_velocity
        rate = (rate + model.max_velocity) % span - model.max_velocity
    az_o = az + rng.normal(0, model.azimuth_std, n)
    el_o = el + rng.normal(0, model.elevation_std, n)
    r = rng.uniform(*model.ranges, n)
    xyz = _directions(az_o, el_o) * r[:, None]
    kind = np.concatenate([np.ones(n_static), np.zeros(n_ghost), np.full(n_mover, 2.0)])
    return np.column_stack([xyz, kind, rate]).astype(np.float32)


def simulate_clouds(trajectory, base_T_radar: np.ndarray, times: np.ndarray,
                    model: CloudModel, rng: np.random.Generator
                    ) -> tuple[list[np.ndarray], np.ndarray]:
    """Detections of a radar on a moving rig at ``times``.

    Parameters
    ----------
    trajectory
        The rig's motion (anything with ``state(t)``, times relative to the run start [s]).
    base_T_radar
        float ``(4, 4)``: the radar's extrinsic.
    times
        float64 ``(M,)`` frame times [s].
    model
        The detections' statistics.
    rng
        Random generator.

    Returns
    -------
    clouds : list of numpy.ndarray
        ``M`` float32 ``(N_k, 5)`` clouds ``x y z kind range_rate`` (kind: 1 static,
        0 ghost, 2 mover).
    velocity : numpy.ndarray
        float64 ``(M, 3)``: the true radar velocity (radar frame) [m/s].
    """
    y = radar_velocities(trajectory, base_T_radar, times)
    return [_frame(v, model, rng) for v in y], y
