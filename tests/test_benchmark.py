"""`coloradar benchmark` end to end on a small simulated dataset: our odometry, a folder of TUM
files and a Python function side by side; figures of estimates with a known error checked in
closed form; failures as rows; resume, refusal, run selection by pattern and named split."""

from __future__ import annotations

import csv
import json
import os
import warnings

import numpy as np
import pytest

from coloradar import OutputExistsError, SettingsError, open_sequence
from coloradar.cli.main import main
from coloradar.dataset import splits
from coloradar.geometry import Trajectory, trajectory_from_groundtruth
from coloradar.odometry import benchmark as bm
from coloradar.odometry import write_tum
from coloradar.sim import run as sim_run

DRIFT_RATE = 0.02   # m/s of lateral drift in the "drifting" estimate


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """Two 5 s corridor runs (single chip, IMU, ground truth), about 7 s to simulate."""
    root = tmp_path_factory.mktemp("bench_ds")
    names = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for seed in (1, 2):
            res = sim_run.simulate_run(root, duration=5.0, seed=seed, heatmaps=False, workers=2,
                                       sensors=("single_chip", "imu", "groundtruth"))
            names.append(res.run_path.name)
    return root, names


def _truth(root, name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return trajectory_from_groundtruth(open_sequence(root / name))


def _path(p):
    total = 0.0
    for k in range(1, len(p)):
        total += float(np.linalg.norm(p[k] - p[k - 1]))
    return total


METHOD_FILE = '''
import numpy as np
from scipy.spatial.transform import Rotation
from coloradar.geometry import Trajectory, trajectory_from_groundtruth

def moved_truth(seq):
    """The ground truth in another frame (any start a method may have): no error."""
    gt = trajectory_from_groundtruth(seq)
    g = Rotation.from_euler("z", 70, degrees=True)
    return Trajectory(gt.timestamps, g.apply(np.array(gt.translations)) + [3.0, -1.0, 0.5],
                      g * gt.rotations, "moved")
'''


def _read_csv(path):
    with open(path, newline="") as fh:
        return {(r["run"], r["method"]): r for r in csv.DictReader(fh)}


def test_benchmark_command_end_to_end(dataset, tmp_path, capsys):
    root, (run1, run2) = dataset
    # A TUM folder: run1 drifts sideways at DRIFT_RATE (flat file), run2 is exact (nested).
    est_dir = tmp_path / "theirs"
    (est_dir / run2).mkdir(parents=True)
    gt1 = _truth(root, run1)
    dt = gt1.timestamps - gt1.timestamps[0]
    write_tum(est_dir / f"{run1}.txt", Trajectory(
        gt1.timestamps, gt1.translations + np.outer(DRIFT_RATE * dt, [0, 1, 0]),
        gt1.rotations, "drift"))
    write_tum(est_dir / run2 / "trajectory.txt", _truth(root, run2))
    # A folder that lacks run2: that run fails, the others go on.
    partial = tmp_path / "partial"
    partial.mkdir()
    write_tum(partial / f"{run1}.txt", gt1)
    method_py = tmp_path / "mymethod.py"
    method_py.write_text(METHOD_FILE)
    out = tmp_path / "bench"
    argv = [str(root), "--out", str(out), "--radar", "single_chip", "--align", "origin",
            "--estimator", "default", "--estimate", f"drifting={est_dir}",
            "--estimate", f"partial={partial}", "--method", f"moved={method_py}:moved_truth",
            "-j", "2"]
    code = main(["benchmark", *argv])
    captured = capsys.readouterr()
    assert code == 1                                     # one failed run
    assert "partial on " + run2 + " failed" in captured.err
    assert "overall (2/2 ok)" in captured.out and "overall (1/2 ok)" in captured.out
    rows = _read_csv(out / "benchmark.csv")
    assert len(rows) == 2 * 4 + 4
    # Closed form of the drifting estimate with the first poses put together: the error at
    # time t is DRIFT_RATE·t, so the ATE RMSE is DRIFT_RATE·rms(t) and the end is DRIFT_RATE·T.
    r = rows[(run1, "drifting")]
    length = _path(gt1.translations)
    assert float(r["ate_rmse_m"]) == pytest.approx(DRIFT_RATE * np.sqrt(np.mean(dt * dt)),
                                                   rel=1e-6)
    assert float(r["final_error_m"]) == pytest.approx(DRIFT_RATE * dt[-1], rel=1e-6)
    assert float(r["final_error_percent"]) == pytest.approx(
        100 * DRIFT_RATE * dt[-1] / length, rel=1e-6)
    assert float(r["path_length_m"]) == pytest.approx(length, rel=1e-9)
    assert r["frames_per_s"] == "" and r["ego_velocity_rmse_m_s"] == ""   # not timed, no track
    for run in (run1, run2):
        exact = rows[(run, "moved")]
        assert float(exact["ate_rmse_m"]) < 1e-6 and float(exact["final_error_m"]) < 1e-6
        assert float(exact["drift_percent"]) < 1e-4
        # The RIO literature's figures: moved about z, the truth is undone by position + yaw
        # alignment; 5 s runs are far shorter than 25 m, so no relative error (empty cells).
        assert float(exact["ate_posyaw_m"]) < 1e-6
        assert exact["re25_percent"] == exact["re100_yaw_deg"] == ""
        assert float(exact["frames_per_s"]) > 0
        ours = rows[(run, "coloradar")]
        assert ours["status"] == "ok"
        # The simulated single chip with the gyro: a few percent at most over 5 s.
        assert 0 < float(ours["ate_rmse_percent"]) < 5
        assert 0 < float(ours["ego_velocity_rmse_m_s"]) < 0.1
        assert float(ours["frames_per_s"]) > 0
    assert float(rows[(run2, "drifting")]["ate_rmse_m"]) < 1e-9
    assert rows[(run2, "partial")]["status"] == "failed"
    assert "no estimate for run" in rows[(run2, "partial")]["error"]
    # Summary rows: ATE as a mean over runs; drift pooled over the segments of all runs.
    ov = rows[("overall", "drifting")]
    assert float(ov["ate_rmse_m"]) == pytest.approx(
        np.mean([float(rows[(k, "drifting")]["ate_rmse_m"]) for k in (run1, run2)]))
    assert ov["status"] == "2/2 ok" and rows[("overall", "partial")]["status"] == "1/2 ok"
    js = json.loads((out / "benchmark.json").read_text())
    assert js["settings"]["evaluation"]["align"] == "origin"
    assert {m["name"] for m in js["settings"]["methods"]} == {"coloradar", "drifting",
                                                              "partial", "moved"}
    assert len(js["runs"]) == 8 and len(js["overall"]) == 4
    text = (out / "benchmark.txt").read_text()
    assert text.count("\n") > 12 and "failed: MissingDataError" in text
    for name in ("trajectory.txt", "evaluation.json", "groundtruth.txt", "row.json"):
        assert (out / "coloradar" / run1 / name).is_file()
    assert (out / "moved" / run2 / "trajectory.txt").is_file()

    # Equal terms: our own output folder given back as someone else's TUM files (with its
    # ego_velocity.csv) gets the same figures as our row, but no frames/s.
    again = bm.benchmark(root, tmp_path / "again", methods=[bm.tum_method(out / "coloradar",
                                                                          "copy")],
                         align="origin", progress=False)
    for row in again.rows:
        ours = rows[(row["run"], "coloradar")]
        for key in ("ate_rmse_m", "final_error_percent", "drift_percent",
                    "rotation_drift_deg_per_m", "ego_velocity_rmse_m_s"):
            assert row[key] == pytest.approx(float(ours[key]), rel=1e-9)
        assert row["frames_per_s"] is None

    # The same command resumes: finished rows are kept as they are, the failed run retried.
    stamp = os.stat(out / "coloradar" / run1 / "row.json").st_mtime_ns
    code = main(["benchmark", *argv, "--quiet"])
    captured = capsys.readouterr()
    assert code == 1 and captured.out == ""
    assert os.stat(out / "coloradar" / run1 / "row.json").st_mtime_ns == stamp
    assert _read_csv(out / "benchmark.csv")[(run1, "drifting")]["ate_rmse_m"] == r["ate_rmse_m"]
    # Other settings into the same folder: refused, unless --overwrite.
    code = main(["benchmark", *argv[:-2], "--align", "se3", "-j", "1", "--quiet"])
    assert code == 1 and "other settings" in capsys.readouterr().err


def test_benchmark_selects_runs_by_pattern_and_by_named_split(dataset, tmp_path, monkeypatch):
    root, (run1, run2) = dataset
    est = tmp_path / "est"
    est.mkdir()
    for run in (run1, run2):
        write_tum(est / f"{run}.txt", _truth(root, run))
    method = bm.tum_method(est, "truth")
    res = bm.benchmark(root, tmp_path / "a", methods=[method], runs=f"*{run2[-5:]}",
                       progress=False)
    assert [r["run"] for r in res.rows] == [run2] and res.ok
    with pytest.raises(SettingsError, match="no run matches"):
        bm.benchmark(root, tmp_path / "b", methods=[method], runs="nothing*", progress=False)
    # A named split (the registry ships run lists of publications): one part, or all parts.
    # A run of the split that the dataset lacks is a failed row, not a smaller table.
    fake = splits.NamedSplit("paper", {"train": (run1,), "test": (run2, "missing_run")},
                             "test entry")
    monkeypatch.setattr(splits, "_registry", lambda: {"paper": fake})
    res = bm.benchmark(root, tmp_path / "c", methods=[method], split="paper:train",
                       progress=False)
    assert [r["run"] for r in res.rows] == [run1]
    res = bm.benchmark(root, tmp_path / "d", methods=[method], split="paper", progress=False)
    assert [r["run"] for r in res.rows] == sorted([run1, run2, "missing_run"])
    assert [r["run"] for r in res.failures] == ["missing_run"]
    assert "not in the dataset" in res.failures[0]["error"]
    assert res.overall[0]["status"] == "2/3 ok"
    with pytest.raises(SettingsError, match="no part"):
        bm.benchmark(root, tmp_path / "e", methods=[method], split="paper:val", progress=False)
    # Published lists drop the release's date prefix: such a name still finds its run.
    undated = splits.NamedSplit("undated", {"test": (run2.split("_", 3)[3],)}, "test entry")
    monkeypatch.setattr(splits, "_registry", lambda: {"undated": undated})
    res = bm.benchmark(root, tmp_path / "f", methods=[method], split="undated", progress=False)
    assert [r["run"] for r in res.rows] == [run2] and res.ok
    # Never into a folder that holds something else.
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(OutputExistsError):
        bm.benchmark(root, other, methods=[method], progress=False)


def test_estimator_is_passed_only_when_chosen(dataset, tmp_path, monkeypatch):
    """``estimator=`` reaches run_odometry only when a user names one (so the benchmark works
    with an odometry that has a single estimator), and is refused when it has none."""
    root, (run1, _) = dataset
    seen = []

    class Out:
        def __init__(self, seq):
            self.trajectory = trajectory_from_groundtruth(seq)
            self.track = None

    def with_estimator(seq, out, *, radar="cascade", overwrite=False, estimator="rio"):
        seen.append(estimator)
        return Out(seq)

    def without_estimator(seq, out, *, radar="cascade", overwrite=False):
        seen.append(None)
        return Out(seq)

    monkeypatch.setattr(bm, "run_odometry", with_estimator)
    res = bm.benchmark(root, tmp_path / "a", runs=run1, progress=False,
                       methods=[bm.builtin_method(), bm.builtin_method("dead-reckoning")])
    assert res.ok and seen == ["rio", "dead-reckoning"]
    assert [m["name"] for m in res.settings["methods"]] == ["coloradar",
                                                            "coloradar-dead-reckoning"]
    monkeypatch.setattr(bm, "run_odometry", without_estimator)
    with pytest.raises(SettingsError, match="one estimator"):
        bm.benchmark(root, tmp_path / "b", runs=run1, progress=False,
                     methods=[bm.builtin_method("rio")])
    with pytest.raises(SettingsError, match="no option bogus"):
        bm.benchmark(root, tmp_path / "c", runs=run1, progress=False,
                     odometry={"bogus": 1})


def test_methods_are_checked_before_anything_runs(tmp_path):
    with pytest.raises(SettingsError, match="module:function"):
        bm.callable_method("no_colon_here")
    with pytest.raises(SettingsError, match="cannot import"):
        bm.callable_method("surely_not_a_module_xyz:fn")
    (tmp_path / "m.py").write_text("x = 1\n")
    with pytest.raises(SettingsError, match="no function"):
        bm.callable_method(f"{tmp_path / 'm.py'}:fn")
    with pytest.raises(SettingsError, match="method name"):
        bm.Method("a/b", "tum", "x")


def _drifting_method(run_path, out_dir, settings):
    """A function method (the SLAM seam): the ground truth drifting sideways, as TUM."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gt = trajectory_from_groundtruth(open_sequence(run_path))
    dt = gt.timestamps - gt.timestamps[0]
    path = out_dir / "slam.txt"
    write_tum(path, Trajectory(gt.timestamps, gt.translations + np.outer(DRIFT_RATE * dt,
                                                                         [0, 1, 0]),
                               gt.rotations, "drift"))
    return path


def test_function_methods_and_the_filter_consistency_column(dataset, tmp_path):
    from scipy.spatial.transform import Rotation

    root, (run1, _) = dataset
    res = bm.benchmark(root, tmp_path / "b", methods=[
        bm.builtin_method(), *bm.function_methods({"slamish": _drifting_method})],
        runs=[run1], align="origin", odometry={"radar": "single_chip"}, progress=False)
    rows = {r["method"]: r for r in res.rows}
    gt = _truth(root, run1)
    dt = gt.timestamps - gt.timestamps[0]
    assert rows["slamish"]["final_error_m"] == pytest.approx(DRIFT_RATE * dt[-1], rel=1e-6)
    assert rows["slamish"]["nees_position"] is None and rows["slamish"]["estimator_s"] > 0
    # The NEES, recomputed here pose by pose from odometry.json and the ground truth.
    folder = tmp_path / "b" / "coloradar" / run1
    info = json.loads((folder / "odometry.json").read_text())["rio"]["poses"]
    from coloradar.odometry import read_tum
    est = read_tum(folder / "trajectory.txt")
    qp, qr = [], []
    for k, t in enumerate(est.timestamps):
        if t <= est.timestamps[0] + 1.0 or not gt.covers(np.array([t]))[0]:
            continue
        c = np.zeros((6, 6))
        c[np.triu_indices(6)] = info["covariance_upper"][k]
        c = c + np.triu(c, 1).T + np.eye(6) * 1e-12
        p, r = gt.interpolate_arrays(np.array([t]))
        e = est.translations[k] - p[0]
        qp.append(e @ np.linalg.solve(c[:3, :3], e) / 3)
        er = (r[0] * Rotation.from_quat(est.rotations[k].as_quat()).inv()).as_rotvec()
        qr.append(er @ np.linalg.solve(c[3:, 3:], er) / 3)
    assert rows["coloradar"]["nees_position"] == pytest.approx(np.mean(qp), rel=1e-2)
    assert rows["coloradar"]["nees_attitude"] == pytest.approx(np.mean(qr), rel=1e-2)
    assert "NEES p" in (tmp_path / "b" / "benchmark.txt").read_text()
    with pytest.raises(SettingsError, match="module-level"):
        bm.function_method(lambda a, b, c: a)
