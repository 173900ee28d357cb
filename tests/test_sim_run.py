"""A simulated run, read back with the dataset API and checked against physics and the truth."""

from __future__ import annotations

import hashlib
import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import coloradar as cr
from coloradar.calib import load_calibration
from coloradar.errors import ColoradarError, OutputExistsError
from coloradar.sim.imu import GRAVITY
from coloradar.sim.lidar import LidarModel, column_times, simulate_scan
from coloradar.sim.run import RATES, open_simulation, simulate_run
from coloradar.sim.truth import load_truth

DURATION = 1.6


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    res = simulate_run(out, scene="corridor", duration=DURATION, seed=4, motion="handheld",
                       vicon=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # a simulated run must open without warnings
        seq = cr.open_sequence(res.run_path)
    return res, seq


def test_run_layout_name_and_calibration(run):
    res, _seq = run
    assert res.run_path.name == "11_21_2026_sim_corridor_run4"
    assert (res.calib_path / "cascade" / "phase_frequency_calib.txt").is_file()
    for radar in ("cascade", "single_chip"):
        assert (res.calib_path / radar / "coupling_calib.txt").is_file()
    calib = load_calibration(res.calib_path)
    # The files hold the simulated board's own calibration, read back without complaint.
    assert calib.cascade.phase_frequency is not None
    assert calib.single_chip.coupling.missing_tx == ()
    assert calib.cascade.frame_shape == (12, 16, 16, 256)
    assert not any(p.name.startswith(".") for p in res.run_path.parent.iterdir())


def test_every_stream_has_its_count_rate_and_shape(run):
    res, seq = run
    expected = {"cascade/adc", "single_chip/adc", "single_chip/pointclouds",
                "lidar/pointclouds", "imu", "groundtruth", "vicon"}
    if res.heatmaps:
        expected |= {"cascade/heatmaps", "single_chip/heatmaps"}
    assert set(seq.available()) == expected
    gt = seq.groundtruth
    span = (gt.timestamps[0], gt.timestamps[-1])
    assert span[1] - span[0] >= DURATION - 1e-6
    streams = {
        "cascade/adc": (seq.cascade.adc, RATES["cascade"], seq.calib.cascade.frame_shape),
        "single_chip/adc": (seq.single_chip.adc, RATES["single_chip"],
                            seq.calib.single_chip.frame_shape),
        "lidar/pointclouds": (seq.lidar.pointclouds, RATES["lidar"], (65536, 4)),
    }
    if res.heatmaps:
        streams["cascade/heatmaps"] = (seq.cascade.heatmaps, 5.0,
                                       (*seq.calib.cascade.heatmap_shape, 2))
    firsts = []
    for key, (stream, rate, shape) in streams.items():
        n = len(stream)
        assert n == res.counts[key]
        # Every full frame period that fits in the run, from the stream's own start offset.
        assert int(DURATION * rate) - 1 <= n <= int(DURATION * rate) + 1
        np.testing.assert_array_equal(stream.frame_ids, np.arange(n))
        dt = np.diff(stream.timestamps)
        assert np.all(np.abs(dt - 1 / rate) < 0.01 / rate + 6e-3)
        assert span[0] <= stream.timestamps[0] and stream.timestamps[-1] <= span[1]
        assert stream[0].shape == shape and stream[n - 1].shape == shape
        if "heatmaps" not in key:               # heatmaps share their ADC frames' stamps
            firsts.append(stream.timestamps[0])
    assert seq.cascade.adc[0].dtype == np.complex64
    pcs = seq.single_chip.pointclouds
    assert len(pcs) == len(seq.single_chip.adc)
    np.testing.assert_array_equal(pcs.timestamps, seq.single_chip.adc.timestamps)
    assert pcs[0].ndim == 2 and pcs[0].shape[1] == 5 and len(pcs[0]) > 3
    imu = seq.imu
    assert imu.data.shape == (len(imu.timestamps), 6)
    assert abs(np.median(np.diff(imu.timestamps)) - 1 / 300) < 1e-5
    assert abs(len(imu.timestamps) - 300 * DURATION) <= 2
    assert abs(np.median(np.diff(gt.timestamps)) - 0.1) < 1e-6   # float64 Unix time: ~0.2 µs
    np.testing.assert_array_equal(gt.poses[0], [0, 0, 0, 0, 0, 0, 1])
    assert seq.vicon is not None and len(seq.vicon.timestamps) == res.counts["vicon"]
    # Streams are not aligned with one another.
    firsts.append(imu.timestamps[0])
    assert len(np.unique(np.round(firsts, 6))) == len(firsts)


def test_lidar_points_lie_on_the_scene_surfaces(run):
    res, seq = run
    sim = open_simulation(res.run_path)
    scan = seq.lidar.pointclouds[3]
    t_scan = sim.run_time(seq.lidar.pointclouds.timestamps[3])
    model = LidarModel()
    hit = np.any(scan[:, :3] != 0, axis=1)
    assert 0.6 < hit.mean() <= 1.0            # closed corridor: most beams return
    world = _scan_to_world(sim, scan, t_scan, res, model)
    d = _distance_to_surfaces(sim.scene, world[hit], _column_of(hit, model, t_scan))
    # Range noise σ = 1.5 cm along the ray; geometry itself exact.
    assert np.median(d) < 0.02 and np.quantile(d, 0.99) < 0.07
    # Noise-free: every return exactly on a surface.
    clean = simulate_scan(sim.scene, sim.trajectory, seq.calib.transforms["lidar"].matrix(),
                          t_scan, model, rng=None)
    hit_c = np.any(clean[:, :3] != 0, axis=1)
    w_c = _scan_to_world(sim, clean, t_scan, res, model)
    assert _distance_to_surfaces(sim.scene, w_c[hit_c], _column_of(hit_c, model, t_scan)).max() < 1e-6


def _column_of(mask, model, t_scan):
    cols = np.tile(np.arange(model.columns), model.beams)
    return column_times(model, t_scan)[cols[mask]]


def _scan_to_world(sim, scan, t_scan, res, model):
    """Each point through the lidar pose at its own column's firing time."""
    calib = load_calibration(res.calib_path)
    b_T_l = calib.transforms["lidar"].matrix()
    times = column_times(model, t_scan)
    st = sim.trajectory.state(times)
    cols = np.tile(np.arange(model.columns), model.beams)
    r = st.rotation.as_matrix()[cols] @ b_T_l[:3, :3]
    o = st.position[cols] + st.rotation[cols].apply(b_T_l[:3, 3])
    return np.einsum("nij,nj->ni", r, scan[:, :3].astype(np.float64)) + o


def _distance_to_surfaces(scene, pts, times):
    """Brute force: distance of every point to the nearest rectangle, objects at each time."""
    best = np.full(len(pts), np.inf)
    uniq, inv = np.unique(times, return_inverse=True)
    rects_t = scene.rect_arrays(uniq)
    for m in range(rects_t.count):
        g = inv if rects_t.center.shape[0] > 1 else np.zeros(len(pts), int)
        c = rects_t.center[g, m]
        q = pts - c
        a = np.einsum("ij,ij->i", q, rects_t.u[g, m])
        b = np.einsum("ij,ij->i", q, rects_t.v[g, m])
        n = np.einsum("ij,ij->i", q, rects_t.normal[g, m])
        h = rects_t.half_size[g, m]
        da = np.maximum(np.abs(a) - h[:, 0], 0)
        db = np.maximum(np.abs(b) - h[:, 1], 0)
        best = np.minimum(best, np.sqrt(da**2 + db**2 + n**2))
    return best


def test_imu_integrates_back_to_the_ground_truth(run):
    res, seq = run
    truth = load_truth(res.run_path)
    calib = seq.calib
    b_T_i = calib.transforms["imu"].matrix()
    r_bi = Rotation.from_matrix(b_T_i[:3, :3])
    w_T_s = truth["world_T_start"]
    r_ws = Rotation.from_matrix(w_T_s[:3, :3])
    gt_t, gt_p = seq.groundtruth.timestamps, seq.groundtruth.poses
    k0, k1 = 3, 13                                                  # a 1 s window
    imu_t, imu = seq.imu.timestamps, seq.imu.data
    grid = np.linspace(gt_t[k0], gt_t[k1], 601)
    f = np.column_stack([np.interp(grid, imu_t, imu[:, j]) for j in range(6)])
    # Initial state from the ground truth (pose) and the truth file (velocity).
    rot = r_ws * Rotation.from_quat(gt_p[k0, 3:]) * r_bi              # world_R_imu
    pos = w_T_s[:3, :3] @ gt_p[k0, :3] + w_T_s[:3, 3] + rot.apply(-r_bi.inv().apply(b_T_i[:3, 3]))
    vel = truth["rig_velocity_world"][k0].copy()
    dt = np.diff(grid)
    for i in range(len(dt)):
        a0 = rot.apply(f[i, :3]) + GRAVITY
        rot = rot * Rotation.from_rotvec(0.5 * (f[i, 3:] + f[i + 1, 3:]) * dt[i])
        a1 = rot.apply(f[i + 1, :3]) + GRAVITY
        pos = pos + vel * dt[i] + (2 * a0 + a1) / 6 * dt[i] ** 2
        vel = vel + 0.5 * (a0 + a1) * dt[i]
    r_true = r_ws * Rotation.from_quat(gt_p[k1, 3:])
    p_true = w_T_s[:3, :3] @ gt_p[k1, :3] + w_T_s[:3, 3]
    base_pos = pos - (rot * r_bi.inv()).apply(b_T_i[:3, 3])
    # Bias 0.02 m/s² → ~1 cm in 1 s; without gravity this would be off by ~5 m.
    assert np.linalg.norm(base_pos - p_true) < 0.05
    ang = (r_true.inv() * rot * r_bi.inv()).magnitude()
    assert np.degrees(ang) < 0.5
    np.testing.assert_allclose(vel, truth["rig_velocity_world"][k1], atol=0.08)


def test_truth_matches_the_run_geometry(run):
    res, seq = run
    truth = load_truth(res.run_path)
    sim = open_simulation(res.run_path)
    for radar in ("cascade", "single_chip"):
        ts = truth.radar_timestamps(radar)
        np.testing.assert_array_equal(ts, seq.radar(radar).adc.timestamps)
        w_T = truth[f"{radar}/world_T_radar"]
        v = truth.radar_velocity(radar)
        for i in (0, len(ts) - 1):
            tg = truth.targets(radar, i)
            static = tg["ident"] < len(truth["static_position"])
            assert static.sum() > 100
            world = tg["position"][static] @ w_T[i, :3, :3].T + w_T[i, :3, 3]
            np.testing.assert_allclose(world, truth["static_position"][tg["ident"][static]],
                                       atol=1e-4)
            # Static scatterers close in at −û·v (docs/conventions.md §3: > 0 receding).
            p = tg["position"][static].astype(np.float64)
            rr = -(p @ v[i]) / np.linalg.norm(p, axis=1)
            np.testing.assert_allclose(tg["range_rate"][static], rr, atol=1e-4)
        # The radar's velocity in its own frame, against finite differences of its pose.
        t = sim.run_time(ts[1])
        calib = seq.calib
        b_T_r = calib.transforms[radar].matrix()
        st = sim.trajectory.state(np.array([t - 1e-4, t + 1e-4]))
        o = st.position + st.rotation.apply(b_T_r[:3, 3])
        r_wr = Rotation.from_matrix(w_T[1, :3, :3])
        np.testing.assert_allclose(r_wr.inv().apply((o[1] - o[0]) / 2e-4), v[1], atol=1e-5)
    # Moving objects are in the truth and seen by the radars.
    assert truth["object_position"].shape == (1, len(seq.groundtruth.timestamps), 3)
    seen = np.concatenate([truth["cascade/target_ident"], truth["single_chip/target_ident"]])
    assert np.any(seen >= truth["object_ident_offset"][0])


def test_radar_frames_are_int16_quantised_and_unclipped(run):
    _res, seq = run
    for radar in ("cascade", "single_chip"):
        a = seq.radar(radar).adc[1]
        assert np.all(a.real == np.round(a.real)) and np.abs(a.real).max() < 32767
        # Thermal noise is present: the last range bins are not empty.
        spec = np.fft.fft(a, axis=-1)
        assert np.abs(spec[..., -8:]).mean() > 0


def test_simulation_is_deterministic_and_never_overwrites(tmp_path):
    kw = dict(scene="mine", duration=0.45, seed=11, sensors=("cascade", "lidar", "imu"))
    a = simulate_run(tmp_path / "a", **kw)
    b = simulate_run(tmp_path / "b", workers=1, **kw)

    def digest(root):
        return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
                for p in sorted(root.rglob("*")) if p.is_file() and p.suffix != ".json"}

    assert digest(a.run_path) == digest(b.run_path)
    assert digest(a.calib_path) == digest(b.calib_path)
    c = simulate_run(tmp_path / "a", **{**kw, "seed": 12})      # shares the calib folder
    fa = (a.run_path / "cascade/adc_samples/data/frame_0.bin").read_bytes()
    fc = (c.run_path / "cascade/adc_samples/data/frame_0.bin").read_bytes()
    assert fa != fc
    with pytest.raises(OutputExistsError, match="overwrite"):
        simulate_run(tmp_path / "a", **kw)
    again = simulate_run(tmp_path / "a", overwrite=True, **kw)
    assert digest(again.run_path) == digest(a.run_path)
    other = tmp_path / "a" / "11_21_2026_sim_mine_run99"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(OutputExistsError, match="not a simulated run"):
        simulate_run(tmp_path / "a", **{**kw, "seed": 99}, overwrite=True)
    assert (other / "notes.txt").read_text() == "mine"


