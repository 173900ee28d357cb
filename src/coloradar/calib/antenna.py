"""Antenna layout (``antenna_cfg.txt``) and the MIMO virtual array.

Positions are in half wavelengths at the design frequency ``F_design``: the ``az`` coordinate
grows toward the radar's +y (left), ``el`` toward +z (up) (docs/conventions.md §3). Cascade (MMWCAS-RF-EVM)
virtual array, azimuth along →, elevation ↑ (each ``o`` one unique virtual element)::

    el 6 |           oooo…
    el 4 |         oooo…
    el 1 |     oooo…
    el 0 | oooooooooooooooooooooooooooooooooooooooooooooo…   (86 unique positions at el 0)
         +-------------------------------------------------> az (half wavelengths)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import CalibrationError
from ._parse import readonly, strip_comment
from .waveform import SPEED_OF_LIGHT

__all__ = ["AntennaConfig", "VirtualArray", "format_antenna_cfg", "parse_antenna_cfg"]


@dataclass(frozen=True, eq=False)
class VirtualArray:
    """The virtual array of a TDM-MIMO radar: one element per (TX, RX) pair.

    Attributes
    ----------
    positions
        float64 ``(tx, rx, 2)``: ``tx + rx`` positions ``(az, el)`` in half wavelengths at
        ``F_design``.
    unique_positions
        float64 ``(M, 2)``: the distinct positions, sorted by (el, az).
    index
        int64 ``(tx, rx)``: for each pair, its row in ``unique_positions``.
    first_pair
        int64 ``(M, 2)``: the first ``(tx, rx)`` pair (TX-major order) at each unique position.
    """

    positions: np.ndarray
    unique_positions: np.ndarray
    index: np.ndarray
    first_pair: np.ndarray

    @property
    def num_unique(self) -> int:
        """Number of distinct virtual element positions."""
        return int(self.unique_positions.shape[0])

    @property
    def num_overlapping(self) -> int:
        """Number of (TX, RX) pairs that share a position with an earlier pair."""
        return int(self.index.size - self.num_unique)


@dataclass(frozen=True, eq=False)
class AntennaConfig:
    """TX and RX antenna positions of one radar.

    Attributes
    ----------
    design_frequency
        ``F_design`` [Hz]: the positions are in half wavelengths at this frequency.
    rx_positions, tx_positions
        float64 ``(num_rx, 2)`` and ``(num_tx, 2)``: ``(az, el)`` in half wavelengths, row i =
        antenna index i (whatever order the file listed them in).
    """

    design_frequency: float
    rx_positions: np.ndarray
    tx_positions: np.ndarray
    virtual: VirtualArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        rx = readonly(np.asarray(self.rx_positions, dtype=np.float64).reshape(-1, 2))
        tx = readonly(np.asarray(self.tx_positions, dtype=np.float64).reshape(-1, 2))
        object.__setattr__(self, "rx_positions", rx)
        object.__setattr__(self, "tx_positions", tx)
        object.__setattr__(self, "virtual", _virtual_array(tx, rx))

    @property
    def num_rx(self) -> int:
        return int(self.rx_positions.shape[0])

    @property
    def num_tx(self) -> int:
        return int(self.tx_positions.shape[0])

    @property
    def half_wavelength(self) -> float:
        """The unit of the positions in metres, ``c / (2·F_design)``."""
        return SPEED_OF_LIGHT / (2.0 * self.design_frequency)

    def virtual_positions_m(self) -> np.ndarray:
        """Virtual element positions ``(tx, rx, 2)`` in metres (``(az, el)`` = (y, z) offsets)."""
        return self.virtual.positions * self.half_wavelength


def _virtual_array(tx: np.ndarray, rx: np.ndarray) -> VirtualArray:
    pos = tx[:, None, :] + rx[None, :, :]
    flat = pos.reshape(-1, 2)
    # Sort by (el, az); np.unique on rows returns the first occurrence index in flat (TX-major).
    keys = np.round(flat[:, ::-1] * 1e6).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    ntx, nrx = pos.shape[:2]
    first_pair = np.stack(np.unravel_index(first, (ntx, nrx)), axis=1)
    return VirtualArray(
        positions=readonly(pos),
        unique_positions=readonly(flat[first]),
        index=readonly(inverse.reshape(ntx, nrx).astype(np.int64)),
        first_pair=readonly(first_pair.astype(np.int64)),
    )


_MAX_POSITION = 1000.0
"""Largest antenna coordinate accepted [half wavelengths] (about 2 m at 77 GHz)."""


def parse_antenna_cfg(text: str, name: str = "antenna_cfg.txt") -> AntennaConfig:
    """Parse ``antenna_cfg.txt``: ``num_rx``, ``num_tx``, ``F_design`` [GHz], ``rx|tx idx az el``.

    Antenna lines may come in any order and have trailing spaces; every index from 0 to n-1 must
    appear exactly once.
    """
    counts: dict[str, int] = {}
    f_design = None
    ants: dict[str, dict[int, tuple[float, float]]] = {"rx": {}, "tx": {}}
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = strip_comment(raw)
        if not line:
            continue
        parts = line.split()
        key = parts[0]
        try:
            if key in ("num_rx", "num_tx") and len(parts) == 2:
                counts[key] = int(parts[1])
            elif key == "F_design" and len(parts) == 2:
                f_design = float(parts[1]) * 1e9
            elif key in ("rx", "tx") and len(parts) == 4:
                idx = int(parts[1])
                if idx in ants[key]:
                    raise CalibrationError(f"{name}, line {lineno}: {key} {idx} listed twice")
                ants[key][idx] = (float(parts[2]), float(parts[3]))
            else:
                raise CalibrationError(f"{name}, line {lineno}: unexpected line {line[:60]!r}; "
                                       "expected num_rx N, num_tx N, F_design GHz or rx|tx idx az el")
        except CalibrationError:
            raise
        except ValueError:
            raise CalibrationError(f"{name}, line {lineno}: expected numbers in {line[:60]!r}") from None
    if f_design is None:
        raise CalibrationError(f"{name}: missing F_design")
    if not (math.isfinite(f_design) and 1e9 <= f_design <= 1e12):
        raise CalibrationError(f"{name}: F_design = {f_design / 1e9:g} GHz is not physically "
                               "sensible; expected a finite value in [1, 1000] GHz")
    arrays = {}
    for kind in ("rx", "tx"):
        n = counts.get(f"num_{kind}")
        if n is None:
            raise CalibrationError(f"{name}: missing num_{kind}")
        if sorted(ants[kind]) != list(range(n)):
            raise CalibrationError(f"{name}: expected {kind} indices 0..{n - 1}, "
                                   f"found {sorted(ants[kind])}")
        arrays[kind] = np.array([ants[kind][i] for i in range(n)], dtype=np.float64)
        # A NaN position gives NaN steering vectors and NaN points downstream; an antenna
        # thousands of half wavelengths away (metres at 77 GHz) is no radar board.
        bad = [i for i in range(n) if not all(math.isfinite(v) and abs(v) <= _MAX_POSITION
                                              for v in ants[kind][i])]
        if bad:
            az, el = ants[kind][bad[0]]
            raise CalibrationError(f"{name}: {kind} {bad[0]} at az {float(az):g}, el {float(el):g}; expected "
                                   f"finite positions within ±{_MAX_POSITION:g} half wavelengths")
    return AntennaConfig(f_design, arrays["rx"], arrays["tx"])


def format_antenna_cfg(a: AntennaConfig, title: str = "antenna layout") -> str:
    """The dataset's ``antenna_cfg.txt`` text for ``a``."""
    lines = [f"# {title}", "# distances specified in half-wavelengths of F_design",
             f"num_rx {a.num_rx}", f"num_tx {a.num_tx}", f"F_design {a.design_frequency / 1e9!r}"]
    lines += [f"rx {i} {p[0]:g} {p[1]:g}" for i, p in enumerate(a.rx_positions)]
    lines += [f"tx {i} {p[0]:g} {p[1]:g}" for i, p in enumerate(a.tx_positions)]
    return "\n".join(lines) + "\n"
