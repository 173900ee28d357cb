"""ROS 1 and ROS 2 bags from ColoRadar runs, and runs from bags (``rosbags``, optional extra ``ros``).

Export writes, in time order, one message per stored sample, stamped with the time in the
run's files (header stamp and bag time alike):

=========================  =========================  ===============================================
stream                     default topic              message
=========================  =========================  ===============================================
lidar/pointclouds          ``/lidar/points``          ``sensor_msgs/PointCloud2`` x y z intensity
cascade/pointclouds        ``/cascade/points``        ``sensor_msgs/PointCloud2`` x y z intensity doppler
single_chip/pointclouds    ``/single_chip/points``    same
imu                        ``/imu/data``              ``sensor_msgs/Imu`` (no orientation: covariance[0] = -1)
groundtruth                ``/groundtruth/odom``      ``nav_msgs/Odometry`` world -> base (or PoseStamped)
vicon                      ``/vicon/pose``            ``geometry_msgs/PoseStamped`` in ``world``
extrinsics                 ``/tf_static``             ``tf2_msgs/TFMessage``: base -> every sensor
=========================  =========================  ===============================================

Frame ids are the sensor names (``cascade``, ``single_chip``, ``lidar``, ``imu``, ``vicon``),
``base`` (the rig) and ``world`` (the ground truth's frame). The ``doppler`` field is the
dataset's range rate [m/s] (> 0 receding). A radar's points are the run's own (shipped) point
clouds, or computed from its ADC frames or heatmaps by ``coloradar.dsp`` when it has none.

Times: a file time ``t`` [s, float64] becomes ``sec = floor(t)``, ``nanosec = round((t - sec)
· 1e9)``; reading back, ``sec + nanosec / 1e9`` is the float64 nearest to the original, because a
float64 near 1.6e9 s is spaced 2.4e-7 s apart, far coarser than 1 ns. So export followed by import
gives the very same float64 timestamps.

Import maps topics to streams (``--topic /my/points=single_chip/pointclouds``), reads each
message's header stamp (or the bag time), writes the run with the dataset's writers into
``OUT/<name>`` (assembled in a hidden partial folder, renamed at the end) and writes ``OUT/calib``
when absent: the radar configurations of ``calib`` (built-in presets by default) with the
extrinsics found on ``/tf_static`` (resolved through the tf tree to ``base``).
"""

from __future__ import annotations

import functools
import os
import shutil
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from ..calib import Calibration, Extrinsic, load_calibration, write_calibration
from ..dataset import Sequence
from ..errors import (
    CalibrationWarning,
    ColoradarError,
    DataWarning,
    FormatError,
    MissingDataError,
    MissingDependencyError,
    OutputExistsError,
    ReadError,
    SettingsError,
)
from ..formats import (
    write_imu,
    write_lidar_pointcloud,
    write_poses,
    write_radar_pointcloud,
    write_timestamps,
)
from ..formats.layout import COLORADAR
from ..geometry import SE3
from .pointcloud2 import CloudLayout, decode_cloud, encode_cloud

__all__ = [
    "DEFAULT_TOPICS",
    "EXPORT_STREAMS",
    "ROS_FORMATS",
    "ExportResult",
    "ImportResult",
    "export_bag",
    "import_bag",
    "iter_topics",
    "ns_to_times",
    "parse_field_map",
    "parse_topic_map",
    "times_to_ns",
]

ROS_FORMATS = ("ros1", "ros2")

DEFAULT_TOPICS: dict[str, str] = {
    "lidar/pointclouds": "/lidar/points",
    "cascade/pointclouds": "/cascade/points",
    "single_chip/pointclouds": "/single_chip/points",
    "imu": "/imu/data",
    "groundtruth": "/groundtruth/odom",
    "vicon": "/vicon/pose",
    "tf_static": "/tf_static",
}
"""Stream -> topic used by export, and (reversed) by import when no topic map is given."""

EXPORT_STREAMS = tuple(k for k in DEFAULT_TOPICS if k != "tf_static")
"""Streams export and import know (besides ``tf_static``)."""

RADAR_POINT_SOURCES = ("auto", "shipped", "adc", "heatmaps")
GROUNDTRUTH_MSGS = ("odometry", "pose")

RADAR_FIELDS = ("x", "y", "z", "intensity", "doppler")
LIDAR_FIELDS = ("x", "y", "z", "intensity")
# Names other recorders use for the same quantities (import only).
FIELD_ALIASES: dict[str, tuple[str, ...]] = {
    "doppler": ("range_rate", "velocity", "v_doppler", "radial_velocity"),
    "intensity": ("power", "snr", "rcs", "i"),
}

WORLD_FRAME = "world"
BASE_FRAME = "base"

_TYPES = {
    "cloud": "sensor_msgs/msg/PointCloud2",
    "imu": "sensor_msgs/msg/Imu",
    "odometry": "nav_msgs/msg/Odometry",
    "pose": "geometry_msgs/msg/PoseStamped",
    "pose_cov": "geometry_msgs/msg/PoseWithCovarianceStamped",
    "transform": "geometry_msgs/msg/TransformStamped",
    "tf": "tf2_msgs/msg/TFMessage",
}


def _rosbags():
    try:
        import rosbags  # noqa: F401
    except ImportError:  # pragma: no cover - depends on the environment
        raise MissingDependencyError("ROS bags need the optional 'rosbags' package: "
                             "pip install 'coloradar[ros]'") from None


