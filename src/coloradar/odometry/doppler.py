"""The tightly coupled radar update: every Doppler point a scalar measurement of the filter.

A static point seen by radar ``r`` in the (unit) direction ``u`` of its frame has the range
rate ``ṙ = −uᵀ y`` with ``y = R_irᵀ (Rᵀ v + ω × t_ir)`` the radar origin's velocity in its
own frame (:meth:`.eskf.ErrorStateEKF.radar_velocity_model`). Each point gives the residual

    r_i = ṙ_i + u_iᵀ ŷ,      H_i = −u_iᵀ H_y        (H_y = ∂y/∂δx, 3 × dim)

with the noise ``σ_i² = σ_ṙ² + ŷᵀ Σ_u,i ŷ``: the Doppler error plus the direction error
projected on the predicted velocity (``Σ_u = σ_az² cos²el e_az e_azᵀ + σ_el² e_el e_elᵀ``,
first order in the angle errors). Each point is gated on its own, ``r_i² ≤ χ²₁(p) s_i`` with
``s_i = H_i P H_iᵀ + σ_i²``: a mover or a ghost disagrees with the IMU-predicted velocity and is
left out, with no RANSAC.

**Errors in variables.** The directions are noisy regressors: ``E[u_o u_oᵀ] = u uᵀ + C`` and
``E[u_o] = K u`` (``K`` shrinks ``u`` by ``exp(−σ²/2)`` per angle). Least squares on the
noisy directions, and so the plain stacked update, converges to ``(Σ w(u uᵀ + C))⁻¹ Σ w K u uᵀ y``
rather than ``y``: the speed shrinks by about ``σ²/2`` and, when the points' elevations are not
centred on boresight, ``C``'s x–z term leaks a fixed fraction of the forward speed into
``v_z``. The update therefore takes the frame's normal equations as a linear measurement whose
regressor is their expectation:

    b = −Σ w_i u_i ṙ_i = A_e y + n,    A_e = Σ w_i diag(K_i)(u_i u_iᵀ − C_i),
    cov(n) = M = Σ w_i² σ_i² u_i u_iᵀ

(``C_i``, ``K_i`` evaluated at the observed angles: exact moments of Gaussian angle errors;
``E[b] ≈ E[A_e] y`` to first order in the angle variances). Its weights are one per frame
(``1 / mean σ_i²``): weights computed from the noisy directions correlate with their errors
and would bias it again (by 0.4 % of the speed at 3°/5° of noise). Solving the corrected
equations per frame instead (``A_c⁻¹ b_c``, until issue 42) inverts a noisy matrix and is
biased on sparse frames; the measurement form inverts nothing and keeps the information the
noise leaves. Without the correction (``σ`` = 0) it equals the stacked scalar updates of the
points to round-off (the information ``H_yᵀ A H_y`` and the information vector are the same;
``tests/test_odometry_doppler.py`` checks it).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from ..errors import SettingsError
from .eskf import ErrorStateEKF

__all__ = [
    "DopplerConfig",
    "PointNoise",
    "PointSolution",
    "angle_basis",
    "direction_moments",
    "doppler_points",
    "doppler_points_index",
    "doppler_update",
    "elevation_rows",
    "point_noise_for",
    "point_variances",
    "solve_points",
    "unwrap_rates",
]

_DEG = np.pi / 180.0


@dataclass(frozen=True)
class PointNoise:
    """Measurement noise of one radar's detections.

    Attributes
    ----------
    range_rate_std
        Range-rate error of a point [m/s].
    azimuth_std, elevation_std
        Direction errors [rad] (Gaussian angle errors about the true direction).
    max_velocity
        The radar's unambiguous range rate [m/s]; range rates are unwrapped towards the
        prediction (None: not folded).
    """

    range_rate_std: float = 0.05
    azimuth_std: float = 2.0 * _DEG
    elevation_std: float = 3.0 * _DEG
    max_velocity: float | None = None

    def __post_init__(self) -> None:
        for name in ("range_rate_std", "azimuth_std", "elevation_std"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise SettingsError(f"PointNoise.{name} must be a finite number >= 0, got {v!r}")
        if self.range_rate_std <= 0:
            raise SettingsError("PointNoise.range_rate_std must be > 0")


# Stated or measured direction accuracy: the cascade's ADC chain (docs/dsp.md, elevation 1.6°
# RMS against the simulator's scatterers) and the single chip's two-row array, whose elevation
# is a two-element phase comparison ("a few degrees", issue 25).
_ANGLE_STD = {"cascade": (1.0 * _DEG, 1.6 * _DEG), "single_chip": (3.0 * _DEG, 5.0 * _DEG)}


def elevation_rows(radar_calib) -> int:
    """Distinct elevation positions of a radar's virtual array (2 for the single chip, whose
    elevation is a two-element phase comparison; more for the cascade).

    Parameters
    ----------
    radar_calib
        The radar's :class:`~coloradar.calib.RadarCalib`.
    """
    return int(np.unique(radar_calib.antenna.virtual.unique_positions[:, 1]).size)


def point_noise_for(radar: str, velocity_bin_width: float | None = None,
                    max_velocity: float | None = None) -> PointNoise:
    """Default :class:`PointNoise` of a radar: the range-rate error is half a Doppler bin, at
    least 5 cm/s; the angle errors are the radar's stated or measured accuracy (unknown radars:
    the single chip's, the coarser)."""
    az, el = _ANGLE_STD.get(radar, _ANGLE_STD["single_chip"])
    rr = 0.05 if velocity_bin_width is None else max(0.05, 0.5 * float(velocity_bin_width))
    return PointNoise(rr, az, el, max_velocity)


