"""``coloradar import-capture CAPTURE OUT_RUN --config CONFIG``: a raw TI radar capture
(DCA1000 file, raw packet dump or MMWCAS folder) as a ColoRadar run (docs/capture.md)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..capture import import_capture
from ..capture.importer import MARKER
from ._common import check_output_outside_dataset, non_negative_float


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "import-capture", help="turn a raw TI radar capture (DCA1000, MMWCAS) into a run",
        description="Read a DCA1000 capture (mmWave Studio's adc_data.bin or a raw packet dump "
                    "adc_data_Raw_0.bin) or an MMWCAS capture folder (master/slave1/slave2/"
                    "slave3_<n>_data.bin and _idx.bin) with its configuration (SDK .cfg, mmWave "
                    "Studio *.mmwave.json / *.setup.json, MMWCAS JSON) and write the run OUT_RUN: "
                    "<radar>/adc_samples and OUT_RUN/calib, which every coloradar command reads "
                    "(see docs/capture.md). The capture is only read.")
    p.add_argument("capture", metavar="CAPTURE", help="the capture file or MMWCAS folder")
    p.add_argument("out", metavar="OUT_RUN", help="the run folder to create")
    p.add_argument("--config", required=True, metavar="CONFIG",
                   help="the capture's configuration: .cfg, *.mmwave.json, *.setup.json or the "
                        "MMWCAS JSON")
    p.add_argument("--board", help="AWR1843BOOST, IWR6843ISK, MMWCAS-RF-EVM, or an "
                                   "antenna_cfg.txt of your board (default: from the config)")
    p.add_argument("--start-time", type=non_negative_float, metavar="T",
                   help="Unix time of the first frame [s] (default: the TDA2's timestamps "
                        "when they are Unix times, else 0)")
    p.add_argument("--iq-order", choices=("iq", "qi"), help="override the config's I/Q order")
    p.add_argument("--lanes", type=int, choices=(2, 4), help="override the LVDS lane count")
    p.add_argument("--format", dest="capture_format", default="auto",
                   choices=("auto", "dca1000", "packets", "mmwcas"),
                   help="what CAPTURE is (default: a folder is MMWCAS, *_Raw_<n>.bin a packet "
                        "dump, any other file a DCA1000 file)")
    p.add_argument("--zero-fill", action="store_true",
                   help="write frames touched by dropped packets as zeros (default: leave "
                        "them out); either way they are reported")
    p.add_argument("--drop-partial-frame", action="store_true",
                   help="import the whole frames of a capture that ends inside a frame (default: "
                        "an error saying how many bytes are missing)")
    p.add_argument("--keep-first-frame", action="store_true",
                   help="MMWCAS: keep every frame (default: the first frame of each segment is "
                        "left out, as TI's cascade scripts do)")
    p.add_argument("--first-frame-skip", choices=("segment", "recording"), default="segment",
                   help="MMWCAS: leave out the first frame of every segment (default, TI's "
                        "scripts) or only the recording's first")
    p.add_argument("--overwrite", action="store_true",
                   help="replace OUT_RUN when an earlier import-capture wrote it")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    if (out / MARKER).is_file():
        # A run an earlier import wrote (replaced with --overwrite, else refused by the
        # importer as existing): the rule applies to where it lies.
        check_output_outside_dataset(out.parent, (args.capture, args.config))
    else:
        check_output_outside_dataset(out, (args.capture, args.config))
    res = import_capture(
        args.capture, args.out, config=args.config, board=args.board,
        start_time=args.start_time, iq_order=args.iq_order, lanes=args.lanes,
        capture_format=args.capture_format, dropped="zero" if args.zero_fill else "skip",
        partial_last_frame="drop" if args.drop_partial_frame else "error",
        keep_first_frame=args.keep_first_frame, first_frame_skip=args.first_frame_skip,
        overwrite=args.overwrite)
    print(f"{res.run_path}: {res.frames_written} {res.radar} frames from {args.capture} "
          f"({res.board}; {res.layout}) in {res.seconds:.1f} s")
    if res.left_out:
        print(f"  left out (notes say why): frames {', '.join(map(str, res.left_out))}")
    if res.zero_filled:
        print(f"  zero-filled (dropped packets): frames {', '.join(map(str, res.zero_filled))}")
    for note in res.notes:
        print(f"  note: {note}")
    return 0
