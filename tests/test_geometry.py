"""coloradar.geometry: SE(3), extrinsics, interpolation, association, velocity, frames."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from _synth import REFERENCE_CALIB
from coloradar import DataWarning, MissingDataError, load_calibration
from coloradar.calib import PRESET_TRANSFORMS
from coloradar.geometry import (
    SE3,
    ExtrapolationError,
    Trajectory,
    associate,
    cloud_to_base,
    cloud_to_world,
    nearest_indices,
    rig_velocity,
    sensor_a_T_sensor_b,
    sensor_to_base,
    static_range_rate,
    window_indices,
    world_T_sensor,
)

CALIB_DIR = REFERENCE_CALIB


def _homog(points: np.ndarray) -> np.ndarray:
    return np.concatenate([points, np.ones((len(points), 1))], axis=1)


def _random_se3(rng: np.random.Generator) -> tuple[SE3, np.ndarray]:
    """An SE3 and its 4x4 matrix built independently from scipy."""
    r = Rotation.random(None, rng)
    t = rng.normal(scale=5.0, size=3)
    m = np.eye(4)
    m[:3, :3] = r.as_matrix()
    m[:3, 3] = t
    return SE3(r, t), m


@pytest.fixture(scope="module")
def real_calib():
    if not CALIB_DIR.is_dir():
        pytest.skip(f"real calibration not found at {CALIB_DIR}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_calibration(CALIB_DIR)


# -- SE3 ---------------------------------------------------------------------------------------
def test_se3_matches_homogeneous_matrices():
    rng = np.random.default_rng(1)
    pts = rng.normal(scale=10.0, size=(50, 3))
    for _ in range(20):
        a, ma = _random_se3(rng)
        b, mb = _random_se3(rng)
        np.testing.assert_allclose(a.matrix(), ma, atol=1e-12)
        np.testing.assert_allclose(a.apply(pts), (_homog(pts) @ ma.T)[:, :3], atol=1e-9)
        np.testing.assert_allclose((a @ b).matrix(), ma @ mb, atol=1e-9)
        np.testing.assert_allclose(a.inverse().matrix(), np.linalg.inv(ma), atol=1e-9)
        np.testing.assert_allclose((a @ a.inverse()).matrix(), np.eye(4), atol=1e-9)
        np.testing.assert_allclose(SE3.from_matrix(ma).matrix(), ma, atol=1e-12)
        # Pose rows x y z qx qy qz qw round-trip (the dataset's pose files).
        np.testing.assert_allclose(SE3.from_pose(a.as_pose()).matrix(), ma, atol=1e-12)
        # Associativity of application: (a @ b)(p) == a(b(p)).
        np.testing.assert_allclose((a @ b).apply(pts), a.apply(b.apply(pts)), atol=1e-9)


def test_se3_keeps_float32_clouds_and_extra_columns():
    rng = np.random.default_rng(2)
    a, ma = _random_se3(rng)
    cloud = rng.normal(size=(100, 5)).astype(np.float32)
    out = a.apply_to_cloud(cloud)
    assert out.dtype == np.float32 and out.shape == cloud.shape
    np.testing.assert_allclose(out[:, :3], (_homog(cloud[:, :3].astype(float)) @ ma.T)[:, :3],
                               atol=1e-4)
    np.testing.assert_array_equal(out[:, 3:], cloud[:, 3:])  # intensity, range rate unchanged
    np.testing.assert_allclose(a.rotate(np.array([1.0, 0, 0])), ma[:3, 0], atol=1e-12)


def test_se3_rejects_bad_input():
    with pytest.raises(ValueError):
        SE3(Rotation.random(2, 0), np.zeros(3))
    with pytest.raises(ValueError):
        SE3.from_pose(np.zeros(6))
    with pytest.raises(ValueError):
        SE3.from_matrix(np.ones((4, 4)))


# -- extrinsics --------------------------------------------------------------------------------
def test_extrinsics_match_calibration_files(real_calib):
    for sensor, ext in real_calib.transforms.items():
        np.testing.assert_allclose(sensor_to_base(real_calib, sensor).matrix(), ext.matrix(),
                                   atol=1e-12)
    # docs/conventions.md §3: the radars' boresight (x) points along the rig's forward axis (base +y),
    # and their y (left) along base -x.
    for radar in ("cascade", "single_chip"):
        b_T_r = sensor_to_base(real_calib, radar)
        np.testing.assert_allclose(b_T_r.rotate(np.array([1.0, 0, 0])), [0, 1, 0], atol=2e-3)
        np.testing.assert_allclose(b_T_r.rotate(np.array([0, 1.0, 0])), [-1, 0, 0], atol=2e-3)
    # Cascade -> lidar by brute-force matrix algebra on the raw file values.
    m_c, m_l = real_calib.transforms["cascade"].matrix(), real_calib.transforms["lidar"].matrix()
    pts = np.random.default_rng(3).normal(size=(20, 3))
    np.testing.assert_allclose(sensor_a_T_sensor_b(real_calib, "cascade", "lidar").apply(pts),
                               (_homog(pts) @ (np.linalg.inv(m_c) @ m_l).T)[:, :3], atol=1e-12)
    np.testing.assert_allclose(cloud_to_base(pts.astype(np.float32), real_calib, "lidar"),
                               (_homog(pts) @ m_l.T)[:, :3], atol=1e-5)


def test_missing_extrinsic_is_a_clear_error():
    calib = load_calibration(None)
    with pytest.raises(MissingDataError, match="base_to_radar9"):
        sensor_to_base(calib, "radar9")
    np.testing.assert_array_equal(sensor_to_base(calib, "base").matrix(), np.eye(4))


# -- trajectory interpolation ------------------------------------------------------------------
T0 = 1.6e9  # Unix times: interpolation must not lose precision at this magnitude


@pytest.fixture(scope="module")
def wiggly():
    rng = np.random.default_rng(4)
    n = 40
    t = T0 + np.cumsum(rng.uniform(0.05, 0.15, n))
    pos = np.cumsum(rng.normal(scale=0.1, size=(n, 3)), axis=0)
    rot = Rotation.from_rotvec(np.cumsum(rng.normal(scale=0.2, size=(n, 3)), axis=0))
    return Trajectory(t, pos, rot, "wiggly")


def test_interpolation_exact_at_knots(wiggly):
    at = wiggly.interpolate(wiggly.timestamps)
    np.testing.assert_allclose(at.translations, wiggly.translations, atol=1e-12)
    np.testing.assert_allclose((at.rotations.inv() * wiggly.rotations).magnitude(), 0, atol=1e-7)
    one = wiggly.at(wiggly.timestamps[7])
    np.testing.assert_allclose(one.matrix(), wiggly[7].matrix(), atol=1e-9)


def test_interpolation_continuous_and_geodesic(wiggly):
    k, eps = wiggly.timestamps, 1e-6
    before = wiggly.interpolate_arrays(k[1:-1] - eps)
    after = wiggly.interpolate_arrays(k[1:-1] + eps)
    # Steps across a knot are of the order of the local speed times 2 µs.
    assert np.max(np.abs(before[0] - after[0])) < 1e-5
    assert np.max((before[1].inv() * after[1]).magnitude()) < 1e-4
    # Between knots i and i+1 at fraction a: translation linear, rotation on the geodesic
    # R_i · exp(a · log(R_iᵀ R_{i+1})) (written out here without Slerp).
    a = np.random.default_rng(5).uniform(0, 1, len(k) - 1)
    tq = k[:-1] + a * np.diff(k)
    a = (tq - k[:-1]) / np.diff(k)  # the fraction actually represented at Unix-time magnitude
    trans, rot = wiggly.interpolate_arrays(tq)
    p = wiggly.translations
    np.testing.assert_allclose(trans, (1 - a)[:, None] * p[:-1] + a[:, None] * p[1:], atol=1e-9)
    r = wiggly.rotations
    rel = (r[:-1].inv() * r[1:]).as_rotvec()
    expect = r[:-1] * Rotation.from_rotvec(a[:, None] * rel)
    np.testing.assert_allclose((expect.inv() * rot).magnitude(), 0, atol=1e-6)


def test_interpolation_outside_span(wiggly):
    with pytest.raises(ExtrapolationError, match="before the first pose"):
        wiggly.at(wiggly.start - 0.5)
    with pytest.raises(ExtrapolationError, match="after the last pose"):
        wiggly.interpolate(np.array([wiggly.start, wiggly.end + 1.0]))
    # Within tolerance the end pose is used.
    np.testing.assert_allclose(wiggly.at(wiggly.end + 0.01, tolerance=0.02).matrix(),
                               wiggly[len(wiggly) - 1].matrix(), atol=1e-9)
    assert wiggly.covers(np.array([wiggly.start - 1, wiggly.start, wiggly.end])).tolist() == [
        False, True, True]


def test_from_poses_cleans_time_axis():
    t = np.array([3.0, 1.0, 2.0, 2.0])
    poses = np.zeros((4, 7))
    poses[:, 0] = [30, 10, 20, 21]
    poses[:, 6] = 1.0
    with pytest.warns(DataWarning):
        traj = Trajectory.from_poses(t, poses, "gt")
    np.testing.assert_array_equal(traj.timestamps, [1, 2, 3])
    np.testing.assert_array_equal(traj.translations[:, 0], [10, 20, 30])
    from coloradar import FormatError

    with pytest.raises(FormatError, match="gt"):
        Trajectory.from_poses(t, poses[:, :6], "gt")


def test_trajectory_composition_matches_pose_by_pose(wiggly):
    rng = np.random.default_rng(6)
    mount, mm = _random_se3(rng)
    left, ml = _random_se3(rng)
    both = left @ wiggly @ mount
    mats = wiggly.matrices()
    np.testing.assert_allclose(both.matrices(), ml @ mats @ mm, atol=1e-9)
    np.testing.assert_allclose(wiggly.inverse().matrices(), np.linalg.inv(mats), atol=1e-9)
    rel = wiggly.relative_to_first()
    np.testing.assert_allclose(rel.matrices()[0], np.eye(4), atol=1e-12)


# -- time association --------------------------------------------------------------------------
def test_association_on_jittered_timestamps():
    rng = np.random.default_rng(7)
    a = T0 + np.arange(200) * 0.1                       # 10 Hz stream
    truth = np.sort(rng.choice(200, 150, replace=False))
    b = a[truth] + rng.uniform(-0.02, 0.02, truth.size)  # jittered copies of some frames
    b = np.concatenate([b, T0 + np.array([-5.0, 50.0])])  # two frames far from any
    shuffle = rng.permutation(b.size)
    b = b[shuffle]
    idx = nearest_indices(b, a, tolerance=0.03)
    expect = np.full(b.size, -1)
    expect[np.argsort(shuffle)[: truth.size]] = truth
    np.testing.assert_array_equal(idx, expect)
    # Brute force over all pairs for the tolerance-free case.
    brute = np.argmin(np.abs(b[:, None] - a[None, :]), axis=1)
    np.testing.assert_array_equal(nearest_indices(b, a), brute)
    ia, ib = associate(a, b, tolerance=0.03)
    np.testing.assert_array_equal(ia, truth)
    np.testing.assert_array_equal(b[ib] - a[ia], b[ib] - a[truth])
    assert np.all(np.abs(b[ib] - a[ia]) <= 0.03)
    # A tolerance below the jitter loses exactly the pairs that are farther apart.
    idx_tight = nearest_indices(b, a, tolerance=0.01)
    d = np.abs(b - a[np.maximum(brute, 0)])
    np.testing.assert_array_equal(idx_tight >= 0, d <= 0.01)


def test_mutual_association_uses_each_frame_once():
    a = np.array([0.0, 0.1, 0.2, 0.3])
    b = np.array([0.09, 0.31])
    ia, ib = associate(a, b, tolerance=0.15)
    assert ia.tolist() == [1, 3] and ib.tolist() == [0, 1]
    ia, ib = associate(a, b, tolerance=0.15, mutual=False)
    assert ia.tolist() == [0, 1, 2, 3] and ib.tolist() == [0, 0, 1, 1]
    ia, ib = associate(a, b, tolerance=0.05, mutual=False)
    assert ia.tolist() == [1, 3] and ib.tolist() == [0, 1]
    assert nearest_indices(np.array([1.0]), np.array([])).tolist() == [-1]
    assert window_indices(np.array([0.0, 1, 2, 3]), 1.0, 3.0).tolist() == [1, 2]


# -- rig velocity ------------------------------------------------------------------------------
def _screw_trajectory(v: np.ndarray, yaw_rate: float, r0: Rotation, n: int = 30,
                      dt: float = 0.1) -> Trajectory:
    t = T0 + np.arange(n) * dt
    rel = t - T0
    rot = Rotation.from_rotvec(np.outer(rel, [0, 0, yaw_rate])) * r0
    return Trajectory(t, np.outer(rel, v), rot, "screw")


def test_rig_velocity_of_a_lever_arm_is_exact_for_constant_rates():
    v = np.array([0.8, -0.3, 0.1])
    yaw = 0.6
    r0 = Rotation.from_euler("xyz", [0.1, -0.2, 0.3])
    traj = _screw_trajectory(v, yaw, r0)
    calib = load_calibration(None)
    mount = sensor_to_base(calib, "cascade")
    tq = np.linspace(traj.start + 0.05, traj.end - 0.05, 17)
    vel = rig_velocity(traj, tq, calib=calib, sensor="cascade")
    assert vel.frame == "cascade"
    # Truth: s(t) = v t + R(t) t_bs, ds/dt = v + ω ẑ × R(t) t_bs, expressed in the sensor frame.
    for k, t in enumerate(tq):
        r = Rotation.from_rotvec([0, 0, yaw * (t - T0)]) * r0
        ds = v + np.cross([0, 0, yaw], r.apply(np.array(mount.translation)))
        r_ws = (r * mount.rotation).as_matrix()
        np.testing.assert_allclose(vel.linear[k], r_ws.T @ ds, atol=1e-9)
        np.testing.assert_allclose(vel.angular[k], r_ws.T @ [0, 0, yaw], atol=1e-9)
    world = rig_velocity(traj, tq, calib=calib, sensor="cascade", expressed_in="world")
    np.testing.assert_allclose(world.angular, np.tile([0, 0, yaw], (tq.size, 1)), atol=1e-9)


def test_static_point_range_rate_matches_differentiated_range(wiggly):
    """What a Doppler radar on the rig measures for a static world point."""
    calib = load_calibration(None)
    world_pt = np.array([3.0, 4.0, 0.5])
    k = wiggly.timestamps
    t = (k[[5, 20]] + k[[6, 21]]) / 2  # mid-segment: the interpolation is smooth there
    h = 1e-3
    for tk in t:
        def rng_at(tt):
            pose = wiggly.at(tt) @ sensor_to_base(calib, "single_chip")
            return np.linalg.norm(pose.inverse().apply(world_pt))

        tp, tm = tk + h, tk - h  # divide by the difference float64 actually holds
        numeric = (rng_at(tp) - rng_at(tm)) / (tp - tm)
        # A small half-window differentiates the piecewise interpolation locally.
        vel = rig_velocity(wiggly, np.array([tk]), calib=calib, sensor="single_chip",
                           half_window=h)
        p_sensor = (wiggly.at(tk) @ sensor_to_base(calib, "single_chip")).inverse().apply(
            world_pt[None])
        rr = static_range_rate(p_sensor, vel.linear[0])
        np.testing.assert_allclose(rr[0], numeric, atol=1e-4)


# -- one world point, two sensors --------------------------------------------------------------
def test_point_seen_by_two_sensors_maps_to_the_same_world_point(wiggly):
    """Cascade and lidar frames at different times see one static point: both land on it."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the real files' known defects are not tested here
        calib = load_calibration(CALIB_DIR if CALIB_DIR.is_dir() else None)
    world_pts = np.array([[2.0, 5.0, 0.3], [-1.0, 3.0, 1.2]])
    knot_rows = np.concatenate([wiggly.translations, wiggly.rotations.as_quat()], axis=1)
    for sensor, k in (("cascade", 7), ("lidar", 19), ("single_chip", 22)):
        t = wiggly.timestamps[k]
        # The sensor's view built with 4x4 matrices from the raw pose row and calib values.
        w_T_b = np.eye(4)
        w_T_b[:3, :3] = Rotation.from_quat(knot_rows[k, 3:]).as_matrix()
        w_T_b[:3, 3] = knot_rows[k, :3]
        b_T_s = calib.transforms[sensor].matrix()
        seen = (_homog(world_pts) @ np.linalg.inv(w_T_b @ b_T_s).T)[:, :3]
        cloud = np.concatenate([seen, np.ones((2, 1))], axis=1).astype(np.float32)
        back = cloud_to_world(cloud, t, wiggly, calib, sensor)
        np.testing.assert_allclose(back[:, :3], world_pts, atol=1e-4)
        poses = world_T_sensor(wiggly, calib, sensor, np.array([t]))
        np.testing.assert_allclose(poses.matrices()[0], w_T_b @ b_T_s, atol=1e-9)


def test_preset_transforms_equal_the_real_files(real_calib):
    for sensor, ext in PRESET_TRANSFORMS.items():
        np.testing.assert_allclose(real_calib.transforms[sensor].matrix(), ext.matrix(),
                                   atol=1e-9)
