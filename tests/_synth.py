"""A tiny synthetic ColoRadar run written with the format writers, for the foundation tests.

The content is random but known, so reads can be compared with what was written.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np

from coloradar import formats as fm
from coloradar.calib import Calibration, preset_calibration, write_calibration

# The real calibration of the release (read, never copied): beside the checkout as CI lays it out,
# or wherever COLORADAR_REFERENCE_CALIB points (worktrees, other machines).
REFERENCE_CALIB = Path(os.environ.get(
    "COLORADAR_REFERENCE_CALIB",
    Path(__file__).resolve().parents[1].parent / "shared" / "reference" / "coloradar_calib"))


def write_run(root: Path, name: str = "12_21_2020_ec_hallways_run0", *, calib: Calibration | None = None,
              n_cascade: int = 2, n_single: int = 3, n_lidar: int = 2, n_imu: int = 30, n_gt: int = 8,
              base: int = 0, vicon: bool = False, seed: int = 0, write_calib: bool = True) -> dict:
    """Write a run folder ``root/name`` (and ``root/calib``); return what was written."""
    rng = np.random.default_rng(seed)
    calib = calib or preset_calibration()
    run = root / name
    t0 = 1_608_580_000.123456
    truth: dict = {"path": run}

    def frames(folder: str, data: str, prefix: str, arrays, rate: float, writer):
        ts = t0 + np.arange(len(arrays)) / rate + rng.uniform(0, 1e-3, len(arrays))
        fm.write_timestamps(run / folder / "timestamps.txt", ts)
        for i, a in enumerate(arrays):
            writer(run / data / f"{prefix}_{i + base}.bin", a)
        truth[f"{folder.split('/')[0]}/{prefix}"] = (ts, arrays)

    for radar, n, rate in (("cascade", n_cascade, 5.0), ("single_chip", n_single, 10.0)):
        rc = calib.radar(radar)
        adc = [(rng.integers(-2000, 2000, rc.frame_shape)
                + 1j * rng.integers(-2000, 2000, rc.frame_shape)).astype(np.complex64) for _ in range(n)]
        frames(f"{radar}/adc_samples", f"{radar}/adc_samples/data", "frame", adc, rate, fm.write_adc)
        hm = [rng.random((*rc.heatmap_shape, 2), dtype=np.float32) for _ in range(n)]
        frames(f"{radar}/heatmaps", f"{radar}/heatmaps/data", "heatmap", hm, rate, fm.write_heatmap)
    pcs = [rng.standard_normal((int(rng.integers(5, 40)), 5)).astype(np.float32) for _ in range(n_single)]
    frames("single_chip/pointclouds", "single_chip/pointclouds/data", "radar_pointcloud", pcs, 10.0,
           fm.write_radar_pointcloud)
    lid = [rng.standard_normal((100, 4)).astype(np.float32) for _ in range(n_lidar)]
    frames("lidar", "lidar/pointclouds", "lidar_pointcloud", lid, 10.0, fm.write_lidar_pointcloud)

    imu_t = t0 + np.arange(n_imu) / 300.0
    imu = rng.standard_normal((n_imu, 6))
    fm.write_timestamps(run / "imu" / "timestamps.txt", imu_t)
    fm.write_imu(run / "imu" / "imu_data.txt", imu)
    truth["imu"] = (imu_t, imu)
    for kind, n in (("groundtruth", n_gt),) + ((("vicon", n_gt),) if vicon else ()):
        gt_t = t0 + np.arange(n) / 10.0
        q = rng.standard_normal((n, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        poses = np.hstack([rng.standard_normal((n, 3)), q])
        fm.write_timestamps(run / kind / "timestamps.txt", gt_t)
        fm.write_poses(run / kind / f"{kind}_poses.txt", poses)
        truth[kind] = (gt_t, poses)
    if write_calib:
        write_calibration(calib, root / "calib")
    return truth


def zip_folder(folder: Path, archive: Path, top: str | None = None) -> Path:
    """Zip ``folder``'s content, under the folder name ``top`` (None: at the archive's root)."""
    with zipfile.ZipFile(archive, "w", compression=zipfile.ZIP_STORED) as zf:
        for p in sorted(folder.rglob("*")):
            rel = p.relative_to(folder).as_posix()
            zf.write(p, f"{top}/{rel}" if top else rel)
    return archive


def exact_adc(calib, positions, velocities=None, amplitudes=1.0, *, noise_std: float = 0.0,
              rng=None) -> np.ndarray:
    """ADC frame of point scatterers from the exact spherical-wave delays (tests only).

    Independent of coloradar's processor and of the simulator's narrowband model: for every
    TX ``t``, RX ``r``, chirp loop ``c`` and sample ``n`` the scatterer sits at
    ``x(T) = x0 + v·T`` (``T`` = chirp start ``(c·Ntx + t)·Tc`` + sample time ``t_n``), the
    delay is ``τ = (|x(T) − p_t| + |x(T) − p_r|)/c0`` with the antennas at ``(0, y, z)`` of the
    antenna file (half wavelengths of the design frequency), and the IF sample is
    ``a/R0² · exp(j2π(f_start·τ + S·t_n·τ − S·τ²/2))`` (TI's complex baseband, receding =
    growing delay). Range migration, the beat-frequency shift of each antenna's own path
    length and the range–Doppler coupling are all in it.

    Parameters are as :func:`coloradar.sim.synthesize_adc`; returns complex64
    ``(tx, rx, chirp, sample)``.
    """
    c0 = 299_792_458.0
    w, ant = calib.waveform, calib.antenna
    p = np.atleast_2d(np.asarray(positions, dtype=np.float64))
    v = np.zeros_like(p) if velocities is None else np.atleast_2d(np.asarray(velocities, float))
    a = np.broadcast_to(np.asarray(amplitudes, dtype=np.complex128), (p.shape[0],))
    ntx, nrx, nc, ns = w.frame_shape
    hw = ant.half_wavelength
    tx = np.zeros((ntx, 3))
    tx[:, 1:] = ant.tx_positions * hw
    rx = np.zeros((nrx, 3))
    rx[:, 1:] = ant.rx_positions * hw
    t_n = w.adc_start_time + np.arange(ns) / w.sample_rate                      # (ns,)
    t_chirp = ((np.arange(nc)[None, :] * ntx + np.arange(ntx)[:, None])
               * (w.idle_time + w.ramp_end_time))                               # (tx, c)
    big_t = t_chirp[:, None, :, None] + t_n[None, None, None, :]                # (tx, 1, c, ns)
    out = np.zeros((ntx, nrx, nc, ns), dtype=np.complex128)
    for x0, vk, ak in zip(p, v, a, strict=True):
        pos = x0[None, None, None, None, :] + vk * big_t[..., None]             # (tx,1,c,ns,3)
        d_t = np.linalg.norm(pos - tx[:, None, None, None, :], axis=-1)         # (tx,1,c,ns)
        d_r = np.linalg.norm(pos - rx[None, :, None, None, :], axis=-1)         # (tx,rx,c,ns)
        tau = (d_t + d_r) / c0
        phase = 2 * np.pi * ((w.start_frequency + w.slope * t_n) * tau - 0.5 * w.slope * tau**2)
        out += ak / float(np.dot(x0, x0)) * np.exp(1j * phase)
    if noise_std > 0:
        g = np.random.default_rng(rng)
        out += noise_std * (g.standard_normal(out.shape) + 1j * g.standard_normal(out.shape))
    return out.astype(np.complex64)


def calibrated_hardware(calib):
    """The channel errors of the hardware behind ``calib``'s phase/frequency calibration
    (tests only): a calibration measured on a reflector near the array holds the hardware's
    phases *and* that reflector's spherical-wave phases, so the hardware is the calibration
    less the reflector's own channel phases and path-length beat shifts.

    The reflector: on boresight of the virtual array's phase centre at the range of the
    file's mean peak bin (bins of ``c·fs_cal/(2·S_cal·Ns)``); its phases are measured on an
    exact spherical-wave capture (:func:`exact_adc`, channel (0, 0) the reference), its path
    lengths from the antenna positions. Imposing the result (``coloradar.sim.
    apply_channel_errors``) on frames of :func:`exact_adc` gives what a real board with that
    calibration records. Returns the calibration itself when it holds no near-field phases
    (``near_field=False``) and None without one.
    """
    from dataclasses import replace

    from coloradar.dsp.array import phase_centre

    pf = calib.phase_frequency
    if pf is None or not pf.near_field:
        return pf
    c0 = 299_792_458.0
    w, ant = calib.waveform, calib.antenna
    r0 = float(np.mean(pf.frequency)) * c0 * pf.sample_rate / (2.0 * pf.slope * w.num_samples)
    x0 = phase_centre(ant) + np.array([r0, 0.0, 0.0])
    hw = ant.half_wavelength
    tx = np.c_[np.zeros(ant.num_tx), ant.tx_positions * hw]
    rx = np.c_[np.zeros(ant.num_rx), ant.rx_positions * hw]
    path = (np.linalg.norm(x0 - tx, axis=1)[:, None] + np.linalg.norm(x0 - rx, axis=1)[None, :])
    bins = (path - path[0, 0]) * pf.slope * w.num_samples / (c0 * pf.sample_rate)
    # The file's model (conventions §2): a channel's beat frequency is moved onto the
    # reference's by a ramp from sample 0, then its phase aligned. So the reflector's phase
    # of a channel is that of its capture at sample 0 once its own beat shift is removed.
    cap = exact_adc(calib, [x0])[:, :, 0, :].astype(np.complex128)          # (tx, rx, ns)
    n = np.arange(w.num_samples)
    cap = cap * np.exp(-2j * np.pi * bins[:, :, None] * n / w.num_samples)
    phi = np.angle(np.sum(cap * np.conj(cap[0, 0])[None, None, :], axis=-1))
    return replace(pf, phase=pf.phase * np.exp(-1j * phi), frequency=pf.frequency - bins)


def matched(calib):
    """``calib`` (a RadarCalib) with a unit phase calibration where it has none: the boards that
    tests synthesise from first principles have matched channels, and the chain searches Doppler
    aliases only on an array it knows to be phase-calibrated (docs/dsp.md)."""
    from dataclasses import replace

    from coloradar.calib import identity_phase_calib

    if calib.phase_frequency is not None:
        return calib
    w = calib.waveform
    return replace(calib, phase_frequency=identity_phase_calib(w.num_tx, w.num_rx, w.slope,
                                                               w.sample_rate))
