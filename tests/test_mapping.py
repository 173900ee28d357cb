"""coloradar.mapping: the log-odds map, the inverse sensor models, the ROS grid files, the scores
and ``coloradar map`` / ``map-score`` on tiny synthetic scenes (each reference is written here:
the OctoMap update, Gaussian integrals, the map_server format as documented)."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

import coloradar as cr
from _synth import write_run
from coloradar.calib import HeatmapConfig
from coloradar.cli.main import main
from coloradar.mapping import (
    FREE,
    OCCUPIED,
    UNKNOWN,
    HeatmapModel,
    OccupancyJob,
    OccupancyMap,
    OccupancySettings,
    PointSensorModel,
    build_occupancy_map,
    grid_iou,
    heatmap_evidence,
    map_quality,
    occupancy_grid,
    point_evidence,
    write_map_server,
)
from coloradar.mapping.sensor_model import _spread
from coloradar.mapping.voxels import keys_to_indices, voxel_keys

DEG = math.pi / 180
MODEL = PointSensorModel(range_std=0.06, azimuth_resolution=0.25, elevation_resolution=1.0,
                         snr_db=20.0)


def _logit(p):
    return math.log(p / (1 - p))


def test_log_odds_update_and_clamping_follow_octomap():
    s = OccupancySettings()
    m = OccupancyMap(s)
    key = voxel_keys(np.array([[1.0, 2.0, 3.0]]), s.voxel)
    for _ in range(3):
        m.integrate(key, np.array([0.4], np.float32))
    assert m.logodds()[0] == pytest.approx(1.2, abs=1e-6)
    assert m.probability()[0] == pytest.approx(1 / (1 + math.exp(-1.2)), abs=1e-6)
    for _ in range(100):                       # clamped at logit(p_max), not beyond
        m.integrate(key, np.array([2.0], np.float32))
    assert m.logodds()[0] == pytest.approx(_logit(s.p_max), abs=1e-6)
    for _ in range(100):
        m.integrate(key, np.array([-2.0], np.float32))
    assert m.logodds()[0] == pytest.approx(_logit(s.p_min), abs=1e-6)
    hits, misses = m.counts()
    assert (hits[0], misses[0]) == (103, 100) and m.frames == 203
    assert m.state(np.array([[1.0, 2.0, 3.0], [9.0, 9.0, 9.0]])).tolist() == [FREE, UNKNOWN]
    # centre of the voxel holding (1, 2, 3): ((floor(x / v) + 1/2) v)
    np.testing.assert_allclose(m.centers()[0], (np.floor(np.array([1.0, 2.0, 3.0]) / s.voxel)
                                                + 0.5) * s.voxel)


def test_many_frames_of_new_voxels_are_found_again():
    # More new voxels than the side table holds: merged into the main table and still found.
    s = OccupancySettings(voxel=0.1)
    m = OccupancyMap(s)
    rng = np.random.default_rng(0)
    ijk = rng.integers(-500, 500, (60000, 3))
    keys = np.unique(voxel_keys((ijk + 0.5) * s.voxel, s.voxel))
    for part in np.array_split(keys, 7):
        m.integrate(part, np.full(part.size, 0.5, np.float32))
    m.integrate(keys, np.full(keys.size, 0.5, np.float32))
    assert len(m) == keys.size and np.all(m.logodds() == np.float32(1.0))
    np.testing.assert_array_equal(keys_to_indices(m.keys()), keys_to_indices(keys))


def test_a_return_spreads_its_unit_mass_as_a_gaussian():
    # The voxels' masses are samples of the return's Gaussian: they add up to 1 and their mean
    # is the return (the integral of a normal density, written here, not taken from the code).
    c = np.array([[4.0, 1.0, 0.3, 20.0]])
    r = np.linalg.norm(c[:, :3], axis=1)
    model = PointSensorModel(range_std=0.05, azimuth_resolution=0.25, elevation_resolution=0.25,
                             min_azimuth_std=0.5 * DEG, min_elevation_std=0.5 * DEG,
                             snr_db=30.0, max_spread=4)
    keys, mass = _spread(c, r, np.eye(3), np.zeros(3), model, 0.05)
    assert mass.sum() == pytest.approx(1.0, abs=0.03)
    centres = (keys_to_indices(keys) + 0.5) * 0.05
    np.testing.assert_allclose(mass @ centres / mass.sum(), c[0, :3], atol=0.01)


def _wall_frames(rng, ys, x_wall=5.0, n=30, offset=0.0):
    """Frames of a sensor at (0, y, 0) looking along +x at a wall x = x_wall (sensor frame
    points; ``offset`` added to every range)."""
    frames = []
    for y0 in ys:
        yw = rng.uniform(-3, 3, n)
        zw = rng.uniform(-0.4, 0.4, n)
        p = np.column_stack([np.full(n, x_wall), yw - y0, zw])
        p *= (1 + offset / np.linalg.norm(p, axis=1))[:, None]
        frames.append((p, np.array([0.0, y0, 0.0])))
    return frames


def _map(frames, s=None, model=MODEL):
    m = OccupancyMap(s)
    for p, t in frames:
        m.integrate(*point_evidence(p, np.eye(3), t, model, m.settings))
    return m


def test_a_ghost_planted_in_one_frame_leaves_no_occupied_voxel():
    rng = np.random.default_rng(1)
    frames = _wall_frames(rng, np.linspace(-2, 2, 40))
    ghost_in_room = np.array([2.5, 0.5, 0.0])          # in front of the wall (rays cross it)
    ghost_behind = np.array([7.0, -1.0, 0.2])          # behind it (no ray ever reaches it)
    p, t = frames[20]
    cluster = np.vstack([g + rng.normal(0, 0.02, (6, 3)) for g in (ghost_in_room, ghost_behind)])
    frames[20] = (np.vstack([p, cluster - t]), t)      # 12 ghost points, one frame
    m = _map(frames)
    occ = m.occupied()
    assert occ.shape[0] > 50                            # the wall is there
    for g in (ghost_in_room, ghost_behind):
        assert np.min(np.linalg.norm(occ[:, :3] - g, axis=1)) > 0.5
    assert np.all(np.abs(occ[:, 0] - 5.0) < 0.2)
    assert m.state(ghost_in_room[None])[0] == FREE      # carved by the other frames' rays


def test_a_wall_seen_once_from_far_and_often_from_near_is_where_the_near_views_put_it():
    rng = np.random.default_rng(2)
    near = _wall_frames(rng, np.linspace(-1.5, 1.5, 20), n=25)
    far = [(p, t + np.array([-8.0, 0, 0])) for p, t in
           _wall_frames(rng, [0.0], x_wall=13.0, n=60, offset=0.45)]   # 0.45 m too far
    m = _map(near[:10] + far + near[10:])
    occ = m.occupied()
    assert occ.shape[0] > 30
    assert np.all(np.abs(occ[:, 0] - 5.0) < 0.2)        # where the near views put it
    far_wall = np.column_stack([np.full(5, 5.45), np.linspace(-1, 1, 5), np.zeros(5)])
    assert not np.any(m.state(far_wall) == OCCUPIED)


def test_heatmap_cells_become_occupied_free_and_shadow():
    # A 1 x 9 x 40 heatmap (one elevation row) of noise as a heatmap holds it (each cell the
    # peak over 32 Doppler bins of exponential speckle), and one strong target at range bin 20
    # of the middle beam, seen 20 times (a cell is free evidence when it is below the floor:
    # about every other frame).
    nr, na = 40, 9
    cfg = HeatmapConfig(num_range_bins=nr, num_elevation_bins=1, num_azimuth_bins=na,
                        range_bin_width=0.1, azimuth_bins=np.linspace(-0.4, 0.4, na),
                        elevation_bins=np.zeros(1))
    model = HeatmapModel(cfg, MODEL, occupied_db=12.0, stride=1)
    s = OccupancySettings(voxel=0.1)
    m = OccupancyMap(s)
    rng = np.random.default_rng(3)
    for _ in range(20):
        h = rng.exponential(1.0, (32, 1, na, nr)).max(axis=0).astype(np.float32) * 0.5
        h[0, 4, 20] = 1000.0                           # about 27 dB above the floor
        m.integrate(*heatmap_evidence(h, np.eye(3), np.zeros(3), model, s))
    assert m.state(np.array([[2.0, 0.0, 0.0]]))[0] == OCCUPIED       # range 20 · 0.1 m
    assert m.state(np.array([[1.0, 0.0, 0.0]]))[0] == FREE            # in front of it
    assert m.state(np.array([[3.0, 0.0, 0.0]]))[0] == UNKNOWN         # its shadow
    with pytest.raises(cr.FormatError, match="expected a heatmap of shape"):
        heatmap_evidence(np.zeros((2, na, nr)), np.eye(3), np.zeros(3), model, s)


# --- the ROS map_server files, read as the format's documentation says ------------------------

def _read_map_server(yaml_path: Path):
    """A reader written from http://wiki.ros.org/map_server: YAML keys, a P5 PGM (comments
    allowed in the header), ``p = (255 − v)/255`` (or ``v/255`` when negate), occupied above
    occupied_thresh, free below free_thresh, unknown between; row 0 of the image is the top.
    Returns (states with row 0 the lowest y, resolution, origin)."""
    meta = {}
    for line in yaml_path.read_text().splitlines():
        key, _, value = line.partition(":")
        meta[key.strip()] = value.strip()
    for key in ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh"):
        assert key in meta, key
    data = (yaml_path.parent / meta["image"]).read_bytes()
    tokens, pos = [], 0
    while len(tokens) < 4:                         # magic, width, height, maxval
        while data[pos:pos + 1].isspace():
            pos += 1
        if data[pos:pos + 1] == b"#":
            pos = data.index(b"\n", pos) + 1
            continue
        end = pos
        while not data[end:end + 1].isspace():
            end += 1
        tokens.append(data[pos:end].decode())
        pos = end
    assert tokens[0] == "P5" and tokens[3] == "255"
    w, h = int(tokens[1]), int(tokens[2])
    img = np.frombuffer(data[pos + 1:pos + 1 + w * h], np.uint8).reshape(h, w)
    p = img / 255.0 if int(meta["negate"]) else (255 - img) / 255.0
    states = np.full(img.shape, UNKNOWN)
    states[p > float(meta["occupied_thresh"])] = OCCUPIED
    states[p < float(meta["free_thresh"])] = FREE
    origin = [float(v) for v in meta["origin"].strip("[]").split(",")]
    return states[::-1], float(meta["resolution"]), origin


def test_the_grid_files_load_in_a_map_server_reader(tmp_path):
    rng = np.random.default_rng(4)
    m = _map(_wall_frames(rng, np.linspace(-2, 2, 30)))
    grid = occupancy_grid(m, -0.3, 0.3)
    pgm, yaml = write_map_server(grid, tmp_path / "grid.yaml")
    assert pgm == tmp_path / "grid.pgm"
    states, res, origin = _read_map_server(yaml)
    np.testing.assert_array_equal(states, grid.states)
    assert res == pytest.approx(m.voxel) and origin[2] == 0.0
    # every occupied voxel of the band lies over an occupied pixel, found from the origin
    occ = m.occupied()
    band = occ[(occ[:, 2] >= -0.3) & (occ[:, 2] < 0.3)]
    col = np.floor((band[:, 0] - origin[0]) / res + 1e-6).astype(int)
    row = np.floor((band[:, 1] - origin[1]) / res + 1e-6).astype(int)
    assert band.shape[0] > 0 and np.all(states[row, col] == OCCUPIED)
    # the free pixels are in front of the wall
    _, i = np.nonzero(states == FREE)
    assert np.all(origin[0] + (i + 0.5) * res < 5.0)


def test_a_grid_of_one_frame_spans_what_the_sensor_looked_at():
    # One frame decides nothing (no voxel occupied or free yet), but the grid covers the
    # rays' extent: from the sensor at the origin to the wall 5 m ahead, 6 m wide.
    rng = np.random.default_rng(6)
    m = _map(_wall_frames(rng, [0.0], n=60))
    assert m.occupied().shape[0] == 0
    grid = occupancy_grid(m, -0.3, 0.3, margin=0)
    assert grid.counts()["occupied"] == grid.counts()["free"] == 0
    x0, y0 = grid.origin
    ny, nx = grid.states.shape
    assert x0 <= 0.15 and x0 + nx * m.voxel >= 5.0
    assert y0 <= -2.5 and y0 + ny * m.voxel >= 2.5


def test_grid_iou_and_map_quality_against_hand_counts():
    s = OccupancySettings(voxel=1.0, min_hits=1)
    a, b = OccupancyMap(s), OccupancyMap(s)
    pts_a = np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [2.5, 0.5, 0.5], [3.5, 0.5, 0.5]])
    pts_b = np.array([[1.5, 0.5, 0.5], [2.5, 0.5, 0.5], [5.5, 0.5, 0.5]])
    a.integrate(voxel_keys(pts_a, 1.0), np.full(4, 3.0, np.float32))
    b.integrate(voxel_keys(pts_b, 1.0), np.full(3, 3.0, np.float32))
    ga, gb = occupancy_grid(a, 0, 1), occupancy_grid(b, 0, 1)
    # occupied {0,1,2,3} and {1,2,5}: 2 in common, 5 in the union; a never saw cell 5
    assert grid_iou(ga, gb, observed_only=False) == pytest.approx(2 / 5)
    assert grid_iou(ga, gb) == pytest.approx(2 / 4)
    q = map_quality(pts_a, pts_b, (0.1, 1.5))
    assert q.precision == pytest.approx((0.5, 1.0)) and q.completeness[0] == pytest.approx(2 / 3)
    assert q.f_score[0] == pytest.approx(2 * 0.5 * (2 / 3) / (0.5 + 2 / 3))
    assert map_quality(pts_a, pts_b, (0.1,), observed=a).num_reference == 2


def test_the_map_file_round_trips_and_a_bad_one_is_named(tmp_path):
    rng = np.random.default_rng(5)
    m = _map(_wall_frames(rng, np.linspace(-1, 1, 10)))
    m.save(tmp_path / "o.npz")
    back = OccupancyMap.load(tmp_path / "o.npz")
    np.testing.assert_array_equal(back.keys(), m.keys())
    np.testing.assert_array_equal(back.logodds(), m.logodds())
    assert back.settings == m.settings and back.frames == m.frames
    (tmp_path / "bad.npz").write_bytes(b"not a map")
    with pytest.raises(cr.FormatError, match=r"bad\.npz: expected an occupancy map"):
        OccupancyMap.load(tmp_path / "bad.npz")


# --- the command line ---------------------------------------------------------------------------

RUN = "12_21_2020_ec_hallways_run0"


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("maprun")
    write_run(root, n_single=12, n_gt=20, n_lidar=3)
    return root


def _cli(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return code, out, err


def test_map_without_ground_truth_says_what_it_needs_and_works_with_poses(small_run, tmp_path,
                                                                           capsys):
    run = tmp_path / "data" / RUN
    shutil.copytree(small_run / RUN, run)
    shutil.copytree(small_run / "calib", tmp_path / "data" / "calib")
    gt_t = np.loadtxt(run / "groundtruth" / "timestamps.txt")
    shutil.rmtree(run / "groundtruth")
    code, _, err = _cli(["map", run, "--out", tmp_path / "m"], capsys)
    assert code == 1 and "no ground truth" in err and "--poses FILE.txt" in err
    assert not (tmp_path / "m").exists()
    tum = tmp_path / "poses.txt"
    tum.write_text("".join(f"{t:.6f} {0.1 * k:.3f} 0 0 0 0 0 1\n" for k, t in enumerate(gt_t)))
    code, out, err = _cli(["map", run, "--out", tmp_path / "m", "--poses", tum], capsys)
    assert code == 0, err
    for name in ("map.ply", "occupancy.npz", "grid.pgm", "grid.yaml", "poses.txt", "map.json"):
        assert (tmp_path / "m" / name).is_file(), name
    info = json.loads((tmp_path / "m" / "map.json").read_text())
    assert info["poses"] == str(tum) and info["sensor"] == "single_chip"
    assert info["job"]["static_gate"]["direction_std_deg"] == 3.0      # the static test, on
    code, _, err = _cli(["map", run, "--out", tmp_path / "mk", "--poses", tum, "--keep-movers",
                         "--quiet"], capsys)
    assert code == 0, err
    assert json.loads((tmp_path / "mk" / "map.json").read_text())["job"]["static_gate"] is None
    code, _, err = _cli(["map", run, "--out", tmp_path / "m", "--poses", tum], capsys)
    assert code == 1 and "--overwrite" in err                      # never overwritten unasked
    code, _, err = _cli(["map", run, "--out", tmp_path / "m2", "--poses", tmp_path / "nope"],
                        capsys)
    assert code == 1 and "nope: no such file" in err
    # the same poses in a slam-like folder
    (tmp_path / "slamdir").mkdir()
    shutil.copy(tum, tmp_path / "slamdir" / "trajectory.txt")
    code, _, err = _cli(["map", run, "--out", tmp_path / "m3", "--poses", tmp_path / "slamdir",
                         "--source", "heatmaps", "--quiet"], capsys)
    assert code == 0, err
    code, out, _ = _cli(["map-score", tmp_path / "m3", "--reference", tmp_path / "m" / "map.ply",
                         "--json"], capsys)
    assert code == 0 and json.loads(out)["quality"]["thresholds"] == [0.1, 0.3]


def test_map_refuses_a_source_with_a_point_file_name(small_run, tmp_path, capsys):
    code, _, err = _cli(["map", small_run / RUN, "--out", tmp_path / "m.ply", "--source",
                         "points"], capsys)
    assert code == 1 and "folder name" in err


def test_build_tests_every_mapped_radar_frame_and_not_the_lidar(small_run):
    from coloradar.geometry import rig_velocity, trajectory_from_groundtruth
    from coloradar.mapping import StaticTest

    seq = cr.open_sequence(small_run / RUN)
    gt = trajectory_from_groundtruth(seq)
    res = build_occupancy_map(seq, gt, OccupancyJob(sensor="single_chip"))
    assert res.static_test is not None
    assert res.static_test["frames"] == res.frame_indices.size > 0
    assert res.static_test["points"] > 0
    # Frame by frame, each cloud with the velocity at its own stamp, counted again here.
    test = StaticTest.for_radar(seq.calib.single_chip)
    for i, t in zip(res.frame_indices, res.timestamps, strict=True):
        v = rig_velocity(gt, np.array([t]), calib=seq.calib, sensor="single_chip").linear[0]
        test(seq.single_chip.pointclouds[int(i)], v)
    assert test.summary() == {k: res.static_test[k] for k in test.summary()}
    off = build_occupancy_map(seq, gt, OccupancyJob(sensor="single_chip", static_gate=None))
    assert off.static_test is None
    assert build_occupancy_map(seq, gt, OccupancyJob(sensor="lidar")).static_test is None


def test_the_angle_floor_follows_each_radars_aperture():
    """TI's MMWCAS cascade spans 86 distinct azimuth positions of half a wavelength (a beam of
    asin(2/86) = 1.33°), the AWR1843 8 (14.5°): the cascade's floor is 0.4 of its beam, the
    single chip keeps the caps, and a job's explicit floor wins."""
    from coloradar.calib import preset_calibration
    from coloradar.mapping import angle_std_floor, radar_sensor_model
    from coloradar.mapping.build import _floors

    calib = preset_calibration()
    casc = radar_sensor_model(calib.radar("cascade"))
    assert casc.min_azimuth_std == pytest.approx(0.4 * math.asin(2 / 86))
    assert math.degrees(casc.min_azimuth_std) == pytest.approx(0.533, abs=1e-3)
    assert casc.min_elevation_std == pytest.approx(2 * DEG)        # 4 rows: 0.4·30° > cap
    chip = radar_sensor_model(calib.radar("single_chip"))
    assert (chip.min_azimuth_std, chip.min_elevation_std) == pytest.approx((1 * DEG, 2 * DEG))
    assert angle_std_floor(2.0, 1 * DEG) == pytest.approx(1 * DEG)  # a sine past 1 is capped
    job = OccupancyJob(sensor="cascade", min_azimuth_std_deg=0.25)
    f = _floors(job)
    assert f["min_azimuth_std"] == pytest.approx(0.25 * DEG) and f["min_elevation_std"] is None
    m = radar_sensor_model(calib.radar("cascade"), **f)
    assert (m.min_azimuth_std, m.min_elevation_std) == pytest.approx((0.25 * DEG, 2 * DEG))


