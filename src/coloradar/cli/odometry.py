"""``coloradar odometry RUN --out DIR``: radar ego-velocity and radar–inertial dead reckoning."""

from __future__ import annotations

import argparse
import sys

from ..dataset import open_sequence
from ..odometry import (
    ORIENTATION_SOURCES,
    SOURCES,
    ego_velocity_config,
    path_length,
    run_odometry,
)
from ..progress import Progress


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "odometry", help="estimate radar ego-velocity and a radar-inertial trajectory",
        description="Estimate the radar's velocity in every frame from the range rates of its "
                    "point cloud (RANSAC + least squares), integrate it with the gyro attitude "
                    "into the rig's trajectory, and write DIR/ego_velocity.csv, "
                    "DIR/trajectory.txt (TUM: timestamp x y z qx qy qz qw) and "
                    "DIR/odometry.json. Evaluate with 'coloradar evaluate DIR'.")
    p.add_argument("run", help="run folder or .zip")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--radar", choices=("cascade", "single_chip"), default="cascade",
                   help="which radar (default cascade)")
    p.add_argument("--source", choices=SOURCES,
                   help="point clouds from: the sensor's own point clouds (single chip), raw "
                        "ADC frames (processed with coloradar.dsp), or heatmaps; default: "
                        "pointclouds when present, else adc, else heatmaps")
    p.add_argument("--orientation", choices=ORIENTATION_SOURCES, default="imu",
                   help="attitude from the IMU gyro (default) or from the ground truth "
                        "(an upper bound)")
    p.add_argument("--threshold", type=float,
                   help="inlier threshold on range-rate residuals [m/s] (default from the "
                        "radar's Doppler resolution)")
    p.add_argument("--min-inliers", type=int, help="fewest static points per frame (default 6)")
    p.add_argument("--model", choices=("auto", "3d", "planar"), default="auto",
                   help="estimate vx vy vz (3d) or vx vy with vz = 0 (planar); auto: planar for "
                        "a radar with fewer than 3 elevation rows (the single chip)")
    p.add_argument("--gyro-bias-window", type=float, metavar="S",
                   help="the rig is at rest for the first S seconds of the IMU stream: subtract "
                        "their mean rate as gyro bias")
    p.add_argument("--start", type=float, help="seconds after the first radar frame")
    p.add_argument("--duration", type=float, help="seconds to process (default: to the end)")
    p.add_argument("--stride", type=int, default=1, help="use every N-th frame (default 1)")
    p.add_argument("--seed", type=int, default=0, help="RANSAC seed (default 0)")
    p.add_argument("--calib", help="calib folder or calib.zip (default: found beside the run)")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")
    p.add_argument("--quiet", action="store_true",
                   help="no progress counter (shown only on a terminal anyway)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    seq = open_sequence(args.run, calib=args.calib)
    overrides = {}
    if args.threshold is not None:
        overrides["threshold"] = args.threshold
    if args.min_inliers is not None:
        overrides["min_inliers"] = args.min_inliers
    if args.model != "auto":
        overrides["planar"] = args.model == "planar"
    cfg = ego_velocity_config(seq.calib.radar(args.radar), **overrides)
    progress = None if args.quiet else Progress(0, f"{args.radar} frames")
    res = run_odometry(seq, args.out, radar=args.radar, source=args.source,
                       orientation=args.orientation, config=cfg, start=args.start,
                       duration=args.duration, stride=args.stride, seed=args.seed,
                       gyro_bias_window=args.gyro_bias_window, overwrite=args.overwrite,
                       progress=progress)
    tr, traj = res.track, res.trajectory
    dist = float(path_length(traj.translations)[-1])
    print(f"{seq.name}: {int(tr.ok.sum())}/{len(tr)} {args.radar} frames with an ego-velocity; "
          f"trajectory of {len(traj)} poses, {dist:.1f} m travelled", file=sys.stdout)
    for path in res.files:
        print(f"  wrote {path}")
    return 0
