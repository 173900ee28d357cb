"""``coloradar map RUN --out map.pcd``: a run's point clouds accumulated in the world frame."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..dataset import open_sequence
from ..geometry import MAP_SOURCES, build_map, write_point_file
from ..geometry.cloud_io import check_point_file_name
from ..progress import Progress
from ._common import (
    add_file_output_args,
    add_quiet_arg,
    check_input,
    new_output_file,
    non_negative_float,
    positive_float,
    positive_int,
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "map", help="accumulate a run's lidar or radar point clouds into a world-frame map",
        description="Move every point cloud of a time window into the world frame with the "
                    "interpolated ground truth and the sensor's extrinsic, optionally voxel "
                    "down-sample, and write a PCD or PLY file (by the --out suffix).")
    p.add_argument("run", help="run folder or .zip")
    p.add_argument("--out", required=True, help="output .pcd or .ply file")
    p.add_argument("--sensor", default="lidar", choices=sorted(MAP_SOURCES),
                   help="whose point clouds (default: lidar)")
    p.add_argument("--products",
                   help="output folder of 'coloradar process' for this run: radar point "
                        "clouds are read from it (default: the radar's own point clouds, or "
                        "computed from its ADC frames when it has none, as the cascade)")
    p.add_argument("--start", type=non_negative_float, default=0.0,
                   help="window start, seconds after the first ground-truth pose (default 0)")
    p.add_argument("--duration", type=positive_float, help="window length in seconds (default: to the end)")
    p.add_argument("--voxel", type=positive_float, help="voxel size in metres for down-sampling")
    p.add_argument("--stride", type=positive_int, default=1, help="use every N-th frame (default 1)")
    p.add_argument("--min-range", type=non_negative_float, default=0.0,
                   help="drop points closer to the sensor than this [m] (the rig itself)")
    p.add_argument("--max-range", type=positive_float, help="drop points farther than this [m]")
    p.add_argument("--ascii", action="store_true", help="write ascii instead of binary")
    add_file_output_args(p)
    add_quiet_arg(p)
    p.set_defaults(func=run)


def _points_source(args: argparse.Namespace, points_from: str) -> str:
    """Where a radar map's points came from, said in the summary (with --products, whether
    the processed folder or the run gave them)."""
    if args.sensor == "lidar":
        return ""
    processed = args.products is not None and (
        Path(args.products) / args.sensor / "pointclouds").is_dir()
    if points_from == "adc":
        return ", points computed from their ADC" + (
            f" (none in {args.products})" if args.products else "")
    if processed:
        return f", points from {Path(args.products) / args.sensor / 'pointclouds'}"
    return ", the run's own point clouds" + (
        f" (none in {args.products})" if args.products else "")


def run(args: argparse.Namespace) -> int:
    check_input(args.run)
    out = new_output_file(str(check_point_file_name(args.out)), args.overwrite,
                          inputs=(args.run, args.calib))
    seq = open_sequence(args.run, calib=args.calib, products=args.products)
    m = build_map(seq, args.sensor, start=args.start, duration=args.duration,
                  voxel_size=args.voxel, stride=args.stride, max_range=args.max_range,
                  min_range=args.min_range,
                  progress=Progress(0, f"{args.sensor} frames", enabled=not args.quiet))
    write_point_file(out, m.points, m.fields, binary=not args.ascii, overwrite=args.overwrite)
    if not args.quiet:
        src = _points_source(args, m.points_from)
        print(f"{out}: {len(m.points):,} points from {m.frame_indices.size} {args.sensor} "
              f"frames{src} ({', '.join(m.fields)}, world frame)", file=sys.stdout)
    # Said every time (the CalibrationWarning shows once, when the calibration is loaded).
    used = [f"{args.sensor} extrinsic"] + ([f"{args.sensor} radar"] if m.points_from == "adc"
                                           else [])
    note = seq.calib.preset_note(used)
    if note:
        print(f"note: {note}", file=sys.stderr)
    return 0
