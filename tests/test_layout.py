"""The layout table: what ``process`` and the simulator write is what the reader reads, for
ColoRadar and ColoRadar+ alike."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from coloradar.cli.main import main
from coloradar.dataset import open_dataset, open_sequence
from coloradar.errors import MissingDataError
from coloradar.formats import write_timestamps
from coloradar.formats.layout import COLORADAR, COLORADAR_PLUS, LAYOUTS
from coloradar.geometry import read_point_file
from coloradar.sim.run import simulate_run


def _raw_adc(path: Path, shape) -> np.ndarray:
    """Independent decoding of an ADC file: int16 I/Q pairs, (tx, rx, chirp, sample)."""
    iq = np.fromfile(path, dtype="<i2").astype(np.float64).reshape(*shape, 2)
    return iq[..., 0] + 1j * iq[..., 1]


def _pose_rows(path: Path) -> np.ndarray:
    return np.loadtxt(path, ndmin=2)


# -- process output is a run the reader reads ------------------------------------------------
@pytest.fixture(scope="module")
def processed(tmp_path_factory):
    root = tmp_path_factory.mktemp("sim")
    res = simulate_run(root, duration=1.0, seed=2, sensors=["cascade", "groundtruth"],
                       heatmaps=False)
    out = tmp_path_factory.mktemp("out") / "processed"
    assert main(["process", str(res.run_path), "--out", str(out), "--radar", "cascade",
                 "--products", "pointclouds", "--quiet"]) == 0
    return res.run_path, out


def test_every_product_process_writes_is_readable(processed):
    run, out = processed
    seq = open_sequence(run)
    adc = seq.cascade.adc
    written = open_sequence(out, calib=seq.calib)
    assert "cascade/pointclouds" in written.available()
    clouds = written.cascade.pointclouds
    np.testing.assert_array_equal(clouds.frame_ids, adc.frame_ids)
    np.testing.assert_array_equal(clouds.timestamps, adc.timestamps)
    for k in range(len(clouds)):
        raw = np.fromfile(out / "cascade/pointclouds/data"
                          / f"radar_pointcloud_{adc.frame_ids[k]}.bin", dtype="<f4")
        np.testing.assert_array_equal(clouds[k], raw.reshape(-1, 5))
    # The run with its products: radar streams from the output, ground truth from the run.
    both = open_sequence(run, products=out)
    assert {"cascade/adc", "cascade/pointclouds", "groundtruth"} <= set(both.available())
    np.testing.assert_array_equal(both.cascade.pointclouds[0], clouds[0])


def test_map_of_cascade_point_clouds(processed, tmp_path):
    run, out = processed
    pcd = tmp_path / "cascade.pcd"
    # Without the products the cascade's points are computed from its ADC frames, as
    # `coloradar odometry` and `export` do (tests/test_first_hour.py checks those points).
    assert main(["map", str(run), "--sensor", "cascade", "--out",
                 str(tmp_path / "from_adc.pcd")]) == 0
    assert main(["map", str(run), "--sensor", "cascade", "--products", str(out),
                 "--out", str(pcd)]) == 0
    pts, _fields = read_point_file(pcd)
    # Independent reference: the ground truth interpolated with scipy (linear positions,
    # slerp rotations) and the cascade extrinsic, p_world = R_wb (R_bc p + t_bc) + t_wb.
    seq = open_sequence(run, products=out)
    gt_t = seq.groundtruth.timestamps
    gt = seq.groundtruth.poses
    slerp = Slerp(gt_t, Rotation.from_quat(gt[:, 3:]))
    ext = seq.calib.transforms["cascade"]
    r_bc = Rotation.from_quat(ext.quaternion)
    clouds = seq.cascade.pointclouds
    expect = []
    for k, t in enumerate(clouds.timestamps):
        if not gt_t[0] <= t <= gt_t[-1]:
            continue
        p = clouds[k][:, :3].astype(np.float64)
        t_wb = np.array([np.interp(t, gt_t, gt[:, j]) for j in range(3)])
        expect.append(slerp([t]).apply(r_bc.apply(p) + np.asarray(ext.translation)) + t_wb)
    expect_arr = np.concatenate(expect)
    assert len(expect_arr) > 0 and pts.shape[0] == expect_arr.shape[0]
    np.testing.assert_allclose(pts[:, :3], expect_arr, atol=1e-4)


# -- ColoRadar+ ------------------------------------------------------------------------------
RGB_SIZE, DEPTH_SIZE = (6, 8), (4, 5)    # (height, width)


@pytest.fixture(scope="module")
def plus_root(tmp_path_factory):
    """A ColoRadar+ tree: a simulated run written in that layout, and a camera by hand."""
    root = tmp_path_factory.mktemp("plus")
    res = simulate_run(root, duration=0.6, seed=1, layout="coloradar_plus", heatmaps=False)
    run = res.run_path
    rng = np.random.default_rng(0)
    cam: dict = {}
    for kind, (h, w), n in (("rgb", RGB_SIZE, 3), ("depth", DEPTH_SIZE, 2)):
        ts = 1_795_262_400.05 + np.arange(n) / 15.0
        write_timestamps(run / "camera" / f"{kind}_timestamps.txt", ts)
        imgs = [rng.integers(0, 255, (h, w, 3), dtype=np.uint8) if kind == "rgb"
                else rng.integers(0, 9000, (h, w), dtype=np.uint16) for _ in range(n)]
        folder = run / "camera" / "images" / kind
        folder.mkdir(parents=True, exist_ok=True)
        for i, img in enumerate(imgs, start=1):          # numbered from 1
            img.astype(img.dtype.newbyteorder("<")).tofile(
                folder / f"camera_{kind}_image_{i}.bin")
        info = json.dumps({"height": h, "width": w, "distortion_model": "plumb_bob"})
        # As the ColoRadar+ tools write it: the JSON text serialised once more for rgb.
        (run / "camera" / f"{kind}_cam_info.json").write_text(
            json.dumps(info) if kind == "rgb" else info)
        cam[kind] = (ts, imgs)
    return root, res, cam


def test_plus_layout_on_disk(plus_root):
    root, res, _ = plus_root
    run = res.run_path
    assert run.parent == root / "kitti"
    assert sorted(p.name for p in (root / "calib" / "transforms").iterdir()) == [
        "base_to_imu.txt", "base_to_lidar.txt", "base_to_radar.txt"]
    assert not (root / "calib" / "single_chip").exists()
    assert (run / "cascade/adc_samples/data/frame_1.bin").is_file()
    assert not (run / "cascade/adc_samples/data/frame_0.bin").exists()
    assert (run / "lidar/pointclouds/lidar_pointcloud_1.bin").is_file()


def test_plus_read_through_the_same_api(plus_root):
    root, res, cam = plus_root
    run = res.run_path
    with warnings.catch_warnings():
        warnings.simplefilter("error")               # no preset fallback, no mismatch
        ds = open_dataset(root)
        seq = ds[run.name]
    assert ds.layout is COLORADAR_PLUS and ds.sequences == [run.name]
    assert set(seq.available()) == {"cascade/adc", "lidar/pointclouds", "camera/rgb",
                                    "camera/depth", "imu", "groundtruth"}
    # Radar: 1-based files paired with the timestamp lines in order.
    adc = seq.cascade.adc
    ts = np.loadtxt(run / "cascade/adc_samples/timestamps.txt")
    assert len(adc) == res.counts["cascade/adc"] == ts.size
    np.testing.assert_array_equal(adc.frame_ids, np.arange(1, ts.size + 1))
    np.testing.assert_allclose(adc.timestamps, ts, rtol=0, atol=1e-6)
    shape = seq.calib.cascade.frame_shape
    np.testing.assert_array_equal(adc[-1], _raw_adc(
        run / f"cascade/adc_samples/data/frame_{ts.size}.bin", shape))
    # Lidar.
    lid = seq.lidar.pointclouds
    np.testing.assert_array_equal(lid.frame_ids, np.arange(1, len(lid) + 1))
    np.testing.assert_array_equal(
        lid[0], np.fromfile(run / "lidar/pointclouds/lidar_pointcloud_1.bin",
                            dtype="<f4").reshape(-1, 4))
    # IMU and poses.
    np.testing.assert_allclose(seq.imu.data, _pose_rows(run / "imu/imu_data.txt"))
    np.testing.assert_allclose(seq.groundtruth.poses,
                               _pose_rows(run / "groundtruth/groundtruth_poses.txt"))
    # Camera: timestamps and raw images, sizes from the cam_info files.
    for kind in ("rgb", "depth"):
        stream = seq.stream(f"camera/{kind}")
        ts_k, imgs = cam[kind]
        np.testing.assert_allclose(stream.timestamps, ts_k, rtol=0, atol=1e-6)
        assert len(stream) == len(imgs)
        for k, img in enumerate(imgs):
            np.testing.assert_array_equal(stream[k], img)
    # Extrinsics: base_to_radar.txt is the cascade's.
    lines = (root / "calib/transforms/base_to_radar.txt").read_text().split("\n")
    np.testing.assert_allclose(seq.calib.transforms["cascade"].translation,
                               [float(v) for v in lines[0].split()])
    # What the layout does not have is a named error.
    with pytest.raises(MissingDataError, match="ColoRadar\\+ layout has no single_chip"):
        seq.single_chip
    # The run opened on its own finds the layout and the calib beside kitti/.
    alone = open_sequence(run)
    assert alone.layout is COLORADAR_PLUS
    assert alone.calib.source == ds.calib.source


def test_plus_info(plus_root, capsys):
    root, res, _ = plus_root
    assert main(["info", str(root)]) == 0
    out = capsys.readouterr().out
    assert "1 runs (ColoRadar+ layout)" in out
    for name, n in (("camera/rgb", 3), ("camera/depth", 2),
                    ("cascade/adc", res.counts["cascade/adc"]), ("imu", res.counts["imu"])):
        line = next(ln for ln in out.splitlines() if ln.strip().startswith(name + " "))
        assert int(line.split()[1]) == n
    assert "single_chip" not in out
    assert main(["info", str(res.run_path)]) == 0
    assert "ColoRadar+ layout" in capsys.readouterr().out


def test_bad_camera_frame_size_is_a_named_error(plus_root, tmp_path):
    from coloradar.errors import FormatError
    from coloradar.formats.camera import decode_image, parse_camera_info

    with pytest.raises(FormatError, match=r"cam\.json.*height"):
        parse_camera_info('{"width": 4}', "cam.json")
    with pytest.raises(FormatError, match=r"img\.bin: a 5x4 depth image should be 40 bytes"):
        decode_image(b"\0" * 39, "depth", 4, 5, "img.bin")


def test_layout_table_is_consistent():
    for lay in LAYOUTS.values():
        assert lay.first_frame in (0, 1)
        for name, st in lay.frames.items():
            assert name == f"{st.sensor}/{st.product}"
            assert st.frame_path(7) == f"{st.data}/{st.prefix}_7.bin"
    # process writes ColoRadar-layout products of both radars.
    for radar in COLORADAR.radars:
        assert {"heatmaps", "pointclouds"} <= set(COLORADAR.radar_streams(radar))


def test_heatmaps_are_placed_on_the_grid_stored_beside_them(tmp_path):
    """Heatmaps made by ``process`` carry their own grid (true bin angles); points are placed
    on it, not on the calibration's shipped angle lists (half a bin apart)."""
    from _synth import write_run
    from coloradar.calib import format_heatmap_cfg, preset_calibration
    from coloradar.dsp import RadarProcessor, radar_point_stream
    from coloradar.formats import write_heatmap

    calib = preset_calibration()
    truth = write_run(tmp_path, n_cascade=1, calib=calib)
    run = truth["path"]
    grid = RadarProcessor(calib.cascade).heatmap_config()
    assert not np.allclose(grid.azimuth_bins, calib.cascade.heatmap.azimuth_bins)
    (run / "cascade/heatmaps/heatmap_cfg.txt").write_text(format_heatmap_cfg(grid))
    e, a, r = 20, 90, 60
    hm = np.zeros((*grid.shape, 2), np.float32)
    hm[..., 0] = 1.0
    hm[e, a, r, 0] = 1e4
    write_heatmap(run / "cascade/heatmaps/data/heatmap_0.bin", hm)
    seq = open_sequence(run)
    np.testing.assert_array_equal(seq.cascade.heatmap_config.azimuth_bins, grid.azimuth_bins)
    stream, points = radar_point_stream(seq, "cascade", "heatmaps",
                                        processing={"threshold": 100.0})
    pts = points(stream[0])
    uy, uz = np.sin(grid.azimuth_bins[a]), np.sin(grid.elevation_bins[e])
    expect = r * grid.range_bin_width * np.array([np.sqrt(1 - uy**2 - uz**2), uy, uz])
    assert pts.shape == (1, 5)
    np.testing.assert_allclose(pts[0, :3], expect, atol=1e-5)


