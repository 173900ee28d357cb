"""``coloradar animate RUN --out FILE.mp4|.gif``: a video of the run's sensors and ground truth."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..dataset import open_sequence
from ..progress import Progress
from ._common import (
    UsageError,
    add_file_output_args,
    add_quiet_arg,
    check_input,
    dpi,
    float_in,
    new_output_file,
    non_negative_float,
    positive_float,
)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "animate", help="render a run (lidar, radar points, ground truth) to .mp4, .gif or .rrd",
        description="Each picture shows every sensor's latest reading and the ground-truth "
                    "trajectory in a rig- or sensor-centric frame; pictures are taken at --fps "
                    "per second of run time, so the video plays in real time. MP4 needs ffmpeg "
                    "(pip install imageio-ffmpeg); GIF does not. An .rrd output logs the run for the Rerun "
                    "viewer instead (pip install 'coloradar[rerun]'; world frame, all frames).")
    p.add_argument("run", help="run folder or .zip")
    p.add_argument("--out", required=True, help="output .mp4, .gif or .rrd")
    p.add_argument("--start", type=non_negative_float, default=0.0,
                   help="seconds after the run's start (its first ground-truth pose)")
    p.add_argument("--duration", type=positive_float, help="seconds to render (default: to the end)")
    p.add_argument("--fps", type=float_in(0, 120, low_open=True), default=10.0,
                   help="pictures per second (at most 120; default 10)")
    p.add_argument("--coords", default="base",
                   help="frame: base (default), world, or a sensor name (e.g. cascade)")
    p.add_argument("--view", default="bev", choices=("bev", "3d"), help="bird's-eye or 3-D")
    p.add_argument("--extent", type=positive_float, default=20.0, help="half-width of the view [m]")
    p.add_argument("--dpi", type=dpi, default=100, help="resolution (default 100: 800x720 px)")
    add_file_output_args(p)
    add_quiet_arg(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    check_input(args.run)
    if Path(args.out).suffix.lower() not in (".mp4", ".gif", ".rrd"):
        raise UsageError(f"--out {args.out}: expected a .mp4, .gif or .rrd file")
    out = new_output_file(args.out, args.overwrite, inputs=(args.run, args.calib))
    seq = open_sequence(args.run, calib=args.calib)
    if out.suffix.lower() == ".rrd":
        from ..viz.rerun_log import log_run_rrd

        log_run_rrd(seq, out, start=args.start, duration=args.duration,
                    overwrite=args.overwrite, progress=Progress(0, "recording", enabled=not args.quiet))
        if not args.quiet:
            print(f"{out}: {seq.name} from {args.start:g} s (open with: rerun {out})")
        return 0
    from ..viz import animate_run  # matplotlib: after the arguments are known to be right

    animate_run(seq, out, start=args.start, duration=args.duration, fps=args.fps,
                frame=args.coords, view=args.view, extent=args.extent, dpi=args.dpi,
                overwrite=args.overwrite, progress=Progress(0, "pictures", enabled=not args.quiet))
    if not args.quiet:
        print(f"{out}: {seq.name} from {args.start:g} s")
    return 0
