"""``coloradar process RUN --out OUT``: ADC frames → heatmaps and point clouds."""

from __future__ import annotations

import argparse

from ..batch.run_processing import PRODUCTS, process_run


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
    return slice(start, stop)


def _products(text: str) -> tuple[str, ...]:
    prods = tuple(p.strip() for p in text.split(",") if p.strip())
    bad = [p for p in prods if p not in PRODUCTS]
    if bad or not prods:
        raise argparse.ArgumentTypeError(f"expected a comma-separated subset of "
                                         f"{','.join(PRODUCTS)}, got {text!r}")
    return prods


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "process", help="process raw ADC frames into heatmaps and point clouds",
        description="Run the radar processing chain (calibration, range/Doppler FFTs, TDM-MIMO "
                    "compensation, angle FFT, CFAR) on a run's ADC frames and write heatmaps "
                    "and point clouds in the dataset's layout under OUT/<radar>/, keeping each "
                    "frame's number and timestamp. Never writes into RUN.")
    p.add_argument("run", metavar="RUN", help="run folder or run .zip")
    p.add_argument("--out", required=True, metavar="OUT", help="output folder (outside RUN)")
    p.add_argument("--calib", metavar="DIR",
                   help="calib folder or calib.zip (default: found beside the run)")
    p.add_argument("--radar", choices=("cascade", "single_chip", "all"), default="all",
                   help="radar to process (default: every radar with ADC frames)")
    p.add_argument("--products", type=_products, default=PRODUCTS,
                   help="comma-separated: heatmaps,pointclouds (default: both)")
    p.add_argument("--frames", type=_frames, metavar="START:STOP",
                   help="positions in the ADC stream to process, Python slice style "
                        "(default: all)")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")
    p.add_argument("--quiet", action="store_true", help="no progress line")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    report = process_run(args.run, args.out, calib=args.calib, radars=args.radar,
                         products=args.products, frames=args.frames, overwrite=args.overwrite,
                         progress=not args.quiet)
    for radar, n in report.frames.items():
        print(f"{radar}: {n} frames -> " + ", ".join(str(f) for f in report.folders[radar]))
    print(f"done in {report.seconds:.1f} s")
    return 0
