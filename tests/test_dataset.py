"""Dataset access: folders and zips, lazy streams, frame numbering, mismatches and clear errors."""

from __future__ import annotations

import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import coloradar as cr
from _synth import write_run, zip_folder
from coloradar.formats.source import FolderSource

RUN = "12_21_2020_ec_hallways_run0"


@pytest.fixture(scope="module")
def dataset_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("ds")
    truth = write_run(root, RUN, vicon=True)
    # A second run, numbered from 1 as in the derived release, shipped only as a zip whose content
    # sits in a top folder named like the run.
    tmp = tmp_path_factory.mktemp("tmp")
    truth1 = write_run(tmp, "12_22_2020_arpg_lab_run1", base=1, seed=5, write_calib=False)
    zip_folder(tmp / "12_22_2020_arpg_lab_run1", root / "12_22_2020_arpg_lab_run1.zip",
               top="12_22_2020_arpg_lab_run1")
    return root, truth, truth1


def _check_against_truth(seq, truth):
    for key, stream in (("cascade/frame", seq.cascade.adc), ("cascade/heatmap", seq.cascade.heatmaps),
                        ("single_chip/frame", seq.single_chip.adc),
                        ("single_chip/heatmap", seq.single_chip.heatmaps),
                        ("single_chip/radar_pointcloud", seq.single_chip.pointclouds),
                        ("lidar/lidar_pointcloud", seq.lidar.pointclouds)):
        ts, arrays = truth[key]
        assert len(stream) == len(arrays)
        assert stream.timestamps.dtype == np.float64
        np.testing.assert_allclose(stream.timestamps, ts, rtol=0, atol=1e-8)
        for k, a in enumerate(arrays):
            np.testing.assert_array_equal(stream[k], a)
    np.testing.assert_allclose(seq.imu.data, truth["imu"][1])
    np.testing.assert_allclose(seq.imu.timestamps, truth["imu"][0], rtol=0, atol=1e-8)
    np.testing.assert_allclose(seq.groundtruth.poses, truth["groundtruth"][1])


def test_open_dataset_lists_folders_and_zips(dataset_root):
    root, truth, truth1 = dataset_root
    ds = cr.open_dataset(root)
    assert ds.sequences == [RUN, "12_22_2020_arpg_lab_run1"]
    assert ds.calib.source.endswith("calib")
    _check_against_truth(ds[RUN], truth)
    seq1 = ds["12_22_2020_arpg_lab_run1"]
    _check_against_truth(seq1, truth1)
    # Frames numbered from 1 keep their numbers.
    assert seq1.cascade.adc.frame_ids.tolist() == [1, 2]
    with pytest.raises(cr.MissingDataError, match="no run named 'nope'"):
        ds["nope"]


def test_folder_and_zip_give_identical_arrays(dataset_root, tmp_path):
    root, _truth, _ = dataset_root
    flat = zip_folder(root / RUN, tmp_path / f"{RUN}.zip")  # content at the archive's root
    shutil.copytree(root / "calib", tmp_path / "calib")
    a = cr.open_sequence(root / RUN)
    b = cr.open_sequence(flat)
    assert b.name == RUN and "zip" in b.location
    for sa, sb in ((a.cascade.adc, b.cascade.adc), (a.single_chip.heatmaps, b.single_chip.heatmaps),
                   (a.lidar.pointclouds, b.lidar.pointclouds)):
        np.testing.assert_array_equal(sa.timestamps, sb.timestamps)
        for x, y in zip(sa, sb, strict=True):
            np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(a.vicon.poses, b.vicon.poses)


