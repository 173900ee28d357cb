"""Bad input gets a named coloradar error (or warning) naming the file and what was expected;
the command line prints one ``coloradar: error:`` line, never a traceback, and never hangs."""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest

import coloradar as cr
from _synth import write_run
from coloradar import formats as fm
from coloradar.calib import load_calibration, preset_calibration, write_calibration
from coloradar.cli.main import main
from coloradar.errors import (
    CalibrationError,
    ColoradarError,
    DataWarning,
    FormatError,
    FrameIndexError,
    MissingDependencyError,
    ReadError,
    SettingsError,
    WriteError,
)
from coloradar.sim.trajectory import make_trajectory

# `plot` needs the viz extra; the oldest-dependency CI run has only numpy and scipy.
HAS_MATPLOTLIB = importlib.util.find_spec("matplotlib") is not None

RUN = "12_21_2020_ec_hallways_run0"


@pytest.fixture(scope="module")
def root(tmp_path_factory) -> Path:
    """A small dataset root: calib/ and one run (2 cascade, 3 single-chip frames)."""
    r = tmp_path_factory.mktemp("errors")
    write_run(r, RUN, n_lidar=3)
    return r


@pytest.fixture
def copy(root, tmp_path) -> Path:
    """A private copy of the dataset root, to damage."""
    dst = tmp_path / "root"
    shutil.copytree(root, dst)
    return dst


def _cli(argv: list[str], capsys) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _one_error_line(err: str) -> str:
    """The CLI's error line; fails on a traceback or on more than one error line."""
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if ln.startswith("coloradar: error:")]
    assert len(lines) == 1, err
    return lines[0]


# --- calibration values -------------------------------------------------------------------------

def _replace_line(path: Path, key: str, new: str) -> None:
    lines = path.read_text().splitlines()
    hits = [i for i, ln in enumerate(lines) if ln.split()[:1] == [key] or ln.startswith(key + ":")]
    assert hits, f"{key} not in {path}"
    lines[hits[0]] = new
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("rel,key,line,expect", [
    ("cascade/waveform_cfg.txt", "start_frequency", "start_frequency nan", "start_frequency"),
    ("cascade/waveform_cfg.txt", "adc_sample_frequency", "adc_sample_frequency 1e30",
     "adc_sample_frequency"),
    ("single_chip/waveform_cfg.txt", "frequency_slope", "frequency_slope -inf", "frequency_slope"),
    ("single_chip/waveform_cfg.txt", "idle_time", "idle_time 3.0e5", "idle_time"),
    ("cascade/antenna_cfg.txt", "rx", "rx 0 nan 0", "rx 0"),
    ("cascade/antenna_cfg.txt", "F_design", "F_design 1e12", "F_design"),
    ("cascade/heatmap_cfg.txt", "range_bin_width", "range_bin_width nan", "range_bin_width"),
    ("single_chip/heatmap_cfg.txt", "azimuth_bins", "azimuth_bins " + " ".join(["nan"] * 64),
     "azimuth_bins"),
    ("transforms/base_to_lidar.txt", None, "nan 0 0", "translation"),
])
def test_non_finite_or_absurd_calibration_values_are_refused(tmp_path, rel, key, line, expect):
    calib = tmp_path / "calib"
    write_calibration(preset_calibration(), calib)
    path = calib / rel
    if key is None:
        lines = path.read_text().splitlines()
        path.write_text(line + "\n" + lines[1] + "\n")
    else:
        _replace_line(path, key, line)
    with pytest.raises(CalibrationError) as exc:
        load_calibration(calib)
    msg = str(exc.value)
    assert str(path) in msg and expect in msg


