"""One run (a folder or a ``.zip``) of any known layout, with lazy per-sensor access."""

from __future__ import annotations

import os
import warnings
from collections.abc import Collection
from functools import cached_property, partial
from pathlib import Path

from ..calib import Calibration, HeatmapConfig, RadarCalib, load_calibration, parse_heatmap_cfg
from ..errors import CalibrationWarning, FormatError, MissingDataError
from ..formats.binary import (
    decode_adc,
    decode_heatmap,
    decode_lidar_pointcloud,
    decode_radar_pointcloud,
)
from ..formats.camera import decode_image, parse_camera_info
from ..formats.layout import COLORADAR, COLORADAR_PLUS, LAYOUTS, FrameLayout, RunLayout, get_layout
from ..formats.source import Source, open_source
from .streams import FrameStream, ImuData, PoseData, open_frame_stream, read_imu, read_poses

__all__ = ["STREAMS", "CameraSensor", "LidarSensor", "RadarSensor", "Sequence", "detect_layout",
           "open_sequence"]

SENSOR_FOLDERS = COLORADAR.sensor_folders
"""Top-level folders of a ColoRadar run (see :data:`coloradar.formats.layout.COLORADAR`)."""

RUN_MARKERS = COLORADAR.run_markers
"""Folders of which a ColoRadar run has at least one (a calib folder has ``cascade/`` too, but
none of these)."""

STREAMS: dict[str, tuple[str, str, str]] = {
    name: (s.folder, s.data, s.prefix) for name, s in COLORADAR.frames.items()}
"""stream name -> (folder holding timestamps.txt, folder holding the frames, file prefix) of
the ColoRadar layout; kept for compatibility, the table is :mod:`coloradar.formats.layout`."""


def is_run(src: Source, layout: RunLayout | None = None) -> bool:
    """True when ``src`` looks like a run of ``layout`` (None: of any known layout)."""
    layouts = [layout] if layout is not None else list(LAYOUTS.values())
    return any(src.is_dir(m) for lay in layouts for m in lay.run_markers)


def detect_layout(src: Source, path: Path | None = None) -> RunLayout:
    """The layout of the run in ``src``: ColoRadar+ when the run lies in a ``kitti/`` folder
    or has a ``camera/`` folder, ColoRadar otherwise."""
    in_runs_folder = path is not None and path.parent.name == COLORADAR_PLUS.runs_folder
    if in_runs_folder or src.is_dir("camera"):
        return COLORADAR_PLUS
    return COLORADAR


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
            layout = self._seq.layout
            if key not in layout.frames or not self._seq._has_stream(key):
                have = [s.split("/", 1)[1] for s in self._seq.available() if s.startswith(self.name + "/")]
                raise MissingDataError(f"{self._seq.location}: no {key} in this run "
                                       f"({self.name} has: {', '.join(have) or 'nothing'})")
            st = layout.frames[key]
            src = self._seq._source_of(st)
            data_dir = self._seq._data_dir(st, src)
            self._streams[key] = open_frame_stream(key, src, st.folder, data_dir,
                                                   st.prefix, self._decoder(product),
                                                   timestamps=st.timestamps,
                                                   first_frame=layout.first_frame)
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

    @property
    def heatmap_config(self) -> HeatmapConfig:
        """The grid of :attr:`heatmaps`: the ``heatmap_cfg.txt`` stored beside them when there
        is one (``coloradar process`` and the simulator write the grid they used), else the
        calibration's."""
        st = self._seq.layout.frame(f"{self.name}/heatmaps")
        src = self._seq._source_of(st)
        rel = f"{st.folder}/heatmap_cfg.txt"
        if not src.exists(rel):
            return self.calib.heatmap
        cfg = parse_heatmap_cfg(src.read_text(rel), src.describe(rel))
        if cfg.shape != self.calib.heatmap.shape:
            raise FormatError(f"{src.describe(rel)}: a {cfg.shape} grid, but the calibration's "
                              f"heatmaps are {self.calib.heatmap.shape} (el, az, range)")
        return cfg

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


class CameraSensor(_SensorBase):
    """The camera of a ColoRadar+ run: raw ``rgb`` and ``depth`` images.

    Image sizes come from ``camera/rgb_cam_info.json`` and ``camera/depth_cam_info.json``
    (:func:`coloradar.formats.camera.parse_camera_info`).
    """

    def info(self, kind: str) -> dict:
        """The camera info (ROS ``CameraInfo`` fields) of ``"rgb"`` or ``"depth"``."""
        rel = f"camera/{kind}_cam_info.json"
        src = self._seq.source
        if not src.exists(rel):
            raise MissingDataError(f"{src.describe(rel)}: camera info not found (it gives the "
                                   f"size of the {kind} images)")
        return parse_camera_info(src.read_text(rel), src.describe(rel))

    def _decoder(self, product: str):
        info = self.info(product)
        return partial(_decode_image, product, info["height"], info["width"])

    @property
    def rgb(self) -> FrameStream:
        """Colour images, each uint8 ``(height, width, 3)``."""
        return self._stream("rgb")

    @property
    def depth(self) -> FrameStream:
        """Depth images, each uint16 ``(height, width)`` in the sensor's units (mm)."""
        return self._stream("depth")

    def __repr__(self) -> str:
        return f"<CameraSensor of {self._seq.name}>"


