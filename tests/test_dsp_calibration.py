"""Phase/frequency calibration and coupling subtraction (docs/conventions.md §2)."""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

from _synth import REFERENCE_CALIB
from coloradar.calib import CouplingCalib, PhaseFrequencyCalib, load_calibration, preset_radar
from coloradar.dsp import (
    RadarProcessor,
    apply_phase_frequency_calibration,
    coupling_signal,
    phase_frequency_factors,
)
from coloradar.sim import apply_channel_errors, synthesize_adc

REAL_CALIB = REFERENCE_CALIB


def _errors(calib, seed, slope=None, fs=None):
    g = np.random.default_rng(seed)
    ntx, nrx = calib.waveform.num_tx, calib.waveform.num_rx
    return PhaseFrequencyCalib(51.0 + 0.3 * g.standard_normal((ntx, nrx)),
                               g.uniform(5e3, 3e4, (ntx, nrx)) * np.exp(2j * np.pi * g.random((ntx, nrx))),
                               slope or calib.waveform.slope, fs or calib.waveform.sample_rate)


def test_factors_follow_the_design_formula_with_rescaled_bins():
    calib = preset_radar("cascade")
    w = calib.waveform
    pf = _errors(calib, 1, slope=2 * w.slope, fs=0.5 * w.sample_rate)   # calibrated elsewhere
    got = phase_frequency_factors(pf, w)
    n = np.arange(w.num_samples)
    for t, r in ((0, 0), (3, 7), (11, 15)):
        df = (pf.frequency[t, r] - pf.frequency[0, 0]) * (w.slope / pf.slope) * (
            pf.sample_rate / w.sample_rate)
        expected = pf.phase[0, 0] / pf.phase[t, r] * np.exp(-2j * np.pi * df * n / w.num_samples)
        np.testing.assert_allclose(got[t, r], expected, rtol=1e-12)
    np.testing.assert_allclose(got[0, 0], 1.0)


def test_calibration_undoes_the_simulated_channel_errors():
    calib = preset_radar("cascade")
    pf = _errors(calib, 2)
    adc = synthesize_adc(calib, [[3.0, 0.5, 0.2]], None, 1e4, noise_std=1.0, rng=0)
    back = apply_phase_frequency_calibration(apply_channel_errors(adc, pf), pf, calib.waveform)
    np.testing.assert_allclose(back, adc, atol=1e-3 * np.abs(adc).max())


def _coupling_calib(calib, seed, all_bins):
    """A coupling spectrum (tx, rx, Ns); all_bins=False keeps it inside the file's bins."""
    w = calib.waveform
    g = np.random.default_rng(seed)
    ns = w.num_samples
    k = np.arange(ns)
    dist = np.minimum(k, ns - k) if all_bins else k          # leak below bin 0 too, or not
    env = 5e3 * np.exp(-dist / 3.0)
    if not all_bins:
        env[calib.heatmap.num_range_bins - 2:] = 0.0
    spec = env * (g.standard_normal((*w.frame_shape[:2], ns))
                  + 1j * g.standard_normal((*w.frame_shape[:2], ns)))
    kept = calib.heatmap.num_range_bins
    return spec, CouplingCalib(spec[..., :kept], w.num_chirps)


def _coupling_frame(calib, spec):
    sig = np.fft.ifft(spec, axis=-1)                        # one chirp of coupling per channel
    return np.broadcast_to(sig[:, :, None, :], calib.frame_shape).astype(np.complex64)


@pytest.mark.parametrize("window", ["hann", "blackman", "none"])
@pytest.mark.parametrize("dc_removal", [True, False])
def test_a_coupling_only_frame_processes_to_nothing(window, dc_removal):
    base = preset_radar("cascade")
    spec, coupling = _coupling_calib(base, 3, all_bins=False)
    calib = replace(base, coupling=coupling, phase_frequency=_errors(base, 4))
    frame = _coupling_frame(calib, spec)
    kw = dict(range_window=window, doppler_window=window, dc_removal=dc_removal)
    before = RadarProcessor(calib, coupling_subtraction=False, **kw).range_doppler_power(frame)
    after = RadarProcessor(calib, **kw).range_doppler_power(frame)
    assert after.max() < 1e-9 * before.max()
    hm = RadarProcessor(calib, **kw).heatmap(frame)
    assert hm[..., 0].max() < 1e-9 * before.max()


