"""Formats: round trips, the ADC index formula, size checks and clear errors."""

from __future__ import annotations

import numpy as np
import pytest

import coloradar as cr
from coloradar import formats as fm


def test_adc_index_formula_element_by_element(tmp_path):
    # Values that encode their own position: value index v holds v (fits in int16 for this shape).
    nt, nr, nc, ns = 3, 4, 5, 7
    raw = np.arange(2 * nt * nr * nc * ns, dtype="<i2")
    path = tmp_path / "frame_0.bin"
    path.write_bytes(raw.tobytes())
    adc = fm.read_adc(path, (nt, nr, nc, ns))
    assert adc.dtype == np.complex64 and adc.shape == (nt, nr, nc, ns)
    for t in range(nt):
        for r in range(nr):
            for c in range(nc):
                for s in range(ns):
                    i = 2 * (s + ns * (c + nc * (r + t * nr)))
                    assert adc[t, r, c, s] == complex(i, i + 1)


def test_adc_round_trip_rounds_and_clips(tmp_path):
    rng = np.random.default_rng(1)
    shape = (2, 3, 4, 8)
    adc = (rng.integers(-30000, 30000, shape) + 1j * rng.integers(-30000, 30000, shape)).astype(np.complex64)
    fm.write_adc(tmp_path / "a.bin", adc)
    assert (tmp_path / "a.bin").stat().st_size == fm.adc_nbytes(shape)
    np.testing.assert_array_equal(fm.read_adc(tmp_path / "a.bin", shape), adc)
    big = np.full(shape, 1e6 - 1e6j, dtype=np.complex64)
    back = fm.decode_adc(fm.encode_adc(big), shape)
    assert np.all(back.real == 32767) and np.all(back.imag == -32768)


def test_heatmap_and_pointcloud_round_trips(tmp_path):
    rng = np.random.default_rng(2)
    hm = rng.standard_normal((4, 5, 6, 2)).astype(np.float32)
    fm.write_heatmap(tmp_path / "h.bin", hm)
    np.testing.assert_array_equal(fm.read_heatmap(tmp_path / "h.bin", (4, 5, 6)), hm)
    pc = rng.standard_normal((17, 5)).astype(np.float32)
    fm.write_radar_pointcloud(tmp_path / "r.bin", pc)
    np.testing.assert_array_equal(fm.read_radar_pointcloud(tmp_path / "r.bin"), pc)
    lp = rng.standard_normal((33, 4)).astype(np.float32)
    fm.write_lidar_pointcloud(tmp_path / "l.bin", lp)
    np.testing.assert_array_equal(fm.read_lidar_pointcloud(tmp_path / "l.bin"), lp)
    fm.write_radar_pointcloud(tmp_path / "empty.bin", np.zeros((0, 5), np.float32))
    assert fm.read_radar_pointcloud(tmp_path / "empty.bin").shape == (0, 5)


def test_text_round_trips_keep_float64_time(tmp_path):
    rng = np.random.default_rng(3)
    t = 1_608_580_000.0 + np.cumsum(rng.uniform(0.09, 0.11, 50))
    fm.write_timestamps(tmp_path / "timestamps.txt", t)
    back = fm.parse_timestamps((tmp_path / "timestamps.txt").read_text())
    assert back.dtype == np.float64
    np.testing.assert_allclose(back, t, rtol=0, atol=1e-8)  # float32 would be ~100 s off
    imu = rng.standard_normal((20, 6))
    fm.write_imu(tmp_path / "imu.txt", imu)
    np.testing.assert_array_equal(fm.parse_imu((tmp_path / "imu.txt").read_text()), imu)
    poses = rng.standard_normal((9, 7))
    fm.write_poses(tmp_path / "p.txt", poses)
    np.testing.assert_array_equal(fm.parse_poses((tmp_path / "p.txt").read_text()), poses)


def test_timestamps_with_20_decimals_and_trailing_blank_lines():
    text = "1608580000.12345678901234567890\n1608580000.22345678901234567890\n\n"
    t = fm.parse_timestamps(text)
    np.testing.assert_allclose(t, [1608580000.1234568, 1608580000.2234568], rtol=0, atol=1e-6)


def test_truncated_adc_frame_names_file_and_sizes(tmp_path):
    path = tmp_path / "frame_3.bin"
    path.write_bytes(b"\0" * 1000)
    with pytest.raises(cr.FormatError) as err:
        fm.read_adc(path, (12, 16, 16, 256))
    msg = str(err.value)
    assert "frame_3.bin" in msg and "3,145,728" in msg and "1,000" in msg


def test_wrong_size_heatmap_and_pointcloud(tmp_path):
    (tmp_path / "heatmap_0.bin").write_bytes(b"\0" * 524_288)
    with pytest.raises(cr.FormatError, match=r"heatmap_0.bin.*4,194,304.*524,288"):
        fm.read_heatmap(tmp_path / "heatmap_0.bin", (32, 128, 128))
    (tmp_path / "radar_pointcloud_0.bin").write_bytes(b"\0" * 24)
    with pytest.raises(cr.FormatError, match="multiple of 20 bytes"):
        fm.read_radar_pointcloud(tmp_path / "radar_pointcloud_0.bin")


def test_non_numeric_pose_line_reports_line(tmp_path):
    text = "0 0 0 0 0 0 1\n1 2 3 0 0 0 1\n1 2 abc 0 0 0 1\n"
    with pytest.raises(cr.FormatError, match=r"poses.txt, line 3: expected a number.*'abc'"):
        fm.parse_poses(text, "poses.txt")
    with pytest.raises(cr.FormatError, match=r"line 2: expected 7 numbers"):
        fm.parse_poses("0 0 0 0 0 0 1\n1 2 3 0 0 1\n", "poses.txt")


def test_atomic_write_leaves_no_partial_file(tmp_path):
    target = tmp_path / "out" / "x.bin"
    fm.atomic_write_bytes(target, b"old")

    with pytest.raises(TypeError):
        fm.atomic_write_bytes(target, object())  # type: ignore[arg-type]
    assert target.read_bytes() == b"old"
    assert sorted(p.name for p in target.parent.iterdir()) == ["x.bin"]


def test_lines_of_wrong_length_are_caught_even_when_the_total_fits():
    # 8 + 6 numbers = 2 x 7: a parser that only counts tokens would read two shifted poses.
    text = "0 0 0 0 0 0 1 9\n1 2 3 0 0 1\n"
    with pytest.raises(cr.FormatError, match=r"poses.txt, line 1: expected 7 numbers.*found 8"):
        fm.parse_poses(text, "poses.txt")