def test_stream_indexing_slicing_iteration(dataset_root):
    root, truth, _ = dataset_root
    seq = cr.open_sequence(root / RUN)
    st = seq.single_chip.adc
    arrays = truth["single_chip/frame"][1]
    np.testing.assert_array_equal(st[-1], arrays[-1])
    np.testing.assert_array_equal(st[np.int64(1)], arrays[1])
    sub = st[1:]
    assert len(sub) == 2 and sub.frame_ids.tolist() == [1, 2]
    np.testing.assert_array_equal(sub[0], arrays[1])
    np.testing.assert_array_equal(sub.timestamps, st.timestamps[1:])
    assert [f.shape for f in st] == [(3, 4, 128, 128)] * 3
    with pytest.raises(IndexError, match="out of range"):
        st[3]
    assert seq.single_chip.adc[0].dtype == np.complex64


def test_frames_are_read_only_when_asked(dataset_root, monkeypatch):
    root, _, _ = dataset_root
    reads: list[str] = []
    orig = FolderSource.read_bytes

    def counting(self, rel):
        reads.append(rel)
        return orig(self, rel)

    monkeypatch.setattr(FolderSource, "read_bytes", counting)
    seq = cr.open_sequence(root / RUN)
    stream = seq.cascade.adc
    _ = stream[0:2]
    assert not [r for r in reads if r.endswith(".bin")]
    stream[1]
    assert [r for r in reads if r.endswith(".bin")] == ["cascade/adc_samples/data/frame_1.bin"]


def test_vicon_is_none_when_absent(dataset_root):
    root, _, _ = dataset_root
    ds = cr.open_dataset(root)
    assert ds["12_22_2020_arpg_lab_run1"].vicon is None
    assert ds[RUN].vicon.poses.shape == (8, 7)


def test_count_mismatch_warns_and_exposes_only_timestamped_frames(tmp_path):
    truth = write_run(tmp_path, RUN, n_single=4)
    ts_file = tmp_path / RUN / "single_chip" / "adc_samples" / "timestamps.txt"
    lines = ts_file.read_text().splitlines()
    ts_file.write_text("\n".join(lines[:3]) + "\n")  # 3 timestamps, 4 frames
    seq = cr.open_sequence(tmp_path / RUN)
    with pytest.warns(cr.DataWarning, match="3 timestamps but 4 frame files"):
        st = seq.single_chip.adc
    assert len(st) == 3 and st.frame_ids.tolist() == [0, 1, 2]
    np.testing.assert_array_equal(st[2], truth["single_chip/frame"][1][2])
    out = subprocess.run([sys.executable, "-m", "coloradar", "info", str(tmp_path / RUN)],
                         capture_output=True, text=True, check=True).stdout
    assert "3 timestamps but 4 frame files" in out


@pytest.mark.parametrize("base", [0, 1])
def test_first_frame_file_missing_keeps_every_time(tmp_path, base):
    # A run whose first frame file is lost: file k must keep timestamp k, not take k-1's.
    truth = write_run(tmp_path, RUN, n_single=5, base=base)
    data = tmp_path / RUN / "single_chip" / "adc_samples" / "data"
    (data / f"frame_{base}.bin").unlink()
    ts, arrays = truth["single_chip/frame"]
    with pytest.warns(cr.DataWarning, match="1 timestamps have no file"):
        st = cr.open_sequence(tmp_path / RUN).single_chip.adc
    assert st.frame_ids.tolist() == [base + i for i in range(1, 5)]
    np.testing.assert_array_equal(st.timestamps, ts[1:])
    np.testing.assert_array_equal(st[0], arrays[1])


def test_missing_sensor_and_missing_timestamps_are_clear_errors(tmp_path):
    write_run(tmp_path, RUN)
    shutil.rmtree(tmp_path / RUN / "lidar")
    (tmp_path / RUN / "cascade" / "heatmaps" / "timestamps.txt").unlink()
    seq = cr.open_sequence(tmp_path / RUN)
    with pytest.raises(cr.MissingDataError, match=r"no lidar in this run \(present: cascade/adc"):
        seq.lidar
    with pytest.raises(cr.MissingDataError, match=r"heatmaps/timestamps.txt: timestamps file not found"):
        seq.cascade.heatmaps
    with pytest.raises(cr.MissingDataError, match=r"no cascade/pointclouds.*cascade has: adc, heatmaps"):
        seq.cascade.pointclouds
    with pytest.raises(cr.MissingDataError, match="not a ColoRadar run"):
        cr.open_sequence(tmp_path / "calib" / "transforms")


