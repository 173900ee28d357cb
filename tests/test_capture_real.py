"""The chain on real TI bytes: OpenRadar's three ADC frames (xWR16xx/18xx + DCA1000, Apache-2.0;
``../shared/real/openradar/README.md``) written as a DCA1000 capture by the test-side writer,
imported, and processed: the moving return is found at its bins, near-range coupling and DC make
no flood of points, and the CFAR's false-alarm rate on the far-range cells is measured against
the requested one (docs/capture.md, "Real frames")."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest

import _capture_writer as cw
from coloradar.calib import AntennaConfig, HeatmapConfig, RadarCalib, WaveformConfig
from coloradar.capture import import_capture
from coloradar.dataset import open_sequence
from coloradar.dsp import RadarProcessor

REAL = Path(os.environ.get("COLORADAR_REAL_OPENRADAR",
                           Path(__file__).resolve().parents[1].parent / "shared" / "real" / "openradar"))
pytestmark = pytest.mark.skipif(not (REAL / "doppler_example_1.npy").is_file(),
                                reason=f"OpenRadar's real frames not at {REAL}")

# The xWR1642 set-up of OpenRadar's mmWave Studio scripts of the time (README beside the frames):
# likely, not known, so the checks are in bins.
XWR1642 = dict(start_ghz=77.0, idle_us=30.0, adc_start_us=7.0, ramp_end_us=62.0, slope=60.012,
               samples=128, rate_ksps=2500, loops=128, period_ms=40.0)


def _signed(name: str) -> np.ndarray:
    """A frame's raw 16-bit words (stored as unsigned in complex128) as signed counts."""
    x = np.load(REAL / name)
    re = x.real.astype(np.int64).astype(np.uint16).view(np.int16)
    im = x.imag.astype(np.int64).astype(np.uint16).view(np.int16)
    return re.astype(np.float64) + 1j * im


@pytest.fixture(scope="module")
def real_run(tmp_path_factory) -> tuple[Path, np.ndarray]:
    """doppler_example_1 (loop, channel, sample), channel = 4·TX + RX assumed, as a capture."""
    c = _signed("doppler_example_1.npy")
    frame = c.reshape(128, 2, 4, 128).transpose(1, 2, 0, 3)[None]     # (1, tx, rx, loop, s)
    root = tmp_path_factory.mktemp("openradar")
    (root / "adc_data.bin").write_bytes(cw.dca1000_bytes(frame))
    # The xWR1642's two TX lie 2λ apart, as TX0 and TX2 of the AWR1843BOOST.
    (root / "xwr1642.cfg").write_text(cw.sdk_cfg([0, 2], w=XWR1642, frames=1))
    import_capture(root / "adc_data.bin", root / "run", config=root / "xwr1642.cfg",
                   board="AWR1843BOOST")
    return root / "run", frame[0]


def _proc_and_frame(run: Path, **settings) -> tuple[RadarProcessor, np.ndarray]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seq = open_sequence(run)
    return RadarProcessor(seq.calib.single_chip, **settings), seq.single_chip.adc[0]


def test_real_bytes_survive_the_import(real_run):
    run, frame = real_run
    _, adc = _proc_and_frame(run)
    np.testing.assert_array_equal(adc, frame.astype(np.complex64))


def test_moving_return_found_at_its_bins_without_a_near_range_flood(real_run):
    proc, adc = _proc_and_frame(run := real_run[0])
    det = proc.detect(adc)
    nd = proc.doppler_fft_size
    off = det.doppler_bin - nd // 2
    # The README's moving return: range bin ~60, about 7 Doppler bins from zero.
    assert np.any((np.abs(det.range_bin - 60) <= 2) & (np.abs(np.abs(off) - 7) <= 1)), run
    # Coupling and DC (~50 dB over the far-range median in bins 0-3) give no points, and the
    # frame is no flood: fewer points than range bins (the scene has a handful of returns).
    assert not np.any(det.range_bin < 4)
    assert 0 < len(det) < proc.num_range_bins
    pts = proc.pointcloud(adc)
    assert np.all(np.isfinite(pts)) and len(pts) == len(det)