def test_non_finite_coupling_and_phase_values_are_refused(tmp_path):
    calib = tmp_path / "calib"
    pre = preset_calibration()
    write_calibration(pre, calib)
    # The presets carry no coupling: write one with a NaN among its values.
    from coloradar.calib.coupling import CouplingCalib, format_coupling_calib

    rc = pre.cascade
    data = np.ones((rc.waveform.num_tx, rc.waveform.num_rx, 8), dtype=np.complex64)
    text = format_coupling_calib(CouplingCalib(data, 16)).replace("data:1,", "data:nan,", 1)
    (calib / "cascade" / "coupling_calib.txt").write_text(text)
    with pytest.raises(CalibrationError, match=r"coupling_calib.txt.*data"):
        load_calibration(calib)
    (calib / "cascade" / "coupling_calib.txt").unlink()
    pf = {"antennaCalib": {"numTx": 12, "numRx": 16, "frequencySlope": 79e12,
                           "samplingRate": 8e6, "frequencyCalibrationMatrix": [51.0] * 192,
                           "phaseCalibrationMatrix": [1.0, 0.0] * 191 + [float("nan"), 0.0]}}
    (calib / "cascade" / "phase_frequency_calib.txt").write_text(json.dumps(pf))
    with pytest.raises(CalibrationError, match=r"phase_frequency_calib.txt.*phaseCalibration"):
        load_calibration(calib)


def test_nan_calibration_is_an_error_on_the_command_line(copy, capsys):
    _replace_line(copy / "calib" / "cascade" / "waveform_cfg.txt", "start_frequency",
                  "start_frequency nan")
    code, _, err = _cli(["info", copy / RUN], capsys)
    assert code == 1
    assert "waveform_cfg.txt" in _one_error_line(err) and "start_frequency" in err


# --- files that are not regular files ------------------------------------------------------------

def _finishes(fn, seconds: float = 10.0):
    """Run ``fn`` in a thread; the exception it raised, failing if it is still running."""
    box: dict = {}

    def target():
        try:
            fn()
        except BaseException as exc:
            box["exc"] = exc

    t = threading.Thread(target=target, daemon=True)
    t.start()
    t.join(seconds)
    assert not t.is_alive(), "blocked reading a FIFO"
    return box.get("exc")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
def test_a_fifo_in_place_of_a_frame_is_refused_not_read(copy, capsys):
    frame = copy / RUN / "cascade" / "adc_samples" / "data" / "frame_1.bin"
    frame.unlink()
    os.mkfifo(frame)
    seq = cr.open_sequence(copy / RUN)
    exc = _finishes(lambda: seq.cascade.adc[1])
    assert isinstance(exc, ReadError) and str(frame) in str(exc) and "FIFO" in str(exc)
    out = copy.parent / "out.png"
    box: dict = {}
    if HAS_MATPLOTLIB:
        exc = _finishes(lambda: box.update(code=main(["plot", str(copy / RUN), "--view",
                                                      "range-doppler", "--frame", "1",
                                                      "--out", str(out)])))
        assert exc is None and box["code"] == 1
        assert "FIFO" in _one_error_line(capsys.readouterr().err)
    # process skips and reports it, like any bad frame
    box.clear()
    exc = _finishes(lambda: box.update(code=main(["process", str(copy / RUN), "--out",
                                                  str(copy.parent / "p"), "--radar", "cascade",
                                                  "--jobs", "1", "--quiet"])))
    assert exc is None and box["code"] == 1
    rep = json.loads((copy.parent / "p" / "process_report.json").read_text())
    (fail,) = rep["runs"][RUN]["radars"]["cascade"]["failures"]
    assert fail["error"] == "ReadError" and fail["frame_id"] == 1


def test_a_folder_in_place_of_a_calibration_file_is_named(copy, capsys):
    wf = copy / "calib" / "single_chip" / "waveform_cfg.txt"
    wf.unlink()
    wf.mkdir()
    code, _, err = _cli(["info", copy / RUN], capsys)
    assert code == 1 and str(wf) in _one_error_line(err) and "regular file" in err
    with pytest.raises(ReadError):
        load_calibration(copy / "calib")


# --- the command line ----------------------------------------------------------------------------

