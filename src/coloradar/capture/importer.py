"""``import_capture``: a raw TI capture and its configuration become a ColoRadar run.

The run is built in a temporary folder beside ``OUT_RUN`` and renamed into place at the end, so
a failed import leaves nothing half-written; the capture's own folder is only read. The run
holds ``<radar>/adc_samples/{timestamps.txt,data/frame_<i>.bin}`` (``coloradar.formats.layout``)
and its calibration in ``OUT_RUN/calib`` (``waveform_cfg.txt``, ``antenna_cfg.txt``,
``heatmap_cfg.txt`` of the radar, ``transforms/base_to_<radar>.txt``), where ``open_sequence``
looks first; ``capture_import.json`` records what was imported and what was left out.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from ..calib import (
    Extrinsic,
    HeatmapConfig,
    WaveformConfig,
    format_antenna_cfg,
    format_heatmap_cfg,
    format_transform,
    format_waveform_cfg,
    shipped_angle_bins,
)
from ..errors import FormatError, OutputExistsError, ReadError, SettingsError
from ..formats.atomic import atomic_write_bytes, atomic_write_text
from ..formats.binary import encode_adc
from ..formats.layout import COLORADAR
from ..formats.text import format_timestamps
from .boards import Board, get_board, run_antenna
from .config import CaptureConfig, check_config_values, load_config
from .lvds import ByteLayout, decode_dca1000, decode_tda2
from .packets import read_packet_dump
from .tda2 import DEVICES, find_cascade_files, read_idx, timestamp_unit

__all__ = ["MARKER", "CaptureImport", "ImportResult", "import_capture"]

MARKER = "capture_import.json"
"""File at the root of an imported run: what was imported (and the mark ``--overwrite`` needs)."""

CaptureFormat = Literal["auto", "dca1000", "packets", "mmwcas"]


@dataclass(frozen=True)
class CaptureImport:
    """What to import and how (every field is also a keyword of :func:`import_capture`).

    Attributes
    ----------
    config
        The configuration file (``.cfg``, ``*.mmwave.json``, ``*.setup.json``, MMWCAS JSON) or a
        :class:`~coloradar.capture.config.CaptureConfig`.
    board
        Board name or user ``antenna_cfg.txt`` (None: from the configuration's device).
    start_time
        Unix time of the first frame [s] (None: the TDA2's own timestamps when they are Unix
        times, else 0).
    iq_order, lanes
        Override the configuration's I/Q order (``"iq"``/``"qi"``) and LVDS lanes (2/4).
    capture_format
        ``"auto"`` (a folder: MMWCAS; a ``*_Raw_<n>.bin``: packets; else a DCA1000 file),
        ``"dca1000"``, ``"packets"`` or ``"mmwcas"``.
    dropped
        Frames touched by dropped packets: ``"skip"`` (left out: no file, a ``nan`` timestamp
        line) or ``"zero"`` (written as zeros); both reported.
    partial_last_frame
        A capture that ends inside a frame: ``"error"`` (FormatError) or ``"drop"`` (the whole
        frames are imported; the cut one is reported).
    keep_first_frame
        MMWCAS: keep every frame (by default the first frame of a segment is left out, as TI's
        cascade scripts do: docs/capture.md).
    first_frame_skip
        MMWCAS, unless ``keep_first_frame``: leave out the first frame of every segment
        (``"segment"``, TI's processing scripts) or only the recording's first
        (``"recording"``). Frames of later segments left out are holes in the run (no file, a
        ``nan`` timestamp line), reported in ``left_out``.
    overwrite
        Replace an ``OUT_RUN`` written by an earlier import.
    """

    config: str | os.PathLike[str] | CaptureConfig
    board: str | os.PathLike[str] | None = None
    start_time: float | None = None
    iq_order: str | None = None
    lanes: int | None = None
    capture_format: CaptureFormat = "auto"
    dropped: Literal["skip", "zero"] = "skip"
    partial_last_frame: Literal["error", "drop"] = "error"
    keep_first_frame: bool = False
    first_frame_skip: Literal["segment", "recording"] = "segment"
    overwrite: bool = False


@dataclass(frozen=True)
class ImportResult:
    """What :func:`import_capture` wrote.

    Attributes
    ----------
    run_path, radar, board
        The run, its radar folder (``single_chip``/``cascade``), the board's name.
    frames_written
        Frame files written (zero-filled ones included).
    capture_frames
        Frames in the capture (whole and cut).
    left_out, zero_filled
        Capture frame numbers (from 0) not written / written as zeros, with why in ``notes``.
    dropped_packets
        Packets missing from a packet dump.
    layout
        The byte layout read (:meth:`ByteLayout.describe`).
    notes
        One line per thing the user must know (each also in ``capture_import.json``).
    seconds
        Time taken.
    """

    run_path: Path
    radar: str
    board: str
    frames_written: int
    capture_frames: int
    left_out: tuple[int, ...]
    zero_filled: tuple[int, ...]
    dropped_packets: int
    layout: str
    notes: tuple[str, ...] = field(default=())
    seconds: float = 0.0


@dataclass
class _Frames:
    """Frames to write: a generator of ``(first index, complex frames)`` blocks and what the
    reading learnt."""

    count: int                       # whole frames available
    blocks: Iterator[tuple[int, np.ndarray]]
    times: np.ndarray                # float64 (count,) [s]
    bad: dict[int, str]              # frame -> why it is incomplete (dropped packets)
    notes: list[str]
    layout: str
    first: int = 0                   # capture frames before the first imported one
    dropped_packets: int = 0
    skipped: dict[int, str] = field(default_factory=dict)   # frame -> why it is always left out


# ----------------------------------------------------------------------- the capture's size
def _whole_frames(nbytes: int, frame_bytes: int, cfg: CaptureConfig, name: str,
                  partial: str, notes: list[str]) -> int:
    n, rem = divmod(nbytes, frame_bytes)
    what = (f"frames of {cfg.num_samples} samples x {cfg.num_loops} loops x {cfg.num_tx} TX x "
            f"{cfg.num_rx} RX ({cfg.sampling}) = {frame_bytes:,} bytes")
    if cfg.num_frames > 0 and n > cfg.num_frames:
        raise FormatError(f"{name}: {nbytes:,} bytes hold {n} {what}, but {cfg.source} asks for "
                          f"{cfg.num_frames} frames: the configuration disagrees with the file")
    if rem:
        msg = (f"{name}: {nbytes:,} bytes is not a whole number of {what}: frame {n} (from 0) "
               f"has {rem:,} bytes, {frame_bytes - rem:,} bytes short")
        if partial != "drop":
            raise FormatError(msg + "; check the configuration (samples, loops, TX, RX, real or "
                              "complex) or pass --drop-partial-frame to import the whole ones")
        notes.append(msg + "; left out")
    if n == 0:
        raise FormatError(f"{name}: {nbytes:,} bytes, less than one of the configuration's "
                          f"{what}")
    if 0 < cfg.num_frames and n < cfg.num_frames:
        notes.append(f"{name}: {n} whole frames of the {cfg.num_frames} configured (the capture "
                     "stopped early)")
    return n


def _layout(cfg: CaptureConfig, notes: list[str]) -> ByteLayout:
    lanes = cfg.lanes
    if lanes is None:
        lanes = 4 if cfg.interleaved else 2
        notes.append(f"{cfg.source}: no LVDS lane count; read as {lanes} lanes (pass --lanes)")
    interleaved = cfg.interleaved if cfg.interleaved is not None else lanes == 4
    iq = cfg.iq_order
    if iq is None:
        iq = "iq"
        notes.append(f"{cfg.source}: no I/Q order; read as I first (pass --iq-order qi if the "
                     "targets show up mirrored in range)")
    return ByteLayout(lanes, iq, interleaved, cfg.sampling)


def _read_file(path: Path) -> np.ndarray:
    try:
        return np.memmap(path, dtype=np.uint8, mode="r") if path.stat().st_size else \
            np.zeros(0, np.uint8)
    except FileNotFoundError:
        raise ReadError(f"{path}: capture file not found") from None
    except (IsADirectoryError, PermissionError, OSError) as exc:
        raise ReadError(f"{path}: cannot read the capture ({exc})") from None


def _dca_blocks(stream: np.ndarray, n: int, cfg: CaptureConfig, lay: ByteLayout,
                block: int = 32) -> Iterator[tuple[int, np.ndarray]]:
    fb = cfg.frame_nbytes
    for a in range(0, n, block):
        b = min(n, a + block)
        words = np.frombuffer(stream[a * fb:b * fb], dtype="<i2")
        yield a, decode_dca1000(words, cfg, lay)


def _frame_times(n: int, cfg: CaptureConfig, start: float | None, notes: list[str]) -> np.ndarray:
    if start is None:
        notes.append("no --start-time: timestamps count from 0 s at the first frame")
        start = 0.0
    return start + np.arange(n) * cfg.frame_period


def _dca1000_frames(path: Path, cfg: CaptureConfig, spec: CaptureImport, packets: bool
                    ) -> _Frames:
    notes: list[str] = []
    lay = _layout(cfg, notes)
    raw = _read_file(path)
    fb = cfg.frame_nbytes
    bad: dict[int, str] = {}
    dropped = 0
    if packets:
        ps = read_packet_dump(raw, str(path))
        stream, dropped = ps.data, ps.dropped_packets
        for a, b in ps.missing:
            for f in range(a // fb, (b - 1) // fb + 1):
                bad.setdefault(f, f"bytes {a:,}..{b - 1:,} of the stream were in dropped packets")
        if ps.missing:
            notes.append(f"{path}: {dropped} dropped packet{'s' * (dropped != 1)} "
                         f"({len(ps.missing)} gap{'s' * (len(ps.missing) != 1)}) touch frame"
                         f"{'s' * (len(bad) != 1)} {', '.join(map(str, sorted(bad)))}")
    else:
        stream = raw
    n = _whole_frames(stream.size, fb, cfg, str(path), spec.partial_last_frame, notes)
    bad = {f: why for f, why in bad.items() if f < n}
    return _Frames(n, _dca_blocks(stream, n, cfg, lay), _frame_times(n, cfg, spec.start_time,
                                                                     notes),
                   bad, notes, lay.describe(), 0, dropped)


def _device_frames(data: Path, idx: Path, dev_fb: int, cfg: CaptureConfig, d: int,
                   spec: CaptureImport, notes: list[str]) -> tuple[np.ndarray, np.ndarray, int]:
    """One device file's indexed frames (bytes), their timestamps and the bytes after them.

    As TI's reader (``read_ADC_bin_TDA2_separateFiles``) the frame size comes from the
    configuration and the file's first ``numIdx`` frames are read at ``k`` frame sizes; unlike
    it, the index's own sizes and offsets are checked against that size.
    """
    ix = read_idx(idx)
    what = (f"{cfg.source} makes a device's frame {cfg.num_samples} samples x {cfg.num_loops} "
            f"loops x {cfg.num_tx} TX x 4 RX = {dev_fb:,} bytes")
    bad = np.flatnonzero(ix.sizes != dev_fb)
    if bad.size:
        k = int(bad[0])
        raise FormatError(f"{idx}: frame {k} of {data.name} is {int(ix.sizes[k]):,} bytes (the "
                          f"index's size), but {what}: the configuration disagrees with the "
                          "capture")
    want = np.arange(ix.num_frames, dtype=np.int64) * dev_fb
    bad = np.flatnonzero(ix.offsets != want)
    if bad.size:
        k = int(bad[0])
        raise FormatError(f"{idx}: frame {k} of {data.name} lies at byte {int(ix.offsets[k]):,}, "
                          f"but frames of {dev_fb:,} bytes one after another put it at "
                          f"{int(want[k]):,} ({what})")
    raw = _read_file(data)
    need = ix.num_frames * dev_fb
    if raw.size < need:
        # One device's share of a frame: its four RX.
        dev_cfg = replace(cfg, num_frames=0, rx_channels=cfg.rx_channels[4 * d:4 * d + 4])
        n = _whole_frames(raw.size, dev_fb, dev_cfg, str(data), spec.partial_last_frame, notes)
        raise FormatError(f"{data}: {n} whole frames of {dev_fb:,} bytes but {idx.name} "
                          f"indexes {ix.num_frames}: frame {n} is "
                          f"{(n + 1) * dev_fb - raw.size:,} bytes short")
    if ix.data_size != need:
        notes.append(f"{idx}: dataFileSize {ix.data_size:,} bytes, but its {ix.num_frames} "
                     f"frames of {dev_fb:,} bytes are {need:,}; the frames are read")
    return raw[:need], ix.timestamps, raw.size - need


def _first_frames(folder: Path, seg_frames: list[int], spec: CaptureImport, notes: list[str]
                  ) -> tuple[int, dict[int, str]]:
    """Capture frames before the first imported one, and the run frames left out as the first
    of a later segment (``first_frame_skip="segment"``, TI's rule)."""
    total = sum(seg_frames)
    if spec.keep_first_frame:
        return 0, {}
    if spec.first_frame_skip not in ("segment", "recording"):
        raise SettingsError(f"first_frame_skip {spec.first_frame_skip!r}; expected segment or "
                            "recording")
    skipped: dict[int, str] = {}
    if spec.first_frame_skip == "segment":
        starts = np.cumsum([0, *seg_frames[:-1]])
        for k, a in enumerate(starts[1:], start=1):
            skipped[int(a) - 1] = (f"the first frame of segment {k:04d} (TI's cascade scripts "
                                   "skip the first frame of every segment; --first-frame-skip "
                                   "recording keeps it)")
    if total - 1 - len(skipped) <= 0:
        raise FormatError(f"{folder}: {total} frame(s); nothing left after the first of each "
                          "segment, which TI's cascade scripts skip (--keep-first-frame)")
    if spec.first_frame_skip == "segment":
        frames = ", ".join(str(x) for x in [0, *np.cumsum(seg_frames[:-1]).tolist()])
        notes.append(f"{folder}: the first frame of each of its {len(seg_frames)} segment(s) "
                     f"left out (capture frames {frames}), as TI's cascade scripts do "
                     "(--first-frame-skip recording leaves out only the recording's first, "
                     "--keep-first-frame none)")
    else:
        notes.append(f"{folder}: capture frame 0, the recording's first, left out "
                     "(--keep-first-frame keeps it)")
    return 1, skipped


def _tda2_iq(cfg: CaptureConfig, spec: CaptureImport, notes: list[str]) -> str:
    """The I/Q order: the devices' ``iqSwapSel`` (applied by the AWR2243 to its output, which
    the TDA2 records as sent), unless ``--iq-order`` says otherwise."""
    iq = cfg.iq_order or "iq"
    if spec.iq_order is None and iq == "qi":
        notes.append(f"{cfg.source}: iqSwapSel 1: read Q first, as the devices send it "
                     "(mmWaveLink rlDevDataFmtCfg_t); TI's reader, written for its scripts' "
                     "iqSwapSel 0, reads I first: pass --iq-order iq if the targets show up "
                     "mirrored in range")
    return iq


def _tda2_frames(folder: Path, cfg: CaptureConfig, spec: CaptureImport) -> _Frames:
    notes: list[str] = []
    if cfg.num_devices != 4 or cfg.num_rx != 16:
        raise FormatError(f"{folder}: an MMWCAS capture (four devices of 4 RX) but {cfg.source} "
                          f"configures {cfg.num_devices} device(s) with {cfg.num_rx} RX in all")
    iq = _tda2_iq(cfg, spec, notes)
    files = find_cascade_files(folder)
    dev_fb = cfg.frame_nbytes // 4
    arrays: list[list[np.ndarray]] = [[] for _ in DEVICES]
    ticks = []
    trailing = []
    for seg in files.segments:
        counts = []
        for d, dev in enumerate(DEVICES):
            data, idx = seg[dev]
            raw, ts, extra = _device_frames(data, idx, dev_fb, cfg, d, spec, notes)
            counts.append(raw.size // dev_fb)
            arrays[d].append(raw)
            if extra:
                trailing.append(f"{data.name} {extra:,}")
            if d == 0:
                ticks.append(ts)
        if len(set(counts)) != 1:
            raise FormatError(f"{folder}: the devices' files hold different numbers of frames "
                              f"({', '.join(f'{dv} {c}' for dv, c in zip(DEVICES, counts, strict=True))})")
    if trailing:
        notes.append(f"{folder}: bytes after the last indexed frame, not read (preallocated data "
                     f"files; TI's reader reads only the indexed frames): {'; '.join(trailing)}")
    seg_frames = [a.size // dev_fb for a in arrays[0]]       # frames of each segment
    total = sum(seg_frames)
    first, skipped = _first_frames(folder, seg_frames, spec, notes)
    tk = np.concatenate(ticks)
    unit = timestamp_unit(tk, cfg.frame_period)
    secs = tk.astype(np.float64) * unit
    if spec.start_time is not None:
        times = spec.start_time + (secs - secs[first])
    elif 1e9 <= secs[first] <= 4e9:
        times = secs
    else:
        times = secs - secs[first]
        notes.append("no --start-time and the TDA2 timestamps are not Unix times: timestamps "
                     "count from 0 s at the first imported frame")
    notes.append(f"TDA2 timestamps read in units of {unit:g} s (the one matching the configured "
                 f"{cfg.frame_period * 1e3:g} ms frame period)")

    def blocks(block: int = 16) -> Iterator[tuple[int, np.ndarray]]:
        # Segment by segment, straight from the memory-mapped files (no copy of the capture).
        done = 0
        for k, n in enumerate(seg_frames):
            for a in range(max(first - done, 0), n, block):
                b = min(n, a + block)
                words = [np.frombuffer(arrays[d][k][a * dev_fb:b * dev_fb], dtype="<i2")
                         for d in range(len(DEVICES))]
                yield done + a - first, decode_tda2(words, cfg, iq)
            done += n

    return _Frames(total - first, blocks(), times[first:], {}, notes,
                   f"TDA2, 4 devices, complex {iq.upper()}", first, skipped=skipped)


# -------------------------------------------------------------------------------- writing
def _calib_texts(cfg: CaptureConfig, board: Board, radar: str) -> tuple[dict[str, str], WaveformConfig]:
    w = WaveformConfig(
        num_rx=cfg.num_rx, num_tx=cfg.num_tx, num_samples=cfg.num_samples,
        num_chirps=cfg.num_loops, sample_rate=cfg.sample_rate,
        start_frequency=cfg.start_frequency, idle_time=cfg.idle_time,
        adc_start_time=cfg.adc_start_time, ramp_end_time=cfg.ramp_end_time, slope=cfg.slope)
    ant = run_antenna(board, cfg.tx_slots, cfg.rx_channels, cfg.source)
    # Complex samples give Ns unambiguous range bins, real ones Ns/2 (the rest is the mirror).
    n_range = cfg.num_samples if cfg.sampling == "complex" else cfg.num_samples // 2
    n_el, n_az = (32, 128) if radar == "cascade" else (16, 64)
    grid = HeatmapConfig(n_range, n_el, n_az, w.range_bin_width, shipped_angle_bins(n_az),
                         shipped_angle_bins(n_el))
    ident = Extrinsic(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))
    return {
        f"calib/{radar}/waveform_cfg.txt": format_waveform_cfg(w),
        f"calib/{radar}/antenna_cfg.txt": format_antenna_cfg(
            ant, f"{board.name}: TX slots {list(cfg.tx_slots)}, RX {list(cfg.rx_channels)} "
                 f"(imported from {cfg.source})"),
        f"calib/{radar}/heatmap_cfg.txt": format_heatmap_cfg(grid),
        # The radar is the rig's base frame of a one-radar run.
        f"calib/transforms/base_to_{radar}.txt": format_transform(ident),
    }, w


def _check_target(out: Path, capture: Path, overwrite: bool) -> None:
    out_r, cap_r = out.resolve(), capture.resolve()
    if out_r == cap_r or out_r in cap_r.parents:
        raise SettingsError(f"{out}: the output run would contain the capture {capture}; write "
                            "the run elsewhere")
    if cap_r in out_r.parents:
        raise SettingsError(f"{out}: lies inside the capture {capture}; coloradar never writes "
                            "into its inputs: write the run elsewhere")
    if out.exists() or out.is_symlink():
        if not overwrite:
            raise OutputExistsError(f"{out}: exists; pass --overwrite (overwrite=True) to replace "
                                    "a run written by an earlier import")
        if not (out / MARKER).is_file():
            raise OutputExistsError(f"{out}: exists and is not a run written by import-capture "
                                    f"(no {MARKER}); not replacing it")


def _move_into_place(tmp: Path, out: Path) -> None:
    if out.exists():
        old = out.with_name(f".{out.name}.replaced")
        shutil.rmtree(old, ignore_errors=True)
        os.replace(out, old)
        os.replace(tmp, out)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(tmp, out)


def _write_run(tmp: Path, fr: _Frames, radar: str, spec: CaptureImport
               ) -> tuple[list[int], list[int], int]:
    """Frames and timestamps into ``tmp``; returns left-out and zero-filled frames, and how many
    files were written."""
    stream = COLORADAR.frame(f"{radar}/adc")
    times = fr.times.astype(np.float64).copy()
    left, zeroed, written = [], [], 0
    for a, block in fr.blocks:
        for k in range(block.shape[0]):
            i = a + k
            frame = block[k]
            if i in fr.skipped:
                times[i] = np.nan
                left.append(i)
                continue
            if i in fr.bad:
                if spec.dropped == "skip":
                    times[i] = np.nan
                    left.append(i)
                    continue
                frame = np.zeros_like(frame)
                zeroed.append(i)
            atomic_write_bytes(tmp / stream.frame_path(COLORADAR.first_frame + i), encode_adc(frame))
            written += 1
    atomic_write_text(tmp / stream.timestamps_path, format_timestamps(times))
    return left, zeroed, written


def _resolve(capture: Path, spec: CaptureImport) -> tuple[CaptureConfig, str]:
    cfg = spec.config if isinstance(spec.config, CaptureConfig) else load_config(spec.config)
    cfg = cfg.with_options(iq_order=spec.iq_order, lanes=spec.lanes)
    if spec.iq_order is not None and spec.iq_order not in ("iq", "qi"):
        raise SettingsError(f"--iq-order {spec.iq_order!r}; expected iq or qi")
    if spec.lanes is not None and spec.lanes not in (2, 4):
        raise SettingsError(f"--lanes {spec.lanes}; expected 2 or 4")
    check_config_values(cfg)
    kind = spec.capture_format
    if kind == "auto":
        if capture.is_dir():
            kind = "mmwcas"
        elif "_raw_" in capture.name.lower():
            kind = "packets"
        else:
            kind = "dca1000"
    if kind not in ("dca1000", "packets", "mmwcas"):
        raise SettingsError(f"capture format {kind!r}; expected auto, dca1000, packets or mmwcas")
    if not capture.exists():
        raise ReadError(f"{capture}: capture not found")
    return cfg, kind


def import_capture(capture: str | os.PathLike[str], out_run: str | os.PathLike[str],
                   spec: CaptureImport | None = None, **fields: Any) -> ImportResult:
    """Import a raw TI capture as the ColoRadar run ``out_run``.

    Parameters
    ----------
    capture
        A DCA1000 file (mmWave Studio's ``adc_data.bin`` or the CLI's recording), a raw packet
        dump (``adc_data_Raw_0.bin``), or an MMWCAS capture folder.
    out_run
        The run folder to create (must not exist, unless ``overwrite`` and written by an
        earlier import).
    spec
        A :class:`CaptureImport`; keyword arguments named like its fields replace them
        (``config=`` is required one way or the other).

    Returns
    -------
    ImportResult

    Raises
    ------
    FormatError
        A capture that is not a whole number of frames (bytes short and which frame), a
        configuration that disagrees with it, a broken packet dump or index.
    MissingDataError
        A missing device file of an MMWCAS folder.
    SettingsError
        An unknown board or option.
    OutputExistsError
        ``out_run`` exists (and ``overwrite`` is not set or it is not an import).
    """
    t0 = time.perf_counter()
    if spec is None and "config" not in fields:
        raise SettingsError("import_capture needs config= (the capture's configuration file)")
    spec = replace(spec, **fields) if spec is not None else CaptureImport(**fields)
    cap, out = Path(capture), Path(out_run)
    cfg, kind = _resolve(cap, spec)
    _check_target(out, cap, spec.overwrite)
    board_name = spec.board or cfg.device
    if board_name is None:
        raise SettingsError(f"{cfg.source} does not name the radar board; pass --board "
                            "(AWR1843BOOST, IWR6843ISK, MMWCAS-RF-EVM or an antenna_cfg.txt)")
    radar = "cascade" if kind == "mmwcas" else "single_chip"
    board = get_board(board_name, radar)
    if (board.radar == "cascade") != (kind == "mmwcas"):
        raise SettingsError(f"board {board.name} does not record "
                            f"{'MMWCAS folders' if kind == 'mmwcas' else 'DCA1000 files'}")
    texts, _ = _calib_texts(cfg, board, radar)
    fr = (_tda2_frames(cap, cfg, spec) if kind == "mmwcas"
          else _dca1000_frames(cap, cfg, spec, packets=kind == "packets"))
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=out.parent))
    # mkdtemp makes the folder 0700; the run gets the mode a plain mkdir would give it.
    umask = os.umask(0)
    os.umask(umask)
    tmp.chmod(0o777 & ~umask)
    try:
        left, zeroed, written = _write_run(tmp, fr, radar, spec)
        notes = list(fr.notes)
        why = {**fr.bad, **fr.skipped}
        for i in left + zeroed:
            notes.append(f"capture frame {i + fr.first} "
                         f"{'left out' if i in left else 'zero-filled'}: {why[i]}")
        for rel, text in texts.items():
            atomic_write_text(tmp / rel, text)
        record = dict(capture=str(cap.resolve()), config=cfg.source, board=board.name,
                      radar=radar, format=kind, layout=fr.layout, frames=fr.count,
                      first_capture_frame=fr.first, frames_written=written,
                      left_out=[i + fr.first for i in left],
                      zero_filled=[i + fr.first for i in zeroed],
                      dropped_packets=fr.dropped_packets, notes=notes)
        atomic_write_text(tmp / MARKER, json.dumps(record, indent=1) + "\n")
        _move_into_place(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return ImportResult(out, radar, board.name, written, fr.count + fr.first,
                        tuple(i + fr.first for i in left), tuple(i + fr.first for i in zeroed),
                        fr.dropped_packets, fr.layout, tuple(notes), time.perf_counter() - t0)
