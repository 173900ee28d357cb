"""``coloradar odometry RUN --out DIR``: radar ego-velocity and radar-inertial odometry (EKF or
dead reckoning)."""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace

from ..dataset import open_sequence
from ..errors import MissingDataError
from ..odometry import (
    ESTIMATORS,
    ORIENTATION_SOURCES,
    SOURCES,
    ego_velocity_config,
    path_length,
    run_odometry,
)
from ..odometry.rio import UPDATES, RioConfig
from ..progress import Progress
from ._common import (
    check_output_outside_dataset,
    float_in,
    int_in,
    non_negative_float,
    non_negative_int,
    other_radar_hint,
    pick_radar,
    positive_float,
    positive_int,
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "odometry", help="estimate radar ego-velocity and a radar-inertial trajectory",
        description="Estimate the radar's velocity in every frame from the range rates of its "
                    "point cloud (RANSAC + least squares) and fuse it with the IMU in an "
                    "error-state EKF (IMU propagation, radar velocity updates, automatic "
                    "zero-velocity updates, online IMU biases and radar time offset; "
                    "--estimator dead-reckoning: the gyro-attitude baseline), and write "
                    "DIR/ego_velocity.csv, DIR/trajectory.txt (TUM: timestamp x y z qx qy qz "
                    "qw) and DIR/odometry.json (settings; for the filter its biases, time "
                    "offset and per-pose covariance). Evaluate with 'coloradar evaluate DIR'.")
    p.add_argument("run", help="run folder or .zip")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--radar", choices=("cascade", "single_chip"),
                   help="which radar (default: cascade, or the run's only radar)")
    p.add_argument("--source", choices=SOURCES,
                   help="point clouds from: the sensor's own point clouds (single chip), raw "
                        "ADC frames (processed with coloradar.dsp), or heatmaps; default: "
                        "pointclouds when present, else adc, else heatmaps")
    p.add_argument("--estimator", choices=ESTIMATORS, default="rio",
                   help="rio: the radar-inertial error-state EKF (default); dead-reckoning: "
                        "ego-velocities integrated with the gyro attitude (the baseline)")
    p.add_argument("--fuse", choices=("cascade", "single_chip"), action="append", default=None,
                   metavar="RADAR",
                   help="filter: also update it with this radar's ego-velocities (default: "
                        "the other radar when the run has its data)")
    p.add_argument("--no-fuse", action="store_true",
                   help="filter: use the --radar radar only")
    p.add_argument("--no-time-offset", action="store_true",
                   help="filter: do not estimate the radar-IMU time offset")
    p.add_argument("--time-offset", type=float_in(-1.0, 1.0), default=0.0, metavar="S",
                   help="filter: initial radar-IMU time offset t_d [s] (a frame stamped t "
                        "shows the motion at IMU time t + t_d; within ±1 s; default 0)")
    p.add_argument("--no-extrinsic-rotation", action="store_true",
                   help="filter: take the radar's extrinsic rotation as exact (default: "
                        "refine it online, the calibration's as prior)")
    p.add_argument("--extrinsic-rotation-axes", choices=("auto", "all", "yaw"), default="auto",
                   help="filter: refine the extrinsic's roll, pitch and yaw (all) or its yaw "
                        "alone; auto (default): yaw alone for a radar with fewer than 3 "
                        "elevation rows (the single chip), all for the others")
    p.add_argument("--imu-noise-scale", type=positive_float, default=1.0, metavar="K",
                   help="filter: multiply the IMU noise densities and bias walks of the "
                        "3DM-GX5-25 datasheet by K (default 1)")
    p.add_argument("--orientation", choices=ORIENTATION_SOURCES, default="imu",
                   help="dead reckoning: attitude from the IMU gyro (default) or from the "
                        "ground truth (an upper bound)")
    p.add_argument("--threshold", type=positive_float,
                   help="inlier threshold on range-rate residuals [m/s] (default from the "
                        "radar's Doppler resolution)")
    p.add_argument("--min-inliers", type=int_in(3),
                   help="fewest static points per frame (at least 3; default 6)")
    p.add_argument("--model", choices=("auto", "3d", "planar"), default="auto",
                   help="estimate vx vy vz (3d) or vx vy with vz held near 0 (planar: this "
                        "radar, for a rig that truly stays in its plane, such as a wheeled "
                        "vehicle; the single chip's default before issue 42); auto (default): "
                        "the filter's Doppler-point update is 3d for every radar, the "
                        "per-frame ego-velocities are planar for a radar with fewer than 3 "
                        "elevation rows (the single chip)")
    p.add_argument("--update", choices=UPDATES, default="doppler",
                   help="filter: every Doppler point a measurement, gated point by point "
                        "(doppler, default) or one RANSAC ego-velocity per frame "
                        "(ego-velocity, loosely coupled)")
    p.add_argument("--gyro-bias-window", type=positive_float, metavar="S",
                   help="dead reckoning: the rig is at rest for the first S seconds of the IMU "
                        "stream: subtract their mean rate as gyro bias")
    p.add_argument("--start", type=non_negative_float, help="seconds after the first radar frame")
    p.add_argument("--duration", type=positive_float, help="seconds to process (default: to the end)")
    p.add_argument("--stride", type=positive_int, default=1, help="use every N-th frame (default 1)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="RANSAC seed (default 0)")
    p.add_argument("--calib", help="calib folder or calib.zip (default: found beside the run)")
    p.add_argument("--overwrite", action="store_true", help="replace existing output files")
    p.add_argument("--quiet", action="store_true",
                   help="no progress counter (shown only on a terminal anyway)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    check_output_outside_dataset(args.out, (args.run, args.calib))
    seq = open_sequence(args.run, calib=args.calib)
    args.radar = pick_radar(seq, args.radar, "cascade", args.quiet)
    overrides = {}
    if args.threshold is not None:
        overrides["threshold"] = args.threshold
    if args.min_inliers is not None:
        overrides["min_inliers"] = args.min_inliers
    if args.model != "auto":
        overrides["planar"] = args.model == "planar"
    cfg = ego_velocity_config(seq.calib.radar(args.radar), **overrides)
    base = RioConfig()
    k = args.imu_noise_scale
    # planar: the named radar's ego-velocities planar and each radar's Doppler points as its
    # ego-velocity model (the default before issue 42); 3d: every radar's points in 3-D.
    planar = {"auto": base.doppler.planar, "planar": None, "3d": False}[args.model]
    rio = replace(base, estimate_time_offset=not args.no_time_offset,
                  update=args.update, doppler=replace(base.doppler, planar=planar),
                  time_offset=args.time_offset,
                  estimate_extrinsic_rotation=not args.no_extrinsic_rotation,
                  extrinsic_rotation_axes=args.extrinsic_rotation_axes,
                  accel_noise_density=base.accel_noise_density * k,
                  gyro_noise_density=base.gyro_noise_density * k,
                  accel_bias_walk=base.accel_bias_walk * k,
                  gyro_bias_walk=base.gyro_bias_walk * k)
    progress = None if args.quiet else Progress(0, f"{args.radar} frames")
    try:
        res = run_odometry(seq, args.out, radar=args.radar, source=args.source,
                           orientation=args.orientation, config=cfg, start=args.start,
                           duration=args.duration, stride=args.stride, seed=args.seed,
                           gyro_bias_window=args.gyro_bias_window, overwrite=args.overwrite,
                           progress=progress, estimator=args.estimator, rio_config=rio,
                           fuse=() if args.no_fuse else
                           ("auto" if args.fuse is None else tuple(args.fuse)))
    except MissingDataError as exc:
        raise MissingDataError(f"{exc}{other_radar_hint(seq, args.radar)}") from None
    tr, traj = res.track, res.trajectory
    dist = float(path_length(traj.translations)[-1])
    edge = len(tr) - len(traj) if args.estimator == "rio" else 0
    print(f"{seq.name}: {int(tr.ok.sum())}/{len(tr)} {args.radar} frames with an ego-velocity; "
          f"trajectory of {len(traj)} poses, {dist:.1f} m travelled"
          + (f" ({edge} frame{'s' if edge > 1 else ''} at the edges of the IMU's span left out)"
             if edge > 0 else ""), file=sys.stdout)
    if args.estimator == "rio":
        import json

        info = json.loads(res.files[2].read_text(encoding="utf-8"))["rio"]
        td = ", ".join(f"{r} {1e3 * t:+.1f} ± {1e3 * s:.1f} ms" for r, t, s in zip(
            info["radars"], info["time_offset_s"], info["time_offset_std_s"], strict=True))
        print(f"  filter: time offset {td}; {info['static_frames']} static frames; gyro bias "
              f"{', '.join(f'{x:+.5f}' for x in info['gyro_bias_rad_s'])} rad/s, accel bias "
              f"{', '.join(f'{x:+.4f}' for x in info['accel_bias_m_s2'])} m/s²")
    for path in res.files:
        print(f"  wrote {path}")
    return 0
