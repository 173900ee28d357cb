"""Reading the HDF5 learning files that ``coloradar export RUN OUT.h5 --format hdf5`` writes
(:func:`coloradar.interop.hdf5.export_hdf5`; ``h5py``, optional extra ``hdf5``).

The file's layout is described in :mod:`coloradar.interop.hdf5`; its format name, version and
the kinds of its datasets are defined here, below both the writer and
:class:`~coloradar.learning.SyncedSamples` (which opens such files through :class:`H5Run`).
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from ..calib import HeatmapConfig, load_calibration
from ..errors import FormatError, MissingDataError, MissingDependencyError, ReadError
from .targets import TargetSettings
from .views import BevGrid, ViewOptions

__all__ = ["DESCRIPTIONS", "FORMAT", "FORMAT_VERSION", "H5Run"]

FORMAT = "coloradar-learning"
FORMAT_VERSION = 1

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
