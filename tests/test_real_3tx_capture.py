"""A real 3-TX capture through the command line: mmwave-eyes' IWR6843 + DCA1000 frame (MIT;
``../shared/real/mmwave-eyes/README.md``) imported with its mmWave Studio configuration,
processed, and its channel phases measured (issue 39; docs/capture.md "A real 3-TX frame").

The scene is static (an independent numpy reading of the bytes: 99.6 % of the power within one
Doppler bin of zero; its strongest returns at 1.57, 1.06, 1.73, 1.85, 1.37 and 8.48 m) and the
board is not phase-calibrated (TX3 about +90° from TX1): the point cloud must stay at zero
Doppler, and ``calibrate phase`` must find TX3's offset."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from coloradar.calib import read_phase_frequency_calib
from coloradar.cli.main import main
from coloradar.errors import CalibrationWarning

EYES = Path(os.environ.get("COLORADAR_REAL_EYES",
                           Path(__file__).resolve().parents[1].parent / "shared" / "real"
                           / "mmwave-eyes"))
pytestmark = pytest.mark.skipif(not (EYES / "adc_data.bin").is_file(),
                                reason=f"the mmwave-eyes capture is not at {EYES}")

STRONGEST_M = (1.57, 1.06, 1.73, 1.85, 1.37, 8.48)
"""Ranges of the strongest returns by the independent reading (README beside the capture)."""


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("eyes")
    assert main(["import-capture", str(EYES / "adc_data.bin"), str(root / "RUN"), "--config",
                 str(EYES / "mmwaveDevice.mmwave.json")]) == 0
    return root / "RUN"


def points(folder: Path) -> np.ndarray:
    data = (folder / "single_chip" / "pointclouds" / "data" / "radar_pointcloud_0.bin")
    return np.fromfile(data, dtype="<f4").reshape(-1, 5)


def test_static_scene_stays_static_and_returns_are_where_measured(run, tmp_path):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main(["process", str(run), "--out", str(tmp_path / "P"), "--quiet"]) == 0
    p = points(tmp_path / "P")
    assert len(p) > 50
    assert np.mean(np.abs(p[:, 4]) <= 0.1) >= 0.95, np.round(p[:, 4], 3)
    # the strongest returns lie at the independently measured ranges (± 5 cm)
    rng = np.linalg.norm(p[:, :3], axis=1)
    top = rng[np.argsort(-p[:, 3])[:12]]
    for r in STRONGEST_M:
        assert np.min(np.abs(top - r)) <= 0.05, (r, np.round(np.sort(top), 2))
    # item 5: nothing said about sensors the run does not have (cascade, lidar, IMU, Vicon)
    said = " ".join(str(w.message) for w in caught if issubclass(w.category, CalibrationWarning))
    for other in ("cascade", "lidar", "imu", "vicon"):
        assert other not in said, said


def test_calibrate_phase_finds_tx3_about_90_degrees_from_tx1(run, tmp_path):
    out = tmp_path / "phase.txt"
    assert main(["calibrate", "phase", str(run), "--out", str(out), "--quiet"]) == 0
    pf = read_phase_frequency_calib(out)
    # TX slots of the capture: TX1, TX2 (raised), TX3 (antenna_cfg.txt of the imported run);
    # x = g·ideal, the file holds g: TX3's phase relative to TX1's, averaged over the RX
    rel = np.degrees(np.angle(np.sum(pf.phase[2] * np.conj(pf.phase[0]))))
    assert abs(rel - 90.0) <= 30.0, rel
    # with it the alias search runs again, and the static scene stays mostly at zero Doppler
    assert main(["process", str(run), "--out", str(tmp_path / "P"), "--phase-calib", str(out),
                 "--quiet"]) == 0
    p = points(tmp_path / "P")
    assert np.mean(np.abs(p[:, 4]) <= 0.1) >= 0.9, np.round(p[:, 4], 3)
