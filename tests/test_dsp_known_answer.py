"""Known-answer tests: synthesized point targets -> heatmap peak at the bins physics predicts.

The expected bins are computed here from the waveform's raw fields and the geometry (beat
frequency 2·S·R/c, carrier at mid-sampling, spatial frequency ρ·u/2 per half wavelength),
independently of coloradar.dsp.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from _synth import REFERENCE_CALIB
from coloradar.calib import PhaseFrequencyCalib, load_calibration, preset_radar
from coloradar.dsp import RadarProcessor, coupling_signal
from coloradar.errors import CalibrationWarning
from coloradar.sim import apply_channel_errors, synthesize_adc

C0 = 299_792_458.0


def truth_bins(calib, pos, vel):
    """(range bin, el bin, az bin, range rate, velocity bin width) from physics."""
    w, h = calib.waveform, calib.heatmap
    r = np.linalg.norm(pos)
    u = pos / r
    range_bin = 2.0 * w.slope * r * w.num_samples / (C0 * w.sample_rate)
    fc = w.start_frequency + w.slope * (w.adc_start_time + w.num_samples / (2 * w.sample_rate))
    rho = fc / calib.antenna.design_frequency
    # half-wavelength element spacing: spatial frequency ρ·u/2 cycles per element, N bins per cycle
    az_bin = h.num_azimuth_bins / 2 + u[1] * rho * h.num_azimuth_bins / 2
    el_bin = h.num_elevation_bins / 2 + u[2] * rho * h.num_elevation_bins / 2
    lam = C0 / fc
    tc = w.idle_time + w.ramp_end_time
    v_bin = lam / (2.0 * w.num_chirps * w.num_tx * tc)
    return range_bin, el_bin, az_bin, float(vel @ u), v_bin


def target(r, az_deg, el_deg, v_frac, calib):
    az, el = np.deg2rad(az_deg), np.deg2rad(el_deg)
    u = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return r * u, v_frac * calib.waveform.max_velocity * u


CASES = [  # range [m], azimuth [deg], elevation [deg], radial velocity / v_max
    (2.3, 0.0, 0.0, 0.0),
    (3.1, 25.0, 8.0, 0.9),
    (4.7, -35.0, -12.0, -0.9),
    (5.5, 12.0, 15.0, 0.5),
    (6.4, -50.0, 5.0, -0.3),
    (1.6, 40.0, -20.0, 0.75),
]


def realistic_errors(calib, seed):
    """Per-channel errors like the real cascade file: f ≈ 51 ± 0.3 bins, random phases."""
    g = np.random.default_rng(seed)
    ntx, nrx = calib.waveform.num_tx, calib.waveform.num_rx
    freq = 51.0 + 0.3 * g.standard_normal((ntx, nrx))
    phase = g.uniform(5e3, 3e4, (ntx, nrx)) * np.exp(2j * np.pi * g.random((ntx, nrx)))
    return PhaseFrequencyCalib(freq, phase, calib.waveform.slope, calib.waveform.sample_rate)


@pytest.fixture(scope="module")
def radars():
    cas = preset_radar("cascade")
    errors = realistic_errors(cas, 7)
    return {
        "cascade": (cas, None),
        "cascade+errors": (replace(cas, phase_frequency=errors), errors),
        "single_chip": (preset_radar("single_chip"), None),
    }


def _frame(calib, errors, case, seed):
    pos, vel = target(*case, calib)
    amp = 400.0 * case[0] ** 2                      # 400 counts per sample at any range
    adc = synthesize_adc(calib, pos[None], vel[None], amp, noise_std=20.0, rng=seed)
    if errors is not None:
        adc = apply_channel_errors(adc, errors)
    return adc, pos, vel, 400.0


@pytest.mark.parametrize("which", ["cascade", "cascade+errors", "single_chip"])
def test_heatmap_peak_at_physical_bins(radars, which):
    calib, errors = radars[which]
    proc = RadarProcessor(calib)
    for i, case in enumerate(CASES):
        adc, pos, vel, amp = _frame(calib, errors, case, i)
        hm = proc.heatmap(adc)
        assert hm.shape == (*calib.heatmap_shape, 2) and hm.dtype == np.float32
        e, a, r = np.unravel_index(np.argmax(hm[..., 0]), hm.shape[:3])
        rb, eb, ab, vr, vbin = truth_bins(calib, pos, vel)
        msg = f"{which} case {case}: peak (el {e}, az {a}, r {r}) vs truth ({eb:.2f}, {ab:.2f}, {rb:.2f})"
        assert abs(r - rb) <= 1.0, msg
        assert abs(a - ab) <= 1.0, msg
        assert abs(e - eb) <= 2.0, msg
        assert abs(hm[e, a, r, 1] - vr) <= vbin * 1.0001, f"{msg}: v {hm[e, a, r, 1]} vs {vr}"
        # Unit coherent gain: the peak is the target's power per sample, less scalloping
        # (Hann range/Doppler and the angle grid lose at most ~2.6 dB each at half a bin).
        assert 0.1 * amp**2 < hm[e, a, r, 0] <= 1.05 * amp**2, msg


def test_calibration_is_what_undoes_channel_errors(radars):
    """Negative control: the same frames with calibration switched off lose the beam."""
    calib, errors = radars["cascade+errors"]
    on = RadarProcessor(calib)
    off = RadarProcessor(calib, phase_frequency_calibration=False)
    adc = _frame(calib, errors, CASES[1], 0)[0]
    assert off.heatmap(adc)[..., 0].max() < 0.2 * on.heatmap(adc)[..., 0].max()


def test_heatmap_config_holds_true_bin_angles(radars):
    """A target placed exactly on a bin's listed angle peaks in that bin at full gain."""
    calib = radars["cascade"][0]
    proc = RadarProcessor(calib, range_window="none", doppler_window="none")
    cfg = proc.heatmap_config()
    assert cfg.shape == calib.heatmap_shape
    assert cfg.range_bin_width == pytest.approx(
        C0 * calib.waveform.sample_rate / (2 * calib.waveform.slope * calib.waveform.num_samples))
    for ia in (10, 64, 100):
        az = cfg.azimuth_bins[ia]
        r = 40 * cfg.range_bin_width
        pos = r * np.array([np.cos(az), np.sin(az), 0.0])
        hm = proc.heatmap(synthesize_adc(calib, pos[None], None, r**2))
        e, a, rr = np.unravel_index(np.argmax(hm[..., 0]), hm.shape[:3])
        assert (a, rr) == (ia, 40)
        assert cfg.elevation_bins[e] == pytest.approx(0.0, abs=1e-12)
        assert hm[e, a, rr, 0] == pytest.approx(1.0, rel=1e-3)   # no scalloping anywhere


