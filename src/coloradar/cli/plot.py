"""``coloradar plot RUN --frame I --view VIEW --out FILE.png``: one picture of one frame."""

from __future__ import annotations

import argparse

from ..calib import RADARS
from ..dataset import open_sequence
from ._common import (
    add_file_output_args,
    add_quiet_arg,
    check_input,
    check_output_outside_dataset,
    dpi,
    positive_float,
)


def _frame_index(seq, args: argparse.Namespace) -> int:
    """``--frame`` as a position from the start: -1 is the last frame of the stream it
    counts in, and the picture and the message say its real number (out of range: left as
    given, for the view's own error)."""
    if args.frame >= 0:
        return args.frame
    from ..viz.scene import REFERENCE_STREAMS, radar_source

    present = seq.available()
    if args.view == "scene":
        name = args.stream or (radar_source(seq, args.radar) if args.radar else
                               next((s for s in REFERENCE_STREAMS if s in present), None))
    else:
        radar = args.radar or "cascade"
        has_adc = f"{radar}/adc" in present
        use_hm = f"{radar}/heatmaps" in present and (
            args.view == "heatmap" or (args.view == "range-azimuth" and not has_adc))
        name = f"{radar}/heatmaps" if use_hm else f"{radar}/adc" if has_adc else None
    if name is None or name not in present:
        return args.frame
    n = len(seq.stream(name).timestamps)
    return args.frame + n if -n <= args.frame else args.frame


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plot", help="draw one frame of a run: range-Doppler, range-azimuth, heatmap or scene",
        description="range-doppler and range-azimuth are computed from the radar's raw ADC "
                    "frame; heatmap slices the run's heatmap (azimuth-range at the elevation of "
                    "the strongest cell, or elevation-azimuth with --slice); scene draws the "
                    "lidar, both radars' points (coloured by range rate) and the ground truth "
                    "in one frame. Written without a display.")
    p.add_argument("run", help="run folder or .zip")
    p.add_argument("--view", required=True,
                   choices=("range-doppler", "range-azimuth", "heatmap", "scene"))
    p.add_argument("--frame", type=int, default=0,
                   help="frame index (of the radar's stream; for scene, of --stream; "
                        "default: %(default)s, the first)")
    p.add_argument("--out", required=True, help="output image (.png, .pdf, .svg)")
    p.add_argument("--radar", choices=RADARS,
                   help="which radar (default: cascade; for scene, both radars; a radar named "
                        "for scene shows it alone, --frame counting its frames)")
    p.add_argument("--coords", default="base",
                   help="scene frame: base (default), world, or a sensor name (e.g. cascade)")
    p.add_argument("--scene-view", default="bev", choices=("bev", "3d"),
                   help="scene: bird's-eye (default) or 3-D")
    p.add_argument("--stream", help="scene: the stream --frame counts in (e.g. lidar/pointclouds)")
    p.add_argument("--extent", type=positive_float, default=20.0, help="scene half-width [m]")
    p.add_argument("--polar", action="store_true",
                   help="range-azimuth on azimuth/range axes instead of a bird's-eye view")
    p.add_argument("--slice", default="azimuth-range",
                   choices=("azimuth-range", "elevation-azimuth"), help="heatmap slice")
    p.add_argument("--max-range", type=positive_float, help="clip the range axis [m]")
    p.add_argument("--dpi", type=dpi, default=100, help="image resolution (at most 1200; default 100)")
    add_file_output_args(p)
    add_quiet_arg(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..viz import frame_figure, save_figure
    from ..viz._figure import check_image_path

    check_input(args.run)
    check_output_outside_dataset(args.out, (args.run, args.calib))
    out = check_image_path(args.out, args.overwrite)
    seq = open_sequence(args.run, calib=args.calib)
    args.frame = _frame_index(seq, args)
    fig = frame_figure(seq, args.view, args.frame, radar=args.radar, coords=args.coords,
                       scene_view=args.scene_view, stream=args.stream, extent=args.extent,
                       heatmap_slice=args.slice, polar=args.polar, max_range=args.max_range)
    fig.set_dpi(args.dpi)
    save_figure(fig, out, overwrite=args.overwrite)
    w, h = fig.canvas.get_width_height()
    if not args.quiet:
        print(f"{out}: {args.view} of {seq.name} frame {args.frame} ({w}x{h} px)")
    return 0
