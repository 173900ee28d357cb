"""coloradar.devkit: the original devkit's names and return conventions over coloradar's readers."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from _synth import REFERENCE_CALIB, write_run
from coloradar import CalibrationWarning, ColoradarError, MissingDataError
from coloradar import devkit as dl


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    root = tmp_path_factory.mktemp("devkit")
    truth = write_run(root, base=1, vicon=True)        # frame files numbered from 1
    return root, truth


def test_readers_return_the_devkit_shapes_and_values(data):
    root, truth = data
    seq_dir = str(truth["path"])
    calib_dir = str(root / "calib")
    casc = dl.get_cascade_params(calib_dir)
    sc = dl.get_single_chip_params(calib_dir)
    assert set(casc) == {"waveform", "heatmap", "antenna", "coupling", "phase", "frequency"}
    assert set(sc) == {"waveform", "heatmap", "pointcloud", "antenna", "coupling"}

    ts, frames = truth["cascade/frame"]
    adc = dl.get_adc_frame(2, seq_dir, casc["waveform"])     # file frame_2.bin = second frame
    assert adc.dtype == np.complex128
    w = casc["waveform"]
    assert adc.shape == (w["num_tx"], w["num_rx"], w["num_chirps_per_frame"],
                         w["num_adc_samples_per_chirp"])
    # brute force: the file's int16 I/Q pairs in the documented order
    raw = np.fromfile(truth["path"] / "cascade/adc_samples/data/frame_2.bin", "<i2").astype(float)
    assert np.array_equal(adc.reshape(-1), raw[0::2] + 1j * raw[1::2])
    assert np.array_equal(adc, frames[1])

    hm = dl.get_heatmap(1, seq_dir, sc["heatmap"])
    h = sc["heatmap"]
    assert hm.dtype == np.float64
    assert hm.shape == (h["num_elevation_bins"], h["num_azimuth_bins"], h["num_range_bins"], 2)
    assert np.array_equal(hm, truth["single_chip/heatmap"][1][0])

    pc = dl.get_pointcloud(3, seq_dir, sc["pointcloud"])
    assert pc.dtype == np.float64 and np.array_equal(pc, truth["single_chip/radar_pointcloud"][1][2])
    lid = dl.get_pointcloud(1, seq_dir, dl.get_lidar_params(calib_dir))
    assert lid.shape[1] == 4 and np.array_equal(lid, truth["lidar/lidar_pointcloud"][1][0])

    assert dl.get_timestamps(seq_dir, sc["pointcloud"]) == truth["single_chip/radar_pointcloud"][0].tolist()
    assert dl.get_timestamps(seq_dir, casc["waveform"]) == ts.tolist()
    assert dl.get_timestamps(seq_dir, dl.get_imu_params(calib_dir)) == truth["imu"][0].tolist()
    assert dl.get_timestamps(seq_dir, dl.get_groundtruth_params()) == truth["groundtruth"][0].tolist()

    imu = dl.get_imu(seq_dir)
    assert isinstance(imu, list) and set(imu[0]) == {"accel", "gyro"}
    assert np.array_equal([m["accel"] + m["gyro"] for m in imu], truth["imu"][1])
    for fn, key in ((dl.get_groundtruth, "groundtruth"), (dl.get_vicon, "vicon")):
        poses = fn(seq_dir)
        assert np.array_equal([np.r_[p["position"], p["orientation"]] for p in poses], truth[key][1])


def test_missing_frames_and_wrong_params_raise(data):
    root, truth = data
    sc = dl.get_single_chip_params(str(root / "calib"))
    with pytest.raises(MissingDataError, match="numbered 0"):
        dl.get_heatmap(0, str(truth["path"]), sc["heatmap"])       # this run counts from 1
    with pytest.raises(ColoradarError, match="sensor_type"):
        dl.get_heatmap(1, str(truth["path"]), dl.get_lidar_params(str(root / "calib")))
    with pytest.raises(MissingDataError):
        dl.read_tf_file(root / "calib" / "transforms" / "base_to_nothing.txt")


@pytest.mark.skipif(not REFERENCE_CALIB.is_dir(), reason="real ColoRadar calib files not available")
def test_params_of_the_real_calibration():
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        casc = dl.get_cascade_params(REFERENCE_CALIB)
    assert any(issubclass(r.category, CalibrationWarning) for r in rec)
    text = (REFERENCE_CALIB / "cascade/waveform_cfg.txt").read_text()
    raw = dict(ln.split()[:2] for ln in text.splitlines() if ln.strip())
    w = casc["waveform"]
    for key in ("num_rx", "num_tx", "num_adc_samples_per_chirp", "num_chirps_per_frame",
                "adc_sample_frequency", "start_frequency", "idle_time", "frequency_slope"):
        assert w[key] == float(raw[key])
    assert w["adc_start_time"] == pytest.approx(6e-6) and w["ramp_end_time"] == pytest.approx(40e-6)
    t, r = dl.read_tf_file(REFERENCE_CALIB / "transforms/base_to_cascade.txt")
    lines = (REFERENCE_CALIB / "transforms/base_to_cascade.txt").read_text().split("\n")
    assert t == [float(v) for v in lines[0].split()]
    assert np.allclose(r, [float(v) for v in lines[1].split()], atol=1e-6)
    assert w["translation"] == t
    assert casc["phase"]["cal_matrix"].shape == (12, 16) and casc["frequency"]["cal_matrix"].dtype == float
    ant = dl.read_antenna_cfg(REFERENCE_CALIB / "single_chip/antenna_cfg.txt")
    assert ant["num_tx"] == 3 and len(ant["tx_locations"]) == 3 and 70 < ant["F_design"] < 90
    with pytest.warns(CalibrationWarning, match="TX 2"):   # the known defect of the real file
        coup = dl.read_coupling_cfg(REFERENCE_CALIB / "single_chip/coupling_calib.txt")
    assert coup["data"].shape == (coup["num_tx"], coup["num_rx"], coup["num_range_bins"])
    hm = dl.read_heatmap_cfg(REFERENCE_CALIB / "cascade/heatmap_cfg.txt", {})
    assert hm["data_type"] == "heatmap" and len(hm["azimuth_bins"]) == hm["num_azimuth_bins"]


def test_frames_written_after_the_first_call_are_seen(tmp_path):
    # A recorder (or a conversion) still writing a run: the devkit's per-call interface must
    # see what is on disk now, not what was there at the first call.
    from coloradar import formats as fm

    truth = write_run(tmp_path, n_lidar=2)
    seq_dir = str(truth["path"])
    lidar = dl.get_lidar_params(str(tmp_path / "calib"))
    ts, clouds = truth["lidar/lidar_pointcloud"]
    assert dl.get_timestamps(seq_dir, lidar) == ts.tolist()
    assert np.array_equal(dl.get_pointcloud(1, seq_dir, lidar), clouds[1])
    with pytest.raises(MissingDataError, match="numbered 2"):
        dl.get_pointcloud(2, seq_dir, lidar)
    new = np.arange(40, dtype=np.float32).reshape(10, 4)
    fm.write_lidar_pointcloud(truth["path"] / "lidar/pointclouds/lidar_pointcloud_2.bin", new)
    fm.write_timestamps(truth["path"] / "lidar/timestamps.txt", np.r_[ts, ts[-1] + 0.1])
    assert dl.get_timestamps(seq_dir, lidar) == [*ts.tolist(), ts[-1] + 0.1]
    assert np.array_equal(dl.get_pointcloud(2, seq_dir, lidar), new)
    # and a removed frame is gone
    (truth["path"] / "lidar/pointclouds/lidar_pointcloud_2.bin").unlink()
    fm.write_timestamps(truth["path"] / "lidar/timestamps.txt", ts)
    with pytest.raises(MissingDataError, match="numbered 2"):
        dl.get_pointcloud(2, seq_dir, lidar)