# -- time ---------------------------------------------------------------------------------------
def times_to_ns(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """float64 Unix times [s] -> ``(sec, nanosec)`` int64 arrays (ROS ``Time``), exactly invertible.

    Parameters
    ----------
    t
        float64 ``(N,)`` [s], non-negative.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        int64 ``(N,)`` seconds and nanoseconds in ``[0, 1e9)``.
    """
    t = np.asarray(t, dtype=np.float64).reshape(-1)
    if np.any(~np.isfinite(t)) or np.any(t < 0):
        raise FormatError("ROS times must be finite, non-negative Unix seconds")
    sec = np.floor(t)
    # t - floor(t) is exact (Sterbenz), so only the scaling rounds, far below 1 ns.
    nsec = np.rint((t - sec) * 1e9).astype(np.int64)
    sec = sec.astype(np.int64)
    carry = nsec >= 1_000_000_000
    sec[carry] += 1
    nsec[carry] -= 1_000_000_000
    return sec, nsec


def ns_to_times(sec: np.ndarray, nsec: np.ndarray) -> np.ndarray:
    """``(sec, nanosec)`` -> float64 Unix times [s] (the inverse of :func:`times_to_ns`)."""
    return np.asarray(sec, dtype=np.float64) + np.asarray(nsec, dtype=np.float64) / 1e9


# -- export -------------------------------------------------------------------------------------
@dataclass
class ExportResult:
    """What :func:`export_bag` wrote.

    Attributes
    ----------
    path
        The bag (a ``.bag`` file for ROS 1, a folder for ROS 2).
    format
        ``"ros1"`` or ``"ros2"``.
    counts
        Messages per topic.
    sources
        Where each radar's points came from (``shipped``, ``adc``, ``heatmaps``).
    frames
        Point-cloud messages written (lidar and radar scans).
    seconds
        Wall time of the export.
    skipped
        Streams asked for (or known) that the run lacks, with the reason.
    failures
        Frames that could not be read or converted (a truncated file, say), one line each
        naming the file: they were left out of the bag (each also a :class:`DataWarning`), and
        the bag holds every other message.
    """

    path: Path
    format: str
    counts: dict[str, int] = field(default_factory=dict)
    sources: dict[str, str] = field(default_factory=dict)
    frames: int = 0
    seconds: float = 0.0
    skipped: dict[str, str] = field(default_factory=dict)
    failures: list[str] = field(default_factory=list)

    @property
    def messages(self) -> int:
        """All messages written."""
        return sum(self.counts.values())


class _Builder:
    """Message construction for one typestore (ROS 1 Noetic or ROS 2 Humble definitions)."""

    def __init__(self, fmt: str):
        from rosbags.typesys import Stores, get_typestore

        self.ros1 = fmt == "ros1"
        self.store = get_typestore(Stores.ROS1_NOETIC if self.ros1 else Stores.ROS2_HUMBLE)
        if "tf2_msgs/msg/TFMessage" not in self.store.types:
            # rosbags' Noetic store lacks tf2_msgs; its definition is one line (tf2_msgs/TFMessage).
            from rosbags.typesys import get_types_from_msg

            self.store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                                   "tf2_msgs/msg/TFMessage"))
        T = self.store.types
        self.Time = T["builtin_interfaces/msg/Time"]
        self.Header = T["std_msgs/msg/Header"]
        self.PointField = T["sensor_msgs/msg/PointField"]
        self.PointCloud2 = T["sensor_msgs/msg/PointCloud2"]
        self.Imu = T["sensor_msgs/msg/Imu"]
        self.Vector3 = T["geometry_msgs/msg/Vector3"]
        self.Quaternion = T["geometry_msgs/msg/Quaternion"]
        self.Point = T["geometry_msgs/msg/Point"]
        self.Pose = T["geometry_msgs/msg/Pose"]
        self.PoseStamped = T["geometry_msgs/msg/PoseStamped"]
        self.PoseWithCovariance = T["geometry_msgs/msg/PoseWithCovariance"]
        self.Twist = T["geometry_msgs/msg/Twist"]
        self.TwistWithCovariance = T["geometry_msgs/msg/TwistWithCovariance"]
        self.Odometry = T["nav_msgs/msg/Odometry"]
        self.Transform = T["geometry_msgs/msg/Transform"]
        self.TransformStamped = T["geometry_msgs/msg/TransformStamped"]
        self.TFMessage = T["tf2_msgs/msg/TFMessage"]
        self.serialize = self.store.serialize_ros1 if self.ros1 else self.store.serialize_cdr

    def header(self, sec: int, nsec: int, frame: str, seq: int = 0):
        stamp = self.Time(sec=int(sec), nanosec=int(nsec))
        if self.ros1:
            return self.Header(seq=seq, stamp=stamp, frame_id=frame)
        return self.Header(stamp=stamp, frame_id=frame)

    def cloud(self, header, points: np.ndarray, names: tuple[str, ...]):
        layout, data = encode_cloud(points, names)
        fields = [self.PointField(name=n, offset=o, datatype=d, count=c)
                  for n, o, d, c in zip(layout.names, layout.offsets, layout.datatypes,
                                        layout.counts, strict=True)]
        return self.PointCloud2(header=header, height=layout.height, width=layout.width,
                                fields=fields, is_bigendian=False, point_step=layout.point_step,
                                row_step=layout.row_step, data=data,
                                is_dense=bool(np.all(np.isfinite(points))))

    def quat(self, q: np.ndarray):
        return self.Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))

    def vec(self, v: np.ndarray):
        return self.Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))

    def pose(self, row: np.ndarray):
        return self.Pose(position=self.Point(x=float(row[0]), y=float(row[1]), z=float(row[2])),
                         orientation=self.quat(row[3:7]))

    def imu(self, header, row: np.ndarray):
        no_orientation = np.zeros(9)
        no_orientation[0] = -1.0  # sensor_msgs/Imu: "-1 in element 0: no orientation estimate"
        return self.Imu(header=header, orientation=self.quat(np.array([0.0, 0.0, 0.0, 1.0])),
                        orientation_covariance=no_orientation,
                        angular_velocity=self.vec(row[3:6]), angular_velocity_covariance=np.zeros(9),
                        linear_acceleration=self.vec(row[0:3]),
                        linear_acceleration_covariance=np.zeros(9))

    def odometry(self, header, row: np.ndarray, child: str):
        zero = self.Twist(linear=self.vec(np.zeros(3)), angular=self.vec(np.zeros(3)))
        return self.Odometry(header=header, child_frame_id=child,
                             pose=self.PoseWithCovariance(pose=self.pose(row), covariance=np.zeros(36)),
                             twist=self.TwistWithCovariance(twist=zero, covariance=np.zeros(36)))

    def pose_stamped(self, header, row: np.ndarray):
        return self.PoseStamped(header=header, pose=self.pose(row))

    def tf_static(self, sec: int, nsec: int, transforms: Mapping[str, Extrinsic]):
        items = [self.TransformStamped(header=self.header(sec, nsec, BASE_FRAME),
                                       child_frame_id=name,
                                       transform=self.Transform(translation=self.vec(e.translation),
                                                                rotation=self.quat(e.quaternion)))
                 for name, e in sorted(transforms.items())]
        return self.TFMessage(transforms=items)


