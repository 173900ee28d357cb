"""Analytic motion primitives: sums of sinusoids and planar paths with exact derivatives.

Everything here is a closed-form function of time, so that position, velocity, acceleration and
jerk (and a heading with its first two derivatives) are exact at any query time. The rig
trajectory (:mod:`.trajectory`) and the moving objects of a scene are built from these.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import SettingsError

__all__ = ["EllipsePath", "LinePath", "Path", "PathSample", "Sinusoids", "path_from_dict"]


@dataclass(frozen=True, eq=False)
class Sinusoids:
    """``x(t) = Σ_i A_i · sin(2π f_i t + φ_i)``, with its derivatives.

    Attributes
    ----------
    amplitude, frequency, phase
        float64 ``(n,)``: amplitudes (any unit), frequencies [Hz], phases [rad].
    """

    amplitude: np.ndarray = field(default_factory=lambda: np.zeros(0))
    frequency: np.ndarray = field(default_factory=lambda: np.zeros(0))
    phase: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        for name in ("amplitude", "frequency", "phase"):
            object.__setattr__(self, name, np.atleast_1d(np.asarray(getattr(self, name), float)))
        if not (self.amplitude.shape == self.frequency.shape == self.phase.shape):
            raise SettingsError("Sinusoids: amplitude, frequency and phase must have the same length")

    def derivative(self, t: np.ndarray, order: int = 0) -> np.ndarray:
        """The ``order``-th time derivative at times ``t`` (float64, shape of ``t``)."""
        t = np.asarray(t, dtype=np.float64)
        if self.amplitude.size == 0:
            return np.zeros_like(t)
        w = 2.0 * np.pi * self.frequency
        # d^k/dt^k sin(wt + φ) = w^k sin(wt + φ + kπ/2)
        arg = np.multiply.outer(t, w) + self.phase + order * np.pi / 2
        return np.sin(arg) @ (self.amplitude * w**order)


@dataclass(frozen=True)
class PathSample:
    """A path evaluated at N times: derivatives of position (world, [m], [m/s], …) and heading.

    ``position``, ``velocity``, ``acceleration``, ``jerk`` are float64 ``(N, 3)``; ``heading``,
    ``heading_rate``, ``heading_accel`` float64 ``(N,)`` [rad, rad/s, rad/s²]: the direction
    the moving frame's x axis points to, counter-clockwise from world +x.
    """

    position: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray
    heading: np.ndarray
    heading_rate: np.ndarray
    heading_accel: np.ndarray


class Path:
    """Base class of the analytic paths."""

    def sample(self, t: np.ndarray) -> PathSample:  # pragma: no cover - abstract
        raise NotImplementedError

    def to_dict(self) -> dict:  # pragma: no cover - abstract
        raise NotImplementedError


def _rot2(angle: float, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.cos(angle), np.sin(angle)
    return c * x - s * y, s * x + c * y


@dataclass(frozen=True, eq=False)
class EllipsePath(Path):
    """A closed elliptic loop at constant height, travelled counter-clockwise (or clockwise).

    ``p(θ) = c + Rz(α)·(a·sin θ, −b·cos θ, 0)``, with the path parameter
    ``θ(t) = θ0 + ω·s(t)``, ``ω = speed / a`` (so ``speed`` is reached on the long sides) and
    the start-up time warp ``s(t) = t − τ(1 − e^{−t/τ})`` (starts from rest, reaches full
    speed after a few ``τ``; ``τ = 0`` for constant speed). The heading is the curve's tangent
    direction, defined even at rest.

    Attributes
    ----------
    center
        ``(3,)`` [m]; ``center[2]`` is the height.
    radii
        ``(a, b)`` [m], semi-axes along the rotated x and y.
    speed
        Speed on the long sides [m/s].
    orientation
        ``α`` [rad]: direction of the ``a`` axis.
    phase
        ``θ0`` [rad]; 0 starts at ``c + Rz(α)(0, −b)`` heading along ``+a``.
    ramp
        ``τ`` [s], start-up time constant.
    clockwise
        Travel direction seen from above.
    """

    center: np.ndarray
    radii: tuple[float, float]
    speed: float
    orientation: float = 0.0
    phase: float = 0.0
    ramp: float = 0.0
    clockwise: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", np.asarray(self.center, dtype=np.float64).reshape(3))
        a, b = (float(r) for r in self.radii)
        if a <= 0 or b <= 0 or self.speed < 0 or self.ramp < 0:
            raise SettingsError("EllipsePath: radii must be positive, speed and ramp not negative")
        object.__setattr__(self, "radii", (a, b))

    def _theta(self, t: np.ndarray) -> tuple[np.ndarray, ...]:
        w = self.speed / self.radii[0] * (-1.0 if self.clockwise else 1.0)
        tau = self.ramp
        if tau > 0:
            e = np.exp(-np.maximum(t, 0.0) / tau)
            s, s1, s2, s3 = t - tau * (1 - e), 1 - e, e / tau, -e / tau**2
            # Before t = 0 the rig stands still at its start point.
            before = t < 0
            s, s1, s2, s3 = (np.where(before, 0.0, x) for x in (s, s1, s2, s3))
        else:
            s, s1, s2, s3 = t, np.ones_like(t), np.zeros_like(t), np.zeros_like(t)
        return self.phase + w * s, w * s1, w * s2, w * s3

    def sample(self, t: np.ndarray) -> PathSample:
        """Evaluate at times ``t`` [s] (relative to the run start)."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        a, b = self.radii
        th, th1, th2, th3 = self._theta(t)
        sn, cs = np.sin(th), np.cos(th)
        # Derivatives of the curve with respect to θ (local axes, before the rotation by α).
        d0 = (a * sn, -b * cs)
        d1 = (a * cs, b * sn)
        d2 = (-a * sn, b * cs)
        d3 = (-a * cs, -b * sn)
        # Chain rule through θ(t).
        vel = tuple(d1[i] * th1 for i in range(2))
        acc = tuple(d2[i] * th1**2 + d1[i] * th2 for i in range(2))
        jerk = tuple(d3[i] * th1**3 + 3 * d2[i] * th1 * th2 + d1[i] * th3 for i in range(2))

        def world(xy, offset=None):
            x, y = _rot2(self.orientation, xy[0], xy[1])
            out = np.zeros((t.size, 3))
            out[:, 0], out[:, 1] = x, y
            if offset is not None:
                out += offset
            return out

        # Heading = tangent direction, flipped when travelling clockwise.
        den = a**2 * cs**2 + b**2 * sn**2
        psi_th = a * b / den
        psi_thth = -a * b * 2 * (b**2 - a**2) * sn * cs / den**2
        heading = self.orientation + np.arctan2(d1[1], d1[0])
        if self.clockwise:
            heading = heading + np.pi
        return PathSample(world(d0, self.center), world(vel), world(acc), world(jerk),
                          heading, psi_th * th1, psi_thth * th1**2 + psi_th * th2)

    def to_dict(self) -> dict:
        return {"type": "ellipse", "center": self.center.tolist(), "radii": list(self.radii),
                "speed": self.speed, "orientation_deg": float(np.degrees(self.orientation)),
                "phase_deg": float(np.degrees(self.phase)), "ramp": self.ramp,
                "clockwise": self.clockwise}


