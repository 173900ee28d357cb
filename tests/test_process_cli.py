"""``coloradar process``: a hand-written run in, dataset-layout heatmaps and point clouds out."""

from __future__ import annotations

import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

from coloradar import formats as fm
from coloradar.batch.run_processing import process_frames, process_run
from coloradar.calib import load_calibration, parse_heatmap_cfg, preset_calibration, write_calibration
from coloradar.cli.main import main
from coloradar.dataset import open_sequence
from coloradar.dsp import ProcessingSettings, RadarProcessor
from coloradar.errors import ColoradarError, OutputExistsError
from coloradar.sim import synthesize_adc

TARGET = np.array([[4.0, 1.0, 0.3]])
T0 = 1_608_580_000.5


def _write_run(root: Path) -> Path:
    """Run folder (docs/conventions.md §1) with cascade frames numbered from 0 and single-chip from 1."""
    run = root / "12_21_2020_ec_hallways_run0"
    calib = preset_calibration()
    write_calibration(calib, root / "calib")
    for radar, n, base, rate in (("cascade", 2, 0, 5.0), ("single_chip", 4, 1, 10.0)):
        rc = calib.radar(radar)
        folder = run / radar / "adc_samples"
        fm.write_timestamps(folder / "timestamps.txt", T0 + np.arange(n) / rate)
        for i in range(n):
            adc = synthesize_adc(rc, TARGET, [[0.3, 0.0, 0.0]], 300.0 * 17, noise_std=5.0, rng=i)
            fm.write_adc(folder / "data" / f"frame_{i + base}.bin", adc)
    fm.write_timestamps(run / "imu" / "timestamps.txt", T0 + np.arange(3) / 100)
    fm.write_imu(run / "imu" / "imu_data.txt", np.zeros((3, 6)))
    return run


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    return _write_run(tmp_path_factory.mktemp("data"))


