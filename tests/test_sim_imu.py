"""The simulator's IMU errors, rest at the start and radar time offset."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from coloradar.calib import load_calibration
from coloradar.errors import ColoradarError, SettingsError
from coloradar.sim.imu import GX5_25, ImuModel, simulate_imu
from coloradar.sim.paths import EllipsePath
from coloradar.sim.rest import RestStart
from coloradar.sim.run import open_simulation, simulate_run
from coloradar.sim.trajectory import make_trajectory
from coloradar.sim.truth import load_truth


def _still():
    path = EllipsePath(np.array([0.0, 0.0, 1.0]), (5.0, 3.0), 0.0)
    return make_trajectory(path, "smooth", 0)


def test_datasheet_defaults():
    # MicroStrain 3DM-GX5-25: 100 µg/√Hz, 0.005 °/s/√Hz, ±0.002 g, ±0.04 °/s.
    assert GX5_25.accel_noise_density == pytest.approx(100e-6 * 9.80665)
    assert GX5_25.gyro_noise_density == pytest.approx(np.radians(0.005))
    assert GX5_25.accel_bias == pytest.approx(0.002 * 9.80665)
    assert GX5_25.gyro_bias == pytest.approx(np.radians(0.04))
    assert GX5_25.gyro_noise == pytest.approx(np.radians(0.005) * np.sqrt(300.0))
    ideal = GX5_25.scaled(0.0)
    assert ideal.accel_bias == ideal.gyro_noise_density == ideal.gyro_bias_walk == 0.0
    with pytest.raises(SettingsError):
        ImuModel(accel_bias=-1.0)
    with pytest.raises(SettingsError):
        GX5_25.scaled(float("nan"))


def test_noise_bias_and_random_walk_statistics():
    """Per-sample white noise = density·√rate, turn-on bias spread, and the bias random walk's
    variance growing as walk²·T, measured over independent draws."""
    model = ImuModel(accel_noise_density=0.01, gyro_noise_density=0.001, accel_bias=0.05,
                     gyro_bias=0.004, accel_bias_walk=0.002, gyro_bias_walk=0.0003)
    rig = _still()
    t = np.arange(0.0, 100.0, 1 / 300)
    b_T_imu = np.eye(4)
    clean, *_ = simulate_imu(rig, b_T_imu, t)
    noisy, ab, gb = simulate_imu(rig, b_T_imu, t, model, np.random.default_rng(0))
    white = noisy - clean - np.hstack([ab, gb])
    assert np.std(white[:, :3]) == pytest.approx(model.accel_noise, rel=0.02)
    assert np.std(white[:, 3:]) == pytest.approx(model.gyro_noise, rel=0.02)
    starts, ends = [], []
    for seed in range(300):
        _, ab, gb = simulate_imu(rig, b_T_imu, t[::300], model, np.random.default_rng(seed))
        starts.append(np.concatenate([ab[0], gb[0]]))
        ends.append(np.concatenate([ab[-1] - ab[0], gb[-1] - gb[0]]))
    starts, ends = np.array(starts), np.array(ends)
    assert np.std(starts[:, :3]) == pytest.approx(model.accel_bias, rel=0.1)
    assert np.std(starts[:, 3:]) == pytest.approx(model.gyro_bias, rel=0.1)
    span = t[::300][-1] - t[0]
    assert np.std(ends[:, :3]) == pytest.approx(model.accel_bias_walk * np.sqrt(span), rel=0.1)
    assert np.std(ends[:, 3:]) == pytest.approx(model.gyro_bias_walk * np.sqrt(span), rel=0.1)


def test_rest_start_is_still_then_moves_with_exact_derivatives():
    inner = make_trajectory(EllipsePath(np.array([0.0, 0.0, 1.0]), (5.0, 3.0), 1.5, ramp=0.5),
                            "handheld", 3)
    rig = RestStart(inner, 2.0, ramp=1.0)
    st = rig.state(np.linspace(0.0, 1.99, 50))
    assert np.all(st.velocity == 0) and np.all(st.angular_velocity == 0)
    assert np.allclose(st.position, st.position[0])
    # Finite differences of the pose against the closed-form rates, across the ramp.
    t = np.linspace(1.9, 4.0, 40)
    h = 1e-5
    a, b = rig.state(t - h), rig.state(t + h)
    mid = rig.state(t)
    np.testing.assert_allclose((b.position - a.position) / (2 * h), mid.velocity, atol=1e-6)
    np.testing.assert_allclose((b.velocity - a.velocity) / (2 * h), mid.acceleration,
                               atol=1e-4)
    rel = (mid.rotation.inv() * b.rotation).as_rotvec() / h
    np.testing.assert_allclose(rel, mid.angular_velocity, atol=1e-4)
    np.testing.assert_allclose((b.angular_velocity - a.angular_velocity) / (2 * h),
                               mid.angular_acceleration, atol=1e-3)
    with pytest.raises(SettingsError):
        RestStart(inner, -1.0)


def test_simulated_run_records_imu_biases_rest_and_radar_time_offset(tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = simulate_run(tmp_path, duration=2.0, seed=1, heatmaps=False, rest=1.0,
                           radar_time_offset=0.025, sensors=("single_chip", "imu"))
    truth = load_truth(res.run_path)
    assert float(truth["radar_time_offset"]) == 0.025
    imu_t = truth["imu_timestamps"]
    assert truth["imu_accel_bias"].shape == (imu_t.size, 3) == truth["imu_gyro_bias"].shape
    sim = open_simulation(res.run_path)
    assert sim.config["rest"] == 1.0 and sim.config["imu_model"]["rate"] == 300.0
    # A frame stamped t was simulated at t + t_d: the radar's pose in the truth is the rig's
    # there (the trajectory rebuilt from sim_config, rest included).
    stamps = truth["single_chip/timestamps"]
    st = sim.trajectory.state(sim.run_time(stamps + 0.025))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ext = load_calibration(res.calib_path).transforms["single_chip"].matrix()
    origin = st.position + st.rotation.apply(ext[:3, 3])
    np.testing.assert_allclose(truth["single_chip/world_T_radar"][:, :3, 3], origin, atol=1e-6)
    # Before the rest ends the IMU reads the same specific force as at the start (still).
    data = np.loadtxt(res.run_path / "imu" / "imu_data.txt")
    still = sim.run_time(imu_t) < 0.9
    assert np.ptp(data[still, 3:], axis=0).max() < 10 * GX5_25.gyro_noise
    with pytest.raises(ColoradarError):
        simulate_run(tmp_path / "x", duration=1.0, radar_time_offset=2.0)
