"""``coloradar map-score MAP``: a point map against a reference cloud (Chamfer, precision /
recall / F-score, voxel IoU)."""

from __future__ import annotations

import argparse
import json

from ..geometry import read_point_file
from ..geometry.cloud_metrics import format_map_scores, score_map
from ._common import positive_float


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "map-score", help="score a point map (e.g. SLAM's map.ply) against a reference cloud",
        description="Compare a map (PLY or PCD, world frame) with a reference: a point file "
                    "(--reference) or the run's lidar map built with its ground truth (--run). "
                    "Prints the Chamfer distance, precision / recall / F-score at a threshold "
                    "and the voxel IoU.")
    p.add_argument("map", help="the map (.ply or .pcd)")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--reference", help="reference point file (.ply or .pcd)")
    src.add_argument("--run", help="run folder or .zip: the reference is its lidar map placed "
                                   "with its ground truth")
    p.add_argument("--calib", help="calib folder or calib.zip (with --run)")
    p.add_argument("--threshold", type=positive_float, default=0.25, metavar="M",
                   help="distance of precision / recall / F-score (default 0.25 m)")
    p.add_argument("--voxel", type=positive_float, default=0.25, metavar="M",
                   help="voxel edge of the IoU (default 0.25 m)")
    p.add_argument("--json", action="store_true", help="print the scores as JSON")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    pred, _ = read_point_file(args.map)
    if args.reference:
        ref, _ = read_point_file(args.reference)
        what = args.reference
    else:
        from ..dataset import open_sequence
        from ..slam.run import reference_lidar_map

        ref = reference_lidar_map(open_sequence(args.run, calib=args.calib))
        what = f"the lidar map of {args.run} (ground truth)"
    s = score_map(pred, ref, threshold=args.threshold, voxel=args.voxel)
    if args.json:
        print(json.dumps(s.to_dict(), indent=2))
    else:
        print(format_map_scores(s, f"{args.map} against {what}:"), end="")
    return 0
