"""Point cloud files: PCD (v0.7, ascii or binary) and PLY (ascii or binary little-endian).

A small writer and reader of the two formats most viewers open (CloudCompare, PCL,
Open3D, MeshLab). Points are written as float32 columns, one named field per column. Writes
are atomic and refuse to replace an existing file unless ``overwrite=True``.
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..errors import FormatError, SettingsError
from ..formats.atomic import atomic_write_bytes, new_output_path
from ..formats.source import read_file_bytes

__all__ = ["check_point_file_name", "default_fields", "read_pcd", "read_ply", "read_point_file",
           "write_pcd", "write_ply", "write_point_file"]

_PCD_TYPES = {("F", 4): "<f4", ("F", 8): "<f8", ("I", 1): "<i1", ("I", 2): "<i2",
              ("I", 4): "<i4", ("I", 8): "<i8", ("U", 1): "<u1", ("U", 2): "<u2",
              ("U", 4): "<u4", ("U", 8): "<u8"}
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
              "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
              "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
              "float64": "f8"}


def default_fields(ncols: int) -> tuple[str, ...]:
    """Field names for an ``(N, ncols)`` ColoRadar cloud: lidar ``x y z intensity``, radar
    ``x y z intensity range_rate``; extra columns are ``f<k>``."""
    names = ("x", "y", "z", "intensity", "range_rate")
    return names[:ncols] + tuple(f"f{k}" for k in range(len(names), ncols))


def _prepare(path: str | os.PathLike[str], points: np.ndarray,
             fields: Sequence[str] | None, overwrite: bool) -> tuple[Path, np.ndarray,
                                                                       tuple[str, ...]]:
    path = new_output_path(path, overwrite)
    p = np.asarray(points)
    if p.ndim != 2 or p.shape[1] < 3:
        raise SettingsError(f"expected points of shape (N, C>=3), got {p.shape}")
    names = tuple(fields) if fields is not None else default_fields(p.shape[1])
    if len(names) != p.shape[1] or any(not n or any(c.isspace() for c in n) for n in names):
        raise SettingsError(f"need {p.shape[1]} field names without spaces, got {names}")
    return path, np.ascontiguousarray(p, dtype="<f4"), names


def _ascii_rows(p: np.ndarray) -> bytes:
    buf = io.StringIO()
    np.savetxt(buf, p, fmt="%.9g")
    return buf.getvalue().encode("ascii")


def write_pcd(path: str | os.PathLike[str], points: np.ndarray,
              fields: Sequence[str] | None = None, *, binary: bool = True,
              overwrite: bool = False) -> Path:
    """Write a PCD v0.7 file (unorganised: ``HEIGHT 1``).

    Parameters
    ----------
    path
        Output file.
    points
        ``(N, C)``, ``C >= 3``, x y z first [m]; stored as float32.
    fields
        Column names; default :func:`default_fields`.
    binary
        ``DATA binary`` (default) or ``DATA ascii``.
    overwrite
        Replace an existing file; otherwise :class:`~coloradar.OutputExistsError`.
    """
    path, p, names = _prepare(path, points, fields, overwrite)
    n, c = p.shape
    header = ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
              f"FIELDS {' '.join(names)}\nSIZE {' '.join(['4'] * c)}\n"
              f"TYPE {' '.join(['F'] * c)}\nCOUNT {' '.join(['1'] * c)}\n"
              f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
              f"DATA {'binary' if binary else 'ascii'}\n").encode("ascii")
    atomic_write_bytes(path, header + (p.tobytes() if binary else _ascii_rows(p)))
    return path


def write_ply(path: str | os.PathLike[str], points: np.ndarray,
              fields: Sequence[str] | None = None, *, binary: bool = True,
              overwrite: bool = False) -> Path:
    """Write a PLY file with one ``vertex`` element of float properties.

    Parameters are those of :func:`write_pcd`; ``binary`` selects
    ``binary_little_endian 1.0`` or ``ascii 1.0``.
    """
    path, p, names = _prepare(path, points, fields, overwrite)
    fmt = "binary_little_endian" if binary else "ascii"
    header = (f"ply\nformat {fmt} 1.0\ncomment written by coloradar\n"
              f"element vertex {p.shape[0]}\n"
              + "".join(f"property float {n}\n" for n in names)
              + "end_header\n").encode("ascii")
    atomic_write_bytes(path, header + (p.tobytes() if binary else _ascii_rows(p)))
    return path


def _split_header(data: bytes, end_marker: bytes, name: str, what: str) -> tuple[list[str], int]:
    lines, pos = [], 0
    while True:
        nl = data.find(b"\n", pos)
        if nl < 0:
            raise FormatError(f"{name}: {what} header has no {end_marker.decode()!r} line")
        line = data[pos:nl].decode("ascii", errors="replace").strip()
        pos = nl + 1
        lines.append(line)
        if line.split()[:1] == [end_marker.decode()]:
            return lines, pos


def _ascii_table(body: bytes, n: int, ncols: int, name: str) -> np.ndarray:
    values = np.array(body.split()[: n * ncols], dtype=np.float64) if n else np.zeros(0)
    if values.size != n * ncols:
        raise FormatError(f"{name}: expected {n} points of {ncols} values, "
                          f"found {values.size} values")
    return values.reshape(n, ncols)


def _to_array(rec: np.ndarray, names: list[str]) -> np.ndarray:
    wide = any(rec.dtype[k].itemsize == 8 and rec.dtype[k].kind == "f" for k in names)
    out = np.empty((rec.shape[0], len(names)), dtype=np.float64 if wide else np.float32)
    for j, k in enumerate(names):
        out[:, j] = rec[k]
    return out


def read_pcd(path: str | os.PathLike[str]) -> tuple[np.ndarray, tuple[str, ...]]:
    """Read a PCD file (``DATA ascii`` or ``binary``; ``binary_compressed`` is refused).

    Returns
    -------
    (numpy.ndarray, tuple[str, ...])
        float32 ``(N, C)`` (float64 if a field is 8-byte float) and the field names; fields
        with ``COUNT k > 1`` become ``k`` columns ``name_0 .. name_{k-1}``.
    """
    name = str(path)
    data = read_file_bytes(path)
    lines, pos = _split_header(data, b"DATA", name, "PCD")
    hdr = {ln.split()[0].upper(): ln.split()[1:] for ln in lines
           if ln and not ln.startswith("#")}
    try:
        fields, sizes, types = hdr["FIELDS"], [int(s) for s in hdr["SIZE"]], hdr["TYPE"]
        counts = [int(s) for s in hdr.get("COUNT", ["1"] * len(fields))]
        n = int(hdr["POINTS"][0]) if "POINTS" in hdr else (int(hdr["WIDTH"][0])
                                                           * int(hdr["HEIGHT"][0]))
        mode = hdr["DATA"][0].lower()
    except (KeyError, IndexError, ValueError):
        raise FormatError(f"{name}: PCD header lacks FIELDS/SIZE/TYPE/POINTS/DATA") from None
    if not len(fields) == len(sizes) == len(types) == len(counts):
        raise FormatError(f"{name}: PCD FIELDS, SIZE, TYPE and COUNT differ in length")
    cols, dts = [], []
    for f, s, t, k in zip(fields, sizes, types, counts, strict=True):
        dt = _PCD_TYPES.get((t.upper(), s))
        if dt is None:
            raise FormatError(f"{name}: PCD field {f!r} has unsupported TYPE {t} SIZE {s}")
        sub = [f] if k == 1 else [f"{f}_{i}" for i in range(k)]
        cols += sub
        dts += [(c, dt) for c in sub]
    body = data[pos:]
    if mode == "ascii":
        return _ascii_table(body, n, len(cols), name).astype(
            np.float64 if any(d[1] == "<f8" for d in dts) else np.float32), tuple(cols)
    if mode != "binary":
        raise FormatError(f"{name}: PCD DATA {mode} is not supported (ascii or binary only)")
    rec_dt = np.dtype(dts)
    if len(body) < n * rec_dt.itemsize:
        raise FormatError(f"{name}: PCD body has {len(body):,} bytes, expected "
                          f"{n * rec_dt.itemsize:,} for {n} points")
    rec = np.frombuffer(body, dtype=rec_dt, count=n)
    return _to_array(rec, cols), tuple(cols)


def read_ply(path: str | os.PathLike[str]) -> tuple[np.ndarray, tuple[str, ...]]:
    """Read the ``vertex`` element of a PLY file (ascii or binary little-endian).

    The vertex element must come first (as every point-cloud writer puts it); its scalar
    properties become the columns. Returns ``(points, field names)`` as :func:`read_pcd`.
    """
    name = str(path)
    data = read_file_bytes(path)
    lines, pos = _split_header(data, b"end_header", name, "PLY")
    if not lines or lines[0] != "ply":
        raise FormatError(f"{name}: not a PLY file (no 'ply' magic line)")
    fmt, n, props, element = None, 0, [], None
    for ln in lines[1:]:
        parts = ln.split()
        if not parts or parts[0] in ("comment", "obj_info"):
            continue
        if parts[0] == "format":
            fmt = parts[1]
        elif parts[0] == "element":
            if element == "vertex":
                break  # later elements are not needed
            element, n = parts[1], int(parts[2])
            if element != "vertex":
                raise FormatError(f"{name}: PLY element {element!r} precedes 'vertex'")
        elif parts[0] == "property" and element == "vertex":
            if parts[1] == "list":
                raise FormatError(f"{name}: list property in the vertex element")
            if parts[1] not in _PLY_TYPES:
                raise FormatError(f"{name}: unknown PLY property type {parts[1]!r}")
            props.append((parts[2], _PLY_TYPES[parts[1]]))
    if element != "vertex" or not props:
        raise FormatError(f"{name}: PLY file has no vertex element with properties")
    cols = [p[0] for p in props]
    body = data[pos:]
    if fmt == "ascii":
        wide = any(p[1] == "f8" for p in props)
        return (_ascii_table(body, n, len(cols), name).astype(np.float64 if wide
                                                               else np.float32), tuple(cols))
    if fmt != "binary_little_endian":
        raise FormatError(f"{name}: PLY format {fmt} is not supported "
                          "(ascii or binary_little_endian)")
    rec_dt = np.dtype([(c, "<" + t) for c, t in props])
    if len(body) < n * rec_dt.itemsize:
        raise FormatError(f"{name}: PLY body has {len(body):,} bytes, expected at least "
                          f"{n * rec_dt.itemsize:,} for {n} vertices")
    return _to_array(np.frombuffer(body, dtype=rec_dt, count=n), cols), tuple(cols)


def write_point_file(path: str | os.PathLike[str], points: np.ndarray,
                     fields: Sequence[str] | None = None, *, binary: bool = True,
                     overwrite: bool = False) -> Path:
    """:func:`write_pcd` or :func:`write_ply` by the file's suffix (``.pcd``, ``.ply``)."""
    suffix = check_point_file_name(path).suffix.lower()
    if suffix == ".pcd":
        return write_pcd(path, points, fields, binary=binary, overwrite=overwrite)
    return write_ply(path, points, fields, binary=binary, overwrite=overwrite)


def check_point_file_name(path: str | os.PathLike[str]) -> Path:
    """``path`` as a :class:`~pathlib.Path` after checking that it names a point file this
    module writes (``.pcd`` or ``.ply``): a check to make before a long computation.

    Raises
    ------
    FormatError
        For any other suffix.
    """
    p = Path(path)
    if p.suffix.lower() not in (".pcd", ".ply"):
        raise FormatError(f"{p}: expected a .pcd or .ply file name")
    return p


def read_point_file(path: str | os.PathLike[str]) -> tuple[np.ndarray, tuple[str, ...]]:
    """:func:`read_pcd` or :func:`read_ply` by the file's suffix."""
    suffix = Path(path).suffix.lower()
    if suffix == ".pcd":
        return read_pcd(path)
    if suffix == ".ply":
        return read_ply(path)
    raise FormatError(f"{path}: expected a .pcd or .ply file name")
