"""ROS 1 and ROS 2 bags from ColoRadar runs (``rosbags``, optional extra ``ros``).

Export writes, in time order, one message per stored sample, stamped with the time in the run's
files (header stamp and bag time alike); topics, messages and times are those of
:mod:`.ros_messages`. A radar's points are the run's own (shipped) point clouds, or computed from
its ADC frames or heatmaps by ``coloradar.dsp`` when it has none.

:func:`export_bag` is a short pipeline: check the options, plan the topics (which streams, where
their samples come from), order every sample by time, write the messages into a hidden partial
bag, and finish (rename it into place).
"""

from __future__ import annotations

import os
import shutil
import time
import warnings
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..calib import Extrinsic
from ..dataset import Sequence
from ..errors import (
    ColoradarError,
    DataWarning,
    FormatError,
    MissingDataError,
    OutputExistsError,
    ReadError,
    SettingsError,
    WriteError,
)
from .ros_messages import (
    _TYPES,
    BASE_FRAME,
    DEFAULT_TOPICS,
    LIDAR_FIELDS,
    RADAR_FIELDS,
    ROS_FORMATS,
    WORLD_FRAME,
    _Builder,
    _builder,
    _rosbags,
    times_to_ns,
)

__all__ = ["GROUNDTRUTH_MSGS", "RADAR_POINT_SOURCES", "ExportResult", "export_bag"]

RADAR_POINT_SOURCES = ("auto", "shipped", "adc", "heatmaps")
GROUNDTRUTH_MSGS = ("odometry", "pose")


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
    job = _check_options(seq, Path(out), fmt, streams, topics, radar_points, groundtruth_msg,
                         overwrite)
    job.progress = progress
    _plan_topics(job, processing)
    order = _time_order(job.plan)
    start = time.perf_counter()
    try:
        bag_path, partial = _partial_bag(job.out, fmt)
        _write_messages(job, order, bag_path, partial)
        _finish(job, bag_path, partial)
    except OSError as exc:
        if isinstance(exc, ColoradarError):
            raise
        # The system names the hidden partial bag it could not make; the user named OUT.
        raise WriteError(f"{job.out}: cannot write ({exc.strerror or exc})") from None
    job.result.seconds = time.perf_counter() - start
    return job.result


@dataclass
class _Export:
    """One export in progress: the run, where it goes, and what has been decided so far."""

    seq: Sequence
    out: Path
    fmt: str
    topic_of: dict[str, str]
    asked: list[str] | None
    radar_points: str
    groundtruth_msg: str
    result: ExportResult
    plan: list[_Planned] = field(default_factory=list)
    progress: Callable[[int, int], None] | None = None


def _check_options(seq: Sequence, out: Path, fmt: str, streams: Iterable[str] | None,
                   topics: Mapping[str, str] | None, radar_points: str, groundtruth_msg: str,
                   overwrite: bool) -> _Export:
    """Step 1: refuse unknown formats, sources, streams and topics, and an output in the way."""
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
    _check_bag_target(out, fmt, overwrite)
    asked = list(streams) if streams is not None else None
    for s in asked or ():
        if s not in DEFAULT_TOPICS:
            raise SettingsError(f"unknown stream {s!r}; expected some of {', '.join(DEFAULT_TOPICS)}")
    used_topics = [topic_of[s] for s in (asked or DEFAULT_TOPICS)]
    if len(set(used_topics)) != len(used_topics):
        raise SettingsError(f"two streams share one topic: {', '.join(used_topics)}")
    return _Export(seq, out, fmt, topic_of, asked, radar_points, groundtruth_msg,
                   ExportResult(out, fmt))


def _plan_topics(job: _Export, processing: Mapping[str, Any] | None) -> None:
    """Step 2: the streams to write, in topic order, and where their samples come from."""
    seq, asked, result, plan = job.seq, job.asked, job.result, job.plan
    have = set(seq.available())

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
            stream, conv, src = _radar_point_stream(seq, radar, job.radar_points, processing)
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
    for p in plan:
        p.msgtype = _export_type(p.key, job.groundtruth_msg)


