"""Radar configurations of TI captures: the mmWave SDK CLI profile (``.cfg``), mmWave Studio's
JSON (``*.mmwave.json`` with its ``*.setup.json``) and the MMWCAS (cascade) JSON.

Each parser returns a :class:`CaptureConfig`: the chirp profile, which TX each chirp of a loop
fires, which RX channels the data holds (in the order the bytes hold them), the frame, and what
the file says of the byte layout (LVDS lanes, I/Q order, real or complex samples, channel
interleaving). What a file does not say is None; the importer then asks for the option
(``--lanes``, ``--iq-order``) or takes the layout TI documents for the device
(docs/capture.md).
"""

from __future__ import annotations

import json
import os
import re
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

from ..errors import DataWarning, FormatError, ReadError, SettingsError

__all__ = ["CaptureConfig", "load_config", "parse_cli_cfg", "parse_mmwave_json"]

Sampling = Literal["complex", "real"]
IqOrder = Literal["iq", "qi"]


@dataclass(frozen=True)
class CaptureConfig:
    """What a capture's configuration says about its frames and bytes.

    Attributes
    ----------
    start_frequency, slope, sample_rate
        Chirp start [Hz], slope [Hz/s], ADC output rate [Hz] (complex or real samples/s).
    idle_time, adc_start_time, ramp_end_time
        Chirp timing [s].
    num_samples, num_loops
        ADC samples per chirp; chirp loops per frame.
    tx_slots
        For each chirp of a loop, in time order, the TX it fires: a device-global index from 0
        (``3·device + bit`` of the device's TX enable mask).
    rx_channels
        The enabled RX channels, device-global from 0 (``4·device + bit``), in the order the
        data holds them.
    frame_period
        Frame periodicity [s].
    num_frames
        Frames the configuration asked for (0: until stopped).
    sampling
        ``"complex"`` (TI's complex 1x or 2x: the same bytes) or ``"real"``.
    complex_mode
        ``"1x"``, ``"2x"`` or ``""`` (real), as configured (reported; the bytes do not differ).
    iq_order, lanes, interleaved
        The byte layout when the configuration states it, else None: ``"iq"`` (I in the lower
        16 bits, written first) or ``"qi"``; LVDS lanes (2 or 4); whether the RX channels are
        interleaved sample by sample (else each RX's samples follow one another).
    device
        The radar device or board the configuration names (``"awr1843"``…), or None.
    num_devices
        1, or 4 for the MMWCAS cascade.
    source
        The file(s) it was read from, for messages.
    """

    start_frequency: float
    slope: float
    sample_rate: float
    idle_time: float
    adc_start_time: float
    ramp_end_time: float
    num_samples: int
    num_loops: int
    tx_slots: tuple[int, ...]
    rx_channels: tuple[int, ...]
    frame_period: float
    num_frames: int
    sampling: Sampling = "complex"
    complex_mode: str = "1x"
    iq_order: IqOrder | None = None
    lanes: int | None = None
    interleaved: bool | None = None
    device: str | None = None
    num_devices: int = 1
    source: str = "<config>"

    @property
    def num_tx(self) -> int:
        """TX slots (chirps) per loop."""
        return len(self.tx_slots)

    @property
    def num_rx(self) -> int:
        """RX channels in the data."""
        return len(self.rx_channels)

    @property
    def values_per_frame(self) -> int:
        """ADC values (complex or real) in one frame of all devices."""
        return self.num_loops * self.num_tx * self.num_rx * self.num_samples

    @property
    def frame_nbytes(self) -> int:
        """Bytes of one frame as captured (16-bit words; two per complex value)."""
        return self.values_per_frame * (4 if self.sampling == "complex" else 2)

    def with_options(self, **changes: Any) -> CaptureConfig:
        """A copy with the given fields replaced (None values leave the field as it is)."""
        return replace(self, **{k: v for k, v in changes.items() if v is not None})


