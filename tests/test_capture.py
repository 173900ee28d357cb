"""``coloradar import-capture``: raw TI captures laid out by an independent test-side writer
(tests/_capture_writer.py) in every byte order are imported, and the run's frames hold the
written values and show the simulated targets at their range, angle and range rate."""

from __future__ import annotations

import json
import os
import runpy
import warnings
from pathlib import Path

import numpy as np
import pytest

import _capture_writer as cw
from coloradar.capture import import_capture
from coloradar.cli.main import main
from coloradar.dataset import open_sequence
from coloradar.dsp import RadarProcessor
from coloradar.errors import (
    FormatError,
    MissingDataError,
    OutputExistsError,
    SettingsError,
)
from coloradar.formats import read_radar_pointcloud

ORDER = [0, 2, 1]                        # TX0, TX2, TX1: the ColoRadar single chip's order
ROOT = Path(__file__).resolve().parents[1]
TARGETS = [(5.0, 20.0, 1.6), (9.0, -30.0, -2.4)]   # range m, azimuth deg, range rate m/s


@pytest.fixture(scope="module")
def frames() -> np.ndarray:
    return cw.target_frames(cw.truth_calib(ORDER), TARGETS, 2)


def _open(run: Path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # the other radar's preset, the rig's extrinsics
        return open_sequence(run)


def _assert_targets(run: Path, radar: str, targets, frame: int = 0) -> None:
    """Each target is detected within a range bin, 3° of azimuth and half a Doppler bin."""
    seq = _open(run)
    calib = seq.calib.radar(radar)
    det = RadarProcessor(calib).detect(seq.stream(f"{radar}/adc")[frame])
    w = calib.waveform
    for r, az, v in targets:
        ok = ((np.abs(det.range - r) < w.range_bin_width)
              & (np.abs(np.degrees(det.azimuth) - az) < 3.0)
              & (np.abs(det.range_rate - v) < 0.5 * w.velocity_bin_width))
        found = np.c_[det.range, np.degrees(det.azimuth), det.range_rate].round(2)
        assert ok.any(), f"target at {r} m, {az}°, {v} m/s not found; detections: {found}"


def _write(tmp: Path, name: str, data: bytes, cfg_name: str, cfg_text: str,
           setup: str | None = None) -> tuple[Path, Path]:
    tmp.mkdir(parents=True, exist_ok=True)
    (tmp / name).write_bytes(data)
    (tmp / cfg_name).write_text(cfg_text)
    if setup is not None:
        (tmp / cfg_name.replace(".mmwave.json", ".setup.json")).write_text(setup)
    return tmp / name, tmp / cfg_name


# ------------------------------------------------------------------------ byte layouts
LAYOUTS = {
    # name: (writer kwargs, config kind, config kwargs)
    "sdk-2lane-iq": (dict(lanes=2, iq="iq"), "cfg", dict()),
    "sdk-2lane-qi": (dict(lanes=2, iq="qi"), "cfg", dict(swap=True)),
    "sdk-real": (dict(lanes=2, real=True), "cfg", dict(real=True)),
    "studio-4lane-iq": (dict(lanes=4, iq="iq", interleave=True), "json",
                        dict(lanes=4, interleave=True)),
    "studio-4lane-qi": (dict(lanes=4, iq="qi", interleave=True), "json",
                        dict(lanes=4, interleave=True, swap=True)),
    "studio-2lane-complex2x": (dict(lanes=2, iq="iq"), "json", dict(complex2x=True)),
    "studio-4lane-real": (dict(lanes=4, real=True, interleave=True), "json",
                          dict(lanes=4, interleave=True, real=True)),
}


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_dca1000_layouts_round_trip_to_the_targets(tmp_path, frames, layout):
    wkw, kind, ckw = LAYOUTS[layout]
    data = cw.dca1000_bytes(frames, **wkw)
    if kind == "cfg":
        cap, cfg = _write(tmp_path, "adc_data.bin", data, "profile.cfg", cw.sdk_cfg(ORDER, **ckw))
        board = "AWR1843BOOST"
    else:
        mm, setup = cw.studio_json(ORDER, **ckw)
        cap, cfg = _write(tmp_path, "adc_data.bin", data, "capture.mmwave.json", mm, setup)
        board = None                                # from the setup.json's mmWaveDevice
    res = import_capture(cap, tmp_path / "run", config=cfg, board=board, start_time=1.7e9)
    assert res.frames_written == 2 and res.radar == "single_chip"
    seq = _open(tmp_path / "run")
    want = frames.real if wkw.get("real") else frames
    for i in range(2):
        np.testing.assert_array_equal(seq.single_chip.adc[i], want[i].astype(np.complex64))
    np.testing.assert_allclose(seq.single_chip.adc.timestamps, 1.7e9 + np.array([0.0, 0.05]))
    _assert_targets(tmp_path / "run", "single_chip", TARGETS)


def test_wrong_iq_order_mirrors_the_targets(tmp_path, frames):
    """Reading QI bytes as IQ conjugates the signal: a target at range R shows at the mirrored
    beat frequency, so nothing is found at 5 m and 20° (the option matters)."""
    cap, cfg = _write(tmp_path, "adc_data.bin", cw.dca1000_bytes(frames, iq="qi"),
                      "profile.cfg", cw.sdk_cfg(ORDER, swap=True))
    import_capture(cap, tmp_path / "run", config=cfg, board="awr1843", iq_order="iq")
    with pytest.raises(AssertionError, match="not found"):
        _assert_targets(tmp_path / "run", "single_chip", TARGETS[:1])


# ------------------------------------------------------------------------ packet dumps
def test_packet_dump_with_drops_reports_frames_and_never_shifts(tmp_path):
    fr = cw.target_frames(cw.truth_calib(ORDER), TARGETS, 4, seed=1)
    stream = cw.dca1000_bytes(fr)
    fb = len(stream) // 4
    # Packet 33 straddles frames 0 and 1 (bytes 48,048..49,503; a frame is 49,152 bytes).
    drop = (33,)
    assert 33 * 1456 < fb < 34 * 1456
    dump = cw.packet_dump(stream, drop=drop)
    cap, cfg = _write(tmp_path, "adc_data_Raw_0.bin", dump, "profile.cfg",
                      cw.sdk_cfg(ORDER, frames=4))
    res = import_capture(cap, tmp_path / "run", config=cfg, board="AWR1843BOOST")
    assert res.left_out == (0, 1) and res.dropped_packets == 1 and res.frames_written == 2
    seq = _open(tmp_path / "run")
    # Frames 2 and 3 keep their numbers and bytes; frames 0 and 1 are holes (nan timestamps).
    assert list(seq.single_chip.adc.frame_ids) == [2, 3]
    np.testing.assert_array_equal(seq.single_chip.adc[0], fr[2].astype(np.complex64))
    np.testing.assert_array_equal(seq.single_chip.adc[1], fr[3].astype(np.complex64))
    rec = json.loads((tmp_path / "run" / "capture_import.json").read_text())
    assert rec["left_out"] == [0, 1] and any("dropped packets" in n for n in rec["notes"])
    # Zero-filled instead: four files, frames 0 and 1 all zeros, the others intact.
    res = import_capture(cap, tmp_path / "run0", config=cfg, board="AWR1843BOOST",
                         dropped="zero")
    assert res.zero_filled == (0, 1) and res.frames_written == 4
    seq = _open(tmp_path / "run0")
    assert not np.any(seq.single_chip.adc[1])
    np.testing.assert_array_equal(seq.single_chip.adc[3], fr[3].astype(np.complex64))
    _assert_targets(tmp_path / "run0", "single_chip", TARGETS, frame=2)


def test_packet_dump_cut_inside_a_frame_is_named(tmp_path, frames):
    stream = cw.dca1000_bytes(frames)
    dump = cw.packet_dump(stream[:len(stream) - 1000])
    cap, cfg = _write(tmp_path, "adc_data_Raw_0.bin", dump, "p.cfg", cw.sdk_cfg(ORDER))
    with pytest.raises(FormatError, match=r"frame 1 \(from 0\) has 48,152 bytes, 1,000 bytes short"):
        import_capture(cap, tmp_path / "run", config=cfg, board="AWR1843BOOST")
    res = import_capture(cap, tmp_path / "run", config=cfg, board="AWR1843BOOST",
                         partial_last_frame="drop")
    assert res.frames_written == 1


# ------------------------------------------------------------------------------ MMWCAS
CASCADE_W = dict(cw.SMALL, loops=8)
# Slot order of the ColoRadar cascade (its antenna_cfg's TX order), as global TX numbers.
CASCADE_ORDER = [11, 10, 9, 2, 1, 0, 8, 7, 6, 5, 4, 3]
CASCADE_TARGETS = [(6.0, 15.0, 0.5), (10.0, -25.0, -0.9)]


def _cascade(tmp_path: Path, *, truncate: str | None = None, nf: int = 3
             ) -> tuple[Path, Path, np.ndarray, np.ndarray]:
    calib = cw.truth_calib(CASCADE_ORDER, CASCADE_W, tx_table=cw.CASCADE_TX,
                           rx_pos=[(a, 0) for a in cw.CASCADE_RX], num_rx=16)
    fr = cw.target_frames(calib, CASCADE_TARGETS, nf, amplitude=2e4)
    ticks = 5_000_000 + np.arange(nf) * 50_000 + np.array([0, 7, 3])[:nf]   # µs, jittered
    cw.write_mmwcas(tmp_path / "capture", fr, ticks, truncate_device=truncate)
    (tmp_path / "cascade.json").write_text(cw.cascade_json(CASCADE_ORDER, w=CASCADE_W, frames=nf))
    return tmp_path / "capture", tmp_path / "cascade.json", fr, ticks


def test_mmwcas_folder_round_trips_with_rx_order_and_idx_timestamps(tmp_path):
    cap, cfg, fr, ticks = _cascade(tmp_path)
    res = import_capture(cap, tmp_path / "run", config=cfg, start_time=1.7e9)
    assert res.radar == "cascade" and res.board == "MMWCAS-RF-EVM"
    assert res.frames_written == 2            # the first frame (before the config settles) left out
    seq = _open(tmp_path / "run")
    np.testing.assert_array_equal(seq.cascade.adc[0], fr[1].astype(np.complex64))
    np.testing.assert_allclose(seq.cascade.adc.timestamps,
                               1.7e9 + (ticks[1:] - ticks[1]) * 1e-6, atol=1e-7)
    _assert_targets(tmp_path / "run", "cascade", CASCADE_TARGETS)
    res = import_capture(cap, tmp_path / "run_all", config=cfg, keep_first_frame=True)
    assert res.frames_written == 3


def test_mmwcas_segments_are_read_in_order(tmp_path):
    """With ``first_frame_skip="recording"`` only the recording's first frame is left out."""
    cap, cfg, fr, ticks = _cascade(tmp_path)
    more = fr[::-1].copy()                               # a second segment, other frames
    cw.write_mmwcas(cap, more, ticks + 150_000, segment=1)
    (tmp_path / "cascade.json").write_text(cw.cascade_json(CASCADE_ORDER, w=CASCADE_W, frames=6))
    res = import_capture(cap, tmp_path / "run", config=cfg, start_time=0.0,
                         first_frame_skip="recording")
    assert res.frames_written == 5 and res.left_out == ()
    seq = _open(tmp_path / "run")
    want = np.concatenate([fr, more])[1:]
    for k in range(5):
        np.testing.assert_array_equal(seq.cascade.adc[k], want[k].astype(np.complex64))
    all_ticks = np.concatenate([ticks, ticks + 150_000])
    np.testing.assert_allclose(seq.cascade.adc.timestamps, (all_ticks[1:] - all_ticks[1]) * 1e-6)


def test_mmwcas_first_frame_of_every_segment_is_left_out_as_ti_does(tmp_path, capsys):
    """Issue 41 item 15: TI's cascade processing (``cascade_MIMO_signalProcessing.m``) loops
    over the segments and, in each, over ``frameIdx = 2:numValidFrames``: the first frame of
    every segment is left out. The later segments' first frames are holes (no file, a ``nan``
    timestamp line); no frame is shifted."""
    cap, cfg, fr, ticks = _cascade(tmp_path)
    more = fr[::-1].copy()
    cw.write_mmwcas(cap, more, ticks + 150_000, segment=1)
    (tmp_path / "cascade.json").write_text(cw.cascade_json(CASCADE_ORDER, w=CASCADE_W, frames=6))
    res = import_capture(cap, tmp_path / "run", config=cfg, start_time=0.0)
    assert res.frames_written == 4 and res.left_out == (3,)   # capture frames 0 and 3 out
    seq = _open(tmp_path / "run")
    assert list(seq.cascade.adc.frame_ids) == [0, 1, 3, 4]    # run frame k = capture frame k+1
    for k, want in enumerate([fr[1], fr[2], more[1], more[2]]):
        np.testing.assert_array_equal(seq.cascade.adc[k], want.astype(np.complex64))
    all_ticks = np.concatenate([ticks, ticks + 150_000])
    np.testing.assert_allclose(seq.cascade.adc.timestamps,
                               (all_ticks[[1, 2, 4, 5]] - all_ticks[1]) * 1e-6)
    rec = json.loads((tmp_path / "run" / "capture_import.json").read_text())
    assert rec["left_out"] == [3] and any("segment 0001" in n for n in rec["notes"])
    # The CLI offers the other rule.
    assert main(["import-capture", str(cap), str(tmp_path / "run_rec"), "--config", str(cfg),
                 "--first-frame-skip", "recording"]) == 0
    assert "5 cascade frames" in capsys.readouterr().out


def test_mmwcas_preallocated_data_files_import_with_a_note(tmp_path):
    """Issue 41 item 14: mmWave Studio's ``Cascade_Capture.lua`` preallocates each data file at
    2047 MB; the index counts the frames. The frame size comes from the configuration, checked
    against the index entries' ``size`` and ``offset``; the bytes after the last indexed frame
    are a note."""
    calib = cw.truth_calib(CASCADE_ORDER, CASCADE_W, tx_table=cw.CASCADE_TX,
                           rx_pos=[(a, 0) for a in cw.CASCADE_RX], num_rx=16)
    fr = cw.target_frames(calib, CASCADE_TARGETS, 3, amplitude=2e4)
    ticks = 5_000_000 + np.arange(3) * 50_000
    cap = tmp_path / "capture"
    size = 2047 * 2**20
    cw.write_mmwcas(cap, fr, ticks, file_size=size)           # sparse: no disk written
    cfg = tmp_path / "cascade.json"
    cfg.write_text(cw.cascade_json(CASCADE_ORDER, w=CASCADE_W, frames=3))
    assert (cap / "slave3_0000_data.bin").stat().st_size == size
    res = import_capture(cap, tmp_path / "run", config=cfg, start_time=1.7e9,
                         keep_first_frame=True)
    assert res.frames_written == 3
    seq = _open(tmp_path / "run")
    for k in range(3):
        np.testing.assert_array_equal(seq.cascade.adc[k], fr[k].astype(np.complex64))
    per = 98_304                                               # 64 x 8 x 12 x 4 RX x 4 bytes
    note = [n for n in res.notes if "after the last indexed frame" in n]
    assert note and f"master_0000_data.bin {size - 3 * per:,}" in note[0]
    _assert_targets(tmp_path / "run", "cascade", CASCADE_TARGETS)
    # An index entry whose size disagrees with the configuration's frame is still an error.
    idx = cap / "slave2_0000_idx.bin"
    raw = bytearray(idx.read_bytes())
    entry = 24 + 48 * 1                                        # frame 1; size at byte 28
    raw[entry + 28:entry + 32] = (per + 4).to_bytes(4, "little")
    idx.write_bytes(bytes(raw))
    with pytest.raises(FormatError, match=r"slave2_0000_idx\.bin: frame 1 of slave2_0000_data"
                                          r"\.bin is 98,308 bytes .* = 98,304 bytes"):
        import_capture(cap, tmp_path / "run2", config=cfg)
    raw[entry + 28:entry + 32] = per.to_bytes(4, "little")
    raw[entry + 40:entry + 48] = (per + 8).to_bytes(8, "little")  # offset: not after frame 0
    idx.write_bytes(bytes(raw))
    with pytest.raises(FormatError, match=r"slave2_0000_idx\.bin: frame 1 .* at byte 98,312, "
                                          r"but .* put it at 98,304"):
        import_capture(cap, tmp_path / "run2", config=cfg)
    assert not (tmp_path / "run2").exists()


def test_mmwcas_iq_swap_is_read_as_the_devices_send_it(tmp_path):
    """Issue 41 item 16: ``iqSwapSel`` is the AWR2243's own output setting (mmWaveLink
    ``rlDevDataFmtCfg_t``: 0 I first, 1 Q first) and the TDA2 records the words as sent; TI's
    reader reads I first because TI's scripts configure 0. A Q-first capture is read Q first,
    with a note naming the difference from TI's reader; ``--iq-order iq`` reads it as TI's
    reader would (Q + jI)."""
    calib = cw.truth_calib(CASCADE_ORDER, CASCADE_W, tx_table=cw.CASCADE_TX,
                           rx_pos=[(a, 0) for a in cw.CASCADE_RX], num_rx=16)
    fr = cw.target_frames(calib, CASCADE_TARGETS, 2, amplitude=2e4)
    cap = tmp_path / "capture"
    cw.write_mmwcas(cap, fr, 5_000_000 + np.arange(2) * 50_000, iq="qi")
    cfg = tmp_path / "cascade.json"
    cfg.write_text(cw.cascade_json(CASCADE_ORDER, w=CASCADE_W, frames=2, iq_swap=1))
    res = import_capture(cap, tmp_path / "run", config=cfg, keep_first_frame=True)
    assert "complex QI" in res.layout
    assert any("iqSwapSel 1" in n and "TI's reader" in n for n in res.notes), res.notes
    seq = _open(tmp_path / "run")
    np.testing.assert_array_equal(seq.cascade.adc[0], fr[0].astype(np.complex64))
    _assert_targets(tmp_path / "run", "cascade", CASCADE_TARGETS)
    res = import_capture(cap, tmp_path / "run_ti", config=cfg, keep_first_frame=True,
                         iq_order="iq")
    assert not any("iqSwapSel" in n for n in res.notes)
    seq = _open(tmp_path / "run_ti")
    np.testing.assert_array_equal(seq.cascade.adc[1],
                                  (fr[1].imag + 1j * fr[1].real).astype(np.complex64))


def test_mmwcas_missing_or_short_device_file_is_named(tmp_path):
    cap, cfg, _, _ = _cascade(tmp_path, truncate="slave1", nf=2)
    short = r"slave1_0000_data\.bin.*4 RX.*frame 1 \(from 0\) has 98,204 bytes, 100 bytes short"
    with pytest.raises(FormatError, match=short):
        import_capture(cap, tmp_path / "run", config=cfg)
    (tmp_path / "half.json").write_text(cw.cascade_json(CASCADE_ORDER, w=dict(CASCADE_W, loops=4),
                                                         frames=2))
    with pytest.raises(FormatError, match=r"master_0000_idx\.bin: frame 0 of master_0000_data"
                                          r"\.bin is 98,304 bytes .* 49,152 bytes: the "
                                          r"configuration disagrees"):
        import_capture(cap, tmp_path / "run", config=tmp_path / "half.json")
    (cap / "slave2_0000_data.bin").unlink()
    with pytest.raises(MissingDataError, match=r"missing slave2_0000_data\.bin"):
        import_capture(cap, tmp_path / "run", config=cfg)
    assert not (tmp_path / "run").exists()


def test_imported_antennas_are_coloradars_for_its_tx_orders(tmp_path, frames):
    """With ColoRadar's TX orders, the boards' layouts give the antenna positions of the
    released calibration (read from the reference files, never copied)."""
    from _synth import REFERENCE_CALIB
    from coloradar.calib import load_calibration
    if not REFERENCE_CALIB.is_dir():
        pytest.skip(f"reference calibration not at {REFERENCE_CALIB}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = load_calibration(REFERENCE_CALIB)
    cap, cfg = _write(tmp_path, "adc_data.bin", cw.dca1000_bytes(frames), "p.cfg",
                      cw.sdk_cfg(ORDER))
    import_capture(cap, tmp_path / "single", config=cfg, board="AWR1843BOOST")
    got = _open(tmp_path / "single").calib.single_chip.antenna
    np.testing.assert_array_equal(got.tx_positions, ref.single_chip.antenna.tx_positions)
    np.testing.assert_array_equal(got.rx_positions, ref.single_chip.antenna.rx_positions)
    cap, cfg, _, _ = _cascade(tmp_path, nf=2)
    import_capture(cap, tmp_path / "cascade", config=cfg)
    got = _open(tmp_path / "cascade").calib.cascade.antenna
    np.testing.assert_array_equal(got.tx_positions, ref.cascade.antenna.tx_positions)
    # The data's RX channels are in device order; as a set they are ColoRadar's array.
    np.testing.assert_array_equal(np.sort(got.rx_positions[:, 0]),
                                  ref.cascade.antenna.rx_positions[:, 0])
    np.testing.assert_array_equal(got.virtual.unique_positions,
                                  ref.cascade.antenna.virtual.unique_positions)


# ----------------------------------------------------------------------- bad captures
def test_bad_captures_get_named_errors_and_leave_nothing(tmp_path, frames):
    data = cw.dca1000_bytes(frames)
    cap, cfg = _write(tmp_path, "adc_data.bin", data[:-6], "p.cfg", cw.sdk_cfg(ORDER))
    with pytest.raises(FormatError, match=r"frame 1 \(from 0\) has 49,146 bytes, 6 bytes short"):
        import_capture(cap, tmp_path / "run", config=cfg, board="AWR1843BOOST")
    # A config with 2 RX where the data has 4: twice the frames the config asks for.
    cap, cfg = _write(tmp_path, "adc_data.bin", data, "p2.cfg", cw.sdk_cfg(ORDER, rx_mask=0x3))
    with pytest.raises(FormatError, match="disagrees with the file"):
        import_capture(cap, tmp_path / "run", config=cfg, board="AWR1843BOOST")
    # A ramp that ends before the 64 samples at 10 Msps from 6 µs do (12.4 µs).
    cap, cfg = _write(tmp_path, "adc_data.bin", data, "p3.cfg",
                      cw.sdk_cfg(ORDER, w=dict(cw.SMALL, ramp_end_us=10.0)))
    with pytest.raises(FormatError, match=r"samples until 12\.4 µs .* ramp ends at 10 µs"):
        import_capture(cap, tmp_path / "run", config=cfg, board="AWR1843BOOST")
    cap, cfg = _write(tmp_path, "adc_data.bin", data, "p.cfg", cw.sdk_cfg(ORDER))
    with pytest.raises(SettingsError, match="unknown board 'AWR9999'"):
        import_capture(cap, tmp_path / "run", config=cfg, board="AWR9999")
    with pytest.raises(SettingsError, match="does not name the radar board"):
        import_capture(cap, tmp_path / "run", config=cfg)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adc_data.bin", "p.cfg", "p2.cfg", "p3.cfg"]
    # An existing run is not replaced without --overwrite; a folder that no import wrote never.
    import_capture(cap, tmp_path / "run", config=cfg, board="AWR1843BOOST")
    with pytest.raises(OutputExistsError):
        import_capture(cap, tmp_path / "run", config=cfg, board="AWR1843BOOST")
    import_capture(cap, tmp_path / "run", config=cfg, board="AWR1843BOOST", overwrite=True)
    (tmp_path / "mine").mkdir()
    with pytest.raises(OutputExistsError, match="not a run written by import-capture"):
        import_capture(cap, tmp_path / "mine", config=cfg, board="AWR1843BOOST", overwrite=True)
    with pytest.raises(SettingsError, match="would contain the capture"):
        import_capture(cap, tmp_path, config=cfg, board="AWR1843BOOST", overwrite=True)


# ---------------------------------------------------------------------------- the CLI
def test_readme_example_capture_imports_and_processes_to_its_targets(tmp_path, capsys,
                                                                      monkeypatch):
    """The README's instructions: ``python docs/capture_example.py example_capture``, then
    ``coloradar import-capture … && coloradar process …``; the points hold the script's
    targets."""
    monkeypatch.chdir(tmp_path)
    script = runpy.run_path(str(ROOT / "docs" / "capture_example.py"))
    script["main"](Path("example_capture"))
    assert main(["import-capture", "example_capture/adc_data.bin", "example_run", "--config",
                 "example_capture/profile.cfg", "--board", "AWR1843BOOST"]) == 0
    assert "4 single_chip frames" in capsys.readouterr().out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["process", "example_run", "--out", "example_out", "--jobs", "1",
                     "--quiet", "--products", "pointclouds"]) == 0
    for k in range(4):
        pts = read_radar_pointcloud(f"example_out/single_chip/pointclouds/data/"
                                    f"radar_pointcloud_{k}.bin")
        rng = np.linalg.norm(pts[:, :3], axis=1)
        az = np.degrees(np.arctan2(pts[:, 1], pts[:, 0]))
        for r, a, v in script["TARGETS"]:
            assert np.any((np.abs(rng - r) < 0.4) & (np.abs(az - a) < 3)
                          & (np.abs(pts[:, 4] - v) < 0.4)), (k, r, a, v)


def test_cli_replaces_its_own_import_with_overwrite_and_gives_normal_modes(tmp_path, capsys,
                                                                            monkeypatch):
    """``import-capture … --overwrite`` replaces a run an earlier import wrote (the one-output
    rule must not take it for the user's dataset); the run's folders get the mode a plain
    ``mkdir`` gives."""
    monkeypatch.chdir(tmp_path)
    script = runpy.run_path(str(ROOT / "docs" / "capture_example.py"))
    script["main"](Path("example_capture"))
    argv = ["import-capture", "example_capture/adc_data.bin", "example_run", "--config",
            "example_capture/profile.cfg", "--board", "AWR1843BOOST"]
    assert main(argv) == 0
    umask = os.umask(0)
    os.umask(umask)
    assert (Path("example_run").stat().st_mode & 0o777) == 0o777 & ~umask
    assert main(argv) == 1                                   # exists: refused
    assert "--overwrite" in capsys.readouterr().err
    assert main([*argv, "--overwrite"]) == 0
    assert "4 single_chip frames" in capsys.readouterr().out


def test_mmwcas_empty_index_is_named(tmp_path):
    cap, cfg, _, _ = _cascade(tmp_path, nf=2)
    idx = cap / "master_0000_idx.bin"
    raw = bytearray(idx.read_bytes())
    raw[12:16] = (0).to_bytes(4, "little")                    # numIdx = 0
    idx.write_bytes(bytes(raw))
    with pytest.raises(FormatError, match=r"master_0000_idx\.bin: the index header says 0 frames"):
        import_capture(cap, tmp_path / "run", config=cfg)
    assert not (tmp_path / "run").exists()
    with pytest.raises(Exception, match="inside the capture"):
        import_capture(cap, cap / "run", config=cfg)