@dataclass(frozen=True, eq=False)
class LinePath(Path):
    """Back and forth along a straight segment with a sinusoidal speed profile.

    ``p(t) = m + h·d·sin(ω t + φ)`` with ``m`` the midpoint, ``h`` half the length, ``d`` the
    unit direction and ``ω = speed / h`` (``speed`` is the top speed, reached mid-segment). The
    heading is fixed along ``d``: an object walking back simply reverses (use it for objects
    that look the same from both ends, or that really do walk backwards).

    Attributes
    ----------
    start, end
        ``(3,)`` [m]. Equal for an object that stands still.
    speed
        Top speed [m/s].
    phase
        ``φ`` [rad]; 0 starts mid-segment moving toward ``end``.
    """

    start: np.ndarray
    end: np.ndarray
    speed: float
    phase: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "start", np.asarray(self.start, dtype=np.float64).reshape(3))
        object.__setattr__(self, "end", np.asarray(self.end, dtype=np.float64).reshape(3))
        if self.speed < 0:
            raise SettingsError("LinePath: speed must not be negative")

    def sample(self, t: np.ndarray) -> PathSample:
        """Evaluate at times ``t`` [s]."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        seg = self.end - self.start
        length = float(np.linalg.norm(seg))
        mid = 0.5 * (self.start + self.end)
        zeros = np.zeros((t.size, 3))
        if length == 0 or self.speed == 0:
            pos = np.broadcast_to(mid, (t.size, 3)).copy()
            return PathSample(pos, zeros, zeros.copy(), zeros.copy(), np.zeros(t.size),
                              np.zeros(t.size), np.zeros(t.size))
        d, h = seg / length, 0.5 * length
        w = self.speed / h
        arg = w * t + self.phase
        s = np.sin(arg)[:, None]
        c = np.cos(arg)[:, None]
        heading = np.full(t.size, np.arctan2(d[1], d[0]))
        return PathSample(mid + h * s * d, h * w * c * d, -h * w**2 * s * d, -h * w**3 * c * d,
                          heading, np.zeros(t.size), np.zeros(t.size))

    def to_dict(self) -> dict:
        return {"type": "line", "start": self.start.tolist(), "end": self.end.tolist(),
                "speed": self.speed, "phase_deg": float(np.degrees(self.phase))}


def path_from_dict(d: dict, where: str = "path") -> Path:
    """Build a path from its scene-file description (see ``docs/simulator.md``).

    ``{"type": "ellipse", "center": [x, y, z], "radii": [a, b], "speed": v, "orientation_deg",
    "phase_deg", "ramp", "clockwise"}`` or ``{"type": "line", "start": [...], "end": [...],
    "speed": v, "phase_deg"}``. Raises ``ValueError`` naming ``where`` on bad input.
    """
    kind = d.get("type")
    try:
        if kind == "ellipse":
            return EllipsePath(d["center"], tuple(d["radii"]), float(d["speed"]),
                               np.radians(float(d.get("orientation_deg", 0.0))),
                               np.radians(float(d.get("phase_deg", 0.0))),
                               float(d.get("ramp", 0.0)), bool(d.get("clockwise", False)))
        if kind == "line":
            return LinePath(d["start"], d.get("end", d["start"]), float(d.get("speed", 0.0)),
                            np.radians(float(d.get("phase_deg", 0.0))))
    except (KeyError, TypeError, ValueError) as exc:
        raise SettingsError(f"{where}: {exc}") from None
    raise SettingsError(f"{where}: unknown path type {kind!r}; expected 'ellipse' or 'line'")
