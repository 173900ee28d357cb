"""Whole-dataset processing (issue 6): local pool and Dask give the bytes of serial processing,
a killed job resumes to the same bytes, bad frames are reported and the rest is processed."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest

from coloradar.batch.driver import process_dataset
from coloradar.batch.executors import LocalExecutor, TaskError
from coloradar.batch.manifest import settings_differences, settings_record
from coloradar.batch.output_folder import OutputLock
from coloradar.batch.run_processing import process_run
from coloradar.calib import load_calibration
from coloradar.cli.main import main
from coloradar.dataset import open_dataset, open_sequence
from coloradar.dsp import ProcessingSettings
from coloradar.errors import ColoradarError, MissingDataError, OutputExistsError
from coloradar.progress import Progress
from coloradar.sim.run import simulate_run

RUN0 = "11_21_2026_sim_corridor_run0"   # folder: cascade + single chip
RUN1 = "11_21_2026_sim_corridor_run1"   # zip: single chip


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """A dataset root of two short simulated runs, one a folder and one a zip."""
    root = tmp_path_factory.mktemp("dataset")
    simulate_run(root, duration=1.2, seed=0, sensors=["cascade", "single_chip"], heatmaps=False)
    res = simulate_run(root, duration=1.2, seed=1, sensors=["single_chip"], heatmaps=False)
    with zipfile.ZipFile(root / f"{RUN1}.zip", "w") as zf:
        for p in sorted(res.run_path.rglob("*")):
            zf.write(p, p.relative_to(res.run_path).as_posix())
    shutil.rmtree(res.run_path)
    return root


@pytest.fixture(scope="module")
def reference(dataset, tmp_path_factory) -> Path:
    """Each run processed on its own, serially in this process."""
    ref = tmp_path_factory.mktemp("reference")
    for name, path in ((RUN0, dataset / RUN0), (RUN1, dataset / f"{RUN1}.zip")):
        rep = process_run(path, ref / name, jobs=1, progress=False)
        assert rep.ok
    return ref


def _tree(folder: Path) -> dict[str, bytes]:
    """Every output file's bytes; the manifest without its record of input file versions
    (modification times differ between copies of a run)."""
    tree = {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != "process_report.json"}
    for name, data in tree.items():
        if name.endswith("process_manifest.json"):
            manifest = json.loads(data)
            assert set(manifest.pop("inputs")) <= {"cascade", "single_chip"}
            tree[name] = json.dumps(manifest).encode()
    return tree


def _frames(ref: Path) -> int:
    return len(list(ref.rglob("heatmap_*.bin")))


def _leftovers(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.name.endswith(".tmp") or p.name == ".process.lock"]


def test_local_pool_and_dask_write_the_bytes_of_serial_processing(dataset, reference, tmp_path):
    out = tmp_path / "pool"
    report = process_dataset(dataset, out, jobs=2, chunk_size=4, progress=False)
    assert report.ok and report.executor == "local process pool, 2 workers"
    assert report.totals() == {"frames": _frames(reference), "done": _frames(reference),
                               "skipped": 0, "failed": 0}
    for name in (RUN0, RUN1):
        assert _tree(out / name) == _tree(reference / name)
    assert not _leftovers(out)
    # Each run's folder reads back as a run whose products pair with the ADC frames.
    back = open_dataset(out, calib=load_calibration(dataset / "calib"))
    assert back.sequences == [RUN0, RUN1]
    seq = open_sequence(dataset / RUN0)
    for radar in ("cascade", "single_chip"):
        hm = back[RUN0].radar(radar).heatmaps
        np.testing.assert_array_equal(hm.frame_ids, seq.radar(radar).adc.frame_ids)
        np.testing.assert_array_equal(hm.timestamps, seq.radar(radar).adc.timestamps)
    saved = json.loads((out / "process_report.json").read_text())
    assert saved["status"] == "ok" and saved["totals"]["done"] == _frames(reference)
    assert all(v > 10 * 2**20 for v in saved["workers"].values())   # real peak RSS values

    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=":0") as cluster:
        out_dask = tmp_path / "dask"
        assert main(["process", str(dataset), "--out", str(out_dask), "--scheduler",
                     cluster.scheduler_address, "--chunk-size", "3", "--quiet"]) == 0
    for name in (RUN0, RUN1):
        assert _tree(out_dask / name) == _tree(reference / name)
    saved = json.loads((out_dask / "process_report.json").read_text())
    assert saved["executor"].startswith("dask cluster")
    assert not _leftovers(out_dask)


def _children(pid: int) -> list[int]:
    kids = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        try:
            kids += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            continue
    return kids


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"


@pytest.mark.skipif(sys.platform != "linux", reason="kills processes and reads /proc")
def test_job_killed_midway_resumes_to_identical_output(dataset, reference, tmp_path):
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "coloradar", "process", str(dataset), "--out", str(out),
           "--jobs", "2", "--chunk-size", "1", "--quiet"]
    job = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL,
                           stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60
        while len(list(out.rglob("*.bin"))) < 3:
            assert job.poll() is None, job.stderr.read().decode()
            assert time.monotonic() < deadline, "the job wrote nothing"
            time.sleep(0.005)
        workers = _children(job.pid)
        os.kill(job.pid, signal.SIGKILL)           # the driver only: its workers must follow
        job.wait(10)
        deadline = time.monotonic() + 10
        while any(_alive(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert workers and not any(_alive(w) for w in workers)
    finally:
        if job.poll() is None:
            os.killpg(job.pid, signal.SIGKILL)
            job.wait(10)
        job.stderr.close()
    written = len(list(out.rglob("heatmap_*.bin")))
    assert 0 < written < _frames(reference)          # really killed mid-way
    assert main(["process", str(dataset), "--out", str(out), "--jobs", "2", "--quiet"]) == 0
    totals = json.loads((out / "process_report.json").read_text())["totals"]
    assert totals["skipped"] >= 1 and totals["failed"] == 0
    assert totals["done"] + totals["skipped"] == _frames(reference)
    for name in (RUN0, RUN1):
        assert _tree(out / name) == _tree(reference / name)
    assert not _leftovers(out)


def test_corrupted_frame_is_reported_and_every_other_frame_processed(dataset, reference,
                                                                      tmp_path, capsys):
    root = tmp_path / "bad"
    shutil.copytree(dataset / "calib", root / "calib")
    shutil.copytree(dataset / RUN0, root / RUN0)
    bad = root / RUN0 / "single_chip" / "adc_samples" / "data" / "frame_3.bin"
    good = bad.read_bytes()
    bad.write_bytes(good[:1000])                    # a truncated ADC file
    out = tmp_path / "out"
    argv = ["process", str(root), "--out", str(out), "--jobs", "2", "--chunk-size", "4",
            "--quiet"]
    assert main(argv) == 1
    text, err = capsys.readouterr()
    assert "single_chip 10/11 frames (1 FAILED)" in text
    assert "frame 3" in err and "frame 3" not in text     # the failure itself: on stderr
    rep = json.loads((out / "process_report.json").read_text())
    assert rep["status"] == "failed" and rep["totals"]["failed"] == 1
    sc = rep["runs"][RUN0]["radars"]["single_chip"]
    assert (sc["done"], sc["failed"]) == (10, 1)
    (fail,) = sc["failures"]
    assert fail["frame_id"] == 3 and fail["file"] == str(bad) and fail["error"] == "FormatError"
    assert "786,432 bytes" in fail["message"] and "1,000 bytes" in fail["message"]
    missing = {"single_chip/heatmaps/data/heatmap_3.bin",
               "single_chip/pointclouds/data/radar_pointcloud_3.bin"}
    expected = {k: v for k, v in _tree(reference / RUN0).items() if k not in missing}
    for prod in ("heatmaps", "pointclouds"):  # a frame that produced nothing has no time
        key = f"single_chip/{prod}/timestamps.txt"
        lines = expected[key].decode().splitlines()
        lines[3] = "nan"
        expected[key] = ("\n".join(lines) + "\n").encode()
    assert _tree(out / RUN0) == expected
    # A rerun retries only the failed frame; once the input is repaired it completes.
    assert main(argv) == 1
    sc = json.loads((out / "process_report.json").read_text())["runs"][RUN0]["radars"][
        "single_chip"]
    assert (sc["skipped"], sc["failed"]) == (10, 1)
    bad.write_bytes(good)
    assert main(argv) == 0
    sc = json.loads((out / "process_report.json").read_text())["runs"][RUN0]["radars"][
        "single_chip"]
    assert (sc["skipped"], sc["done"], sc["failed"]) == (10, 1, 0)
    assert _tree(out / RUN0) == _tree(reference / RUN0)
    capsys.readouterr()


def test_damaged_or_missing_outputs_are_redone_and_complete_ones_kept(dataset, reference,
                                                                       tmp_path):
    out = tmp_path / "resume"
    shutil.copytree(reference / RUN1, out)
    data = out / "single_chip"
    (data / "heatmaps" / "data" / "heatmap_5.bin").unlink()
    (data / "pointclouds" / "data" / "radar_pointcloud_7.bin").write_bytes(b"\0" * 7)
    stale = data / "heatmaps" / "data" / ".heatmap_2.bin.x1y2z3.tmp"
    stale.write_bytes(b"partial")
    keep = data / "heatmaps" / "data" / "heatmap_0.bin"
    os.utime(keep, ns=(1, 1))
    rep = process_run(dataset / f"{RUN1}.zip", out, progress=False).batch
    sc = rep.runs[RUN1].radars["single_chip"]
    assert (sc.done, sc.skipped, sc.failed) == (2, 10, 0)
    assert _tree(out) == _tree(reference / RUN1)
    assert keep.stat().st_mtime_ns == 1 and not stale.exists()


def test_output_that_cannot_be_resumed_is_refused(dataset, reference, tmp_path):
    # Frames made by something else (no manifest) are not mixed with ours.
    out = tmp_path / "foreign"
    shutil.copytree(reference / RUN1, out)
    (out / "process_manifest.json").unlink()
    with pytest.raises(OutputExistsError, match="no entry in the manifest"):
        process_run(dataset / f"{RUN1}.zip", out, progress=False)
    # ... and --overwrite does not delete them either (they may be a download's heatmaps).
    before = _tree(out)
    with pytest.raises(OutputExistsError, match="not deleting them"):
        process_run(dataset / f"{RUN1}.zip", out, overwrite=True, progress=False)
    assert _tree(out) == before
    # Another job writing the same folder.
    with OutputLock(tmp_path / "busy"), pytest.raises(OutputExistsError, match="another"):
        process_run(dataset / f"{RUN1}.zip", tmp_path / "busy", progress=False)
    # A dataset run is never an output folder.
    with pytest.raises(ColoradarError, match="never writes into a run"):
        process_run(dataset / f"{RUN1}.zip", dataset / RUN0, progress=False)


def test_run_selection(dataset, tmp_path, capsys):
    out = tmp_path / "some"
    rep = process_dataset(dataset, out, runs=["*_run1"], radars="single_chip",
                          products=["pointclouds"], frames=slice(0, 2), progress=False)
    assert list(rep.runs) == [RUN1] and rep.totals()["done"] == 2
    assert sorted(p.name for p in out.iterdir()) == [RUN1, "process_report.json"]
    assert not (out / RUN1 / "single_chip" / "heatmaps").exists()
    with pytest.raises(MissingDataError, match="no run matches 'run9'"):
        process_dataset(dataset, out, runs=["run9"], progress=False)
    assert main(["process", str(dataset / RUN0), "--out", str(tmp_path / "x"), "--runs",
                 "a"]) == 1
    assert "runs can be selected only from a dataset root" in capsys.readouterr().err
    # A run without the radar asked for is noted, not failed.
    rep = process_dataset(dataset, tmp_path / "casc", radars="cascade", frames=slice(0, 1),
                          progress=False)
    assert rep.ok and rep.runs[RUN1].note.startswith("no cascade ADC frames")


def _square(task):
    i, mode, marker = task
    if mode == "die" or (mode == "die_once" and not os.path.exists(marker)):
        if mode == "die_once":
            Path(marker).touch()
        os.kill(os.getpid(), signal.SIGKILL)
    if mode == "raise":
        raise ValueError(f"task {i} is bad")
    return i * i


@pytest.mark.skipif(sys.platform == "win32", reason="SIGKILL")
def test_local_pool_survives_killed_workers_and_bounds_tasks_in_flight(tmp_path):
    modes = {3: "die_once", 7: "die", 9: "raise"}
    pulled = []

    def tasks():
        for i in range(12):
            pulled.append(i)
            yield i, modes.get(i, ""), str(tmp_path / f"marker{i}")

    results = {}
    with LocalExecutor(2, max_in_flight=3) as ex:
        for n, (task, res) in enumerate(ex.imap_unordered(_square, tasks(), errors="return"), 1):
            assert len(pulled) <= n - 1 + 3          # never more than 3 tasks ahead
            results[task[0]] = res
        assert ex.restarts >= 2
    assert sorted(results) == list(range(12))
    assert results[7] == TaskError("WorkerDied", results[7].message)
    assert results[9] == TaskError("ValueError", "task 9 is bad")
    assert all(results[i] == i * i for i in range(12) if i not in (7, 9))


def test_settings_comparison_and_progress_line():
    rec = settings_record(ProcessingSettings(pfa=1e-3))
    assert settings_differences(rec, settings_record(None)) == ["pfa: 0.001 -> 0.0001"]
    older = {k: v for k, v in settings_record(None).items() if k != "capon_loading"}
    assert settings_differences(older, settings_record(None)) == []   # a new default setting
    assert "workers" not in rec                                       # speed, not output
    numpy_engine = settings_record(ProcessingSettings(engine="numpy"))
    assert settings_differences(numpy_engine, settings_record(None)) == []   # nor engine

    class Log(list):
        def write(self, s):
            self.append(s)

        def flush(self):
            pass

    log = Log()
    bar = Progress(40, desc="process", stream=log, min_interval=0)
    bar.update(10, failed=1)
    bar.close()
    assert "10/40 frames" in log[0] and "frames/s" in log[0]
    assert "ETA" not in log[0]        # one update: no rate after start-up is known yet
    assert "1 failed" in log[0]


SCRIPT = """
from coloradar.batch.driver import process_dataset
{guard}report = process_dataset({root!r}, {out!r}, runs=[{run!r}], jobs=2, chunk_size=1,
{indent}                         frames=slice(0, 2), progress=False)
{indent}print(report.summary())
"""


def test_a_script_without_main_guard_is_told_what_to_do(dataset, tmp_path):
    # docs/batch.md's own example, run as a script: under 'spawn' (the default on macOS,
    # Windows and Python >= 3.14; always used by the local pool) every worker imports the main
    # module. Without the guard the workers die at start-up; that must not read as frames
    # killing their workers ("out of memory"), nor end with exit status 0.
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
    codes = {}
    for guarded in (False, True):
        script = tmp_path / f"job_{guarded}.py"
        out = tmp_path / f"out_{guarded}"
        script.write_text(SCRIPT.format(guard='if __name__ == "__main__":\n    ' if guarded else "",
                                        indent="    " if guarded else "", root=str(dataset),
                                        out=str(out), run=RUN1))
        proc = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=240)
        codes[guarded] = proc.returncode
        saved = json.loads((out / "process_report.json").read_text())
        if guarded:
            assert saved["status"] == "ok" and saved["totals"]["done"] == 2, proc.stderr
        else:
            last = proc.stderr.strip().splitlines()[-1]
            assert last.startswith("coloradar.batch.executors.WorkerStartupError: the 2 local "
                                   "worker process(es) died while starting")
            assert str(script) in last and 'if __name__ == "__main__":' in last
            assert "out of memory" not in proc.stdout + last
            assert saved["status"] == "failed" and "died while starting" in saved["error"]
            assert saved["totals"]["failed"] == 0        # no frame is blamed
    assert codes == {False: 1, True: 0}
