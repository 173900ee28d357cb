"""The byte layouts of TI ADC captures, decoded to the dataset's ``(tx, rx, chirp, sample)``.

DCA1000 (docs/capture.md "Byte layouts", after TI's "mmWave Radar Device ADC Raw Data Capture"
guide, SWRA581): the file is the LVDS stream, frames after one another, chirps in time order
(loop by loop, TX slot by TX slot), and within a chirp either each RX's samples in turn
(non-interleaved, the xWR16xx/18xx/68xx) or the RX channels sample by sample (interleaved, the
4-lane xWR12xx/14xx/AWR2243 captures). The lanes carry 16-bit words: with ``L`` lanes each group
of ``L`` consecutive complex values is written as their ``L`` I words, then their ``L`` Q words
(``I0 I1 Q0 Q1`` on two lanes); real captures carry one word per value. ``qi`` swaps the roles
of the two halves.

TDA2 (MMWCAS): each device's file holds, per frame, loop by loop and chirp by chirp, the samples
one after another, each sample the device's four RX, each an I, Q pair (Q first with ``qi``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SettingsError
from .config import CaptureConfig

__all__ = ["ByteLayout", "decode_dca1000", "decode_tda2"]


@dataclass(frozen=True)
class ByteLayout:
    """How a capture's words are ordered.

    Attributes
    ----------
    lanes
        LVDS lanes: 2 or 4 (DCA1000 files; unused for TDA2).
    iq_order
        ``"iq"`` or ``"qi"``.
    interleaved
        RX channels sample by sample (True) or each RX's samples in turn (False).
    sampling
        ``"complex"`` or ``"real"``.
    """

    lanes: int
    iq_order: str
    interleaved: bool
    sampling: str

    def __post_init__(self) -> None:
        if self.lanes not in (1, 2, 4):
            raise SettingsError(f"lanes = {self.lanes}; expected 2 or 4 LVDS lanes")
        if self.iq_order not in ("iq", "qi"):
            raise SettingsError(f"iq order {self.iq_order!r}; expected 'iq' or 'qi'")
        if self.sampling not in ("complex", "real"):
            raise SettingsError(f"sampling {self.sampling!r}; expected 'complex' or 'real'")

    def describe(self) -> str:
        """One line for reports: ``2 lanes, complex IQ, RX non-interleaved``."""
        kind = f"complex {self.iq_order.upper()}" if self.sampling == "complex" else "real"
        return (f"{self.lanes} lanes, {kind}, RX "
                f"{'interleaved' if self.interleaved else 'non-interleaved'}")


def _to_frames(values: np.ndarray, cfg: CaptureConfig, interleaved: bool) -> np.ndarray:
    """``(F, V)`` values in capture order -> complex64 ``(F, tx, rx, chirp, sample)``."""
    nf = values.shape[0]
    ntx, nrx, nl, ns = cfg.num_tx, cfg.num_rx, cfg.num_loops, cfg.num_samples
    if interleaved:
        v = values.reshape(nf, nl, ntx, ns, nrx).transpose(0, 2, 4, 1, 3)
    else:
        v = values.reshape(nf, nl, ntx, nrx, ns).transpose(0, 2, 3, 1, 4)
    return np.ascontiguousarray(v, dtype=np.complex64)


def decode_dca1000(words: np.ndarray, cfg: CaptureConfig, layout: ByteLayout) -> np.ndarray:
    """Decode whole frames of a DCA1000 capture.

    Parameters
    ----------
    words
        int16 ``(F · words_per_frame,)``: the file's 16-bit little-endian words.
    cfg
        The configuration (sizes).
    layout
        Lanes, I/Q order, interleaving, real or complex.

    Returns
    -------
    numpy.ndarray
        complex64 ``(F, tx, rx, chirp, sample)`` in ADC counts (Q = 0 for real captures).
    """
    nv = cfg.values_per_frame
    w = np.asarray(words, dtype=np.int16)
    if layout.sampling == "real":
        vals = w.reshape(-1, nv).astype(np.float32).astype(np.complex64)
        return _to_frames(vals, cfg, layout.interleaved)
    lanes = layout.lanes
    if nv % lanes:
        raise SettingsError(f"{cfg.source}: {nv} complex values per frame do not fill whole "
                            f"groups of {lanes} LVDS lanes")
    g = w.reshape(-1, 2, lanes).astype(np.float32)      # (groups, I|Q half, lane)
    first, second = g[:, 0, :], g[:, 1, :]
    re, im = (first, second) if layout.iq_order == "iq" else (second, first)
    vals = np.empty(re.shape, dtype=np.complex64)
    vals.real, vals.imag = re, im
    return _to_frames(vals.reshape(-1, nv), cfg, layout.interleaved)


def decode_tda2(device_words: list[np.ndarray], cfg: CaptureConfig, iq_order: str,
                rx_per_device: int = 4) -> np.ndarray:
    """Decode whole frames of an MMWCAS capture from its device files' words.

    Parameters
    ----------
    device_words
        int16 ``(F · words_per_device_frame,)`` per device, master first, then slave1..3.
    cfg
        The configuration; its RX channels are the devices' four RX each, in device order.
    iq_order
        ``"iq"`` (TI's TDA2 default: I first) or ``"qi"``.
    rx_per_device
        RX channels in each device's file.

    Returns
    -------
    numpy.ndarray
        complex64 ``(F, tx, rx, chirp, sample)``, RX in the order master RX0-3, slave1 RX0-3,
        slave2, slave3.
    """
    ntx, nl, ns = cfg.num_tx, cfg.num_loops, cfg.num_samples
    parts = []
    for w in device_words:
        a = np.asarray(w, dtype=np.int16).reshape(-1, nl, ntx, ns, rx_per_device, 2)
        a = a.astype(np.float32)
        re, im = (a[..., 0], a[..., 1]) if iq_order == "iq" else (a[..., 1], a[..., 0])
        c = np.empty(re.shape, dtype=np.complex64)
        c.real, c.imag = re, im
        parts.append(c.transpose(0, 2, 4, 1, 3))          # (F, tx, rx, loop, sample)
    return np.ascontiguousarray(np.concatenate(parts, axis=2))