def test_coupling_measured_on_calibrated_samples():
    base = preset_radar("cascade")
    spec, coupling = _coupling_calib(base, 5, all_bins=False)
    pf = _errors(base, 6)
    calib = replace(base, coupling=coupling, phase_frequency=pf)
    # raw samples whose *calibrated* FFT is the coupling spectrum
    raw = np.fft.ifft(spec, axis=-1) / phase_frequency_factors(pf, base.waveform)
    frame = np.broadcast_to(raw[:, :, None, :], calib.frame_shape).astype(np.complex64)
    before = RadarProcessor(calib, coupling_subtraction=False).range_doppler_power(frame)
    good = RadarProcessor(calib, coupling_domain="calibrated").range_doppler_power(frame)
    wrong = RadarProcessor(calib, coupling_domain="raw").range_doppler_power(frame)
    assert good.max() < 1e-9 * before.max()
    assert wrong.max() > 1e-3 * before.max()


@pytest.mark.parametrize(("window", "affected"), [("none", 0), ("hann", 1), ("blackman", 2)])
def test_unknown_coupling_bins_only_touch_the_first_range_bins(window, affected):
    """Coupling below bin 0 (absent from the file) leaks into `affected` bins via the window."""
    base = preset_radar("cascade")
    spec, coupling = _coupling_calib(base, 7, all_bins=True)
    calib = replace(base, coupling=coupling)
    frame = _coupling_frame(calib, spec)
    kw = dict(range_window=window, dc_removal=False)
    before = RadarProcessor(calib, coupling_subtraction=False, **kw).range_doppler_power(frame)
    after = RadarProcessor(calib, **kw).range_doppler_power(frame)
    assert after[:, affected:].max() < 1e-9 * before.max()
    if affected:
        assert after[:, :affected].max() > 1e-6 * before.max()


def test_target_survives_coupling_subtraction():
    base = preset_radar("single_chip")
    spec, coupling = _coupling_calib(base, 8, all_bins=False)
    calib = replace(base, coupling=coupling)
    target = synthesize_adc(calib, [[4.0, -1.0, 0.3]], [[0.5, 0.0, 0.0]], 500.0 * 17)
    proc = RadarProcessor(calib)
    clean = proc.heatmap(target)
    both = proc.heatmap(target + _coupling_frame(calib, spec))
    peak = np.unravel_index(np.argmax(clean[..., 0]), clean.shape[:3])
    assert np.unravel_index(np.argmax(both[..., 0]), both.shape[:3]) == peak
    assert both[(*peak, 0)] == pytest.approx(clean[(*peak, 0)], rel=1e-4)


