"""``coloradar import BAG OUT``: a ROS 1 or ROS 2 bag as a ColoRadar run (optional extra ``ros``)."""

from __future__ import annotations

import argparse

from ..interop.bag_import import import_bag, iter_topics, parse_field_map, parse_topic_map
from ..interop.ros_messages import DEFAULT_TOPICS
from ..progress import Progress
from ._common import check_output_outside_dataset


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "import", help="turn a ROS 1 or ROS 2 bag into a ColoRadar run",
        # OUT is required except with --list, which argparse cannot say by itself.
        usage="coloradar import [options] BAG OUT\n       coloradar import BAG --list",
        description="Read point clouds (sensor_msgs/PointCloud2), IMU (sensor_msgs/Imu), poses "
                    "(nav_msgs/Odometry, geometry_msgs/PoseStamped, PoseWithCovarianceStamped "
                    "or TransformStamped) and /tf_static extrinsics from a bag and write them "
                    "as the run OUT/NAME in the dataset's layout, with OUT/calib when absent, "
                    "so that every coloradar command and open_sequence read it. Needs the "
                    "optional 'rosbags' package: pip install 'coloradar[ros]'.")
    p.add_argument("bag", metavar="BAG", help="a ROS 1 .bag file or a ROS 2 bag folder")
    p.add_argument("out", metavar="OUT", nargs="?",
                   help="dataset root to write the run into (required unless --list)")
    p.add_argument("--topic", action="append", default=[], metavar="/TOPIC=STREAM",
                   help="take TOPIC as STREAM (one of " + ", ".join(DEFAULT_TOPICS) + "); "
                        "repeatable; without any, the topics 'coloradar export' writes")
    p.add_argument("--field", action="append", default=[], metavar="COLUMN=FIELD",
                   help="the PointField name of a radar point column when it is none of the "
                        "usual ones: intensity=FIELD or range_rate=FIELD, e.g. "
                        "--field intensity=snr_db --field range_rate=v_doppler_mps (repeatable; "
                        "a column without a field is imported as zeros, with a warning)")
    p.add_argument("--flip-range-rate", action="store_true",
                   help="negate the range rates: coloradar's are > 0 when the target recedes; "
                        "use this for a recorder whose Doppler is > 0 when it approaches")
    p.add_argument("--name", help="run folder name (default: the bag's name)")
    p.add_argument("--calib", help="calib folder whose radar configurations OUT/calib gets "
                               "(default: the built-in presets); extrinsics come from /tf_static")
    p.add_argument("--base-frame", default="base", help="tf frame of the rig's base (default base)")
    p.add_argument("--time", dest="time_source", choices=("header", "bag"), default="header",
                   help="message header stamps (default) or bag record times")
    p.add_argument("--relative-poses", action="store_true",
                   help="make ground-truth poses relative to the first one, as the dataset's are")
    p.add_argument("--list", action="store_true", help="only list the bag's topics")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a run of the same name written by an earlier import")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run, import_parser=p)


def run(args: argparse.Namespace) -> int:
    if args.list:
        for topic, mtype, n in iter_topics(args.bag):
            print(f"{topic:<32} {mtype:<40} {n:>7}")
        return 0
    if args.out is None:
        args.import_parser.error("the following arguments are required: OUT (the dataset root "
                                 "to import into; or --list)")
    check_output_outside_dataset(args.out, (args.bag,))  # a new run beside others only
    topics = parse_topic_map(args.topic) if args.topic else None
    fields = parse_field_map(args.field)
    prog = Progress(0, "import", unit="messages", enabled=not args.quiet)
    res = import_bag(args.bag, args.out, name=args.name, topics=topics, calib=args.calib,
                     base_frame=args.base_frame, time_source=args.time_source,
                     relative_poses=args.relative_poses, overwrite=args.overwrite,
                     fields=fields, flip_range_rate=args.flip_range_rate, progress=prog)
    prog.close()  # only on success: a failed command shows its error, not an empty bar
    print(f"{res.run_path}: run imported from {args.bag} in {res.seconds:.1f} s")
    for stream, n in res.counts.items():
        print(f"  {stream:<24} {n:>7}  from {res.topics[stream]}")
    print(f"  calib: {res.calib_path} ({'written' if res.calib_written else 'kept'}; extrinsics "
          f"from /tf_static: {', '.join(res.extrinsics) or 'none'})")
    if res.preset_extrinsics:
        print(f"  preset extrinsics (not from this bag) written for: "
              f"{', '.join(res.preset_extrinsics)}")
    if res.extrinsics_not_applied:
        print(f"  NOT applied (the kept calib differs): bag extrinsics of "
              f"{', '.join(res.extrinsics_not_applied)}")
    for a, b in res.disjoint:
        print(f"  NOT overlapping in time: {a} and {b}")
    for topic, mtype in res.ignored.items():
        print(f"  ignored {topic} ({mtype})")
    return 0
