"""One HDF5 file per run for training (``h5py``, optional extra ``hdf5``).

``export_hdf5`` writes the samples of a :class:`~coloradar.learning.SyncedSamples` view of one
run (one sample per radar frame) and :class:`H5Run` reads them back, so that
``SyncedSamples("run.h5")[i]`` equals the sample ``i`` of the view that wrote it, key for key
and bit for bit.

Layout (``N`` samples)::

    /                         attributes: format, format_version, coloradar_version, run, radar,
                              products, lidar, targets, sample_keys, views (JSON: reduce,
                              range_rate, angles, grid), target_settings (JSON), dropped (JSON),
                              source, base_T_radar, base_T_lidar (4x4), heatmap grid
                              (num_*_bins, range_bin_width, azimuth_bins, elevation_bins)
    /calib                    attributes: every calib file's text, by its relative path
    /radar_frame, /frame_id   int64 (N,)
    /radar_time               float64 (N,)  [s]; also points_time, lidar_time when present
    /heatmap                  float32 (N, el, az, range, 2)     one chunk per sample
    /polar, /bev              float32 (N, C, ., .)              one chunk per sample
    /lidar_polar, /lidar_bev  float32 (N, 3, ., .)
    /world_T_base, /world_T_radar, /radar_T_lidar   float64 (N, 4, 4)
    /pose_knots               float64 (N, 2)
    /points, /lidar, /lidar_target   groups of a ragged array: data (ΣN_i, C), offsets int64
                              (N + 1,): sample i is data[offsets[i]:offsets[i+1]]

Every dataset is chunked and compressed (gzip by default, with the byte shuffle filter) and
carries a ``description`` attribute (what it is and its unit). The file is written under a
temporary name beside the output and renamed when complete.
"""

from __future__ import annotations

import json
import os
import tempfile
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._version import __version__
from ..calib import HeatmapConfig, load_calibration, write_calibration
from ..dataset import Sequence, open_sequence
from ..errors import FormatError, MissingDataError, MissingDependencyError, ReadError, WriteError
from ..formats.atomic import default_file_mode, new_output_path
from ..learning.samples import SyncedSamples, ViewOptions
from ..learning.targets import TargetSettings
from ..learning.views import BevGrid

__all__ = ["COMPRESSIONS", "FORMAT", "FORMAT_VERSION", "H5Run", "Hdf5ExportResult", "export_hdf5"]

FORMAT = "coloradar-learning"
FORMAT_VERSION = 1
COMPRESSIONS = ("gzip", "lzf", "none")

_RAGGED = ("points", "lidar", "lidar_target")
_SCALARS = ("radar_frame", "frame_id", "radar_time", "points_time", "lidar_time")
_NEEDS: dict[str, tuple[str, ...]] = {
    # sample key -> what must be asked for it to be in a sample: products, "lidar", "targets"
    "heatmap": ("heatmap",), "polar": ("polar",), "bev": ("bev",),
    "points": ("points",), "points_time": ("points",),
    "lidar": ("lidar",), "lidar_time": ("lidar",), "radar_T_lidar": ("lidar",),
    "lidar_target": ("targets",), "lidar_polar": ("targets", "polar"),
    "lidar_bev": ("targets", "bev"),
}
DESCRIPTIONS = {
    "radar_frame": "position of the radar frame in its stream",
    "frame_id": "number in the radar frame's file name",
    "radar_time": "radar frame time, Unix seconds",
    "points_time": "time of the associated radar point cloud, Unix seconds",
    "lidar_time": "time of the nearest lidar scan, Unix seconds",
    "heatmap": "radar heatmap (el, az, range, 2): intensity, range rate [m/s]",
    "polar": "range-azimuth image (C, range, az): intensity [dB], range rate [m/s]",
    "bev": "bird's-eye image (C, nx, ny), radar frame: intensity [dB], range rate [m/s]; "
           "NaN outside the field of view",
    "lidar_polar": "lidar target on the polar grid (3, range, az): occupancy, height [m], intensity",
    "lidar_bev": "lidar target on the BEV grid (3, nx, ny): occupancy, height [m], intensity",
    "points": "radar point cloud x y z [m] intensity range_rate [m/s], radar frame",
    "lidar": "nearest lidar scan x y z [m] intensity, lidar frame",
    "lidar_target": "lidar voxel map cut to the radar's field of view: x y z [m] intensity, radar frame",
    "world_T_base": "ground-truth pose at radar_time (4x4)",
    "world_T_radar": "radar pose at radar_time (4x4)",
    "radar_T_lidar": "maps the lidar scan into the radar frame at radar_time (4x4)",
    "pose_knots": "ground-truth times bracketing radar_time [s]",
}


