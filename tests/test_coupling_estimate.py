"""The coupling estimated from a run's frames (``coloradar calibrate coupling``), its file, and the
simulator's planted coupling (issue 28; docs/calibration.md)."""

from __future__ import annotations

import os
import re
import warnings
from dataclasses import replace

import numpy as np
import pytest

from _synth import REFERENCE_CALIB
from coloradar.calib import (
    CouplingCalib,
    parse_coupling_calib,
    preset_radar,
    read_coupling_calib,
    with_coupling,
    write_coupling_calib,
)
from coloradar.cli.calibrate import coupling_calibration
from coloradar.cli.main import build_parser, main
from coloradar.dsp import RadarProcessor
from coloradar.dsp.coupling_estimate import estimate_coupling
from coloradar.errors import CalibrationError, CalibrationWarning, ColoradarError, OutputExistsError
from coloradar.sim.run import simulate_run
from coloradar.sim.truth import load_truth

RELEASED = REFERENCE_CALIB / "single_chip" / "coupling_calib.txt"
needs_released = pytest.mark.skipif(not RELEASED.is_file(),
                                    reason=f"the release's coupling file not at {RELEASED}")


def _coupling(rng, shape, amplitude=60.0):
    """Leakage tones at a few near ranges, per channel: complex (tx, rx, sample) [counts]."""
    ntx, nrx, ns = shape
    n = np.arange(ns)
    bins = np.array([0.2, 0.7, 1.3, 2.4])
    amp = (amplitude / (1 + np.arange(4)) * rng.rayleigh(1.0, (ntx, nrx, 4))
           * np.exp(1j * rng.uniform(-np.pi, np.pi, (ntx, nrx, 4))))
    return amp @ np.exp(2j * np.pi * bins[:, None] * n[None, :] / ns)


def _frames(rng, coupling, nc, n_frames, target=0.0, doppler=0.0, step=0.0, present=1.0,
            noise=3.0):
    """Frames (tx, rx, chirp, sample) of coupling + noise + one point target at range bin
    ``4 + step·i`` in frame ``i`` with a new phase each frame, ``doppler`` bins within a frame,
    in the first ``present`` fraction of the frames."""
    ntx, nrx, ns = coupling.shape
    n, c = np.arange(ns), np.arange(nc)
    out = []
    for i in range(n_frames):
        x = np.broadcast_to(coupling[:, :, None, :], (ntx, nrx, nc, ns)).astype(np.complex128)
        x = x + noise * (rng.standard_normal(x.shape) + 1j * rng.standard_normal(x.shape))
        if target and i < present * n_frames:
            rbin = 4.3 + step * i
            phase = np.exp(1j * rng.uniform(-np.pi, np.pi, (ntx, nrx, 1, 1)))
            tone = np.exp(2j * np.pi * (rbin * n[None, :] / ns + doppler * c[:, None] / nc))
            x = x + target * phase * tone
        out.append(x.astype(np.complex64))
    return out


