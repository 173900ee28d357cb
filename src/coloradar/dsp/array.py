"""Stage 5: the MIMO virtual array on the heatmap's azimuth × elevation FFT grid.

Physics (docs/conventions.md §3, :mod:`coloradar.sim.radar_if`): a virtual element at ``(p, q)`` half
wavelengths of ``F_design`` sees a far target in direction ``u = (u_x, u_y, u_z)`` with phase
``exp(−jπ·ρ·(s_a·p·u_y + s_e·q·u_z))`` relative to the origin, where ``ρ = f_c/F_design``
(carrier at mid-sampling over design frequency), ``u_y = cos(el)·sin(az)``, ``u_z = sin(el)``
and ``s_a``, ``s_e`` the azimuth/elevation sign settings (+1: the antenna file's ``az`` grows
toward +y and ``el`` toward +z). The beamformer ``B(u) = Σ_m z_m·exp(+jπρ(s_a p_m u_y + s_e q_m u_z))``
is an FFT over the element grid read at reversed indices; bin ``j`` of an ``N``-bin axis holds

    u_j = 2·(j − N//2) / (N·ρ)        (ascending with the angle, as heatmap_cfg requires)

so the true bin angles are ``el_j = asin(u_z,j)`` and, in the ``el = 0`` plane,
``az_i = asin(u_y,i)``. Off that plane the azimuth axis measures ``u_y = cos(el)·sin(az)``;
:meth:`AngleGrid.directions` gives the exact unit vector of every bin.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal, get_args

import numpy as np
import scipy.fft as sfft

from ..calib import AntennaConfig, VirtualArray
from ..errors import CalibrationError, SettingsError

__all__ = ["OVERLAP_MODES", "AngleGrid", "OverlapMode", "angle_grid", "beamform", "combine_channels",
           "pair_antennas", "phase_centre", "sines_to_unit"]

OverlapMode = Literal["first", "average"]
"""Virtual pairs sharing a position: keep the TX-major first one, or average them."""
OVERLAP_MODES: tuple[OverlapMode, ...] = get_args(OverlapMode)
"""How (TX, RX) pairs sharing a virtual position are combined."""


@dataclass(frozen=True, eq=False)
class AngleGrid:
    """Where each unique virtual element goes in the angle FFT, and what each output bin means.

    Attributes
    ----------
    num_el, num_az
        Output bins along elevation and azimuth.
    rho
        Carrier over design frequency, ``f_c / F_design``.
    el_pos, az_pos
        int64 ``(M,)``: element positions in half wavelengths, shifted so that the smallest is
        0 (a common shift changes only the spectrum's phase, never its magnitude).
    n_el, n_az
        FFT lengths: the smallest multiples of ``num_el``/``num_az`` that hold the aperture
        (then every ``n/N``-th FFT bin is an output bin: exact samples of the array response).
    el_read, az_read
        int64 ``(num_el,)``, ``(num_az,)``: FFT index of each output bin (signs included).
    el_sines, az_sines
        float64: ``u_z`` and ``u_y`` of each output bin (ascending).
    """

    num_el: int
    num_az: int
    rho: float
    azimuth_sign: int
    elevation_sign: int
    el_pos: np.ndarray
    az_pos: np.ndarray
    n_el: int
    n_az: int
    el_read: np.ndarray
    az_read: np.ndarray
    el_sines: np.ndarray
    az_sines: np.ndarray

    @property
    def num_elements(self) -> int:
        """Number of unique virtual elements ``M`` (the coherent gain of a beam)."""
        return int(self.el_pos.size)

    @property
    def elevation_angles(self) -> np.ndarray:
        """float64 ``(num_el,)``: ``asin(u_z)`` of each elevation bin [rad], ascending."""
        return _asin_ascending(self.el_sines)

    @property
    def azimuth_angles(self) -> np.ndarray:
        """float64 ``(num_az,)``: ``asin(u_y)`` of each azimuth bin [rad], the azimuth in the
        ``el = 0`` plane, ascending."""
        return _asin_ascending(self.az_sines)

    def directions(self) -> np.ndarray:
        """Unit vector of every (el, az) bin, float64 ``(num_el, num_az, 3)`` (x, y, z).

        Bins with ``u_y² + u_z² > 1`` lie outside the visible region; they get ``x = 0`` and
        ``(y, z)`` scaled to unit length.
        """
        uy = np.broadcast_to(self.az_sines[None, :], (self.num_el, self.num_az))
        uz = np.broadcast_to(self.el_sines[:, None], (self.num_el, self.num_az))
        return sines_to_unit(uy, uz)


def sines_to_unit(uy: np.ndarray, uz: np.ndarray) -> np.ndarray:
    """Unit vectors ``(..., 3)`` from direction sines ``u_y``, ``u_z`` (x ≥ 0 half-space)."""
    uy = np.asarray(uy, dtype=np.float64)
    uz = np.asarray(uz, dtype=np.float64)
    s2 = uy**2 + uz**2
    scale = np.where(s2 > 1.0, 1.0 / np.sqrt(np.maximum(s2, 1e-300)), 1.0)
    ux = np.sqrt(np.clip(1.0 - s2, 0.0, None))
    return np.stack([ux, uy * scale, uz * scale], axis=-1)


def _asin_ascending(u: np.ndarray) -> np.ndarray:
    a = np.arcsin(np.clip(u, -1.0, 1.0))
    if np.any(np.abs(u) >= 1.0):
        # ρ < 1: the outer bins are invisible and would all read ±90°; keep the list strictly
        # ascending as heatmap_cfg requires.
        a = a + np.arange(a.size) * 1e-9
    return a


def _axis(num: int, positions: np.ndarray, sign: int, rho: float
          ) -> tuple[int, np.ndarray, np.ndarray]:
    extent = int(positions.max()) + 1
    n_fft = num * -(-extent // num)
    step = n_fft // num
    j = np.arange(num) - num // 2
    read = (-sign * j * step) % n_fft
    sines = 2.0 * j / (num * rho)
    return n_fft, read.astype(np.int64), sines


def angle_grid(antenna: AntennaConfig, carrier_frequency: float, num_el: int, num_az: int,
               azimuth_sign: int = 1, elevation_sign: int = 1) -> AngleGrid:
    """The FFT angle grid of ``antenna``'s unique virtual elements.

    Parameters
    ----------
    antenna
        Antenna layout; positions must be whole half wavelengths (an FFT grid needs them).
    carrier_frequency
        Carrier at mid-sampling [Hz] (``WaveformConfig.center_frequency``).
    num_el, num_az
        Output bins (the heatmap's, or more for finer detection angles).
    azimuth_sign, elevation_sign
        +1 or −1 (docs/conventions.md §3).
    """
    if azimuth_sign not in (1, -1) or elevation_sign not in (1, -1):
        raise SettingsError("azimuth_sign and elevation_sign must be +1 or -1")
    pos = antenna.virtual.unique_positions
    ipos = np.rint(pos).astype(np.int64)
    if np.any(np.abs(pos - ipos) > 1e-6):
        raise CalibrationError("antenna layout: virtual positions are not whole half "
                               "wavelengths; an FFT angle grid cannot place them")
    ipos = ipos - ipos.min(axis=0)
    rho = carrier_frequency / antenna.design_frequency
    n_az, az_read, az_sines = _axis(num_az, ipos[:, 0], azimuth_sign, rho)
    n_el, el_read, el_sines = _axis(num_el, ipos[:, 1], elevation_sign, rho)
    return AngleGrid(num_el, num_az, float(rho), azimuth_sign, elevation_sign,
                     ipos[:, 1].copy(), ipos[:, 0].copy(), n_el, n_az, el_read, az_read,
                     el_sines, az_sines)


def combine_channels(cube: np.ndarray, virtual: VirtualArray, mode: OverlapMode = "first"
                     ) -> np.ndarray:
    """One signal per unique virtual position from a ``(tx, rx, ...)`` cube.

    Parameters
    ----------
    cube
        complex ``(tx, rx, ...)`` (TDM-compensated when Doppler matters).
    virtual
        The antenna's virtual array.
    mode
        ``"first"``: the first (TX-major) pair at each position; ``"average"``: the mean of all
        pairs there.

    Returns
    -------
    numpy.ndarray
        ``(M, ...)`` in the order of ``virtual.unique_positions``.
    """
    flat = cube.reshape((cube.shape[0] * cube.shape[1], *cube.shape[2:]))
    nrx = cube.shape[1]
    if mode == "first":
        return flat[virtual.first_pair[:, 0] * nrx + virtual.first_pair[:, 1]]
    if mode == "average":
        idx = virtual.index.ravel()
        order = np.argsort(idx, kind="stable")
        counts = np.bincount(idx, minlength=virtual.num_unique)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        sums = np.add.reduceat(flat[order], starts, axis=0)
        inv = (1.0 / counts).astype(flat.real.dtype)
        return sums * inv.reshape((-1,) + (1,) * (sums.ndim - 1))
    raise SettingsError(f"unknown overlap mode {mode!r}; expected one of {', '.join(OVERLAP_MODES)}")


def beamform(grid: AngleGrid, values: np.ndarray, el_pos: np.ndarray | None = None,
             az_pos: np.ndarray | None = None, workers: int = 1) -> np.ndarray:
    """Bartlett (FFT) beamformer output on the grid, ``B = Σ_m values_m · conj(a_m(u))``.

    Parameters
    ----------
    grid
        The angle grid.
    values
        complex ``(K, P)``: K independent vectors over P positions.
    el_pos, az_pos
        int ``(P,)`` positions (may be negative or repeat: repeated positions add up);
        None = the grid's unique elements.

    Returns
    -------
    numpy.ndarray
        complex64 ``(K, num_el, num_az)``, bins in ascending angle order, not normalised.
    """
    values = np.asarray(values)
    k = values.shape[0]
    if el_pos is None:
        el_pos, az_pos = grid.el_pos, grid.az_pos
        w_el, w_az = int(el_pos.max()) + 1, int(az_pos.max()) + 1
        buf = np.zeros((k, w_el, w_az), dtype=np.complex64)
        buf[:, el_pos, az_pos] = values
    else:
        flat = ((np.asarray(el_pos) % grid.n_el) * grid.n_az + (np.asarray(az_pos) % grid.n_az))
        idx = (np.arange(k)[:, None] * (grid.n_el * grid.n_az) + flat[None, :]).ravel()
        size = k * grid.n_el * grid.n_az
        re = np.bincount(idx, weights=values.real.ravel(), minlength=size)
        im = np.bincount(idx, weights=values.imag.ravel(), minlength=size)
        buf = (re + 1j * im).astype(np.complex64).reshape(k, grid.n_el, grid.n_az)
    spec = sfft.fft(buf, n=grid.n_az, axis=2, workers=workers)
    spec = sfft.fft(spec, n=grid.n_el, axis=1, workers=workers, overwrite_x=True)
    return spec[:, grid.el_read[:, None], grid.az_read[None, :]]


def phase_centre(antenna: AntennaConfig, azimuth_sign: int = 1, elevation_sign: int = 1
                 ) -> np.ndarray:
    """Phase centre of the unique virtual elements in the radar frame, float64 ``(3,)`` [m].

    The virtual element of a (TX, RX) pair sits, for the two-way path, at the midpoint
    ``(p_tx + p_rx)/2`` of the two antennas: the range FFT of that channel measures
    ``(|x − p_tx| + |x − p_rx|)/2 ≈ |x − (p_tx + p_rx)/2|``. A beam over the unique elements
    (equal weights) therefore measures range and direction from their centroid, not from the
    radar origin where the antenna file's coordinates start (docs/dsp.md, "Where a point
    is").
    """
    pos = antenna.virtual.unique_positions.astype(np.float64).mean(axis=0)   # (az, el) half-λ
    half = 0.5 * antenna.half_wavelength
    return np.array([0.0, azimuth_sign * pos[0] * half, elevation_sign * pos[1] * half])


def pair_antennas(antenna: AntennaConfig, azimuth_sign: int = 1, elevation_sign: int = 1
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Transmit and receive antenna of each unique virtual element's first pair.

    Returns
    -------
    tuple
        float64 ``(M, 3)`` each [m], radar frame (x = 0; y, z from the antenna file's az, el
        with the sign settings), in the order of ``virtual.unique_positions``.
    """
    first = antenna.virtual.first_pair
    sign = np.array([azimuth_sign, elevation_sign], dtype=np.float64)
    out = []
    for pos, idx in ((antenna.tx_positions, first[:, 0]), (antenna.rx_positions, first[:, 1])):
        p = np.zeros((idx.size, 3))
        p[:, 1:] = np.asarray(pos, dtype=np.float64)[idx] * sign * antenna.half_wavelength
        out.append(p)
    return out[0], out[1]
