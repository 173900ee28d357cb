"""One ColoRadar run (a folder or a ``.zip``), with lazy per-sensor access."""

from __future__ import annotations

import os
import warnings
from functools import cached_property, partial
from pathlib import Path

from ..calib import Calibration, RadarCalib, load_calibration
from ..errors import CalibrationWarning, MissingDataError
from ..formats.binary import (
    decode_adc,
    decode_heatmap,
    decode_lidar_pointcloud,
    decode_radar_pointcloud,
)
from ..formats.source import Source, open_source
from .streams import FrameStream, ImuData, PoseData, open_frame_stream, read_imu, read_poses

__all__ = ["STREAMS", "LidarSensor", "RadarSensor", "Sequence", "open_sequence"]

SENSOR_FOLDERS = ("cascade", "single_chip", "lidar", "imu", "groundtruth", "vicon")

RUN_MARKERS = ("cascade/adc_samples", "cascade/heatmaps", "single_chip/adc_samples",
               "single_chip/heatmaps", "single_chip/pointclouds", "lidar", "imu", "groundtruth",
               "vicon")
"""Folders of which a run has at least one (a calib folder has ``cascade/`` too, but none of these)."""


def is_run(src: Source) -> bool:
    """True when ``src`` looks like a ColoRadar run."""
    return any(src.is_dir(m) for m in RUN_MARKERS)

# stream name -> (folder holding timestamps.txt, folder holding the frames, file prefix)
STREAMS: dict[str, tuple[str, str, str]] = {
    "cascade/adc": ("cascade/adc_samples", "cascade/adc_samples/data", "frame"),
    "cascade/heatmaps": ("cascade/heatmaps", "cascade/heatmaps/data", "heatmap"),
    "single_chip/adc": ("single_chip/adc_samples", "single_chip/adc_samples/data", "frame"),
    "single_chip/heatmaps": ("single_chip/heatmaps", "single_chip/heatmaps/data", "heatmap"),
    "single_chip/pointclouds": ("single_chip/pointclouds", "single_chip/pointclouds/data",
                                "radar_pointcloud"),
    "lidar/pointclouds": ("lidar", "lidar/pointclouds", "lidar_pointcloud"),
}
"""Layout of the frame streams inside a run (docs/conventions.md §1)."""


def _decode_adc(shape, buf, name):
    return decode_adc(buf, shape, name)


def _decode_heatmap(shape, buf, name):
    return decode_heatmap(buf, shape, name)


def _decode_radar_points(buf, name):
    return decode_radar_pointcloud(buf, name)


def _decode_lidar_points(buf, name):
    return decode_lidar_pointcloud(buf, name)


class _SensorBase:
    def __init__(self, seq: Sequence, name: str):
        self._seq = seq
        self.name = name
        self._streams: dict[str, FrameStream] = {}

    def _stream(self, product: str) -> FrameStream:
        key = f"{self.name}/{product}"
        if key not in self._streams:
            if key not in STREAMS or not self._seq._has_stream(key):
                have = [s.split("/", 1)[1] for s in self._seq.available() if s.startswith(self.name + "/")]
                raise MissingDataError(f"{self._seq.location}: no {key} in this run "
                                       f"({self.name} has: {', '.join(have) or 'nothing'})")
            folder, data_dir, prefix = STREAMS[key]
            if key == "lidar/pointclouds" and self._seq.source.is_dir("lidar/pointclouds/data"):
                data_dir = "lidar/pointclouds/data"
            self._streams[key] = open_frame_stream(key, self._seq.source, folder, data_dir, prefix,
                                                   self._decoder(product))
        return self._streams[key]

    def _decoder(self, product: str):  # pragma: no cover - overridden
        raise NotImplementedError


class RadarSensor(_SensorBase):
    """One radar's data in a run: ``adc``, ``heatmaps`` and (single chip) ``pointclouds``.

    Attributes
    ----------
    calib
        The radar's :class:`~coloradar.calib.RadarCalib` (sizes of its frames come from it).
    """

    def __init__(self, seq: Sequence, name: str, calib: RadarCalib):
        super().__init__(seq, name)
        self.calib = calib

    def _decoder(self, product: str):
        if product == "adc":
            return partial(_decode_adc, self.calib.frame_shape)
        if product == "heatmaps":
            return partial(_decode_heatmap, self.calib.heatmap_shape)
        return _decode_radar_points

    @property
    def adc(self) -> FrameStream:
        """Raw ADC frames, each complex64 ``(tx, rx, chirp, sample)`` in ADC counts."""
        return self._stream("adc")

    @property
    def heatmaps(self) -> FrameStream:
        """Heatmaps, each float32 ``(el, az, range, 2)``: peak intensity, range rate [m/s]."""
        return self._stream("heatmaps")

    @property
    def pointclouds(self) -> FrameStream:
        """The sensor's own point clouds, each float32 ``(N, 5)`` x y z intensity range_rate."""
        return self._stream("pointclouds")

    def __repr__(self) -> str:
        return f"<RadarSensor {self.name} of {self._seq.name}>"


class LidarSensor(_SensorBase):
    """Lidar scans of a run."""

    def _decoder(self, product: str):
        return _decode_lidar_points

    @property
    def pointclouds(self) -> FrameStream:
        """Scans, each float32 ``(N, 4)`` x y z [m] intensity, in the lidar frame."""
        return self._stream("pointclouds")

    @property
    def timestamps(self):
        """Timestamps of the scans [s] (same as ``pointclouds.timestamps``)."""
        return self.pointclouds.timestamps

    def __repr__(self) -> str:
        return f"<LidarSensor of {self._seq.name}>"