def _decode_image(kind, height, width, buf, name):
    return decode_image(buf, kind, height, width, name)


class Sequence:
    """One run, read lazily from a folder or a zip.

    Parameters
    ----------
    source
        The run's files.
    calib
        The rig calibration used to size and interpret radar frames.
    name
        Run name (defaults to the folder or zip name).
    layout
        The dataset layout (:data:`coloradar.formats.layout.LAYOUTS`); default ColoRadar.
    products
        Output of ``coloradar process`` for this run (ColoRadar layout): its radar streams
        are part of the sequence and take precedence over the run's own.
    """

    def __init__(self, source: Source, calib: Calibration, name: str | None = None,
                 layout: str | RunLayout = COLORADAR, products: Source | None = None):
        self.source = source
        self.products = products
        self.calib = calib
        self.layout = get_layout(layout)
        loc = source.location.rstrip("/")
        self.name = name or Path(loc.split(":")[-1] or loc).name.removesuffix(".zip")
        self.location = source.location

    def __repr__(self) -> str:
        return f"<Sequence {self.name}: {', '.join(self.sensors) or 'empty'}>"

    @cached_property
    def sensors(self) -> list[str]:
        """Sensor folders present in the run."""
        return [s for s in self.layout.sensor_folders if self.source.is_dir(s)]

    def _source_of(self, st: FrameLayout) -> Source:
        """Where stream ``st`` is read from: the products folder when it holds the stream."""
        if (self.products is not None and st.sensor in self.layout.radars
                and self.products.is_dir(COLORADAR.frame(st.name).data)):
            return self.products
        return self.source

    def _data_dir(self, st: FrameLayout, src: Source) -> str:
        """The stream's data folder as present in ``src`` (the layout's, or an alternative)."""
        for d in (st.data, *st.alt_data):
            if src.is_dir(d) and (d == st.data or self._holds_frames(src, d, st.prefix)):
                return d
        return st.data

    @staticmethod
    def _holds_frames(src: Source, folder: str, prefix: str) -> bool:
        return any(n.startswith(prefix + "_") for n in src.listdir(folder))

    def _has_stream(self, key: str) -> bool:
        lay = self.layout
        if key in lay.frames:
            st = lay.frames[key]
            src = self._source_of(st)
            return src.is_dir(st.data) or any(src.is_dir(d) for d in st.alt_data)
        if key in lay.tables:
            return self.source.exists(lay.tables[key].path)
        return False

    def available(self) -> list[str]:
        """Streams present in the run, e.g. ``["cascade/adc", "lidar/pointclouds", "imu"]``."""
        return [k for k in self.layout.stream_names if self._has_stream(k)]

    def stream(self, name: str) -> FrameStream:
        """The frame stream ``name`` (``"cascade/adc"``, ``"lidar/pointclouds"``,
        ``"camera/rgb"`` …, see :attr:`layout`)."""
        if name not in self.layout.frames:
            raise MissingDataError(f"{self.location}: no stream {name!r} in the "
                                   f"{self.layout.title} layout (streams: "
                                   f"{', '.join(self.layout.frames)})")
        sensor, product = name.split("/", 1)
        return getattr(getattr(self, sensor), product)

    def _missing(self, what: str) -> MissingDataError:
        return MissingDataError(f"{self.location}: no {what} in this run (present: "
                                f"{', '.join(self.available()) or 'nothing'})")

    def _radar(self, name: str) -> RadarSensor:
        if name not in self.layout.radars:
            raise MissingDataError(f"{self.location}: the {self.layout.title} layout has no "
                                   f"{name} radar (it has {', '.join(self.layout.radars)})")
        if not (self.source.is_dir(name)
                or (self.products is not None and self.products.is_dir(name))):
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
    def camera(self) -> CameraSensor:
        """The camera's images (ColoRadar+ runs)."""
        if "camera/rgb" not in self.layout.frames or not self.source.is_dir("camera"):
            raise self._missing("camera")
        return CameraSensor(self, "camera")

    def _table(self, key: str):
        t = self.layout.tables.get(key)
        if t is None or not self.source.is_dir(t.folder):
            raise self._missing(key)
        if t.kind == "imu":
            return read_imu(self.source, t.folder)
        return read_poses(self.source, t.folder, t.file)

    @cached_property
    def imu(self) -> ImuData:
        """IMU samples (read in full on first access)."""
        return self._table("imu")

    @cached_property
    def groundtruth(self) -> PoseData:
        """Ground-truth poses of the rig, relative to the start pose."""
        return self._table("groundtruth")

    @cached_property
    def vicon(self) -> PoseData | None:
        """Vicon poses, or None when the run has none."""
        t = self.layout.tables.get("vicon")
        if t is None or not self.source.is_dir(t.folder):
            return None
        return self._table("vicon")


