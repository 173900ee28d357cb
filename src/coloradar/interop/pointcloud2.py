"""``sensor_msgs/PointCloud2`` payloads <-> numpy point arrays, without ROS.

A PointCloud2 message carries its points as one byte buffer described by ``fields`` (name,
byte offset, datatype, count), ``point_step`` (bytes per point), ``row_step`` (bytes per row)
and ``is_bigendian``. These functions build and read that buffer with one structured numpy
view: no per-point Python. The datatype numbers are those of ``sensor_msgs/PointField``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..errors import FormatError, SettingsError

__all__ = ["POINTFIELD_DTYPES", "CloudLayout", "decode_cloud", "encode_cloud"]

POINTFIELD_DTYPES: dict[int, str] = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4",
                                     7: "f4", 8: "f8"}
"""``sensor_msgs/PointField`` datatype constant -> numpy type code (INT8 … FLOAT64)."""

FLOAT32 = 7


@dataclass(frozen=True)
class CloudLayout:
    """The geometry of a PointCloud2 buffer (the message fields other than ``data``).

    Attributes
    ----------
    names, offsets, datatypes, counts
        One entry per ``PointField``.
    point_step, row_step
        Bytes per point and per row.
    height, width
        Rows and points per row (``height == 1`` for an unorganised cloud).
    is_bigendian
        Byte order of the values.
    """

    names: tuple[str, ...]
    offsets: tuple[int, ...]
    datatypes: tuple[int, ...]
    counts: tuple[int, ...]
    point_step: int
    row_step: int
    height: int
    width: int
    is_bigendian: bool = False


def encode_cloud(points: np.ndarray, names: tuple[str, ...]) -> tuple[CloudLayout, np.ndarray]:
    """The PointCloud2 layout and ``data`` bytes of an ``(N, C)`` float point array.

    Parameters
    ----------
    points
        float ``(N, C)``; each column becomes one little-endian FLOAT32 field.
    names
        ``C`` field names (``x y z intensity doppler`` for a radar, ``x y z intensity`` for lidar).

    Returns
    -------
    (CloudLayout, numpy.ndarray)
        The layout (``height = 1``, ``width = N``, packed 4-byte fields) and the uint8
        ``(N * 4C,)`` buffer.
    """
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1] != len(names):
        raise SettingsError(f"expected points of shape (N, {len(names)}) for fields {names}, "
                         f"got {p.shape}")
    data = np.ascontiguousarray(p, dtype="<f4").reshape(-1).view(np.uint8)
    n, c = p.shape
    layout = CloudLayout(tuple(names), tuple(4 * i for i in range(c)), (FLOAT32,) * c,
                         (1,) * c, 4 * c, 4 * c * n, 1, n, False)
    return layout, data


def decode_cloud(layout: CloudLayout, data: np.ndarray | bytes | memoryview,
                 names: tuple[str, ...], *, aliases: Mapping[str, tuple[str, ...]] | None = None,
                 optional: tuple[str, ...] = (), what: str = "PointCloud2",
                 prefer: Mapping[str, str] | None = None) -> np.ndarray:
    """Read the fields ``names`` of a PointCloud2 buffer as a float32 ``(height·width, len(names))``.

    Parameters
    ----------
    layout
        The message's fields, steps and sizes.
    data
        Its ``data`` bytes.
    names
        Fields wanted, in output column order.
    aliases
        Other field names accepted for a wanted one (e.g. ``doppler`` for ``range_rate``).
    optional
        Wanted fields that may be absent: their column is 0.
    what
        Names the message in errors (topic, time).
    prefer
        ``{wanted name: field name}`` tried before the wanted name and its aliases (a user's
        own naming, e.g. ``{"doppler": "v_doppler_mps"}``).

    Raises
    ------
    FormatError
        A required field is missing, has a count other than 1 or an unknown datatype, or the
        buffer is shorter than the layout says.
    """
    buf = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data
    n = layout.height * layout.width
    if layout.point_step <= 0 and n:
        raise FormatError(f"{what}: point_step {layout.point_step} must be positive")
    need = (layout.height - 1) * layout.row_step + layout.width * layout.point_step if n else 0
    if buf.size < need:
        raise FormatError(f"{what}: {buf.size} data bytes, expected at least {need} "
                          f"({layout.height}x{layout.width} points of {layout.point_step} B)")
    by_name = {nm: i for i, nm in enumerate(layout.names)}
    order = ">" if layout.is_bigendian else "<"
    out = np.zeros((n, len(names)), dtype=np.float32)
    for col, name in enumerate(names):
        first = (prefer[name],) if prefer and name in prefer else ()
        candidates = (*first, name, *((aliases or {}).get(name, ())))
        idx = next((by_name[c] for c in candidates if c in by_name), None)
        if idx is None:
            if name in optional:
                continue
            raise FormatError(f"{what}: no field {' or '.join(candidates)!s} (fields: "
                              f"{', '.join(layout.names) or 'none'})")
        code = POINTFIELD_DTYPES.get(layout.datatypes[idx])
        if code is None or layout.counts[idx] != 1:
            raise FormatError(f"{what}: field {layout.names[idx]!r} has datatype "
                              f"{layout.datatypes[idx]} and count {layout.counts[idx]}; expected "
                              "one value of a PointField type (1-8)")
        dtype = np.dtype(order + code) if code not in ("i1", "u1") else np.dtype(code)
        if n:
            # One strided view per row block: rows may be padded (row_step > width*point_step).
            rows = np.lib.stride_tricks.as_strided(
                buf[layout.offsets[idx]:], shape=(layout.height, layout.width, dtype.itemsize),
                strides=(layout.row_step, layout.point_step, 1), writeable=False)
            out[:, col] = rows.copy().view(dtype).reshape(n)
    return out