@dataclass
class _Order:
    """Every sample of the plan in global time order (ties keep the stream order)."""

    sec: np.ndarray
    nsec: np.ndarray
    stream: np.ndarray
    frame: np.ndarray
    order: np.ndarray


def _time_order(plan: list[_Planned]) -> _Order:
    """Step 3: stamps of every sample, and their order across streams."""
    stamps = [times_to_ns(p.timestamps) for p in plan]
    sec = np.concatenate([st[0] for st in stamps])
    nsec = np.concatenate([st[1] for st in stamps])
    stream_i = np.concatenate([np.full(p.timestamps.size, i, np.int64) for i, p in enumerate(plan)])
    frame_k = np.concatenate([np.arange(p.timestamps.size, dtype=np.int64) for p in plan])
    return _Order(sec, nsec, stream_i, frame_k, np.lexsort((frame_k, stream_i, nsec, sec)))


def _partial_bag(out: Path, fmt: str) -> tuple[Path, Path]:
    """``(path the writer opens, partial path to rename or remove)``.

    The bag is written under a hidden partial name and renamed into place when complete.
    rosbag2 names its data file after the bag folder (NAME/NAME.db3, listed in metadata.yaml),
    so a ROS 2 bag is written as .NAME.partial/NAME and the folder NAME is moved out: the final
    bag holds the normal names that `ls` and `cp NAME/*` see.
    """
    partial = out.with_name(f".{out.name}.partial")
    if partial.exists() or partial.is_symlink():  # left by an interrupted export of ours
        shutil.rmtree(partial) if partial.is_dir() and not partial.is_symlink() else partial.unlink()
    out.parent.mkdir(parents=True, exist_ok=True)
    if fmt == "ros2":
        partial.mkdir()
    return (partial / out.name if fmt == "ros2" else partial), partial


def _connections(job: _Export, writer: Any, b: _Builder) -> dict[str, Any]:
    conns = {}
    for p in job.plan:
        topic = job.topic_of[p.key]
        if job.fmt == "ros1":
            conns[p.key] = writer.add_connection(topic, p.msgtype, typestore=b.store,
                                                 latching=1 if p.key == "tf_static" else None)
        else:
            qos = _latched_qos() if p.key == "tf_static" else ()
            conns[p.key] = writer.add_connection(topic, p.msgtype, typestore=b.store,
                                                 offered_qos_profiles=qos)
    return conns


def _write_messages(job: _Export, o: _Order, bag_path: Path, partial: Path) -> None:
    """Step 4: every sample as a message, in time order; a bad frame is skipped and reported.
    On any error the partial bag is removed."""
    b = _builder(job.fmt)
    writer = _open_writer(job.fmt, bag_path)
    counts = {p.key: 0 for p in job.plan}
    total, result, transforms = int(o.order.size), job.result, job.seq.calib.transforms
    try:
        conns = _connections(job, writer, b)
        for done, j in enumerate(o.order, start=1):
            p = job.plan[int(o.stream[j])]
            t_s, t_ns, k = int(o.sec[j]), int(o.nsec[j]), int(o.frame[j])
            try:
                msg = _message(b, p, k, t_s, t_ns, transforms)
            except _BadFrame as exc:
                # Skipped and reported, as every other command does with a bad frame; the bag
                # stays valid and holds every other message.
                result.failures.append(str(exc))
                warnings.warn(str(exc), DataWarning, stacklevel=3)
            else:
                writer.write(conns[p.key], t_s * 1_000_000_000 + t_ns, b.serialize(msg, p.msgtype))
                counts[p.key] += 1
                result.frames += int(p.frames is not None)
            if job.progress is not None:
                job.progress(done, total)
        writer.close()
    except BaseException:
        try:
            writer.abort()  # releases the file; the partial bag is removed below
        except Exception:
            pass  # the original error is the one to report
        if partial.exists():
            shutil.rmtree(partial) if partial.is_dir() else partial.unlink()
        raise
    result.counts = {job.topic_of[k]: v for k, v in counts.items()}


def _finish(job: _Export, bag_path: Path, partial: Path) -> None:
    """Step 5: move the finished bag into place."""
    _replace(bag_path, job.out)
    if job.fmt == "ros2":
        partial.rmdir()


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
