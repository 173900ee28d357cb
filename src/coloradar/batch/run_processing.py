"""Process a run's ADC frames into heatmaps and point clouds written in the dataset's layout.

Output (mirroring a run, one folder per radar and product)::

    OUT/process_manifest.json            settings the products were made with
    OUT/process_report.json              what the last job did (see coloradar.batch.report)
    OUT/<radar>/heatmaps/{timestamps.txt, heatmap_cfg.txt, data/heatmap_<i>.bin}
    OUT/<radar>/pointclouds/{timestamps.txt, data/radar_pointcloud_<i>.bin}

``<i>`` is the ADC frame's own file number and line ``j`` of ``timestamps.txt`` is the
timestamp of frame ``base + j``, written up to the last frame complete on disk, with ``base``
= 1 when the first complete frame is number 1 and 0 otherwise — the rule readers use to pair
lines with files (docs/conventions.md §1) — so the folders read back like the dataset's own streams
whatever frame range was processed. Lines of frames without an ADC timestamp (before a
1-based run's first frame, or missing from the run) hold ``nan``. ``heatmap_cfg.txt`` lists
the true angles of the bins (:meth:`coloradar.dsp.RadarProcessor.heatmap_config`).

:func:`process_frames` is the plain unit of work (open the run, process some frames, write
their files); :func:`process_run` drives one run through :mod:`coloradar.batch.driver`, the
code that also processes whole datasets — resumable, in chunks, on any executor.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..dataset import open_sequence
from ..dsp import ProcessingSettings, RadarProcessor
from ..formats import write_heatmap, write_radar_pointcloud
from .driver import CalibLike, ProcessingJob, RunTarget, check_products, process_targets
from .output_folder import PRODUCTS, ProcessedRun, output_paths
from .report import REPORT, BatchReport

__all__ = ["PRODUCTS", "ProcessReport", "output_paths", "process_frames", "process_run"]


@dataclass
class ProcessReport:
    """What :func:`process_run` did.

    Attributes
    ----------
    frames
        Frames asked for, per radar.
    folders
        Product folders written, per radar.
    seconds
        Wall time.
    batch
        The full record (frames done, skipped, failed with their errors), also saved as
        ``OUT/process_report.json``.
    """

    frames: dict[str, int] = field(default_factory=dict)
    folders: dict[str, list[Path]] = field(default_factory=dict)
    seconds: float = 0.0
    batch: BatchReport | None = None

    @property
    def ok(self) -> bool:
        """True when every frame asked for is complete."""
        return self.batch is None or self.batch.ok


def process_frames(seq_path: str | os.PathLike, calib_path: CalibLike, radar: str,
                   products: Sequence[str], frame_indices: Sequence[int],
                   out: str | os.PathLike, settings: ProcessingSettings | None = None) -> int:
    """Process some ADC frames of one radar and write their product files.

    Parameters
    ----------
    seq_path
        The run folder or zip.
    calib_path
        Calibration (object, folder/zip, or None to find it beside the run).
    radar
        ``"cascade"`` or ``"single_chip"``.
    products
        Any of ``"heatmaps"``, ``"pointclouds"``.
    frame_indices
        Positions in the run's ADC stream (``seq.<radar>.adc[k]``), not file numbers.
    out
        Output root; files go to ``out/<radar>/<product>/data/`` named by the frame's file
        number. Existing files are replaced (atomically); checking for them is the caller's.
    settings
        Processing settings (default: :class:`~coloradar.dsp.ProcessingSettings`).

    Returns
    -------
    int
        Frames written.

    Raises
    ------
    coloradar.errors.FormatError
        On a malformed frame (the batch driver records such frames and goes on instead).
    """
    prods = check_products(products)
    seq = open_sequence(seq_path, calib=calib_path)
    stream = seq.radar(radar).adc
    proc = RadarProcessor(seq.calib.radar(radar), settings)
    folder = ProcessedRun(out)
    for k in frame_indices:
        fid = int(stream.frame_ids[k])
        hm, pts = proc.products(stream[k], "heatmaps" in prods, "pointclouds" in prods)
        if hm is not None:
            write_heatmap(folder.frame_file(radar, "heatmaps", fid), hm)
        if pts is not None:
            write_radar_pointcloud(folder.frame_file(radar, "pointclouds", fid), pts)
    return len(frame_indices)


def process_run(run: str | os.PathLike, out: str | os.PathLike,
                job: ProcessingJob | None = None, **options: Any) -> ProcessReport:
    """Process one run's ADC frames into heatmaps and/or point clouds under ``out``.

    Parameters
    ----------
    run
        Run folder or zip.
    out
        Output root (must not lie inside ``run``).
    job
        A :class:`~coloradar.batch.driver.ProcessingJob` holding the options below (its
        ``strict`` is always on here, and its ``desc`` defaults to the run's name); keywords
        replace its fields.

    Other Parameters
    ----------------
    calib
        Calibration object or folder/zip; None finds it beside the run as
        :func:`coloradar.dataset.open_sequence` does.
    radars
        ``"all"`` (every radar with ADC frames), a radar name, or a list of names.
    products
        ``"heatmaps"`` and/or ``"pointclouds"``.
    frames
        Positions in each ADC stream to process (a slice, e.g. ``slice(0, 100)``); None = all.
    overwrite
        Delete the requested products' frame files and redo every frame. Without it an
        existing output made with the same settings is resumed (complete frames are kept,
        the others processed) and one made otherwise is an
        :class:`~coloradar.errors.OutputExistsError`, raised before anything is written.
    settings
        Processing settings.
    progress
        Show a progress line on stderr.
    chunk_size
        Frames per task.
    jobs
        Worker processes (1: this process; None: all cores); ignored with ``executor``.
    executor
        A :class:`~coloradar.batch.executors.Executor` (a Dask cluster, say) to run on.

    Returns
    -------
    ProcessReport
        Frames that failed (malformed input) are listed in ``report.batch``; they do not
        raise.
    """
    defaults = {"desc": Path(run).name.removesuffix(".zip")} if job is None else {}
    opts = dataclasses.replace(ProcessingJob.of(job, **{**defaults, **options}), strict=True)
    batch = process_targets([RunTarget(Path(run), Path(out))], Path(out) / REPORT, opts)
    rep = ProcessReport(seconds=batch.seconds, batch=batch)
    prods, folder = check_products(opts.products), ProcessedRun(out)
    for outcome in batch.runs.values():
        for radar, o in outcome.radars.items():
            rep.frames[radar] = o.frames
            rep.folders[radar] = [folder.paths(radar, p)[0] for p in prods]
    return rep
