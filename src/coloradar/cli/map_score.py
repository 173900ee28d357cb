"""``coloradar map-score MAP``: a map against a reference cloud (Chamfer, precision /
completeness / F-score at 0.1 and 0.3 m, voxel IoU) and, for an occupancy map and a run, the
IoU of its 2-D grid against the lidar's."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from ..errors import MissingDataError
from ..geometry import read_point_file
from ..geometry.cloud_metrics import format_map_scores, score_map
from ._common import positive_float


def _thresholds(text: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if not vals or not all(0 < v < float("inf") for v in vals):
        raise argparse.ArgumentTypeError(f"expected distances > 0 separated by commas, got "
                                         f"{text!r}")
    return vals


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "map-score", help="score a map (map.ply, or a 'coloradar map' / 'coloradar slam' "
                          "folder) against a reference cloud or the run's lidar",
        description="Compare a map (PLY or PCD, world frame; or the folder 'coloradar map' or "
                    "'coloradar slam' wrote) with a reference: a point file (--reference) or "
                    "the run's lidar map placed with the map's own poses (--run; the ground "
                    "truth for a plain point file). Prints the Chamfer distance, precision / "
                    "recall / F-score at --threshold, the voxel IoU, and precision / "
                    "completeness / F-score at --thresholds. For an occupancy map folder with "
                    "--run: completeness counts the lidar points the map observed, and the IoU "
                    "of the 2-D grid's occupied cells against the lidar's occupancy grid built "
                    "with the same poses (lidar free space from lidar rays) is added.")
    p.add_argument("map", help="the map (.ply or .pcd), or a map folder")
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--reference", help="reference point file (.ply or .pcd)")
    src.add_argument("--run", help="run folder or .zip: the reference is its lidar")
    p.add_argument("--calib", help="calib folder or calib.zip (with --run)")
    p.add_argument("--threshold", type=positive_float, default=0.25, metavar="M",
                   help="distance of precision / recall / F-score (default 0.25 m)")
    p.add_argument("--thresholds", type=_thresholds, default=(0.1, 0.3), metavar="M,M",
                   help="distances of precision / completeness / F-score (default 0.1,0.3)")
    p.add_argument("--voxel", type=positive_float, default=0.25, metavar="M",
                   help="voxel edge of the IoU (default 0.25 m)")
    p.add_argument("--json", action="store_true", help="print the scores as JSON")
    p.set_defaults(func=run)


def _folder_map(folder: Path):
    """``(map.ply, occupancy map or None, poses file or None, band or None)`` of a map folder."""
    ply = folder / "map.ply"
    if not ply.is_file():
        raise MissingDataError(f"{folder}: expected a map folder of 'coloradar map' or "
                               "'coloradar slam' (with map.ply), or a .ply / .pcd file")
    occ = poses = band = None
    if (folder / "occupancy.npz").is_file():
        from ..mapping import OccupancyMap

        occ = OccupancyMap.load(folder / "occupancy.npz")
    for name in ("poses.txt", "trajectory.txt"):
        if (folder / name).is_file():
            poses = folder / name
            break
    for name, key in (("map.json", "grid"), ("slam.json", "summary")):
        if (folder / name).is_file():
            info = json.loads((folder / name).read_text())
            b = (info.get(key) or {}).get("band_m") or \
                ((info.get(key) or {}).get("occupancy") or {}).get("band_m")
            band = tuple(b) if b else None
    return ply, occ, poses, band


def run(args: argparse.Namespace) -> int:
    from ..mapping.quality import format_map_quality, lidar_grid, map_quality

    given = Path(args.map)
    occ = poses_file = band = None
    ply = given
    if given.is_dir():
        ply, occ, poses_file, band = _folder_map(given)
    pred, _ = read_point_file(ply)
    iou = None
    if args.reference:
        ref, _ = read_point_file(args.reference)
        what = args.reference
    else:
        from ..dataset import open_sequence
        from ..geometry import build_map
        from ..mapping import grid_iou, occupancy_grid

        seq = open_sequence(args.run, calib=args.calib)
        traj = None
        if poses_file is not None:
            from ..odometry.tum import read_tum

            traj = read_tum(poses_file)
        ref = build_map(seq, "lidar", voxel_size=0.1, stride=5, min_range=0.5,
                        trajectory=traj).points[:, :3]
        placed = f"placed with {poses_file}" if traj is not None else "ground truth"
        what = f"the lidar map of {args.run} ({placed})"
        if occ is not None and traj is not None and band is not None:
            iou = grid_iou(occupancy_grid(occ, *band), lidar_grid(seq, traj, occ.voxel, band))
    s = score_map(pred, ref, threshold=args.threshold, voxel=args.voxel)
    q = map_quality(pred, ref, args.thresholds, observed=occ, grid_iou=iou)
    if args.json:
        print(json.dumps({**s.to_dict(), "quality": q.to_dict()}, indent=2))
    else:
        print(format_map_scores(s, f"{ply} against {what}:"), end="")
        print(format_map_quality(q), end="")
    return 0
