"""Antenna coupling calibration (``coupling_calib.txt``).

The file holds the range FFT of a capture with no target in view, per (TX, RX): the leakage
and near-field coupling that every frame carries. It is subtracted in the range-FFT domain.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError, CalibrationWarning
from ..formats.atomic import atomic_write_text, new_output_path
from ..formats.source import read_file_text
from ._parse import check_finite, get_number, key_values, readonly

__all__ = ["CouplingCalib", "format_coupling_calib", "parse_coupling_calib", "read_coupling_calib",
           "write_coupling_calib"]


@dataclass(frozen=True, eq=False)
class CouplingCalib:
    """Coupling range profile to subtract.

    Attributes
    ----------
    data
        complex64 ``(tx, rx, range)``: the range FFT (no window, no normalisation, as the file
        holds it) of a target-free capture, for the first ``num_range_bins`` range bins.
    num_doppler_bins
        Chirp loops of the capture (informative).
    missing_tx
        TX indices whose block in the file is all zeros (no coupling measured for them).
    """

    data: np.ndarray
    num_doppler_bins: int
    missing_tx: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        d = np.asarray(self.data)
        if d.ndim != 3 or not np.iscomplexobj(d):
            raise CalibrationError(f"coupling: expected complex (tx, rx, range) data, got {d.shape}")
        object.__setattr__(self, "data", readonly(d.astype(np.complex64)))

    @property
    def num_tx(self) -> int:
        return int(self.data.shape[0])

    @property
    def num_rx(self) -> int:
        return int(self.data.shape[1])

    @property
    def num_range_bins(self) -> int:
        return int(self.data.shape[2])


def parse_coupling_calib(text: str, name: str = "coupling_calib.txt") -> CouplingCalib:
    """Parse ``coupling_calib.txt``: ``key:value`` lines, then ``data:`` re/im interleaved,
    order [tx][rx][range].

    An all-zero TX block (the real single-chip file's TX 2) is kept as zeros (nothing subtracted)
    and reported with a :class:`CalibrationWarning`.
    """
    kv = key_values(text, name, sep=":")
    ntx = get_number(kv, "num_tx", name, int)
    nrx = get_number(kv, "num_rx", name, int)
    nr = get_number(kv, "num_range_bins", name, int)
    nd = get_number(kv, "num_doppler_bins", name, int)
    if "data" not in kv:
        raise CalibrationError(f"{name}: missing 'data:' line")
    tokens = [t for t in kv["data"][0].replace(",", " ").split()]
    try:
        vals = np.array(tokens, dtype=np.float64)
    except ValueError:
        raise CalibrationError(f"{name}: 'data:' holds something that is not a number") from None
    for key, n in (("num_tx", ntx), ("num_rx", nrx), ("num_range_bins", nr),
                   ("num_doppler_bins", nd)):
        if not 1 <= n <= 65536:
            raise CalibrationError(f"{name}: {key} = {n} is outside 1..65536")
    check_finite(vals, name, "'data:'")
    expected = 2 * ntx * nrx * nr
    if vals.size != expected:
        raise CalibrationError(f"{name}: expected {expected} data values (2 x {ntx} tx x {nrx} rx "
                               f"x {nr} range bins), found {vals.size}")
    data = (vals[0::2] + 1j * vals[1::2]).reshape(ntx, nrx, nr)
    missing = tuple(int(t) for t in np.flatnonzero(~np.any(data != 0, axis=(1, 2))))
    if missing:
        warnings.warn(f"{name}: the coupling block of TX {', '.join(map(str, missing))} is all "
                      "zeros; no coupling will be removed for it", CalibrationWarning, stacklevel=3)
    return CouplingCalib(data=data, num_doppler_bins=nd, missing_tx=missing)


def format_coupling_calib(c: CouplingCalib) -> str:
    """The dataset's ``coupling_calib.txt`` text for ``c``."""
    flat = c.data.reshape(-1)
    inter = np.empty(flat.size * 2, dtype=np.float64)
    inter[0::2] = flat.real
    inter[1::2] = flat.imag
    return (f"num_tx:{c.num_tx}\nnum_rx:{c.num_rx}\nnum_range_bins:{c.num_range_bins}\n"
            f"num_doppler_bins:{c.num_doppler_bins}\n"
            "data:" + ",".join(f"{v:g}" for v in inter) + "\n")


def read_coupling_calib(path: str | os.PathLike[str]) -> CouplingCalib:
    """Read a ``coupling_calib.txt`` file (the release's, or one written by
    :func:`write_coupling_calib`); errors name the file."""
    return parse_coupling_calib(read_file_text(path), str(path))


def write_coupling_calib(path: str | os.PathLike[str], c: CouplingCalib,
                         overwrite: bool = False) -> None:
    """Write ``c`` as a ``coupling_calib.txt`` file, atomically (whole or not at all).

    The text is the release's format (:func:`format_coupling_calib`: ``%g`` values, six
    significant digits, as the released files hold them).

    Raises
    ------
    OutputExistsError
        ``path`` exists and ``overwrite`` is not set.
    """
    atomic_write_text(new_output_path(path, overwrite), format_coupling_calib(c))