def _radar_point_stream(seq: Sequence, radar: str, source: str,
                        processing: Mapping[str, Any] | None) -> tuple[Any, Callable | None, str]:
    """``(frame stream, converter or None, source used)`` for one radar's points."""
    have = seq.available()
    order = {"auto": ("shipped", "adc", "heatmaps")}.get(source, (source,))
    for src in order:
        key = {"shipped": "pointclouds", "adc": "adc", "heatmaps": "heatmaps"}[src]
        if f"{radar}/{key}" not in have:
            continue
        rs = seq.radar(radar)
        if src == "shipped":
            return rs.pointclouds, None, src
        if src == "adc":
            from ..dsp import RadarProcessor

            proc = RadarProcessor(rs.calib, **dict(processing or {}))
            return rs.adc, proc.pointcloud, src
        from ..dsp import heatmap_pointcloud

        cfg = rs.calib.heatmap
        opts = {"min_range": 0.3, **dict(processing or {})}
        return rs.heatmaps, (lambda hm, cfg=cfg, opts=opts: heatmap_pointcloud(hm, cfg, **opts)), src
    raise MissingDataError(f"{seq.location}: no {radar} "
                           f"{'point clouds, ADC frames or heatmaps' if source == 'auto' else source}"
                           f" to export (present: {', '.join(have) or 'nothing'})")


@functools.lru_cache(maxsize=2)
def _builder(fmt: str) -> _Builder:
    # Building a typestore compiles its message classes: ~0.1-0.3 s, paid once per format.
    return _Builder(fmt)


@dataclass
class _Planned:
    """One stream to export: its times, frame id, and where its samples come from."""

    key: str
    timestamps: np.ndarray
    frame_id: str
    frames: Any = None                       # a FrameStream (point clouds or radar input)
    convert: Callable[[np.ndarray], np.ndarray] | None = None   # radar input -> (N, 5) points
    rows: np.ndarray | None = None           # IMU or pose rows
    msgtype: str = ""


class _BadFrame(Exception):
    """A frame of the run that cannot be exported; its message names the file."""


def _message(b: _Builder, p: _Planned, k: int, sec: int, nsec: int,
             transforms: Mapping[str, Extrinsic]) -> Any:
    """Sample ``k`` of ``p`` as a message stamped ``sec, nsec``.

    Raises
    ------
    _BadFrame
        Frame ``k`` cannot be read or converted (malformed, vanished, not a regular file).
    """
    header = b.header(sec, nsec, p.frame_id, k)
    if p.frames is not None:
        try:
            data = p.frames.read(k)
            if p.convert is not None:
                data = p.convert(data)
        except (FormatError, ReadError, MissingDataError) as exc:
            raise _BadFrame(f"{exc} ({p.frames.name} frame {k} skipped)") from None
        names = LIDAR_FIELDS if p.key == "lidar/pointclouds" else RADAR_FIELDS
        return b.cloud(header, np.asarray(data)[:, :len(names)], names)
    if p.key == "tf_static":
        return b.tf_static(sec, nsec, transforms)
    assert p.rows is not None
    if p.key == "imu":
        return b.imu(header, p.rows[k])
    if p.msgtype == _TYPES["odometry"]:
        return b.odometry(header, p.rows[k], BASE_FRAME)
    return b.pose_stamped(header, p.rows[k])


def _check_bag_target(out: Path, fmt: str, overwrite: bool) -> None:
    if not out.exists() and not out.is_symlink():
        return
    if not overwrite:
        raise OutputExistsError(f"{out}: exists; pass overwrite=True (--overwrite) to replace it")
    is_bag = (out.is_file() and out.suffix == ".bag") if fmt == "ros1" else \
        (out.is_dir() and (out / "metadata.yaml").is_file())
    if not is_bag:
        raise OutputExistsError(f"{out}: exists and is not a {fmt} bag; not replacing it")


def _replace(partial: Path, out: Path) -> None:
    """Move the finished bag into place; an old bag is removed only after the new one is there."""
    old = None
    if out.exists():
        old = out.with_name(f".{out.name}.old")
        if old.exists():
            shutil.rmtree(old) if old.is_dir() else old.unlink()
        os.replace(out, old)
    os.replace(partial, out)
    if old is not None:
        shutil.rmtree(old) if old.is_dir() else old.unlink()


