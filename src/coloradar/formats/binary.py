"""Binary data files of ColoRadar: ADC frames, heatmaps, radar and lidar point clouds.

All are little-endian with no header (docs/conventions.md §1). Decoders take the raw bytes so that folders
and zips share one code path; ``read_*`` helpers read a path directly.
"""

from __future__ import annotations

import os

import numpy as np

from ..errors import FormatError, SettingsError
from .atomic import atomic_write_bytes
from .source import read_file_bytes

__all__ = [
    "adc_nbytes",
    "decode_adc",
    "decode_heatmap",
    "decode_lidar_pointcloud",
    "decode_radar_pointcloud",
    "encode_adc",
    "encode_heatmap",
    "encode_pointcloud",
    "heatmap_nbytes",
    "read_adc",
    "read_heatmap",
    "read_lidar_pointcloud",
    "read_radar_pointcloud",
    "write_adc",
    "write_heatmap",
    "write_lidar_pointcloud",
    "write_radar_pointcloud",
]

RADAR_POINT_FIELDS = ("x", "y", "z", "intensity", "range_rate")
LIDAR_POINT_FIELDS = ("x", "y", "z", "intensity")


def adc_nbytes(shape: tuple[int, int, int, int]) -> int:
    """Size in bytes of an ADC frame of ``shape = (tx, rx, chirp, sample)``: int16 I and Q."""
    return int(np.prod(shape)) * 2 * 2


def heatmap_nbytes(shape: tuple[int, int, int]) -> int:
    """Size in bytes of a heatmap of ``shape = (el, az, range)``: two float32 channels."""
    return int(np.prod(shape)) * 2 * 4


def _check_size(buf: bytes | memoryview, expected: int, name: str, what: str) -> None:
    if len(buf) != expected:
        raise FormatError(
            f"{name}: {what} should be {expected:,} bytes but the file has {len(buf):,} bytes"
        )


def decode_adc(buf: bytes | memoryview, shape: tuple[int, int, int, int],
               name: str = "<adc frame>") -> np.ndarray:
    """Decode one raw ADC frame.

    Parameters
    ----------
    buf
        The file's bytes: int16 little-endian, value index ``2*(s + Ns*(c + Nc*(r + t*Nr)))``,
        I at even and Q at odd indices.
    shape
        ``(num_tx, num_rx, num_chirps, num_samples)``.
    name
        The file's name, for error messages.

    Returns
    -------
    numpy.ndarray
        complex64, shape ``(tx, rx, chirp, sample)``, in ADC counts.
    """
    _check_size(buf, adc_nbytes(shape), name, f"an ADC frame of shape {tuple(shape)}")
    raw = np.frombuffer(buf, dtype="<i2")
    # int16 pairs -> float32 pairs -> reinterpret as complex64: one conversion pass, no copy loops.
    return raw.astype(np.float32).view(np.complex64).reshape(shape)


def encode_adc(adc: np.ndarray) -> bytes:
    """Encode a complex ``(tx, rx, chirp, sample)`` frame as int16 I/Q (values rounded, clipped)."""
    adc = np.asarray(adc)
    if adc.ndim != 4 or not np.iscomplexobj(adc):
        raise SettingsError(f"expected a complex (tx, rx, chirp, sample) array, got {adc.dtype} {adc.shape}")
    iq = np.empty((*adc.shape, 2), dtype=np.float32)
    iq[..., 0] = adc.real
    iq[..., 1] = adc.imag
    return np.clip(np.rint(iq), -32768, 32767).astype("<i2").tobytes()


def decode_heatmap(buf: bytes | memoryview, shape: tuple[int, int, int],
                   name: str = "<heatmap>") -> np.ndarray:
    """Decode a heatmap file to float32 ``(el, az, range, 2)``.

    Channel 0 is the peak intensity over Doppler, channel 1 the range rate of that peak in m/s.
    """
    _check_size(buf, heatmap_nbytes(shape), name, f"a heatmap of shape {tuple(shape)}x2")
    return np.frombuffer(buf, dtype="<f4").reshape((*tuple(shape), 2)).astype(np.float32)


