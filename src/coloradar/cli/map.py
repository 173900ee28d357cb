"""``coloradar map RUN --out DIR``: a run's occupancy map (3-D voxels, a ROS 2-D grid, a picture)
along any trajectory; ``--out map.pcd|.ply``: its point clouds accumulated in the world frame."""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

from ..dataset import open_sequence
from ..errors import FormatError, MissingDataError
from ..geometry import MAP_SOURCES, build_map, write_point_file
from ..progress import Progress
from ._common import (
    UsageError,
    add_file_output_args,
    add_quiet_arg,
    check_input,
    check_output_outside_dataset,
    finite_float,
    new_output_file,
    non_negative_float,
    pick_radar,
    positive_float,
    positive_int,
)

POSES_HELP = ("groundtruth (default: the run's), a TUM file (timestamp x y z qx qy qz qw of "
              "world_T_base), or the output folder of 'coloradar slam' or 'coloradar odometry' "
              "(its trajectory.txt)")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "map", help="a run's occupancy map (--out DIR) or accumulated point map (--out FILE.ply)",
        description="--out DIR: a probabilistic occupancy map (sparse log-odds voxels: a "
                    "return's occupancy spread by its range and angle uncertainty, free space "
                    "along its ray; or a heatmap's cells against its noise floor) of a radar's "
                    "or the lidar's frames placed by the poses; DIR gets map.ply (occupied "
                    "voxels with their probability), occupancy.npz, grid.pgm + grid.yaml (ROS "
                    "map_server 2-D grid of a height band), map.png, poses.txt and map.json. "
                    "--out FILE.pcd|.ply: every point cloud moved into the world frame, "
                    "optionally voxel down-sampled (no free space, no probabilities).")
    p.add_argument("run", help="run folder or .zip")
    p.add_argument("--out", required=True,
                   help="output folder (occupancy map), or a .pcd / .ply file (point map)")
    p.add_argument("--poses", metavar="SPEC", help=POSES_HELP)
    p.add_argument("--source", choices=("points", "heatmaps"),
                   help="what the occupancy map is made of (default points): point clouds (the "
                        "sensor's own, --products', or computed from ADC frames) or a radar's "
                        "3-D heatmaps")
    p.add_argument("--sensor", choices=sorted(MAP_SOURCES),
                   help="whose frames (default: lidar for a point map; for an occupancy map the "
                        "single chip, or the run's only radar)")
    p.add_argument("--products",
                   help="output folder of 'coloradar process' for this run: radar point "
                        "clouds and heatmaps are read from it (default: the run's own, or "
                        "points computed from its ADC frames when it has none, as the cascade)")
    p.add_argument("--start", type=non_negative_float, default=0.0,
                   help="window start, seconds after the first pose (default 0)")
    p.add_argument("--duration", type=positive_float, help="window length in seconds (default: to the end)")
    p.add_argument("--voxel", type=positive_float,
                   help="voxel size in metres (occupancy map: default 0.15; point map: "
                        "down-sampling, default none)")
    p.add_argument("--stride", type=positive_int, default=1, help="use every N-th frame (default 1)")
    p.add_argument("--min-range", type=non_negative_float, default=0.0,
                   help="point map: drop points closer to the sensor than this [m] (the rig itself)")
    p.add_argument("--max-range", type=positive_float, help="drop returns farther than this [m]")
    p.add_argument("--band", type=finite_float, nargs=2, metavar=("ZMIN", "ZMAX"),
                   help="occupancy map: height band of the 2-D grid, world z [m] (default: the "
                        "trajectory's median height ± 0.5 m)")
    p.add_argument("--rerun", action="store_true",
                   help="occupancy map: also write map.rrd (needs the extra [rerun])")
    p.add_argument("--keep-movers", action="store_true",
                   help="occupancy map: map every radar point or heatmap return (default: "
                        "leave out those whose range rates a static world does not explain, "
                        "movers and ghosts; the sensor's velocity from the poses); the lidar "
                        "is never tested")
    p.add_argument("--angle-std", type=positive_float, nargs=2, metavar=("AZ", "EL"),
                   help="occupancy map of a radar: its direction error (1 sigma) in azimuth and "
                        "elevation [deg], where a calibration or the recorder says it; the floors "
                        "of each return's angle spread (default: the radar's own, 1 2 for the "
                        "single chip, 0.53 2 for the cascade); a radar whose directions are "
                        "noisier than its floors maps sharper with its own figures (docs/mapping.md)")
    p.add_argument("--ascii", action="store_true", help="point map: write ascii instead of binary")
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


