"""A rig that stands still before it moves: a time warp of any rig trajectory.

Real runs start with the rig at rest (the operator presses record, then walks). The analytic
trajectories (:mod:`.trajectory`) move from ``t = 0``; :class:`RestStart` holds one still for
``rest`` seconds and then eases it into its motion through the warp ``s(t)``::

    state(t) = inner.state(s(t)),   s = 0 for t ≤ rest,
    s' = 3x² − 2x³ over the ramp (x = (t − rest) / ramp ∈ [0, 1]), s' = 1 after it

so velocity and angular velocity are exactly zero at rest and the acceleration is continuous.
The chain rule keeps every derivative exact: ``v = v_in·s'``, ``a = a_in·s'² + v_in·s''``,
``ω = ω_in·s'``, ``α = α_in·s'² + ω_in·s''``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SettingsError
from .trajectory import RigState, RigTrajectory

__all__ = ["RestStart"]


@dataclass(frozen=True, eq=False)
class RestStart:
    """``inner`` held at its ``t = 0`` pose for ``rest`` seconds, then eased in over ``ramp``.

    Attributes
    ----------
    inner
        The trajectory to delay (anything with ``state(t) -> RigState``).
    rest
        Seconds at rest from the run start [s].
    ramp
        Seconds over which the time warp's rate rises from 0 to 1 [s].
    """

    inner: RigTrajectory
    rest: float
    ramp: float = 1.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.rest) and self.rest >= 0):
            raise SettingsError(f"rest must be a finite number of seconds >= 0, got {self.rest!r}")
        if not (np.isfinite(self.ramp) and self.ramp > 0):
            raise SettingsError(f"ramp must be positive, got {self.ramp!r}")

    @property
    def profile(self) -> str:
        return getattr(self.inner, "profile", "custom")

    def warp(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``s(t)``, ``s'(t)``, ``s''(t)`` (float64, shape of ``t``)."""
        t = np.asarray(t, dtype=np.float64)
        T = self.ramp
        x = np.clip((t - self.rest) / T, 0.0, 1.0)
        inside = (t > self.rest) & (t < self.rest + T)
        after = t >= self.rest + T
        s = np.where(after, T / 2 + (t - self.rest - T), T * (x**3 - 0.5 * x**4))
        s1 = np.where(after, 1.0, 3 * x**2 - 2 * x**3)
        s2 = np.where(inside, (6 * x - 6 * x**2) / T, 0.0)
        return s, s1, s2

    def state(self, t: np.ndarray) -> RigState:
        """The rig state at times ``t`` [s] relative to the run start."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        s, s1, s2 = self.warp(t)
        st = self.inner.state(s)
        c1, c2 = s1[:, None], s2[:, None]
        return RigState(
            times=t, position=st.position, rotation=st.rotation,
            velocity=st.velocity * c1,
            acceleration=st.acceleration * c1**2 + st.velocity * c2,
            angular_velocity=st.angular_velocity * c1,
            angular_acceleration=st.angular_acceleration * c1**2 + st.angular_velocity * c2)