def export_bag(seq: Sequence, out: str | os.PathLike[str], fmt: str = "ros2", *,
               streams: Iterable[str] | None = None, topics: Mapping[str, str] | None = None,
               radar_points: str = "auto", groundtruth_msg: str = "odometry",
               processing: Mapping[str, Any] | None = None, overwrite: bool = False,
               progress: Callable[[int, int], None] | None = None) -> ExportResult:
    """Write a run's point clouds, IMU, ground truth and extrinsics to a ROS 1 or ROS 2 bag.

    Parameters
    ----------
    seq
        The run (:func:`coloradar.open_sequence`).
    out
        ``run.bag`` for ROS 1; a folder (rosbag2, sqlite3 storage) for ROS 2.
    fmt
        ``"ros1"`` (Noetic message definitions) or ``"ros2"`` (Humble definitions).
    streams
        Subset of :data:`EXPORT_STREAMS` (and ``"tf_static"``); default: every one the run has.
        A stream named here that the run lacks raises :class:`MissingDataError`.
    topics
        Stream -> topic overrides of :data:`DEFAULT_TOPICS`.
    radar_points
        ``auto`` (the run's own point clouds, else computed from ADC, else from heatmaps),
        ``shipped``, ``adc`` or ``heatmaps``.
    groundtruth_msg
        ``odometry`` (``nav_msgs/Odometry``) or ``pose`` (``geometry_msgs/PoseStamped``).
    processing
        :class:`coloradar.dsp.ProcessingSettings` fields for computed points (ADC), or
        :func:`coloradar.dsp.heatmap_pointcloud` options (heatmaps).
    overwrite
        Replace an existing bag (anything else at ``out`` is never replaced).
    progress
        ``progress(done, total)`` callback, in messages.

    Returns
    -------
    ExportResult
    """
    _rosbags()
    if fmt not in ROS_FORMATS:
        raise SettingsError(f"unknown bag format {fmt!r}; expected ros1 or ros2")
    if radar_points not in RADAR_POINT_SOURCES:
        raise SettingsError(f"unknown radar point source {radar_points!r}; expected one of "
                             f"{', '.join(RADAR_POINT_SOURCES)}")
    if groundtruth_msg not in GROUNDTRUTH_MSGS:
        raise SettingsError(f"unknown ground-truth message {groundtruth_msg!r}; expected "
                             "odometry or pose")
    topic_of = {**DEFAULT_TOPICS, **dict(topics or {})}
    unknown = set(topic_of) - set(DEFAULT_TOPICS)
    if unknown:
        raise SettingsError(f"unknown stream(s) {', '.join(sorted(unknown))} in the topic map; "
                             f"known: {', '.join(DEFAULT_TOPICS)}")
    out = Path(out)
    _check_bag_target(out, fmt, overwrite)
    asked = list(streams) if streams is not None else None
    for s in asked or ():
        if s not in DEFAULT_TOPICS:
            raise SettingsError(f"unknown stream {s!r}; expected some of {', '.join(DEFAULT_TOPICS)}")
    used_topics = [topic_of[s] for s in (asked or DEFAULT_TOPICS)]
    if len(set(used_topics)) != len(used_topics):
        raise SettingsError(f"two streams share one topic: {', '.join(used_topics)}")

    result = ExportResult(out, fmt)
    have = set(seq.available())
    plan: list[_Planned] = []

    def want(key: str, present: bool, why: str) -> bool:
        if asked is not None and key not in asked:
            return False
        if not present:
            if asked is not None:
                raise MissingDataError(f"{seq.location}: cannot export {key}: {why}")
            result.skipped[key] = why
            return False
        return True

    if want("lidar/pointclouds", "lidar/pointclouds" in have, "the run has no lidar scans"):
        lid = seq.lidar.pointclouds
        plan.append(_Planned("lidar/pointclouds", lid.timestamps, "lidar", frames=lid))
    for radar in ("cascade", "single_chip"):
        key = f"{radar}/pointclouds"
        if asked is not None and key not in asked:
            continue
        try:
            stream, conv, src = _radar_point_stream(seq, radar, radar_points, processing)
        except MissingDataError as exc:
            if asked is not None:
                raise
            result.skipped[key] = str(exc)
            continue
        result.sources[radar] = src
        plan.append(_Planned(key, stream.timestamps, radar, frames=stream, convert=conv))
    if want("imu", "imu" in have, "the run has no IMU data"):
        plan.append(_Planned("imu", seq.imu.timestamps, "imu", rows=seq.imu.data))
    if want("groundtruth", "groundtruth" in have, "the run has no ground truth"):
        gt = seq.groundtruth
        plan.append(_Planned("groundtruth", gt.timestamps, WORLD_FRAME, rows=gt.poses))
    if want("vicon", "vicon" in have, "the run has no Vicon poses"):
        vic = seq.vicon
        assert vic is not None
        plan.append(_Planned("vicon", vic.timestamps, WORLD_FRAME, rows=vic.poses))
    if want("tf_static", bool(seq.calib.transforms), "the calibration has no extrinsics"):
        starts = [float(p.timestamps[0]) for p in plan if p.timestamps.size]
        plan.append(_Planned("tf_static", np.array([min(starts) if starts else 0.0]), BASE_FRAME))
    if not plan:
        raise MissingDataError(f"{seq.location}: nothing to export")

    # Global time order across streams; ties keep the stream order above.
    stamps = [times_to_ns(p.timestamps) for p in plan]
    sec = np.concatenate([st[0] for st in stamps])
    nsec = np.concatenate([st[1] for st in stamps])
    stream_i = np.concatenate([np.full(p.timestamps.size, i, np.int64) for i, p in enumerate(plan)])
    frame_k = np.concatenate([np.arange(p.timestamps.size, dtype=np.int64) for p in plan])
    order = np.lexsort((frame_k, stream_i, nsec, sec))
    total = int(order.size)

    # The bag is written under a hidden partial name and renamed into place when complete.
    # rosbag2 names its data file after the bag folder (NAME/NAME.db3, listed in
    # metadata.yaml), so a ROS 2 bag is written as .NAME.partial/NAME and the folder NAME is
    # moved out: the final bag holds the normal names that `ls` and `cp NAME/*` see.
    partial = out.with_name(f".{out.name}.partial")
    if partial.exists() or partial.is_symlink():  # left by an interrupted export of ours
        shutil.rmtree(partial) if partial.is_dir() and not partial.is_symlink() else partial.unlink()
    out.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "ros2":
        partial.mkdir()
    bag_path = partial / out.name if fmt == "ros2" else partial
    start = time.perf_counter()
    b = _builder(fmt)
    writer = _open_writer(fmt, bag_path)
    counts = {p.key: 0 for p in plan}
    try:
        conns = {}
        for p in plan:
            p.msgtype = _export_type(p.key, groundtruth_msg)
            if fmt == "ros1":
                conns[p.key] = writer.add_connection(topic_of[p.key], p.msgtype, typestore=b.store,
                                                     latching=1 if p.key == "tf_static" else None)
            else:
                qos = _latched_qos() if p.key == "tf_static" else ()
                conns[p.key] = writer.add_connection(topic_of[p.key], p.msgtype, typestore=b.store,
                                                     offered_qos_profiles=qos)
        for done, j in enumerate(order, start=1):
            p = plan[int(stream_i[j])]
            t_s, t_ns, k = int(sec[j]), int(nsec[j]), int(frame_k[j])
            try:
                msg = _message(b, p, k, t_s, t_ns, seq.calib.transforms)
            except _BadFrame as exc:
                # Skipped and reported, as every other command does with a bad frame; the bag
                # stays valid and holds every other message.
                result.failures.append(str(exc))
                warnings.warn(str(exc), DataWarning, stacklevel=2)
                if progress is not None:
                    progress(done, total)
                continue
            writer.write(conns[p.key], t_s * 1_000_000_000 + t_ns, b.serialize(msg, p.msgtype))
            counts[p.key] += 1
            result.frames += int(p.frames is not None)
            if progress is not None:
                progress(done, total)
        writer.close()
    except BaseException:
        try:
            writer.abort()  # releases the file; the partial bag is removed below
        except Exception:
            pass  # the original error is the one to report
        if partial.exists():
            shutil.rmtree(partial) if partial.is_dir() else partial.unlink()
        raise
    _replace(bag_path, out)
    if fmt == "ros2":
        partial.rmdir()
    result.counts = {topic_of[k]: v for k, v in counts.items()}
    result.seconds = time.perf_counter() - start
    return result


