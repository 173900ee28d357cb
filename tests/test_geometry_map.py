"""Map accumulation over a run on disk, voxel down-sampling, PCD/PLY files."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from coloradar import FormatError, MissingDataError, OutputExistsError
from coloradar import formats as fm
from coloradar.calib import preset_calibration, write_calibration
from coloradar.dataset import open_sequence
from coloradar.geometry import (
    SE3,
    ExtrapolationError,
    associate,
    build_map,
    read_pcd,
    read_ply,
    read_point_file,
    sensor_to_base,
    trajectory_from_groundtruth,
    voxel_downsample,
    write_pcd,
    write_ply,
    write_point_file,
)

T0 = 1_608_580_000.123456


def _world_T_base(t: np.ndarray) -> tuple[np.ndarray, Rotation]:
    """A smooth drive: forward along +y at 0.5 m/s while yawing slowly."""
    rel = t - T0
    pos = np.stack([0.2 * np.sin(rel), 0.5 * rel, 0.05 * rel], axis=1)
    return pos, Rotation.from_euler("z", 0.1 * rel[:, None])


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A run on disk whose lidar and radar see the same static world points."""
    root = tmp_path_factory.mktemp("maprun")
    calib = preset_calibration()
    write_calibration(calib, root / "calib")
    folder = root / "12_21_2020_synthetic_run0"
    rng = np.random.default_rng(0)
    # Static world: 60 points on a wall at y = 8 m and 40 on the floor.
    wall = np.column_stack([rng.uniform(-3, 3, 60), np.full(60, 8.0), rng.uniform(0, 2, 60)])
    floor = np.column_stack([rng.uniform(-3, 3, 40), rng.uniform(2, 6, 40), np.full(40, -0.5)])
    world = np.vstack([wall, floor])
    # Keep every coordinate >= 5 cm from the 0.5 m voxel faces used below, so that sub-mm
    # interpolation errors cannot move a point across one.
    world = np.floor(world / 0.5) * 0.5 + 0.05 + np.mod(world, 0.5) * 0.8
    # Ground truth at 20 Hz; lidar at 10 Hz and radar at 10 Hz, offset and jittered.
    gt_t = T0 + np.arange(61) / 20.0
    pos, rot = _world_T_base(gt_t)
    fm.write_timestamps(folder / "groundtruth/timestamps.txt", gt_t)
    fm.write_poses(folder / "groundtruth/groundtruth_poses.txt",
                   np.hstack([pos, rot.as_quat()]))
    truth = {"world": world}
    for sensor, folder_ts, data, prefix, offset, ncol in (
            ("lidar", "lidar", "lidar/pointclouds", "lidar_pointcloud", 0.013, 4),
            ("single_chip", "single_chip/pointclouds", "single_chip/pointclouds/data",
             "radar_pointcloud", 0.051, 5)):
        ts = T0 + offset + np.arange(28) / 10.0 + rng.uniform(0, 2e-3, 28)
        fm.write_timestamps(folder / folder_ts / "timestamps.txt", ts)
        # Exact pose at each frame time from the analytic motion; the ground truth is sampled
        # from the same motion, so interpolation error is the only mismatch (checked below).
        p, r = _world_T_base(ts)
        mount = sensor_to_base(calib, sensor)
        for i in range(ts.size):
            w_T_s = SE3(r[i], p[i]) @ mount
            seen = w_T_s.inverse().apply(world)
            cloud = np.zeros((len(world), ncol), dtype=np.float32)
            cloud[:, :3] = seen
            cloud[:, 3] = np.arange(len(world))  # intensity = point id, to follow points
            writer = fm.write_lidar_pointcloud if ncol == 4 else fm.write_radar_pointcloud
            writer(folder / data / f"{prefix}_{i}.bin", cloud)
        truth[sensor] = ts
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seq = open_sequence(folder)
    return seq, truth


