"""``coloradar benchmark DATASET --out DIR``: odometry methods run and evaluated on many runs,
one table (text, CSV, JSON)."""

from __future__ import annotations

import argparse
import json
import sys

from ..errors import ColoradarError
from ..odometry.metrics import ALIGNMENTS, DRIFT_LENGTHS, RPE_PAIRINGS
from ._common import (
    add_executor_args,
    check_output_outside_dataset,
    executor_from_args,
    non_negative_int,
    positive_float,
)


def _named(text: str) -> tuple[str | None, str]:
    """``[NAME=]VALUE``."""
    name, sep, value = text.partition("=")
    if sep and name and "/" not in name and ":" not in name:
        return name, value
    return None, text


def _setting(text: str) -> tuple[str, object]:
    name, sep, value = text.partition("=")
    if not sep or not name.isidentifier():
        raise argparse.ArgumentTypeError(f"expected NAME=VALUE, got {text!r}")
    try:
        return name, json.loads(value)
    except json.JSONDecodeError:
        return name, value


def register(sub: argparse._SubParsersAction) -> None:
    lengths = " ".join(f"{x:g}" for x in DRIFT_LENGTHS)
    p = sub.add_parser(
        "benchmark", help="run odometry methods on every run of a dataset and tabulate "
                          "their errors",
        description="Run odometry on every run of DATASET (or --runs / --split), evaluate "
                    "each estimate against the ground truth the same way, and write one "
                    "table: per run and overall ATE (m and % of the distance), final-position "
                    "error %, KITTI-style translation drift (%) and rotation drift (deg/m), "
                    "ego-velocity RMSE and frames/s; the CSV and JSON also hold the RIO "
                    "literature's ATE after position + yaw alignment and relative errors over "
                    "25, 50, 75 and 100 m (rpg_trajectory_evaluation). Your own method joins the table as a "
                    "folder of TUM files (--estimate) or a Python function (--method). Output: "
                    "DIR/benchmark.txt, .csv, .json and DIR/<method>/<run>/ (estimate, "
                    "evaluation, groundtruth.txt for evo). A rerun with the same settings "
                    "resumes; a run that fails is a row of the table and the exit code is 1.")
    p.add_argument("dataset", metavar="DATASET", help="dataset root (run folders or zips, "
                   "calib/), or one run")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    sel = p.add_mutually_exclusive_group()
    sel.add_argument("--runs", metavar="PATTERNS",
                     help="comma-separated run names or shell patterns, e.g. '*hallways*' "
                          "(default: every run)")
    sel.add_argument("--split", metavar="NAME[:PART]",
                     help="the runs of a named split (coloradar.dataset.splits), or of one "
                          "of its parts")
    p.add_argument("--calib", metavar="DIR", help="calib folder or calib.zip (default: found "
                   "beside each run)")
    m = p.add_argument_group("methods (several side by side; default: coloradar's odometry)")
    m.add_argument("--estimator", action="append", default=[], metavar="NAME",
                   help="coloradar odometry estimator to run (repeatable; 'default' for its "
                        "default, 'slam' for coloradar slam (extra [slam]), 'none' to run "
                        "none of ours)")
    m.add_argument("--estimate", action="append", default=[], metavar="[NAME=]DIR",
                   help="a method's estimates: DIR/<run>.txt or DIR/<run>/trajectory.txt "
                        "(TUM, world_T_base), optionally DIR/<run>/ego_velocity.csv "
                        "(repeatable)")
    m.add_argument("--method", action="append", default=[], metavar="[NAME=]MODULE:FUNCTION",
                   help="a Python function taking a coloradar.Sequence and returning a "
                        "Trajectory (module importable from here, or path/to/file.py:function; "
                        "repeatable)")
    o = p.add_argument_group("coloradar odometry settings (every run)")
    o.add_argument("--radar", choices=("cascade", "single_chip"), default=None,
                   help="radar (default: the odometry's, cascade)")
    o.add_argument("--source", choices=("pointclouds", "adc", "heatmaps"), default=None,
                   help="point-cloud source (default: the run's best)")
    o.add_argument("--orientation", choices=("imu", "groundtruth"), default=None,
                   help="attitude of the dead-reckoning estimator (default imu)")
    o.add_argument("--seed", type=non_negative_int, default=None, help="RANSAC seed (default 0)")
    o.add_argument("--set", dest="settings", type=_setting, action="append", default=[],
                   metavar="NAME=VALUE",
                   help="any other keyword of coloradar.odometry.run_odometry, e.g. --set "
                        "duration=20 --set gyro_bias_window=2 (VALUE read as JSON when it "
                        "parses, else text); repeatable")
    e = p.add_argument_group("evaluation")
    e.add_argument("--align", choices=ALIGNMENTS, default="se3",
                   help="alignment before the ATE (default se3: Umeyama; posyaw: position + "
                        "yaw, in the CSV's ate_posyaw_* columns anyway)")
    e.add_argument("--drift-lengths", type=positive_float, nargs="+", default=list(DRIFT_LENGTHS),
                   metavar="M", help=f"segment lengths of the drift in metres (default "
                   f"{lengths})")
    e.add_argument("--distances", type=positive_float, nargs="+", default=[1.0, 2.0, 5.0], metavar="M",
                   help="RPE lengths reported per run in the JSON (default 1 2 5)")
    e.add_argument("--rpe-pairing", choices=RPE_PAIRINGS, default="every_pose",
                   help="pairs of those RPEs (default every_pose; evo: evo_rpe's)")
    add_executor_args(p)
    p.add_argument("--overwrite", action="store_true",
                   help="redo every run (default: resume a benchmark made with the same "
                        "settings, refuse one made otherwise)")
    p.add_argument("--quiet", action="store_true", help="no progress line, no table on stdout")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..odometry.benchmark import (
        Method,
        benchmark,
        builtin_method,
        callable_method,
        format_table,
        function_method,
        tum_method,
    )

    check_output_outside_dataset(args.out, (args.dataset, args.calib))
    executor = executor_from_args(args)
    methods: list[Method] = []
    estimators = args.estimator or (["default"] if not (args.estimate or args.method) else [])
    if "none" in estimators and len(estimators) > 1:
        raise ColoradarError("--estimator none runs none of ours; drop the other --estimator")
    for est in estimators:
        if est == "slam":
            # a higher layer than odometry: handed to the benchmark as a function method
            from ..slam.run import benchmark_method

            methods.append(function_method(benchmark_method, "slam"))
        elif est != "none":
            methods.append(builtin_method(None if est == "default" else est))
    for text in args.estimate:
        name, folder = _named(text)
        methods.append(tum_method(folder, name))
    for text in args.method:
        name, spec = _named(text)
        methods.append(callable_method(spec, name))
    if not methods:
        raise ColoradarError("no method to benchmark (--estimator none and no --estimate or "
                             "--method)")
    odometry = {k: getattr(args, k) for k in ("radar", "source", "orientation", "seed")
                if getattr(args, k) is not None}
    odometry.update(dict(args.settings))
    try:
        result = benchmark(args.dataset, args.out, methods=methods, runs=args.runs,
                           split=args.split, calib=args.calib, odometry=odometry,
                           align=args.align, distances=tuple(args.distances),
                           drift_lengths=tuple(args.drift_lengths),
                           rpe_pairing=args.rpe_pairing, executor=executor, jobs=args.jobs,
                           overwrite=args.overwrite, progress=not args.quiet)
    except KeyboardInterrupt:
        print("interrupted: finished runs are kept; the same command resumes", file=sys.stderr)
        raise
    finally:
        if executor is not None:
            executor.close()
    if not args.quiet:
        print(format_table(result), end="")
        for path in result.files:
            print(f"  wrote {path}")
    for row in result.failures:
        print(f"coloradar: {row['method']} on {row['run']} failed: {row['error']}",
              file=sys.stderr)
    return 0 if result.ok else 1