def _export_type(key: str, groundtruth_msg: str) -> str:
    if key.endswith("pointclouds"):
        return _TYPES["cloud"]
    if key == "imu":
        return _TYPES["imu"]
    if key == "groundtruth":
        return _TYPES[groundtruth_msg]
    if key == "vicon":
        return _TYPES["pose"]
    return _TYPES["tf"]


def _latched_qos() -> tuple[Any, ...]:
    """ROS 2's equivalent of a latched ROS 1 topic (what tf2's static broadcaster offers):
    reliable, transient-local, keep last 1; so that ``ros2 bag play`` serves /tf_static to
    late subscribers."""
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    never = QosTime(0, 0)
    return (Qos(QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
                never, never, QosLiveliness.AUTOMATIC, never, False),)


def _open_writer(fmt: str, path: Path):
    if fmt == "ros1":
        from rosbags.rosbag1 import Writer as Writer1

        w1 = Writer1(path)
        w1.open()
        return w1
    from rosbags.rosbag2 import Writer as Writer2

    w2 = Writer2(path, version=8)
    w2.open()
    return w2


# -- import -------------------------------------------------------------------------------------
@dataclass
class ImportResult:
    """What :func:`import_bag` wrote.

    Attributes
    ----------
    run_path
        The new run folder.
    calib_path
        The dataset's calib folder (written, or found and kept).
    calib_written
        Whether this import wrote ``calib_path``.
    counts
        Samples written per stream.
    topics
        Stream -> topic it came from.
    extrinsics
        Sensors whose ``base_T_sensor`` came from the bag's ``/tf_static``.
    extrinsics_not_applied
        Sensors whose ``/tf_static`` extrinsic differs from the kept calibration's (a
        :class:`CalibrationWarning` says so): the imported run is read with the kept one.
    ignored
        Topics of the bag that no stream took, with their message type.
    disjoint
        Pairs of imported streams whose time spans do not overlap (a :class:`DataWarning`
        says so): they cannot be associated by time.
    seconds
        Wall time.
    """

    run_path: Path
    calib_path: Path
    calib_written: bool = False
    counts: dict[str, int] = field(default_factory=dict)
    topics: dict[str, str] = field(default_factory=dict)
    extrinsics: list[str] = field(default_factory=list)
    extrinsics_not_applied: list[str] = field(default_factory=list)
    ignored: dict[str, str] = field(default_factory=dict)
    disjoint: list[tuple[str, str]] = field(default_factory=list)
    seconds: float = 0.0


def parse_topic_map(items: Iterable[str]) -> dict[str, str]:
    """``["/topic=stream", ...]`` -> ``{topic: stream}``, checking every stream name.

    Raises
    ------
    ColoradarError
        An item is not ``TOPIC=STREAM`` or names an unknown stream.
    """
    out: dict[str, str] = {}
    for item in items:
        topic, sep, stream = item.partition("=")
        if not sep or not topic.strip() or not stream.strip():
            raise SettingsError(f"topic map entry {item!r}: expected TOPIC=STREAM, e.g. "
                                 "/os1/points=lidar/pointclouds")
        stream = stream.strip()
        if stream not in DEFAULT_TOPICS:
            raise SettingsError(f"topic map entry {item!r}: unknown stream {stream!r}; expected "
                                 f"one of {', '.join(DEFAULT_TOPICS)}")
        out[topic.strip()] = stream
    return out


_ACCEPTED = {
    "cloud": (_TYPES["cloud"],),
    "imu": (_TYPES["imu"],),
    "pose": (_TYPES["odometry"], _TYPES["pose"], _TYPES["pose_cov"], _TYPES["transform"]),
    "tf": (_TYPES["tf"],),
}


def _kind(stream: str) -> str:
    if stream.endswith("pointclouds"):
        return "cloud"
    if stream in ("groundtruth", "vicon"):
        return "pose"
    return "imu" if stream == "imu" else "tf"


def _stamp(msg: Any) -> tuple[int, int]:
    st = msg.header.stamp
    return int(st.sec), int(st.nanosec)


def _pose_row(msg: Any) -> np.ndarray:
    if hasattr(msg, "transform"):  # TransformStamped
        t, q = msg.transform.translation, msg.transform.rotation
        return np.array([t.x, t.y, t.z, q.x, q.y, q.z, q.w], dtype=np.float64)
    pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
    p, q = pose.position, pose.orientation
    return np.array([p.x, p.y, p.z, q.x, q.y, q.z, q.w], dtype=np.float64)


def _layout(msg: Any) -> CloudLayout:
    return CloudLayout(tuple(f.name for f in msg.fields), tuple(int(f.offset) for f in msg.fields),
                       tuple(int(f.datatype) for f in msg.fields), tuple(int(f.count) for f in msg.fields),
                       int(msg.point_step), int(msg.row_step), int(msg.height), int(msg.width),
                       bool(msg.is_bigendian))


def _bag_paths(bag: Path) -> list[Path]:
    if not bag.exists():
        raise MissingDataError(f"{bag}: no such bag (a ROS 1 .bag file or a ROS 2 bag folder)")
    if bag.is_dir():
        if not (bag / "metadata.yaml").is_file():
            raise FormatError(f"{bag}: a folder but not a ROS 2 bag (no metadata.yaml inside)")
        return [bag]
    if bag.suffix != ".bag":
        raise FormatError(f"{bag}: expected a ROS 1 .bag file or a ROS 2 bag folder")
    return [bag]