def _interp_error_bound() -> float:
    # Linear interpolation of the sinusoidal x over 50 ms: |x''| h²/8 = 0.2 · 0.05² / 8 ≈ 6e-5 m,
    # plus SLERP of a constant yaw rate (exact) and float32 storage (~1e-6 m at 10 m).
    return 2e-4


def test_every_frame_maps_onto_the_world(run):
    seq, truth = run
    for sensor in ("lidar", "single_chip"):
        m = build_map(seq, sensor)
        n_world = len(truth["world"])
        assert m.points.shape == (n_world * len(truth[sensor]), 4 if sensor == "lidar" else 5)
        ids = m.points[:, 3].astype(int)
        err = np.linalg.norm(m.points[:, :3] - truth["world"][ids], axis=1)
        assert err.max() < _interp_error_bound(), (sensor, err.max())
        np.testing.assert_array_equal(m.timestamps, truth[sensor])


def test_map_window_stride_and_voxels(run):
    seq, truth = run
    gt_start = seq.groundtruth.timestamps[0]
    m = build_map(seq, "lidar", start=0.5, duration=1.0, stride=2)
    ts = truth["lidar"]
    expect = np.flatnonzero((ts >= gt_start + 0.5) & (ts < gt_start + 1.5))[::2]
    np.testing.assert_array_equal(m.frame_indices, expect)
    # With 0.5 m voxels the repeated views of each static point collapse to its voxel's points.
    vox = build_map(seq, "lidar", voxel_size=0.5)
    world = truth["world"]
    keys = np.floor(world / 0.5).astype(int)
    assert len(vox.points) == len({tuple(k) for k in keys})
    ranged = build_map(seq, "lidar", max_range=6.0)
    d = np.linalg.norm(ranged.points[:, :3] - seq.groundtruth.poses[0, :3], axis=1)
    assert len(ranged.points) < len(build_map(seq, "lidar").points) and d.min() > 0


def test_map_errors(run):
    seq, _ = run
    with pytest.raises(MissingDataError, match="no lidar frames"):
        build_map(seq, "lidar", start=100.0)
    with pytest.raises(MissingDataError):
        build_map(seq, "cascade")
    with pytest.raises(MissingDataError):
        build_map(seq, "sonar")
    traj = trajectory_from_groundtruth(seq)
    with pytest.raises(ExtrapolationError):
        traj.at(seq.lidar.pointclouds.timestamps[-1] + 10.0)


def test_lidar_and_radar_frames_associate(run):
    seq, truth = run
    ia, ib = associate(seq.lidar.pointclouds.timestamps, seq.single_chip.pointclouds.timestamps,
                       tolerance=0.05)
    # Offsets 13 ms and 51 ms: frame k of each stream pairs with frame k of the other.
    np.testing.assert_array_equal(ia, ib)
    assert ia.size == len(truth["lidar"])


def test_voxel_downsample_matches_a_brute_force_grouping():
    rng = np.random.default_rng(1)
    pts = np.column_stack([rng.uniform(-2, 2, (500, 3)), rng.uniform(0, 1, 500)])
    pts = pts.astype(np.float32)
    out = voxel_downsample(pts, 0.7)
    groups: dict[tuple, list[int]] = {}
    for i, p in enumerate(pts):
        groups.setdefault(tuple(np.floor(p[:3].astype(np.float64) / 0.7).astype(int)), []).append(i)
    expect = np.array([pts[idx].astype(np.float64).mean(axis=0) for _, idx in sorted(groups.items())])
    assert out.dtype == np.float32 and out.shape == expect.shape
    order = np.lexsort(np.floor(out[:, :3].astype(np.float64) / 0.7).T[::-1])
    np.testing.assert_allclose(out[order], expect, atol=1e-5)
    first = voxel_downsample(pts, 0.7, reduce="first")
    assert sorted(first[:, 3].tolist()) == sorted(pts[[idx[0] for idx in groups.values()], 3]
                                                  .tolist())
    with_nan = np.vstack([pts, [[np.nan, 0, 0, 1]]]).astype(np.float32)
    assert len(voxel_downsample(with_nan, 0.7)) == len(expect)