def test_plot_frame_out_of_range(root, tmp_path, capsys):
    with pytest.raises(FrameIndexError):
        cr.open_sequence(root / RUN).cascade.adc[2]
    with pytest.raises(IndexError):  # still an IndexError for existing callers
        cr.open_sequence(root / RUN).cascade.adc[-3]
    pytest.importorskip("matplotlib")
    code, _, err = _cli(["plot", root / RUN, "--view", "range-doppler", "--frame", 999,
                         "--out", tmp_path / "x.png"], capsys)
    line = _one_error_line(err)
    assert code == 1 and "frame 999" in line and "2 frames" in line


def test_plot_unsupported_extension_fails_before_reading(root, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    code, _, err = _cli(["plot", root / RUN, "--view", "range-doppler", "--out",
                         tmp_path / "x.txt"], capsys)
    line = _one_error_line(err)
    assert code == 1 and "x.txt" in line and ".png" in line
    assert not (tmp_path / "x.txt").exists()


def test_missing_viz_extra_is_named(root, tmp_path, capsys, monkeypatch):
    # Simulate an install without matplotlib: importing it fails, and coloradar.viz is not
    # yet imported.
    for name in list(sys.modules):
        if name == "matplotlib" or name.startswith(("matplotlib.", "coloradar.viz")):
            monkeypatch.delitem(sys.modules, name)
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    code, _, err = _cli(["plot", root / RUN, "--view", "range-doppler", "--out",
                         tmp_path / "x.png"], capsys)
    assert code == 1 and "coloradar[viz]" in _one_error_line(err)
    with pytest.raises(MissingDependencyError):
        import coloradar.viz
    with pytest.raises(ImportError):  # still an ImportError for existing callers
        import coloradar.viz  # noqa: F401


def test_output_that_is_a_file_or_under_a_file(root, tmp_path, capsys):
    afile = tmp_path / "afile"
    afile.write_text("keep me")
    code, _, err = _cli(["process", root / RUN, "--out", afile, "--quiet"], capsys)
    assert code == 1 and str(afile) in _one_error_line(err)
    code, _, err = _cli(["process", root / RUN, "--out", afile / "sub", "--quiet"], capsys)
    assert code == 1 and "is a file" in _one_error_line(err)
    if HAS_MATPLOTLIB:
        code, _, err = _cli(["plot", root / RUN, "--view", "range-doppler", "--out",
                             afile / "x.png"], capsys)
        assert code == 1 and "afile" in _one_error_line(err)
    code, _, err = _cli(["odometry", root / RUN, "--radar", "single_chip", "--out", afile,
                         "--quiet"], capsys)
    assert code == 1 and "expected an output folder" in _one_error_line(err)
    code, _, err = _cli(["odometry", root / RUN, "--radar", "single_chip", "--out",
                         afile / "sub", "--quiet"], capsys)
    assert code == 1 and "afile" in _one_error_line(err)
    assert afile.read_text() == "keep me"
    with pytest.raises(WriteError):
        fm.write_timestamps(afile / "timestamps.txt", np.zeros(2))


def test_map_checks_the_output_name_before_reading(root, tmp_path, capsys, monkeypatch):
    def no_reading(*a, **k):  # the name is refused before any frame is read
        raise AssertionError("read a frame")

    monkeypatch.setattr(cr.dataset.FrameStream, "read", no_reading)
    code, _, err = _cli(["map", root / RUN, "--out", tmp_path / "m.txt"], capsys)
    assert code == 1 and ".pcd or .ply" in _one_error_line(err)


def test_cfar_window_settings(root, tmp_path, capsys):
    # One number is the same window on both axes; three numbers are an error, not a traceback.
    code, _, err = _cli(["process", root / RUN, "--out", tmp_path / "a", "--radar", "cascade",
                         "--set", "cfar_guard=1", "--jobs", "1", "--quiet"], capsys)
    assert code == 0, err
    manifest = json.loads((tmp_path / "a" / "process_manifest.json").read_text())
    assert manifest["products"]["cascade/heatmaps"]["settings"]["cfar_guard"] == [1, 1]
    code, _, err = _cli(["process", root / RUN, "--out", tmp_path / "b", "--set",
                         "cfar_guard=1,2,3", "--quiet"], capsys)
    assert code == 2 and "cfar_guard" in _one_error_line(err)   # a usage error: exit 2
    with pytest.raises(SettingsError):
        cr.dsp.ProcessingSettings(cfar_train=(2, 8, 1))


def test_corrupt_odometry_json(root, tmp_path, capsys):
    folder = tmp_path / "odo"
    folder.mkdir()
    (folder / "odometry.json").write_text("{not json")
    code, _, err = _cli(["evaluate", folder], capsys)
    line = _one_error_line(err)
    assert code == 1 and "odometry.json" in line
    with pytest.raises(FormatError):
        cr.odometry.evaluate_odometry(folder)


def test_closed_pipe_is_not_a_traceback(root):
    # `coloradar info ROOT | head -1`: the reader goes away before everything is written.
    p = subprocess.Popen([sys.executable, "-m", "coloradar", "info", str(root)],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()
    err = p.stderr.read().decode()
    p.stderr.close()
    code = p.wait(60)
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    assert code == 141


# --- errors raised by the library ---------------------------------------------------------------

def test_bad_settings_and_arguments_are_settings_errors(root):
    rc = preset_calibration().cascade
    cases = [
        lambda: cr.dsp.RadarProcessor(rc, range_window="bogus"),
        lambda: cr.dsp.RadarProcessor(rc, pfa=2.0),
        lambda: cr.dsp.cfar_scale("ca", 0, 1e-4),
        lambda: cr.geometry.voxel_downsample(np.zeros((3, 3)), -1.0),
        lambda: cr.odometry.EgoVelocityConfig(threshold=-1.0),
        lambda: make_trajectory(None, "bogus"),  # type: ignore[arg-type]
    ]
    for case in cases:
        with pytest.raises(SettingsError) as exc:
            case()
        assert isinstance(exc.value, ValueError) and isinstance(exc.value, ColoradarError)


def test_subpackages_are_attributes_and_import_stays_light():
    import coloradar

    assert coloradar.dsp.RadarProcessor is not None and coloradar.geometry.SE3 is not None
    with pytest.raises(AttributeError):
        coloradar.no_such_thing
    code = ("import sys, coloradar; "
            "assert 'coloradar.dsp' not in sys.modules and 'matplotlib' not in sys.modules; "
            "import coloradar as cr; cr.dsp; assert 'coloradar.dsp' in sys.modules")
    subprocess.run([sys.executable, "-c", code], check=True)


# --- resume after the input changed ---------------------------------------------------------------

def test_rewritten_input_frames_are_processed_again(copy, tmp_path, capsys):
    run, out = copy / RUN, tmp_path / "out"
    argv = ["process", run, "--out", out, "--radar", "cascade", "--products", "heatmaps",
            "--jobs", "1", "--quiet"]
    assert _cli(argv, capsys)[0] == 0
    hm1 = out / "cascade" / "heatmaps" / "data" / "heatmap_1.bin"
    hm0 = out / "cascade" / "heatmaps" / "data" / "heatmap_0.bin"
    before0 = hm0.read_bytes()
    # Re-simulate frame 1: another frame in the same file name (same size).
    frame1 = run / "cascade" / "adc_samples" / "data" / "frame_1.bin"
    rc = preset_calibration().cascade
    new = np.full(rc.frame_shape, 100 + 50j, dtype=np.complex64)
    fm.write_adc(frame1, new)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert _cli(argv, capsys)[0] == 0
    assert any("frame 1" in str(w.message) and "changed" in str(w.message) for w in caught)
    rep = json.loads((out / "process_report.json").read_text())["runs"][RUN]["radars"]["cascade"]
    assert (rep["done"], rep["skipped"]) == (1, 1)
    # The redone frame is what the processor makes of the new input; the other is untouched.
    expected = cr.dsp.RadarProcessor(rc).heatmap(new)
    got = fm.read_heatmap(hm1, expected.shape[:3])
    np.testing.assert_array_equal(got, expected)
    assert hm0.read_bytes() == before0
    # Unchanged input: resumed, nothing redone.
    assert _cli(argv, capsys)[0] == 0
    rep = json.loads((out / "process_report.json").read_text())["runs"][RUN]["radars"]["cascade"]
    assert (rep["done"], rep["skipped"]) == (0, 2)


# --- commands that walk frames ----------------------------------------------------------------

def test_info_checks_sizes_and_reports_every_bad_run(root, tmp_path, capsys):
    ds = tmp_path / "ds"
    shutil.copytree(root / "calib", ds / "calib")
    for name in ("a_run0", "b_run1", "c_run2"):
        shutil.copytree(root / RUN, ds / name)
    bad = ds / "a_run0" / "cascade" / "heatmaps" / "data" / "heatmap_1.bin"
    bad.write_bytes(bad.read_bytes()[:1000])
    (ds / "b_run1" / "imu" / "timestamps.txt").write_text("not a number\n")
    code, out, err = _cli(["info", ds], capsys)
    assert code == 1 and "Traceback" not in err
    assert str(bad) in out and "1,000 bytes" in out
    assert "b_run1" in out and "imu" in out and "unreadable" in out
    assert "run c_run2" in out                      # the runs after the bad ones are reported
    assert "2 of 3 runs" in err
    code, out, _ = _cli(["info", ds / "c_run2"], capsys)
    assert code == 0 and "!" not in out


def test_map_and_odometry_skip_and_report_a_bad_frame(copy):
    lidar = copy / RUN / "lidar" / "pointclouds" / "lidar_pointcloud_1.bin"
    lidar.write_bytes(b"\0" * 7)
    seq = cr.open_sequence(copy / RUN)
    with pytest.warns(DataWarning, match="lidar_pointcloud_1.bin"):
        m = cr.geometry.build_map(seq, "lidar")
    assert 1 not in m.frame_indices.tolist() and m.frame_indices.size == 2
    good = [seq.lidar.pointclouds[i] for i in m.frame_indices]
    assert m.points.shape[0] == sum(c.shape[0] for c in good)   # every good point, once
    pc = copy / RUN / "single_chip" / "pointclouds" / "data" / "radar_pointcloud_2.bin"
    pc.write_bytes(b"\0" * 7)
    with pytest.warns(DataWarning, match="radar_pointcloud_2.bin"):
        track = cr.odometry.run_ego_velocity(seq, "single_chip", "pointclouds")
    assert len(track) == 3 and not track.ok[2] and "radar_pointcloud_2.bin" in track.reasons[2]


def test_animation_scenes_skip_and_report_a_bad_frame(copy):
    pytest.importorskip("matplotlib")
    from coloradar.viz import gather_scene

    lidar = copy / RUN / "lidar" / "pointclouds" / "lidar_pointcloud_1.bin"
    lidar.write_bytes(b"\0" * 7)
    seq = cr.open_sequence(copy / RUN)
    t_bad = float(seq.lidar.pointclouds.timestamps[1])
    cache: dict = {}
    with pytest.warns(DataWarning, match="lidar_pointcloud_1.bin"):
        scene = gather_scene(seq, t_bad, cache=cache)
    assert scene.lidar is None and "lidar/pointclouds" not in scene.sources
    assert scene.radars  # the other sensors are still drawn
    t_good = float(seq.lidar.pointclouds.timestamps[2])
    assert gather_scene(seq, t_good, cache=cache).lidar is not None


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs on this platform")
def test_every_file_reader_refuses_a_fifo(tmp_path):
    from coloradar.sim.scene import load_scene

    readers = {"map.pcd": cr.geometry.read_point_file, "map.ply": cr.geometry.read_point_file,
               "trajectory.txt": cr.odometry.read_tum, "scene.json": load_scene,
               "run.zip": cr.open_sequence}
    for name, reader in readers.items():
        fifo = tmp_path / name
        os.mkfifo(fifo)
        exc = _finishes(lambda reader=reader, fifo=fifo: reader(fifo))
        assert isinstance(exc, ReadError) and str(fifo) in str(exc), (name, exc)