def _open_reader(bag: Path):
    """An opened ``rosbags`` ``AnyReader`` on ``bag``, or a :class:`FormatError` naming it."""
    from rosbags.highlevel import AnyReader

    paths = _bag_paths(bag)
    try:
        reader = AnyReader(paths)
        reader.open()
    except Exception as exc:  # rosbags raises its own error types for unreadable bags
        if isinstance(exc, ColoradarError):
            raise
        raise FormatError(f"{bag}: not a readable ROS bag ({exc})") from None
    return reader


def _messages(reader: Any, conns: list, bag: Path) -> Iterator[tuple[Any, int, bytes]]:
    """``reader.messages(connections=conns)``, a damaged bag a :class:`FormatError` naming it."""
    it = reader.messages(connections=conns)
    while True:
        try:
            item = next(it)
        except StopIteration:
            return
        except Exception as exc:  # rosbags' own error types: a damaged chunk or database
            raise FormatError(f"{bag}: damaged, a message cannot be read ({exc})") from None
        yield item


CLOUD_FIELD_KEYS = ("intensity", "range_rate")
"""Point columns whose bag field name :func:`import_bag` can be told (``fields=``)."""


def parse_field_map(items: Iterable[str]) -> dict[str, str]:
    """``["intensity=snr_db", "range_rate=v_doppler_mps"]`` -> ``{column: bag field name}``.

    Raises
    ------
    SettingsError
        An item is not ``COLUMN=FIELD`` or names a column other than intensity / range_rate.
    """
    out: dict[str, str] = {}
    for item in items:
        key, sep, name = item.partition("=")
        key, name = key.strip(), name.strip()
        key = "range_rate" if key == "doppler" else key
        if not sep or not name or key not in CLOUD_FIELD_KEYS:
            raise SettingsError(f"field map entry {item!r}: expected intensity=FIELD or "
                                "range_rate=FIELD, e.g. range_rate=v_doppler_mps")
        out[key] = name
    return out


def _preferred(fields: Mapping[str, str]) -> dict[str, str]:
    """A user's field map keyed by the decoder's column names (``range_rate`` is ``doppler``)."""
    return {("doppler" if k == "range_rate" else k): v for k, v in fields.items()}


def _resolve_tf(edges: Mapping[str, tuple[str, SE3]], frame: str, base: str) -> SE3 | None:
    """``base_T_frame`` through the tf tree (parent links), or None when ``frame`` is not below
    ``base``."""
    pose = SE3.identity()
    seen = set()
    while frame != base:
        if frame in seen or frame not in edges:
            return None
        seen.add(frame)
        parent, parent_T_frame = edges[frame]
        pose = parent_T_frame @ pose
        frame = parent
    return pose


