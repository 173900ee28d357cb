"""Calibration: the real files parse, their defects are corrected loudly, derived quantities are right."""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest

import coloradar as cr
from _synth import REFERENCE_CALIB
from coloradar import calib as cb

C = 299_792_458.0

needs_reference = pytest.mark.skipif(not REFERENCE_CALIB.is_dir(),
                                     reason=f"real calibration not found at {REFERENCE_CALIB}")


@pytest.fixture(scope="module")
def real():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", cr.CalibrationWarning)
        return cr.load_calibration(REFERENCE_CALIB)


@needs_reference
def test_cascade_unit_defects_are_fixed_with_warnings():
    text = (REFERENCE_CALIB / "cascade" / "waveform_cfg.txt").read_text()
    with pytest.warns(cr.CalibrationWarning) as rec:
        w = cb.parse_waveform_cfg(text, "cascade/waveform_cfg.txt")
    msgs = " ".join(str(r.message) for r in rec)
    assert "adc_start_time" in msgs and "ramp_end_time" in msgs
    assert w.adc_start_time == pytest.approx(6e-6)
    assert w.ramp_end_time == pytest.approx(40e-6, rel=1e-6)


@needs_reference
def test_derived_quantities_match_design_numbers(real):
    cas, sc = real.cascade, real.single_chip
    # c*fs/(2*S*Ns) equals the heatmap range bin width (docs/conventions.md §2).
    for r in (cas, sc):
        w = r.waveform
        assert w.range_bin_width == pytest.approx(C * w.sample_rate / (2 * w.slope * w.num_samples))
        assert w.range_bin_width == pytest.approx(r.heatmap.range_bin_width, rel=1e-6)
    assert cas.waveform.range_bin_width == pytest.approx(0.05929, abs=1e-5)
    assert cas.waveform.max_velocity == pytest.approx(1.76, abs=0.01)
    w = sc.waveform
    lam = C / (w.start_frequency + w.slope * (w.adc_start_time + w.num_samples / w.sample_rate / 2))
    assert w.max_velocity == pytest.approx(lam / (4 * 3 * (w.idle_time + w.ramp_end_time)))
    assert w.velocity_bin_width == pytest.approx(2 * w.max_velocity / w.num_chirps)
    assert cas.frame_shape == (12, 16, 16, 256) and sc.frame_shape == (3, 4, 128, 128)
    assert cas.waveform.frame_nbytes == 3_145_728 and sc.waveform.frame_nbytes == 786_432
    assert cas.heatmap_shape == (32, 128, 128) and sc.heatmap_shape == (16, 64, 64)


@needs_reference
def test_antenna_lines_out_of_order_and_trailing_spaces(real):
    sc = real.single_chip.antenna
    # The real file lists tx 0, tx 2, tx 1, and 'rx 0 0 0 ' has a trailing space.
    np.testing.assert_array_equal(sc.tx_positions, [[0, 0], [4, 0], [2, 1]])
    np.testing.assert_array_equal(sc.rx_positions[:, 0], [0, 1, 2, 3])
    assert sc.design_frequency == pytest.approx(76.8e9)


@needs_reference
def test_virtual_array_against_brute_force(real):
    for r in (real.cascade, real.single_chip):
        a = r.antenna
        seen: dict[tuple, tuple] = {}
        for t, x in itertools.product(range(a.num_tx), range(a.num_rx)):
            p = tuple(a.tx_positions[t] + a.rx_positions[x])
            seen.setdefault(p, (t, x))
        v = a.virtual
        assert v.num_unique == len(seen)
        for row, pos in enumerate(v.unique_positions):
            assert tuple(v.first_pair[row]) == seen[tuple(pos)]
        for t, x in itertools.product(range(a.num_tx), range(a.num_rx)):
            np.testing.assert_array_equal(v.unique_positions[v.index[t, x]],
                                          a.tx_positions[t] + a.rx_positions[x])
    assert real.cascade.antenna.virtual.num_unique == 134
    assert real.single_chip.antenna.virtual.num_unique == 12


