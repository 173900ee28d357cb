"""``coloradar evaluate DIR``: odometry output against the run's ground truth."""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

from ..errors import ColoradarError, DataWarning
from ..odometry import evaluate_odometry, format_evaluation, write_evaluation
from ..odometry.metrics import ALIGNMENTS, DRIFT_LENGTHS, RPE_PAIRINGS
from ._common import UsageError, check_input, check_output_outside_dataset, positive_float


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "evaluate", help="compare odometry output with the run's ground truth",
        description="Read DIR/trajectory.txt (TUM) and DIR/ego_velocity.csv written by "
                    "'coloradar odometry', and report the ego-velocity error against the "
                    "ground-truth radar velocity, the ATE after alignment and the RPE over "
                    "fixed distances, the position error at the end and the KITTI-style drift, "
                    "and the RIO literature's figures (rpg_trajectory_evaluation): the ATE "
                    "after position + yaw alignment and the relative error over 25, 50, 75 and "
                    "100 m. "
                    "Writes DIR/evaluation.txt, DIR/evaluation.json, DIR/groundtruth.txt (the "
                    "ground truth at the estimate's timestamps, TUM, for evo) and "
                    "DIR/evaluation.png (with matplotlib).")
    p.add_argument("dir", help="output folder of 'coloradar odometry'")
    p.add_argument("--run", help="run folder or .zip (default: the one named in odometry.json)")
    p.add_argument("--any-run", action="store_true",
                   help="evaluate against --run even when odometry.json names another run")
    p.add_argument("--calib", help="calib folder or calib.zip (default: the odometry's)")
    p.add_argument("--align", choices=ALIGNMENTS, default="se3",
                   help="trajectory alignment before the ATE (default se3: Umeyama; posyaw: "
                        "position + yaw, the 4-DoF alignment of visual/radar-inertial "
                        "odometry, always reported too)")
    p.add_argument("--distances", type=positive_float, nargs="+", default=[1.0, 2.0, 5.0],
                   metavar="M", help="RPE segment lengths in metres (default 1 2 5)")
    p.add_argument("--rpe-pairing", choices=RPE_PAIRINGS, default="every_pose",
                   help="RPE pose pairs: every_pose (default: a pair from every pose), evo "
                        "(evo_rpe -u m: consecutive segments), evo_all_pairs (--all_pairs) or "
                        "rpg (rpg_trajectory_evaluation: nearest d within 20 %%)")
    p.add_argument("--drift-lengths", type=positive_float, nargs="+", default=list(DRIFT_LENGTHS),
                   metavar="M", help="segment lengths of the KITTI-style drift in metres "
                   f"(default {' '.join(f'{x:g}' for x in DRIFT_LENGTHS)})")
    p.add_argument("--no-plot", action="store_true", help="do not write evaluation.png")
    p.add_argument("--quiet", action="store_true",
                   help="print nothing (the files are written all the same)")
    p.add_argument("--overwrite", action="store_true", help="replace an earlier evaluation")
    p.set_defaults(func=run)


def _named_run(folder: str) -> tuple[str | None, str | None]:
    """``(path, name)`` of the run that ``folder/odometry.json`` names (None when it names
    none or cannot be read: evaluate_odometry says why then)."""
    try:
        info = json.loads((Path(folder) / "odometry.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None, None
    if not isinstance(info, dict) or not info.get("run"):
        return None, None
    path = str(info["run"])
    return path, str(info.get("run_name") or Path(path).name.removesuffix(".zip"))


def _run_name(run: str) -> str:
    return Path(run).resolve().name.removesuffix(".zip")


def _check_time_overlap(folder: str, run: str | None, calib: str | None) -> None:
    """Warn when the estimate's time span is not covered by the run's ground truth (a run
    other than the estimate's, or a cut ground truth)."""
    from ..dataset import open_sequence
    from ..odometry.tum import read_tum

    if run is None:
        return
    try:
        est = read_tum(Path(folder) / "trajectory.txt").timestamps
        gt = open_sequence(run, calib=calib).groundtruth.timestamps
    except (ColoradarError, OSError):  # evaluate_odometry says what is wrong, in its words
        return
    if len(est) < 2 or len(gt) < 2:
        return
    span = float(est[-1] - est[0])
    overlap = min(float(est[-1]), float(gt[-1])) - max(float(est[0]), float(gt[0]))
    if overlap < span:
        warnings.warn(f"{folder}: the estimate spans {span:.1f} s but only "
                      f"{max(overlap, 0.0):.1f} s of it lie within the ground truth of {run}; "
                      "the figures cover that part only", DataWarning, stacklevel=2)


def run(args: argparse.Namespace) -> int:
    named_path, named = _named_run(args.dir)
    if args.run is not None:
        check_input(args.run)
        if named is not None and _run_name(args.run) != named and not args.any_run:
            raise UsageError(f"--run {args.run}: {args.dir}/odometry.json names the run {named}; "
                             "against another run's ground truth the figures mean nothing "
                             "(pass --any-run to insist)")
    check_output_outside_dataset(args.dir, (args.run or named_path, args.calib))
    _check_time_overlap(args.dir, args.run or named_path, args.calib)
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
