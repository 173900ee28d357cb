"""``coloradar slam RUN --out DIR``: radar SLAM (keyframe submaps, loop closures, a pose graph
and a radar map) from one radar and the IMU."""

from __future__ import annotations

import argparse
from dataclasses import replace

from ..dataset import open_sequence
from ..dsp.points import POINT_SOURCES
from ..errors import MissingDataError
from ..geometry.cloud_metrics import format_map_scores
from ._common import (
    check_input,
    check_output_outside_dataset,
    non_negative_int,
    other_radar_hint,
    pick_radar,
    positive_float,
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "slam", help="radar SLAM: loop closures, a pose graph and a radar map (radar + IMU)",
        description="Run the radar-inertial filter as front end, build keyframe submaps of "
                    "static radar points, find loop closures (scan-context descriptor within "
                    "the odometry's uncertainty, verified by small_gicp registration and "
                    "consistency tests), optimise the pose graph with GTSAM, and write "
                    "DIR/trajectory.txt (TUM, every radar frame), odometry.txt (before), "
                    "keyframes.csv, loops.csv, map.ply (an occupancy map; --map points: the "
                    "keyframes' points), slam.json and slam.png. Evaluate the "
                    "trajectory with 'coloradar evaluate DIR'. Needs the extra [slam] "
                    "(gtsam, small_gicp).")
    p.add_argument("run", help="run folder or .zip")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--radar", choices=("single_chip", "cascade"),
                   help="which radar (default: single_chip, or the run's only radar)")
    p.add_argument("--source", choices=POINT_SOURCES,
                   help="point clouds from the sensor's own point clouds, ADC frames or "
                        "heatmaps (default: pointclouds when present, else adc, else heatmaps)")
    p.add_argument("--keyframe-distance", type=positive_float, default=1.0, metavar="M",
                   help="a keyframe every M metres (default 1)")
    p.add_argument("--keyframe-angle", type=positive_float, default=15.0, metavar="DEG",
                   help="or every DEG degrees of turn (default 15)")
    p.add_argument("--smooth-frontend", action=argparse.BooleanOptionalAction, default=True,
                   help="smooth the radar-inertial filter's poses with the later frames too "
                        "(Rauch-Tung-Striebel) before they become odometry factors (default on)")
    p.add_argument("--refine-odometry", action=argparse.BooleanOptionalAction, default=True,
                   help="also register consecutive keyframe submaps and add the results as "
                        "gated factors beside the odometry's (scan-to-submap refinement; "
                        "default on)")
    p.add_argument("--disjoint-registration", choices=("elevation", "always", "never"),
                   default="elevation",
                   help="register keyframes whose submaps share no frame and add the results "
                        "as factors: for a radar that resolves elevation (the cascade; "
                        "default), always, or never")
    p.add_argument("--map", choices=("occupancy", "points"), default="occupancy",
                   help="map.ply: an occupancy map of every frame along the optimised "
                        "trajectory (default; with occupancy.npz and the ROS grid grid.pgm + "
                        "grid.yaml), or the keyframes' points seen from 3 keyframes (the map "
                        "before the occupancy map)")
    p.add_argument("--score-map", action="store_true",
                   help="score the map against the lidar map built with ground truth (the run "
                        "needs lidar and ground truth); the scores go to slam.json")
    p.add_argument("--seed", type=non_negative_int, default=0, help="RANSAC seed (default 0)")
    p.add_argument("--calib", help="calib folder or calib.zip (default: found beside the run)")
    p.add_argument("--no-plot", action="store_true", help="do not write slam.png")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")
    p.add_argument("--quiet", action="store_true", help="print nothing")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..slam import SlamSettings
    from ..slam.run import run_slam

    settings = replace(SlamSettings(), keyframe_distance=args.keyframe_distance,
                       keyframe_angle_deg=args.keyframe_angle,
                       refine_odometry=args.refine_odometry,
                       smooth_frontend=args.smooth_frontend,
                       disjoint_registration=args.disjoint_registration, map_kind=args.map)
    check_input(args.run)
    check_output_outside_dataset(args.out, (args.run, args.calib))
    seq = open_sequence(args.run, calib=args.calib)
    args.radar = pick_radar(seq, args.radar, "single_chip", args.quiet)
    try:
        out = run_slam(seq, args.out, radar=args.radar, source=args.source, settings=settings,
                       seed=args.seed, score_against_lidar=args.score_map,
                       plot=not args.no_plot, overwrite=args.overwrite)
    except MissingDataError as exc:
        raise MissingDataError(f"{exc}{other_radar_hint(seq, args.radar)}") from None
    if args.quiet:
        return 0
    s = out.summary
    t = sum(s["timings_s"].values())
    print(f"{seq.name}: {s['frames']} {args.radar} frames, {s['distance_m']:.1f} m in "
          f"{s['duration_s']:.1f} s; {s['keyframes']} keyframes; {s['loops_accepted']} of "
          f"{s['loop_candidates']} loop candidates accepted; map of {s['map_points']:,} voxels; "
          f"{t:.1f} s ({s['duration_s'] / max(t, 1e-9):.1f}x real time)")
    if s["factors"]["registration"]:
        print(f"  {s['factors']['registration']} registration factors between keyframes whose "
              "submaps share no frame")
    sc = s["odometry_scale"]
    if sc["pairs"]:
        print(f"  odometry scale {sc['measured']:.4f} ± {sc['std']:.4f} from {sc['pairs']} "
              f"registrations: " + ("applied" if sc["used"] else "not applied (too uncertain)"))
    if out.map_scores is not None:
        print(format_map_scores(out.map_scores, "map against the lidar map (ground truth):"),
              end="")
    for path in out.files:
        print(f"  wrote {path}")
    return 0
