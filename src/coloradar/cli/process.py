"""``coloradar process PATH --out OUT``: ADC frames of a run or a whole dataset → heatmaps and
point clouds, on a local process pool or a Dask cluster, resumable."""

from __future__ import annotations

import argparse
import os
import sys

from ..batch.driver import DEFAULT_CHUNK_SIZE, process
from ..batch.output_folder import PRODUCTS
from ..dsp import ProcessingSettings
from ..formats.source import check_input_path
from ._common import (
    UsageError,
    add_executor_args,
    check_output_outside_dataset,
    executor_from_args,
    positive_int,
    processing_setting,
)
from .calibrate import coupling_calibration


def _frames(text: str) -> slice:
    """``START:STOP`` (either may be empty) → slice."""
    parts = text.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        start, stop = (int(p) if p.strip() else None for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected START:STOP (e.g. 0:100 or 50:), got {text!r}") from None
    # Empty whatever the stream's length: a STOP of 0, or both ends counted from the same end
    # with STOP not after START (10:5, -2:-5). Said now, not as "nothing to do" with exit 0.
    reversed_ = (start is not None and stop is not None and (start < 0) == (stop < 0)
                 and stop <= start)
    if stop == 0 or reversed_:
        raise argparse.ArgumentTypeError(f"{text!r} selects no frame (STOP must come after "
                                         "START, as in Python slices)")
    return slice(start, stop)


def _products(text: str) -> tuple[str, ...]:
    prods = tuple(p.strip() for p in text.split(",") if p.strip())
    bad = [p for p in prods if p not in PRODUCTS]
    if bad or not prods:
        raise argparse.ArgumentTypeError(f"expected a comma-separated subset of "
                                         f"{','.join(PRODUCTS)}, got {text!r}")
    return prods


def _names(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names:
        raise argparse.ArgumentTypeError("expected comma-separated run names or patterns")
    return names


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "process", help="process raw ADC frames (a run or a whole dataset) into heatmaps and "
                        "point clouds",
        description="Run the radar processing chain (calibration, range/Doppler FFTs, TDM-MIMO "
                    "compensation, angle FFT, CFAR) on ADC frames and write heatmaps and point "
                    "clouds in the dataset's layout, keeping each frame's number and timestamp. "
                    "PATH is a run (folder or .zip): output in OUT/<radar>/; or a dataset root: "
                    "each run's output in OUT/<run>/<radar>/. Work runs in chunks of frames on "
                    "a local process pool (--jobs) or a Dask cluster (--scheduler). A rerun "
                    "resumes: frames already complete are kept, the rest processed. Frames "
                    "that fail are listed in OUT/process_report.json and the exit code is 1. "
                    "Never writes into the input.")
    p.add_argument("path", metavar="PATH", help="a run folder, a run .zip, or a dataset root")
    p.add_argument("--out", required=True, metavar="OUT", help="output folder (outside the runs)")
    p.add_argument("--runs", type=_names, metavar="NAMES",
                   help="with a dataset root: comma-separated run names or shell patterns, "
                        "e.g. '*hallways*' (default: every run)")
    p.add_argument("--calib", metavar="DIR",
                   help="calib folder or calib.zip (default: found beside each run)")
    p.add_argument("--coupling", metavar="FILE",
                   help="a coupling_calib.txt to subtract instead of the calibration's, for the "
                        "radar of its size (as 'coloradar calibrate coupling' writes it)")
    p.add_argument("--phase-calib", metavar="FILE",
                   help="a phase_frequency_calib.txt to calibrate the channels with instead of "
                        "the calibration's, for the radar of its size (as 'coloradar calibrate "
                        "phase' writes it); on a radar without one the Doppler alias search "
                        "keeps folded range rates")
    p.add_argument("--radar", choices=("cascade", "single_chip", "all"), default="all",
                   help="radar to process (default: every radar with ADC frames)")
    p.add_argument("--products", type=_products, default=PRODUCTS,
                   help="comma-separated: heatmaps,pointclouds (default: both)")
    p.add_argument("--frames", type=_frames, metavar="START:STOP",
                   help="positions in each ADC stream to process, Python slice style "
                        "(default: all)")
    p.add_argument("--set", dest="settings", type=processing_setting, action="append", default=[],
                   metavar="NAME=VALUE",
                   help="a processing setting (coloradar.dsp.ProcessingSettings), e.g. "
                        "--set angle_method=capon --set pfa=1e-5; repeatable")
    p.add_argument("--overwrite", action="store_true",
                   help="delete the requested products' existing frame files and redo every "
                        "frame (default: resume output made with the same settings; refuse "
                        "output made otherwise)")
    g = add_executor_args(p)
    g.add_argument("--chunk-size", type=positive_int, default=DEFAULT_CHUNK_SIZE, metavar="N",
                   help=f"frames per task (default {DEFAULT_CHUNK_SIZE})")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    executor = executor_from_args(args)
    try:
        settings = ProcessingSettings(**dict(args.settings)) if args.settings else None
    except ValueError as exc:
        raise UsageError(f"--set: {exc}") from None
    check_input_path(args.path, "a run folder, a run .zip or a dataset root folder")
    check_output_outside_dataset(args.out, (args.path, args.calib))
    try:
        one = None if args.radar == "all" else args.radar
        calib = (coupling_calibration(args.path, args.calib, args.coupling, one,
                                      args.phase_calib)
                 if args.coupling or args.phase_calib else args.calib)
        report = process(args.path, args.out, runs=args.runs, calib=calib,
                         radars=args.radar, products=args.products, frames=args.frames,
                         overwrite=args.overwrite, settings=settings, executor=executor,
                         jobs=args.jobs, chunk_size=args.chunk_size, progress=not args.quiet)
    except KeyboardInterrupt:
        print(f"interrupted: the frames written so far are kept; the same command resumes "
              f"(report: {os.path.join(args.out, 'process_report.json')})", file=sys.stderr)
        raise
    finally:
        if executor is not None:
            executor.close()
    # Failures are errors: on stderr, where a user who redirects the summary still sees them.
    for line in report.summary().splitlines():
        failed = line.startswith(("  failed:", "  … and")) or ": FAILED: " in line
        print(line, file=sys.stderr if failed else sys.stdout)
    return 0 if report.ok else 1
