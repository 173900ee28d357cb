"""Antenna layouts of the TI boards a capture may come from, by physical TX and RX number.

Positions are ``(az, el)`` in half wavelengths at the board's design frequency, with ``az``
toward the radar's +y and ``el`` toward +z (docs/conventions.md §3). TX ``k`` is bit ``k`` of a
device's TX enable mask (``3·device + bit`` on the cascade), RX ``k`` bit ``k`` of its RX mask
(``4·device + bit``). An imported run's ``antenna_cfg.txt`` lists, for each TX slot of the
chirp loop and each RX channel of the data, the position of the antenna it used
(:func:`run_antenna`). Sources of the numbers: docs/capture.md "Boards".
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..calib import AntennaConfig, parse_antenna_cfg
from ..errors import ReadError, SettingsError

__all__ = ["BOARDS", "Board", "get_board", "run_antenna"]


@dataclass(frozen=True)
class Board:
    """A radar board: its antennas by physical number and the dataset radar it becomes.

    Attributes
    ----------
    name
        The board's name (``AWR1843BOOST``…).
    radar
        ``"single_chip"`` or ``"cascade"``: the run folder its data is written to.
    tx, rx
        ``(az, el)`` of TX ``k`` / RX ``k`` [half wavelengths at ``design_frequency``].
    design_frequency
        [Hz].
    num_devices
        Chips whose data files make one frame.
    """

    name: str
    radar: str
    tx: tuple[tuple[float, float], ...]
    rx: tuple[tuple[float, float], ...]
    design_frequency: float
    num_devices: int = 1


# AWR1843BOOST (TI SWRU546 / the xWR18xx SDK demo's virtual array): four RX at λ/2; TX1 and
# TX3 two RX-array widths (2λ) apart in azimuth, TX2 between them, λ/2 up.
_XWR18_TX = ((0.0, 0.0), (2.0, 1.0), (4.0, 0.0))
_XWR18_RX = ((0.0, 0.0), (1.0, 0.0), (2.0, 0.0), (3.0, 0.0))

# MMWCAS-RF-EVM (TI's cascade MATLAB scripts, module_param.m): TX 1..12 are master TX1-3,
# slave1 TX1-3, slave2 TX1-3, slave3 TX1-3; RX channel k of the concatenated device files
# (master RX0-3, slave1, slave2, slave3) lies at TI_Cascade_RX_position_azi[k].
_CASCADE_TX = ((11.0, 6.0), (10.0, 4.0), (9.0, 1.0), (32.0, 0.0), (28.0, 0.0), (24.0, 0.0),
               (20.0, 0.0), (16.0, 0.0), (12.0, 0.0), (8.0, 0.0), (4.0, 0.0), (0.0, 0.0))
_CASCADE_RX = tuple((float(a), 0.0) for a in (*range(11, 15), *range(50, 54), *range(46, 50),
                                              *range(0, 4)))

BOARDS: dict[str, Board] = {
    "awr1843boost": Board("AWR1843BOOST", "single_chip", _XWR18_TX, _XWR18_RX, 76.8e9),
    # IWR6843ISK: the same TX/RX geometry as the xWR18xx boosters (TX2 raised by λ/2), in the
    # 60-64 GHz band; its design frequency is not published, 62 GHz (the band's middle) is
    # assumed (docs/capture.md).
    "iwr6843isk": Board("IWR6843ISK", "single_chip", _XWR18_TX, _XWR18_RX, 62.0e9),
    "mmwcas-rf-evm": Board("MMWCAS-RF-EVM", "cascade", _CASCADE_TX, _CASCADE_RX, 76.8e9, 4),
}
"""The known boards by lower-case name."""

_ALIASES = {"awr1843": "awr1843boost", "xwr1843": "awr1843boost", "iwr1843": "awr1843boost",
            "iwr1843boost": "awr1843boost", "iwr6843": "iwr6843isk", "xwr6843": "iwr6843isk",
            "mmwcas": "mmwcas-rf-evm", "cascade": "mmwcas-rf-evm", "awr2243": "mmwcas-rf-evm"}


def _user_board(path: Path, radar: str) -> Board:
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ReadError(f"{path}: cannot read the antenna layout ({exc.strerror or exc})") from None
    ant = parse_antenna_cfg(text, str(path))
    return Board(path.name, radar, tuple(map(tuple, ant.tx_positions.tolist())),
                 tuple(map(tuple, ant.rx_positions.tolist())), ant.design_frequency,
                 4 if radar == "cascade" else 1)


def get_board(board: str | os.PathLike[str], radar: str = "single_chip") -> Board:
    """A known board by name (case-insensitive: ``AWR1843BOOST``, ``IWR6843ISK``,
    ``MMWCAS-RF-EVM`` and device names such as ``awr1843``), or a user layout: the path of an
    ``antenna_cfg.txt`` listing the board's TX and RX by physical number (``radar`` says which
    dataset radar it becomes).

    Raises
    ------
    SettingsError
        An unknown name, listing the known boards.
    """
    text = os.fspath(board)
    key = text.strip().lower()
    key = _ALIASES.get(key, key)
    if key in BOARDS:
        return BOARDS[key]
    p = Path(text)
    if p.suffix.lower() == ".txt" or p.is_file():
        if not p.is_file():
            raise ReadError(f"{p}: antenna layout file not found")
        return _user_board(p, radar)
    raise SettingsError(f"unknown board {text!r}; expected one of "
                        f"{', '.join(b.name for b in BOARDS.values())} (or the path of an "
                        "antenna_cfg.txt with the board's TX and RX positions)")


def run_antenna(board: Board, tx_slots: tuple[int, ...], rx_channels: tuple[int, ...],
                where: str) -> AntennaConfig:
    """The run's antenna layout: TX slot ``t`` at the position of TX ``tx_slots[t]``, RX channel
    ``k`` at that of RX ``rx_channels[k]``.

    Raises
    ------
    SettingsError
        A TX or RX the configuration uses that the board does not have.
    """
    for kind, used, have in (("TX", tx_slots, board.tx), ("RX", rx_channels, board.rx)):
        bad = sorted({i for i in used if not 0 <= i < len(have)})
        if bad:
            raise SettingsError(f"{where}: uses {kind} {', '.join(map(str, bad))} but the "
                                f"{board.name} has {kind} 0..{len(have) - 1}")
    tx = np.array([board.tx[i] for i in tx_slots], dtype=np.float64)
    rx = np.array([board.rx[i] for i in rx_channels], dtype=np.float64)
    return AntennaConfig(board.design_frequency, rx, tx)
