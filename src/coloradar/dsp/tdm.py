"""Stage 4: TDM-MIMO Doppler phase compensation.

With time-division MIMO, TX slot ``t`` of chirp loop ``c`` starts at ``(c·Ntx + t)·Tc``
(docs/conventions.md §3). A target whose Doppler frequency is ``k/n`` cycles per loop (signed Doppler bin
``k`` of an ``n``-point Doppler FFT) therefore reaches TX slot ``t`` with an extra phase
``2π·k·t/(n·Ntx)``, which the angle FFT would read as a spurious angle. Compensation multiplies
TX ``t`` by ``exp(−j2π·k·t/(n·Ntx))``, exact at bin centres and for fractional ``k``.

Doppler beyond ±v_max (disambiguation)
--------------------------------------
The Doppler FFT sees ``k`` only modulo ``n``: a target whose true Doppler is ``k + m·n`` (alias
``m``, range rate ``(k + m·n)·Δv``) lands in bin ``k`` but reaches TX slot ``t`` with the extra
phase ``2π·m·t/Ntx``, which compensation at ``k`` leaves in place. Hypothesis ``m`` is tested by
compensating that phase too (:func:`alias_phase`); only ``m mod Ntx`` changes the phases, so
``Ntx`` consecutive hypotheses are distinguishable (range rates within ``±Ntx·v_max``). How a
hypothesis is scored:

* **overlapping virtual pairs** (:class:`OverlapPairs`, cascade): two (TX, RX) pairs at the
  same virtual position see the same geometric phase, so after compensation for the right
  ``m`` their product ``z_a·z_b*`` is real and positive; for a wrong one it turns by
  ``2π·(m − m_true)·(t_a − t_b)/Ntx``. The score is ``Re Σ z_a z_b* e^{−j2π m (t_a − t_b)/Ntx}``
  (normalised by ``Σ|z_a||z_b|``). The cascade's 58 overlaps include slot differences of 1, so
  every ``m mod 12`` gives a different score pattern and no angle search is needed;
* **angle-spectrum peak** (arrays without such pairs, single chip): a wrong ``m`` puts phase
  steps between the TX blocks of the aperture, which defocuses the beam; the hypothesis whose
  Bartlett spectrum has the highest peak wins. Blocks that differ only in elevation (the single
  chip's elevated TX) cannot tell a TDM phase from an elevation; its azimuth row (TX 0 and
  TX 1, slots 0 and 1) does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..calib import VirtualArray
from .cube import signed_doppler_bins

__all__ = ["OverlapPairs", "alias_hypotheses", "alias_phase", "compensate_tdm", "overlap_pairs",
           "tdm_phase"]


def tdm_phase(num_tx: int, doppler_bins: np.ndarray | float, fft_size: int) -> np.ndarray:
    """Compensation factors ``exp(−j2π·k·t/(n·Ntx))``.

    Parameters
    ----------
    num_tx
        Number of TX slots per chirp loop.
    doppler_bins
        Signed (possibly fractional) Doppler bins ``k``, any shape ``S``.
    fft_size
        Doppler FFT length ``n``.

    Returns
    -------
    numpy.ndarray
        complex64 ``(num_tx, *S)``.
    """
    k = np.asarray(doppler_bins, dtype=np.float64)
    t = np.arange(num_tx).reshape((num_tx,) + (1,) * k.ndim)
    return np.exp(-2j * np.pi * t * k / (fft_size * num_tx)).astype(np.complex64)


def compensate_tdm(rd_cube: np.ndarray) -> np.ndarray:
    """Compensate a range–Doppler cube whose Doppler axis is centred (as :func:`doppler_fft`).

    Parameters
    ----------
    rd_cube
        complex ``(tx, rx, doppler, range)``.

    Returns
    -------
    numpy.ndarray
        complex64, same shape.
    """
    ntx, _, nd, _ = rd_cube.shape
    ph = tdm_phase(ntx, signed_doppler_bins(nd), nd)
    return (rd_cube * ph[:, None, :, None]).astype(np.complex64, copy=False)


def alias_hypotheses(num_tx: int, max_velocity: float, limit: float) -> np.ndarray:
    """Alias numbers ``m`` to test for range rates up to ``limit``, ordered by ``|m|``.

    Parameters
    ----------
    num_tx
        TX slots per loop: at most ``num_tx`` hypotheses are distinguishable.
    max_velocity
        ``v_max`` [m/s] (folded range rates lie in ``[−v_max, v_max)``).
    limit
        Largest ``|range rate|`` searched [m/s]; 0 = no search (``[0]``).

    Returns
    -------
    numpy.ndarray
        int64, ``0, 1, −1, 2, −2, …``: every ``m`` for which some folded rate gives
        ``|v + 2m·v_max| ≤ limit``, at most ``num_tx`` of them (nearest first).
    """
    if limit <= 0:
        return np.zeros(1, dtype=np.int64)
    big = int(np.ceil((limit + max_velocity) / (2.0 * max_velocity)))
    ms = [0] + [s * k for k in range(1, big + 1) for s in (1, -1)]
    ms = [m for m in ms if abs(m) * 2.0 * max_velocity - max_velocity <= limit]
    return np.asarray(ms[:num_tx], dtype=np.int64)


def alias_phase(num_tx: int, aliases: np.ndarray) -> np.ndarray:
    """Extra compensation ``exp(−j2π·m·t/Ntx)`` of alias ``m``: complex64 ``(num_tx, *m.shape)``."""
    m = np.asarray(aliases, dtype=np.float64)
    t = np.arange(num_tx).reshape((num_tx,) + (1,) * m.ndim)
    return np.exp(-2j * np.pi * t * m / num_tx).astype(np.complex64)


@dataclass(frozen=True, eq=False)
class OverlapPairs:
    """(TX, RX) pairs at the same virtual position with different TX slots.

    Attributes
    ----------
    a, b
        int64 ``(P,)``: flat channel indices ``tx·Nrx + rx`` of the two pairs.
    slot_difference
        int64 ``(P,)``: ``t_a − t_b``.
    num_tx
        TX slots per loop.
    """

    a: np.ndarray
    b: np.ndarray
    slot_difference: np.ndarray
    num_tx: int

    def __len__(self) -> int:
        return int(self.a.size)

    def resolves(self, aliases: np.ndarray, margin: float = 0.5) -> bool:
        """Whether every two hypotheses' noise-free score patterns differ enough: for each
        ``m ≠ m'`` the wrong one's normalised score stays below ``1 − margin``."""
        if len(self) == 0:
            return False
        m = np.asarray(aliases)
        dm = (m[:, None] - m[None, :])[..., None] * self.slot_difference
        score = np.cos(2.0 * np.pi * dm / self.num_tx).mean(axis=-1)
        off = ~np.eye(m.size, dtype=bool)
        return bool(np.all(score[off] < 1.0 - margin))

    def scores(self, channels: np.ndarray, aliases: np.ndarray) -> np.ndarray:
        """Normalised pair coherence of each hypothesis.

        Parameters
        ----------
        channels
            complex ``(K, tx·rx)``: TDM-compensated (at the folded Doppler) channel vectors.
        aliases
            int ``(H,)``: hypotheses ``m``.

        Returns
        -------
        numpy.ndarray
            float64 ``(K, H)`` in ``[−1, 1]``: 1 = every pair in phase after compensating
            ``m``.
        """
        x = np.asarray(channels)
        prod = x[:, self.a] * np.conj(x[:, self.b])                          # (K, P)
        rot = np.exp(-2j * np.pi * np.outer(self.slot_difference, aliases) / self.num_tx)
        num = (prod @ rot.astype(prod.dtype)).real                          # (K, H)
        den = np.abs(prod).sum(axis=1, keepdims=True)
        return np.asarray(num / np.maximum(den, 1e-30), dtype=np.float64)


def overlap_pairs(virtual: VirtualArray) -> OverlapPairs:
    """Every pair of (TX, RX) channels that share a virtual position with different TX slots
    (TX index = slot, as the frame layout ``(tx, rx, chirp, sample)`` holds them)."""
    ntx, nrx = virtual.index.shape
    idx = virtual.index.ravel()
    tx = np.repeat(np.arange(ntx), nrx)
    flat = np.arange(ntx * nrx)
    a, b = [], []
    for u in np.flatnonzero(np.bincount(idx, minlength=virtual.num_unique) > 1):
        members = flat[idx == u]
        for i in range(members.size):
            for j in range(i + 1, members.size):
                if tx[members[i]] != tx[members[j]]:
                    a.append(members[j])
                    b.append(members[i])
    a_ = np.asarray(a, dtype=np.int64)
    b_ = np.asarray(b, dtype=np.int64)
    return OverlapPairs(a_, b_, tx[a_] - tx[b_] if a_.size else a_, ntx)