def test_overlap_average_and_first_agree_on_a_point_target(radars):
    calib = radars["cascade"][0]
    adc = _frame(calib, None, CASES[2], 3)[0]
    a = RadarProcessor(calib, overlap="first").heatmap(adc)
    b = RadarProcessor(calib, overlap="average").heatmap(adc)
    ia = np.unravel_index(np.argmax(a[..., 0]), a.shape[:3])
    ib = np.unravel_index(np.argmax(b[..., 0]), b.shape[:3])
    assert ia == ib
    assert b[(*ib, 0)] == pytest.approx(a[(*ia, 0)], rel=0.05)


REAL_CALIB = REFERENCE_CALIB


@pytest.mark.parametrize("name", ["cascade", "single_chip"])
def test_real_calibration_files(name):
    """The release's own calib files (unit defects fixed by the loader): frames carrying the
    board's channel errors (the phase/frequency file) and its coupling still peak right."""
    if not REAL_CALIB.is_dir():
        pytest.skip(f"real calibration files not found at {REAL_CALIB}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        calib = load_calibration(REAL_CALIB).radar(name)
    coupling = coupling_signal(calib.coupling, calib.waveform.num_samples)[:, :, None, :]
    proc = RadarProcessor(calib)
    for i, case in enumerate(CASES[1:4]):
        pos, vel = target(*case, calib)
        adc = synthesize_adc(calib, pos[None], vel[None], 400.0 * case[0] ** 2, noise_std=20.0,
                             rng=i)
        if calib.phase_frequency is not None:
            adc = apply_channel_errors(adc, calib.phase_frequency)
        hm = proc.heatmap((adc + coupling).astype(np.complex64))
        e, a, r = np.unravel_index(np.argmax(hm[..., 0]), hm.shape[:3])
        rb, eb, ab, vr, vbin = truth_bins(calib, pos, vel)
        assert abs(r - rb) <= 1 and abs(a - ab) <= 1 and abs(e - eb) <= 2, (e, a, r, eb, ab, rb)
        assert abs(hm[e, a, r, 1] - vr) <= vbin * 1.0001