def test_bad_arguments_are_coloradar_errors(tmp_path):
    with pytest.raises(ColoradarError, match="unknown scene"):
        simulate_run(tmp_path, scene="moon", duration=0.2)
    with pytest.raises(ColoradarError, match="unknown sensor"):
        simulate_run(tmp_path, sensors=("radar",), duration=0.2)
    with pytest.raises(ColoradarError, match="motion"):
        simulate_run(tmp_path, motion="wild", duration=0.2)


def test_a_real_calib_folder_is_never_replaced(tmp_path):
    """--overwrite replaces the simulator's own output, never a calibration it did not write."""
    from coloradar.calib import preset_calibration, write_calibration
    from coloradar.errors import OutputExistsError
    from coloradar.sim import simulate_run

    write_calibration(preset_calibration(), tmp_path / "calib")  # stands for a real rig's calib
    before = {p: p.read_bytes() for p in (tmp_path / "calib").rglob("*") if p.is_file()}
    with pytest.raises(OutputExistsError, match="did not write"):
        simulate_run(tmp_path, duration=0.5, sensors=["imu"], overwrite=True)
    assert {p: p.read_bytes() for p in (tmp_path / "calib").rglob("*") if p.is_file()} == before
    # The simulator's own calib folder may be replaced when asked.
    simulate_run(tmp_path / "sim", duration=0.5, sensors=["imu"])
    simulate_run(tmp_path / "sim", duration=0.5, sensors=["imu"], seed=3, board_seed=7,
                 overwrite=True)