def import_bag(bag: str | os.PathLike[str], out: str | os.PathLike[str], *,
               name: str | None = None, topics: Mapping[str, str] | None = None,
               calib: Calibration | str | os.PathLike[str] | None = None,
               base_frame: str = BASE_FRAME, time_source: str = "header",
               relative_poses: bool = False, overwrite: bool = False,
               fields: Mapping[str, str] | None = None, flip_range_rate: bool = False,
               progress: Callable[[int, int], None] | None = None) -> ImportResult:
    """Turn a ROS 1 or ROS 2 bag into a ColoRadar run ``out/<name>`` readable by
    :func:`coloradar.open_sequence`.

    Parameters
    ----------
    bag
        A ROS 1 ``.bag`` file or a ROS 2 bag folder.
    out
        The dataset root to write into (created if needed).
    name
        Run folder name (default: the bag's name without suffix).
    topics
        ``{topic: stream}``; streams are those of :data:`DEFAULT_TOPICS`. Default: the topics
        :func:`export_bag` writes. Topics of the bag not in the map are ignored (and listed).
    calib
        Radar configurations for the written ``out/calib`` (a calib folder, a
        :class:`Calibration`, or None for the built-in presets). Its extrinsics are replaced by
        those on ``/tf_static`` where the bag has them. An existing ``out/calib`` is kept.
    base_frame
        The tf frame that is the rig's ``base``.
    time_source
        ``header`` (each message's header stamp) or ``bag`` (the time it was recorded).
    relative_poses
        Express the ground-truth poses relative to the first one, as the dataset's are.
    overwrite
        Replace an existing run folder of the same name.
    fields
        ``{"intensity": NAME, "range_rate": NAME}``: the PointField names a recorder uses for
        the point columns, when they are none of the usual ones (``intensity``, ``power``,
        ``snr``, ``rcs``, ``i``; ``doppler``, ``range_rate``, ``velocity``, ``v_doppler``,
        ``radial_velocity``), e.g. ``{"intensity": "snr_db", "range_rate":
        "v_doppler_mps"}``. A point-cloud topic with no field for a column imports it as zeros
        and says so (a :class:`DataWarning` naming the topic and the fields it has).
    flip_range_rate
        Negate the imported range rates: coloradar's range rate is > 0 when the target recedes
        (``docs/conventions.md``); set this for a recorder whose Doppler field is > 0 when the
        target approaches.
    progress
        ``progress(done, total)`` callback, in messages.

    Returns
    -------
    ImportResult

    Raises
    ------
    ColoradarError
        A mapped topic is missing or has a message type its stream cannot take; the bag has no
        message on any mapped topic; a point cloud lacks ``x y z``; a field named in
        ``fields`` is in none of the point-cloud topics; the run exists and ``overwrite`` is
        not set.
    """
    _rosbags()

    if time_source not in ("header", "bag"):
        raise SettingsError(f"unknown time source {time_source!r}; expected header or bag")
    bag = Path(bag)
    _bag_paths(bag)
    root = Path(out)
    run_name = name or bag.name.removesuffix(".bag")
    final = root / run_name
    if final.exists() and not overwrite:
        raise OutputExistsError(f"{final}: exists; pass overwrite=True (--overwrite) to replace it")
    if final.exists() and not (final / ".coloradar_import").is_file():
        raise OutputExistsError(f"{final}: exists and was not written by coloradar import; "
                                "not replacing it")
    topic_map = dict(topics) if topics is not None else {v: k for k, v in DEFAULT_TOPICS.items()}
    for stream in topic_map.values():
        if stream not in DEFAULT_TOPICS:
            raise SettingsError(f"unknown stream {stream!r}; expected one of "
                                 f"{', '.join(DEFAULT_TOPICS)}")
    dup = [s for s in set(topic_map.values()) if list(topic_map.values()).count(s) > 1]
    if dup:
        raise SettingsError(f"several topics map to {', '.join(dup)}; give one topic per stream")

    field_map = parse_field_map(f"{k}={v}" for k, v in (fields or {}).items())
    prefer = _preferred(field_map)
    start = time.perf_counter()
    result = ImportResult(final, root / "calib")
    partial = root / f".{run_name}.partial"
    reader = _open_reader(bag)
    try:
        if not sum(c.msgcount for c in reader.connections):
            listed = sorted({c.topic for c in reader.connections})
            raise MissingDataError(f"{bag}: an empty bag: no messages"
                                   + (f" (topics: {', '.join(listed)})" if listed else ""))
        by_topic = {c.topic: c for c in reader.connections}
        conns = []
        for topic, stream in topic_map.items():
            c = by_topic.get(topic)
            if c is None:
                if topics is not None and stream != "tf_static":
                    raise MissingDataError(f"{bag}: no topic {topic} (mapped to {stream}); the bag "
                                           f"has: {', '.join(sorted(by_topic)) or 'nothing'}")
                continue
            kind = _kind(stream)
            if c.msgtype not in _ACCEPTED[kind]:
                raise FormatError(f"{bag}: topic {topic} carries {c.msgtype}; stream {stream} "
                                  f"takes {' or '.join(_ACCEPTED[kind])}")
            conns.append(c)
            result.topics[stream] = topic
        mapped = {c.topic for c in conns}
        result.ignored = {c.topic: c.msgtype for c in reader.connections if c.topic not in mapped}
        if not conns:
            raise MissingDataError(f"{bag}: none of the mapped topics ({', '.join(topic_map)}) is "
                                   f"in the bag (it has: {', '.join(sorted(by_topic)) or 'nothing'})")
        data_conns = [c for c in conns if topic_map[c.topic] != "tf_static"]
        if not any(c.msgcount for c in data_conns):
            raise MissingDataError(
                f"{bag}: no message on the mapped topics "
                f"{', '.join(c.topic for c in data_conns) or '(only /tf_static)'}; the bag's "
                f"messages are on: {', '.join(sorted(c.topic for c in reader.connections if c.msgcount))}")
        for c in data_conns:
            if not c.msgcount:
                warnings.warn(f"{bag}: topic {c.topic} ({topic_map[c.topic]}) has no messages; "
                              "that stream is not imported", DataWarning, stacklevel=2)
        if partial.exists():
            shutil.rmtree(partial)
        partial.mkdir(parents=True)
        total = sum(c.msgcount for c in conns)
        times: dict[str, list[tuple[int, int]]] = {}
        rows: dict[str, list[np.ndarray]] = {}
        frame_ids: dict[str, str] = {}
        edges: dict[str, tuple[str, SE3]] = {}
        cloud_fields: dict[str, tuple[str, ...]] = {}   # topic -> fields of its first message
        for done, (conn, bag_ns, raw) in enumerate(_messages(reader, conns, bag), start=1):
            stream = topic_map[conn.topic]
            try:
                msg = reader.deserialize(raw, conn.msgtype)
            except Exception as exc:  # rosbags' own error types: a damaged message
                raise FormatError(f"{bag}: a {conn.msgtype} message on {conn.topic} (bag time "
                                  f"{bag_ns} ns) cannot be decoded ({exc})") from None
            if stream == "tf_static":
                for tr in msg.transforms:
                    tt, q = tr.transform.translation, tr.transform.rotation
                    edges[tr.child_frame_id] = (tr.header.frame_id, SE3(
                        Rotation.from_quat([q.x, q.y, q.z, q.w]), np.array([tt.x, tt.y, tt.z])))
                continue
            stamp = _stamp(msg) if time_source == "header" else divmod(int(bag_ns), 1_000_000_000)
            k = len(times.setdefault(stream, []))
            times[stream].append(stamp)
            frame_ids.setdefault(stream, getattr(msg.header, "frame_id", ""))
            if _kind(stream) == "cloud":
                what = f"{bag}: {conn.topic} message {k}"
                layout = _layout(msg)
                if conn.topic not in cloud_fields:
                    cloud_fields[conn.topic] = layout.names
                    _check_cloud_fields(bag, conn.topic, stream, layout.names, prefer)
                if stream == "lidar/pointclouds":
                    pts = decode_cloud(layout, msg.data, LIDAR_FIELDS,
                                       aliases=FIELD_ALIASES, optional=("intensity",), what=what,
                                       prefer=prefer)
                    write_lidar_pointcloud(partial / _frame_rel(stream, k), pts)
                else:
                    pts = decode_cloud(layout, msg.data, RADAR_FIELDS,
                                       aliases=FIELD_ALIASES, optional=("intensity", "doppler"),
                                       what=what, prefer=prefer)
                    if flip_range_rate:
                        pts[:, 4] = -pts[:, 4]
                    write_radar_pointcloud(partial / _frame_rel(stream, k), pts)
            elif stream == "imu":
                a, w = msg.linear_acceleration, msg.angular_velocity
                rows.setdefault(stream, []).append(np.array([a.x, a.y, a.z, w.x, w.y, w.z]))
            else:
                rows.setdefault(stream, []).append(_pose_row(msg))
            if progress is not None:
                progress(done, total)
        for key, fname in field_map.items():
            if cloud_fields and not any(fname in names for names in cloud_fields.values()):
                found_fields = "; ".join(f"{t}: {', '.join(n)}" for t, n in cloud_fields.items())
                raise FormatError(f"{bag}: no point-cloud topic has the field {fname!r} given "
                                  f"for {key} (fields found: {found_fields})")
    except BaseException:
        if partial.exists():
            shutil.rmtree(partial)
        raise
    finally:
        reader.close()

    try:
        spans = {}
        for stream, stamps in times.items():
            arr = np.array(stamps, dtype=np.int64).reshape(-1, 2)
            t = ns_to_times(arr[:, 0], arr[:, 1])
            spans[stream] = (float(t.min()), float(t.max()))
            if t.size > 1 and np.any(np.diff(t) <= 0):
                warnings.warn(f"{bag}: {stream} times do not always increase (kept in bag order)",
                              DataWarning, stacklevel=2)
            write_timestamps(partial / _timestamps_rel(stream), t)
            result.counts[stream] = int(t.size)
            if stream == "imu":
                write_imu(partial / COLORADAR.tables["imu"].path, np.array(rows[stream]))
            elif stream in ("groundtruth", "vicon"):
                poses = np.array(rows[stream])
                if relative_poses and poses.shape[0]:
                    first = SE3.from_pose(poses[0]).inverse()
                    poses = np.array([(first @ SE3.from_pose(p)).as_pose() for p in poses])
                write_poses(partial / COLORADAR.tables[stream].path, poses)
        result.disjoint = _disjoint_streams(spans)
        if result.disjoint:
            t0 = min(a for a, _ in spans.values())
            other_time = "--time bag" if time_source == "header" else "--time header"
            shown = ", ".join(f"{s} {a - t0:.3f}..{b - t0:.3f} s" for s, (a, b) in spans.items())
            warnings.warn(f"{bag}: streams that do not overlap in time: "
                          f"{'; '.join(' and '.join(p) for p in result.disjoint)} (spans after "
                          f"the first message: {shown}); they cannot be associated by time "
                          f"(other clocks? try {other_time})",
                          DataWarning, stacklevel=2)
        (partial / ".coloradar_import").write_text(f"imported from {bag}\n", encoding="utf-8")
        # Extrinsics: each stream's frame, plus any tf frame named like a coloradar sensor.
        sensor_frames = {_sensor(s): f for s, f in frame_ids.items() if f and _sensor(s)}
        for sensor in ("cascade", "single_chip", "lidar", "imu", "vicon"):
            sensor_frames.setdefault(sensor, sensor)
        found: dict[str, Extrinsic] = {}
        for sensor, frame in sensor_frames.items():
            pose = _resolve_tf(edges, frame, base_frame)
            if pose is not None and frame != base_frame:
                found[sensor] = Extrinsic(pose.translation, pose.rotation.as_quat())
        result.extrinsics = sorted(found)
        calib_dir = root / "calib"
        if not calib_dir.exists() and not (root / "calib.zip").exists():
            base = calib if isinstance(calib, Calibration) else load_calibration(calib)
            merged = Calibration(base.cascade, base.single_chip,
                                 {**dict(base.transforms), **found}, base.source)
            tmp_calib = root / ".calib.partial"
            if tmp_calib.exists():
                shutil.rmtree(tmp_calib)
            write_calibration(merged, tmp_calib)
            os.replace(tmp_calib, calib_dir)
            result.calib_written = True
        elif found:
            result.calib_path = calib_dir if calib_dir.exists() else root / "calib.zip"
            result.extrinsics_not_applied = _differing_extrinsics(result.calib_path, found)
            if result.extrinsics_not_applied:
                warnings.warn(f"{result.calib_path} is kept, so the bag's /tf_static extrinsics of "
                              f"{', '.join(result.extrinsics_not_applied)} (which differ from it) are "
                              f"not applied to {final}", CalibrationWarning, stacklevel=2)
        if final.exists():
            shutil.rmtree(final)
        os.replace(partial, final)
    except BaseException:
        if partial.exists():
            shutil.rmtree(partial)
        raise
    result.seconds = time.perf_counter() - start
    return result


