"""ColoRadar runs from ROS 1 and ROS 2 bags (``rosbags``, optional extra ``ros``).

Import maps topics to streams (``--topic /my/points=single_chip/pointclouds``), reads each
message's header stamp (or the bag time), writes the run with the dataset's writers into
``OUT/<name>`` (assembled in a hidden partial folder, renamed at the end) and writes ``OUT/calib``
when absent: the radar configurations of ``calib`` (built-in presets by default) with the
extrinsics found on ``/tf_static`` (resolved through the tf tree to ``base``). Topics, messages and
times are those of :mod:`.ros_messages`.

:func:`import_bag` is a short pipeline: check the options, plan the topics (which connection feeds
which stream), read the messages (point clouds written as they come, rows gathered), write the
tables, resolve the frames (extrinsics from ``/tf_static``), and finish (calib, rename into place).
"""

from __future__ import annotations

import dataclasses
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
from ..errors import (
    CalibrationWarning,
    ColoradarError,
    DataWarning,
    FormatError,
    MissingDataError,
    OutputExistsError,
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
from .pointcloud2 import decode_cloud
from .ros_messages import (
    _TYPES,
    BASE_FRAME,
    DEFAULT_TOPICS,
    FIELD_ALIASES,
    LIDAR_FIELDS,
    RADAR_FIELDS,
    _layout,
    _pose_row,
    _rosbags,
    _stamp,
    ns_to_times,
)

__all__ = ["CLOUD_FIELD_KEYS", "BagImport", "ImportResult", "import_bag", "iter_topics",
           "parse_field_map", "parse_topic_map"]


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
    preset_extrinsics
        Sensors whose extrinsic in the written ``calib_path`` is a built-in preset (the
        ColoRadar rig's), because the bag's ``/tf_static`` did not give it (a
        :class:`CalibrationWarning` says so).
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
    preset_extrinsics: list[str] = field(default_factory=list)
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



@dataclass(frozen=True)
class BagImport:
    """How to read a bag into a run: the options of :func:`import_bag` (see there)."""

    name: str | None = None
    topics: Mapping[str, str] | None = None
    calib: Calibration | str | os.PathLike[str] | None = None
    base_frame: str = BASE_FRAME
    time_source: str = "header"
    relative_poses: bool = False
    overwrite: bool = False
    fields: Mapping[str, str] | None = None
    flip_range_rate: bool = False
    progress: Callable[[int, int], None] | None = None


def import_bag(bag: str | os.PathLike[str], out: str | os.PathLike[str],
               options: BagImport | None = None, **kw: Any) -> ImportResult:
    """Turn a ROS 1 or ROS 2 bag into a ColoRadar run ``out/<name>`` readable by
    :func:`coloradar.open_sequence`.

    Parameters
    ----------
    bag
        A ROS 1 ``.bag`` file or a ROS 2 bag folder.
    out
        The dataset root to write into (created if needed).
    options
        A :class:`BagImport` holding the options below; keywords replace its fields.

    Other Parameters
    ----------------
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
    job = _check_options(Path(bag), Path(out), dataclasses.replace(options or BagImport(), **kw))
    start = time.perf_counter()
    reader = _open_reader(job.bag)
    try:
        conns = _plan_topics(job, reader)
        _read_messages(job, reader, conns)
    except BaseException:
        if job.partial.exists():
            shutil.rmtree(job.partial)
        raise
    finally:
        reader.close()
    try:
        _write_tables(job)
        found = _resolve_frames(job)
        _finish(job, found)
    except BaseException:
        if job.partial.exists():
            shutil.rmtree(job.partial)
        raise
    job.result.seconds = time.perf_counter() - start
    return job.result


@dataclass
class _Import:
    """One import in progress: the bag, where the run goes, and what has been read so far."""

    bag: Path
    root: Path
    opts: BagImport
    topic_map: dict[str, str]
    field_map: dict[str, str]
    prefer: dict[str, str]
    result: ImportResult
    partial: Path
    times: dict[str, list[tuple[int, int]]] = field(default_factory=dict)
    rows: dict[str, list[np.ndarray]] = field(default_factory=dict)
    frame_ids: dict[str, str] = field(default_factory=dict)
    edges: dict[str, tuple[str, SE3]] = field(default_factory=dict)
    cloud_fields: dict[str, tuple[str, ...]] = field(default_factory=dict)  # topic -> fields


def _check_options(bag: Path, root: Path, opts: BagImport) -> _Import:
    """Step 1: refuse an unknown time source, a missing bag, a run in the way, a bad topic map."""
    if opts.time_source not in ("header", "bag"):
        raise SettingsError(f"unknown time source {opts.time_source!r}; expected header or bag")
    _bag_paths(bag)
    run_name = opts.name or bag.name.removesuffix(".bag")
    final = root / run_name
    if final.exists() and not opts.overwrite:
        raise OutputExistsError(f"{final}: exists; pass overwrite=True (--overwrite) to replace it")
    if final.exists() and not (final / ".coloradar_import").is_file():
        raise OutputExistsError(f"{final}: exists and was not written by coloradar import; "
                                "not replacing it")
    topics = opts.topics
    topic_map = dict(topics) if topics is not None else {v: k for k, v in DEFAULT_TOPICS.items()}
    for stream in topic_map.values():
        if stream not in DEFAULT_TOPICS:
            raise SettingsError(f"unknown stream {stream!r}; expected one of "
                                 f"{', '.join(DEFAULT_TOPICS)}")
    dup = [s for s in set(topic_map.values()) if list(topic_map.values()).count(s) > 1]
    if dup:
        raise SettingsError(f"several topics map to {', '.join(dup)}; give one topic per stream")
    field_map = parse_field_map(f"{k}={v}" for k, v in (opts.fields or {}).items())
    return _Import(bag, root, opts, topic_map, field_map, _preferred(field_map),
                   ImportResult(final, root / "calib"), root / f".{run_name}.partial")


def _plan_topics(job: _Import, reader: Any) -> list:
    """Step 2: the bag's connections that feed a stream, checked for their message types."""
    bag, topic_map = job.bag, job.topic_map
    if not sum(c.msgcount for c in reader.connections):
        listed = sorted({c.topic for c in reader.connections})
        raise MissingDataError(f"{bag}: an empty bag: no messages"
                               + (f" (topics: {', '.join(listed)})" if listed else ""))
    by_topic = {c.topic: c for c in reader.connections}
    conns = []
    for topic, stream in topic_map.items():
        c = by_topic.get(topic)
        if c is None:
            if job.opts.topics is not None and stream != "tf_static":
                raise MissingDataError(f"{bag}: no topic {topic} (mapped to {stream}); the bag "
                                       f"has: {', '.join(sorted(by_topic)) or 'nothing'}")
            continue
        kind = _kind(stream)
        if c.msgtype not in _ACCEPTED[kind]:
            raise FormatError(f"{bag}: topic {topic} carries {c.msgtype}; stream {stream} "
                              f"takes {' or '.join(_ACCEPTED[kind])}")
        conns.append(c)
        job.result.topics[stream] = topic
    mapped = {c.topic for c in conns}
    job.result.ignored = {c.topic: c.msgtype for c in reader.connections if c.topic not in mapped}
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
                          "that stream is not imported", DataWarning, stacklevel=3)
    return conns


def _read_messages(job: _Import, reader: Any, conns: list) -> None:
    """Step 3: every message of the planned connections; point clouds are written into the
    partial run as they come, IMU and pose rows gathered, /tf_static edges kept."""
    bag, partial = job.bag, job.partial
    if partial.exists():
        shutil.rmtree(partial)
    partial.mkdir(parents=True)
    total = sum(c.msgcount for c in conns)
    for done, (conn, bag_ns, raw) in enumerate(_messages(reader, conns, bag), start=1):
        stream = job.topic_map[conn.topic]
        try:
            msg = reader.deserialize(raw, conn.msgtype)
        except Exception as exc:  # rosbags' own error types: a damaged message
            raise FormatError(f"{bag}: a {conn.msgtype} message on {conn.topic} (bag time "
                              f"{bag_ns} ns) cannot be decoded ({exc})") from None
        if stream == "tf_static":
            for tr in msg.transforms:
                tt, q = tr.transform.translation, tr.transform.rotation
                job.edges[tr.child_frame_id] = (tr.header.frame_id, SE3(
                    Rotation.from_quat([q.x, q.y, q.z, q.w]), np.array([tt.x, tt.y, tt.z])))
            continue
        stamp = (_stamp(msg) if job.opts.time_source == "header"
                 else divmod(int(bag_ns), 1_000_000_000))
        k = len(job.times.setdefault(stream, []))
        job.times[stream].append(stamp)
        job.frame_ids.setdefault(stream, getattr(msg.header, "frame_id", ""))
        if _kind(stream) == "cloud":
            _write_cloud(job, conn.topic, stream, msg, k)
        elif stream == "imu":
            a, w = msg.linear_acceleration, msg.angular_velocity
            job.rows.setdefault(stream, []).append(np.array([a.x, a.y, a.z, w.x, w.y, w.z]))
        else:
            job.rows.setdefault(stream, []).append(_pose_row(msg))
        if job.opts.progress is not None:
            job.opts.progress(done, total)
    for key, fname in job.field_map.items():
        if job.cloud_fields and not any(fname in names for names in job.cloud_fields.values()):
            found_fields = "; ".join(f"{t}: {', '.join(n)}" for t, n in job.cloud_fields.items())
            raise FormatError(f"{bag}: no point-cloud topic has the field {fname!r} given "
                              f"for {key} (fields found: {found_fields})")


def _write_cloud(job: _Import, topic: str, stream: str, msg: Any, k: int) -> None:
    what = f"{job.bag}: {topic} message {k}"
    layout = _layout(msg)
    if topic not in job.cloud_fields:
        job.cloud_fields[topic] = layout.names
        _check_cloud_fields(job.bag, topic, stream, layout.names, job.prefer)
    if stream == "lidar/pointclouds":
        pts = decode_cloud(layout, msg.data, LIDAR_FIELDS, aliases=FIELD_ALIASES,
                           optional=("intensity",), what=what, prefer=job.prefer)
        write_lidar_pointcloud(job.partial / _frame_rel(stream, k), pts)
    else:
        pts = decode_cloud(layout, msg.data, RADAR_FIELDS, aliases=FIELD_ALIASES,
                           optional=("intensity", "doppler"), what=what, prefer=job.prefer)
        if job.opts.flip_range_rate:
            pts[:, 4] = -pts[:, 4]
        write_radar_pointcloud(job.partial / _frame_rel(stream, k), pts)


def _write_tables(job: _Import) -> None:
    """Step 4: timestamps of every stream, the IMU and pose tables; warn of streams that do not
    overlap in time."""
    bag, partial, result = job.bag, job.partial, job.result
    spans = {}
    for stream, stamps in job.times.items():
        arr = np.array(stamps, dtype=np.int64).reshape(-1, 2)
        t = ns_to_times(arr[:, 0], arr[:, 1])
        spans[stream] = (float(t.min()), float(t.max()))
        if t.size > 1 and np.any(np.diff(t) <= 0):
            warnings.warn(f"{bag}: {stream} times do not always increase (kept in bag order)",
                          DataWarning, stacklevel=3)
        write_timestamps(partial / _timestamps_rel(stream), t)
        result.counts[stream] = int(t.size)
        if stream == "imu":
            write_imu(partial / COLORADAR.tables["imu"].path, np.array(job.rows[stream]))
        elif stream in ("groundtruth", "vicon"):
            poses = np.array(job.rows[stream])
            if job.opts.relative_poses and poses.shape[0]:
                first = SE3.from_pose(poses[0]).inverse()
                poses = np.array([(first @ SE3.from_pose(p)).as_pose() for p in poses])
            write_poses(partial / COLORADAR.tables[stream].path, poses)
    result.disjoint = _disjoint_streams(spans)
    if result.disjoint:
        t0 = min(a for a, _ in spans.values())
        other_time = "--time bag" if job.opts.time_source == "header" else "--time header"
        shown = ", ".join(f"{s} {a - t0:.3f}..{b - t0:.3f} s" for s, (a, b) in spans.items())
        warnings.warn(f"{bag}: streams that do not overlap in time: "
                      f"{'; '.join(' and '.join(p) for p in result.disjoint)} (spans after "
                      f"the first message: {shown}); they cannot be associated by time "
                      f"(other clocks? try {other_time})",
                      DataWarning, stacklevel=3)
    (partial / ".coloradar_import").write_text(f"imported from {bag}\n", encoding="utf-8")


def _resolve_frames(job: _Import) -> dict[str, Extrinsic]:
    """Step 5: ``base_T_sensor`` of each stream's frame, plus any tf frame named like a
    coloradar sensor, through the /tf_static tree."""
    base_frame = job.opts.base_frame
    sensor_frames = {_sensor(s): f for s, f in job.frame_ids.items() if f and _sensor(s)}
    for sensor in ("cascade", "single_chip", "lidar", "imu", "vicon"):
        sensor_frames.setdefault(sensor, sensor)
    found: dict[str, Extrinsic] = {}
    for sensor, frame in sensor_frames.items():
        pose = _resolve_tf(job.edges, frame, base_frame)
        if pose is not None and frame != base_frame:
            found[sensor] = Extrinsic(pose.translation, pose.rotation.as_quat())
    job.result.extrinsics = sorted(found)
    return found


def _finish(job: _Import, found: dict[str, Extrinsic]) -> None:
    """Step 6: write ``OUT/calib`` when absent (else say which extrinsics are not applied), and
    move the run into place."""
    root, result, calib = job.root, job.result, job.opts.calib
    final = result.run_path
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
        if calib is None:
            # Once written, preset values look like the rig's own to every later reader: this
            # is the one moment a user can be told which they are.
            result.preset_extrinsics = sorted(set(merged.transforms) - set(found))
            if result.preset_extrinsics:
                warnings.warn(f"{calib_dir}: written with the built-in preset extrinsics (the "
                              f"ColoRadar rig's) for {', '.join(result.preset_extrinsics)}: the "
                              "bag's /tf_static gave none for them; replace those files "
                              "with your rig's", CalibrationWarning, stacklevel=3)
    elif found:
        result.calib_path = calib_dir if calib_dir.exists() else root / "calib.zip"
        result.extrinsics_not_applied = _differing_extrinsics(result.calib_path, found)
        if result.extrinsics_not_applied:
            warnings.warn(f"{result.calib_path} is kept, so the bag's /tf_static extrinsics of "
                          f"{', '.join(result.extrinsics_not_applied)} (which differ from it) are "
                          f"not applied to {final}", CalibrationWarning, stacklevel=3)
    if final.exists():
        shutil.rmtree(final)
    os.replace(job.partial, final)


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
                  f"{hint} (fields= in Python)", DataWarning, stacklevel=5)


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
