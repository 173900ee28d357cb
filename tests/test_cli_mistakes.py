"""What a new (or tired) user meets (issue 27): no wrong number with exit 0, nothing written
into the dataset, no advice to overwrite a run, Ctrl-C that stops, one rule for failed frames."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import types
import warnings
from pathlib import Path

import numpy as np
import pytest

import coloradar as cr
from _synth import write_run
from coloradar import formats as fm
from coloradar.cli.main import main
from coloradar.errors import DataWarning, FormatError
from coloradar.formats.atomic import default_file_mode
from coloradar.learning.scoring import read_prediction

RUN = "12_21_2020_ec_hallways_run0"
SRC = str(Path(cr.__file__).resolve().parents[1])


@pytest.fixture(scope="module")
def root(tmp_path_factory) -> Path:
    r = tmp_path_factory.mktemp("mistakes")
    write_run(r, RUN, n_cascade=2, n_single=6, n_lidar=4, n_imu=60, n_gt=12)
    return r


def _tree(folder: Path) -> dict[str, int]:
    return {p.relative_to(folder).as_posix(): p.stat().st_mtime_ns for p in folder.rglob("*")}


def _cli(argv, capsys) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    return code, out, err


# -- 1: score knows the columns of coloradar's own point clouds ----------------------------------
def test_score_reads_processed_radar_point_clouds_as_five_columns(tmp_path):
    pts = np.arange(15, dtype=np.float32).reshape(3, 5)     # 15 values: also 5 rows of 3
    fm.write_radar_pointcloud(tmp_path / "radar_pointcloud_7.bin", pts)
    np.testing.assert_array_equal(read_prediction(tmp_path / "radar_pointcloud_7.bin"),
                                  pts[:, :3])
    lid = np.arange(12, dtype=np.float32).reshape(3, 4)     # 12 values: also 4 rows of 3
    fm.write_lidar_pointcloud(tmp_path / "lidar_pointcloud_1.bin", lid)
    np.testing.assert_array_equal(read_prediction(tmp_path / "lidar_pointcloud_1.bin"),
                                  lid[:, :3])
    (tmp_path / "heatmaps" / "data").mkdir(parents=True)
    (tmp_path / "heatmaps" / "data" / "heatmap_3.bin").write_bytes(bytes(4 * 6))
    with pytest.raises(FormatError, match="heatmap"):
        read_prediction(tmp_path / "heatmaps" / "data" / "heatmap_3.bin")
    # A prediction of the user's own named frame_<i>.bin (outside adc_samples/) is xyz rows.
    xyz = np.arange(6, dtype=np.float32).reshape(2, 3)
    xyz.tofile(tmp_path / "frame_000012.bin")
    np.testing.assert_array_equal(read_prediction(tmp_path / "frame_000012.bin"), xyz)


def test_score_refuses_a_bad_file_before_scoring_anything(root, tmp_path, capsys, monkeypatch):
    import coloradar.learning.scoring as scoring

    pred = tmp_path / "pred"
    fm.write_radar_pointcloud(pred / "radar_pointcloud_0.bin", np.ones((4, 5), np.float32))
    (pred / "radar_pointcloud_1.bin").write_bytes(np.ones(7, np.float32).tobytes())

    def no_targets(*a, **k):
        raise AssertionError("targets were built before the files were checked")

    monkeypatch.setattr(scoring, "SyncedSamples", no_targets)
    code, out, err = _cli(["score", pred, root / RUN, "--radar", "single_chip",
                           "--out", tmp_path / "s.json"], capsys)
    assert code == 1 and "radar_pointcloud_1.bin" in err and "rows of 5" in err
    assert not (tmp_path / "s.json").exists() and "Chamfer" not in out


# -- 2: evaluate refuses another run's ground truth -----------------------------------------------
def test_evaluate_refuses_a_run_other_than_the_odometrys(root, tmp_path, capsys):
    from coloradar.geometry import trajectory_from_groundtruth
    from coloradar.odometry.tum import write_tum

    other = tmp_path / "data" / "12_21_2020_ec_hallways_run1"
    shutil.copytree(root / RUN, other)
    shutil.copytree(root / "calib", other.parent / "calib")
    odo = tmp_path / "odo"
    write_tum(odo / "trajectory.txt", trajectory_from_groundtruth(cr.open_sequence(root / RUN)))
    (odo / "odometry.json").write_text(json.dumps({"run": str(root / RUN), "run_name": RUN}))
    code, _, err = _cli(["evaluate", odo, "--run", other, "--no-plot"], capsys)
    assert code == 2 and "names the run " + RUN in err and "--any-run" in err
    assert sorted(p.name for p in odo.iterdir()) == ["odometry.json", "trajectory.txt"]
    code, out, _ = _cli(["evaluate", odo, "--run", other, "--no-plot", "--any-run"], capsys)
    assert code == 0 and "12_21_2020_ec_hallways_run1" in out


def test_evaluate_warns_when_the_estimate_outlasts_the_ground_truth(root, tmp_path, capsys):
    from coloradar.geometry import trajectory_from_groundtruth
    from coloradar.geometry.trajectory import Trajectory
    from coloradar.odometry.tum import write_tum

    gt = trajectory_from_groundtruth(cr.open_sequence(root / RUN))
    span = gt.timestamps[-1] - gt.timestamps[0]
    est = Trajectory(gt.timestamps + span / 2, gt.translations, gt.rotations)  # half outside
    odo = tmp_path / "odo"
    write_tum(odo / "trajectory.txt", est)
    (odo / "odometry.json").write_text(json.dumps({"run": str(root / RUN), "run_name": RUN}))
    with pytest.warns(DataWarning, match="lie within the ground truth"):
        main(["evaluate", str(odo), "--no-plot", "--quiet"])
    capsys.readouterr()


# -- 4, 5: never into the dataset, inputs before outputs, no --overwrite for a run ----------------
@pytest.mark.parametrize("argv", [
    ["map", "{run}", "--out", "{run}/m.pcd"],
    ["export", "{run}", "{run}/x.bag"],
    ["export", "{run}", "{run}/x.h5"],
    ["odometry", "{run}", "--out", "{run}/odo"],
    ["process", "{run}", "--out", "{run}/processed"],
    ["process", "{root}", "--out", "{root}/processed"],
    ["process", "{run}", "--out", "{root}"],
    ["animate", "{run}", "--out", "{run}/lidar/v.gif"],
    ["score", "{root}", "{run}", "--out", "{run}/s.json"],
    ["simulate", "{run}/sim"],
    ["export", "{run}", "{root}/calib/x.bag"],
], ids=lambda a: " ".join(a))
def test_no_command_writes_into_the_dataset(root, argv, capsys):
    before = _tree(root)
    code, _, err = _cli([a.format(run=root / RUN, root=root) for a in argv], capsys)
    assert code != 0 and "never writes into a dataset" in err, err
    assert "--overwrite" not in err
    assert _tree(root) == before


def test_swapped_arguments_name_the_input_and_never_suggest_overwrite(root, tmp_path, capsys):
    code, _, err = _cli(["export", tmp_path / "out.bag", root / RUN, "--format", "ros1"], capsys)
    assert code == 1 and "out.bag" in err and "no such" in err and "--overwrite" not in err
    second = tmp_path / "run1"
    shutil.copytree(root / RUN, second)
    before = _tree(second)
    code, _, err = _cli(["export", root / RUN, second, "--format", "ros2"], capsys)
    assert code == 1 and "is a ColoRadar run" in err and "--overwrite" not in err
    assert _tree(second) == before


# -- 6: atomic writes get the mode of a plain open ------------------------------------------------
def test_atomic_outputs_get_the_mode_a_plain_open_gives(root, tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")      # the .rrd writer lives in coloradar.viz
    from coloradar.formats.atomic import atomic_output

    with atomic_output(tmp_path / "a.bin") as tmp:
        tmp.write_bytes(b"x")
    assert (tmp_path / "a.bin").stat().st_mode & 0o777 == default_file_mode()
    (tmp_path / "plain").write_bytes(b"x")
    assert default_file_mode() == (tmp_path / "plain").stat().st_mode & 0o777

    class Anything:  # every rerun call the recorder makes, accepted and ignored
        def __init__(self, *a, **k):
            pass

        def __getattr__(self, name):
            return Anything()

        def __call__(self, *a, **k):
            return Anything()

        def save(self, path):
            Path(path).write_bytes(b"RRD")

    fake = types.ModuleType("rerun")
    fake.__getattr__ = lambda name: Anything()  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "rerun", fake)
    from coloradar.viz.rerun_log import log_run_rrd

    out = log_run_rrd(cr.open_sequence(root / RUN), tmp_path / "run.rrd")
    assert out.read_bytes() == b"RRD"
    assert out.stat().st_mode & 0o777 == default_file_mode()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


# -- 7: the export's format ----------------------------------------------------------------------
def test_export_format_follows_the_suffix_and_a_contradiction_is_refused(root, tmp_path, capsys):
    code, _, err = _cli(["export", root / RUN, tmp_path / "x.bag", "--format", "hdf5"], capsys)
    assert code == 2 and "--format hdf5" in err and not (tmp_path / "x.bag").exists()
    code, _, err = _cli(["export", root / RUN, tmp_path / "x.h5", "--format", "ros1"], capsys)
    assert code == 2 and not (tmp_path / "x.h5").exists()
    code, _, err = _cli(["export", root / RUN, tmp_path / "x"], capsys)
    assert code == 2 and "--format" in err
    with pytest.raises(SystemExit):
        main(["--help"])
    assert "HDF5" in capsys.readouterr().out


# -- 8: one rule for the timestamps of frames that produced nothing -------------------------------
def test_a_failed_frame_reads_nan_and_the_reader_does_not_warn(root, tmp_path, capsys):
    data = tmp_path / "data"
    shutil.copytree(root / RUN, data / RUN)
    shutil.copytree(root / "calib", data / "calib")
    frame = data / RUN / "single_chip" / "adc_samples" / "data" / "frame_2.bin"
    frame.write_bytes(frame.read_bytes()[:1000])              # truncated
    ts_file = data / RUN / "single_chip" / "adc_samples" / "timestamps.txt"
    lines = ts_file.read_text().splitlines()
    lines[4] = "nan"                                          # frame 4 has no time
    ts_file.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        code, _, _ = _cli(["process", data / RUN, "--out", out, "--radar", "single_chip",
                           "--jobs", 1, "--quiet"], capsys)
    assert code == 1
    for prod in ("heatmaps", "pointclouds"):
        written = (out / "single_chip" / prod / "timestamps.txt").read_text().split()
        assert written[2] == "nan" and written[4] == "nan"
        assert np.isfinite([float(v) for k, v in enumerate(written) if k not in (2, 4)]).all()
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)           # no warning at all
        hm = cr.open_sequence(data / RUN, products=out).single_chip.heatmaps
    assert hm.frame_ids.tolist() == [0, 1, 3, 5]
    np.testing.assert_array_equal(hm.timestamps, np.array([float(v) for v in lines])[[0, 1, 3, 5]])


# -- 3, 9: Ctrl-C stops ---------------------------------------------------------------------------
def test_an_interrupt_swallowed_by_python_still_stops_at_the_next_progress():
    from coloradar.progress import Progress, interrupt_handling

    class Swallows:
        def __del__(self):  # Python ignores (prints) what a __del__ raises
            signal.raise_signal(signal.SIGINT)

    bar = Progress(10, enabled=False)
    with interrupt_handling():
        import contextlib
        import io

        with contextlib.redirect_stderr(io.StringIO()):
            Swallows()  # the KeyboardInterrupt of the handler is lost here
        with pytest.raises(KeyboardInterrupt):
            bar.update(1)
    bar.update(1)  # outside the block the flag is gone


def _interrupt(cmd: list[str], ready: str, cwd: Path, timeout: float = 60.0
               ) -> tuple[int, float, str]:
    """Start ``cmd``, send SIGINT once ``ready`` shows on its stderr; (exit code, seconds
    from the signal to the exit, stderr)."""
    env = dict(os.environ, PYTHONPATH=SRC, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(cmd, cwd=cwd, env=env, stderr=subprocess.PIPE, text=True,
                            stdout=subprocess.DEVNULL)
    err = ""
    deadline = time.monotonic() + timeout
    try:
        assert proc.stderr is not None
        while ready not in err and time.monotonic() < deadline:
            line = proc.stderr.readline()
            if not line:
                break
            err += line
        assert ready in err, err
        proc.send_signal(signal.SIGINT)
        t0 = time.monotonic()
        _, rest = proc.communicate(timeout=30)
        return proc.returncode, time.monotonic() - t0, err + rest
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_ctrl_c_ends_a_local_pool_at_once_not_after_its_tasks(tmp_path):
    script = tmp_path / "pool.py"
    script.write_text(textwrap.dedent("""
        import sys, time
        from coloradar.batch.executors import LocalExecutor
        from coloradar.progress import interrupt_handling
        if __name__ == "__main__":
            ex = LocalExecutor(2)
            try:
                with interrupt_handling():
                    for n, _ in enumerate(ex.imap_unordered(time.sleep, [0.2] + [60.0] * 3)):
                        print("running", file=sys.stderr, flush=True)
            except KeyboardInterrupt:
                ex.terminate()
                sys.exit(130)
    """))
    code, seconds, err = _interrupt([sys.executable, str(script)], "running", tmp_path)
    assert code == 130 and seconds < 5.0, err  # not the 60 s its tasks would take


def test_ctrl_c_stops_the_hdf5_export_and_leaves_no_file(tmp_path):
    pytest.importorskip("h5py")
    from coloradar.sim.run import simulate_run

    run = simulate_run(tmp_path, duration=2.0, seed=4, heatmaps=True,
                       sensors=["single_chip", "lidar", "groundtruth"]).run_path
    out = tmp_path / "out"
    out.mkdir()
    code, seconds, err = _interrupt(
        [sys.executable, "-m", "coloradar", "export", str(run), "x.h5", "--radar", "single_chip"],
        "0/", out)
    assert code == 130 and "interrupted" in err, err
    assert seconds < 3.0
    assert list(out.iterdir()) == []   # neither the file nor a temporary one


def test_the_driver_ends_its_pool_on_ctrl_c_and_a_resumed_bar_counts_what_is_done(
        root, tmp_path, capsys, monkeypatch):
    import coloradar.batch.driver as driver
    from coloradar.batch.executors import SerialExecutor

    ended: list[str] = []

    class Interrupted(SerialExecutor):
        def imap_unordered(self, fn, tasks, *, errors="raise"):
            for n, item in enumerate(super().imap_unordered(fn, tasks, errors=errors)):
                if n == 1:
                    raise KeyboardInterrupt
                yield item

        def close(self):
            ended.append("close")

        def terminate(self):
            ended.append("terminate")

    monkeypatch.setattr(driver, "make_executor", lambda jobs: Interrupted())
    out = tmp_path / "out"
    argv = ["process", root / RUN, "--out", out, "--radar", "single_chip", "--chunk-size", 2]
    code, _, err = _cli(argv, capsys)
    assert code == 130 and ended == ["terminate"]
    report = json.loads((out / "process_report.json").read_text())
    assert report["status"] == "interrupted"
    monkeypatch.setattr(driver, "make_executor", lambda jobs: SerialExecutor())
    code, _, err = _cli(argv, capsys)
    assert code == 0
    bars = [ln for ln in err.splitlines() if "frames/s elapsed" in ln]
    assert bars and bars[-1].split("]")[1].split()[0] == "6/6", err   # 2 done before + 4 now


# -- 11: small things ----------------------------------------------------------------------------
def test_a_misspelt_setting_gets_the_close_name(root, tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["process", str(root / RUN), "--out", str(tmp_path / "o"), "--set", "pfaa=1e-3"])
    err = capsys.readouterr().err
    assert "did you mean pfa?" in err


def test_one_frame_is_one_frame(root, tmp_path, capsys):
    code, out, _ = _cli(["process", root / RUN, "--out", tmp_path / "o", "--radar",
                         "single_chip", "--frames", "0:1", "--quiet", "--jobs", 1], capsys)
    assert code == 0 and "1 frame processed," in out


def test_plot_of_frame_minus_one_names_the_last_frame(root, tmp_path, capsys):
    pytest.importorskip("matplotlib")
    code, out, _ = _cli(["plot", root / RUN, "--view", "range-doppler", "--radar", "single_chip",
                         "--frame", -1, "--out", tmp_path / "p.png"], capsys)
    assert code == 0 and "frame 5 " in out and "frame -1" not in out


def test_map_says_where_its_radar_points_came_from(root, tmp_path, capsys):
    proc = tmp_path / "proc"
    _cli(["process", root / RUN, "--out", proc, "--radar", "single_chip", "--quiet",
          "--jobs", 1], capsys)
    code, out, _ = _cli(["map", root / RUN, "--sensor", "single_chip", "--products", proc,
                         "--out", tmp_path / "m.pcd"], capsys)
    assert code == 0 and f"points from {proc / 'single_chip' / 'pointclouds'}" in out
    _cli(["process", root / RUN, "--out", tmp_path / "hm", "--radar", "single_chip", "--quiet",
          "--jobs", 1, "--products", "heatmaps"], capsys)
    code, out, _ = _cli(["map", root / RUN, "--sensor", "single_chip", "--products",
                         tmp_path / "hm", "--out", tmp_path / "m2.pcd"], capsys)
    assert code == 0 and "the run's own point clouds" in out


# -- beyond the list -----------------------------------------------------------------------------
def test_a_misspelt_command_gets_the_close_name(capsys):
    code, _, err = _cli(["exprot", "a", "b"], capsys)
    assert code == 2 and "did you mean export" in err


def test_more_tired_user_mistakes_are_said_as_such(root, tmp_path, capsys):
    run = root / RUN
    code, _, err = _cli(["score", run, tmp_path], capsys)          # swapped
    assert code == 2 and "swapped" in err
    code, _, err = _cli(["export", run, tmp_path / "b", "--format", "ros2", "--streams",
                         "lidar"], capsys)
    assert code == 2 and "did you mean lidar/pointclouds" in err
    code, _, err = _cli(["animate", run, "--out", tmp_path / "v.mp3"], capsys)
    assert code == 2 and ".rrd" in err
    code, _, err = _cli(["evaluate", run], capsys)                  # a run for DIR
    assert code == 1 and "never writes into a dataset" in err


def test_hdf5_export_is_chunked_per_sample_and_compressed_by_default(root, tmp_path, capsys):
    h5py = pytest.importorskip("h5py")
    code, _, err = _cli(["export", root / RUN, tmp_path / "x.h5", "--radar", "single_chip",
                         "--quiet"], capsys)
    assert code == 0, err
    with h5py.File(tmp_path / "x.h5") as f:
        hm = f["heatmap"]
        assert hm.chunks == (1, *hm.shape[1:]) and hm.compression == "gzip" and hm.shuffle
        assert hm.id.get_storage_size() < hm.nbytes   # random floats still lose their exponents


def test_an_interrupt_while_the_temporary_file_is_made_leaves_nothing(tmp_path, monkeypatch):
    """Ctrl-C can land right after the temporary file is created, before the writer knows its
    name (where ``mkstemp`` lost it: the Ctrl-C test of the HDF5 export left one 4 times in 5);
    the file must still be removed."""
    import coloradar.formats.atomic as atomic

    real_open = os.open

    def open_then_interrupt(*args, **kwargs):
        real_open(*args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(atomic.os, "open", open_then_interrupt)
    with pytest.raises(KeyboardInterrupt):
        atomic.atomic_write_bytes(tmp_path / "a.bin", b"x")
    with pytest.raises(KeyboardInterrupt), atomic.atomic_output(tmp_path / "b.h5"):
        pass
    assert list(tmp_path.iterdir()) == []