# ----------------------------------------------------------------------------------- helpers
def _int(value: Any, where: str) -> int:
    """An integer from a JSON/CLI value: ``12``, ``"12"``, ``"0xF"``."""
    try:
        if isinstance(value, str):
            return int(value.strip(), 0)
        if isinstance(value, float) and value.is_integer():
            return int(value)
        if isinstance(value, int):
            return value
    except ValueError:
        pass
    raise FormatError(f"{where}: expected an integer (decimal or 0x hex), found {value!r}")


def _float(value: Any, where: str) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        raise FormatError(f"{where}: expected a number, found {value!r}") from None


def _bits(mask: int) -> list[int]:
    return [b for b in range(32) if mask >> b & 1]


def _sampling(fmt: int, where: str) -> tuple[Sampling, str]:
    # TI's ADC output format code (mmwavelink rlAdcOutCfg_t / SDK adcCfg): 0 real, 1 complex 1x,
    # 2 complex 2x.
    table: dict[int, tuple[Sampling, str]] = {0: ("real", ""), 1: ("complex", "1x"),
                                             2: ("complex", "2x")}
    if fmt not in table:
        raise FormatError(f"{where}: ADC output format {fmt}; expected 0 (real), 1 (complex 1x) "
                          "or 2 (complex 2x)")
    return table[fmt]


def _check_bits(code: int, where: str) -> None:
    # 0: 12 bit, 1: 14 bit, 2: 16 bit. The LVDS stream carries 16-bit words in every case
    # (12/14-bit samples sign-extended), so only the scale differs; say so.
    if code not in (0, 1, 2):
        raise FormatError(f"{where}: ADC bits code {code}; expected 0 (12), 1 (14) or 2 (16 bit)")
    if code != 2:
        warnings.warn(f"{where}: {(12, 14)[code]}-bit ADC samples: read as 16-bit words "
                      "(amplitudes are in the device's counts)", DataWarning, stacklevel=3)


def _slots(chirps: list[tuple[int, int, int, list[int]]], first: int, last: int,
           where: str) -> tuple[tuple[int, ...], int]:
    """TX of every chirp ``first..last`` from ``(start, end, profile, tx masks per device)``
    rows; returns the slots and the profile they use."""
    if last < first:
        raise FormatError(f"{where}: frame chirps {first}..{last}: the end comes before the start")
    slots, profiles = [], set()
    for idx in range(first, last + 1):
        rows = [c for c in chirps if c[0] <= idx <= c[1]]
        if not rows:
            raise FormatError(f"{where}: the frame uses chirp {idx} but no chirp configuration "
                              "covers it")
        _, _, prof, masks = rows[-1]
        fired = [(d, b) for d, m in enumerate(masks) for b in _bits(m)]
        if len(fired) != 1:
            raise FormatError(
                f"{where}: chirp {idx} fires {len(fired)} TX ({', '.join(hex(m) for m in masks)}); "
                "only time-division MIMO (one TX per chirp) can be imported")
        d, b = fired[0]
        slots.append(3 * d + b)
        profiles.add(prof)
    if len(profiles) != 1:
        raise FormatError(f"{where}: the frame's chirps use profiles {sorted(profiles)}; only "
                          "one profile per frame can be imported")
    return tuple(slots), profiles.pop()


# ------------------------------------------------------------------------------- SDK .cfg
_CFG_COMMANDS = ("channelCfg", "adcCfg", "adcbufCfg", "profileCfg", "chirpCfg", "frameCfg")


