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

import dataclasses
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
from ..calib import write_calibration
from ..dataset import Sequence, open_sequence
from ..errors import FormatError, MissingDataError, WriteError
from ..formats.atomic import atomic_output, new_output_path
from ..learning.h5_file import _RAGGED, _SCALARS, DESCRIPTIONS, FORMAT, FORMAT_VERSION, H5Run, _h5py
from ..learning.samples import SyncedSamples
from ..learning.targets import TargetSettings
from ..learning.views import ViewOptions

__all__ = ["COMPRESSIONS", "FORMAT", "FORMAT_VERSION", "H5Run", "Hdf5Export", "Hdf5ExportResult",
           "export_hdf5"]

COMPRESSIONS = ("gzip", "lzf", "none")


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


@dataclass(frozen=True)
class Hdf5Export:
    """What :func:`export_hdf5` writes and how: its options (see there)."""

    radar: str = "cascade"
    products: Iterable[str] = ("heatmap", "bev")
    lidar: bool = False
    targets: bool = True
    target_settings: TargetSettings | None = None
    views: ViewOptions | None = None
    compression: str = "gzip"
    compression_level: int = 1
    pose_source: str = "groundtruth"
    calib: Any = None
    overwrite: bool = False
    progress: Callable[[int, int], None] | None = None


def export_hdf5(source: Sequence | str | os.PathLike[str], out: str | os.PathLike[str],
                options: Hdf5Export | None = None, **kw: Any) -> Hdf5ExportResult:
    """Write one run's learning samples to an HDF5 file.

    Parameters
    ----------
    source
        A run (folder, zip or :class:`~coloradar.Sequence`).
    out
        The ``.h5`` file.
    options
        A :class:`Hdf5Export` holding the options below; keywords replace its fields.

    Other Parameters
    ----------------
    radar, products, lidar, targets, target_settings, views, pose_source
        As for :class:`~coloradar.learning.SyncedSamples`.
    compression
        ``"gzip"`` (portable: every HDF5 reader has it), ``"lzf"`` (faster, h5py only) or
        ``"none"``.
    compression_level
        gzip level 1–9 (default 1: about twice as fast to write as level 4 for 2–3 % more
        bytes, benchmarks/bench_learning.py).
    calib
        Calibration for a run given as a path (None: found beside it).
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
    o = dataclasses.replace(options or Hdf5Export(), **kw)
    h5py = _h5py()
    if o.compression not in COMPRESSIONS:
        raise FormatError(f"compression must be one of {', '.join(COMPRESSIONS)}, got "
                          f"{o.compression!r}")
    out = new_output_path(out, o.overwrite)
    t0 = time.perf_counter()
    seq = source if isinstance(source, Sequence) else open_sequence(source, calib=o.calib)
    view = SyncedSamples(seq, radar=o.radar, products=tuple(o.products), lidar=o.lidar,
                         targets=o.targets, target_settings=o.target_settings, views=o.views,
                         pose_source=o.pose_source)
    if len(view) == 0:
        raise MissingDataError(f"{seq.location}: no {o.radar} frame has every partner asked for "
                               f"(left out: {view.dropped})")
    comp: dict[str, Any] = {}
    if o.compression == "gzip":
        comp = {"compression": "gzip", "compression_opts": int(o.compression_level),
                "shuffle": True}
    elif o.compression == "lzf":
        comp = {"compression": "lzf", "shuffle": True}
    if o.progress is not None:
        o.progress(0, len(view))  # said at once: the first sample may fuse the lidar map first
    try:
        with atomic_output(out) as tmp, h5py.File(tmp, "w") as f:
            _write_attributes(f, seq, view, o)
            shapes = _write_samples(f, view, comp, o.progress)
    except OSError as exc:
        if isinstance(exc, WriteError):
            raise
        raise WriteError(f"{out}: cannot write the HDF5 file ({exc})") from exc
    return Hdf5ExportResult(out, len(view), out.stat().st_size, time.perf_counter() - t0, shapes,
                            dict(view.dropped))


def _write_attributes(f: Any, seq: Sequence, view: SyncedSamples, o: Hdf5Export) -> None:
    """The root attributes (what the file holds and how it was made) and the /calib group."""
    grid = view.grid
    vopt = view.views
    run = view._runs[0]
    a = f.attrs
    a["format"] = FORMAT
    a["format_version"] = FORMAT_VERSION
    a["coloradar_version"] = __version__
    a["run"] = seq.name
    a["source"] = str(seq.location)
    a["radar"] = o.radar
    a["products"] = json.dumps(list(view.products))
    a["lidar"] = bool(o.lidar)
    a["targets"] = bool(o.targets)
    a["pose_source"] = o.pose_source
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


def _create_datasets(f: Any, s: dict[str, Any], n: int, comp: dict[str, Any]
                     ) -> tuple[list[str], dict[str, list[Any]], dict[str, list[int]]]:
    """Datasets for the keys of the first sample ``s``: ``(keys, scalar lists, ragged offsets)``."""
    keys = [k for k in s if k != "run"]
    scalars: dict[str, list[Any]] = {}
    offsets: dict[str, list[int]] = {}
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
    return keys, scalars, offsets


def _write_samples(f: Any, view: SyncedSamples, comp: dict[str, Any],
                   progress: Callable[[int, int], None] | None) -> dict[str, tuple[int, ...]]:
    """Every sample of ``view``; returns dataset name -> shape."""
    n = len(view)
    scalars: dict[str, list[Any]] = {}
    offsets: dict[str, list[int]] = {}
    keys: list[str] = []
    for i in range(n):
        s = view[i]
        if i == 0:
            keys, scalars, offsets = _create_datasets(f, s, n, comp)
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
    f.attrs["sample_keys"] = json.dumps(["run", *keys])
    f.attrs["num_samples"] = n
    return {k: tuple(f[k]["data"].shape if k in offsets else f[k].shape) for k in keys}