@pytest.fixture(scope="module")
def processed(run_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("out") / "processed"
    assert main(["process", str(run_dir), "--out", str(out), "--quiet"]) == 0
    return out


def _snapshot(folder: Path) -> dict:
    return {p: p.stat().st_mtime_ns for p in folder.rglob("*")}


def test_layout_ids_and_timestamps(run_dir, processed):
    calib = load_calibration(run_dir.parent / "calib")
    seq = open_sequence(run_dir)
    out = open_sequence(processed, calib=calib)
    # Every product written is a stream of the output read as a run (cascade point clouds
    # were written but not readable before the layout table).
    assert sorted(out.available()) == ["cascade/heatmaps", "cascade/pointclouds",
                                       "single_chip/heatmaps", "single_chip/pointclouds"]
    assert sorted(p.name for p in (processed / "cascade" / "pointclouds" / "data").iterdir()) == [
        "radar_pointcloud_0.bin", "radar_pointcloud_1.bin"]
    assert sorted(p.name for p in (processed / "single_chip" / "heatmaps" / "data").iterdir()) == [
        f"heatmap_{i}.bin" for i in range(1, 5)]
    for radar in ("cascade", "single_chip"):
        adc = seq.radar(radar).adc
        hm = out.radar(radar).heatmaps
        np.testing.assert_array_equal(hm.frame_ids, adc.frame_ids)
        np.testing.assert_array_equal(hm.timestamps, adc.timestamps)
        proc = RadarProcessor(calib.radar(radar))
        np.testing.assert_array_equal(hm[1], proc.heatmap(adc[1]))
        pts = fm.read_radar_pointcloud(processed / radar / "pointclouds" / "data"
                                       / f"radar_pointcloud_{adc.frame_ids[0]}.bin")
        assert np.linalg.norm(pts[:, :3] - TARGET, axis=1).min() < 0.3
        clouds = out.radar(radar).pointclouds              # read back through open_sequence
        np.testing.assert_array_equal(clouds.frame_ids, adc.frame_ids)
        np.testing.assert_array_equal(clouds.timestamps, adc.timestamps)
        np.testing.assert_array_equal(clouds[0], pts)
        cfg = parse_heatmap_cfg((processed / radar / "heatmaps" / "heatmap_cfg.txt").read_text())
        np.testing.assert_array_equal(cfg.azimuth_bins, proc.heatmap_config().azimuth_bins)
    ts = fm.parse_timestamps((processed / "single_chip" / "pointclouds" / "timestamps.txt")
                             .read_text())
    np.testing.assert_array_equal(ts, seq.single_chip.adc.timestamps)


def test_rerun_resumes_and_refuses_other_settings_unless_overwrite(run_dir, processed, capsys):
    # Semantics since whole-dataset processing (issue 6): the same command again resumes
    # (frames complete on disk are kept); output made with other settings is refused.
    report = processed / "process_report.json"
    before = _snapshot(processed)
    assert main(["process", str(run_dir), "--out", str(processed), "--quiet"]) == 0
    assert "0 frames processed, 6 already complete" in capsys.readouterr().out
    after = _snapshot(processed)
    assert {p: t for p, t in after.items() if p != report} == {
        p: t for p, t in before.items() if p != report}
    before = _snapshot(processed)
    assert main(["process", str(run_dir), "--out", str(processed), "--set", "pfa=1e-3",
                 "--quiet"]) == 1
    assert "other settings (pfa: 0.0001 -> 0.001)" in capsys.readouterr().err
    assert _snapshot(processed) == before
    with pytest.raises(OutputExistsError):
        process_run(run_dir, processed, radars="single_chip", products=["heatmaps"],
                    settings=ProcessingSettings(range_window="blackman"), progress=False)
    assert _snapshot(processed) == before
    assert main(["process", str(run_dir), "--out", str(processed), "--radar", "single_chip",
                 "--products", "heatmaps", "--overwrite", "--quiet"]) == 0
    after = _snapshot(processed)
    changed = {p for p in after if after[p] != before.get(p)}
    assert changed and all("single_chip/heatmaps" in p.as_posix() for p in changed - {report})


def test_never_writes_into_the_run(run_dir, capsys):
    before = _snapshot(run_dir)
    assert main(["process", str(run_dir), "--out", str(run_dir / "derived"), "--quiet"]) == 1
    assert "inside the run" in capsys.readouterr().err
    with pytest.raises(ColoradarError):
        process_run(run_dir, run_dir, progress=False)
    assert _snapshot(run_dir) == before


def test_frame_range_radar_and_product_selection(run_dir, tmp_path):
    out = tmp_path / "part"
    assert main(["process", str(run_dir), "--out", str(out), "--radar", "single_chip",
                 "--products", "pointclouds", "--frames", "1:3", "--quiet"]) == 0
    assert not (out / "cascade").exists() and not (out / "single_chip" / "heatmaps").exists()
    data = out / "single_chip" / "pointclouds" / "data"
    assert sorted(p.name for p in data.iterdir()) == ["radar_pointcloud_2.bin",
                                                      "radar_pointcloud_3.bin"]
    seq = open_sequence(run_dir)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        back = open_sequence(out, calib=seq.calib).single_chip.pointclouds
    # Frame 1 was not processed: its line reads nan (no time for a frame with no output), and
    # a nan line without a file is no fault to warn about.
    assert not [w for w in caught if "no file" in str(w.message)]
    lines = (out / "single_chip" / "pointclouds" / "timestamps.txt").read_text().split()
    assert "nan" in lines[:-2] and set(lines[:-2]) == {"nan"}
    np.testing.assert_array_equal(back.frame_ids, [2, 3])
    np.testing.assert_array_equal(back.timestamps, seq.single_chip.adc.timestamps[1:3])


def test_zip_run_and_bad_arguments(run_dir, tmp_path, capsys):
    archive = tmp_path / "12_21_2020_ec_hallways_run0.zip"
    with zipfile.ZipFile(archive, "w") as zf:
        for p in sorted(run_dir.rglob("*")):
            zf.write(p, p.relative_to(run_dir).as_posix())
    out = tmp_path / "from_zip"
    report = process_run(archive, out, calib=run_dir.parent / "calib", radars=["cascade"],
                         products=["heatmaps"], progress=False)
    assert report.frames == {"cascade": 2}
    assert len(list((out / "cascade" / "heatmaps" / "data").iterdir())) == 2
    with pytest.raises(SystemExit):
        main(["process", str(run_dir), "--out", str(tmp_path / "x"), "--frames", "a:b"])
    with pytest.raises(SystemExit):
        main(["process", str(run_dir), "--out", str(tmp_path / "x"), "--products", "maps"])
    capsys.readouterr()


def test_process_frames_is_a_self_contained_unit_of_work(run_dir, tmp_path):
    n = process_frames(run_dir, run_dir.parent / "calib", "single_chip", ["heatmaps"], [0, 2],
                       tmp_path)
    assert n == 2
    names = sorted(p.name for p in (tmp_path / "single_chip" / "heatmaps" / "data").iterdir())
    assert names == ["heatmap_1.bin", "heatmap_3.bin"]
