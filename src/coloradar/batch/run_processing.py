"""Process a run's ADC frames into heatmaps and point clouds written in the dataset's layout.

Output (mirroring a run, one folder per radar and product)::

    OUT/<radar>/heatmaps/{timestamps.txt, heatmap_cfg.txt, data/heatmap_<i>.bin}
    OUT/<radar>/pointclouds/{timestamps.txt, data/radar_pointcloud_<i>.bin}

``<i>`` is the ADC frame's own file number and line ``j`` of ``timestamps.txt`` is the
timestamp of frame ``base + j``, written up to the last processed frame, with ``base`` = 1
when the first written frame is number 1 and 0 otherwise — the rule readers use to pair
lines with files (DESIGN.md §1) — so the folders read back like the dataset's own streams
whatever frame range was processed. Lines of frames without an ADC timestamp (before a
1-based run's first frame, or missing from the run) hold ``nan``. ``heatmap_cfg.txt`` lists the true angles of
the bins (:meth:`coloradar.dsp.RadarProcessor.heatmap_config`).

:func:`process_frames` is the unit of work — open the run, process some frames, write their
files — so that a process pool or a Dask cluster can run chunks of it; :func:`process_run`
is the single-run driver.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..calib import RADARS, Calibration, format_heatmap_cfg
from ..dataset import open_sequence
from ..dsp import ProcessingSettings, RadarProcessor
from ..errors import ColoradarError, MissingDataError, OutputExistsError
from ..formats import atomic_write_text, write_heatmap, write_radar_pointcloud
from ..formats.text import format_timestamps
from .progress import Progress

__all__ = ["PRODUCTS", "ProcessReport", "output_paths", "process_frames", "process_run"]

PRODUCTS = ("heatmaps", "pointclouds")
"""Products :func:`process_run` can write."""

_FILE = {"heatmaps": "heatmap_{}.bin", "pointclouds": "radar_pointcloud_{}.bin"}

CalibLike = Calibration | str | os.PathLike | None


@dataclass
class ProcessReport:
    """What :func:`process_run` wrote.

    Attributes
    ----------
    frames
        Frames processed per radar.
    folders
        Product folders written, per radar.
    seconds
        Wall time.
    """

    frames: dict[str, int] = field(default_factory=dict)
    folders: dict[str, list[Path]] = field(default_factory=dict)
    seconds: float = 0.0


def output_paths(out: str | os.PathLike, radar: str, product: str) -> tuple[Path, Path]:
    """``(product folder, data folder)`` of one radar's product under ``out``."""
    folder = Path(out) / radar / product
    return folder, folder / "data"