def _check_poses_input(spec: str | None) -> None:
    """A --poses file or folder that does not exist is an input error, said before outputs."""
    if spec is None or spec == "groundtruth":
        return
    p = Path(spec)
    if not p.exists():
        raise MissingDataError(f"{spec}: no such file or folder; --poses takes {POSES_HELP}")
    if p.is_dir() and not (p / "trajectory.txt").is_file():
        raise MissingDataError(f"{spec}: expected the output folder of 'coloradar slam' or "
                               "'coloradar odometry' (with trajectory.txt), or a TUM file")


def load_poses(seq, spec: str | None, quiet: bool = False):
    """``(trajectory, what)``: the ``world_T_base`` poses --poses names, and how to say them."""
    from ..geometry import trajectory_from_groundtruth

    if spec is None or spec == "groundtruth":
        if "groundtruth" not in seq.available():
            raise MissingDataError(
                f"{seq.location}: the run has no ground truth; a map needs poses: pass --poses "
                "FILE.txt (a TUM trajectory of world_T_base) or --poses DIR (the output folder "
                "of 'coloradar slam' or 'coloradar odometry' on this run)")
        return trajectory_from_groundtruth(seq), "groundtruth"
    from ..odometry.tum import read_tum

    p = Path(spec)
    if p.is_dir():
        for name in ("slam.json", "odometry.json"):
            if (p / name).is_file():
                try:
                    made_for = json.loads((p / name).read_text()).get("run_name")
                except (OSError, ValueError, AttributeError):
                    made_for = None
                if made_for and made_for != seq.name and not quiet:
                    print(f"warning: {p} was made from run {made_for}, not {seq.name}",
                          file=sys.stderr)
                break
        p = p / "trajectory.txt"
    return read_tum(p), str(p)


