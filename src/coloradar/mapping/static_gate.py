"""Keep the radar points a static world explains: the Doppler test of a moving sensor.

A static scatterer in direction ``u`` (unit, sensor frame) seen from a sensor moving at ``v``
(sensor frame, the velocity of its origin) has the range rate ``ṙ = −uᵀv``. A point whose
range rate is far from that is a mover (a person, a cart) or a ghost whose Doppler does not
belong to its direction; a map of the static world leaves it out, ray and all. The sensor's
velocity comes from the trajectory that places the frames (the ground truth, the odometry's,
SLAM's), by central differences. The test allows the Doppler's own error (``floor``: a bin's
interpolation error, whichever is larger of ``floor`` and 0.75 of the radar's Doppler bin, the
odometry's static-inlier rule) and the range-rate error a direction error makes at speed
(``|v| · sin(direction_std)``, twice). Range rates folded at the radar's ``v_max`` are compared
folded. Radar-mapping work segments static from moving detections this way (e.g. Kellner et
al., "Instantaneous ego-motion estimation using Doppler radar", ITSC 2013, for the model).

The test trusts the range rates. Where they are not a static world's — zeros from a bag
without a Doppler field, a recorder's opposite sign, the release's cascade heatmaps (whose
channel 1 was made with the wrong chirp-time units), poses of another run — most of a moving
frame's points fail it; :class:`StaticTest` then keeps that frame whole and counts it, so
that a map is never emptied by a test whose premise does not hold (the caller warns).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import SettingsError
from ..geometry import Trajectory

__all__ = ["StaticGate", "StaticTest", "sensor_velocities", "static_frames", "static_mask"]


@dataclass(frozen=True)
class StaticGate:
    """Settings of the static-world Doppler test.

    Attributes
    ----------
    floor
        Smallest range-rate tolerance [m/s] (the radar's Doppler bin raises it:
        ``max(floor, 0.75 · bin)``).
    direction_std_deg
        A point's direction error the test allows for [deg]; the tolerance grows by
        ``2 · |v| · sin`` of it.
    """

    floor: float = 0.1
    direction_std_deg: float = 3.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.floor) and self.floor > 0):
            raise SettingsError(f"StaticGate.floor must be > 0 [m/s], got {self.floor!r}")
        if not (math.isfinite(self.direction_std_deg) and 0 <= self.direction_std_deg < 90):
            raise SettingsError("StaticGate.direction_std_deg must be in [0, 90), got "
                                f"{self.direction_std_deg!r}")

    def tolerance(self, speed: float, velocity_bin_width: float = 0.0) -> float:
        """The range-rate tolerance [m/s] at ``speed`` [m/s]."""
        base = max(self.floor, 0.75 * float(velocity_bin_width))
        return base + 2.0 * float(speed) * math.sin(math.radians(self.direction_std_deg))


def sensor_velocities(trajectory: Trajectory, times: np.ndarray, base_T_sensor: np.ndarray,
                      h: float = 0.05) -> np.ndarray:
    """Velocity of the sensor's origin in the sensor's frame at ``times``.

    Parameters
    ----------
    trajectory
        ``world_T_base(t)``.
    times
        float64 ``(F,)`` [s], within the trajectory's span.
    base_T_sensor
        float ``(4, 4)``: the sensor's mounting.
    h
        Half the central difference's step [s] (clipped to the trajectory's span).

    Returns
    -------
    numpy.ndarray
        float64 ``(F, 3)`` [m/s].
    """
    t = np.asarray(times, np.float64)
    lo = np.maximum(t - h, trajectory.start)
    hi = np.minimum(t + h, trajectory.end)
    dt = np.where(hi > lo, hi - lo, 1.0)
    mount = np.asarray(base_T_sensor, np.float64)

    def origin(tt: np.ndarray) -> np.ndarray:
        p, r = trajectory.interpolate_arrays(tt)
        return p + r.apply(mount[:3, 3])

    v_world = (origin(hi) - origin(lo)) / dt[:, None]
    v_world[hi <= lo] = 0.0
    _, rot = trajectory.interpolate_arrays(t)
    r_ws = rot.as_matrix() @ mount[:3, :3]
    return np.einsum("nji,nj->ni", r_ws, v_world)


def static_mask(cloud: np.ndarray, velocity: np.ndarray, gate: StaticGate,
                velocity_bin_width: float = 0.0, max_velocity: float | None = None
                ) -> np.ndarray:
    """Which points of a radar frame a static world explains (module docstring).

    Parameters
    ----------
    cloud
        float ``(N, 5)``: x y z [m], intensity, range rate [m/s] (sensor frame).
    velocity
        float ``(3,)``: the sensor's velocity [m/s], sensor frame (:func:`sensor_velocities`).
    gate
        :class:`StaticGate`.
    velocity_bin_width, max_velocity
        The radar's Doppler bin [m/s] and unambiguous range rate [m/s] (None: not folded).

    Returns
    -------
    numpy.ndarray
        bool ``(N,)``.
    """
    c = np.asarray(cloud, np.float64)
    if c.ndim != 2 or c.shape[1] < 5:
        raise SettingsError(f"the static test needs range rates: a cloud of shape (N, >=5), "
                            f"got {c.shape}")
    v = np.asarray(velocity, np.float64)
    r = np.linalg.norm(c[:, :3], axis=1)
    u = c[:, :3] / np.maximum(r, 1e-9)[:, None]
    res = c[:, 4] + u @ v
    if max_velocity:
        span = 2.0 * float(max_velocity)
        res = res - span * np.round(res / span)
    return np.abs(res) <= gate.tolerance(float(np.linalg.norm(v)), velocity_bin_width)


class StaticTest:
    """The static test of one radar's frames, with its counts (module docstring).

    Parameters
    ----------
    gate
        :class:`StaticGate`.
    velocity_bin_width, max_velocity
        The radar's Doppler bin [m/s] and unambiguous range rate [m/s] (None: not folded).
    min_static
        A moving frame (speed above the tolerance at rest) of at least ``min_points`` points
        of which fewer than this share pass is kept whole: its range rates are not a static
        world's (a scene with most of its returns on movers is not one a static map is made
        of either).
    min_points
        Frames with fewer points are tested as they are.
    """

    def __init__(self, gate: StaticGate, velocity_bin_width: float = 0.0,
                 max_velocity: float | None = None, min_static: float = 0.3,
                 min_points: int = 8) -> None:
        self.gate, self.velocity_bin_width, self.max_velocity = gate, velocity_bin_width, \
            max_velocity
        self.min_static, self.min_points = min_static, min_points
        self.frames = self.frames_kept_whole = self.points = self.points_dropped = 0

    def __call__(self, cloud: np.ndarray, velocity: np.ndarray) -> np.ndarray:
        """bool ``(N,)``: the points kept (:func:`static_mask`, or all of a frame whose range
        rates are not a static world's)."""
        keep = static_mask(cloud, velocity, self.gate, self.velocity_bin_width,
                           self.max_velocity)
        n = keep.size
        self.frames += 1
        self.points += n
        moving = float(np.linalg.norm(velocity)) > self.gate.tolerance(0.0,
                                                                      self.velocity_bin_width)
        if moving and n >= self.min_points and keep.mean() < self.min_static:
            self.frames_kept_whole += 1
            return np.ones(n, bool)
        self.points_dropped += int(n - keep.sum())
        return keep

    def summary(self) -> dict[str, int]:
        """Frames tested, frames kept whole, points tested and points left out."""
        return {"frames": self.frames, "frames_kept_whole": self.frames_kept_whole,
                "points": self.points, "points_dropped": self.points_dropped}

    def warning(self) -> str | None:
        """A sentence for the user when more than a tenth of the frames were kept whole."""
        if self.frames and self.frames_kept_whole > 0.1 * self.frames:
            return (f"the static test kept {self.frames_kept_whole} of {self.frames} frames "
                    "whole: most of their range rates are not a static world's (range rates "
                    "all zero or of the opposite sign, heatmaps whose range rates were made "
                    "with other chirp timings, or poses of another run); their movers and "
                    "ghosts are mapped")
        return None


def static_frames(clouds: list[np.ndarray], velocities: np.ndarray,
                  test: StaticTest) -> list[np.ndarray]:
    """Each frame's points that ``test`` keeps (``velocities``: ``(F, 3)``, one per cloud,
    :func:`sensor_velocities`)."""
    return [np.asarray(c)[test(c, v)] for c, v in zip(clouds, velocities, strict=True)]