def parse_cli_cfg(text: str, name: str = "<profile.cfg>") -> CaptureConfig:
    """Parse an mmWave SDK CLI profile (``.cfg``).

    Reads ``channelCfg <rxMask> <txMask> <cascading>``, ``adcCfg <bits> <fmt>``,
    ``adcbufCfg [<subFrame>] <fmt> <sampleSwap> <chanInterleave> <threshold>``,
    ``profileCfg`` (start GHz, idle µs, ADC start µs, ramp end µs, …, slope MHz/µs, TX start µs,
    samples, rate ksps, …), ``chirpCfg <start> <end> <profile> … <txMask>`` and
    ``frameCfg <first> <last> <loops> <frames> <period ms> …``; ``%`` starts a comment.

    Raises
    ------
    FormatError
        A command missing or malformed, naming the file and line.
    """
    cmds: dict[str, list[tuple[int, list[str]]]] = {}
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("%", 1)[0].strip()
        if line:
            parts = line.split()
            cmds.setdefault(parts[0], []).append((lineno, parts[1:]))
    missing = [c for c in _CFG_COMMANDS if c not in cmds]
    if missing:
        raise FormatError(f"{name}: missing {', '.join(missing)} (an mmWave SDK profile has "
                          f"{', '.join(_CFG_COMMANDS)})")

    def one(cmd: str, n: int) -> tuple[str, list[str]]:
        lineno, args = cmds[cmd][-1]
        if len(args) < n:
            raise FormatError(f"{name}, line {lineno}: {cmd} needs at least {n} values, found "
                              f"{len(args)}")
        return f"{name}, line {lineno} ({cmd})", args

    w, a = one("channelCfg", 2)
    rx = _bits(_int(a[0], w))
    w, a = one("adcCfg", 2)
    _check_bits(_int(a[0], w), w)
    sampling, mode = _sampling(_int(a[1], w), w)
    w, a = one("adcbufCfg", 4)
    a = a[-4:] if len(a) >= 5 else a          # SDK 2+ puts a sub-frame index first
    buf_real = _int(a[0], w) == 1
    if buf_real != (sampling == "real"):
        raise FormatError(f"{w}: the ADC buffer is {'real' if buf_real else 'complex'} but adcCfg "
                          f"says {sampling}")
    iq: IqOrder = "qi" if _int(a[1], w) == 1 else "iq"   # 1: Q in the lower 16 bits
    interleaved = _int(a[2], w) == 0                      # 0: interleaved, 1: non-interleaved
    profiles = {}
    for lineno, args in cmds["profileCfg"]:
        wp = f"{name}, line {lineno} (profileCfg)"
        if len(args) < 11:
            raise FormatError(f"{wp}: needs 11+ values, found {len(args)}")
        profiles[_int(args[0], wp)] = (wp, args)
    chirps = []
    for lineno, args in cmds["chirpCfg"]:
        wc = f"{name}, line {lineno} (chirpCfg)"
        if len(args) < 8:
            raise FormatError(f"{wc}: needs 8 values, found {len(args)}")
        if any(_float(v, wc) != 0 for v in args[3:7]):
            warnings.warn(f"{wc}: per-chirp frequency/slope/time variations are not imported "
                          "(the profile's values are used)", DataWarning, stacklevel=2)
        chirps.append((_int(args[0], wc), _int(args[1], wc), _int(args[2], wc),
                       [_int(args[7], wc)]))
    w, a = one("frameCfg", 5)
    slots, prof = _slots(chirps, _int(a[0], w), _int(a[1], w), w)
    loops, frames, period = _int(a[2], w), _int(a[3], w), _float(a[4], w) * 1e-3
    if prof not in profiles:
        raise FormatError(f"{name}: the chirps use profile {prof}, which no profileCfg defines")
    if "lvdsStreamCfg" in cmds:
        wl, al = one("lvdsStreamCfg", 2)
        if _int(al[1], wl) != 0:
            raise FormatError(f"{wl}: the LVDS stream carries HSI headers (enableHeader = 1); "
                              "capture with enableHeader 0 to import the ADC data")
    wp, p = profiles[prof]
    return CaptureConfig(
        start_frequency=_float(p[1], wp) * 1e9, idle_time=_float(p[2], wp) * 1e-6,
        adc_start_time=_float(p[3], wp) * 1e-6, ramp_end_time=_float(p[4], wp) * 1e-6,
        slope=_float(p[7], wp) * 1e12, num_samples=_int(p[9], wp),
        sample_rate=_float(p[10], wp) * 1e3, num_loops=loops, tx_slots=slots,
        rx_channels=tuple(rx), frame_period=period, num_frames=frames, sampling=sampling,
        complex_mode=mode, iq_order=iq, lanes=None, interleaved=interleaved, device=None,
        num_devices=1, source=name)