def _point_map(args: argparse.Namespace) -> int:
    _check_poses_input(args.poses)
    out = new_output_file(args.out, args.overwrite, inputs=(args.run, args.calib))
    seq = open_sequence(args.run, calib=args.calib, products=args.products)
    args.sensor = args.sensor or "lidar"
    traj, _ = load_poses(seq, args.poses, args.quiet)
    m = build_map(seq, args.sensor, start=args.start, duration=args.duration,
                  voxel_size=args.voxel, stride=args.stride, max_range=args.max_range,
                  min_range=args.min_range, trajectory=traj,
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


def _occupancy_map(args: argparse.Namespace) -> int:
    from ..mapping import (
        OccupancyJob,
        OccupancySettings,
        StaticGate,
        build_occupancy_map,
        occupancy_grid,
    )
    from ..mapping.output import default_band, map_targets, write_map_folder

    _check_poses_input(args.poses)
    if args.angle_std and args.sensor == "lidar":
        raise UsageError("--angle-std is a radar's direction error; the lidar's is fixed "
                         "(0.2 degrees)")
    if args.band and not args.band[0] < args.band[1]:
        raise UsageError(f"--band {args.band[0]:g} {args.band[1]:g}: expected ZMIN < ZMAX")
    if args.rerun:
        from ..viz.rerun_log import require_rerun

        require_rerun()                        # the missing extra is said before the work
    check_output_outside_dataset(args.out, (args.run, args.calib, args.products))
    extra = ("map.png",) + (("map.rrd",) if args.rerun else ())
    targets = map_targets(args.out, args.overwrite, extra)
    seq = open_sequence(args.run, calib=args.calib, products=args.products)
    args.sensor = args.sensor or pick_radar(seq, None, "single_chip", args.quiet)
    traj, poses_from = load_poses(seq, args.poses, args.quiet)
    az_std, el_std = args.angle_std or (None, None)
    job = OccupancyJob(sensor=args.sensor, source=args.source or "points", start=args.start,
                       duration=args.duration, stride=args.stride, max_range=args.max_range,
                       static_gate=None if args.keep_movers else StaticGate(),
                       min_azimuth_std_deg=az_std, min_elevation_std_deg=el_std)
    settings = OccupancySettings(voxel=args.voxel or OccupancySettings().voxel)
    t0 = time.perf_counter()
    res = build_occupancy_map(seq, traj, job, settings, progress=Progress(
        0, f"{args.sensor} {job.source}", enabled=not args.quiet))
    seconds = time.perf_counter() - t0
    poses = traj.interpolate(res.timestamps)
    band = tuple(args.band) if args.band else default_band(poses)
    grid = occupancy_grid(res.map, *band)
    info = {"run": str(args.run), "run_name": seq.name, "sensor": args.sensor,
            "source": job.source, "read_from": res.points_from, "poses": poses_from,
            "frames_mapped": int(res.frame_indices.size), "seconds": round(seconds, 3),
            "settings": asdict(settings),
            "job": {**{k: getattr(job, k) for k in ("start", "duration", "stride", "max_range",
                                                    "min_azimuth_std_deg",
                                                    "min_elevation_std_deg")},
                    "static_gate": None if job.static_gate is None or job.sensor == "lidar"
                    else asdict(job.static_gate)},
            "static_test": res.static_test}
    if res.static_test is not None and res.static_test["warning"]:
        print(f"warning: {res.static_test['warning']}", file=sys.stderr)
    written = write_map_folder(targets, res.map, grid, poses, info)
    written += _extras(args, targets, res, grid, poses)
    if not args.quiet:
        c = grid.counts()
        span = float(res.timestamps[-1] - res.timestamps[0]) if res.timestamps.size > 1 else 0
        print(f"{seq.name}: {res.frame_indices.size} {args.sensor} {res.points_from} frames "
              f"placed by {poses_from}; {len(res.map):,} voxels of {settings.voxel:g} m, "
              f"{int(res.map.occupied().shape[0]):,} occupied; {seconds:.1f} s "
              f"({res.frame_indices.size / max(seconds, 1e-9):.0f} frames/s, "
              f"{span / max(seconds, 1e-9):.1f} s of run per s)")
        print(f"  2-D grid z in [{band[0]:.2f}, {band[1]:.2f}) m: {c['occupied']:,} occupied, "
              f"{c['free']:,} free, {c['unknown']:,} unknown cells")
        for path in written:
            print(f"  wrote {path}")
    return 0


def _extras(args, targets, res, grid, poses) -> list[Path]:
    """map.png (skipped, and said, without matplotlib) and map.rrd (with --rerun)."""
    out: list[Path] = []
    try:
        from ..viz._figure import save_figure
        from ..viz.occupancy import occupancy_figure
    except ImportError:
        if not args.quiet:
            print("note: map.png needs matplotlib (pip install 'coloradar[viz]'); not drawn",
                  file=sys.stderr)
    else:
        fig = occupancy_figure(grid, poses.translations, title=f"{res.job.sensor} "
                               f"{res.job.source}: occupancy, z in [{grid.band[0]:.2f}, "
                               f"{grid.band[1]:.2f}) m")
        out.append(save_figure(fig, targets["map.png"], overwrite=True))
    if args.rerun:
        from ..viz.rerun_log import log_map_rrd

        out.append(log_map_rrd(targets["map.rrd"], res.map.occupied(), res.map.voxel, poses,
                               overwrite=True))
    return out


def run(args: argparse.Namespace) -> int:
    check_input(args.run)
    suffix = Path(args.out).suffix.lower()
    if args.source is not None and suffix in (".pcd", ".ply"):
        raise FormatError(f"{args.out}: --source makes an occupancy map, written to a folder: "
                          "give --out a folder name (no .pcd / .ply suffix)")
    if suffix in (".pcd", ".ply"):
        if args.angle_std:
            raise UsageError(f"{args.out}: --angle-std shapes an occupancy map's evidence; a "
                             "point map has none: give --out a folder name")
        return _point_map(args)
    if args.source is None and suffix:
        raise FormatError(f"{args.out}: expected a .pcd or .ply file name (a point map) or a "
                          "folder name without a suffix (an occupancy map)")
    return _occupancy_map(args)
