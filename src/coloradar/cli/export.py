"""``coloradar export RUN OUT [--format ros1|ros2|hdf5]``: a run as a ROS 1 bag, a ROS 2 bag
folder (optional extra ``ros``) or one HDF5 file of learning samples (extra ``hdf5``); the
format follows OUT's suffix when ``--format`` is not given."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..dataset import open_sequence
from ..errors import ColoradarError
from ..interop.bag_export import GROUNDTRUTH_MSGS, RADAR_POINT_SOURCES, export_bag
from ..interop.ros_messages import DEFAULT_TOPICS, ROS_FORMATS
from ..progress import Progress
from . import _export_hdf5
from ._common import (
    UsageError,
    check_input,
    check_output_outside_dataset,
    did_you_mean,
    is_run_folder_path,
    new_output_file,
    processing_setting,
)

# What each format is, and the suffix that names it (ros2 bags are folders: no suffix).
FORMATS = {"ros1": "ROS 1 bag: one .bag file", "ros2": "ROS 2 bag: a folder (no suffix)",
           _export_hdf5.HDF5: "HDF5 learning samples: one .h5 file"}
_SUFFIX_FORMAT = {".bag": "ros1", ".h5": _export_hdf5.HDF5, ".hdf5": _export_hdf5.HDF5}


def _topic(text: str) -> tuple[str, str]:
    stream, sep, topic = text.partition("=")
    if not sep or stream not in DEFAULT_TOPICS or not topic.startswith("/"):
        raise argparse.ArgumentTypeError(
            f"expected STREAM=/topic with STREAM one of {', '.join(DEFAULT_TOPICS)}, got {text!r}")
    return stream, topic


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "export", help="write a run as a ROS 1 bag (.bag), a ROS 2 bag folder, or an HDF5 "
                       "file of learning samples (.h5)",
        description="ros1/ros2: write a run's lidar and radar point clouds (sensor_msgs/PointCloud2: x y z "
                    "intensity [doppler]), IMU (sensor_msgs/Imu), ground truth "
                    "(nav_msgs/Odometry or geometry_msgs/PoseStamped), Vicon poses and the "
                    "extrinsics (tf2_msgs/TFMessage on /tf_static) to a ROS 1 .bag file or a "
                    "ROS 2 bag folder, every message stamped with the time in the run's files "
                    "(needs the optional 'rosbags' package: pip install 'coloradar[ros]'). "
                    "hdf5: one file of learning samples, one per radar frame (heatmaps, "
                    "images, lidar targets, poses; chunked and gzip-compressed; pip install "
                    "'coloradar[hdf5]'), read back by coloradar.learning.SyncedSamples. The "
                    "format follows OUT's suffix (.bag: ros1, .h5/.hdf5: hdf5) unless --format "
                    "is given; a suffix that names another format is refused.")
    p.add_argument("run", help="run folder or .zip")
    p.add_argument("out", help="output: a .bag file (ros1), a bag folder (ros2) or a .h5 file "
                               "(hdf5)")
    p.add_argument("--format", choices=(*ROS_FORMATS, _export_hdf5.HDF5),
                   help="; ".join(f"{k}: {v}" for k, v in FORMATS.items())
                        + " (default: from OUT's suffix)")
    p.add_argument("--streams", help="comma-separated subset of "
                   f"{','.join(DEFAULT_TOPICS)} (default: all the run has)")
    p.add_argument("--topic", type=_topic, action="append", default=[], metavar="STREAM=/TOPIC",
                   help="rename a stream's topic, e.g. lidar/pointclouds=/os1/points "
                        "(repeatable; defaults: " + ", ".join(f"{k}={v}" for k, v in
                                                          DEFAULT_TOPICS.items()) + ")")
    p.add_argument("--radar-points", choices=RADAR_POINT_SOURCES, default="auto",
                   help="radar points from the run's own point clouds (shipped), computed from "
                        "ADC frames or from heatmaps; auto (default): shipped, else adc, else "
                        "heatmaps")
    p.add_argument("--set", dest="settings", type=processing_setting, action="append", default=[],
                   metavar="NAME=VALUE", help="a coloradar.dsp.ProcessingSettings field for "
                                          "points computed from ADC (repeatable)")
    p.add_argument("--groundtruth-msg", choices=GROUNDTRUTH_MSGS, default="odometry",
                   help="nav_msgs/Odometry (default) or geometry_msgs/PoseStamped")
    p.add_argument("--calib", help="calib folder or calib.zip (default: found beside the run)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing output")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    _export_hdf5.add_arguments(p)
    p.set_defaults(func=run)


def output_format(out: str, fmt: str | None) -> str:
    """The format of ``out``: ``fmt`` when given (refused when OUT's suffix names another),
    else the one its suffix names; a usage error when neither says."""
    suffix = Path(out).suffix.lower()
    named = _SUFFIX_FORMAT.get(suffix)
    if fmt is None:
        if named is None:
            raise UsageError(f"{out}: cannot tell the format from the suffix "
                             f"{suffix or '(none)'}; name a .bag (ros1) or .h5 (hdf5) file, or "
                             "pass --format (ros2 for a ROS 2 bag folder)")
        return named
    if named is not None and named != fmt:  # e.g. x.bag --format hdf5: refused, not written
        raise UsageError(f"--format {fmt} ({FORMATS[fmt]}) but OUT is {out}; name the file as "
                         "its format is (.bag: ros1, no suffix: ros2, .h5: hdf5)")
    return fmt


def _check_run(args: argparse.Namespace) -> None:
    """RUN as an input; when it is no run but OUT is one (``export RUN.bag RUN``), the error
    also asks whether the arguments are swapped, as ``process`` and ``score`` do."""
    try:
        check_input(args.run)
    except ColoradarError as exc:
        out = Path(args.out)
        if is_run_folder_path(out) or (out.is_file() and out.suffix.lower() == ".zip"):
            exc.args = (f"{exc} (are the arguments swapped? RUN comes first, then OUT)",)
        raise


def run(args: argparse.Namespace) -> int:
    _check_run(args)  # inputs first: swapped arguments are said as such
    check_output_outside_dataset(args.out, (args.run, args.calib))
    args.format = output_format(args.out, args.format)
    new_output_file(args.out, args.overwrite)
    if args.format == _export_hdf5.HDF5:
        return _export_hdf5.run(args)
    streams = [s.strip() for s in args.streams.split(",") if s.strip()] if args.streams else None
    for s in streams or ():
        if s not in DEFAULT_TOPICS:
            raise UsageError(f"--streams: unknown stream {s!r}; {did_you_mean(s, DEFAULT_TOPICS)}"
                             f"(streams: {', '.join(DEFAULT_TOPICS)})")
    seq = open_sequence(args.run, calib=args.calib)
    prog = Progress(0, f"{seq.name} -> {args.format}", unit="messages", enabled=not args.quiet)
    res = export_bag(seq, args.out, args.format, streams=streams, topics=dict(args.topic),
                     radar_points=args.radar_points, groundtruth_msg=args.groundtruth_msg,
                     processing=dict(args.settings) or None, overwrite=args.overwrite,
                     progress=prog)
    prog.close()  # only on success: a failed command shows its error, not an empty bar
    sec = max(res.seconds, 1e-9)
    print(f"{res.path}: {args.format} bag, {res.messages} messages ({res.frames} point clouds) "
          f"in {res.seconds:.1f} s ({res.messages / sec:.0f} messages/s, "
          f"{res.frames / sec:.1f} point clouds/s)")
    for topic, n in res.counts.items():
        print(f"  {topic:<24} {n:>7}")
    for radar, src in res.sources.items():
        print(f"  {radar} points: {src}")
    for key, why in res.skipped.items():
        print(f"  skipped {key}: {why}")
    if res.failures:
        # Each was a warning on stderr as it was met (naming its file); the bag is complete
        # and valid without them.
        print(f"  bad frames skipped: {len(res.failures)}")
        print(f"coloradar: error: {len(res.failures)} frame(s) of {args.run} could not be read "
              "and were left out of the bag (named above)", file=sys.stderr)
        return 1
    return 0