def encode_heatmap(heatmap: np.ndarray) -> bytes:
    """Encode a float ``(el, az, range, 2)`` heatmap."""
    heatmap = np.asarray(heatmap)
    if heatmap.ndim != 4 or heatmap.shape[-1] != 2:
        raise SettingsError(f"expected an (el, az, range, 2) array, got shape {heatmap.shape}")
    return np.ascontiguousarray(heatmap, dtype="<f4").tobytes()


def _decode_points(buf: bytes | memoryview, ncols: int, name: str, what: str) -> np.ndarray:
    rowbytes = 4 * ncols
    if len(buf) % rowbytes:
        raise FormatError(
            f"{name}: a {what} is N x {ncols} float32 (a multiple of {rowbytes} bytes) but the "
            f"file has {len(buf):,} bytes"
        )
    return np.frombuffer(buf, dtype="<f4").reshape(-1, ncols).astype(np.float32)


def decode_radar_pointcloud(buf: bytes | memoryview, name: str = "<radar pointcloud>") -> np.ndarray:
    """Decode a radar point cloud: float32 ``(N, 5)`` x y z [m] intensity range_rate [m/s]."""
    return _decode_points(buf, 5, name, "radar point cloud")


def decode_lidar_pointcloud(buf: bytes | memoryview, name: str = "<lidar pointcloud>") -> np.ndarray:
    """Decode a lidar point cloud: float32 ``(N, 4)`` x y z [m] intensity."""
    return _decode_points(buf, 4, name, "lidar point cloud")


def encode_pointcloud(points: np.ndarray, ncols: int) -> bytes:
    """Encode an ``(N, ncols)`` point cloud as float32 rows."""
    points = np.asarray(points)
    if points.ndim != 2 or points.shape[1] != ncols:
        raise SettingsError(f"expected an (N, {ncols}) array, got shape {points.shape}")
    return np.ascontiguousarray(points, dtype="<f4").tobytes()


def _read(path: str | os.PathLike[str]) -> bytes:
    return read_file_bytes(path)


def read_adc(path: str | os.PathLike[str], shape: tuple[int, int, int, int]) -> np.ndarray:
    """Read an ADC frame file; see :func:`decode_adc`."""
    return decode_adc(_read(path), shape, str(path))


def read_heatmap(path: str | os.PathLike[str], shape: tuple[int, int, int]) -> np.ndarray:
    """Read a heatmap file; see :func:`decode_heatmap`."""
    return decode_heatmap(_read(path), shape, str(path))


def read_radar_pointcloud(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a radar point cloud file; see :func:`decode_radar_pointcloud`."""
    return decode_radar_pointcloud(_read(path), str(path))


def read_lidar_pointcloud(path: str | os.PathLike[str]) -> np.ndarray:
    """Read a lidar point cloud file; see :func:`decode_lidar_pointcloud`."""
    return decode_lidar_pointcloud(_read(path), str(path))


def write_adc(path: str | os.PathLike[str], adc: np.ndarray) -> None:
    """Write an ADC frame atomically; see :func:`encode_adc`."""
    atomic_write_bytes(path, encode_adc(adc))


def write_heatmap(path: str | os.PathLike[str], heatmap: np.ndarray) -> None:
    """Write a heatmap atomically; see :func:`encode_heatmap`."""
    atomic_write_bytes(path, encode_heatmap(heatmap))


def write_radar_pointcloud(path: str | os.PathLike[str], points: np.ndarray) -> None:
    """Write an ``(N, 5)`` radar point cloud atomically."""
    atomic_write_bytes(path, encode_pointcloud(points, 5))


def write_lidar_pointcloud(path: str | os.PathLike[str], points: np.ndarray) -> None:
    """Write an ``(N, 4)`` lidar point cloud atomically."""
    atomic_write_bytes(path, encode_pointcloud(points, 4))