@dataclass(frozen=True)
class DopplerConfig:
    """Settings of the tightly coupled (per-point) radar update.

    Attributes
    ----------
    gate_probability
        Per-point chi-square gate (1 dof): a point whose normalised residual against the
        IMU-predicted velocity exceeds this quantile is an outlier (mover, ghost, multipath).
    min_points
        Fewer accepted points than this, or fewer than ``min_fraction`` of the frame's, and
        the frame is not used by this update (the filter then falls back to the frame's
        RANSAC ego-velocity, and after ``max_rejected`` such frames restarts from it).
    min_fraction
        See ``min_points``.
    errors_in_variables
        Remove the direction errors' bias (module docstring); False: the plain stacked update.
    planar
        Use the points for the radar's ``v_x, v_y`` only (given the filter's ``v_z``, held
        near 0 by ``RioConfig.planar_vz_std``: ``--model planar``, for a rig that truly moves
        in the radar's plane); False (default): 3-D for every radar; None: as the radar's
        per-frame ego-velocity model (planar for the single chip, 3-D for the cascade).
        Issue 42 measured both for the single chip (docs/odometry.md, "3-D single chip"): on
        runs written by another program, whose rigs rise and fall, 3-D with the noise
        measured from the data is far ahead (ATE 0.34 → 0.03 %, 0.60 → 0.10 %); on the
        project's Monte Carlo planar is ahead where the rig keeps its height (3-D drifts in
        height: median final 0.23 → 0.77 % on the handheld runs, 0.26 → 1.10 % on the
        vehicle runs) and behind on the runs that rise and fall. A rig's floor is not known
        in advance; the default is 3-D.
    min_range
        Points closer than this are left out [m] (the rig, antenna leakage).
    noise_uncertainty
        Variance, in units of the correction's change when the angle variances double, of
        the errors-in-variables correction's own error (the direction noise is not known
        exactly and its bias of ``v_z`` is the same sign every frame); 0: trusted.
    """

    gate_probability: float = 0.997
    min_points: int = 4
    min_fraction: float = 0.3
    errors_in_variables: bool = True
    planar: bool | None = False
    min_range: float = 0.3
    noise_uncertainty: float = 1.0

    def __post_init__(self) -> None:
        if not 0 < self.gate_probability < 1:
            raise SettingsError(f"DopplerConfig.gate_probability must be in (0, 1), got "
                                f"{self.gate_probability!r}")
        if self.min_points < 3:
            raise SettingsError(f"DopplerConfig.min_points must be >= 3, got {self.min_points}")
        if not 0 <= self.min_fraction <= 1:
            raise SettingsError(f"DopplerConfig.min_fraction must be in [0, 1], got "
                                f"{self.min_fraction!r}")

    @property
    def gate(self) -> float:
        """The 1-dof chi-square threshold."""
        return float(chi2.ppf(self.gate_probability, 1))