# ---------------------------------------------------------------------- mmWave Studio JSON
def _get(d: Any, key: str, where: str) -> Any:
    if not isinstance(d, dict) or key not in d:
        have = ", ".join(list(d)[:8]) if isinstance(d, dict) else type(d).__name__
        raise FormatError(f"{where}: missing {key!r} (found {have})")
    return d[key]


def _unwrap(item: Any, key: str) -> Any:
    # mmWave Studio writes list entries as {"rlProfileCfg_t": {...}}; accept the bare dict too.
    return item[key] if isinstance(item, dict) and key in item else item


def _device_config(dev: dict, where: str) -> dict[str, Any]:
    rf = _get(dev, "rfConfig", where)
    chan = _get(rf, "rlChanCfg_t", f"{where}.rfConfig")
    fmt = _get(_get(rf, "rlAdcOutCfg_t", f"{where}.rfConfig"), "fmt",
               f"{where}.rfConfig.rlAdcOutCfg_t")
    profiles = [_unwrap(p, "rlProfileCfg_t") for p in _get(rf, "rlProfiles", f"{where}.rfConfig")]
    chirps = [_unwrap(c, "rlChirpCfg_t") for c in _get(rf, "rlChirps", f"{where}.rfConfig")]
    frame = _get(rf, "rlFrameCfg_t", f"{where}.rfConfig")
    raw = dev.get("rawDataCaptureConfig", {})
    return dict(chan=chan, fmt=fmt, profiles=profiles, chirps=chirps, frame=frame, raw=raw)


