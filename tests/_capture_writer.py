"""A test-side writer of raw TI captures, written from the format descriptions (TI's DCA1000
capture guide SWRA581, the DCA1000 packet header, TI's cascade scripts' index layout), not from
coloradar's reader: it lays out known frames value by value in each byte order, so that reading
them back is checked against an independent account of the bytes.

Frames are complex ``(tx slot, rx, chirp loop, sample)`` arrays, as in the dataset.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np

from coloradar.calib import (
    AntennaConfig,
    HeatmapConfig,
    RadarCalib,
    WaveformConfig,
    shipped_angle_bins,
)
from coloradar.sim.radar_if import synthesize_adc

# The physical antennas of the boards, as TI documents them (half wavelengths, az toward +y).
XWR18_TX = [(0, 0), (2, 1), (4, 0)]          # TX0, TX1 (raised), TX2
XWR18_RX = [(0, 0), (1, 0), (2, 0), (3, 0)]
CASCADE_TX = [(11, 6), (10, 4), (9, 1), (32, 0), (28, 0), (24, 0), (20, 0), (16, 0), (12, 0),
              (8, 0), (4, 0), (0, 0)]        # master TX0-2, slave1 TX0-2, slave2, slave3
CASCADE_RX = [11, 12, 13, 14, 50, 51, 52, 53, 46, 47, 48, 49, 0, 1, 2, 3]  # master..slave3

SMALL = dict(start_ghz=77.0, idle_us=30.0, adc_start_us=6.0, ramp_end_us=20.0, slope=60.0,
             samples=64, rate_ksps=10000, loops=16, period_ms=50.0)
"""A small single-chip waveform: 0.39 m range bins (25 m), ±6.5 m/s, 0.81 m/s Doppler bins."""


def truth_calib(tx_order: list[int], w: dict = SMALL, *, tx_table=XWR18_TX, rx_pos=None,
                num_rx: int = 4, f_design: float = 76.8e9) -> RadarCalib:
    """The radar as the test knows it: the waveform, and TX slot t at ``tx_table[tx_order[t]]``."""
    wf = WaveformConfig(num_rx=num_rx, num_tx=len(tx_order), num_samples=w["samples"],
                        num_chirps=w["loops"], sample_rate=w["rate_ksps"] * 1e3,
                        start_frequency=w["start_ghz"] * 1e9, idle_time=w["idle_us"] * 1e-6,
                        adc_start_time=w["adc_start_us"] * 1e-6,
                        ramp_end_time=w["ramp_end_us"] * 1e-6, slope=w["slope"] * 1e12)
    rx = np.array(rx_pos if rx_pos is not None else XWR18_RX, dtype=float)
    ant = AntennaConfig(f_design, rx, np.array([tx_table[k] for k in tx_order], dtype=float))
    grid = HeatmapConfig(w["samples"], 16, 64, wf.range_bin_width, shipped_angle_bins(64),
                         shipped_angle_bins(16))
    return RadarCalib("single_chip", wf, ant, grid)


def target_frames(calib: RadarCalib, targets: list[tuple[float, float, float]], n: int,
                  seed: int = 0, amplitude: float = 4e4, noise: float = 2.0) -> np.ndarray:
    """``n`` frames of point targets ``(range m, azimuth deg, range rate m/s)`` at elevation 0,
    rounded to whole ADC counts: complex ``(n, tx, rx, chirp, sample)``."""
    pos, vel = [], []
    for r, az, v in targets:
        u = np.array([np.cos(np.radians(az)), np.sin(np.radians(az)), 0.0])
        pos.append(r * u)
        vel.append(v * u)
    rng = np.random.default_rng(seed)
    out = [synthesize_adc(calib, np.array(pos), np.array(vel), amplitude, noise_std=noise, rng=rng)
           for _ in range(n)]
    return np.rint(np.stack(out).real) + 1j * np.rint(np.stack(out).imag)


# ------------------------------------------------------------------------------ configs
def sdk_cfg(tx_order: list[int], *, w: dict = SMALL, frames: int = 2, real: bool = False,
            swap: bool = False, interleave: bool = False, rx_mask: int = 0xF) -> str:
    """An mmWave SDK CLI profile: one chirpCfg per TX slot, ``frameCfg`` over them."""
    tx_mask = 0
    for k in tx_order:
        tx_mask |= 1 << k
    lines = ["% test profile", "sensorStop", "flushCfg", "dfeDataOutputMode 1",
             f"channelCfg {rx_mask} {tx_mask} 0",
             f"adcCfg 2 {0 if real else 1}",
             f"adcbufCfg -1 {1 if real else 0} {1 if swap else 0} {0 if interleave else 1} 1",
             f"profileCfg 0 {w['start_ghz']} {w['idle_us']} {w['adc_start_us']} "
             f"{w['ramp_end_us']} 0 0 {w['slope']} 1 {w['samples']} {w['rate_ksps']} 0 0 30"]
    for slot, k in enumerate(tx_order):
        lines.append(f"chirpCfg {slot} {slot} 0 0 0 0 0 {1 << k}")
    lines += [f"frameCfg 0 {len(tx_order) - 1} {w['loops']} {frames} {w['period_ms']} 1 0",
              "lvdsStreamCfg -1 0 1 0", "sensorStart"]
    return "\n".join(lines) + "\n"


def _rf_config(w: dict, rx_mask: int, chirps: list[tuple[int, int]], n_chirps: int,
               frames: int, fmt: int) -> dict:
    return {
        "rlChanCfg_t": {"rxChannelEn": hex(rx_mask), "txChannelEn": "0x7", "cascading": 0},
        "rlAdcOutCfg_t": {"fmt": {"b2AdcBits": 2, "b2AdcOutFmt": fmt}},
        "rlProfiles": [{"rlProfileCfg_t": {
            "profileId": 0, "startFreqConst_GHz": w["start_ghz"],
            "idleTimeConst_usec": w["idle_us"], "adcStartTimeConst_usec": w["adc_start_us"],
            "rampEndTime_usec": w["ramp_end_us"], "freqSlopeConst_MHz_usec": w["slope"],
            "numAdcSamples": w["samples"], "digOutSampleRate": w["rate_ksps"]}}],
        "rlChirps": [{"rlChirpCfg_t": {"chirpStartIdx": i, "chirpEndIdx": i, "profileId": 0,
                                       "txEnable": hex(mask)}} for i, mask in chirps],
        "rlFrameCfg_t": {"chirpStartIdx": 0, "chirpEndIdx": n_chirps - 1,
                         "numLoops": w["loops"], "numFrames": frames,
                         "framePeriodicity_msec": w["period_ms"]},
    }


def studio_json(tx_order: list[int], *, w: dict = SMALL, frames: int = 2, lanes: int = 2,
                swap: bool = False, interleave: bool = False, real: bool = False,
                complex2x: bool = False, device: str = "awr1843") -> tuple[str, str]:
    """mmWave Studio's ``*.mmwave.json`` and ``*.setup.json`` texts for a DCA1000 capture."""
    fmt = 0 if real else (2 if complex2x else 1)
    rf = _rf_config(w, 0xF, [(i, 1 << k) for i, k in enumerate(tx_order)], len(tx_order),
                    frames, fmt)
    dev = {"mmWaveDeviceId": 0, "rfConfig": rf, "rawDataCaptureConfig": {
        "rlDevDataFmtCfg_t": {"iqSwapSel": 1 if swap else 0, "chInterleave": 0 if interleave else 1},
        "rlDevLaneEnable_t": {"laneEn": hex((1 << lanes) - 1)}}}
    mm = {"configGenerator": {"createdBy": "test"}, "mmWaveDevices": [dev]}
    setup = {"configUsed": "capture.mmwave.json", "captureHardware": "DCA1000",
             "DCA1000Config": {"dataLoggingMode": "raw", "lvdsMode": 1 if lanes == 4 else 2},
             "mmWaveDevice": device}
    return json.dumps(mm, indent=1), json.dumps(setup, indent=1)


