"""``coloradar info PATH``: what a dataset root or a run holds."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..calib import load_calibration
from ..dataset import open_dataset, open_sequence
from ..dataset.dataset import is_run_folder
from ..dataset.info import (
    format_calibration_summary,
    format_sequence_summary,
    summarize_sequence,
)
from ..errors import ColoradarError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "info", help="summarise a dataset root or a run (folder or zip)",
        description="Sensors present, frame counts, duration, rate of each stream, gaps in "
                    "timestamps, and the calibration of a ColoRadar dataset root or run.")
    p.add_argument("path", help="dataset root, run folder, or run .zip")
    p.add_argument("--calib", help="calib folder or calib.zip (default: found beside the run)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    path = Path(args.path)
    if path.is_dir() and (path / "transforms").is_dir() and not is_run_folder(path):
        print(format_calibration_summary(load_calibration(path)))
        return 0
    if path.is_dir() and not is_run_folder(path):
        ds = open_dataset(path, calib=args.calib)
        kind = "" if ds.layout.name == "coloradar" else f" ({ds.layout.title} layout)"
        print(f"dataset {path}: {len(ds)} runs{kind}")
        bad = 0
        for name in ds.sequences:  # one bad run is reported, and the others still are
            try:
                summaries = summarize_sequence(ds[name])
                print(format_sequence_summary(ds[name], summaries))
                bad += any(s.errors for s in summaries)
            except ColoradarError as exc:
                print(f"run {name}: error: {exc}")
                bad += 1
        print(format_calibration_summary(ds))
        if bad:
            print(f"coloradar: error: {bad} of {len(ds)} runs have unreadable or malformed "
                  "files (marked ! above)", file=sys.stderr)
        return 1 if bad else 0
    seq = open_sequence(path, calib=args.calib)
    summaries = summarize_sequence(seq)
    print(format_sequence_summary(seq, summaries))
    print(format_calibration_summary(seq))
    return 1 if any(s.errors for s in summaries) else 0