class Sequence:
    """One ColoRadar run, read lazily from a folder or a zip.

    Parameters
    ----------
    source
        The run's files.
    calib
        The rig calibration used to size and interpret radar frames.
    name
        Run name (defaults to the folder or zip name).
    """

    def __init__(self, source: Source, calib: Calibration, name: str | None = None):
        self.source = source
        self.calib = calib
        loc = source.location.rstrip("/")
        self.name = name or Path(loc.split(":")[-1] or loc).name.removesuffix(".zip")
        self.location = source.location

    def __repr__(self) -> str:
        return f"<Sequence {self.name}: {', '.join(self.sensors) or 'empty'}>"

    @cached_property
    def sensors(self) -> list[str]:
        """Sensor folders present in the run."""
        return [s for s in SENSOR_FOLDERS if self.source.is_dir(s)]

    def _has_stream(self, key: str) -> bool:
        if key in STREAMS:
            _folder, data_dir, _ = STREAMS[key]
            return self.source.is_dir(data_dir)
        if key == "imu":
            return self.source.exists("imu/imu_data.txt")
        if key == "groundtruth":
            return self.source.exists("groundtruth/groundtruth_poses.txt")
        if key == "vicon":
            return self.source.exists("vicon/vicon_poses.txt")
        return False

    def available(self) -> list[str]:
        """Streams present in the run, e.g. ``["cascade/adc", "lidar/pointclouds", "imu"]``."""
        keys = [*STREAMS, "imu", "groundtruth", "vicon"]
        return [k for k in keys if self._has_stream(k)]

    def _missing(self, what: str) -> MissingDataError:
        return MissingDataError(f"{self.location}: no {what} in this run (present: "
                                f"{', '.join(self.available()) or 'nothing'})")

    def _radar(self, name: str) -> RadarSensor:
        if not self.source.is_dir(name):
            raise self._missing(f"{name} radar")
        return RadarSensor(self, name, self.calib.radar(name))

    @cached_property
    def cascade(self) -> RadarSensor:
        """The cascade (MMWCAS) radar's streams."""
        return self._radar("cascade")

    @cached_property
    def single_chip(self) -> RadarSensor:
        """The single-chip (AWR1843) radar's streams."""
        return self._radar("single_chip")

    def radar(self, name: str) -> RadarSensor:
        """``cascade`` or ``single_chip`` by name."""
        if name not in ("cascade", "single_chip"):
            raise MissingDataError(f"unknown radar {name!r}; expected cascade or single_chip")
        return getattr(self, name)

    @cached_property
    def lidar(self) -> LidarSensor:
        """The lidar's scans."""
        if not self.source.is_dir("lidar"):
            raise self._missing("lidar")
        return LidarSensor(self, "lidar")

    @cached_property
    def imu(self) -> ImuData:
        """IMU samples (read in full on first access)."""
        if not self.source.is_dir("imu"):
            raise self._missing("imu")
        return read_imu(self.source)

    @cached_property
    def groundtruth(self) -> PoseData:
        """Ground-truth poses of the rig, relative to the start pose."""
        if not self.source.is_dir("groundtruth"):
            raise self._missing("groundtruth")
        return read_poses(self.source, "groundtruth", "groundtruth_poses.txt")

    @cached_property
    def vicon(self) -> PoseData | None:
        """Vicon poses, or None when the run has none."""
        if not self.source.is_dir("vicon"):
            return None
        return read_poses(self.source, "vicon", "vicon_poses.txt")


def _find_calib_near(run_path: Path) -> Path | None:
    candidates = [run_path / "calib", run_path.parent / "calib", run_path.parent / "calib.zip"]
    return next((c for c in candidates if c.exists()), None)


def resolve_calibration(calib: Calibration | str | os.PathLike[str] | None,
                        run_path: Path | None = None) -> Calibration:
    """A :class:`Calibration` from an object, a path, or by looking next to ``run_path``.

    With ``calib=None`` the calibration is looked for in ``<run>/calib``, then beside the run
    (``calib/`` or ``calib.zip`` in its parent folder); if none is found the built-in presets
    are used with a :class:`CalibrationWarning`.
    """
    if isinstance(calib, Calibration):
        return calib
    if calib is not None:
        return load_calibration(calib)
    found = _find_calib_near(run_path) if run_path is not None else None
    if found is None:
        warnings.warn(f"{run_path}: no calib/ or calib.zip found beside the run; using the built-in "
                      "sensor presets (no coupling or phase/frequency calibration)",
                      CalibrationWarning, stacklevel=3)
        return load_calibration(None)
    return load_calibration(found)


def open_sequence(path: str | os.PathLike[str],
                  calib: Calibration | str | os.PathLike[str] | None = None) -> Sequence:
    """Open one run, a folder or a ``.zip`` read in place.

    Parameters
    ----------
    path
        The run folder or zip (``12_21_2020_ec_hallways_run0[.zip]``).
    calib
        A :class:`Calibration`, a calib folder/zip, or None to find ``calib/`` or ``calib.zip``
        beside the run (built-in presets if there is none, with a warning).

    Returns
    -------
    Sequence
    """
    p = Path(path)
    src = open_source(p, markers=SENSOR_FOLDERS)
    if not is_run(src):
        raise MissingDataError(f"{p}: not a ColoRadar run (expected some of "
                               f"{', '.join(RUN_MARKERS)} inside; found "
                               f"{', '.join(src.listdir('')[:10]) or 'nothing'})")
    name = p.name.removesuffix(".zip")
    return Sequence(src, resolve_calibration(calib, p), name)
