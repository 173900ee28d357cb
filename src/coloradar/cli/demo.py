"""``coloradar demo``: simulate a short run, process it, compare with the truth, draw pictures."""

from __future__ import annotations

import argparse
from pathlib import Path

from ._common import float_in, non_negative_int

__all__ = ["DEFAULT_OUT", "register", "run"]

DEFAULT_OUT = "coloradar_demo"


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo", help="run the whole chain on built-in simulated data (no download)",
        description="Simulate a few seconds of a ColoRadar run, process both radars' raw ADC "
                    "frames into heatmaps and point clouds, report how well the detections "
                    "match the simulator's truth, close a loop (radar SLAM on a simulated walk "
                    "that comes back; extra [slam]), and write pictures.")
    p.add_argument("out", nargs="?", type=Path, default=None,
                   help="output folder (default ./coloradar_demo, where a later demo replaces "
                        "the previous one's output)")
    p.add_argument("--scene", default="corridor", help="built-in scene (default corridor)")
    p.add_argument("--duration", type=float_in(0, 3600, low_open=True), default=3.0,
                   help="seconds to simulate (at most 3600; default 3)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="random seed (default 0)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the outputs of a previous demo in OUT")
    p.add_argument("--no-pictures", action="store_true", help="skip the pictures")
    p.add_argument("--no-loop", action="store_true",
                   help="skip the loop closure (radar SLAM on a simulated walk; extra [slam])")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..demo import is_demo_output, run_demo
    from ..progress import StageProgress
    from ._common import check_output_outside_dataset

    out, overwrite = args.out, args.overwrite
    if out is not None:
        check_output_outside_dataset(out)
    if out is None:
        # The default folder is the demo's own scratch space: a rerun of the README's command
        # replaces what an earlier demo wrote there (and nothing else).
        out = Path(DEFAULT_OUT)
        if is_demo_output(out):
            overwrite = True
            print(f"replacing the previous demo's output in {out}/")

    prog = StageProgress("demo", enabled=not args.quiet)
    try:
        report = run_demo(out, scene=args.scene, duration=args.duration, seed=args.seed,
                          overwrite=overwrite, pictures=not args.no_pictures,
                          progress=None if args.quiet else prog, loop=not args.no_loop)
    finally:
        prog.close()
    print(report.text())
    return 0