def test_plus_run_zip_and_simulate_command(plus_root, tmp_path):
    import shutil

    from _synth import zip_folder

    root, res, _ = plus_root
    other = tmp_path / "root"
    (other / "kitti").mkdir(parents=True)
    shutil.copytree(root / "calib", other / "calib")
    zip_folder(res.run_path, other / "kitti" / f"{res.run_path.name}.zip", top=res.run_path.name)
    ds = open_dataset(other)
    assert ds.layout is COLORADAR_PLUS and ds.sequences == [res.run_path.name]
    zipped, folder = ds[res.run_path.name], open_dataset(root)[res.run_path.name]
    np.testing.assert_array_equal(zipped.cascade.adc[0], folder.cascade.adc[0])
    np.testing.assert_array_equal(zipped.stream("camera/rgb")[1], folder.camera.rgb[1])
    out = tmp_path / "sim"
    assert main(["simulate", str(out), "--duration", "0.3", "--layout", "coloradar_plus",
                 "--sensors", "imu,groundtruth", "--quiet"]) == 0
    (run,) = (out / "kitti").iterdir()
    assert open_sequence(run).available() == ["imu", "groundtruth"]
    assert main(["simulate", str(tmp_path / "x"), "--layout", "coloradar_plus",
                 "--sensors", "single_chip", "--quiet"]) == 1
