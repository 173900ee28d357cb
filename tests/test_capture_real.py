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
from coloradar.dsp.cfar import (
    CFARConfig,
    cfar_window,
    effective_train_cells,
    power_correlation,
    run_cfar,
)
from coloradar.dsp.windows import window

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


def _chain_cfar(proc: RadarProcessor, power: np.ndarray, pfa: float, looks: float) -> np.ndarray:
    """The chain's CFAR (kind, guard, train, edges, excision, the windows' cell correlation) on
    a ``(doppler, range)`` power map, through the public :func:`coloradar.dsp.cfar.run_cfar`."""
    s = proc.settings
    nd = power.shape[0]
    ns = proc.calib.waveform.num_samples
    h = [g + t for g, t in zip(s.cfar_guard, s.cfar_train, strict=True)]
    corr = (power_correlation(window(s.doppler_window, proc.calib.waveform.num_chirps), nd,
                              2 * h[0]),
            power_correlation(window(s.range_window, ns), proc.range_fft_size, 2 * h[1]))
    n_all, _ = cfar_window(s.cfar_guard, s.cfar_train, split_axis=1)
    e_all, _ = effective_train_cells(s.cfar_guard, s.cfar_train, corr, split_axis=1,
                                     wrap=(nd, None))
    return run_cfar(power, CFARConfig("ca", s.cfar_guard, s.cfar_train, pfa, looks=looks,
                                      mode=("wrap", "truncate"), split_axis=1,
                                      cell_factor=e_all / n_all,
                                      excise=s.cfar_excision)).detections


def _far_noise(power: np.ndarray) -> np.ndarray:
    """The far-range cells (second half of the range bins) off the static returns' zero-Doppler
    bins (|Doppler bin| > 2)."""
    nd, nr = power.shape
    region = np.zeros(power.shape, dtype=bool)
    region[:, nr // 2:] = True
    region[np.abs(np.arange(nd) - nd // 2) <= 2] = False
    return region


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
    """One channel (one look): the chain's CFAR on the far-range cells of a real frame fires
    within a factor 2 of the requested rate (measured: 1.19x / 0.83x and 1.45x / 1.78x)."""
    proc, adc = _single_channel(name)
    power = proc.range_doppler_power(adc).astype(np.float64)
    region = _far_noise(power)
    rate = (_chain_cfar(proc, power, pfa, looks=1) & region).sum() / region.sum()
    assert 0.5 * pfa <= rate <= 2.0 * pfa, f"{name}: {rate / pfa:.2f}x the requested {pfa:g}"


def _chain_far_alarms(run: Path, pfa: float, looks: str) -> tuple[int, int]:
    """False alarms of the chain's own CFAR stage (its statistic, its looks setting) on the
    far-range noise cells of the 8-channel frame, and the number of those cells."""
    proc, adc = _proc_and_frame(run, pfa=pfa, cfar_looks=looks)
    stage = proc.detector.cfar
    stat, _, num_looks, _ = stage.statistic(proc.range_doppler(adc))
    mask, _ = stage.cfar_mask(stat, num_looks)
    region = _far_noise(stat)
    return int((mask & region).sum()), int(region.sum())


@pytest.mark.parametrize("pfa", [1e-2, 1e-3])
def test_cfar_false_alarms_on_real_eight_channel_noise_within_2x(real_run, pfa):
    """The issue-29 finding: the 8 channels' far-range cells hold power common to all of them
    (their powers correlate at 0.97), so their sum fluctuates like fewer looks than 8. With the
    looks measured per frame (cfar_looks="auto") the chain stays within 2x of the requested
    rate (measured 0.28x / 1.52x); taking the channels as 8 independent looks (the default
    "channels") it does not (3.1x / 11x; docs/capture.md says where those cells are)."""
    alarms, cells = _chain_far_alarms(real_run[0], pfa, "auto")
    assert alarms <= 2.0 * pfa * cells, f"{alarms / cells / pfa:.2f}x the requested {pfa:g}"
    alarms, cells = _chain_far_alarms(real_run[0], pfa, "channels")
    assert alarms > 2.0 * pfa * cells, f"{alarms / cells / pfa:.2f}x the requested {pfa:g}"
