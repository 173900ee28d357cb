"""Where processed products go, and which of their frames are complete on disk.

One run's output (``OUT`` for ``coloradar process RUN``, ``OUT/<run name>`` for a dataset)::

    <out>/process_manifest.json                      settings of what is there (manifest.py)
    <out>/<radar>/heatmaps/{timestamps.txt, heatmap_cfg.txt, data/heatmap_<i>.bin}
    <out>/<radar>/pointclouds/{timestamps.txt, data/radar_pointcloud_<i>.bin}

A frame's product file is **valid** when it has the size its kind requires: a heatmap exactly
``el × az × range × 2`` float32 values of the processor's grid, a point cloud a whole number
of 5-float32 rows (an empty cloud is a valid, empty file). A frame is **complete** when every
requested product has a valid file. Files are only ever written atomically, so a file with a
final name was written whole; the size check also catches files damaged afterwards.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ..formats.layout import COLORADAR, PROCESS_PRODUCTS
from ..formats.text import format_timestamps

__all__ = [
    "PRODUCTS",
    "clean_partial_files",
    "frame_file",
    "is_valid_size",
    "output_paths",
    "product_has_output",
    "remove_product_output",
    "timestamps_text",
    "valid_frames",
]

PRODUCTS = PROCESS_PRODUCTS
"""Products ``coloradar process`` can write."""

# Output is laid out as a ColoRadar run (coloradar.formats.layout.COLORADAR), so that
# ``open_sequence`` reads it back; both radars name their product files alike.
PREFIX = {p: COLORADAR.frame(f"cascade/{p}").prefix for p in PRODUCTS}
POINT_BYTES = 5 * 4
_FRAME_RE = re.compile(r"^(?P<prefix>[a-z_]+)_(?P<num>\d+)\.bin$")
# atomic_write_bytes's temporary names: ".<final name>.<random>.tmp"
_PARTIAL_RE = re.compile(r"^\..+\.tmp$")


def output_paths(out: str | os.PathLike, radar: str, product: str) -> tuple[Path, Path]:
    """``(product folder, data folder)`` of one radar's product under ``out``."""
    st = COLORADAR.frame(f"{radar}/{product}")
    return Path(out) / st.folder, Path(out) / st.data


def frame_file(out: str | os.PathLike, radar: str, product: str, frame_id: int) -> Path:
    """The file of frame number ``frame_id`` of a product (named like the dataset's own)."""
    return Path(out) / COLORADAR.frame(f"{radar}/{product}").frame_path(frame_id)


def is_valid_size(product: str, size: int, heatmap_bytes: int) -> bool:
    """Whether a product file of ``size`` bytes can be complete (see the module notes)."""
    if product == "heatmaps":
        return size == heatmap_bytes
    return size % POINT_BYTES == 0


def _frame_files(data: Path, product: str) -> Iterable[tuple[int, os.DirEntry]]:
    try:
        entries = list(os.scandir(data))
    except FileNotFoundError:
        return
    for e in entries:
        m = _FRAME_RE.match(e.name)
        if m and m["prefix"] == PREFIX[product]:
            yield int(m["num"]), e


def valid_frames(out: str | os.PathLike, radar: str, product: str,
                 heatmap_bytes: int) -> set[int]:
    """Frame numbers whose ``product`` file exists under ``out`` with a valid size."""
    data = output_paths(out, radar, product)[1]
    ok = set()
    for num, e in _frame_files(data, product):
        try:
            if e.is_file() and is_valid_size(product, e.stat().st_size, heatmap_bytes):
                ok.add(num)
        except FileNotFoundError:   # removed meanwhile
            continue
    return ok


def product_has_output(out: str | os.PathLike, radar: str, product: str) -> bool:
    """Whether a product folder holds anything of ours (frame files or a timestamps file)."""
    folder, data = output_paths(out, radar, product)
    if (folder / "timestamps.txt").exists() or (folder / "heatmap_cfg.txt").exists():
        return True
    return next(iter(_frame_files(data, product)), None) is not None


def remove_product_output(out: str | os.PathLike, radar: str, product: str) -> int:
    """Delete a product's frame files and its timestamps/heatmap_cfg (``--overwrite``).

    Only files named as this product's own are touched; anything else in the folder stays.
    Returns the number of files removed.
    """
    folder, data = output_paths(out, radar, product)
    n = 0
    for _num, e in _frame_files(data, product):
        os.unlink(e.path)
        n += 1
    for name in ("timestamps.txt", "heatmap_cfg.txt"):
        try:
            (folder / name).unlink()
            n += 1
        except FileNotFoundError:
            pass
    return n


def clean_partial_files(folders: Iterable[Path], name: str | None = None) -> int:
    """Delete temporary files of interrupted atomic writes (``.<name>.<random>.tmp``) directly
    inside ``folders`` (only those of file ``name`` when given); returns how many."""
    n = 0
    for folder in folders:
        try:
            entries = list(os.scandir(folder))
        except FileNotFoundError:
            continue
        for e in entries:
            if (_PARTIAL_RE.match(e.name) and e.is_file()
                    and (name is None or e.name.startswith(f".{name}."))):
                try:
                    os.unlink(e.path)
                    n += 1
                except FileNotFoundError:
                    pass
    return n


def timestamps_text(frame_ids: np.ndarray, timestamps: np.ndarray, written: np.ndarray) -> str:
    """Timestamps file for the frames ``written`` of a stream with these frames.

    Readers pair line ``j`` with frame ``base + j``, ``base`` being 1 when the first file is
    number 1 and 0 otherwise (``docs/layout.md``), so the lines run from that base to the last
    written frame; frames without an ADC timestamp read ``nan``.

    Parameters
    ----------
    frame_ids, timestamps
        int ``(N,)`` file numbers and float64 ``(N,)`` times [s] of the ADC stream.
    written
        int ``(M,)`` file numbers that have output files.
    """
    if written.size == 0:
        return ""
    base = 1 if written.min() == 1 else 0
    last = int(written.max())
    lines = np.full(last - base + 1, np.nan)
    keep = (frame_ids >= base) & (frame_ids <= last)
    lines[frame_ids[keep] - base] = timestamps[keep]
    return format_timestamps(lines)