def _find_calib_near(run_path: Path, layout: RunLayout = COLORADAR) -> Path | None:
    candidates = [run_path / "calib", run_path.parent / "calib", run_path.parent / "calib.zip"]
    if layout.runs_folder and run_path.parent.name == layout.runs_folder:
        # <root>/kitti/<run>: the calibration is <root>/calib
        candidates += [run_path.parent.parent / "calib", run_path.parent.parent / "calib.zip"]
    return next((c for c in candidates if c.exists()), None)


def resolve_calibration(calib: Calibration | str | os.PathLike[str] | None,
                        run_path: Path | None = None,
                        layout: str | RunLayout = COLORADAR,
                        sensors: Collection[str] | None = None) -> Calibration:
    """A :class:`Calibration` from an object, a path, or by looking next to ``run_path``.

    With ``calib=None`` the calibration is looked for in ``<run>/calib``, then beside the run
    (``calib/`` or ``calib.zip`` in its parent folder; for ColoRadar+, beside ``kitti/``); if
    none is found the built-in presets are used with a :class:`CalibrationWarning`.
    ``layout`` says which radars the calib folder holds and how its transforms are named;
    ``sensors``, which sensors the run has (values taken from the presets are warned about
    for these only; None: all).
    """
    lay = get_layout(layout)
    if isinstance(calib, Calibration):
        return calib
    if calib is not None:
        return load_calibration(calib, layout=lay, sensors=sensors)
    found = _find_calib_near(run_path, lay) if run_path is not None else None
    if found is None:
        calib = load_calibration(None)
        warnings.warn(f"{run_path}: no calib/ or calib.zip found beside the run; using the "
                      "built-in sensor presets for every value: both radars' waveform, antenna "
                      "and heatmap grid (no coupling or phase/frequency calibration) and the "
                      f"extrinsics of {', '.join(calib.transforms)}", CalibrationWarning,
                      stacklevel=3)
        return calib
    return load_calibration(found, layout=lay, sensors=sensors)


def open_sequence(path: str | os.PathLike[str],
                  calib: Calibration | str | os.PathLike[str] | None = None,
                  layout: str | RunLayout | None = None,
                  products: str | os.PathLike[str] | None = None) -> Sequence:
    """Open one run, a folder or a ``.zip`` read in place.

    Parameters
    ----------
    path
        The run folder or zip (``12_21_2020_ec_hallways_run0[.zip]``, or a ColoRadar+
        ``kitti/<seq>_run<k>``).
    calib
        A :class:`Calibration`, a calib folder/zip, or None to find ``calib/`` or ``calib.zip``
        beside the run (built-in presets if there is none, with a warning).
    layout
        ``"coloradar"``, ``"coloradar_plus"``, or None to recognise it
        (:func:`detect_layout`).
    products
        The folder ``coloradar process`` wrote for this run (``OUT`` for one run,
        ``OUT/<run name>`` for a dataset): its heatmaps and point clouds become the radars'
        streams (in place of the run's own), beside the run's ground truth, lidar and IMU.

    Returns
    -------
    Sequence
    """
    p = Path(path)
    markers = tuple(dict.fromkeys(m for lay in LAYOUTS.values() for m in lay.sensor_folders))
    src = open_source(p, markers=markers)
    lay = get_layout(layout) if layout is not None else detect_layout(src, p)
    if not is_run(src, lay):
        raise MissingDataError(f"{p}: not a {lay.title} run (expected some of "
                               f"{', '.join(lay.run_markers)} inside; found "
                               f"{', '.join(src.listdir('')[:10]) or 'nothing'})")
    name = p.name.removesuffix(".zip")
    prod = None
    if products is not None:
        prod = open_source(Path(products))
        if not is_run(prod, COLORADAR):
            raise MissingDataError(f"{products}: not an output folder of coloradar process "
                                   "(no <radar>/heatmaps or <radar>/pointclouds inside)")
    has = [f for f in lay.sensor_folders if src.is_dir(f)]
    return Sequence(src, resolve_calibration(calib, p, lay, has), name, lay, prod)
