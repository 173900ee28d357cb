"""``coloradar demo`` and ``coloradar simulate`` end to end."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

from coloradar.cli.main import main
from coloradar.errors import OutputExistsError


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    from coloradar.demo import run_demo

    out = tmp_path_factory.mktemp("demo")
    return out, run_demo(out, duration=1.2)


def test_demo_processes_both_radars_and_matches_the_truth(demo):
    _out, report = demo
    assert set(report.radars) == {"cascade", "single_chip"}
    casc, single = report.radars["cascade"], report.radars["single_chip"]
    assert casc.frames == report.counts["cascade/adc"] >= 5
    assert single.frames == report.counts["single_chip/adc"] >= 10
    # Detections from raw ADC land on scatterers the radar saw, with their range rate.
    assert casc.detections > 5 * casc.frames
    assert casc.match_fraction > 0.85 and casc.match_rate_fraction > 0.8
    assert single.match_fraction > 0.6
    assert single.onboard["matched"] / single.onboard["detections"] > 0.9
    assert casc.median_distance < 0.15 and casc.median_rate_error < 0.1
    # Processed outputs in the dataset's formats, one per frame.
    hm = sorted((report.processed_path / "cascade" / "heatmaps" / "data").iterdir())
    assert len(hm) == casc.frames
    ts = np.loadtxt(report.processed_path / "single_chip" / "pointclouds" / "timestamps.txt")
    assert len(ts) == single.frames
    text = report.text()
    for needle in ("cascade (dsp)", "single_chip (on-board)", str(report.run_path), "done in"):
        assert needle in text
    # which heatmap engine did the work is said (numba when the accel extra is installed)
    engine = "numba" if importlib.util.find_spec("numba") is not None else "numpy"
    assert report.engine == engine and f"heatmap engine: {engine}" in text


@pytest.mark.skipif(importlib.util.find_spec("matplotlib") is None, reason="needs matplotlib")
def test_demo_writes_a_range_azimuth_picture_per_radar(demo):
    _out, report = demo
    names = {p.name for p in report.pictures}
    assert {"cascade_range_azimuth.png", "single_chip_range_azimuth.png"} <= names
    for p in report.pictures:
        assert p.is_file() and p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert str(p) in report.text()


def test_demo_closes_a_loop_or_says_why(demo):
    """With the extra [slam], the demo's walk comes back and SLAM's trajectory is nearer the
    ground truth than the odometry's; without it the report says what to install."""
    _out, report = demo
    if all(importlib.util.find_spec(m) for m in ("gtsam", "small_gicp")):
        lp = report.loop
        assert lp is not None and lp.loops >= 3 and lp.distance > 20.0
        assert lp.slam_ate < lp.odometry_ate, (lp.slam_ate, lp.odometry_ate)
        assert "loop closure (radar SLAM" in report.text()
    else:
        assert report.loop is None
        assert "pip install 'coloradar[slam]'" in report.loop_note
        assert report.loop_note in report.text()


def test_demo_does_not_overwrite_without_being_asked(demo):
    from coloradar.demo import run_demo

    out, _ = demo
    with pytest.raises(OutputExistsError, match="overwrite"):
        run_demo(out, duration=1.2)


def test_demo_command(tmp_path, capsys):
    assert main(["demo", str(tmp_path / "d"), "--duration", "0.7", "--no-pictures",
                 "--no-loop", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "coloradar demo: simulated run 11_21_2026_sim_corridor_run0" in printed
    assert "cascade (dsp)" in printed and "loop closure" not in printed


def test_simulate_command(tmp_path, capsys):
    out = tmp_path / "s"
    rc = main(["simulate", str(out), "--scene", "courtyard", "--duration", "0.5",
               "--sensors", "imu,groundtruth,lidar", "--seed", "3", "--quiet", "--vicon"])
    assert rc == 0
    run = out / "11_21_2026_sim_courtyard_run3"
    assert (run / "imu" / "imu_data.txt").is_file()
    assert (run / "vicon" / "vicon_poses.txt").is_file()
    assert (run / "lidar" / "pointclouds" / "lidar_pointcloud_0.bin").is_file()
    assert not (run / "cascade").exists()
    assert "lidar/pointclouds" in capsys.readouterr().out
    # Again without --overwrite: a clear error and exit code 1.
    assert main(["simulate", str(out), "--scene", "courtyard", "--duration", "0.5",
                 "--sensors", "imu", "--seed", "3", "--quiet"]) == 1
    assert "--overwrite" in capsys.readouterr().err
    assert main(["simulate", str(out), "--scene", "nowhere", "--quiet"]) == 1
    scene_file = tmp_path / "mine.json"
    assert main(["simulate", "--scene", "mine", "--write-scene", str(scene_file)]) == 0
    assert main(["simulate", str(out), "--scene", str(scene_file), "--duration", "0.3",
                 "--sensors", "groundtruth", "--quiet"]) == 0
    assert (out / "11_21_2026_sim_mine_run0" / "groundtruth" / "timestamps.txt").is_file()
