"""The rig's analytic 6-DoF trajectory: a nominal path plus smooth hand-held perturbations.

``world_T_base(t)``: the world frame is z up (gravity along −z). The rig's *forward frame* F
(x forward, y left, z up) has ``world_R_F = Rz(ψ)·Ry(θ)·Rx(φ)`` with the heading
``ψ = ψ_path + δψ(t)`` and pitch ``θ = δθ(t)`` and roll ``φ = δφ(t)`` sums of sinusoids; the
base frame (x right, y forward, z up, docs/conventions.md §3) is F turned by −90° about z. The position
is the path's plus a sum-of-sinusoids offset. Velocity, acceleration, angular velocity and
angular acceleration follow in closed form (Euler-rate kinematics), so the IMU model and the
truth file are exact at every timestamp.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import SettingsError
from .paths import EllipsePath, LinePath, Path, Sinusoids

__all__ = ["MOTION_PROFILES", "RigState", "RigTrajectory", "make_trajectory"]

_F_R_BASE = Rotation.from_euler("z", -np.pi / 2)


@dataclass(frozen=True, eq=False)
class RigState:
    """The rig's base frame at N times.

    Attributes
    ----------
    times
        float64 ``(N,)`` [s] relative to the run start.
    position
        float64 ``(N, 3)``: base origin in the world [m].
    rotation
        ``world_R_base`` (a scipy ``Rotation`` of N rotations).
    velocity, acceleration
        float64 ``(N, 3)``: of the base origin, world frame [m/s], [m/s²].
    angular_velocity, angular_acceleration
        float64 ``(N, 3)``: of the base frame, expressed in the base frame [rad/s], [rad/s²].
    """

    times: np.ndarray
    position: np.ndarray
    rotation: Rotation
    velocity: np.ndarray
    acceleration: np.ndarray
    angular_velocity: np.ndarray
    angular_acceleration: np.ndarray

    def poses(self) -> np.ndarray:
        """float64 ``(N, 7)`` rows ``x y z qx qy qz qw`` of ``world_T_base``."""
        return np.hstack([self.position, self.rotation.as_quat(canonical=True)])

    def matrices(self) -> np.ndarray:
        """float64 ``(N, 4, 4)`` homogeneous ``world_T_base``."""
        m = np.zeros((len(self.times), 4, 4))
        m[:, :3, :3] = self.rotation.as_matrix()
        m[:, :3, 3] = self.position
        m[:, 3, 3] = 1.0
        return m


def _euler_body_rates(psi, th, ph, d1, d2):
    """Body angular velocity and acceleration of ``Rz(ψ)Ry(θ)Rx(φ)`` from Euler-angle rates.

    ``d1 = (ψ', θ', φ')``, ``d2 = (ψ'', θ'', φ'')``; returns two ``(N, 3)`` arrays in the
    rotated (body) frame.
    """
    p1, t1, f1 = d1
    p2, t2, f2 = d2
    st, ct, sf, cf = np.sin(th), np.cos(th), np.sin(ph), np.cos(ph)
    w = np.stack([f1 - p1 * st,
                  t1 * cf + p1 * ct * sf,
                  -t1 * sf + p1 * ct * cf], axis=-1)
    dw = np.stack([
        f2 - p2 * st - p1 * t1 * ct,
        t2 * cf - t1 * f1 * sf + p2 * ct * sf - p1 * t1 * st * sf + p1 * f1 * ct * cf,
        -t2 * sf - t1 * f1 * cf + p2 * ct * cf - p1 * t1 * st * cf - p1 * f1 * ct * sf,
    ], axis=-1)
    return w, dw


@dataclass(frozen=True, eq=False)
class RigTrajectory:
    """``world_T_base(t)`` in closed form.

    Attributes
    ----------
    path
        The nominal path (position and heading).
    offset
        Three :class:`Sinusoids`: world-frame position offsets x, y, z [m].
    yaw, pitch, roll
        :class:`Sinusoids` [rad] added to the path heading, and the pitch and roll of the
        forward frame.
    profile
        Name of the motion profile it was made with.
    """

    path: Path
    offset: tuple[Sinusoids, Sinusoids, Sinusoids]
    yaw: Sinusoids
    pitch: Sinusoids
    roll: Sinusoids
    profile: str = "custom"

    def state(self, t: np.ndarray) -> RigState:
        """The rig state at times ``t`` [s] relative to the run start (float64 ``(N,)``)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        ps = self.path.sample(t)
        off = [np.stack([o.derivative(t, k) for o in self.offset], axis=-1) for k in range(3)]
        psi = ps.heading + self.yaw.derivative(t)
        d1 = (ps.heading_rate + self.yaw.derivative(t, 1), self.pitch.derivative(t, 1),
              self.roll.derivative(t, 1))
        d2 = (ps.heading_accel + self.yaw.derivative(t, 2), self.pitch.derivative(t, 2),
              self.roll.derivative(t, 2))
        th, ph = self.pitch.derivative(t), self.roll.derivative(t)
        world_r_f = Rotation.from_euler("ZYX", np.stack([psi, th, ph], axis=-1))
        w_f, dw_f = _euler_body_rates(psi, th, ph, d1, d2)
        # Base = F turned by a constant rotation: rates just change coordinates.
        to_base = _F_R_BASE.inv()
        return RigState(
            times=t,
            position=ps.position + off[0],
            rotation=world_r_f * _F_R_BASE,
            velocity=ps.velocity + off[1],
            acceleration=ps.acceleration + off[2],
            angular_velocity=to_base.apply(w_f),
            angular_acceleration=to_base.apply(dw_f),
        )


# Perturbation recipes: per channel, (amplitudes, frequency range [Hz]). Amplitudes in m or rad.
MOTION_PROFILES: dict[str, dict] = {
    "smooth": {
        "speed_factor": 1.0,
        "offset": ((0.02, 0.02, 0.01), (0.05, 0.3)),
        "yaw": (np.radians(2.0), (0.05, 0.3)),
        "pitch": (np.radians(1.0), (0.1, 0.4)),
        "roll": (np.radians(1.0), (0.1, 0.4)),
    },
    "handheld": {
        "speed_factor": 1.0,
        # Gait: about 1.8 steps/s; sway at half the step rate.
        "offset": ((0.015, 0.015, 0.025), (0.8, 1.9)),
        "yaw": (np.radians(4.0), (0.1, 0.9)),
        "pitch": (np.radians(2.5), (0.5, 1.9)),
        "roll": (np.radians(2.5), (0.5, 1.0)),
    },
    "aggressive": {
        "speed_factor": 1.4,
        "offset": ((0.06, 0.06, 0.08), (0.3, 1.5)),
        "yaw": (np.radians(20.0), (0.2, 1.0)),
        "pitch": (np.radians(12.0), (0.3, 1.2)),
        "roll": (np.radians(15.0), (0.3, 1.2)),
    },
    "vehicle": {
        "speed_factor": 1.5,
        # A cart or car: slopes and suspension, little sway; pitch and heave at road rates.
        "offset": ((0.01, 0.01, 0.3), (0.02, 0.1)),
        "yaw": (np.radians(1.0), (0.05, 0.3)),
        "pitch": (np.radians(3.0), (0.05, 0.5)),
        "roll": (np.radians(1.5), (0.1, 0.6)),
    },
    "ramps": {
        "speed_factor": 1.0,
        # A rig carried over ramps and slopes (issue 42, as the runs written by another
        # program move): a 2 Hz step bob of ±3 cm, ±0.5 m of height at 0.02–0.06 Hz (up to
        # about 0.15 m/s of climb), pitch and roll of several degrees at the gait's rates.
        "offset": ((0.015, 0.015, 0.03), (1.6, 2.2)),
        "heave": (0.5, (0.02, 0.06)),
        "yaw": (np.radians(4.0), (0.1, 0.9)),
        "pitch": (np.radians(4.5), (0.5, 0.9)),
        "roll": (np.radians(5.5), (0.6, 1.0)),
    },
}
"""Named motion profiles: ``smooth`` (default; a carefully carried rig), ``handheld`` (walking
gait: bob, sway and tilt at the step rate), ``aggressive`` (fast, large rotations) and
``vehicle`` (1.5× the path's speed, slow pitch of a few degrees and tens of centimetres of
heave, as slopes and suspension give a cart or car) and ``ramps`` (a walk that rises and falls
by ±0.5 m over tens of seconds, with a step bob and several degrees of pitch and roll)."""


def _random_sinusoids(rng: np.random.Generator, amplitude: float, band: tuple[float, float],
                      n: int = 3) -> Sinusoids:
    f = rng.uniform(band[0], band[1], n)
    # Split the amplitude over n terms so the peak stays near `amplitude`.
    a = amplitude * rng.uniform(0.5, 1.0, n) / n * 1.5
    return Sinusoids(a, f, rng.uniform(0, 2 * np.pi, n))


def make_trajectory(path: Path, profile: str = "smooth",
                    seed: int | Sequence[int] | np.random.Generator | None = 0,
                    speed: float | None = None) -> RigTrajectory:
    """A rig trajectory along ``path`` with the perturbations of a motion profile.

    Parameters
    ----------
    path
        The scene's nominal rig path. With the ``aggressive`` profile its speed is scaled up.
    profile
        A key of :data:`MOTION_PROFILES`.
    seed
        Seed of the perturbations' random amplitudes, frequencies and phases.
    speed
        The path's nominal (top) speed [m/s], replacing the scene's (and the profile's
        scaling); None keeps them. Fast runs (a longboard, a cart) exceed the radars'
        unambiguous velocity (cascade 1.76 m/s, single chip 2.45 m/s).
    """
    if profile not in MOTION_PROFILES:
        raise SettingsError(f"unknown motion profile {profile!r}; expected one of "
                            f"{', '.join(MOTION_PROFILES)}")
    spec = MOTION_PROFILES[profile]
    rng = np.random.default_rng(seed)
    if speed is not None:
        if not (np.isfinite(speed) and speed >= 0):
            raise SettingsError(f"speed must be a finite non-negative number [m/s], got {float(speed):g}")
        if not isinstance(path, EllipsePath | LinePath):
            raise SettingsError(f"{type(path).__name__} has no speed to set")
        path = replace(path, speed=float(speed))
    elif spec["speed_factor"] != 1.0 and isinstance(path, EllipsePath | LinePath):
        path = replace(path, speed=path.speed * spec["speed_factor"])
    amps, band = spec["offset"]
    offset = tuple(_random_sinusoids(rng, a, band) for a in amps)
    if "heave" in spec:
        # Slow rise and fall on top of the gait's bob (drawn after it: the other profiles'
        # draws stay as they were).
        h_amp, h_band = spec["heave"]
        h = _random_sinusoids(rng, h_amp, h_band, n=2)
        z = offset[2]
        offset = (offset[0], offset[1], Sinusoids(np.concatenate([z.amplitude, h.amplitude]),
                                                  np.concatenate([z.frequency, h.frequency]),
                                                  np.concatenate([z.phase, h.phase])))
    return RigTrajectory(path, offset,  # type: ignore[arg-type]
                         _random_sinusoids(rng, *spec["yaw"]),
                         _random_sinusoids(rng, *spec["pitch"]),
                         _random_sinusoids(rng, *spec["roll"]), profile)