@pytest.fixture(scope="module")
def real_calib():
    if not REAL_CALIB.is_dir():
        pytest.skip(f"real calibration files not found at {REAL_CALIB}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_calibration(REAL_CALIB)


@pytest.mark.parametrize("name", ["cascade", "single_chip"])
def test_real_coupling_file_removes_its_own_coupling(real_calib, name):
    calib = real_calib.radar(name)
    frame = np.broadcast_to(coupling_signal(calib.coupling, calib.waveform.num_samples)[:, :, None],
                            calib.frame_shape).astype(np.complex64)
    before = RadarProcessor(calib, coupling_subtraction=False).range_doppler_power(frame)
    after = RadarProcessor(calib).range_doppler_power(frame)
    assert before.max() > 1e3
    assert after.max() < 1e-9 * before.max()


@pytest.mark.parametrize("name", ["cascade", "single_chip"])
@pytest.mark.parametrize("window", ["hann", "blackman"])
def test_physical_leakage_leaves_no_target_at_the_far_end(name, window):
    """A real leakage is a near-range tone with sidelobes in every bin, also beyond the bins the
    coupling file holds. Subtracting must not turn those into a static target at the last range
    bins (a sharply truncated subtraction did: -1/4 of the first missing bin leaked into the
    last kept one)."""
    from coloradar.sim.radar import RADAR_MODELS, make_coupling

    base = preset_radar(name)
    leak, coupling = make_coupling(base, RADAR_MODELS[name], np.random.default_rng(0))
    calib = replace(base, coupling=coupling)
    frame = np.broadcast_to(leak[:, :, None, :], calib.frame_shape).astype(np.complex64)
    kw = dict(range_window=window)
    before = RadarProcessor(calib, coupling_subtraction=False, **kw).range_doppler_power(frame)
    after = RadarProcessor(calib, **kw).range_doppler_power(frame)
    assert after.max() < 0.15 * before.max()          # the leakage itself is removed
    far = after.shape[1] // 2
    # Beyond mid-range nothing above -70 dB of the leakage remains.
    assert after[:, far:].max() < 1e-7 * before.max()


def test_calibration_measured_on_a_reflector_undoes_physical_channel_delays():
    """Independent of `apply_channel_errors`: channels get a physical extra delay δτ and a
    complex gain, x'[n] = g·x[n]·exp(j2π(f0 + S·t_n)·δτ). A corner reflector capture (3 m,
    boresight) gives each channel's bin f (the beat of τ_c + δτ) and response P (its DTFT
    there), as a calibration would measure them. Calibrating a scene with those numbers must
    leave every channel with the same residual factor as channel (0, 0)."""
    from coloradar.calib.waveform import SPEED_OF_LIGHT as C0

    calib = preset_radar("cascade")
    w = calib.waveform
    g = np.random.default_rng(11)
    shape = (w.num_tx, w.num_rx)
    delay = g.uniform(-0.3, 0.3, shape) * 2 / C0 * w.range_bin_width     # up to ±0.3 range bins
    gain = g.uniform(0.5, 2.0, shape) * np.exp(2j * np.pi * g.random(shape))
    t_n = w.adc_start_time + np.arange(w.num_samples) / w.sample_rate
    channel = gain[:, :, None] * np.exp(2j * np.pi * (w.start_frequency + w.slope * t_n)
                                        * delay[:, :, None])            # (tx, rx, sample)

    reflector = synthesize_adc(calib, [[3.0, 0.0, 0.0]], None, 3e4)[:, :, 0, :] * channel
    f = (2 * 3.0 / C0 + delay) * w.slope * w.num_samples / w.sample_rate  # its range bin
    n = np.arange(w.num_samples)
    p = np.einsum("trn,trn->tr", reflector, np.exp(-2j * np.pi * f[:, :, None] * n / w.num_samples))
    pf = PhaseFrequencyCalib(f, p, w.slope, w.sample_rate)

    pos = [[4.0, 1.5, 0.3], [2.0, -1.0, -0.2], [6.0, 0.5, 0.8]]
    vel = [[0.3, 0.0, 0.0], [-0.5, 0.2, 0.0], [0.0, 0.0, 0.1]]
    ideal = synthesize_adc(calib, pos, vel, [800.0, 300.0, 2000.0]).astype(np.complex128)
    observed = ideal * channel[:, :, None, :]
    fixed = apply_phase_frequency_calibration(observed.astype(np.complex64), pf, w)
    ratio = fixed / ideal
    np.testing.assert_allclose(ratio, np.broadcast_to(ratio[0, 0], ratio.shape), rtol=2e-3)
    assert np.abs(ratio[0, 0] - 1).max() > 0.1  # the residual is a real, common factor
    # The simulator's error model is the same physics, up to a factor common to all channels.
    imposed = apply_channel_errors(ideal.astype(np.complex64), pf) / ideal
    common = imposed / channel[:, :, None, :]
    np.testing.assert_allclose(common, np.broadcast_to(common[0, 0], common.shape), rtol=2e-3)
