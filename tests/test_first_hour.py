"""What a new user meets in the first hour with real data (issue 17): every fault of the data or
of the command line is said, in one line naming the file (or the option), and nothing is lost or
passed on silently."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

import coloradar as cr
from _synth import write_run, zip_folder
from coloradar import formats as fm
from coloradar.calib import load_calibration, preset_calibration, write_calibration
from coloradar.cli.main import main
from coloradar.errors import CalibrationWarning, DataWarning, FormatError, MissingDataError, ReadError
from coloradar.geometry import VoxelAccumulator, accumulate_clouds, build_map
from coloradar.geometry.se3 import SE3

RUN = "12_21_2020_ec_hallways_run0"
SRC = str(Path(cr.__file__).resolve().parents[1])


@pytest.fixture(scope="module")
def root(tmp_path_factory) -> Path:
    r = tmp_path_factory.mktemp("first_hour")
    write_run(r, RUN, n_cascade=3, n_single=4, n_lidar=4, n_imu=60, n_gt=12)
    return r


@pytest.fixture
def copy(root, tmp_path) -> Path:
    dst = tmp_path / "root"
    shutil.copytree(root, dst)
    return dst


def _cli(argv, capsys) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return code, out, err


def _set_line(path: Path, lineno: int, text: str) -> None:
    lines = path.read_text().splitlines()
    lines[lineno - 1] = text
    path.write_text("\n".join(lines) + "\n")


# --- non-finite rows of the IMU and pose tables ---------------------------------------------------

def test_a_nan_imu_row_is_left_out_with_a_warning_naming_file_and_line(copy):
    run = copy / RUN
    imu_file = run / "imu" / "imu_data.txt"
    truth = np.loadtxt(imu_file)
    _set_line(imu_file, 7, "nan nan nan nan nan nan")
    with pytest.warns(DataWarning, match=r"imu_data\.txt, line 7: .*not finite.*1 IMU row"):
        imu = cr.open_sequence(run).imu
    assert len(imu) == 59 and np.all(np.isfinite(imu.data))
    keep = np.r_[0:6, 7:60]
    np.testing.assert_array_equal(imu.data, truth[keep])        # nothing else lost or moved
    t = np.loadtxt(run / "imu" / "timestamps.txt")
    np.testing.assert_array_equal(imu.timestamps, t[keep])


def test_odometry_runs_on_an_imu_with_a_nan_row(tmp_path, capsys):
    # Before: `ValueError: Found zero norm quaternions` from the dead reckoning, a traceback.
    from coloradar.sim.run import simulate_run

    run = simulate_run(tmp_path / "sim", duration=2.0, seed=4, heatmaps=False,
                       sensors=["single_chip", "imu", "groundtruth"]).run_path
    _set_line(run / "imu" / "imu_data.txt", 200, "nan 0 0 nan nan nan")
    with pytest.warns(DataWarning, match=r"imu_data\.txt, line 200"):
        code, _, err = _cli(["odometry", run, "--radar", "single_chip", "--out",
                             tmp_path / "odo", "--quiet"], capsys)
    assert code == 0, err
    assert (tmp_path / "odo" / "trajectory.txt").is_file()


def test_imu_timestamps_out_of_order_leave_out_the_fewest_samples(copy):
    ts_file = copy / RUN / "imu" / "timestamps.txt"
    t = np.loadtxt(ts_file)
    _set_line(ts_file, 10, f"{t[30]:.9f}")          # one stray time, far ahead
    _set_line(ts_file, 40, f"{t[38]:.9f}")          # a duplicate
    with pytest.warns(DataWarning, match=r"timestamps\.txt, lines 10, (39|40): .*2 sample\(s\) left out"):
        imu = cr.open_sequence(copy / RUN).imu
    assert len(imu) == 58 and np.all(np.diff(imu.timestamps) > 0)


def test_a_nan_pose_row_is_left_out_not_a_quaternion_error(copy):
    gt = copy / RUN / "groundtruth" / "groundtruth_poses.txt"
    _set_line(gt, 4, "nan nan nan nan nan nan nan")
    with pytest.warns(DataWarning, match=r"groundtruth_poses\.txt, line 4"):
        poses = cr.open_sequence(copy / RUN).groundtruth
    assert len(poses) == 11 and np.all(np.isfinite(poses.poses))
    # A finite quaternion that is not a unit one is still an error, naming the file's line.
    _set_line(gt, 9, "0 0 0 0 0 0 2")
    with pytest.raises(FormatError, match=r"groundtruth_poses\.txt, line 9: quaternion norm"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            cr.open_sequence(copy / RUN).groundtruth


# --- timestamps of frame streams ------------------------------------------------------------------

def test_a_nan_radar_timestamp_leaves_its_frame_out_and_info_says_so(copy, capsys):
    ts_file = copy / RUN / "cascade" / "adc_samples" / "timestamps.txt"
    t = np.loadtxt(ts_file)
    _set_line(ts_file, 2, "nan")
    with pytest.warns(DataWarning, match=r"adc_samples/timestamps\.txt, line 2: timestamp nan"):
        adc = cr.open_sequence(copy / RUN).cascade.adc
    assert len(adc) == 2 and adc.frame_ids.tolist() == [0, 2]
    np.testing.assert_array_equal(adc.timestamps, t[[0, 2]])
    code, out, _ = _cli(["info", copy / RUN], capsys)
    assert code == 1
    assert any(ln.lstrip().startswith("!") and "line 2" in ln and "nan" in ln
               for ln in out.splitlines())


def test_process_skips_a_frame_without_a_time_and_writes_none_with_nan(copy, tmp_path, capsys):
    ts_file = copy / RUN / "cascade" / "adc_samples" / "timestamps.txt"
    _set_line(ts_file, 2, "nan")
    out = tmp_path / "out"
    with pytest.warns(DataWarning, match=r"timestamps\.txt, line 2: timestamp nan"):
        code, _, err = _cli(["process", copy / RUN, "--out", out, "--radar", "cascade",
                             "--jobs", 1, "--quiet"], capsys)
    # Not processed, and not silent: a failed frame in the report and on stderr, exit 1.
    assert code == 1, err
    assert "frame_1.bin" in err and "not a finite number" in err
    report = json.loads((out / "process_report.json").read_text())
    fails = [f for run in report["runs"].values() for r in run["radars"].values()
             for f in r["failures"]]
    assert [(f["frame_id"], f["position"]) for f in fails] == [(1, -1)]
    assert sorted(p.name for p in (out / "cascade" / "heatmaps" / "data").iterdir()) == [
        "heatmap_0.bin", "heatmap_2.bin"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        hm = cr.open_sequence(copy / RUN, products=out).cascade.heatmaps
    # Every frame that was written has its ADC frame's own, finite time.
    assert hm.frame_ids.tolist() == [0, 2] and np.all(np.isfinite(hm.timestamps))
    np.testing.assert_array_equal(hm.timestamps, np.loadtxt(ts_file)[[0, 2]])


def test_duplicated_frame_timestamps_are_said_and_info_exits_1(copy, capsys):
    ts_file = copy / RUN / "single_chip" / "pointclouds" / "timestamps.txt"
    t = ts_file.read_text().splitlines()
    _set_line(ts_file, 3, t[1])
    with pytest.warns(DataWarning, match=r"pointclouds/timestamps\.txt, line 3: duplicated"):
        pc = cr.open_sequence(copy / RUN).single_chip.pointclouds
    assert len(pc) == 4                                  # kept: each frame is worth its file
    code, out, _ = _cli(["info", copy / RUN], capsys)
    assert code == 1 and "line 3: duplicated" in out


def test_empty_timestamps_beside_frame_files_is_an_error(copy, tmp_path, capsys):
    # Before: "nothing to do", exit 0.
    ts_file = copy / RUN / "cascade" / "adc_samples" / "timestamps.txt"
    ts_file.write_text("")
    code, _, err = _cli(["process", copy / RUN, "--out", tmp_path / "out", "--radar", "cascade",
                         "--quiet"], capsys)
    line = [ln for ln in err.splitlines() if ln.startswith("coloradar: error:")]
    assert code == 1 and len(line) == 1
    assert str(ts_file) in line[0] and "3 frame_<i>.bin frame files" in line[0]
    code, out, _ = _cli(["info", copy / RUN], capsys)
    assert code == 1 and "no timestamps" in out
    ts_file.write_text("nan\nnan\nnan\n")             # as good as none
    with pytest.raises(FormatError, match="none of its 3 timestamps is a finite time"):
        cr.open_sequence(copy / RUN).cascade.adc


# --- calibration that is not the run's own --------------------------------------------------------

def test_a_missing_extrinsic_is_said_and_the_map_says_it_again(copy, tmp_path, capsys):
    (copy / "calib" / "transforms" / "base_to_lidar.txt").unlink()
    with pytest.warns(CalibrationWarning, match=r"base_to_lidar\.txt.*preset extrinsic of lidar"):
        calib = load_calibration(copy / "calib")
    assert calib.presets == ("lidar extrinsic",)
    code, out, err = _cli(["map", copy / RUN, "--out", tmp_path / "m.pcd", "--quiet"], capsys)
    assert code == 0 and out == ""
    assert "note: calibration: built-in preset for lidar extrinsic" in err
    code, out, _ = _cli(["info", copy / RUN], capsys)
    assert "built-in presets" in out and "lidar extrinsic" in out


def test_no_calib_folder_names_every_preset_value(copy, tmp_path, capsys):
    shutil.rmtree(copy / "calib")
    with pytest.warns(CalibrationWarning, match=r"built-in sensor presets for every value.*"
                                                r"extrinsics of cascade, single_chip, lidar"):
        seq = cr.open_sequence(copy / RUN)
    assert "cascade radar" in seq.calib.presets and "imu extrinsic" in seq.calib.presets
    code, _, err = _cli(["map", copy / RUN, "--out", tmp_path / "m.pcd", "--quiet"], capsys)
    assert code == 0 and "preset for lidar extrinsic" in err
    # A complete calibration has no presets, and says nothing.
    with warnings.catch_warnings():
        warnings.simplefilter("error", CalibrationWarning)
        write_calibration(preset_calibration(), tmp_path / "full")
        assert load_calibration(tmp_path / "full").presets == ()


# --- map: memory and radar points -----------------------------------------------------------------

def test_voxel_accumulator_matches_a_brute_force_mean_of_frame_centroids():
    rng = np.random.default_rng(3)
    size = 0.5
    clouds = [rng.uniform(-2, 2, (int(rng.integers(50, 300)), 4)).astype(np.float32)
              for _ in range(6)]
    acc = VoxelAccumulator(size)
    for c in clouds:
        acc.add(c)
    # Brute force: per frame, each voxel's centroid; per voxel, the mean over frames.
    per_voxel: dict[tuple, list] = {}
    for c in clouds:
        groups: dict[tuple, list] = {}
        for p in c.astype(np.float64):
            groups.setdefault(tuple(np.floor(p[:3] / size).astype(int)), []).append(p)
        for k, pts in groups.items():
            per_voxel.setdefault(k, []).append(np.mean(pts, axis=0))
    keys = sorted(per_voxel)
    expect = np.array([np.mean(per_voxel[k], axis=0) for k in keys])
    got = acc.points()
    assert got.dtype == np.float32 and got.shape == expect.shape
    np.testing.assert_allclose(got, expect, rtol=0, atol=1e-5)


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads Linux's VmHWM")
def test_map_memory_does_not_grow_with_the_number_of_scans():
    # Peak RSS of accumulating 10 and 40 synthetic scans (random points in a fixed room, as a
    # lidar sees the same walls again): the voxel map is bounded by the room, so should memory.
    # Before the accumulator the 40-scan peak was about twice the 10-scan one (110 -> 229 MB
    # measured; with it 80 -> 82 MB).
    script = textwrap.dedent("""
        import re, sys
        import numpy as np
        from coloradar.geometry import accumulate_clouds
        from coloradar.geometry.se3 import SE3
        n = int(sys.argv[1])
        rng = np.random.default_rng(0)
        def clouds():
            for _ in range(n):
                yield rng.uniform((-4, -4, -0.75, 0), (4, 4, 0.75, 1), (40000, 4)).astype(np.float32)
        m = accumulate_clouds(clouds(), [SE3.identity()] * n, voxel_size=0.1)
        # VmHWM: this process's own peak (ru_maxrss would carry the forking parent's over).
        hwm = re.search(r"VmHWM:\\s+(\\d+)", open("/proc/self/status").read()).group(1)
        print(m.shape[0], hwm)
    """)
    env = {**os.environ, "PYTHONPATH": SRC}
    peak = {}
    for n in (10, 40):
        res = subprocess.run([sys.executable, "-c", script, str(n)], capture_output=True,
                             text=True, env=env, timeout=300, check=True)
        voxels, peak[n] = map(int, res.stdout.split())
        assert voxels > 90_000                 # the room's 96,000 voxels, nearly all seen
    assert peak[40] <= 1.2 * peak[10], peak


def test_map_of_the_cascade_computes_points_from_adc(root, tmp_path, capsys):
    # Before: "no cascade/pointclouds stream ... --products OUT".
    seq = cr.open_sequence(root / RUN)
    m = build_map(seq, "cascade")
    assert m.points_from == "adc" and m.fields[-1] == "range_rate"
    # Independently: each frame's points through the processor, moved by the interpolated
    # ground truth and the cascade's extrinsic, stacked.
    from coloradar.dsp import RadarProcessor
    from coloradar.geometry import sensor_to_base, trajectory_from_groundtruth

    proc = RadarProcessor(seq.calib.cascade)
    traj = trajectory_from_groundtruth(seq)
    mount = sensor_to_base(seq.calib, "cascade")
    ts = seq.cascade.adc.timestamps[m.frame_indices]
    trans, rot = traj.interpolate_arrays(ts)
    parts = [(SE3(rot[k], trans[k]) @ mount).apply_to_cloud(proc.pointcloud(seq.cascade.adc[int(i)]))
             for k, i in enumerate(m.frame_indices)]
    np.testing.assert_allclose(m.points, np.concatenate(parts), atol=1e-4)
    code, out, _ = _cli(["map", root / RUN, "--sensor", "cascade", "--out", tmp_path / "c.ply"],
                        capsys)
    assert code == 0 and "computed from their ADC" in out


def test_accumulate_without_voxels_keeps_every_point():
    rng = np.random.default_rng(1)
    clouds = [rng.standard_normal((20, 4)).astype(np.float32) for _ in range(3)]
    out = accumulate_clouds(clouds, [SE3.identity()] * 3)
    np.testing.assert_array_equal(out, np.concatenate(clouds))


# --- the command line -----------------------------------------------------------------------------

def test_overwrite_is_said_as_the_option_on_the_command_line(root, tmp_path, capsys):
    out = tmp_path / "m.pcd"
    out.write_text("keep")
    code, _, err = _cli(["map", root / RUN, "--out", out], capsys)
    assert code == 1 and "pass --overwrite" in err and "overwrite=True" not in err
    assert out.read_text() == "keep"
    with pytest.raises(cr.OutputExistsError, match=r"overwrite=True \(--overwrite\)"):
        fm.atomic.new_output_path(out, False)          # API callers keep the Python wording


def _exit_code(args) -> int:
    try:
        return main(args)
    except SystemExit as exc:  # argparse's own checks
        return int(exc.code or 0)


@pytest.mark.parametrize("argv", [
    ["process", "{run}", "--out", "{tmp}/o", "--jobs", "2", "--scheduler", "tcp://h:1"],
    ["process", "{run}", "--out", "{tmp}/o", "--set", "cfar_guard=1,2,3"],
    ["process", "{run}", "--out", "{tmp}/o", "--jobs", "0"],
    ["map", "{run}", "--out", "{tmp}/o.pcd", "--voxel", "0"],
    ["map", "{run}", "--out", "{tmp}/o.pcd", "--stride", "0"],
    ["animate", "{run}", "--out", "{tmp}/o.gif", "--fps", "-1"],
    ["simulate"],
])
def test_usage_errors_exit_2_whichever_check_finds_them(root, tmp_path, capsys, argv):
    # Before: the checks coloradar made itself (--jobs with --scheduler, --set values, a
    # missing OUT) exited 1 where argparse's exit 2; --voxel 0 and --stride 0 were accepted.
    code = _exit_code([a.format(run=root / RUN, tmp=tmp_path) for a in argv])
    _, err = capsys.readouterr()
    assert code == 2 and "Traceback" not in err and "error:" in err
    assert not any(p.name.startswith("o") for p in tmp_path.iterdir())


def test_failed_frames_are_listed_on_stderr(copy, tmp_path, capsys):
    bad = copy / RUN / "cascade" / "adc_samples" / "data" / "frame_1.bin"
    bad.write_bytes(bad.read_bytes()[:-8])
    code, out, err = _cli(["process", copy / RUN, "--out", tmp_path / "o", "--radar", "cascade",
                           "--jobs", 1, "--quiet"], capsys)
    assert code == 1
    assert "failed:" in err and "frame_1.bin" in err and "failed:" not in out
    assert "2 frames processed" in out


def test_quiet_plot_map_animate_print_nothing_on_success(root, tmp_path, capsys):
    code, out, err = _cli(["map", root / RUN, "--out", tmp_path / "m.pcd", "--quiet"], capsys)
    assert code == 0 and out == "" and "frames/s" not in err
    pytest.importorskip("matplotlib")
    code, out, err = _cli(["plot", root / RUN, "--view", "heatmap", "--out", tmp_path / "p.png",
                           "--quiet"], capsys)
    assert code == 0 and out == "" and (tmp_path / "p.png").stat().st_size > 0
    code, out, err = _cli(["animate", root / RUN, "--out", tmp_path / "a.gif", "--quiet",
                           "--duration", "0.3", "--fps", "5", "--dpi", "30"], capsys)
    assert code == 0 and out == "" and "pictures" not in err


def test_plot_help_shows_the_default_frame(capsys):
    with pytest.raises(SystemExit):
        main(["plot", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "--frame FRAME frame index" in out and "default: 0" in out


def test_messages_print_plain_numbers_not_numpy_reprs(tmp_path):
    calib = tmp_path / "calib"
    write_calibration(preset_calibration(), calib)
    path = calib / "single_chip" / "heatmap_cfg.txt"
    text = path.read_text().splitlines()
    i = next(k for k, ln in enumerate(text) if ln.startswith("azimuth_bins"))
    for value, expect in (("nan", "is nan"), ("7", "from 7 to 7")):
        text[i] = "azimuth_bins " + " ".join([value] * 64)
        path.write_text("\n".join(text) + "\n")
        with pytest.raises(cr.CalibrationError) as exc:
            load_calibration(calib)
        assert "np." not in str(exc.value) and expect in str(exc.value)


# --- inputs that are not what they seem -----------------------------------------------------------

def test_a_symlink_loop_a_fifo_and_a_truncated_zip_are_said_as_such(root, tmp_path, capsys):
    loop = tmp_path / "loop"
    os.symlink(tmp_path / "loop2", loop)
    os.symlink(loop, tmp_path / "loop2")
    dangling = tmp_path / "dangling"
    os.symlink(tmp_path / "nowhere", dangling)
    truncated = tmp_path / "run.zip"
    zip_folder(root / RUN, truncated)
    data = truncated.read_bytes()
    truncated.write_bytes(data[: len(data) // 2])
    notzip = tmp_path / "notes.zip"
    notzip.write_text("hello")
    cases = [(loop, MissingDataError, "loop of symbolic links"),
             (dangling, MissingDataError, "symbolic link to"),
             (truncated, FormatError, "zip archive cut short"),
             (notzip, FormatError, "not a zip archive")]
    if hasattr(os, "mkfifo"):
        fifo = tmp_path / "fifo"
        os.mkfifo(fifo)
        cases.append((fifo, ReadError, "a FIFO (named pipe)"))
    for path, exc_type, text in cases:
        with pytest.raises(exc_type, match=re.escape(text)):
            cr.open_sequence(path)
        for cmd in (["info", path], ["process", path, "--out", tmp_path / "o", "--quiet"]):
            code, _, err = _cli(cmd, capsys)
            assert code == 1 and text in err and "dataset root folder not found" not in err, err
    assert zipfile.is_zipfile(tmp_path / "run.zip") is False


# ------------------------------------------------------------ issue 41, items 12 and 13
def _doc_texts() -> dict[str, str]:
    root = Path(__file__).resolve().parents[1]
    return {p.name: p.read_text(encoding="utf-8")
            for p in [root / "README.md", *sorted((root / "docs").glob("*.md"))]}


def test_quick_starts_show_the_progress_of_long_jobs():
    """docs/slam.md's quick start simulates 3 minutes of data: with --quiet a newcomer saw
    nothing for minutes. No quick-start command is silenced."""
    for name, text in _doc_texts().items():
        for line in text.splitlines():
            if line.startswith("$ coloradar simulate") and "--duration" not in line:
                assert "--quiet" not in line, (name, line)


def test_paths_outside_the_repository_are_explained():
    """Every ../shared/ folder a doc names is explained in the README's section on data we did
    not write (what it is, that it lies beside the repository, which tests read it)."""
    texts = _doc_texts()
    readme = texts["README.md"]
    assert "## Data we did not write" in readme
    section = readme.split("## Data we did not write", 1)[1]
    named = {m.group(1).rstrip("/.") for text in texts.values()
             for m in re.finditer(r"\.\./shared/((?:real|reference|foreign)(?:/[\w.-]+)?)", text)}
    for folder in sorted(named):
        top = "/".join(folder.split("/")[:2])
        assert f"../shared/{top}" in section, folder


# --------------------------------------------------------------------- issue 41, item 6
@pytest.fixture(scope="module")
def one_radar_runs(tmp_path_factory):
    from coloradar.sim.run import simulate_run

    out = tmp_path_factory.mktemp("one_radar")
    runs = {}
    for radar, seed in (("cascade", 1), ("single_chip", 2)):
        res = simulate_run(out / radar, scene="corridor", duration=8.0, seed=seed, rest=1.0,
                           sensors=[radar, "imu", "groundtruth"], heatmaps=False)
        runs[radar] = res.run_path
    return runs


def test_slam_and_odometry_take_the_only_radar_a_run_has(one_radar_runs, tmp_path, capsys):
    """slam defaults to the single chip and odometry to the cascade: on a run with the other
    radar alone they used to fail ("the single_chip radar has no point clouds…"); they take
    the radar the run has and say so."""
    pytest.importorskip("gtsam")
    assert main(["slam", str(one_radar_runs["cascade"]), "--out", str(tmp_path / "s"),
                 "--no-plot"]) == 0
    err = capsys.readouterr().err
    assert "cascade radar only" in err and "--radar cascade" in err
    assert json.loads((tmp_path / "s" / "odometry.json").read_text())["radar"] == "cascade"
    assert main(["odometry", str(one_radar_runs["single_chip"]), "--out",
                 str(tmp_path / "o")]) == 0
    assert "single_chip radar only" in capsys.readouterr().err


def test_a_radar_without_data_names_the_one_the_run_has(one_radar_runs, tmp_path, capsys):
    assert main(["odometry", str(one_radar_runs["single_chip"]), "--radar", "cascade",
                 "--out", str(tmp_path / "o")]) == 1
    assert "pass --radar single_chip" in capsys.readouterr().err


def test_the_readme_opens_with_the_first_hour():
    """Issue 41, item 11: the first screen is what a newcomer does first — the two set-up
    commands with how long they take, then the first-hour path with each step's time — not a
    paragraph of speed claims."""
    text = _doc_texts()["README.md"]
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.startswith("## Your first hour"))
    first = "\n".join(lines[:start])
    assert start < 30 and "coloradar demo" in first and "pytest -q" in first
    assert re.search(r"Command 2 takes about \d+ minutes", first)
    assert text.index("faster than") > text.index("## Your first hour")   # claims come later
    steps = [ln for ln in lines[start:start + 20] if re.match(r"\| \d\. ", ln)]
    assert len(steps) >= 6 and all(re.search(r"\d+(\.\d+)? s", ln) for ln in steps), steps
