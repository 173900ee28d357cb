"""RadarProcessor settings, zero padding, input checks and shared products."""

from __future__ import annotations

import numpy as np
import pytest

from coloradar.calib import preset_radar
from coloradar.dsp import ProcessingSettings, RadarProcessor
from coloradar.errors import FormatError
from coloradar.sim import synthesize_adc

C0 = 299_792_458.0


def test_zero_padding_refines_range_and_doppler_bins():
    calib = preset_radar("single_chip")
    w = calib.waveform
    r, v = 3.33, 0.77
    adc = synthesize_adc(calib, [[r, 0.0, 0.0]], [[v, 0.0, 0.0]], r**2)
    plain = RadarProcessor(calib)
    padded = RadarProcessor(calib, range_fft_size=4 * w.num_samples,
                            doppler_fft_size=4 * w.num_chirps, num_range_bins=256)
    dr = C0 * w.sample_rate / (2 * w.slope * w.num_samples)
    assert padded.heatmap_config().range_bin_width == pytest.approx(dr / 4)
    assert padded.heatmap_config().num_range_bins == 256
    for proc, width in ((plain, dr), (padded, dr / 4)):
        hm = proc.heatmap(adc)
        e, a, rb = np.unravel_index(np.argmax(hm[..., 0]), hm.shape[:3])
        assert abs(rb * width - r) <= width / 2 + 1e-9
        vbin = proc.velocities[1] - proc.velocities[0]
        assert abs(hm[e, a, rb, 1] - v) <= vbin / 2 + 1e-6
    assert padded.velocities[1] - padded.velocities[0] == pytest.approx(
        w.velocity_bin_width / 4)


def test_products_share_one_computation_and_match_single_calls():
    calib = preset_radar("cascade")
    adc = synthesize_adc(calib, [[4.0, 1.0, 0.2]], [[0.5, 0.0, 0.0]], 4e3, noise_std=3.0, rng=0)
    proc = RadarProcessor(calib)
    hm, pts = proc.products(adc)
    np.testing.assert_array_equal(hm, proc.heatmap(adc))
    np.testing.assert_array_equal(pts, proc.pointcloud(adc))
    assert proc.products(adc, heatmap=False)[0] is None


def test_settings_are_validated():
    with pytest.raises(ValueError, match="range_window"):
        ProcessingSettings(range_window="hamming")
    with pytest.raises(ValueError, match="azimuth_sign"):
        RadarProcessor(preset_radar("single_chip"), azimuth_sign=0)
    with pytest.raises(TypeError):
        RadarProcessor(preset_radar("single_chip"), no_such_setting=1)
    with pytest.raises(ValueError, match="FFT sizes"):
        RadarProcessor(preset_radar("single_chip"), range_fft_size=64)
    s = ProcessingSettings(pfa=1e-3).replace(angle_method="capon")
    assert (s.pfa, s.angle_method) == (1e-3, "capon")
    assert "angle_method" in repr(RadarProcessor(preset_radar("single_chip"), s))


def test_wrong_frame_shape_is_a_format_error():
    proc = RadarProcessor(preset_radar("cascade"))
    bad = np.zeros(preset_radar("single_chip").frame_shape, np.complex64)
    with pytest.raises(FormatError, match=r"\(tx, rx, chirp, sample\)"):
        proc.heatmap(bad)
    with pytest.raises(FormatError):
        proc.pointcloud(np.zeros(proc.calib.frame_shape, np.int16))


def test_zero_padding_keeps_the_range_span_by_default():
    calib = preset_radar("single_chip")
    plain = RadarProcessor(calib)
    padded = RadarProcessor(calib, range_fft_size=4 * calib.waveform.num_samples)
    span = plain.num_range_bins * plain.range_bin_width
    assert padded.num_range_bins * padded.range_bin_width == pytest.approx(span)
    assert padded.heatmap_config().num_range_bins == 4 * calib.heatmap.num_range_bins


@pytest.mark.parametrize("name", ["cascade", "single_chip"])
def test_fused_processor_equals_the_chain_of_stage_functions(name):
    """The processor fuses windows, calibration and the Doppler shift into one multiplier; the
    result must be what the documented stages give one after the other."""
    from coloradar.dsp import compensate_tdm, doppler_fft, range_fft, remove_dc

    calib = preset_radar(name)
    adc = synthesize_adc(calib, [[4.0, 1.0, 0.2], [2.5, -1.2, 0.0]], [[0.4, 0, 0], [-0.8, 0, 0]],
                         [500.0, 900.0], noise_std=2.0, rng=0)
    proc = RadarProcessor(calib)
    staged = compensate_tdm(doppler_fft(range_fft(remove_dc(adc), "hann",
                                                  keep=proc.num_range_bins), "hann"))
    fused = proc.range_doppler(adc)
    assert fused.shape == staged.shape
    np.testing.assert_allclose(fused, staged, atol=1e-4 * np.abs(staged).max())


def test_unknown_setting_names_the_closest_ones():
    from coloradar.cli._common import processing_setting

    with pytest.raises(ValueError, match=r"did you mean pfa\b"):
        ProcessingSettings.parse_setting("pfaa=1e-5")
    with pytest.raises(ValueError, match="did you mean sidelobe_margin_db"):
        ProcessingSettings.parse_setting("sidelobe_margin=3")
    with pytest.raises(ValueError) as far:
        ProcessingSettings.parse_setting("zzzz=1")
    assert "did you mean" not in str(far.value)
    # the command line's --set says the same (argparse shows the message)
    with pytest.raises(Exception, match=r"did you mean pfa\b"):
        processing_setting("pfaa=1e-5")
    assert ProcessingSettings.parse_setting("pfa=1e-5") == ("pfa", 1e-5)


def test_every_setting_reaches_its_stage_through_one_group():
    from dataclasses import fields

    from coloradar.dsp.settings import (
        AliasSettings,
        AngleSettings,
        ArraySettings,
        CFARSettings,
        CubeSettings,
        GuardSettings,
        PointSettings,
    )

    groups = (CubeSettings, ArraySettings, CFARSettings, AngleSettings, AliasSettings,
              GuardSettings, PointSettings)
    names = [f.name for g in groups for f in fields(g)]
    flat = [f.name for f in fields(ProcessingSettings)]
    assert sorted(names) == sorted(flat)                 # each flat setting in exactly one group
    # a changed setting arrives in the stage that uses it, with its value
    s = ProcessingSettings(pfa=1e-6, sidelobe_margin_db=3.0, doppler_unwrap=4.0,
                           angle_pfa=1e-2, phase_centre=False, range_window="blackman")
    proc = RadarProcessor(preset_radar("cascade"), s)
    assert proc.detector.cfar.settings.pfa == 1e-6
    assert proc.detector.guard.settings.sidelobe_margin_db == 3.0
    assert proc.detector.alias.settings.doppler_unwrap == 4.0
    assert proc.detector.resolve.settings.angle_pfa == 1e-2
    assert proc.detector.points.settings.phase_centre is False
    assert not proc.detector.points.centre.any()             # no phase centre: the origin
    assert proc.cube.settings.range_window == "blackman"
    for g in groups:
        for f in fields(g):
            assert getattr(getattr(s, {CubeSettings: "cube", ArraySettings: "array",
                                       CFARSettings: "cfar", AngleSettings: "angle",
                                       AliasSettings: "alias", GuardSettings: "guard",
                                       PointSettings: "points"}[g]), f.name) == getattr(s, f.name)