def test_wrong_size_frame_in_run_raises_format_error(tmp_path):
    write_run(tmp_path, RUN)
    bad = tmp_path / RUN / "cascade" / "adc_samples" / "data" / "frame_1.bin"
    bad.write_bytes(bad.read_bytes()[:-2])
    seq = cr.open_sequence(tmp_path / RUN)
    seq.cascade.adc[0]
    with pytest.raises(cr.FormatError, match=r"frame_1.bin: an ADC frame .* 3,145,728 bytes .* 3,145,726"):
        seq.cascade.adc[1]


def test_bad_pose_line_in_run(tmp_path):
    write_run(tmp_path, RUN)
    f = tmp_path / RUN / "groundtruth" / "groundtruth_poses.txt"
    lines = f.read_text().splitlines()
    lines[4] = "1.0 2.0 nan? 0 0 0 1"
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(cr.FormatError, match=r"groundtruth_poses.txt, line 5: expected a number"):
        cr.open_sequence(tmp_path / RUN).groundtruth


def test_open_sequence_without_calib_uses_presets_with_warning(tmp_path):
    write_run(tmp_path, RUN, write_calib=False)
    with pytest.warns(cr.CalibrationWarning, match="built-in sensor presets"):
        seq = cr.open_sequence(tmp_path / RUN)
    assert seq.calib.source == "preset"
    assert seq.cascade.adc[0].shape == (12, 16, 16, 256)


def test_info_command_on_run_zip_and_root(dataset_root, tmp_path):
    root, _, _ = dataset_root
    exe = [sys.executable, "-m", "coloradar", "info"]
    out = subprocess.run([*exe, str(root / RUN)], capture_output=True, text=True, check=True).stdout
    assert f"run {RUN}" in out
    assert "cascade/adc" in out and "lidar/pointclouds" in out and "vicon" in out
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("imu"))
    assert "30" in line and "300.00 Hz" in line
    assert "calibration:" in out and "v_max 1.76 m/s" in out
    out = subprocess.run([*exe, str(root)], capture_output=True, text=True, check=True).stdout
    assert out.startswith(f"dataset {root}: 2 runs") and "12_22_2020_arpg_lab_run1" in out
    proc = subprocess.run([*exe, str(tmp_path / "missing")], capture_output=True, text=True)
    assert proc.returncode == 1 and "no such folder or zip file" in proc.stderr


def test_info_reports_gaps(tmp_path):
    write_run(tmp_path, RUN, n_imu=40)
    f = tmp_path / RUN / "imu" / "timestamps.txt"
    t = np.array(f.read_text().split(), float)
    t[20:] += 0.5  # half a second without IMU samples
    f.write_text("".join(f"{v:.9f}\n" for v in t))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from coloradar.dataset.info import summarize_sequence

        s = {x.name: x for x in summarize_sequence(cr.open_sequence(tmp_path / RUN))}
    assert len(s["imu"].gaps) == 1 and s["imu"].gaps[0][0] == 19
    assert s["imu"].gaps[0][1] == pytest.approx(0.5 + 1 / 300, abs=1e-6)


def test_sequence_and_stream_pickle(dataset_root):
    import pickle

    root, _truth, _ = dataset_root
    seq = cr.open_dataset(root)["12_22_2020_arpg_lab_run1"]
    st = pickle.loads(pickle.dumps(seq.cascade.adc))
    np.testing.assert_array_equal(st[0], seq.cascade.adc[0])
    assert Path(seq.location.split(":")[0]).suffix == ".zip"
