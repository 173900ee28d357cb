"""A radar's point noise measured from its own static points while the filter runs.

The errors-in-variables correction of the Doppler update (:mod:`.doppler`) removes a bias
whose size is the direction noise's variance: with an assumed constant it over-corrects
exact directions and under-corrects noisy ones (issue 42: on a run with exact directions the
assumed 3°/5° of the single chip took 27 % of the ``v_z`` information away and leaked
forward speed into ``v_z``). The noise shows in the data: a static point in direction ``u``
with angle errors ``δa``, ``δe`` has, against the radar velocity ``y``, the range-rate
residual ``r = ṙ + uᵀy ≈ n_ṙ + cos(e) (e_azᵀy) δa + (e_elᵀy) δe``, so

    E[r²] = σ_ṙ² + σ_az² · cos²(e) (e_azᵀy)² + σ_el² · (e_elᵀy)² + uᵀ P_y u

with ``P_y`` the predicted velocity's covariance. The three variances are the least-squares
solution of this linear model over every accepted point seen so far (non-negative), each
column pulled towards the prior by ``prior_points`` pseudo-points: speed and a spread of
directions separate them (at rest only ``σ_ṙ`` is seen). The residuals are those of the
points the per-point gate accepted, so the variances come out a little low (a 3σ gate keeps
97 % of a Gaussian's variance): the estimate is a fixed point of gate and noise, not a
runaway.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import nnls

from ..errors import SettingsError
from .doppler import PointNoise, PointSolution, angle_basis

__all__ = ["NoiseEstimateConfig", "PointNoiseEstimator", "VerticalPrior", "observer"]

_MIN_DESIGN = np.array([1.0, np.sin(np.radians(30.0)) ** 4, np.sin(np.radians(6.0)) ** 4])
"""The smallest design magnitudes of the prior's pseudo-points, per variance: 1 for the
range rate; for the angles those of points seen at 1 m/s about 14.5° (azimuth) and 0.6°
(elevation) off the motion (``sin⁴`` of 30° and 6°, the values the figures were measured
with)."""
_MIN_CAP = np.radians(5.0)
"""The angle noise is capped at twice the prior's, and never below this [rad]."""


@dataclass(frozen=True)
class NoiseEstimateConfig:
    """Settings of the online point-noise estimate.

    Attributes
    ----------
    enabled
        Measure the noise from the data (default, every radar and model); False: the prior
        (the radar's stated accuracy or ``RioConfig.point_noise``) throughout. The planar
        model kept its prior until it was measured against the data (docs/odometry.md):
        with the noise measured, its ATE on the ladder's vehicles with exact directions went
        from 0.08–0.11 % to 0.03–0.06 %, on the foreign clean run from 0.34 to 0.31 % (final
        0.47 → 0.17 %), and the Monte Carlo's stayed level.
    prior_points
        Weight of the prior, in points (per variance): until about this many informative
        points have been seen the prior dominates. 300: about fifteen frames of the single
        chip.
    min_range_rate_std
        Floor of the estimated range-rate noise [m/s] (a Doppler bin is never exact).
    """

    enabled: bool = True
    prior_points: float = 300.0
    min_range_rate_std: float = 0.01

    def __post_init__(self) -> None:
        if not (np.isfinite(self.prior_points) and self.prior_points > 0):
            raise SettingsError("NoiseEstimateConfig.prior_points must be > 0, got "
                                f"{self.prior_points!r}")
        if not (np.isfinite(self.min_range_rate_std) and self.min_range_rate_std > 0):
            raise SettingsError("NoiseEstimateConfig.min_range_rate_std must be > 0, got "
                                f"{self.min_range_rate_std!r}")