@needs_reference
def test_coupling_and_phase_frequency(real):
    c = real.cascade.coupling
    assert c.data.shape == (12, 16, 128) and c.data.dtype == np.complex64
    first = (REFERENCE_CALIB / "cascade" / "coupling_calib.txt").read_text().split("data:")[1].split(",")
    assert c.data[0, 0, 0] == pytest.approx(complex(float(first[0]), float(first[1])), rel=1e-6)
    assert c.data[0, 0, 1] == pytest.approx(complex(float(first[2]), float(first[3])), rel=1e-6)
    with pytest.warns(cr.CalibrationWarning, match="TX 2"):
        sc = cb.parse_coupling_calib((REFERENCE_CALIB / "single_chip" / "coupling_calib.txt").read_text())
    assert sc.missing_tx == (2,)
    assert not np.any(sc.data[2]) and np.all(np.any(sc.data[:2] != 0, axis=2))
    pf = real.cascade.phase_frequency
    assert pf.frequency.shape == (12, 16) and np.all(np.abs(pf.frequency - 51.2) < 1.0)
    assert pf.relative_frequency()[0, 0] == 0 and pf.relative_phase()[0, 0] == pytest.approx(1)
    assert real.single_chip.phase_frequency is None


@needs_reference
def test_shipped_heatmap_angles_follow_documented_formula(real):
    for r in (real.cascade, real.single_chip):
        h = r.heatmap
        for bins, n in ((h.azimuth_bins, h.num_azimuth_bins), (h.elevation_bins, h.num_elevation_bins)):
            i = np.arange(n)
            np.testing.assert_allclose(bins, np.arcsin((2 * (i + 0.5) / n - 1) * 76 / 77), atol=1e-6)


@needs_reference
def test_transforms_and_presets_agree_with_real_files(real):
    assert set(real.transforms) == {"cascade", "single_chip", "lidar", "imu", "vicon"}
    t = real.transforms["cascade"]
    np.testing.assert_allclose(t.translation, [0.03, 0.12, -0.09])
    # The radar's x axis (boresight) points along the rig's +y (docs/conventions.md §3).
    np.testing.assert_allclose(t.matrix()[:3, 0], [0, 1, 0], atol=2e-3)
    preset = cb.preset_calibration()
    for name in ("cascade", "single_chip"):
        p, r = preset.radar(name), real.radar(name)
        for f in ("num_rx", "num_tx", "num_samples", "num_chirps", "sample_rate", "idle_time",
                  "adc_start_time", "ramp_end_time", "slope", "start_frequency"):
            assert getattr(p.waveform, f) == pytest.approx(getattr(r.waveform, f), rel=1e-6), f
        np.testing.assert_array_equal(p.antenna.tx_positions, r.antenna.tx_positions)
        np.testing.assert_array_equal(p.antenna.rx_positions, r.antenna.rx_positions)
        np.testing.assert_allclose(p.heatmap.azimuth_bins, r.heatmap.azimuth_bins, atol=1e-6)
        np.testing.assert_allclose(p.heatmap.elevation_bins, r.heatmap.elevation_bins, atol=1e-6)
    for s, e in real.transforms.items():
        np.testing.assert_allclose(preset.transforms[s].matrix(), e.matrix(), atol=1e-9)


@needs_reference
def test_write_then_load_gives_the_same_calibration(real, tmp_path):
    cb.write_calibration(real, tmp_path / "calib")
    with warnings.catch_warnings():
        warnings.simplefilter("error", cr.CalibrationWarning)  # the written files are clean
        warnings.filterwarnings("ignore", ".*the coupling block", cr.CalibrationWarning)
        back = cr.load_calibration(tmp_path)
    for name in ("cascade", "single_chip"):
        a, b = real.radar(name), back.radar(name)
        assert a.waveform == b.waveform
        np.testing.assert_array_equal(a.antenna.virtual.positions, b.antenna.virtual.positions)
        np.testing.assert_allclose(a.heatmap.azimuth_bins, b.heatmap.azimuth_bins, rtol=0, atol=0)
        np.testing.assert_allclose(a.coupling.data, b.coupling.data, rtol=1e-5)
    np.testing.assert_array_equal(real.cascade.phase_frequency.phase, back.cascade.phase_frequency.phase)


