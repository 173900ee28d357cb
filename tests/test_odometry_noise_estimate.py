"""The point noise measured from the data (issue 42): static points drawn in the test from
first principles (true directions, Gaussian angle errors, the range rate of a moving radar)."""

import numpy as np
import pytest

from coloradar.odometry.doppler import PointNoise
from coloradar.odometry.noise_estimate import PointNoiseEstimator, VerticalPrior

DEG = np.pi / 180


def _frames(rng, n_frames, az_std, el_std, rr_std, speed=1.5, vz=0.0):
    """Frames of 20 static points ±60° azimuth, ±20° elevation; the radar moves forward at
    ``speed`` with a vertical ``vz`` [m/s]: (observed unit vectors, range rates, velocity)."""
    for _ in range(n_frames):
        az = rng.uniform(-60, 60, 20) * DEG
        el = rng.uniform(-20, 20, 20) * DEG
        u = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        y = np.array([speed, rng.normal(0, 0.2) if speed else 0.0, vz])
        rates = -(u @ y) + rng.normal(0, rr_std, 20)
        azo, elo = az + rng.normal(0, az_std, 20), el + rng.normal(0, el_std, 20)
        uo = np.column_stack([np.cos(elo) * np.cos(azo), np.cos(elo) * np.sin(azo), np.sin(elo)])
        yield uo, rates, y


@pytest.mark.parametrize("az_deg, el_deg, rr", [(2.0, 4.0, 0.04), (0.0, 0.0, 0.03)])
def test_noise_recovered_from_the_residuals(az_deg, el_deg, rr):
    rng = np.random.default_rng(7)
    est = PointNoiseEstimator(PointNoise(0.05, 3 * DEG, 5 * DEG))
    for uo, rates, y in _frames(rng, 600, az_deg * DEG, el_deg * DEG, rr):
        est.add(uo, rates, y, np.zeros((3, 3)))
    n = est.noise
    assert n.range_rate_std == pytest.approx(rr, rel=0.15)
    # 12,000 points: the angles within a degree of the truth, far from the prior's 3° / 5°
    # (measured: 2.2° / 4.6° and 0.6° / 0.4°; the prior weighs 300 points, and elevation,
    # seen only through sin(e)·v, is the least certain).
    assert abs(n.azimuth_std / DEG - az_deg) < 0.7, n
    assert abs(n.elevation_std / DEG - el_deg) < 1.0, n


def test_prediction_uncertainty_is_not_taken_for_noise():
    """The predicted velocity's own error shows in every residual; given its covariance the
    estimator leaves it out."""
    rng = np.random.default_rng(3)
    est = PointNoiseEstimator(PointNoise(0.05, 3 * DEG, 5 * DEG))
    py = np.diag([0.03, 0.03, 0.03]) ** 2
    for uo, rates, y in _frames(rng, 600, 2 * DEG, 4 * DEG, 0.04):
        y_pred = y + rng.normal(0, 0.03, 3)          # the filter's prediction, with its error
        est.add(uo, rates, y_pred, py)
    assert est.noise.range_rate_std == pytest.approx(0.04, rel=0.15)
    assert abs(est.noise.azimuth_std / DEG - 2.0) < 0.5


def test_rest_keeps_the_prior_angles():
    """At rest the residuals say nothing about the directions: the angles stay the prior's."""
    rng = np.random.default_rng(1)
    prior = PointNoise(0.05, 3 * DEG, 5 * DEG)
    est = PointNoiseEstimator(prior)
    for uo, rates, y in _frames(rng, 50, 0.0, 0.0, 0.04, speed=0.0):
        est.add(uo, rates, y, np.zeros((3, 3)))
    assert est.noise.azimuth_std == pytest.approx(prior.azimuth_std, rel=0.05)
    assert est.noise.elevation_std == pytest.approx(prior.elevation_std, rel=0.05)
    assert est.noise.range_rate_std == pytest.approx(0.04, rel=0.1)


class _Sol:
    def __init__(self, value, cov):
        self.basis, self.value, self.covariance = np.eye(3), value, cov


def test_vertical_prior_is_the_measured_vertical_speed():
    """Frames whose 3-D solutions carry v_z = ±0.1 m/s plus their own noise (0.15 m/s): the
    prior's standard deviation is the true 0.1 m/s, not the noisy spread."""
    rng = np.random.default_rng(5)
    vp = VerticalPrior(window=5000)
    assert vp.std is None
    cov = np.diag([0.01, 0.02, 0.15]) ** 2
    for k in range(3000):
        vz = 0.1 if k % 2 else -0.1
        vp.add(None, None, None, None, _Sol(np.array([1.4, 0.0, vz + rng.normal(0, 0.15)]), cov))
    assert vp.std == pytest.approx(0.1, abs=0.015)
