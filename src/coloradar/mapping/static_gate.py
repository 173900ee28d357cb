"""Keep the radar points a static world explains: the Doppler test of a moving sensor.

A static scatterer in direction ``u`` (unit, sensor frame) seen from a sensor moving at ``v``
(sensor frame, the velocity of its origin) has the range rate ``ṙ = −uᵀv``
(:func:`coloradar.geometry.static_range_rate`). A point whose range rate is far from that is a
mover (a person, a cart) or a ghost whose Doppler does not belong to its direction; a map of
the static world leaves it out, ray and all. The sensor's velocity comes from the trajectory
that places the frames (the ground truth, the odometry's, SLAM's), by
:func:`coloradar.geometry.rig_velocity`. The test allows the Doppler's own error (``floor``:
a bin's interpolation error, whichever is larger of ``floor`` and 0.75 of the radar's Doppler
bin, the rule of the odometry's static inliers, which sits above this layer) and the
range-rate error a direction error makes at speed (``|v| · sin(direction_std)``, twice).
Range rates folded at the radar's ``v_max`` are compared folded. Radar-mapping work segments
static from moving detections this way (e.g. Kellner et al., "Instantaneous ego-motion
estimation using Doppler radar", ITSC 2013, for the model).

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

from ..calib import RadarCalib
from ..errors import SettingsError
from ..geometry import static_range_rate

__all__ = ["StaticGate", "StaticTest", "static_frames", "static_mask"]


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


def static_mask(cloud: np.ndarray, velocity: np.ndarray, gate: StaticGate,
                velocity_bin_width: float = 0.0, max_velocity: float | None = None
                ) -> np.ndarray:
    """Which points of a radar frame a static world explains (module docstring).

    Parameters
    ----------
    cloud
        float ``(N, 5)``: x y z [m], intensity, range rate [m/s] (sensor frame).
    velocity
        float ``(3,)``: the sensor's velocity [m/s], sensor frame
        (:func:`coloradar.geometry.rig_velocity`).
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
    res = c[:, 4] - static_range_rate(c[:, :3], v)        # NaN at the origin: not kept
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

    @classmethod
    def for_radar(cls, radar: RadarCalib, gate: StaticGate | None = None) -> StaticTest:
        """The test of a radar's frames with its Doppler bin and ``v_max`` (default gate)."""
        w = radar.waveform
        return cls(gate or StaticGate(), float(w.velocity_bin_width), float(w.max_velocity))

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
    :func:`coloradar.geometry.rig_velocity`)."""
    return [np.asarray(c)[test(c, v)] for c, v in zip(clouds, velocities, strict=True)]
