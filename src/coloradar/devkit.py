"""The original ColoRadar devkit's functions, on top of coloradar's readers.

Code written for the devkit's ``dataset_loaders.py`` (github.com/arpg/ColoRadar_tools, ``python/``;
function list and return conventions as documented in its README) runs unchanged with
``from coloradar import devkit as dataset_loaders``: the same names, arguments and returned
structures (dicts of parameters, lists of dicts for IMU and poses, float64 / complex128 arrays
in the devkit's shapes, ``index`` = the number in the frame file's name). Underneath, every
call goes through :func:`coloradar.open_sequence` and :func:`coloradar.load_calibration`, so
it also reads zipped runs, checks file sizes, accepts frames numbered from 0 or 1 and corrects
the known calibration defects (with a warning).

Differences, on purpose (``docs/interop.md`` has the migration table):

- a missing file or frame raises :class:`coloradar.MissingDataError` (the devkit printed a
  message and returned None);
- waveform values are the corrected ones (cascade ``adc_start_time`` and ``ramp_end_time`` in
  seconds), heatmap angle lists are the file's, antenna positions are floats;
- the cascade ``coupling`` entry holds the coupling calibration when the calib folder has one
  (the devkit left it empty);
- every ``get_*_params`` dict also carries the parsed :class:`~coloradar.Calibration` under
  ``"_calibration"``, which the readers use to size frames.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from .calib import (
    AntennaConfig,
    Calibration,
    CouplingCalib,
    HeatmapConfig,
    PhaseFrequencyCalib,
    WaveformConfig,
    load_calibration,
    parse_antenna_cfg,
    parse_coupling_calib,
    parse_heatmap_cfg,
    parse_phase_frequency_calib,
    parse_transform,
    parse_waveform_cfg,
)
from .dataset import FrameStream, Sequence, open_sequence
from .errors import MissingDataError, SettingsError
from .formats.layout import LAYOUTS
from .formats.source import read_file_text

__all__ = [
    "get_adc_frame",
    "get_cascade_params",
    "get_groundtruth",
    "get_groundtruth_params",
    "get_heatmap",
    "get_imu",
    "get_imu_params",
    "get_lidar_params",
    "get_pointcloud",
    "get_single_chip_params",
    "get_timestamps",
    "get_vicon",
    "get_vicon_params",
    "read_antenna_cfg",
    "read_coupling_cfg",
    "read_heatmap_cfg",
    "read_phase_freq_calib",
    "read_tf_file",
    "read_waveform_cfg",
]

PathLike = str | os.PathLike[str]
Params = dict[str, Any]

_CACHE: dict[tuple[str, int], tuple[tuple, Sequence, Calibration | None]] = {}


def _run_state(run: Path) -> tuple:
    """What changes when frames are added to, removed from or re-stamped in a run: the
    modification time and size of the run folder, of each stream's timestamps file and data
    folder (a folder's time changes when a file is added or removed), and of each table; or
    of the zip. A few dozen ``stat`` calls, no listing, so every devkit call can afford it."""
    def st(path: Path) -> tuple[int, int] | None:
        try:
            info = path.stat()
        except OSError:
            return None
        return info.st_mtime_ns, info.st_size

    if not run.is_dir():
        return (st(run),)
    rels = {""}
    for layout in LAYOUTS.values():
        for fl in layout.frames.values():
            rels.update((fl.timestamps_path, fl.data, *fl.alt_data))
        for tl in layout.tables.values():
            rels.update((tl.path, tl.timestamps_path))
    return tuple((rel, st(run / rel)) for rel in sorted(rels))


def _sequence(seq_dir: PathLike, params: Params | None) -> Sequence:
    calib = (params or {}).get("_calibration")
    path = Path(seq_dir).resolve()
    key = (str(path), id(calib))
    state = _run_state(path)
    hit = _CACHE.get(key)
    # Keyed by path and calibration, kept only while the run's files are as they were when it
    # was opened: frames written (or removed) since are seen by the next call.
    if hit is None or hit[0] != state:
        _CACHE.pop(key, None)
        if len(_CACHE) >= 16:
            _CACHE.pop(next(iter(_CACHE)))
        # The calibration is kept with the sequence so that its id stays valid as a key.
        _CACHE[key] = (state, open_sequence(seq_dir, calib=calib), calib)
    return _CACHE[key][1]


def _read(text_path: PathLike) -> tuple[str, str]:
    p = Path(text_path)
    return read_file_text(p), str(p)  # MissingDataError, or ReadError for a FIFO, a folder...


def _frame(stream: FrameStream, index: int, seq_dir: PathLike) -> np.ndarray:
    """Frame whose file is numbered ``index`` (the devkit's convention)."""
    hits = np.flatnonzero(stream.frame_ids == int(index))
    if hits.size == 0:
        ids = stream.frame_ids
        span = f"{ids[0]}..{ids[-1]}" if ids.size else "none"
        raise MissingDataError(f"{seq_dir}: no {stream.name} frame numbered {index} "
                               f"(frames {span})")
    return stream[int(hits[0])]


# -- calibration files ------------------------------------------------------------------------
def read_tf_file(filename: PathLike) -> tuple[list[float], list[float]]:
    """Translation ``[x, y, z]`` and rotation ``[x, y, z, w]`` of a ``base_to_<sensor>.txt``."""
    text, name = _read(filename)
    e = parse_transform(text, name)
    return [float(v) for v in e.translation], [float(v) for v in e.quaternion]


def _waveform_dict(w: WaveformConfig) -> Params:
    return {"num_rx": w.num_rx, "num_tx": w.num_tx, "num_adc_samples_per_chirp": w.num_samples,
            "num_chirps_per_frame": w.num_chirps, "adc_sample_frequency": w.sample_rate,
            "start_frequency": w.start_frequency, "idle_time": w.idle_time,
            "adc_start_time": w.adc_start_time, "ramp_end_time": w.ramp_end_time,
            "frequency_slope": w.slope}


def _heatmap_dict(h: HeatmapConfig) -> Params:
    return {"num_range_bins": h.num_range_bins, "num_elevation_bins": h.num_elevation_bins,
            "num_azimuth_bins": h.num_azimuth_bins, "range_bin_width": h.range_bin_width,
            "azimuth_bins": [float(a) for a in h.azimuth_bins],
            "elevation_bins": [float(e) for e in h.elevation_bins]}


def _antenna_dict(a: AntennaConfig) -> Params:
    return {"num_rx": a.num_rx, "num_tx": a.num_tx, "F_design": a.design_frequency / 1e9,
            "rx_locations": [tuple(float(v) for v in row) for row in a.rx_positions],
            "tx_locations": [tuple(float(v) for v in row) for row in a.tx_positions]}


def _coupling_dict(c: CouplingCalib | None) -> Params:
    if c is None:
        return {}
    return {"num_tx": c.num_tx, "num_rx": c.num_rx, "num_range_bins": c.num_range_bins,
            "num_doppler_bins": c.num_doppler_bins, "data": c.data.astype(np.complex128)}


def read_antenna_cfg(filename: PathLike) -> Params:
    """``antenna_cfg.txt`` as the devkit's dict: num_rx, num_tx, F_design [GHz],
    rx_locations / tx_locations (lists of ``(az, el)`` in half wavelengths, by index)."""
    text, name = _read(filename)
    return _antenna_dict(parse_antenna_cfg(text, name))


def read_heatmap_cfg(hm_filename: PathLike, hm_params: Params) -> Params:
    """Add ``heatmap_cfg.txt``'s values (and ``data_type='heatmap'``) to ``hm_params``; return it."""
    text, name = _read(hm_filename)
    hm_params["data_type"] = "heatmap"
    hm_params.update(_heatmap_dict(parse_heatmap_cfg(text, name)))
    return hm_params


def read_waveform_cfg(wave_filename: PathLike, wave_params: Params) -> Params:
    """Add ``waveform_cfg.txt``'s values (unit defects corrected, with a warning) and
    ``data_type='adc_samples'`` to ``wave_params``; return it."""
    text, name = _read(wave_filename)
    wave_params["data_type"] = "adc_samples"
    wave_params.update(_waveform_dict(parse_waveform_cfg(text, name)))
    return wave_params


def read_coupling_cfg(coupling_filename: PathLike) -> Params:
    """``coupling_calib.txt``: num_tx, num_rx, num_range_bins, num_doppler_bins and ``data``
    complex128 ``(tx, rx, range)``."""
    text, name = _read(coupling_filename)
    return _coupling_dict(parse_coupling_calib(text, name))


def read_phase_freq_calib(calib_filename: PathLike) -> tuple[Params, Params]:
    """``phase_frequency_calib.txt`` as the devkit's ``(phase_calib, freq_calib)`` dicts:
    ``cal_matrix`` complex128 ``(tx, rx)`` and float64 ``(tx, rx)``."""
    text, name = _read(calib_filename)
    pf = parse_phase_frequency_calib(text, name)
    return _phase_frequency_dicts(pf)


def _phase_frequency_dicts(pf: PhaseFrequencyCalib | None) -> tuple[Params, Params]:
    if pf is None:
        return {}, {}
    phase = {"num_rx": pf.num_rx, "num_tx": pf.num_tx, "cal_matrix": np.array(pf.phase)}
    freq = {"num_rx": pf.num_rx, "num_tx": pf.num_tx, "frequency_slope": pf.slope,
            "sampling_rate": pf.sample_rate, "cal_matrix": np.array(pf.frequency)}
    return phase, freq


# -- sensor parameters ------------------------------------------------------------------------
def _transform(calib: Calibration, sensor: str) -> tuple[list[float], list[float]]:
    e = calib.transforms.get(sensor)
    if e is None:
        raise MissingDataError(f"calibration {calib.source}: no base_to_{sensor}.txt transform")
    return [float(v) for v in e.translation], [float(v) for v in e.quaternion]


def _sensor_params(calib_dir: PathLike, sensor: str, **extra: Any) -> Params:
    calib = load_calibration(calib_dir)
    t, r = _transform(calib, sensor)
    return {"sensor_type": sensor, **extra, "translation": t, "rotation": r, "_calibration": calib}


def get_lidar_params(calib_dir: PathLike) -> Params:
    """``{'sensor_type': 'lidar', 'data_type': 'pointcloud', 'translation', 'rotation'}``."""
    return _sensor_params(calib_dir, "lidar", data_type="pointcloud")


def get_imu_params(calib_dir: PathLike) -> Params:
    """``{'sensor_type': 'imu', 'translation', 'rotation'}``."""
    return _sensor_params(calib_dir, "imu")


def get_vicon_params(calib_dir: PathLike) -> Params:
    """``{'sensor_type': 'vicon', 'translation', 'rotation'}``."""
    return _sensor_params(calib_dir, "vicon")


def get_groundtruth_params() -> Params:
    """``{'sensor_type': 'groundtruth', 'data_type': 'pose'}`` (no file is read)."""
    return {"sensor_type": "groundtruth", "data_type": "pose"}


def _radar_params(calib_dir: PathLike, radar: str) -> Params:
    calib = load_calibration(calib_dir)
    rc = calib.radar(radar)
    t, r = _transform(calib, radar)
    common = {"sensor_type": radar, "translation": t, "rotation": r, "_calibration": calib}
    out: Params = {
        "waveform": {**common, "data_type": "adc_samples", **_waveform_dict(rc.waveform)},
        "heatmap": {**common, "data_type": "heatmap", **_heatmap_dict(rc.heatmap)},
        "antenna": _antenna_dict(rc.antenna),
        "coupling": _coupling_dict(rc.coupling),
    }
    if radar == "single_chip":
        out["pointcloud"] = {**common, "data_type": "pointcloud"}
    else:
        out["phase"], out["frequency"] = _phase_frequency_dicts(rc.phase_frequency)
    return out


def get_single_chip_params(calib_dir: PathLike) -> Params:
    """The single-chip radar's ``{'waveform', 'heatmap', 'pointcloud', 'antenna', 'coupling'}``."""
    return _radar_params(calib_dir, "single_chip")


def get_cascade_params(calib_dir: PathLike) -> Params:
    """The cascade radar's ``{'waveform', 'heatmap', 'antenna', 'coupling', 'phase', 'frequency'}``."""
    return _radar_params(calib_dir, "cascade")


# -- data -------------------------------------------------------------------------------------
def _radar_of(params: Params) -> str:
    radar = params.get("sensor_type")
    if radar not in ("cascade", "single_chip"):
        raise SettingsError(f"expected the params of a radar (sensor_type cascade or single_chip), "
                             f"got sensor_type {radar!r}")
    return str(radar)


def get_adc_frame(index: int, seq_dir: PathLike, params: Params) -> np.ndarray:
    """ADC frame numbered ``index``: complex128 ``(num_tx, num_rx, num_chirps_per_frame,
    num_adc_samples_per_chirp)``; ``params`` = ``get_<radar>_params(...)['waveform']``."""
    seq = _sequence(seq_dir, params)
    return _frame(seq.radar(_radar_of(params)).adc, index, seq_dir).astype(np.complex128)


def get_heatmap(index: int, seq_dir: PathLike, params: Params) -> np.ndarray:
    """Heatmap numbered ``index``: float64 ``(el, az, range, 2)`` (peak intensity, range rate
    [m/s]); ``params`` = ``get_<radar>_params(...)['heatmap']``."""
    seq = _sequence(seq_dir, params)
    return _frame(seq.radar(_radar_of(params)).heatmaps, index, seq_dir).astype(np.float64)


def get_pointcloud(index: int, seq_dir: PathLike, params: Params) -> np.ndarray:
    """Point cloud numbered ``index``, float64: lidar ``(N, 4)`` x y z intensity, radar ``(N, 5)``
    x y z intensity doppler; ``params`` = ``get_lidar_params`` or a radar's ``['pointcloud']``."""
    seq = _sequence(seq_dir, params)
    if params.get("sensor_type") == "lidar":
        stream = seq.lidar.pointclouds
    else:
        stream = seq.radar(_radar_of(params)).pointclouds
    return _frame(stream, index, seq_dir).astype(np.float64)


def get_timestamps(seq_dir: PathLike, params: Params) -> list[float]:
    """Timestamps [s] of the stream ``params`` describes (sensor_type, and data_type for radars)."""
    seq = _sequence(seq_dir, params)
    sensor = params.get("sensor_type")
    if sensor == "lidar":
        t = seq.lidar.pointclouds.timestamps
    elif sensor in ("imu", "groundtruth", "vicon"):
        track = getattr(seq, str(sensor))
        if track is None:
            raise MissingDataError(f"{seq_dir}: no {sensor} in this run")
        t = track.timestamps
    else:
        rs = seq.radar(_radar_of(params))
        product = {"adc_samples": "adc", "heatmap": "heatmaps", "pointcloud": "pointclouds"}.get(
            str(params.get("data_type")))
        if product is None:
            raise SettingsError(f"unknown data_type {params.get('data_type')!r}; expected "
                                 "adc_samples, heatmap or pointcloud")
        t = getattr(rs, product).timestamps
    return [float(v) for v in t]


def get_imu(seq_dir: PathLike) -> list[dict[str, list[float]]]:
    """IMU samples as ``[{'accel': [ax, ay, az], 'gyro': [gx, gy, gz]}, ...]`` (m/s², rad/s)."""
    data = _sequence(seq_dir, None).imu.data
    return [{"accel": row[:3].tolist(), "gyro": row[3:].tolist()} for row in data]


def _poses(seq_dir: PathLike, which: str) -> list[dict[str, np.ndarray]]:
    track = getattr(_sequence(seq_dir, None), which)
    if track is None:
        raise MissingDataError(f"{seq_dir}: no {which} poses in this run")
    return [{"position": row[:3].copy(), "orientation": row[3:].copy()} for row in track.poses]


def get_groundtruth(seq_dir: PathLike) -> list[dict[str, np.ndarray]]:
    """Ground-truth poses as ``[{'position': (3,), 'orientation': (4,) x y z w}, ...]``."""
    return _poses(seq_dir, "groundtruth")


def get_vicon(seq_dir: PathLike) -> list[dict[str, np.ndarray]]:
    """Vicon poses, as :func:`get_groundtruth`."""
    return _poses(seq_dir, "vicon")