def _rel_error(est: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return np.linalg.norm(est - truth, axis=-1) / np.linalg.norm(truth, axis=-1)


def test_estimate_matches_the_planted_coupling_in_the_files_representation():
    rng = np.random.default_rng(1)
    cpl = _coupling(rng, (3, 4, 32))
    k = 16
    # The file holds the unwindowed, unnormalised FFT over samples (numpy's, independently).
    truth = np.fft.fft(cpl, axis=-1)[..., :k]
    est = estimate_coupling(_frames(rng, cpl, 16, 12), k)
    assert est.frames == 12 and est.coupling.data.shape == (3, 4, k)
    assert est.coupling.num_doppler_bins == 16
    # Noise of 3 counts per I/Q over 12 frames x 16 chirps x 32 samples: ~0.2 % of the leakage.
    assert _rel_error(est.coupling.data, truth).max() < 0.01
    # The reported standard error is the scale of the true error (a 0.5..3x band for 12 frames).
    err = np.abs(est.coupling.data - truth)
    ratio = np.sqrt(np.mean(err**2) / np.mean(est.standard_error.astype(float) ** 2))
    assert 0.5 < ratio < 3.0


def test_estimate_ignores_a_strong_target_moving_through_the_scene():
    """A target 3x the strongest leakage path, approaching: 0.6 range bins a frame, so 5.5
    Doppler bins within one (16 loops of 32 samples; a rig at ~1 m/s). The chirp mean's
    Doppler window is what keeps it out: without one, its sidelobes reach every bin."""
    rng = np.random.default_rng(2)
    cpl = _coupling(rng, (3, 4, 32))
    k = 16
    truth = np.fft.fft(cpl, axis=-1)[..., :k]
    frames = _frames(rng, cpl, 16, 25, target=180.0, doppler=5.5, step=0.6)
    for statistic in ("trimmed", "median", "mean"):
        err = _rel_error(estimate_coupling(frames, k, statistic=statistic).coupling.data, truth)
        assert err.max() < 0.01, statistic
    bare = estimate_coupling(frames, k, doppler_window="none", statistic="mean").coupling.data
    assert _rel_error(bare, truth).max() > 0.03


def test_estimate_ignores_a_static_target_in_a_few_frames():
    """A target 3x the strongest leakage path at zero Doppler (crossing the beam, or the rig
    pausing beside it) in 5 of 25 frames: the frame statistic leaves it out, a plain mean
    does not."""
    rng = np.random.default_rng(5)
    cpl = _coupling(rng, (3, 4, 32))
    k = 16
    truth = np.fft.fft(cpl, axis=-1)[..., :k]
    frames = _frames(rng, cpl, 16, 25, target=180.0, present=0.2)
    for statistic in ("trimmed", "median"):
        err = _rel_error(estimate_coupling(frames, k, statistic=statistic).coupling.data, truth)
        assert err.max() < 0.02, statistic
    mean = estimate_coupling(frames, k, statistic="mean").coupling.data
    assert _rel_error(mean, truth).max() > 0.1


def test_processing_with_the_estimate_removes_the_coupling():
    """The estimate is what RadarProcessor subtracts: processed with it, a frame's coupling is
    gone from every range bin the file covers (bin 0: its negative-frequency part is in no
    file, docs/dsp.md)."""
    rng = np.random.default_rng(3)
    rc = preset_radar("single_chip")
    ntx, nrx, nc, ns = rc.frame_shape
    cpl = _coupling(rng, (ntx, nrx, ns), amplitude=100.0)
    frames = _frames(rng, cpl, nc, 4, noise=1.0)
    est = estimate_coupling(frames, rc)
    assert est.coupling.num_range_bins == rc.heatmap.num_range_bins
    only = np.broadcast_to(cpl[:, :, None, :], rc.frame_shape).astype(np.complex64)
    z = nc // 2
    before = np.abs(RadarProcessor(rc).range_doppler(only)[:, :, z, 1:40]) ** 2
    after = np.abs(RadarProcessor(replace(rc, coupling=est.coupling))
                   .range_doppler(only)[:, :, z, 1:40]) ** 2
    assert before.max() > 1e3                                  # strong coupling there without
    assert after.max() < 1e-4 * before.max()


@needs_released
def test_writer_round_trip_and_the_released_file(tmp_path):
    rng = np.random.default_rng(4)
    data = (rng.normal(0, 1e4, (3, 4, 64)) + 1j * rng.normal(0, 1e4, (3, 4, 64)))
    c = CouplingCalib(data, 128)
    path = tmp_path / "coupling_calib.txt"
    write_coupling_calib(path, c)
    back = read_coupling_calib(path)
    assert back.num_doppler_bins == 128
    np.testing.assert_allclose(back.data, c.data, rtol=1e-5)      # %g: six significant digits
    with pytest.raises(OutputExistsError):
        write_coupling_calib(path, c)
    write_coupling_calib(path, CouplingCalib(data * 2, 128), overwrite=True)
    np.testing.assert_allclose(read_coupling_calib(path).data, 2 * c.data, rtol=1e-5)
    assert sorted(os.listdir(tmp_path)) == ["coupling_calib.txt"]   # no temporary file left
    # The released file, read and written back: the same text (and an unchanged TX 2 hole).
    text = RELEASED.read_text()
    with pytest.warns(CalibrationWarning, match="TX 2"):
        released = parse_coupling_calib(text)
    write_coupling_calib(tmp_path / "released.txt", released)
    assert (tmp_path / "released.txt").read_text().rstrip("\n") == text.rstrip("\n")


def test_with_coupling_picks_the_radar_of_the_files_size(tmp_path):
    from coloradar.calib import preset_calibration
    cal = preset_calibration()
    c = CouplingCalib(np.ones((3, 4, 64), dtype=np.complex64), 128)
    new = with_coupling(cal, c)
    assert new.single_chip.coupling is c and new.cascade.coupling is cal.cascade.coupling
    with pytest.raises(CalibrationError, match="does not fit the cascade"):
        with_coupling(cal, c, radar="cascade")
    with pytest.raises(CalibrationError, match="either"):
        with_coupling(cal, CouplingCalib(np.ones((2, 4, 8), dtype=np.complex64), 16))


@pytest.fixture(scope="module")
def released_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("cpl")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        res = simulate_run(out / "data", scene="corridor", duration=2.5, seed=3,
                           sensors=["single_chip", "groundtruth"], heatmaps=False,
                           coupling_calib=RELEASED, rest=1.0)
    return out, res


@needs_released
def test_simulator_carries_the_released_file_and_plants_coupling_on_every_tx(released_run):
    _out, res = released_run
    with pytest.warns(CalibrationWarning, match="TX 2"):
        written = read_coupling_calib(res.calib_path / "single_chip" / "coupling_calib.txt")
    with pytest.warns(CalibrationWarning):
        rel = read_coupling_calib(RELEASED)
    assert written.missing_tx == (2,)
    np.testing.assert_array_equal(written.data, rel.data)
    planted = load_truth(res.run_path)["single_chip/coupling"]            # (tx, rx, Ns)
    np.testing.assert_allclose(planted[:2, :, :64], rel.data[:2], rtol=1e-4, atol=0.05)
    assert np.abs(planted[2, :, :4]).min() > 100                         # TX 2 has leakage
    # The frames carry it: the chirp mean's FFT of a frame taken on the move is the planted
    # coupling (+ what of the scene is at zero Doppler, and noise).
    from coloradar.dataset import open_sequence
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        adc = open_sequence(res.run_path).single_chip.adc[-1]          # the rig moving
    mean = np.fft.fft(adc.astype(np.complex128).mean(axis=2), axis=-1)
    assert _rel_error(mean[..., :3], planted[..., :3]).max() < 0.05


@needs_released
def test_calibrate_command_writes_outside_the_dataset_only(released_run, tmp_path, capsys):
    _out, res = released_run
    target = tmp_path / "estimated.txt"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", CalibrationWarning)
        assert main(["calibrate", "coupling", str(res.run_path), "--out", str(target)]) == 0
        # The rig stands still for the first second (by the ground truth): those frames are
        # left out.
        said = re.search(r"from (\d+) of (\d+) frames .*\((\d+) left out: slower than 0\.1 m/s\)",
                         capsys.readouterr().out)
        assert said is not None
        used, total, still = map(int, said.groups())
        assert used + still == total and still >= 10                   # 1 s at 10 Hz, then easing
        est = read_coupling_calib(target)
        truth = load_truth(res.run_path)["single_chip/coupling"][..., :64]
        assert _rel_error(est.data, truth).max() < 0.05                  # 1.5 s of motion
        # Every frame, the still ones too: the corridor's static walls are taken for coupling.
        every = tmp_path / "every_frame.txt"
        assert main(["calibrate", "coupling", str(res.run_path), "--out", str(every),
                     "--min-speed", "0", "--quiet"]) == 0
        assert _rel_error(read_coupling_calib(every).data, truth).max() > 0.5
        assert main(["calibrate", "coupling", str(res.run_path), "--out", str(target)]) == 1
        assert "exists" in capsys.readouterr().err
        # The one rule of every command (cli._common.check_output_outside_dataset): not in the
        # run, not in its calibration (a file beside the runs in the root is allowed, as
        # root/processed is).
        for inside in (res.run_path / "c.txt", res.calib_path / "single_chip" / "c.txt"):
            assert main(["calibrate", "coupling", str(res.run_path), "--out", str(inside)]) == 1
            assert "never writes into a dataset" in capsys.readouterr().err
            assert not inside.exists()
        # What `coloradar process --coupling FILE` hands the batch: the run's calibration with
        # the estimated single-chip coupling.
        cal = coupling_calibration(res.run_path, None, target)
    np.testing.assert_array_equal(cal.single_chip.coupling.data, est.data)
    assert cal.single_chip.coupling.missing_tx == ()
    args = build_parser().parse_args(["process", str(res.run_path), "--out", "o",
                                      "--coupling", str(target)])
    assert args.coupling == str(target)
    with pytest.raises(ColoradarError):
        coupling_calibration(res.run_path, None, tmp_path / "missing.txt")
    # A single-chip file with `--radar cascade` would be silently unused: refused, naming the
    # file and both radars' sizes.
    with pytest.raises(ColoradarError, match=r"estimated\.txt.*does not fit the cascade"):
        coupling_calibration(res.run_path, None, target, "cascade")
