"""``coloradar score PRED_DIR RUN``: predicted point clouds against a run's lidar targets."""

from __future__ import annotations

import argparse

from ..formats.atomic import new_output_path
from ..learning.scoring import PREDICTION_SUFFIXES, format_score_report, score_folder, write_score_report
from ..learning.targets import TargetSettings
from ..progress import Progress
from ._common import (
    UsageError,
    check_input,
    check_output_outside_dataset,
    is_run_folder_path,
    positive_float,
    positive_int,
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "score", help="score predicted point clouds against a run's lidar targets",
        description="Compare one predicted cloud per radar frame (files in PRED_DIR named by the "
                    "radar frame's number, e.g. 000012.npy; "
                    f"{', '.join(PREDICTION_SUFFIXES)}; points in the radar frame) with the "
                    "run's lidar target of that frame (the lidar map cut to the radar's field of "
                    "view): Chamfer distance, modified Hausdorff distance, F-score at a "
                    "threshold, BEV occupancy IoU / precision / recall. RUN is a run folder or "
                    "zip, or a file written by 'coloradar export RUN OUT.h5 --format hdf5' with "
                    "targets.")
    p.add_argument("pred_dir", help="folder of predicted clouds")
    p.add_argument("run", help="run folder or .zip, or an exported .h5")
    p.add_argument("--radar", choices=("cascade", "single_chip"), default="cascade",
                   help="the radar whose frames are predicted (default cascade)")
    p.add_argument("--threshold", type=positive_float, default=0.2,
                   help="F-score distance in m (default 0.2)")
    p.add_argument("--cell", type=positive_float, default=0.1,
                   help="BEV cell in m for the occupancy scores")
    p.add_argument("--voxel-size", type=positive_float, default=0.1,
                   help="lidar map voxel in m (run folders; default 0.1)")
    p.add_argument("--min-hits", type=positive_int, default=1, help="scans that must hit a map voxel")
    p.add_argument("--bin-columns", type=positive_int, default=None,
                   help="float32 values per row of .bin files (default: by the file's kind: 5 "
                        "for radar_pointcloud_<i>.bin, what 'coloradar process' writes; 4 for "
                        "lidar_pointcloud_<i>.bin; 3 for any other name)")
    p.add_argument("--out", help="also write per-frame scores to this .json file")
    p.add_argument("--calib", help="calib folder or calib.zip (default: found beside the run)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if is_run_folder_path(args.pred_dir):
        raise UsageError(f"{args.pred_dir}: this is a ColoRadar run, not a folder of predicted "
                         "clouds (are the arguments swapped? PRED_DIR comes first)")
    if not args.run.lower().endswith((".h5", ".hdf5")):
        check_input(args.run, "a run folder or .zip, or an exported .h5 file")
    if args.out:
        check_output_outside_dataset(args.out, (args.run, args.calib))
        new_output_path(args.out, args.overwrite)  # before the scoring, not after it
    settings = TargetSettings(voxel_size=args.voxel_size, min_hits=args.min_hits)
    prog = Progress(0, "score", unit="frames", enabled=not args.quiet)
    report = score_folder(args.pred_dir, args.run, radar=args.radar, threshold=args.threshold,
                          cell=args.cell, bin_columns=args.bin_columns, target_settings=settings,
                          calib=args.calib, progress=prog)
    prog.close()
    print(format_score_report(report), end="")
    if args.out:
        print(f"wrote {write_score_report(report, args.out, args.overwrite)}")
    return 0