def test_map_takes_the_radars_direction_error_and_records_it(small_run, tmp_path, capsys):
    # An angle error beyond what the array's resolution at the returns' SNR gives (at most
    # 3.6° / 14.4° for the single chip's 8 / 2 positions at the 5 dB clip) spreads each return
    # over more voxels: more voxels are hit.
    code, _, err = _cli(["map", small_run / RUN, "--out", tmp_path / "d", "--quiet"], capsys)
    assert code == 0, err
    code, _, err = _cli(["map", small_run / RUN, "--out", tmp_path / "w", "--quiet",
                         "--angle-std", "6", "20"], capsys)
    assert code == 0, err
    d = json.loads((tmp_path / "d" / "map.json").read_text())
    w = json.loads((tmp_path / "w" / "map.json").read_text())
    assert d["job"]["min_azimuth_std_deg"] is None and d["job"]["min_elevation_std_deg"] is None
    assert (w["job"]["min_azimuth_std_deg"], w["job"]["min_elevation_std_deg"]) == (6.0, 20.0)
    n_d = np.count_nonzero(OccupancyMap.load(tmp_path / "d" / "occupancy.npz").counts()[0])
    n_w = np.count_nonzero(OccupancyMap.load(tmp_path / "w" / "occupancy.npz").counts()[0])
    assert n_w > 1.1 * n_d > 0
    for out, argv, said in ((tmp_path / "x", ["--sensor", "lidar"], "the lidar's is fixed"),
                            (tmp_path / "p.ply", [], "a point map has none")):
        code, _, err = _cli(["map", small_run / RUN, "--out", out, "--angle-std", "2", "4",
                             *argv], capsys)
        assert code != 0 and said in err, err
        assert not out.exists()
    with pytest.raises(SystemExit):
        main(["map", str(small_run / RUN), "--out", str(tmp_path / "z"), "--angle-std", "0",
              "2"])
    assert "expected a number > 0, got '0'" in capsys.readouterr().err