def cascade_json(tx_order: list[int], *, w: dict, frames: int, iq_swap: int | None = None) -> str:
    """The MMWCAS JSON: four devices, each with 4 RX and the chirps that fire its TX; with
    ``iq_swap``, each device's ``rawDataCaptureConfig.rlDevDataFmtCfg_t.iqSwapSel``."""
    devices = []
    for d in range(4):
        chirps = [(i, (1 << (k - 3 * d)) if 3 * d <= k < 3 * d + 3 else 0)
                  for i, k in enumerate(tx_order)]
        rf = _rf_config(w, 0xF, chirps, len(tx_order), frames, 1)
        dev: dict = {"mmWaveDeviceId": d, "rfConfig": rf}
        if iq_swap is not None:
            dev["rawDataCaptureConfig"] = {"rlDevDataFmtCfg_t": {"iqSwapSel": iq_swap,
                                                                 "chInterleave": 1}}
        devices.append(dev)
    return json.dumps({"mmWaveDevices": devices}, indent=1)


# ------------------------------------------------------------------------------ DCA1000
def dca1000_bytes(frames: np.ndarray, *, lanes: int = 2, iq: str = "iq", real: bool = False,
                  interleave: bool = False) -> bytes:
    """The DCA1000 LVDS stream of ``frames`` ``(F, tx, rx, loop, sample)``.

    Chirps in time order (loop, then TX slot); within a chirp each RX's samples in turn, or
    (``interleave``) sample by sample across the RX. Complex values in groups of ``lanes``:
    the group's I words, then its Q words (``qi``: Q words first). Real: one word per value.
    """
    words: list[int] = []
    nf, ntx, nrx, nl, ns = frames.shape
    for f in range(nf):
        for c in range(nl):
            for t in range(ntx):
                if interleave:
                    vals = [frames[f, t, r, c, s] for s in range(ns) for r in range(nrx)]
                else:
                    vals = [frames[f, t, r, c, s] for r in range(nrx) for s in range(ns)]
                if real:
                    words += [int(v.real) for v in vals]
                    continue
                for g in range(0, len(vals), lanes):
                    grp = vals[g:g + lanes]
                    i_words = [int(v.real) for v in grp]
                    q_words = [int(v.imag) for v in grp]
                    words += (i_words + q_words) if iq == "iq" else (q_words + i_words)
    return struct.pack(f"<{len(words)}h", *words)