def _h5py() -> Any:
    try:
        import h5py
    except ImportError:
        raise MissingDependencyError("HDF5 files need h5py: pip install 'coloradar[hdf5]'") from None
    return h5py


@dataclass
class Hdf5ExportResult:
    """What :func:`export_hdf5` wrote.

    Attributes
    ----------
    path
        The file.
    frames
        Samples written.
    bytes
        Size of the file.
    seconds
        Wall time.
    shapes
        Dataset name -> shape.
    dropped
        Radar frames left out, by reason (no lidar scan, outside the ground truth...).
    """

    path: Path
    frames: int
    bytes: int
    seconds: float
    shapes: dict[str, tuple[int, ...]] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)


def _calib_texts(seq: Sequence) -> dict[str, str]:
    with tempfile.TemporaryDirectory(prefix="coloradar-calib-") as tmp:
        root = write_calibration(seq.calib, Path(tmp) / "calib")
        return {p.relative_to(root).as_posix(): p.read_text(encoding="utf-8")
                for p in sorted(root.rglob("*")) if p.is_file()}


def export_hdf5(source: Sequence | str | os.PathLike[str], out: str | os.PathLike[str], *,
                radar: str = "cascade", products: Iterable[str] = ("heatmap", "bev"),
                lidar: bool = False, targets: bool = True,
                target_settings: TargetSettings | None = None, views: ViewOptions | None = None,
                compression: str = "gzip", compression_level: int = 4,
                pose_source: str = "groundtruth", calib: Any = None, overwrite: bool = False,
                progress: Callable[[int, int], None] | None = None) -> Hdf5ExportResult:
    """Write one run's learning samples to an HDF5 file.

    Parameters
    ----------
    source
        A run (folder, zip or :class:`~coloradar.Sequence`).
    out
        The ``.h5`` file.
    radar, products, lidar, targets, target_settings, views, pose_source
        As for :class:`~coloradar.learning.SyncedSamples`.
    compression
        ``"gzip"`` (portable: every HDF5 reader has it), ``"lzf"`` (faster, h5py only) or
        ``"none"``.
    compression_level
        gzip level 1–9.
    overwrite
        Replace an existing file.
    progress
        ``progress(done, total)`` after each sample (the first sample of a run with targets
        also fuses the run's lidar map).

    Raises
    ------
    OutputExistsError
        ``out`` exists and ``overwrite`` is not set.
    """
    h5py = _h5py()
    if compression not in COMPRESSIONS:
        raise FormatError(f"compression must be one of {', '.join(COMPRESSIONS)}, got {compression!r}")
    out = new_output_path(out, overwrite)
    t0 = time.perf_counter()
    seq = source if isinstance(source, Sequence) else open_sequence(source, calib=calib)
    view = SyncedSamples(seq, radar=radar, products=tuple(products), lidar=lidar, targets=targets,
                         target_settings=target_settings, views=views, pose_source=pose_source)
    if len(view) == 0:
        raise MissingDataError(f"{seq.location}: no {radar} frame has every partner asked for "
                               f"(left out: {view.dropped})")
    grid = view.grid
    vopt = view.views
    run = view._runs[0]
    comp: dict[str, Any] = {}
    if compression == "gzip":
        comp = {"compression": "gzip", "compression_opts": int(compression_level), "shuffle": True}
    elif compression == "lzf":
        comp = {"compression": "lzf", "shuffle": True}
    n = len(view)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    shapes: dict[str, tuple[int, ...]] = {}
    try:
        with h5py.File(tmp, "w") as f:
            a = f.attrs
            a["format"] = FORMAT
            a["format_version"] = FORMAT_VERSION
            a["coloradar_version"] = __version__
            a["run"] = seq.name
            a["source"] = str(seq.location)
            a["radar"] = radar
            a["products"] = json.dumps(list(view.products))
            a["lidar"] = bool(lidar)
            a["targets"] = bool(targets)
            a["pose_source"] = pose_source
            a["views"] = json.dumps({"reduce": vopt.reduce, "range_rate": vopt.range_rate,
                                     "angles": vopt.angles,
                                     "grid": grid.to_dict() if grid is not None else None})
            a["target_settings"] = json.dumps(view.target_settings.to_dict())
            a["dropped"] = json.dumps(view.dropped)
            a["base_T_radar"] = run.base_T_radar.matrix()
            if run.base_T_lidar is not None:
                a["base_T_lidar"] = run.base_T_lidar.matrix()
            cfg = run.config
            if cfg is not None:
                a["num_range_bins"] = cfg.num_range_bins
                a["num_azimuth_bins"] = cfg.num_azimuth_bins
                a["num_elevation_bins"] = cfg.num_elevation_bins
                a["range_bin_width"] = cfg.range_bin_width
                a["azimuth_bins"] = np.asarray(cfg.azimuth_bins)
                a["elevation_bins"] = np.asarray(cfg.elevation_bins)
            cal = f.create_group("calib")
            for rel, text in _calib_texts(seq).items():
                cal.attrs[rel] = text
            scalars: dict[str, list[Any]] = {}
            offsets: dict[str, list[int]] = {}
            keys: list[str] = []
            for i in range(n):
                s = view[i]
                if i == 0:
                    keys = [k for k in s if k != "run"]
                    for k in keys:
                        v = s[k]
                        if k in _SCALARS:
                            scalars[k] = []
                        elif k in _RAGGED:
                            g = f.create_group(k)
                            g.attrs["description"] = DESCRIPTIONS.get(k, "")
                            g.create_dataset("data", shape=(0, v.shape[1]), maxshape=(None, v.shape[1]),
                                             dtype=v.dtype, chunks=(16384, v.shape[1]), **comp)
                            offsets[k] = [0]
                        else:
                            arr = np.asarray(v)
                            big = arr.size >= 256
                            chunks = (1, *arr.shape) if big else (min(n, 4096), *arr.shape)
                            d = f.create_dataset(k, shape=(n, *arr.shape), dtype=arr.dtype,
                                                 chunks=chunks, **comp)
                            d.attrs["description"] = DESCRIPTIONS.get(k, "")
                for k in keys:
                    v = s[k]
                    if k in scalars:
                        scalars[k].append(v)
                    elif k in offsets:
                        d = f[k]["data"]
                        m = d.shape[0]
                        d.resize(m + v.shape[0], axis=0)
                        d[m:] = v
                        offsets[k].append(m + v.shape[0])
                    else:
                        f[k][i] = v
                if progress is not None:
                    progress(i + 1, n)
            for k, vals in scalars.items():
                d = f.create_dataset(k, data=np.asarray(
                    vals, dtype=np.int64 if k in ("radar_frame", "frame_id") else np.float64))
                d.attrs["description"] = DESCRIPTIONS.get(k, "")
            for k, offs in offsets.items():
                f[k].create_dataset("offsets", data=np.asarray(offs, dtype=np.int64))
            a["sample_keys"] = json.dumps(["run", *keys])
            a["num_samples"] = n
            for k in keys:
                obj = f[k]
                shapes[k] = tuple(obj["data"].shape if k in offsets else obj.shape)
        os.chmod(tmp, default_file_mode())
        os.replace(tmp, out)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise WriteError(f"{out}: cannot write the HDF5 file ({exc})") from exc
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return Hdf5ExportResult(out, n, out.stat().st_size, time.perf_counter() - t0, shapes,
                            dict(view.dropped))


