"""``coloradar evaluate DIR``: odometry output against the run's ground truth."""

from __future__ import annotations

import argparse

from ..odometry import evaluate_odometry, format_evaluation, write_evaluation
from ..odometry.metrics import ALIGNMENTS, DRIFT_LENGTHS, RPE_PAIRINGS


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "evaluate", help="compare odometry output with the run's ground truth",
        description="Read DIR/trajectory.txt (TUM) and DIR/ego_velocity.csv written by "
                    "'coloradar odometry', and report the ego-velocity error against the "
                    "ground-truth radar velocity, the ATE after alignment and the RPE over "
                    "fixed distances, the position error at the end and the KITTI-style drift. "
                    "Writes DIR/evaluation.txt, DIR/evaluation.json, DIR/groundtruth.txt (the "
                    "ground truth at the estimate's timestamps, TUM, for evo) and "
                    "DIR/evaluation.png (with matplotlib).")
    p.add_argument("dir", help="output folder of 'coloradar odometry'")
    p.add_argument("--run", help="run folder or .zip (default: the one named in odometry.json)")
    p.add_argument("--calib", help="calib folder or calib.zip (default: the odometry's)")
    p.add_argument("--align", choices=ALIGNMENTS, default="se3",
                   help="trajectory alignment before the ATE (default se3: Umeyama)")
    p.add_argument("--distances", type=float, nargs="+", default=[1.0, 2.0, 5.0],
                   metavar="M", help="RPE segment lengths in metres (default 1 2 5)")
    p.add_argument("--rpe-pairing", choices=RPE_PAIRINGS, default="every_pose",
                   help="RPE pose pairs: every_pose (default: a pair from every pose), evo "
                        "(evo_rpe -u m: consecutive segments) or evo_all_pairs (--all_pairs)")
    p.add_argument("--drift-lengths", type=float, nargs="+", default=list(DRIFT_LENGTHS),
                   metavar="M", help="segment lengths of the KITTI-style drift in metres "
                   f"(default {' '.join(f'{x:g}' for x in DRIFT_LENGTHS)})")
    p.add_argument("--no-plot", action="store_true", help="do not write evaluation.png")
    p.add_argument("--quiet", action="store_true",
                   help="print nothing (the files are written all the same)")
    p.add_argument("--overwrite", action="store_true", help="replace an earlier evaluation")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    ev = evaluate_odometry(args.dir, args.run, calib=args.calib, align=args.align,
                           distances=tuple(args.distances), rpe_pairing=args.rpe_pairing,
                           drift_lengths=tuple(args.drift_lengths))
    files = write_evaluation(ev, args.dir, plot=not args.no_plot, overwrite=args.overwrite)
    if args.quiet:
        return 0
    print(format_evaluation(ev), end="")
    for path in files:
        print(f"  wrote {path}")
    return 0
