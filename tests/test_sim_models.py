"""Simulator building blocks against brute force, finite differences and the reference physics."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from coloradar.calib import preset_radar
from coloradar.errors import ColoradarError
from coloradar.sim import synthesize_adc
from coloradar.sim.imu import GRAVITY, simulate_imu
from coloradar.sim.paths import EllipsePath, LinePath, Sinusoids
from coloradar.sim.radar import (
    RADAR_MODELS,
    RadarTargets,
    make_channel_errors,
    make_coupling,
    onboard_pointcloud,
    radar_frame,
)
from coloradar.sim.raycast import RectArrays, cast_rays
from coloradar.sim.scene import load_scene, scene_from_dict
from coloradar.sim.scenes import SCENES, builtin_scene, builtin_scene_dict
from coloradar.sim.trajectory import MOTION_PROFILES, RigTrajectory, make_trajectory

H = 1e-5  # finite-difference step [s]


@pytest.mark.parametrize("profile", list(MOTION_PROFILES))
@pytest.mark.parametrize("clockwise", [False, True])
def test_trajectory_derivatives_match_finite_differences(profile, clockwise):
    path = EllipsePath([1.0, -2.0, 1.1], (6.0, 0.8), 1.0, 0.4, 0.3, 0.5, clockwise)
    tr = make_trajectory(path, profile, 7)
    t = np.array([0.05, 0.7, 3.3, 11.9])
    s, sp, sm = tr.state(t), tr.state(t + H), tr.state(t - H)
    np.testing.assert_allclose((sp.position - sm.position) / (2 * H), s.velocity, atol=1e-6)
    np.testing.assert_allclose((sp.velocity - sm.velocity) / (2 * H), s.acceleration, atol=1e-5)
    # Body rates: rotation vector of R(t-h)ᵀ R(t+h), in the base frame.
    w_fd = (sm.rotation.inv() * sp.rotation).as_rotvec() / (2 * H)
    np.testing.assert_allclose(w_fd, s.angular_velocity, atol=1e-6)
    np.testing.assert_allclose((sp.angular_velocity - sm.angular_velocity) / (2 * H),
                               s.angular_acceleration, atol=1e-5)
    # The rig's forward axis (base +y) points along the direction of travel, within the
    # profile's yaw/pitch perturbations.
    # profile's yaw perturbations (seen horizontally, once the rig is up to speed).
    fwd = s.rotation.apply([0.0, 1.0, 0.0])[1:, :2]
    v = s.velocity[1:, :2]
    cos = np.einsum("ij,ij->i", fwd, v) / np.linalg.norm(fwd, axis=1) / np.linalg.norm(v, axis=1)
    limit = {"smooth": 0.99, "handheld": 0.97, "aggressive": 0.6, "vehicle": 0.99,
             "ramps": 0.9}[profile]   # ramps: a 2 Hz sway of ±1.5 cm, ~11° of lateral velocity
    assert np.all(cos > limit)


def test_paths_start_from_rest_and_line_reverses():
    e = EllipsePath([0, 0, 1], (5.0, 1.0), 1.2, ramp=0.5)
    s = e.sample(np.array([0.0, 5.0]))
    assert np.linalg.norm(s.velocity[0]) < 1e-12            # starts at rest
    np.testing.assert_allclose(s.position[0], [0, -1, 1])
    line = LinePath([-2, 0, 0], [2, 0, 0], 1.0)
    ls = line.sample(np.linspace(0, 40, 4001))
    assert ls.position[:, 0].min() == pytest.approx(-2, abs=1e-3)
    assert ls.position[:, 0].max() == pytest.approx(2, abs=1e-3)
    assert np.abs(ls.velocity[:, 0]).max() == pytest.approx(1.0, abs=1e-4)


def _unperturbed(path):
    return RigTrajectory(path, (Sinusoids(), Sinusoids(), Sinusoids()), Sinusoids(),
                         Sinusoids(), Sinusoids())


def test_imu_at_rest_reads_gravity_and_rotates_into_its_frame():
    still = _unperturbed(LinePath([0, 0, 1], [0, 0, 1], 0.0))
    base_T_imu = np.eye(4)
    base_T_imu[:3, :3] = Rotation.from_euler("x", 180, degrees=True).as_matrix()  # z down
    data, _ab, _gb = simulate_imu(still, base_T_imu, np.linspace(0, 1, 5))
    np.testing.assert_allclose(data[:, :3], [[0, 0, GRAVITY[2]]] * 5, atol=1e-12)  # −9.81 on z
    np.testing.assert_allclose(data[:, 3:], 0, atol=1e-12)


def test_imu_lever_arm_sees_centripetal_acceleration():
    # A rig turning on a circle at constant speed; an IMU 0.5 m off the base origin.
    tr = _unperturbed(EllipsePath([0, 0, 0], (2.0, 2.0), 1.0))
    base_T_imu = np.eye(4)
    base_T_imu[:3, 3] = [0.5, 0.0, 0.0]                     # to the right of the path
    t = np.array([1.0, 2.0])
    data, _, _ = simulate_imu(tr, base_T_imu, t)
    # Counter-clockwise turn: the centre is to the left; the IMU's radius is 2.5 m and its
    # speed ω·2.5 with ω = 0.5 rad/s, so it feels v²/r = ω²·2.5 toward the centre (−x).
    np.testing.assert_allclose(data[:, 0], -(0.5**2) * 2.5, atol=1e-9)
    np.testing.assert_allclose(data[:, 5], 0.5, atol=1e-12)  # yaw rate about base z


@pytest.mark.parametrize("radar", ["cascade", "single_chip"])
def test_fast_synthesizer_matches_reference_model(radar):
    calib = preset_radar(radar)
    rng = np.random.default_rng(3)
    k = 300
    p = rng.uniform(-6, 6, (k, 3))
    p[:, 0] = np.abs(p[:, 0]) + 0.5
    v = rng.normal(0, 1.5, (k, 3))
    a = rng.uniform(1, 200, k) * np.exp(1j * rng.uniform(-np.pi, np.pi, k))
    for sign in (1.0, -1.0):
        ref = synthesize_adc(calib, p, v, a, azimuth_sign=sign)
        fast = synthesize_adc(calib, p, v, a, azimuth_sign=sign, precision="single", block=97)
        assert fast.dtype == np.complex64 and fast.shape == calib.frame_shape
        assert np.abs(fast - ref).max() <= 2e-5 * np.abs(ref).max()


def _brute_force_cast(o, d, rects):
    best, idx = np.inf, -1
    for m in range(rects.count):
        c, u, v, n = (getattr(rects, f)[0, m] for f in ("center", "u", "v", "normal"))
        hu, hv = rects.half_size[0, m]
        den = float(d @ n)
        if abs(den) < 1e-12:
            continue
        t = float((c - o) @ n) / den
        q = o + t * d - c
        if t > 1e-6 and abs(q @ u) <= hu and abs(q @ v) <= hv and t < best:
            best, idx = t, m
    return best, idx


def test_ray_caster_agrees_with_a_loop_over_rays_and_rectangles():
    scene = builtin_scene("corridor")
    rects = scene.static_rect_arrays
    rng = np.random.default_rng(0)
    o = np.array([0.3, -0.2, 1.1])
    d = rng.normal(size=(400, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    dist, idx = cast_rays(o[None, None, :], d[None], rects, block=64)
    for i in range(0, 400, 7):
        b, m = _brute_force_cast(o, d[i], rects)
        assert idx[0, i] == m
        assert dist[0, i] == pytest.approx(b, rel=1e-12)
    # Inside a closed corridor every ray hits something.
    assert np.all(np.isfinite(dist))


@pytest.mark.parametrize("spread", [0.0, 0.3])
def test_sector_ray_casting_equals_testing_every_rectangle(spread):
    rng = np.random.default_rng(1)
    # Random rectangles all around, some under and over the origins (floors, ceilings).
    m = 60
    c = rng.uniform(-6, 6, (m, 3))
    u = rng.normal(size=(m, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(u, rng.normal(size=(m, 3)))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    rects = RectArrays(c[None], u[None], v[None], np.cross(u, v)[None],
                       rng.uniform(0.1, 3, (1, m, 2)), np.ones(m), -np.ones(m, np.int64))
    n = 5000
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.array([0.2, -0.1, 0.3]) + rng.uniform(-spread, spread, (n, 3))
    d1, i1 = cast_rays(o[None], d[None], rects, method="dense")
    d2, i2 = cast_rays(o[None], d[None], rects, method="sectors")
    np.testing.assert_array_equal(i1, i2)
    np.testing.assert_allclose(d1, d2, rtol=1e-12)
    assert np.isfinite(d1).mean() > 0.3


def test_coupling_term_is_what_coupling_calib_holds():
    for radar in ("cascade", "single_chip"):
        calib = preset_radar(radar)
        model = RADAR_MODELS[radar]
        adc, cc = make_coupling(calib, model, np.random.default_rng(1))
        empty = RadarTargets(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, complex),
                             np.zeros(0, np.int64))
        frame = radar_frame(calib, RadarModel_noiseless(model), empty, channel_errors=None,
                            coupling_adc=adc, rng=np.random.default_rng(0))
        # Defined as np.fft.fft over samples, averaged over chirps, first num_range_bins bins.
        spec = np.fft.fft(frame, axis=-1).mean(axis=2)[..., :calib.heatmap.num_range_bins]
        assert cc.data.shape == (calib.waveform.num_tx, calib.waveform.num_rx,
                                 calib.heatmap.num_range_bins)
        np.testing.assert_allclose(spec, cc.data, rtol=0, atol=1e-3 * np.abs(cc.data).max())
        # Leakage sits near zero range: most of its energy in the first few bins.
        energy = np.abs(cc.data) ** 2
        assert energy[..., :8].sum() > 0.9 * energy.sum()


def RadarModel_noiseless(model):
    from dataclasses import replace
    return replace(model, noise_std=0.0)


def test_channel_errors_are_undone_by_the_design_calibration_formula():
    calib = preset_radar("cascade")
    pf = make_channel_errors(calib, np.random.default_rng(5))
    assert np.all((pf.frequency > 50.8) & (pf.frequency < 51.5))
    amp = np.abs(pf.phase)
    # Gain mismatch as in the real file (amplitudes spread ~7x, nearly a TX gain x an RX gain).
    assert 6.0 < amp.max() / amp.min() < 8.0
    sv = np.linalg.svd(np.log(amp) - np.log(amp).mean(), compute_uv=False)
    assert sv[2] < 0.5 * sv[0]
    assert pf.slope == calib.waveform.slope and pf.sample_rate == calib.waveform.sample_rate
    targets = RadarTargets(np.array([[3.0, 0.8, 0.3]]), np.array([[0.4, 0.0, 0.0]]),
                           np.array([500.0 + 0j]), np.array([0]))
    model = RadarModel_noiseless(RADAR_MODELS["cascade"])
    g = np.random.default_rng(0)
    clean = radar_frame(calib, model, targets, channel_errors=None, coupling_adc=None, rng=g)
    bad = radar_frame(calib, model, targets, channel_errors=pf, coupling_adc=None, rng=g)
    assert np.abs(bad - clean).max() > 0.5 * np.abs(clean).max()
    # docs/conventions.md §2, written out: A·exp(−j2π(f−f00)·(S/S_cal)(fs_cal/fs)·n/Ns)·P00/P.
    ns = calib.waveform.num_samples
    n = np.arange(ns)
    df = (pf.frequency - pf.frequency[0, 0]) * (calib.waveform.slope / pf.slope) \
        * (pf.sample_rate / calib.waveform.sample_rate)
    fixed = (bad * np.exp(-2j * np.pi * df[:, :, None, None] * n / ns)
             * (pf.phase[0, 0] / pf.phase)[:, :, None, None])
    np.testing.assert_allclose(fixed, clean, atol=1e-4 * np.abs(clean).max())


def test_noise_enters_before_the_receive_gain():
    """Receiver noise is scaled by the RX part of a channel's gain, not by the TX power: after
    the calibration (÷ the whole gain) channel (t, r) carries noise power 2σ²/a_t²."""
    from coloradar.sim import tx_gains

    calib = preset_radar("cascade")
    pf = make_channel_errors(calib, np.random.default_rng(7))
    model = RADAR_MODELS["cascade"]
    empty = RadarTargets(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, complex),
                         np.zeros(0, np.int64))
    frame = radar_frame(calib, model, empty, channel_errors=pf, coupling_adc=None,
                        rng=np.random.default_rng(1))
    # Undo the errors with the calibration formula (apply_channel_errors' inverse).
    n = np.arange(calib.waveform.num_samples)
    undo = (np.exp(-2j * np.pi * pf.relative_frequency()[:, :, None] * n / n.size)
            * pf.relative_phase()[:, :, None])
    fixed = frame * undo[:, :, None, :]
    power = np.mean(np.abs(fixed) ** 2, axis=(2, 3))                      # (tx, rx)
    a = np.exp(np.log(np.abs(1.0 / pf.relative_phase())).mean(axis=1))
    a = a / np.exp(np.log(a).mean())
    np.testing.assert_allclose(tx_gains(pf), a, rtol=1e-9)
    expected = 2.0 * model.noise_std**2 / a[:, None] ** 2
    # 4096 samples per channel: 1.6 % standard error; 192 channels stay within 4.5 sigma
    np.testing.assert_allclose(power / np.broadcast_to(expected, power.shape), 1.0, atol=0.075)
    assert abs(np.mean(power / expected) - 1.0) < 0.01
    assert np.ptp(np.log(a)) > np.log(2.0)           # the TX gains do differ


def test_onboard_points_sit_on_truth_targets():
    calib = preset_radar("single_chip")
    model = RADAR_MODELS["single_chip"]
    rng = np.random.default_rng(2)
    k = 40
    r = rng.uniform(1, 12, k)
    az = rng.uniform(-1, 1, k)
    el = rng.uniform(-0.3, 0.3, k)
    pos = r[:, None] * np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az),
                                        np.sin(el)])
    vel = rng.normal(0, 0.8, (k, 3))
    t = RadarTargets(pos, vel, np.full(k, 300.0 + 0j), np.arange(k))
    pts = onboard_pointcloud(calib, model, t, rng)
    assert pts.dtype == np.float32 and pts.shape[1] == 5 and len(pts) > 0.8 * k
    w = calib.waveform
    for p in pts:
        d = np.linalg.norm(pos - p[:3], axis=1)
        j = np.argmin(d)
        # Range at its bin centre; angle errors of a few degrees at most.
        assert abs(np.linalg.norm(p[:3]) - r[j]) <= 0.5 * w.range_bin_width + 1e-6
        assert d[j] < 0.05 * r[j] + 0.1
        # Range rate: the truth's, quantised to the Doppler bin and aliased.
        rr = t.range_rate[j]
        alias = (rr + w.max_velocity) % (2 * w.max_velocity) - w.max_velocity
        err = (p[4] - alias + w.max_velocity) % (2 * w.max_velocity) - w.max_velocity
        assert abs(err) <= 0.5 * w.velocity_bin_width + 1e-5


@pytest.mark.parametrize("name", list(SCENES))
def test_builtin_scenes_round_trip_through_their_file_format(name, tmp_path):
    scene = builtin_scene(name)
    f = tmp_path / f"{name}.json"
    f.write_text(scene.to_json())
    again = load_scene(f)
    a, b = scene.static_scatterers, again.static_scatterers
    np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(a.strength, b.strength)
    np.testing.assert_array_equal(a.phase, b.phase)
    s1 = scene.object_scatterers(2.5)
    s2 = again.object_scatterers(2.5)
    np.testing.assert_allclose(s1.position, s2.position, atol=1e-12)
    assert len(scene.objects) >= 1 and len(a) > 500


def test_bad_scene_files_name_the_file_and_the_entry(tmp_path):
    f = tmp_path / "bad.json"
    d = builtin_scene_dict("corridor")
    d["boxes"][1]["size"] = [1.0, -1.0, 2.0]
    f.write_text(json.dumps(d))
    with pytest.raises(ColoradarError, match=r"bad\.json.*boxes\[1\]"):
        load_scene(f)
    f.write_text("{not json")
    with pytest.raises(ColoradarError, match="not valid JSON"):
        load_scene(f)
    with pytest.raises(ColoradarError, match="rig_path"):
        scene_from_dict({"name": "x"}, "inline")


def test_moving_person_scatterers_move_with_their_path():
    scene = builtin_scene("corridor")
    person = scene.objects[0]
    t = np.array([1.0, 1.0 + H, 1.0 - H])
    s = person.scatterers(t)
    fd = (s.position[1] - s.position[2]) / (2 * H)
    np.testing.assert_allclose(fd, s.velocity[0], atol=1e-6)
    # Limbs swing (micro-Doppler): their velocities differ from the torso's.
    spread = np.linalg.norm(s.velocity[0] - s.velocity[0, 0], axis=1)
    assert spread.max() > 0.5


@pytest.mark.parametrize("precision", ["double", "single"])
def test_if_model_against_a_loop_over_the_documented_formula(precision):
    """Each (TX, RX, chirp) built with explicit loops from the formula of docs/conventions.md §3:
    exp(+j2π((f0 + S·t_n)·τ0 + f_c·(τ − τ0))), τ = (2(R + vr·T) − u·p_tx − u·p_rx)/c,
    T = (c·Ntx + t)·(idle + ramp_end)."""
    from coloradar.calib.waveform import SPEED_OF_LIGHT as C0

    calib = preset_radar("single_chip")
    w, ant = calib.waveform, calib.antenna
    pos = np.array([[3.0, 1.2, -0.4], [5.5, -2.0, 0.8]])
    vel = np.array([[0.7, -0.2, 0.1], [-1.1, 0.4, 0.0]])
    amp = np.array([400.0, 900.0 * np.exp(0.5j)])
    got = synthesize_adc(calib, pos, vel, amp, precision=precision)
    t_n = w.adc_start_time + np.arange(w.num_samples) / w.sample_rate
    want = np.zeros(calib.frame_shape, dtype=np.complex128)
    hw = C0 / (2 * ant.design_frequency)
    for p, v, a in zip(pos, vel, amp, strict=True):
        r = np.linalg.norm(p)
        u = p / r
        vr = u @ v
        tau0 = 2 * r / C0
        for t in range(w.num_tx):
            p_tx = np.array([0.0, *ant.tx_positions[t]]) * hw
            for x in range(w.num_rx):
                p_rx = np.array([0.0, *ant.rx_positions[x]]) * hw
                for c in range(w.num_chirps):
                    big_t = (c * w.num_tx + t) * (w.idle_time + w.ramp_end_time)
                    tau = (2 * (r + vr * big_t) - u @ p_tx - u @ p_rx) / C0
                    phase = (w.start_frequency + w.slope * t_n) * tau0 + w.center_frequency * (tau - tau0)
                    want[t, x, c] += a / r**2 * np.exp(2j * np.pi * phase)
    assert np.abs(got - want).max() <= 3e-5 * np.abs(want).max()
