"""``coloradar simulate``: write a simulated run (calib + run folder) from a built-in or file scene."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import OutputExistsError
from ..progress import StageProgress
from ._common import (
    UsageError,
    check_output_outside_dataset,
    float_in,
    non_negative_float,
    non_negative_int,
    positive_float,
)

# The simulator's own bounds (coloradar.sim.run), said by the parser before any work.
MAX_DURATION = 3600.0

__all__ = ["register", "run"]


def register(subparsers: argparse._SubParsersAction) -> None:
    from ..sim.run import SENSOR_CHOICES
    from ..sim.scenes import SCENES
    from ..sim.trajectory import MOTION_PROFILES

    p = subparsers.add_parser(
        "simulate", help="write a simulated run (all sensors, with known truth)",
        description="Simulate a ColoRadar run from a scene and write it in the dataset layout: "
                    "OUT/calib and OUT/<date>_sim_<scene>_run<seed> (raw ADC of both radars, "
                    "single-chip point clouds, heatmaps when coloradar.dsp is available, lidar, "
                    "IMU, ground truth, optionally Vicon) plus OUT/<run>/truth/ for evaluation.")
    p.add_argument("out", nargs="?", type=Path, help="output folder (created if needed)")
    p.add_argument("--scene", default="corridor",
                   help=f"built-in scene ({', '.join(SCENES)}) or a scene .json file "
                        "(default: corridor)")
    p.add_argument("--duration", type=float_in(0, MAX_DURATION, low_open=True), default=10.0,
                   help=f"seconds (at most {MAX_DURATION:g}; default 10)")
    p.add_argument("--laps", type=positive_float, metavar="N",
                   help="instead of --duration: as long as N laps of the scene's closed path "
                        "take (after --rest), so that the rig comes back (loop closures)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="random seed (default 0); also the run "
                   "number in the run's name")
    p.add_argument("--motion", choices=list(MOTION_PROFILES), default="smooth",
                   help="rig motion profile (default smooth)")
    p.add_argument("--speed", type=float_in(0, 30), default=None, metavar="M_PER_S",
                   help="nominal rig speed in m/s (default: the scene's); above 1.76 m/s the "
                        "cascade's Doppler folds")
    p.add_argument("--rest", type=float_in(0, MAX_DURATION, high_open=True), default=0.0, metavar="S",
                   help="the rig stands still for the first S seconds, then eases into its "
                        "motion (default 0: it moves from the start)")
    p.add_argument("--imu-noise", type=non_negative_float, default=1.0, metavar="SCALE",
                   help="scale of the IMU's errors (white noise, turn-on bias, bias random "
                        "walk; 1 = the 3DM-GX5-25 datasheet, the default; 0 = an ideal IMU)")
    p.add_argument("--radar-time-offset", type=float_in(-0.5, 0.5), default=0.0, metavar="S",
                   help="radar clock lag t_d [s]: radar frames are stamped t - t_d "
                        "(default 0); recorded in the truth")
    p.add_argument("--sensors", default=",".join(SENSOR_CHOICES),
                   help=f"comma-separated subset of {','.join(SENSOR_CHOICES)} (default: all)")
    p.add_argument("--vicon", action="store_true", help="also write vicon/ poses (100 Hz)")
    p.add_argument("--no-heatmaps", action="store_true",
                   help="do not compute heatmaps even when coloradar.dsp is available")
    p.add_argument("--name", help="run folder name (default <date>_sim_<scene>_run<seed>)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing simulated run of the same name")
    p.add_argument("--write-scene", type=Path, metavar="FILE",
                   help="write the scene's JSON description to FILE (a start for your own "
                        "scene); simulates only if OUT is given too")
    p.add_argument("--layout", choices=("coloradar", "coloradar_plus"), default="coloradar",
                   help="dataset layout to write (default coloradar; coloradar_plus: runs in "
                        "OUT/kitti/, frames from 1, cascade/lidar/IMU/ground truth only; "
                        "see docs/layout.md)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..formats import atomic_write_text
    from ..sim.imu import GX5_25
    from ..sim.run import SENSOR_CHOICES, resolve_scene, simulate_run

    if args.write_scene is not None:
        check_output_outside_dataset(args.write_scene)
        if args.write_scene.exists() and not args.overwrite:
            raise OutputExistsError(f"{args.write_scene}: exists; pass --overwrite to replace it")
        atomic_write_text(args.write_scene, resolve_scene(args.scene).to_json())
        print(f"scene {args.scene!r} written to {args.write_scene}")
        if args.out is None:
            return 0
    if args.out is None:
        raise UsageError("give an output folder OUT (or --write-scene FILE)")
    check_output_outside_dataset(args.out)  # a new run beside others, never inside one
    sensors: list[str] | None = [s.strip() for s in args.sensors.split(",") if s.strip()]
    if args.sensors == ",".join(SENSOR_CHOICES):
        sensors = None                  # the default: every sensor of the layout
    if args.laps is not None:
        from ..sim.point_runs import laps_duration

        args.duration = laps_duration(args.scene, args.laps, speed=args.speed, rest=args.rest)
        if args.duration > MAX_DURATION:
            raise UsageError(f"--laps {args.laps:g}: {args.laps:g} laps of {args.scene!r} take "
                             f"{args.duration:.0f} s; at most {MAX_DURATION:g} s are simulated")
    if args.rest >= args.duration:
        raise UsageError(f"--rest {args.rest:g}: the rig would rest for the whole run "
                         f"(--duration {args.duration:g}); give a shorter --rest")
    prog = StageProgress("simulate", enabled=not args.quiet)
    try:
        res = simulate_run(args.out, scene=args.scene, duration=args.duration, seed=args.seed,
                           motion=args.motion, speed=args.speed, sensors=sensors, vicon=args.vicon,
                           heatmaps=False if args.no_heatmaps else None, name=args.name,
                           overwrite=args.overwrite, progress=prog, layout=args.layout,
                           imu=GX5_25.scaled(args.imu_noise), rest=args.rest,
                           radar_time_offset=args.radar_time_offset)
    finally:
        prog.close()
    print(f"simulated {args.duration:g} s of scene {res.scene!r} in {res.seconds:.1f} s")
    print(f"  run:   {res.run_path}")
    print(f"  calib: {res.calib_path}")
    print(f"  truth: {res.run_path / 'truth'}")
    for key, n in res.counts.items():
        print(f"  {key:<24} {n:>6}")
    if args.no_heatmaps:
        print("  (no heatmaps: --no-heatmaps)")
    return 0