def test_calibration_from_zip_with_top_folder(tmp_path):
    from _synth import zip_folder

    cb.write_calibration(cb.preset_calibration(), tmp_path / "calib")
    zip_folder(tmp_path / "calib", tmp_path / "calib.zip", top="calib")
    cal = cr.load_calibration(tmp_path / "calib.zip")
    assert cal.cascade.frame_shape == (12, 16, 16, 256)
    assert cal.source.endswith("calib.zip:calib/")


def test_presets_work_without_a_calib_folder():
    cal = cr.load_calibration(None)
    assert cal.source == "preset"
    assert cal.cascade.waveform.range_bin_width == pytest.approx(0.05929, abs=1e-5)
    assert cal.single_chip.waveform.max_velocity == pytest.approx(2.45, abs=0.02)


@pytest.mark.parametrize(("text", "match"), [
    ("num_rx 2\nnum_tx 1\nF_design 76.8\nrx 0 0 0\nrx 0 1 0\ntx 0 0 0\n", "rx 0 listed twice"),
    ("num_rx 2\nnum_tx 1\nF_design 76.8\nrx 0 0 0\ntx 0 0 0\n", r"expected rx indices 0..1"),
    ("num_rx 1\nnum_tx 1\nrx 0 0 0\ntx 0 0 0\n", "missing F_design"),
    ("num_rx 1\nnum_tx 1\nF_design 76.8\nrx 0 zero 0\ntx 0 0 0\n", "line 4: expected numbers"),
])
def test_malformed_antenna_cfg(text, match):
    with pytest.raises(cr.CalibrationError, match=match) as err:
        cb.parse_antenna_cfg(text, "antenna_cfg.txt")
    assert "antenna_cfg.txt" in str(err.value)


def test_malformed_waveform_and_coupling():
    with pytest.raises(cr.CalibrationError, match=r"waveform_cfg\.txt: missing key 'frequency_slope'"):
        cb.parse_waveform_cfg("num_rx 4\nnum_tx 3\nnum_adc_samples_per_chirp 128\nnum_chirps_per_frame 128\n"
                              "adc_sample_frequency 1e7\nstart_frequency 77e9\nidle_time 1e-4\n"
                              "adc_start_time 7e-6\nramp_end_time 2e-5\n", "waveform_cfg.txt")
    with pytest.raises(cr.CalibrationError, match=r"expected 8 data values.*found 6"):
        cb.parse_coupling_calib("num_tx:1\nnum_rx:2\nnum_range_bins:2\nnum_doppler_bins:4\n"
                                "data:1,2,3,4,5,6\n", "coupling_calib.txt")
    with pytest.raises(cr.CalibrationError, match="not valid JSON"):
        cb.parse_phase_frequency_calib('{"antennaCalib": [', "phase_frequency_calib.txt")


def test_nested_phase_matrices_and_zero_quaternion():
    import json

    f = [[51.0, 51.1], [51.2, 51.3]]
    p = [[1.0, 0.0, 0.0, 1.0], [-1.0, 0.0, 0.0, -1.0]]  # [tx][rx re/im...]
    text = json.dumps({"antennaCalib": {"numTx": 2, "numRx": 2, "frequencySlope": 7.9e13,
                                        "samplingRate": 8e6, "frequencyCalibrationMatrix": f,
                                        "phaseCalibrationMatrix": p}})
    pf = cb.parse_phase_frequency_calib(text)
    np.testing.assert_array_equal(pf.frequency, f)
    np.testing.assert_array_equal(pf.phase, [[1, 1j], [-1, -1j]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an error, not a warning first
        with pytest.raises(cr.CalibrationError, match=r"base_to_x\.txt: quaternion"):
            cb.parse_transform("0 0 0\n0 0 0 0\n", "base_to_x.txt")
