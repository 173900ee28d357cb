"""The output folder's coarse calls (batch/output_folder.py): what ``JobOutputs.open`` leaves on
disk and in hand, that the lock is held until ``close`` and the report written before it goes,
and where workers are told to write."""

from __future__ import annotations

import json

import pytest

from coloradar import __version__
from coloradar.batch.output_folder import (
    LOCK,
    MANIFEST,
    JobOutputs,
    OutputLock,
    OutputRequest,
    ProcessedRun,
    RadarProducts,
)
from coloradar.errors import ColoradarError, OutputExistsError, WriteError
from coloradar.formats.atomic import is_partial_file, make_output_dir

PRODS = ("heatmaps", "pointclouds")
HM_BYTES = 4 * 2 * 4  # a (1, 1, 4, 2) float32 heatmap


def _radar(settings: dict | None = None) -> RadarProducts:
    return RadarProducts("cascade", settings or {"pfa": 1e-4}, "sha", HM_BYTES, "cfg\n",
                         {"0": "v0", "1": "v1", "2": "v2"})


def test_open_prepares_locks_and_says_what_is_complete_and_close_reports_then_unlocks(tmp_path):
    out = tmp_path / "out"
    data = out / "cascade" / "heatmaps" / "data"
    data.mkdir(parents=True)
    (data / "heatmap_1.bin").write_bytes(b"\0" * HM_BYTES)           # valid size
    (data / ".heatmap_2.bin.abc123.tmp").write_bytes(b"partial")       # an interrupted write
    (out / MANIFEST).write_text(json.dumps({  # a manifest that does not record these files
        "format": "coloradar-process-manifest/1", "run": "r", "coloradar_version": __version__,
        "products": {}}))
    pc = out / "cascade" / "pointclouds" / "data"
    pc.mkdir(parents=True)
    (pc / "radar_pointcloud_1.bin").write_bytes(b"\0" * 20)
    (pc / "radar_pointcloud_0.bin").write_bytes(b"\0" * 7)            # damaged: not complete

    request = OutputRequest(tmp_path / "run", out, "r", [_radar()])
    with pytest.raises(OutputExistsError, match="no entry in the manifest"):
        JobOutputs.open([request], PRODS, overwrite=False)
    assert not (out / LOCK).exists()                                  # refused: nothing held

    (out / MANIFEST).write_text(json.dumps({
        "format": "coloradar-process-manifest/1", "run": "r", "coloradar_version": __version__,
        "products": {f"cascade/{p}": {"settings": {"pfa": 1e-4}, "calibration_sha256": "sha"}
                     for p in PRODS}}))
    outputs = JobOutputs.open([request], PRODS, overwrite=False)
    (plan,) = outputs.plans
    assert plan.complete == {"cascade": {1}}
    assert not (data / ".heatmap_2.bin.abc123.tmp").exists()
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["inputs"] == {"cascade": {"0": "v0", "1": "v1", "2": "v2"}}
    for p, (head, tail) in zip(PRODS, plan.frame_files["cascade"], strict=True):
        assert head + "7" + tail == str(ProcessedRun(out).frame_file("cascade", p, 7))
    with pytest.raises(OutputExistsError, match="another coloradar process"), OutputLock(out):
        pass
    assert outputs.close(out / "process_report.json", '{"status": "ok"}\n') == \
        out / "process_report.json"
    assert (out / "process_report.json").read_text() == '{"status": "ok"}\n'
    with OutputLock(out):                                             # released
        pass


def test_every_folder_is_checked_before_any_is_written(tmp_path):
    good, bad = tmp_path / "good", tmp_path / "run" / "inside"
    (tmp_path / "run").mkdir()
    requests = [OutputRequest(tmp_path / "elsewhere", good, "a", [_radar()]),
                OutputRequest(tmp_path / "run", bad, "b", [_radar()])]
    with pytest.raises(ColoradarError, match="lies inside the run"):
        JobOutputs.open(requests, PRODS, overwrite=False)
    assert not good.exists()


def test_partial_names_and_a_file_where_a_folder_belongs(tmp_path):
    assert is_partial_file(".heatmap_3.bin.k2j4h1.tmp")
    assert not is_partial_file("heatmap_3.bin") and not is_partial_file(".process.lock")
    (tmp_path / "f").write_text("x")
    with pytest.raises(WriteError, match="expected an output folder, found a file"):
        make_output_dir(tmp_path / "f")
    with pytest.raises(WriteError, match="a folder on its path is a file"):
        make_output_dir(tmp_path / "f" / "sub")
    request = OutputRequest(tmp_path / "run", tmp_path / "f", "r", [_radar()])
    with pytest.raises(WriteError, match="is a file"):
        JobOutputs.open([request], PRODS, overwrite=False)