class PointNoiseEstimator:
    """Running estimate of one radar's :class:`~coloradar.odometry.doppler.PointNoise`.

    Parameters
    ----------
    prior
        The noise assumed before any data (its ``max_velocity`` is kept).
    config
        :class:`NoiseEstimateConfig`.
    """

    def __init__(self, prior: PointNoise, config: NoiseEstimateConfig | None = None) -> None:
        self.prior = prior
        self.config = config or NoiseEstimateConfig()
        self._m = np.zeros((3, 3))        # normal equations of the variance model
        self._c = np.zeros(3)
        self._n = 0
        self._noise = prior
        self._s_prior = np.array([prior.range_rate_std, prior.azimuth_std,
                                  prior.elevation_std]) ** 2

    @property
    def noise(self) -> PointNoise:
        """The current estimate (the prior until points are added, or when disabled)."""
        return self._noise

    @property
    def points(self) -> int:
        """Points added so far."""
        return self._n

    def add(self, u: np.ndarray, rates: np.ndarray, y: np.ndarray, py: np.ndarray,
            solution: object = None) -> None:
        """Add a frame's static points and update :attr:`noise`.

        Parameters
        ----------
        u, rates
            float64 ``(N, 3)`` unit directions and ``(N,)`` range rates [m/s] (unwrapped) of
            the points the gate accepted, radar frame.
        y, py
            The predicted radar velocity ``(3,)`` [m/s] and its covariance ``(3, 3)``
            [m²/s²], before the frame's update.
        solution
            Unused (the :data:`~coloradar.odometry.doppler.PointObserver` signature).
        """
        if self.config.enabled is False or u.shape[0] == 0:
            return
        _, el, e_az, e_el = angle_basis(u)
        r = rates + u @ y
        z = r * r - np.einsum("ni,ij,nj->n", u, py, u)
        x = np.column_stack([np.ones(u.shape[0]), (np.cos(el) * (e_az @ y)) ** 2,
                             (e_el @ y) ** 2])
        self._m += x.T @ x
        self._c += x.T @ z
        self._n += u.shape[0]
        self._noise = self._solve()

    def _solve(self) -> PointNoise:
        # Each column gets prior_points pseudo-points of the data's average design (the
        # prior's weight against the data the same for every variance), at least
        # _MIN_DESIGN: slow frames (the first ones, at rest) inform the angle variances
        # little and must not move them.
        scale = np.maximum(np.diag(self._m) / max(self._n, 1), _MIN_DESIGN)
        lam = self.config.prior_points * scale
        m = self._m + np.diag(lam)
        c = self._c + lam * self._s_prior
        try:
            chol = np.linalg.cholesky(m)
        except np.linalg.LinAlgError:
            return self._noise
        s, _ = nnls(chol.T, np.linalg.solve(chol, c))
        rr = max(float(np.sqrt(s[0])), self.config.min_range_rate_std)
        # Beyond a few degrees the first-order noise model and the correction's O(σ⁴)
        # residual no longer hold: the angles are capped at the prior's twice.
        cap = 2.0 * np.sqrt(self._s_prior[1:])
        az, el = np.minimum(np.sqrt(s[1:]), np.maximum(cap, _MIN_CAP))
        return PointNoise(rr, float(az), float(el), self.prior.max_velocity)


class VerticalPrior:
    """The rig's vertical motion as a soft prior: the radar's ``v_z ≈ 0`` with a standard
    deviation measured from the data (issue 42, item 3).

    A rig carried or driven moves mostly along the radar's boresight; how far it moves along
    the radar's z shows in the frames' own 3-D point solutions: ``E[ŷ_z²] = E[y_z²] +
    var(ŷ_z)``, so the mean of ``ŷ_z² − var(ŷ_z)`` over recent frames (exponential window of
    ``window`` frames) is the prior's variance, at least ``floor²``. It comes from the
    measurements, not from the filter's estimate, so the prior cannot talk itself into a
    planar rig: on a ramp or a pitching rig it widens by itself. Frames whose points do not
    observe all three directions are not counted; until ``min_frames`` have been, no prior.

    Parameters
    ----------
    floor
        Smallest standard deviation [m/s].
    window
        Frames in the exponential window.
    min_frames
        Frames counted before the prior is given.
    """

    def __init__(self, floor: float = 0.02, window: float = 300.0, min_frames: int = 30
                 ) -> None:
        self.floor, self.window, self.min_frames = floor, window, min_frames
        self._mean = 0.0
        self._n = 0

    @property
    def std(self) -> float | None:
        """The prior's standard deviation [m/s], or None (too few frames yet)."""
        if self._n < self.min_frames:
            return None
        return float(np.sqrt(max(self._mean, self.floor**2)))

    def add(self, u: np.ndarray, rates: np.ndarray, y: np.ndarray, py: np.ndarray,
            solution: PointSolution | None = None) -> None:
        """Count a frame's point solution (the other arguments are those of the observer
        signature, unused)."""
        if solution is None or solution.basis.shape[0] < 3:
            return
        b_inv = np.linalg.inv(solution.basis)
        yz = float((b_inv @ solution.value)[2])
        var = float((b_inv @ solution.covariance @ b_inv.T)[2, 2])
        self._n += 1
        a = 1.0 / min(self._n, self.window)
        self._mean += a * (yz * yz - var - self._mean)


def observer(estimator: PointNoiseEstimator, vertical: VerticalPrior
             ) -> Callable[..., None]:
    """A :data:`~coloradar.odometry.doppler.PointObserver` that reports a frame's accepted
    points and solution to both."""
    def observe(*args: Any) -> None:
        estimator.add(*args)
        vertical.add(*args)
    return observe