class H5Run:
    """Samples of one file written by :func:`export_hdf5` (read on demand; picklable: each
    process opens its own handle).

    Attributes
    ----------
    name, radar, products, lidar, targets
        What the file holds.
    views, target_settings
        How its images and targets were made.
    config
        Its heatmap grid (None without heatmap products).
    radar_k
        int64 ``(N,)``: each sample's radar frame position.
    """

    def __init__(self, path: str | os.PathLike[str]):
        h5py = _h5py()
        self.path = Path(path)
        if not self.path.is_file():
            raise ReadError(f"{self.path}: not a file")
        try:
            f = h5py.File(self.path, "r")
        except OSError as exc:
            raise FormatError(f"{self.path}: not an HDF5 file ({exc})") from None
        with f:
            a = f.attrs
            if a.get("format") != FORMAT:
                raise FormatError(f"{self.path}: not a {FORMAT} file (written by 'coloradar "
                                  "export RUN OUT.h5 --format hdf5')")
            if int(a["format_version"]) > FORMAT_VERSION:
                raise FormatError(f"{self.path}: format version {int(a['format_version'])}; this "
                                  f"coloradar reads up to {FORMAT_VERSION}")
            self.name = str(a["run"])
            self.radar = str(a["radar"])
            self.products = tuple(json.loads(a["products"]))
            self.lidar = bool(a["lidar"])
            self.targets = bool(a["targets"])
            self.keys: list[str] = json.loads(a["sample_keys"])
            v = json.loads(a["views"])
            self.views = ViewOptions(BevGrid(**v["grid"]) if v["grid"] else None, v["reduce"],
                                     v["range_rate"], v["angles"])
            self.target_settings = TargetSettings(**json.loads(a["target_settings"]))
            self.dropped: dict[str, int] = json.loads(a["dropped"])
            self.config = None
            if "range_bin_width" in a:
                self.config = HeatmapConfig(int(a["num_range_bins"]), int(a["num_elevation_bins"]),
                                            int(a["num_azimuth_bins"]), float(a["range_bin_width"]),
                                            np.asarray(a["azimuth_bins"]),
                                            np.asarray(a["elevation_bins"]))
            self.radar_k = f["radar_frame"][()]
            self.frame_ids = f["frame_id"][()]
            self._times = f["radar_time"][()]
        self._file: Any = None

    def __len__(self) -> int:
        return int(self.radar_k.size)

    def __getstate__(self) -> dict[str, Any]:
        # h5py handles do not pickle: a worker opens the file itself.
        return {k: v for k, v in self.__dict__.items() if k not in ("_file", "_ds", "_small")} | {
            "_file": None}

    def radar_times(self, radar: str) -> np.ndarray:
        return self._times.copy()

    def check(self, radar: str, products: Iterable[str], lidar: bool, targets: bool) -> None:
        """Raise when the file lacks what a view asks for."""
        have = set(self.products)
        missing = [p for p in products if p not in have]
        if radar != self.radar:
            missing.insert(0, f"radar {radar} (the file holds {self.radar})")
        if lidar and not self.lidar:
            missing.append("lidar scans")
        if targets and not self.targets:
            missing.append("lidar targets")
        if missing:
            raise MissingDataError(f"{self.path}: no {', '.join(missing)} in this file (it holds "
                                   f"{', '.join(self.products)}{', lidar' if self.lidar else ''}"
                                   f"{', targets' if self.targets else ''})")

    def calibration(self) -> Any:
        """The :class:`~coloradar.calib.Calibration` stored in the file."""
        f = self._open()
        with tempfile.TemporaryDirectory(prefix="coloradar-calib-") as tmp:
            for rel, text in f["calib"].attrs.items():
                p = Path(tmp) / rel
                p.parent.mkdir(parents=True, exist_ok=True)
                p.write_text(str(text), encoding="utf-8")
            return load_calibration(tmp)

    def _open(self) -> Any:
        if self._file is None:
            f = _h5py().File(self.path, "r")
            # Small per-sample tables are read once; big datasets keep an open handle.
            self._small = {k: f[k][()] for k in self.keys if k in _SCALARS}
            self._small.update({k: f[k]["offsets"][()] for k in self.keys if k in _RAGGED})
            self._ds = {k: (f[k]["data"] if k in _RAGGED else f[k]) for k in self.keys
                        if k != "run" and k not in _SCALARS}
            self._file = f
        return self._file

    def sample(self, k: int, products: Iterable[str], lidar: bool, targets: bool) -> dict[str, Any]:
        """Sample ``k`` with the keys the view asks for, in the order they were written."""
        self._open()
        asked = {*products, *(("lidar",) if lidar else ()), *(("targets",) if targets else ())}
        out: dict[str, Any] = {}
        for key in self.keys:
            if key in _NEEDS and not all(x in asked for x in _NEEDS[key]):
                continue
            if key == "run":
                out[key] = self.name
            elif key in ("radar_frame", "frame_id"):
                out[key] = int(self._small[key][k])
            elif key in _SCALARS:
                out[key] = float(self._small[key][k])
            elif key in _RAGGED:
                o = self._small[key]
                out[key] = self._ds[key][int(o[k]):int(o[k + 1])]
            else:
                out[key] = self._ds[key][k]
        return out