def packet_dump(stream: bytes, *, payload: int = 1456, drop: tuple[int, ...] = ()) -> bytes:
    """UDP packets of ``stream`` as a raw dump: per packet a 4-byte sequence number (from 1), a
    6-byte count of the stream bytes sent before it, its payload; packets ``drop`` (0-based)
    left out."""
    out = bytearray()
    for k, off in enumerate(range(0, len(stream), payload)):
        if k in drop:
            continue
        out += struct.pack("<I", k + 1) + off.to_bytes(6, "little") + stream[off:off + payload]
    return bytes(out)


# ------------------------------------------------------------------------------ MMWCAS
def write_mmwcas(folder: Path, frames: np.ndarray, ticks_us: np.ndarray, *,
                 truncate_device: str | None = None, segment: int = 0, iq: str = "iq",
                 file_size: int | None = None) -> None:
    """An MMWCAS capture folder: per device ``<dev>_<segment>_data.bin`` (per frame, loop,
    chirp, sample: the device's 4 RX as int16 I, Q; ``iq="qi"``: Q, I, as a device configured
    with ``iqSwapSel`` 1 sends them) and ``<dev>_<segment>_idx.bin`` (24-byte header ``tag,
    version, flags, numIdx`` uint32 and ``dataFileSize`` uint64, the bytes written; 48-byte
    entries ``tag, version`` uint16, ``flags`` uint32, ``width, height`` uint16, four uint32
    metadata sizes, ``size`` uint32, ``timestamp`` uint64, ``offset`` uint64: TI's
    ``getValidNumFrames.m``).

    ``file_size``: the data file is extended to that many bytes (zeros, sparse), as mmWave
    Studio's ``Cascade_Capture.lua`` preallocates each data file at 2047 MB whatever was
    captured; the index still counts the frames written.
    """
    folder.mkdir(parents=True, exist_ok=True)
    nf, ntx, _, nl, ns = frames.shape
    for d, dev in enumerate(("master", "slave1", "slave2", "slave3")):
        words: list[int] = []
        for f in range(nf):
            for c in range(nl):
                for t in range(ntx):
                    for s in range(ns):
                        for r in range(4 * d, 4 * d + 4):
                            v = frames[f, t, r, c, s]
                            pair = [int(v.real), int(v.imag)]
                            words += pair if iq == "iq" else pair[::-1]
        data = struct.pack(f"<{len(words)}h", *words)
        per = len(data) // nf
        if dev == truncate_device:
            data = data[:-100]
        path = folder / f"{dev}_{segment:04d}_data.bin"
        path.write_bytes(data)
        if file_size is not None:
            with open(path, "r+b") as fh:
                fh.truncate(file_size)
        idx = struct.pack("<IIIIQ", 0x1234, 1, 0, nf, len(data))
        for f in range(nf):
            idx += struct.pack("<HHIHH4IIQQ", 1, 1, 0, 0, 0, 0, 0, 0, 0, per,
                               int(ticks_us[f]), f * per)
        (folder / f"{dev}_{segment:04d}_idx.bin").write_bytes(idx)