def _json(text: str, name: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise FormatError(f"{name}: not JSON ({exc.msg} at line {exc.lineno})") from None


def _lanes_from_setup(setup: Any, name: str) -> tuple[int | None, str | None]:
    dca = setup.get("DCA1000Config", {}) if isinstance(setup, dict) else {}
    lanes = None
    if "lvdsMode" in dca:
        # DCA1000 CLI / mmWave Studio: lvdsMode 1 = four lanes, 2 = two lanes.
        mode = _int(dca["lvdsMode"], f"{name}: DCA1000Config.lvdsMode")
        if mode not in (1, 2):
            raise FormatError(f"{name}: DCA1000Config.lvdsMode = {mode}; expected 1 (4 lanes) "
                              "or 2 (2 lanes)")
        lanes = 4 if mode == 1 else 2
    dev = setup.get("mmWaveDevice") if isinstance(setup, dict) else None
    return lanes, (str(dev).lower() if dev else None)


def parse_mmwave_json(text: str, name: str = "<mmwave.json>", setup_text: str | None = None,
                      setup_name: str = "<setup.json>") -> CaptureConfig:
    """Parse mmWave Studio's ``*.mmwave.json`` (one device) or an MMWCAS JSON (four devices).

    The profile, chirps and frame come from ``mmWaveDevices[*].rfConfig`` (``rlChanCfg_t``,
    ``rlAdcOutCfg_t.fmt``, ``rlProfiles``, ``rlChirps``, ``rlFrameCfg_t``); the lanes and I/Q
    order from ``rawDataCaptureConfig`` (``rlDevLaneEnable_t.laneEn``,
    ``rlDevDataFmtCfg_t.iqSwapSel`` / ``chInterleave``) when present, and from the
    ``*.setup.json`` (``DCA1000Config.lvdsMode``, ``mmWaveDevice``) when given.
    """
    doc = _json(text, name)
    devices = _get(doc, "mmWaveDevices", name)
    if not isinstance(devices, list) or len(devices) not in (1, 4):
        raise FormatError(f"{name}: mmWaveDevices holds {len(devices) if isinstance(devices, list) else '?'} "
                          "devices; expected 1 (single chip) or 4 (MMWCAS cascade)")
    devices = sorted(devices, key=lambda d: _int(d.get("mmWaveDeviceId", 0), name))
    cfgs = [_device_config(d, f"{name}: mmWaveDevices[{i}]") for i, d in enumerate(devices)]
    c0, w0 = cfgs[0], f"{name}: mmWaveDevices[0].rfConfig"
    fmt = c0["fmt"]
    _check_bits(_int(_get(fmt, "b2AdcBits", w0), w0), w0)
    sampling, mode = _sampling(_int(_get(fmt, "b2AdcOutFmt", w0), w0), w0)
    rx = [4 * d + b for d, c in enumerate(cfgs)
          for b in _bits(_int(_get(c["chan"], "rxChannelEn", w0), w0))]
    chirps = []
    for d, c in enumerate(cfgs):
        for k, ch in enumerate(c["chirps"]):
            wc = f"{name}: mmWaveDevices[{d}].rfConfig.rlChirps[{k}]"
            masks = [0] * len(cfgs)
            masks[d] = _int(_get(ch, "txEnable", wc), wc)
            chirps.append((_int(_get(ch, "chirpStartIdx", wc), wc),
                           _int(_get(ch, "chirpEndIdx", wc), wc),
                           _int(_get(ch, "profileId", wc), wc), masks))
    # A chirp index fires the union of what each device's chirp table says for it.
    merged: dict[tuple[int, int, int], list[int]] = {}
    for s, e, p, m in chirps:
        for idx in range(s, e + 1):
            key = (idx, idx, p)
            cur = merged.setdefault(key, [0] * len(cfgs))
            merged[key] = [a | b for a, b in zip(cur, m, strict=True)]
    rows = [(k[0], k[1], k[2], m) for k, m in sorted(merged.items())]
    fr, wf = c0["frame"], f"{w0}.rlFrameCfg_t"
    slots, prof = _slots(rows, _int(_get(fr, "chirpStartIdx", wf), wf),
                         _int(_get(fr, "chirpEndIdx", wf), wf), wf)
    profs = [p for p in c0["profiles"] if _int(p.get("profileId", 0), w0) == prof]
    if not profs:
        raise FormatError(f"{w0}: the chirps use profile {prof}, which rlProfiles does not define")
    p, wp = profs[0], f"{w0}.rlProfiles[profileId={prof}]"
    raw = c0["raw"] if isinstance(c0["raw"], dict) else {}
    iq: IqOrder | None = None
    interleaved: bool | None = None
    lanes: int | None = None
    dfmt = raw.get("rlDevDataFmtCfg_t")
    if isinstance(dfmt, dict):
        if "iqSwapSel" in dfmt:
            iq = "qi" if _int(dfmt["iqSwapSel"], wp) == 1 else "iq"
        if "chInterleave" in dfmt:
            interleaved = _int(dfmt["chInterleave"], wp) == 0
    lane_en = raw.get("rlDevLaneEnable_t")
    if isinstance(lane_en, dict) and "laneEn" in lane_en:
        lanes = len(_bits(_int(lane_en["laneEn"], wp))) or None
    device = None
    if setup_text is not None:
        s_lanes, device = _lanes_from_setup(_json(setup_text, setup_name), setup_name)
        lanes = s_lanes or lanes
    if len(cfgs) == 4:
        device = "mmwcas"
    return CaptureConfig(
        start_frequency=_float(_get(p, "startFreqConst_GHz", wp), wp) * 1e9,
        idle_time=_float(_get(p, "idleTimeConst_usec", wp), wp) * 1e-6,
        adc_start_time=_float(_get(p, "adcStartTimeConst_usec", wp), wp) * 1e-6,
        ramp_end_time=_float(_get(p, "rampEndTime_usec", wp), wp) * 1e-6,
        slope=_float(_get(p, "freqSlopeConst_MHz_usec", wp), wp) * 1e12,
        num_samples=_int(_get(p, "numAdcSamples", wp), wp),
        sample_rate=_float(_get(p, "digOutSampleRate", wp), wp) * 1e3,
        num_loops=_int(_get(fr, "numLoops", wf), wf), tx_slots=slots, rx_channels=tuple(rx),
        frame_period=_float(_get(fr, "framePeriodicity_msec", wf), wf) * 1e-3,
        num_frames=_int(fr.get("numFrames", 0), wf), sampling=sampling, complex_mode=mode,
        iq_order=iq, lanes=lanes, interleaved=interleaved, device=device,
        num_devices=len(cfgs), source=name if setup_text is None else f"{name} + {setup_name}")


# ------------------------------------------------------------------------------- dispatch
def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8", errors="replace")
    except FileNotFoundError:
        raise ReadError(f"{path}: configuration file not found") from None
    except IsADirectoryError:
        raise ReadError(f"{path}: expected a configuration file, found a folder") from None
    except OSError as exc:
        raise ReadError(f"{path}: cannot read ({exc.strerror or exc})") from None


def _setup_beside(path: Path) -> Path | None:
    """The ``*.setup.json`` mmWave Studio writes beside ``*.mmwave.json``, if there is one."""
    stem = re.sub(r"\.mmwave\.json$", "", path.name, flags=re.I)
    same = path.with_name(f"{stem}.setup.json")
    if same.is_file():
        return same
    # Otherwise only an unambiguous one: the single setup file of the folder.
    others = sorted(path.parent.glob("*.setup.json"))
    return others[0] if len(others) == 1 else None


def load_config(path: str | os.PathLike[str], setup: str | os.PathLike[str] | None = None
                ) -> CaptureConfig:
    """Read a capture configuration: an SDK ``.cfg``, an mmWave Studio ``*.mmwave.json``
    (its ``*.setup.json`` is looked for beside it; or name it with ``setup``; a
    ``*.setup.json`` given as ``path`` leads to the ``*.mmwave.json`` it names), or an MMWCAS
    JSON.

    Raises
    ------
    ReadError
        The file is missing or unreadable.
    FormatError
        Not a configuration this reads, or one with a missing/malformed field (named).
    """
    p = Path(path)
    text = _read_text(p)
    if p.suffix.lower() == ".cfg" or ("profileCfg" in text and not text.lstrip().startswith("{")):
        return parse_cli_cfg(text, str(p))
    doc = _json(text, str(p))
    if isinstance(doc, dict) and "mmWaveDevices" not in doc and "configUsed" in doc:
        # A setup.json: it names the mmwave.json it was captured with.
        used = Path(str(doc["configUsed"]).replace("\\", "/"))
        mm = used if used.is_file() else p.with_name(used.name)
        if not mm.is_file():
            raise ReadError(f"{p}: names the configuration {doc['configUsed']!r}, which is not "
                            f"at {mm}")
        return parse_mmwave_json(_read_text(mm), str(mm), text, str(p))
    sp = Path(setup) if setup is not None else _setup_beside(p)
    if sp is None:
        return parse_mmwave_json(text, str(p))
    return parse_mmwave_json(text, str(p), _read_text(sp), str(sp))


def check_config_values(cfg: CaptureConfig) -> None:
    """Refuse sizes that cannot describe a frame (zero samples, no RX, no loops)."""
    for what, v in (("samples per chirp", cfg.num_samples), ("chirp loops", cfg.num_loops),
                    ("RX channels", cfg.num_rx), ("TX slots", cfg.num_tx)):
        if v <= 0:
            raise SettingsError(f"{cfg.source}: {v} {what}; a frame needs at least one")
    if not cfg.frame_period > 0:
        raise SettingsError(f"{cfg.source}: frame periodicity {cfg.frame_period!r} s; expected > 0")
    window_end = cfg.adc_start_time + cfg.num_samples / cfg.sample_rate
    if cfg.sample_rate > 0 and window_end > cfg.ramp_end_time * (1 + 1e-9):
        raise FormatError(f"{cfg.source}: the ADC samples until {window_end * 1e6:.3g} µs (ADC "
                          f"start + {cfg.num_samples} samples at {cfg.sample_rate / 1e3:g} ksps) "
                          f"but the ramp ends at {cfg.ramp_end_time * 1e6:.3g} µs")
