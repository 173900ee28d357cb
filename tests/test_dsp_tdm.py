"""TDM-MIMO Doppler phase compensation."""

from __future__ import annotations

import numpy as np
import pytest

from coloradar.calib import preset_radar
from coloradar.dsp import RadarProcessor, compensate_tdm, doppler_fft, range_fft, tdm_phase
from coloradar.sim import slow_times, synthesize_adc


@pytest.mark.parametrize("name", ["cascade", "single_chip"])
@pytest.mark.parametrize("k", [-7, 3, 6])
def test_boresight_mover_is_in_phase_on_every_channel_after_compensation(name, k):
    """A boresight target has no geometric phase across the array; what is left after the
    Doppler FFT is the TDM slot delay t·Tc, which the compensation must remove exactly."""
    calib = preset_radar(name)
    w = calib.waveform
    # radial velocity whose Doppler is exactly bin k: 2v/λ · Ntx·Tc = k/Nc
    v = k / w.num_chirps * w.wavelength / (2.0 * w.tdm_period)
    r = 60 * w.range_bin_width
    adc = synthesize_adc(calib, [[r, 0.0, 0.0]], [[v, 0.0, 0.0]], 1.0)
    rd = doppler_fft(range_fft(adc, "none"), "none")
    cell = (slice(None), slice(None), w.num_chirps // 2 + k, 60)
    raw = rd[cell]
    # before: TX slot t lags by the Doppler phase over t·Tc (docs/conventions.md §3 timing)
    t_slot = slow_times(calib)[:, 0]
    expected = np.exp(2j * np.pi * (2 * v / w.wavelength) * t_slot)
    np.testing.assert_allclose(raw / raw[0, 0], np.broadcast_to(expected[:, None], raw.shape),
                               atol=1e-4)
    after = compensate_tdm(rd)[cell]
    np.testing.assert_allclose(after / after[0, 0], 1.0, atol=1e-4)


def test_tdm_phase_formula():
    ph = tdm_phase(4, np.array([-2.5, 0.0, 1.0]), 16)
    t = np.arange(4)[:, None]
    np.testing.assert_allclose(ph, np.exp(-2j * np.pi * t * np.array([-2.5, 0.0, 1.0]) / 64),
                               rtol=1e-6)


def test_without_compensation_fast_targets_move_in_angle():
    calib = preset_radar("single_chip")
    w = calib.waveform
    el = np.deg2rad(15.0)
    u = np.array([np.cos(el), 0.0, np.sin(el)])
    adc = synthesize_adc(calib, 4.0 * u[None], 0.9 * w.max_velocity * u[None], 16.0)
    cfg = RadarProcessor(calib).heatmap_config()
    for comp, ok in ((True, True), (False, False)):
        hm = RadarProcessor(calib, tdm_compensation=comp).heatmap(adc)
        e, _, _ = np.unravel_index(np.argmax(hm[..., 0]), hm.shape[:3])
        err = abs(cfg.elevation_bins[e] - el)
        assert (err < np.deg2rad(6.0)) == ok, (comp, np.rad2deg(cfg.elevation_bins[e]))
