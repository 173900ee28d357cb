"""coloradar.odometry on arrays: ego-velocity RANSAC, alignment, ATE/RPE, TUM, dead reckoning.

References are independent of the code under test: brute-force least squares on the known
inliers, scipy's Kabsch solver, loops over pose pairs, closed-form motions.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from _synth import REFERENCE_CALIB
from coloradar import ColoradarError, FormatError, OutputExistsError
from coloradar.calib import preset_calibration
from coloradar.geometry import SE3, Trajectory, sensor_to_base
from coloradar.odometry import (
    EgoVelocityConfig,
    EgoVelocityTrack,
    absolute_trajectory_error,
    cumulative_rotations,
    estimate_ego_velocities,
    estimate_ego_velocity,
    integrate_gyro,
    parse_tum,
    radar_inertial_odometry,
    read_tum,
    read_velocity_table,
    relative_pose_error,
    umeyama_alignment,
    write_tum,
    write_velocity_table,
)

T0 = 1_608_580_000.123456


# -- synthetic clouds ----------------------------------------------------------------------------
def _directions(rng, n, az_max=1.2, el_max=0.35):
    az = rng.uniform(-az_max, az_max, n)
    el = rng.uniform(-el_max, el_max, n)
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)


def _scene(rng, *, n_static=40, n_object=50, n_false=10, noise=0.02, speed=1.2, thr=0.15):
    """A cloud whose static points, moving-object points and false alarms are known.

    The object is compact (a person-sized blob 3 m ahead) and moves so that each of its points'
    range rate is > 4 thresholds away from what a static point there would show; false alarms
    likewise. Returns (v, points (N,3), range rates (N,), static mask).
    """
    v = rng.normal(size=3)
    v[2] *= 0.3
    v *= speed / np.linalg.norm(v)
    ds = _directions(rng, n_static)
    ps = ds * rng.uniform(1.0, 15.0, (n_static, 1))
    vr_s = -ds @ v + rng.normal(scale=noise, size=n_static)
    a = rng.uniform(-0.8, 0.8)
    centre = 3.0 * np.array([np.cos(a), np.sin(a), 0.0])
    po = centre + rng.normal(scale=[0.15, 0.15, 0.4], size=(n_object, 3))
    do = po / np.linalg.norm(po, axis=1, keepdims=True)
    u = rng.choice([-1.0, 1.0]) * rng.uniform(0.9, 1.4) * centre / 3.0   # walks along the line of sight
    vr_o = do @ (u - v) + rng.normal(scale=noise, size=n_object)
    assert np.all(np.abs(vr_o - (-do @ v)) > 4 * thr)
    df = _directions(rng, n_false)
    pf = df * rng.uniform(1.0, 15.0, (n_false, 1))
    vr_f = -df @ v + rng.choice([-1.0, 1.0], n_false) * rng.uniform(4 * thr, 1.5, n_false)
    pts = np.concatenate([ps, po, pf])
    vr = np.concatenate([vr_s, vr_o, vr_f])
    static = np.zeros(len(pts), dtype=bool)
    static[:n_static] = True
    perm = rng.permutation(len(pts))
    return v, pts[perm], vr[perm], static[perm]


def _lstsq_reference(pts, vr, mask):
    d = pts[mask] / np.linalg.norm(pts[mask], axis=1, keepdims=True)
    a = -d
    v = np.linalg.solve(a.T @ a, a.T @ vr[mask])
    res = a @ v - vr[mask]
    s2 = res @ res / (mask.sum() - 3)
    return v, s2 * np.linalg.inv(a.T @ a)


def test_ransac_equals_least_squares_on_true_inliers_with_half_the_points_moving():
    rng = np.random.default_rng(3)
    errors = []
    for k in range(25):
        v, pts, vr, static = _scene(rng)
        assert (~static).sum() >= len(pts) / 2           # half moving + false alarms
        ev = estimate_ego_velocity(pts, vr, rng=k)
        assert ev.ok, ev.reason
        np.testing.assert_array_equal(ev.inliers, static)
        v_ref, cov_ref = _lstsq_reference(pts, vr, static)
        np.testing.assert_allclose(ev.velocity, v_ref, rtol=0, atol=1e-10)
        np.testing.assert_allclose(ev.covariance, cov_ref, rtol=1e-8, atol=1e-14)
        errors.append(ev.velocity - v)
    rmse = np.sqrt(np.mean(np.sum(np.square(errors), axis=1)))
    assert rmse < 0.05


def test_covariance_matches_the_actual_scatter_of_the_estimate():
    # Static-only clouds with Gaussian range-rate noise: the normalised squared error
    # eᵀ C⁻¹ e of a correct covariance is chi-square with 3 degrees of freedom (mean 3).
    rng = np.random.default_rng(11)
    m2 = []
    for k in range(300):
        v, pts, vr, _ = _scene(rng, n_static=30, n_object=0, n_false=0, noise=0.04)
        ev = estimate_ego_velocity(pts, vr, rng=k)
        e = ev.velocity - v
        m2.append(e @ np.linalg.solve(ev.covariance, e))
    assert 2.6 < np.mean(m2) < 3.6


def test_planar_model_equals_two_column_least_squares():
    # A sensor moving in its own x-y plane, seen with coarse elevation: vz is fixed to 0.
    rng = np.random.default_rng(12)
    for k in range(10):
        v, pts, vr, static = _scene(rng, n_object=40, n_false=10)
        v[2] = 0.0
        d = pts / np.linalg.norm(pts, axis=1, keepdims=True)
        vr[static] = -d[static] @ v + rng.normal(scale=0.02, size=static.sum())
        ev = estimate_ego_velocity(pts, vr, EgoVelocityConfig(planar=True), rng=k)
        assert ev.ok, ev.reason
        np.testing.assert_array_equal(ev.inliers, static)
        a = -d[static][:, :2]
        ref = np.linalg.solve(a.T @ a, a.T @ vr[static])
        np.testing.assert_allclose(ev.velocity, [*ref, 0.0], atol=1e-10)
        assert ev.covariance[2, 2] == 0.0 and ev.covariance[0, 0] > 0


def test_cloud_columns_and_seed_determinism():
    rng = np.random.default_rng(5)
    v, pts, vr, _ = _scene(rng)
    cloud = np.column_stack([pts, rng.random(len(pts)), vr]).astype(np.float32)
    a = estimate_ego_velocity(cloud, rng=42)
    b = estimate_ego_velocity(cloud[:, :3], cloud[:, 4], rng=42)
    c = estimate_ego_velocity(cloud, rng=42)
    np.testing.assert_array_equal(a.velocity, b.velocity)
    np.testing.assert_array_equal(a.velocity, c.velocity)
    assert np.linalg.norm(a.velocity - v) < 0.05


def test_doppler_aliasing_is_unwrapped():
    rng = np.random.default_rng(8)
    vmax = 1.76                                          # the cascade's unambiguous range rate
    for k in range(10):
        _v, pts, vr, static = _scene(rng, speed=2.3, n_object=0, n_false=5)
        wrapped = (vr + vmax) % (2 * vmax) - vmax
        assert np.any(wrapped[static] != vr[static])     # some static points alias
        ev = estimate_ego_velocity(pts, wrapped, EgoVelocityConfig(max_velocity=vmax), rng=k)
        assert ev.ok
        np.testing.assert_array_equal(ev.inliers, static)
        v_ref, _ = _lstsq_reference(pts, vr, static)     # least squares on the true rates
        np.testing.assert_allclose(ev.velocity, v_ref, atol=1e-10)


def test_too_few_points_and_degenerate_geometry_are_reported():
    rng = np.random.default_rng(2)
    _v, pts, vr, _ = _scene(rng, n_static=5, n_object=0, n_false=0)
    ev = estimate_ego_velocity(pts, vr)
    assert not ev.ok and "too few points" in ev.reason and np.all(np.isnan(ev.velocity))
    # All points in the sensor's horizontal plane: vz is unobservable.
    d = _directions(rng, 50, el_max=0.0)
    ev = estimate_ego_velocity(d * 5.0, -d @ np.array([1.0, 0.2, 0.3]))
    assert not ev.ok and "degenerate" in ev.reason
    # Points inside min_range (the rig itself) do not count.
    _v, pts, vr, _ = _scene(rng, n_static=30, n_object=0, n_false=0)
    ev = estimate_ego_velocity(pts * 0.01, vr, EgoVelocityConfig(min_range=0.3))
    assert not ev.ok and ev.num_points == 0


def test_batch_estimation_and_velocity_table_round_trip(tmp_path):
    rng = np.random.default_rng(4)
    truth, clouds = [], []
    for _ in range(6):
        v, pts, vr, _ = _scene(rng)
        truth.append(v)
        clouds.append(np.column_stack([pts, np.ones(len(pts)), vr]).astype(np.float32))
    clouds.insert(3, np.zeros((2, 5), np.float32))          # an empty-ish frame
    t = T0 + 0.2 * np.arange(len(clouds))
    track = estimate_ego_velocities(clouds, t, seed=9, frame="cascade")
    assert track.ok.tolist() == [True] * 3 + [False] + [True] * 3
    est = np.delete(track.velocity, 3, axis=0)
    assert np.sqrt(np.mean(np.sum((est - np.array(truth)) ** 2, axis=1))) < 0.05
    p = write_velocity_table(tmp_path / "ego_velocity.csv", track)
    back = read_velocity_table(p)
    np.testing.assert_array_equal(back.timestamps, track.timestamps)
    np.testing.assert_array_equal(back.velocity, track.velocity)
    np.testing.assert_array_equal(back.covariance, track.covariance)
    assert back.ok.tolist() == track.ok.tolist() and back.reasons == track.reasons
    assert back.frame == "cascade"
    with pytest.raises(OutputExistsError):
        write_velocity_table(p, track)


# -- alignment and metrics -----------------------------------------------------------------------
def test_umeyama_recovers_a_known_random_transform():
    rng = np.random.default_rng(0)
    for _ in range(10):
        x = rng.normal(scale=5.0, size=(40, 3))
        r = Rotation.random(None, rng)
        t = rng.normal(scale=10.0, size=3)
        s = rng.uniform(0.5, 2.0)
        al = umeyama_alignment(x, r.apply(x) + t)
        assert (al.rotation.inv() * r).magnitude() < 1e-10
        np.testing.assert_allclose(al.translation, t, atol=1e-9)
        assert al.scale == 1.0
        al = umeyama_alignment(x, s * r.apply(x) + t, with_scale=True)
        assert (al.rotation.inv() * r).magnitude() < 1e-10
        np.testing.assert_allclose([al.scale, *al.translation], [s, *t], atol=1e-9)


def test_umeyama_with_noise_matches_kabsch_and_never_reflects():
    rng = np.random.default_rng(1)
    x = rng.normal(size=(30, 3))
    y = Rotation.random(None, rng).apply(x) + rng.normal(scale=0.05, size=(30, 3)) + 3.0
    al = umeyama_alignment(x, y)
    ref, _ = Rotation.align_vectors(y - y.mean(0), x - x.mean(0))   # Kabsch, independent
    assert (al.rotation.inv() * ref).magnitude() < 1e-9
    mirrored = x * np.array([1.0, 1.0, -1.0])
    al = umeyama_alignment(x, mirrored)
    assert np.linalg.det(al.rotation.as_matrix()) > 0


def _circle(n=400, radius=4.0, speed=1.0, rate=10.0, z_amp=0.3):
    t = T0 + np.arange(n) / rate
    s = speed * (t - t[0])
    ang = s / radius
    p = np.stack([radius * np.sin(ang), radius * (1 - np.cos(ang)), z_amp * np.sin(0.5 * ang)], 1)
    rot = Rotation.from_euler("z", ang[:, None]) * Rotation.from_euler("x", 0.1 * np.sin(ang)[:, None])
    return Trajectory(t, p, rot, "reference")


def test_ate_is_zero_for_a_rigidly_moved_trajectory():
    ref = _circle()
    g = SE3(Rotation.from_euler("xyz", [0.3, -0.2, 1.1]), [5.0, -2.0, 0.7])
    moved = g @ ref
    ate = absolute_trajectory_error(moved, ref)
    assert ate.rmse < 1e-9 and ate.rotation_rmse < 1e-6
    scaled = Trajectory(ref.timestamps, 1.7 * moved.translations, moved.rotations)
    assert absolute_trajectory_error(scaled, ref, align="sim3").rmse < 1e-9
    # Without alignment the error is the displacement itself.
    raw = absolute_trajectory_error(moved, ref, align="none")
    np.testing.assert_allclose(raw.errors, np.linalg.norm(moved.translations - ref.translations,
                                                          axis=1), atol=1e-12)


def test_ate_of_a_known_offset_and_percent_of_distance():
    ref = _circle()
    noise = np.random.default_rng(0).normal(scale=0.05, size=ref.translations.shape)
    noisy = Trajectory(ref.timestamps, ref.translations + noise, ref.rotations)
    ate = absolute_trajectory_error(noisy, ref, align="none")
    assert ate.rmse == pytest.approx(np.sqrt(np.mean(np.sum(noise**2, axis=1))), rel=1e-12)
    dist = np.sum(np.linalg.norm(np.diff(ref.translations, axis=0), axis=1))
    assert ate.rmse_percent == pytest.approx(100 * ate.rmse / dist)


def test_rpe_of_a_constant_scale_drift_is_that_drift():
    ref = _circle()
    drift = 0.02
    est = Trajectory(ref.timestamps, (1 + drift) * ref.translations, ref.rotations)
    p = ref.translations
    seg = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
    for res in relative_pose_error(est, ref, (1.0, 2.0, 5.0)):
        expected = []
        for i in range(len(p)):                      # brute force over every start pose
            later = [j for j in range(i, len(p)) if seg[j] - seg[i] >= res.distance - 1e-9]
            if later:
                expected.append(drift * np.linalg.norm(p[later[0]] - p[i]))
        assert res.pairs == len(expected)
        np.testing.assert_allclose(res.translation_errors, expected, rtol=1e-9, atol=1e-12)
        assert res.translation_percent == pytest.approx(100 * np.mean(expected) / res.distance,
                                                        rel=1e-9)
        # On a 4 m circle a 1 m chord is 99 % of its arc: the drift, 2 %, shows through.
        if res.distance == 1.0:
            assert res.translation_percent == pytest.approx(100 * drift, rel=0.02)
        assert res.rotation_deg_per_m < 1e-9


def test_rpe_of_a_constant_heading_drift_in_degrees_per_metre():
    t = T0 + np.arange(300) / 10.0
    p = np.stack([t - t[0], np.zeros_like(t), np.zeros_like(t)], axis=1)     # 1 m/s, 0.1 m apart
    ref = Trajectory(t, p, Rotation.identity(len(t)))
    k = 0.5                                                                 # deg per metre
    est = Trajectory(t, p, Rotation.from_euler("z", k * p[:, :1], degrees=True))
    for res in relative_pose_error(est, ref, (1.0, 2.0, 5.0)):
        assert res.pairs == len(t) - round(res.distance / 0.1)
        assert res.rotation_deg_per_m == pytest.approx(k, rel=1e-9)


def test_tum_round_trip_and_errors(tmp_path):
    rng = np.random.default_rng(6)
    t = T0 + np.cumsum(rng.uniform(0.05, 0.15, 50))
    traj = Trajectory(t, rng.normal(scale=20.0, size=(50, 3)), Rotation.random(50, rng))
    path = write_tum(tmp_path / "traj.txt", traj, comments=["made by a test"])
    back = read_tum(path)
    np.testing.assert_array_equal(back.timestamps, traj.timestamps)
    np.testing.assert_array_equal(back.translations, traj.translations)
    assert np.all((back.rotations.inv() * traj.rotations).magnitude() < 1e-12)
    lines = path.read_text().splitlines()
    assert lines[0].startswith("#") and len(lines[-1].split()) == 8
    with pytest.raises(OutputExistsError):
        write_tum(path, traj)
    with pytest.raises(FormatError, match="line 3"):
        parse_tum("# c\n1.0 0 0 0 0 0 0 1\n2.0 0 0 0 0 0 1\n", "bad.txt")


# -- gyro integration and dead reckoning ---------------------------------------------------------
def test_cumulative_rotations_equals_sequential_products():
    rng = np.random.default_rng(0)
    d = Rotation.random(37, rng)
    ref = [d[0]]
    for k in range(1, 37):
        ref.append(ref[-1] * d[k])
    got = cumulative_rotations(d)
    assert np.all((Rotation.concatenate(ref).inv() * got).magnitude() < 1e-12)


def test_gyro_integration_of_a_known_rate_profile():
    t = np.linspace(0.0, 10.0, 3001)
    axis = np.array([1.0, 2.0, -0.5]) / np.linalg.norm([1.0, 2.0, -0.5])
    rate = 0.8 + 0.3 * np.sin(1.3 * t)                       # rad/s about a fixed axis
    r = integrate_gyro(t, rate[:, None] * axis, bias=None)
    angle = 0.8 * t + 0.3 / 1.3 * (1 - np.cos(1.3 * t))      # ∫ rate dt
    truth = Rotation.from_rotvec(angle[:, None] * axis)
    assert np.max((truth.inv() * r).magnitude()) < 1e-5
    # A known bias is removed.
    r_b = integrate_gyro(t, rate[:, None] * axis + [0.01, -0.02, 0.03],
                         bias=np.array([0.01, -0.02, 0.03]))
    assert np.max((truth.inv() * r_b).magnitude()) < 1e-5


def _circle_motion(times, radius=3.0, omega=0.3):
    """Base frame on a circle, facing along the path (base y forward): exact pose and rates."""
    ang = omega * (times - times[0])
    pos = np.stack([radius * np.sin(ang), radius * (1 - np.cos(ang)), 0.02 * ang], axis=1)
    vel = np.stack([radius * omega * np.cos(ang), radius * omega * np.sin(ang),
                    np.full_like(ang, 0.02 * omega)], axis=1)
    # Forward (world +x at t0) is base +y: base = Rz(ang - 90°).
    rot = Rotation.from_euler("z", (ang - np.pi / 2)[:, None])
    return pos, vel, rot, np.array([0.0, 0.0, omega])        # body rate in base frame


def test_radar_inertial_dead_reckoning_follows_a_known_circle():
    calib = preset_calibration()
    radar = "cascade"
    bs = sensor_to_base(calib, radar)
    bi = sensor_to_base(calib, "imu")
    t_radar = T0 + np.arange(0, 30.0, 0.2)
    t_imu = T0 - 0.5 + np.arange(0, 31.0, 1 / 200)
    pos, vel, rot, w_base = _circle_motion(t_radar)
    # Radar origin velocity in its frame: R_bsᵀ (Rᵀ v + ω × t_bs) (rigid body kinematics).
    v_base = rot.inv().apply(vel) + np.cross(w_base, bs.translation)
    v_radar = bs.rotation.inv().apply(v_base)
    m = len(t_radar)
    ok = np.ones(m, dtype=bool)
    ok[[5, 6, 40]] = False                              # gaps get interpolated
    v_meas = np.where(ok[:, None], v_radar, np.nan)
    track = EgoVelocityTrack(t_radar, v_meas, np.tile(np.eye(3) * 1e-4, (m, 1, 1)),
                             np.full(m, 50), np.full(m, 40), np.full(m, 0.02), ok, frame=radar)
    gyro = np.tile(bi.rotation.inv().apply(w_base), (len(t_imu), 1))
    gt = Trajectory(t_radar, pos, rot, "truth")
    start = SE3(rot[0], pos[0])
    est = radar_inertial_odometry(track, calib, imu_timestamps=t_imu, imu_rates=gyro,
                                  initial_pose=start)
    err = np.linalg.norm(est.translations - pos, axis=1)
    assert err.max() < 0.01                              # 9 m of arc
    assert np.max((rot.inv() * est.rotations).magnitude()) < 1e-6
    est_gt = radar_inertial_odometry(track, calib, orientation="groundtruth", groundtruth=gt)
    assert np.max(np.linalg.norm(est_gt.translations - pos, axis=1)) < 0.01


def test_association_skips_ground_truth_gaps_and_rejects_disjoint_runs():
    ref = _circle()
    keep = np.ones(len(ref), dtype=bool)
    keep[100:130] = False                                    # a 3 s ground-truth dropout
    holey = ref[np.flatnonzero(keep)]
    est = Trajectory(ref.timestamps + 0.05, ref.translations, ref.rotations)
    ate = absolute_trajectory_error(est, holey, align="none", max_gap=1.0)
    t_gap = (ref.timestamps[99], ref.timestamps[130])
    assert not np.any((ate.timestamps > t_gap[0]) & (ate.timestamps < t_gap[1]))
    assert ate.timestamps.size == len(ref) - 1 - 31
    later = Trajectory(ref.timestamps + 1000.0, ref.translations, ref.rotations, "later")
    with pytest.raises(ColoradarError, match="same run"):
        absolute_trajectory_error(later, ref)


def test_settings_for_the_real_radars():
    from coloradar import load_calibration
    from coloradar.odometry import ego_velocity_config

    calib_dir = REFERENCE_CALIB
    if not calib_dir.is_dir():
        pytest.skip(f"real calibration not found at {calib_dir}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        calib = load_calibration(calib_dir)
    cas = ego_velocity_config(calib.cascade)
    sc = ego_velocity_config(calib.single_chip)
    # Cascade: 0.22 m/s Doppler bins, v_max 1.76 m/s, 4 elevation rows -> 3D.
    assert cas.threshold == pytest.approx(0.75 * 2 * 1.7627 / 16, rel=1e-3)
    assert cas.max_velocity == pytest.approx(1.7627, rel=1e-3) and not cas.planar
    # Single chip: two elevation rows -> planar; fine Doppler bins -> the 0.1 m/s floor.
    assert sc.planar and sc.threshold == 0.1