def _check_cloud_fields(bag: Path, topic: str, stream: str, names: tuple[str, ...],
                        prefer: Mapping[str, str]) -> None:
    """Say (DataWarning) which point columns of a topic will be zeros for want of a field."""
    wanted = ("intensity",) if stream == "lidar/pointclouds" else ("intensity", "doppler")
    missing = [c for c in wanted
               if not any(n in names for n in (prefer.get(c, c), c, *FIELD_ALIASES.get(c, ())))]
    if not missing:
        return
    cols = ["range_rate" if c == "doppler" else c for c in missing]
    hint = " ".join(f"--field {c}=NAME" for c in cols)
    warnings.warn(f"{bag}: topic {topic} has no field for {' or '.join(cols)} (its fields: "
                  f"{', '.join(names) or 'none'}), so {' and '.join(cols)} "
                  f"{'is' if len(cols) == 1 else 'are'} imported as zeros; name the fields with "
                  f"{hint} (fields= in Python)", DataWarning, stacklevel=3)


def _disjoint_streams(spans: Mapping[str, tuple[float, float]]) -> list[tuple[str, str]]:
    """Pairs of streams whose time spans do not overlap (a single sample counts as a point)."""
    keys = list(spans)
    return [(a, b) for i, a in enumerate(keys) for b in keys[i + 1:]
            if spans[a][1] < spans[b][0] or spans[b][1] < spans[a][0]]


def _sensor(stream: str) -> str:
    return {"lidar/pointclouds": "lidar", "cascade/pointclouds": "cascade",
            "single_chip/pointclouds": "single_chip", "imu": "imu"}.get(stream, "")


def _timestamps_rel(stream: str) -> str:
    if stream in COLORADAR.frames:
        return COLORADAR.frame(stream).timestamps_path
    return COLORADAR.tables[stream].timestamps_path


def _frame_rel(stream: str, k: int) -> str:
    return COLORADAR.frame(stream).frame_path(k)


def iter_topics(bag: str | os.PathLike[str]) -> Iterator[tuple[str, str, int]]:
    """``(topic, message type, count)`` of every connection in a bag (for ``--list``)."""
    _rosbags()
    reader = _open_reader(Path(bag))
    try:
        listed = [(topic, str(info.msgtype), int(info.msgcount))
                  for topic, info in sorted(reader.topics.items())]
    finally:
        reader.close()
    yield from listed


def _differing_extrinsics(calib_path: Path, found: Mapping[str, Extrinsic]) -> list[str]:
    """Sensors of ``found`` whose pose differs (beyond 1e-9) from the calibration at ``calib_path``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")       # its known unit defects do not matter here
        kept = load_calibration(calib_path).transforms
    return sorted(name for name, ext in found.items()
                  if name not in kept or not np.allclose(kept[name].matrix(), ext.matrix(), atol=1e-9))