def doppler_points(cloud: np.ndarray, min_range: float = 0.3) -> np.ndarray:
    """Unit directions and range rates of a cloud's usable points.

    Parameters
    ----------
    cloud
        float ``(N, 5)`` ``x y z intensity range_rate`` (sensor frame, m, m/s).
    min_range
        Closer points are dropped [m].

    Returns
    -------
    numpy.ndarray
        float64 ``(K, 4)``: ``ux uy uz range_rate``.
    """
    return doppler_points_index(cloud, min_range)[0]


def doppler_points_index(cloud: np.ndarray, min_range: float = 0.3
                         ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`doppler_points` and the int64 ``(K,)`` rows of ``cloud`` they come from."""
    c = np.asarray(cloud, dtype=np.float64)
    if c.size == 0:
        return np.zeros((0, 4)), np.zeros(0, dtype=np.int64)
    if c.ndim != 2 or c.shape[1] < 5:
        raise SettingsError(f"expected an (N, 5) point cloud x y z intensity range_rate, got "
                            f"shape {c.shape}")
    xyz, vr = c[:, :3], c[:, 4]
    rng = np.linalg.norm(xyz, axis=1)
    ok = np.isfinite(rng) & np.isfinite(vr) & (rng >= max(min_range, 1e-6))
    return np.column_stack([xyz[ok] / rng[ok, None], vr[ok]]), np.flatnonzero(ok)


def angle_basis(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Azimuth, elevation and the unit vectors along their increase, of unit vectors (N, 3)."""
    az = np.arctan2(u[:, 1], u[:, 0])
    el = np.arcsin(np.clip(u[:, 2], -1.0, 1.0))
    ca, sa, ce, se = np.cos(az), np.sin(az), np.cos(el), np.sin(el)
    e_az = np.column_stack([-sa, ca, np.zeros_like(az)])
    e_el = np.column_stack([-se * ca, -se * sa, ce])
    return az, el, e_az, e_el


def point_variances(u: np.ndarray, y: np.ndarray, noise: PointNoise) -> np.ndarray:
    """``σ_i² = σ_ṙ² + yᵀ Σ_u,i y`` [m²/s²] of points in directions ``u`` (N, 3) for the
    radar velocity ``y`` (3,) [m/s] (first order in the angle errors)."""
    _, el, e_az, e_el = angle_basis(u)
    pa = (e_az @ y) * np.cos(el) * noise.azimuth_std
    pe = (e_el @ y) * noise.elevation_std
    return noise.range_rate_std**2 + pa**2 + pe**2


def direction_moments(u: np.ndarray, sigma_az: float, sigma_el: float
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Bias of noisy unit vectors: ``E[u_o] = k ⊙ u`` and ``E[u_o u_oᵀ] − u uᵀ``.

    For ``u = (cos e cos a, cos e sin a, sin e)`` with independent Gaussian errors of ``a``
    and ``e`` (standard deviations ``sigma_az``, ``sigma_el`` [rad]), from
    ``E[cos(x+n)] = cos x·e^{−σ²/2}`` and ``E[cos²(x+n)] = ½(1 + cos 2x·e^{−2σ²})``.

    Returns
    -------
    k : numpy.ndarray
        float64 ``(N, 3)``: the shrink factors.
    c : numpy.ndarray
        float64 ``(N, 3, 3)``: the excess second moment, evaluated at the angles of ``u``.
    """
    az, el, _, _ = angle_basis(u)
    ga1, ge1 = np.exp(-0.5 * sigma_az**2), np.exp(-0.5 * sigma_el**2)
    ga2, ge2 = np.exp(-2.0 * sigma_az**2), np.exp(-2.0 * sigma_el**2)
    cc_e = 0.5 * (1 + np.cos(2 * el) * ge2)            # E[cos² e]
    ss_e = 0.5 * (1 - np.cos(2 * el) * ge2)
    sc_e = 0.5 * np.sin(2 * el) * ge2                    # E[sin e cos e]
    cc_a = 0.5 * (1 + np.cos(2 * az) * ga2)
    ss_a = 0.5 * (1 - np.cos(2 * az) * ga2)
    sc_a = 0.5 * np.sin(2 * az) * ga2
    m = np.empty((u.shape[0], 3, 3))
    m[:, 0, 0] = cc_e * cc_a
    m[:, 1, 1] = cc_e * ss_a
    m[:, 2, 2] = ss_e
    m[:, 0, 1] = m[:, 1, 0] = cc_e * sc_a
    m[:, 0, 2] = m[:, 2, 0] = sc_e * np.cos(az) * ga1
    m[:, 1, 2] = m[:, 2, 1] = sc_e * np.sin(az) * ga1
    k = np.column_stack([np.full(u.shape[0], ga1 * ge1), np.full(u.shape[0], ga1 * ge1),
                         np.full(u.shape[0], ge1)])
    return k, m - u[:, :, None] * u[:, None, :]


def unwrap_rates(rates: np.ndarray, predicted: np.ndarray, max_velocity: float | None
                 ) -> np.ndarray:
    """Range rates unwrapped by multiples of ``2·v_max`` towards ``predicted`` [m/s]."""
    if not max_velocity:
        return rates
    span = 2.0 * max_velocity
    return rates + span * np.round((predicted - rates) / span)


@dataclass(frozen=True)
class PointSolution:
    """A frame's accepted points, compressed into a measurement of the radar velocity.

    Attributes
    ----------
    accepted
        bool ``(N,)``: points that passed the per-point gate.
    basis
        float64 ``(k, 3)`` (k = 3, or 2 with ``DopplerConfig.planar``): the regressor of the
        linear measurement ``value = basis @ y + noise``: the frame's weighted normal
        equations, with the errors-in-variables correction their expectation
        ``Σ w diag(k)(u uᵀ − C)`` (weights ``w`` [s²/m²]).
    value
        float64 ``(k,)``: the right-hand side ``−Σ w u ṙ`` [s/m].
    covariance
        float64 ``(k, k)``: of ``value`` [s²/m²].
    """

    accepted: np.ndarray
    basis: np.ndarray
    value: np.ndarray
    covariance: np.ndarray


def _expected_regressor(u: np.ndarray, w: np.ndarray, sigma_az: float, sigma_el: float
                        ) -> np.ndarray:
    """``Σ w_i diag(k_i) (u_i u_iᵀ − C_i)``: what the normal equations' right-hand side
    ``b = −Σ w_i u_i ṙ_i`` of noisy directions ``u`` (N, 3) is, in expectation, times ``y``
    (first order in the angle variances; :func:`direction_moments`)."""
    k, c = direction_moments(u, sigma_az, sigma_el)
    m = u[:, :, None] * u[:, None, :] - c
    return np.einsum("n,ni,nij->ij", w, k, m)


def solve_points(u: np.ndarray, rates: np.ndarray, y: np.ndarray, py: np.ndarray,
                 noise: PointNoise, config: DopplerConfig) -> PointSolution | None:
    """Gate a frame's points against the predicted radar velocity and compress the survivors.

    Parameters
    ----------
    u, rates
        float64 ``(N, 3)`` unit directions and ``(N,)`` range rates [m/s], radar frame.
    y, py
        Predicted radar velocity ``(3,)`` [m/s] and its covariance ``H_y P H_yᵀ`` ``(3, 3)``.
    noise, config
        The radar's point noise and the update's settings.

    Returns
    -------
    PointSolution or None
        None when too few points pass the gate (``min_points``, ``min_fraction``) or they
        observe no direction of ``y``.
    """
    n = u.shape[0]
    if n < config.min_points:
        return None
    rates = unwrap_rates(rates, -(u @ y), noise.max_velocity)
    sig2 = point_variances(u, y, noise)
    res = rates + u @ y
    s = np.einsum("ni,ij,nj->n", u, py, u) + sig2
    acc = res * res <= config.gate * s
    m = int(acc.sum())
    if m < config.min_points or m < config.min_fraction * n:
        return None
    ua, ra, sa = u[acc], rates[acc], sig2[acc]
    eiv = config.errors_in_variables and (noise.azimuth_std > 0 or noise.elevation_std > 0)
    # Weights that depend on the noisy directions correlate with their errors and bias the
    # correction (by 0.4 % of the speed at 3°/5°): with the correction the frame's points
    # are weighed alike, and the covariance keeps each point's own variance (sandwich).
    w = np.full(m, 1.0 / sa.mean()) if eiv else 1.0 / sa
    b = -(ua * (w * ra)[:, None]).sum(axis=0)
    meat = (ua * (w * w * sa)[:, None]).T @ ua
    if not eiv:
        a_e = (ua * w[:, None]).T @ ua
    else:
        a_e = _expected_regressor(ua, w, noise.azimuth_std, noise.elevation_std)
        # The direction noise is known only roughly (σ² within a factor of two): the
        # correction's own uncertainty, ΔA_e y, goes into the covariance.
        j_sig = (_expected_regressor(ua, w, noise.azimuth_std * np.sqrt(2),
                                     noise.elevation_std * np.sqrt(2)) - a_e) @ y
        meat = meat + config.noise_uncertainty * np.outer(j_sig, j_sig)
    basis, value, cov = a_e, b, meat
    if config.planar:
        # The points inform the x-y velocity only: their x and y normal equations, with v_z
        # taken from the filter's state.
        basis, value, cov = a_e[:2], b[:2], meat[:2, :2]
    return PointSolution(acc, basis, value, 0.5 * (cov + cov.T))


PointObserver = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, "PointSolution"], None]
"""Called with a frame's accepted points ``u (K, 3)``, their unwrapped range rates ``(K,)``,
the predicted radar velocity ``y (3,)`` and its covariance ``(3, 3)`` (before the update), and
the frame's :class:`PointSolution`."""


def doppler_update(ekf: ErrorStateEKF, r: int, t_ir: np.ndarray, points: np.ndarray,
                   noise: PointNoise, config: DopplerConfig, shift: float = 0.0,
                   planar_vz_std: float | None = None,
                   observe: PointObserver | None = None) -> np.ndarray | None:
    """Update the filter with one frame's Doppler points of radar ``r``.

    Parameters
    ----------
    ekf
        The filter, propagated to the frame's time.
    r, t_ir
        The radar's index and its origin in the IMU frame [m].
    points
        float64 ``(N, 4)`` ``ux uy uz range_rate`` (:func:`doppler_points`).
    noise, config
        The radar's point noise and the update's settings.
    shift
        The frame's time minus the filter's [s] (≤ 0: a frame whose time has passed is
        predicted to first order along the time-offset column).
    planar_vz_std
        Also ``v_z ≈ 0`` (radar frame) with this standard deviation [m/s]: with
        ``config.planar`` the planar model's assumption
        (:attr:`~coloradar.odometry.rio.RioConfig.planar_vz_std`), else a soft prior of the
        rig's vertical motion (:class:`~coloradar.odometry.noise_estimate.VerticalPrior`);
        None: no such row.
    observe
        Given the accepted points, e.g. :meth:`.noise_estimate.PointNoiseEstimator.add`.

    Returns
    -------
    numpy.ndarray or None
        bool ``(N,)``: the points used (static by the gate); None when the frame gave no
        update (too few points passed the gate).
    """
    y, H = ekf.radar_velocity_model(r, t_ir)
    if shift:
        y = y + shift * H[:, ekf.td_index(r)]
    py = H @ ekf.P @ H.T
    sol = solve_points(points[:, :3], points[:, 3], y, py, noise, config)
    if sol is None:
        return None
    if observe is not None:
        acc = sol.accepted
        observe(points[acc, :3], unwrap_rates(points[acc, 3], -(points[acc, :3] @ y),
                                              noise.max_velocity), y, py, sol)
    basis, value, cov = sol.basis, sol.value, sol.covariance
    if planar_vz_std:
        # The planar model's assumption, held loosely (or, for the 3-D model, the rig's
        # vertical motion as a soft prior): the radar's v_z is about 0.
        basis = np.vstack([basis, [0.0, 0.0, 1.0]])
        value = np.append(value, 0.0)
        k = cov.shape[0]
        cov = np.pad(cov, ((0, 1), (0, 1)))
        cov[k, k] = planar_vz_std**2
    ekf.update(value - basis @ y, basis @ H, cov, None)
    return sol.accepted