def _far_noise(shape: tuple[int, int]) -> np.ndarray:
    """The far-range noise cells of a ``(doppler, range)`` map: range bins from 84 (the
    8-channel frame's moving return at bin 60 and its echoes reach bin 83: their alarms there
    are coherent over the channels, as one direction's return, see
    ``test_alarms_left_out_of_the_noise_are_returns``) and Doppler bins 16 or more from zero
    (the frames' moving things lie within 13 bins of zero; there the far-range floor of the
    8-channel frame is 1.5–2.5 dB up)."""
    nd = shape[0]
    region = np.zeros(shape, dtype=bool)
    region[:, 84:] = True
    region[np.abs(np.arange(nd) - nd // 2) < 16] = False
    return region


def _stage_alarms(proc: RadarProcessor, adc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The chain's own CFAR stage on a frame: its detection statistic and its mask (before
    peak grouping), both ``(doppler, range)``."""
    stage = proc.detector.cfar
    stat, _, looks, _ = stage.statistic(proc.range_doppler(adc))
    return stat, stage.cfar_mask(stat, looks)[0]


def _single_channel(name: str) -> tuple[RadarProcessor, np.ndarray]:
    c = _signed(name)                                                   # (chirp, sample)
    nc, ns = c.shape
    w = WaveformConfig(1, 1, ns, nc, 2.5e6 * ns / 128, 77e9, 30e-6, 7e-6, 62e-6 * ns / 128,
                       60.012e12)
    grid = HeatmapConfig(ns, 1, 1, w.range_bin_width, np.zeros(1), np.zeros(1))
    calib = RadarCalib("single_chip", w, AntennaConfig(76.8e9, np.zeros((1, 2)),
                                                       np.zeros((1, 2))), grid)
    return RadarProcessor(calib), c[None, None].astype(np.complex64)


@pytest.mark.parametrize("name", ["doppler_example.npy", "simple_frame_1.npy"])
@pytest.mark.parametrize("pfa", [1e-2, 1e-3])
def test_cfar_false_alarms_on_real_single_channel_noise_within_2x(name, pfa):
    """One channel (one look): the chain's CFAR on the far-range noise of a real frame fires
    within a factor 2 of the requested rate (measured: 1.18x / 0.84x and 1.10x / 1.64x)."""
    proc, adc = _single_channel(name)
    stat, mask = _stage_alarms(RadarProcessor(proc.calib, pfa=pfa), adc)
    region = _far_noise(stat.shape)
    rate = (mask & region).sum() / region.sum()
    assert 0.5 * pfa <= rate <= 2.0 * pfa, f"{name}: {rate / pfa:.2f}x the requested {pfa:g}"


def _eight_channel_rate(run: Path, pfa: float, **settings) -> float:
    """The chain's false-alarm rate on the 8-channel frame's far-range noise, over ``pfa``."""
    proc, adc = _proc_and_frame(run, pfa=pfa, **settings)
    stat, mask = _stage_alarms(proc, adc)
    region = _far_noise(stat.shape)
    return float((mask & region).sum() / region.sum() / pfa)


@pytest.mark.parametrize("pfa", [1e-2, 1e-3])
def test_cfar_false_alarms_on_real_eight_channel_noise_within_2x(real_run, pfa):
    """Eight channels, the chain's defaults: within 2x of the requested rate on the far-range
    noise (measured 1.45x / 0.94x; 4,268 cells, so 1e-3 expects 4 alarms and only the upper
    bound is asserted there). The finding of issue 29: the receiver's anti-alias roll-off
    lowers the floor ~9 dB over range bins 116-122, and a CA window straddling it fired 3.2x
    (1e-2) and 8x (1e-3) here; flattening the floor along range (``cfar_range_floor``) is
    what holds the rate."""
    rate = _eight_channel_rate(real_run[0], pfa)
    assert rate <= 2.0, f"{rate:.2f}x the requested {pfa:g}"
    if pfa >= 1e-2:
        assert rate >= 0.5, f"{rate:.2f}x the requested {pfa:g}"
        before = _eight_channel_rate(real_run[0], pfa, cfar_range_floor=False)
        assert before > 2.0, f"{before:.2f}x the requested {pfa:g} without the flattening"


def _beam_fraction(rd: np.ndarray, d: int, r: int) -> float:
    """Share of a cell's power over its 8 channels that the best single direction explains
    (TDM phase of either sign): near 1 for one return, ~0.44 (median) for noise."""
    nd = rd.shape[2]
    best = 0.0
    for sign in (1.0, -1.0):
        v = np.concatenate([rd[0, :, d, r], rd[1, :, d, r] * np.exp(1j * sign * np.pi
                                                                     * (d - nd // 2) / nd)])
        beams = np.abs(np.fft.fft(v, 256)) ** 2
        best = max(best, float(beams.max() / (v.size * np.sum(np.abs(v) ** 2))))
    return best


def test_alarms_left_out_of_the_noise_are_returns(real_run):
    """Why the noise region starts at range bin 84: most of the default chain's alarms in bins
    58-83 (beside and behind the moving return; measured 85 of 135) are one direction's
    return — their channels' beam fraction above what only 1 noise cell in 1000 reaches."""
    proc, adc = _proc_and_frame(real_run[0], pfa=1e-3)
    rd = proc.range_doppler(adc)
    stat, mask = _stage_alarms(proc, adc)
    noise = np.argwhere(_far_noise(stat.shape))
    pick = np.random.default_rng(0).choice(len(noise), 2000, replace=False)
    level = np.quantile([_beam_fraction(rd, d, r) for d, r in noise[pick]], 0.999)
    near = np.argwhere(mask & (np.arange(stat.shape[1]) >= 58) & (np.arange(stat.shape[1]) < 84))
    coherent = np.mean([_beam_fraction(rd, d, r) > level for d, r in near])
    assert len(near) >= 20 and coherent >= 0.5, (len(near), coherent, level)