# -- PCD / PLY ---------------------------------------------------------------------------------
@pytest.mark.parametrize("binary", [True, False])
@pytest.mark.parametrize("writer,reader", [(write_pcd, read_pcd), (write_ply, read_ply)])
def test_point_files_round_trip(tmp_path, writer, reader, binary):
    pts = np.random.default_rng(2).normal(scale=30, size=(257, 5)).astype(np.float32)
    path = tmp_path / ("cloud" + (".pcd" if writer is write_pcd else ".ply"))
    writer(path, pts, binary=binary)
    back, fields = reader(path)
    assert fields == ("x", "y", "z", "intensity", "range_rate")
    assert back.dtype == np.float32
    np.testing.assert_array_equal(back, pts)  # %.9g keeps float32 exactly in ascii too
    with pytest.raises(OutputExistsError):
        writer(path, pts)
    writer(path, pts[:3], ("a", "b", "c", "d", "e"), overwrite=True)
    back, fields = read_point_file(path)
    assert fields == ("a", "b", "c", "d", "e") and back.shape == (3, 5)
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temp files left


def test_pcd_reader_accepts_other_writers_files(tmp_path):
    """A PCL-style binary file with mixed types and a COUNT > 1 field; an ascii PLY with faces."""
    n = 4
    rec = np.zeros(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4"),
                             ("n", "<f8", (2,))])
    rec["x"], rec["y"], rec["z"] = np.arange(n), -np.arange(n), 0.5
    rec["rgb"] = [1, 2, 3, 4]
    rec["n"] = np.arange(2 * n).reshape(n, 2)
    header = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z rgb n\nSIZE 4 4 4 4 8\nTYPE F F F U F\n"
              f"COUNT 1 1 1 1 2\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
              "DATA binary\n")
    (tmp_path / "a.pcd").write_bytes(header.encode() + rec.tobytes())
    pts, fields = read_pcd(tmp_path / "a.pcd")
    assert fields == ("x", "y", "z", "rgb", "n_0", "n_1") and pts.dtype == np.float64
    np.testing.assert_array_equal(pts[:, 3], [1, 2, 3, 4])
    np.testing.assert_array_equal(pts[:, 5], [1, 3, 5, 7])
    ply = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
           "property float z\nproperty uchar red\nelement face 1\n"
           "property list uchar int vertex_indices\nend_header\n"
           "0 0 0 255\n1 0 0 128\n0 1 0 0\n3 0 1 2\n")
    (tmp_path / "b.ply").write_text(ply)
    pts, fields = read_ply(tmp_path / "b.ply")
    assert fields == ("x", "y", "z", "red")
    np.testing.assert_array_equal(pts, [[0, 0, 0, 255], [1, 0, 0, 128], [0, 1, 0, 0]])
    (tmp_path / "c.pcd").write_bytes(header.replace("binary", "binary_compressed").encode())
    with pytest.raises(FormatError, match="binary_compressed"):
        read_pcd(tmp_path / "c.pcd")
    (tmp_path / "d.pcd").write_bytes(header.encode() + rec.tobytes()[:10])
    with pytest.raises(FormatError, match=r"d\.pcd"):
        read_pcd(tmp_path / "d.pcd")
    with pytest.raises(FormatError):
        write_point_file(Path(tmp_path / "e.xyz"), np.zeros((1, 3)))


def test_map_command_writes_a_readable_file(run, tmp_path, capsys):
    from coloradar.cli.main import main

    seq, truth = run
    out = tmp_path / "map.pcd"
    argv = ["map", str(seq.location), "--out", str(out), "--sensor", "single_chip",
            "--voxel", "0.5", "--calib", str(Path(seq.location).parent / "calib")]
    assert main(argv) == 0
    pts, fields = read_pcd(out)
    assert fields == ("x", "y", "z", "intensity", "range_rate")
    keys = {tuple(k) for k in np.floor(truth["world"] / 0.5).astype(int)}
    assert len(pts) == len(keys)
    assert main(argv) == 1 and "exists" in capsys.readouterr().err