def _check_products(products: Iterable[str]) -> tuple[str, ...]:
    prods = tuple(dict.fromkeys(products))
    bad = [p for p in prods if p not in PRODUCTS]
    if bad or not prods:
        raise ColoradarError(f"unknown product(s) {', '.join(bad) or '(none)'}; expected one or "
                             f"both of {', '.join(PRODUCTS)}")
    return prods


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
    """
    prods = _check_products(products)
    seq = open_sequence(seq_path, calib=calib_path)
    stream = seq.radar(radar).adc
    proc = RadarProcessor(seq.calib.radar(radar), settings)
    dirs = {p: output_paths(out, radar, p)[1] for p in prods}
    for k in frame_indices:
        fid = int(stream.frame_ids[k])
        hm, pts = proc.products(stream[k], "heatmaps" in prods, "pointclouds" in prods)
        if hm is not None:
            write_heatmap(dirs["heatmaps"] / _FILE["heatmaps"].format(fid), hm)
        if pts is not None:
            write_radar_pointcloud(dirs["pointclouds"] / _FILE["pointclouds"].format(fid), pts)
    return len(frame_indices)


def _timestamps_text(frame_ids: np.ndarray, timestamps: np.ndarray, written: np.ndarray) -> str:
    """Timestamps file for the frames ``written`` of a stream with these frames.

    Readers pair line ``j`` with frame ``base + j``, ``base`` being 1 when the first file is
    number 1 and 0 otherwise (DESIGN.md §1), so the lines run from that base to the last
    written frame; frames without an ADC timestamp read ``nan``.
    """
    if written.size == 0:
        return ""
    base = 1 if written.min() == 1 else 0
    last = int(written.max())
    lines = np.full(last - base + 1, np.nan)
    keep = (frame_ids >= base) & (frame_ids <= last)
    lines[frame_ids[keep] - base] = timestamps[keep]
    return format_timestamps(lines)


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def process_run(run: str | os.PathLike, out: str | os.PathLike, *, calib: CalibLike = None,
                radars: str | Sequence[str] = "all", products: Sequence[str] = PRODUCTS,
                frames: slice | None = None, overwrite: bool = False,
                settings: ProcessingSettings | None = None, progress: bool = True,
                chunk_size: int = 16) -> ProcessReport:
    """Process one run's ADC frames into heatmaps and/or point clouds under ``out``.

    Parameters
    ----------
    run
        Run folder or zip.
    out
        Output root (must not lie inside ``run``).
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
        Replace the files this run writes; otherwise any non-empty product folder is an
        :class:`~coloradar.errors.OutputExistsError` (checked before anything is written).
        Other files in those folders are left alone (never deleted).
    settings
        Processing settings.
    progress
        Show a progress line on stderr.
    chunk_size
        Frames per :func:`process_frames` call.

    Returns
    -------
    ProcessReport
    """
    t0 = time.perf_counter()
    prods = _check_products(products)
    run_p, out_p = Path(run).resolve(), Path(out).resolve()
    if _inside(out_p, run_p):
        raise ColoradarError(f"{out}: the output folder lies inside the run {run}; "
                             "choose an output folder outside it (coloradar never writes into "
                             "a run)")
    seq = open_sequence(run_p, calib=calib)
    have = [r for r in RADARS if f"{r}/adc" in seq.available()]
    if radars == "all":
        chosen = have
        if not chosen:
            raise MissingDataError(f"{run}: no radar ADC frames in this run (present: "
                                   f"{', '.join(seq.available()) or 'nothing'})")
    else:
        chosen = [radars] if isinstance(radars, str) else list(radars)
        for r in chosen:
            if r not in RADARS:
                raise MissingDataError(f"unknown radar {r!r}; expected one of "
                                       f"{', '.join(RADARS)} or all")
            if r not in have:
                raise MissingDataError(f"{run}: no {r} ADC frames in this run (present: "
                                       f"{', '.join(seq.available()) or 'nothing'})")
    existing = [d for r in chosen for p in prods
                if (d := output_paths(out_p, r, p)[0]).exists() and any(d.iterdir())]
    if existing and not overwrite:
        raise OutputExistsError("output exists: " + ", ".join(map(str, existing))
                                + "; pass overwrite=True (--overwrite) to replace it")
    report = ProcessReport()
    for radar in chosen:
        stream = seq.radar(radar).adc
        idx = list(range(len(stream)))[frames] if frames is not None else list(range(len(stream)))
        report.frames[radar] = len(idx)
        report.folders[radar] = []
        for p in prods:
            folder, data = output_paths(out_p, radar, p)
            data.mkdir(parents=True, exist_ok=True)
            report.folders[radar].append(folder)
        with Progress(len(idx), desc=f"{seq.name} {radar}", enabled=progress) as bar:
            for s in range(0, len(idx), chunk_size):
                chunk = idx[s: s + chunk_size]
                process_frames(run_p, seq.calib, radar, prods, chunk, out_p, settings)
                bar.update(len(chunk))
        # Written last: a folder with a timestamps file is complete.
        ids, ts = np.asarray(stream.frame_ids), np.asarray(stream.timestamps)
        stamps = _timestamps_text(ids, ts, ids[idx])
        for p in prods:
            folder = output_paths(out_p, radar, p)[0]
            if p == "heatmaps":
                proc_cfg = RadarProcessor(seq.calib.radar(radar), settings).heatmap_config()
                atomic_write_text(folder / "heatmap_cfg.txt", format_heatmap_cfg(proc_cfg))
            atomic_write_text(folder / "timestamps.txt", stamps)
    report.seconds = time.perf_counter() - t0
    return report
