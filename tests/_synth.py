"""A tiny synthetic ColoRadar run written with the format writers, for the foundation tests.

The content is random but known, so reads can be compared with what was written.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path

import numpy as np

from coloradar import formats as fm
from coloradar.calib import Calibration, preset_calibration, write_calibration

# The real calibration of the release (read, never copied): beside the checkout as CI lays it out,
# or wherever COLORADAR_REFERENCE_CALIB points (worktrees, other machines).
REFERENCE_CALIB = Path(os.environ.get(
    "COLORADAR_REFERENCE_CALIB",
    Path(__file__).resolve().parents[1].parent / "shared" / "reference" / "coloradar_calib"))


def write_run(root: Path, name: str = "12_21_2020_ec_hallways_run0", *, calib: Calibration | None = None,
              n_cascade: int = 2, n_single: int = 3, n_lidar: int = 2, n_imu: int = 30, n_gt: int = 8,
              base: int = 0, vicon: bool = False, seed: int = 0, write_calib: bool = True) -> dict:
    """Write a run folder ``root/name`` (and ``root/calib``); return what was written."""
    rng = np.random.default_rng(seed)
    calib = calib or preset_calibration()
    run = root / name
    t0 = 1_608_580_000.123456
    truth: dict = {"path": run}

    def frames(folder: str, data: str, prefix: str, arrays, rate: float, writer):
        ts = t0 + np.arange(len(arrays)) / rate + rng.uniform(0, 1e-3, len(arrays))
        fm.write_timestamps(run / folder / "timestamps.txt", ts)
        for i, a in enumerate(arrays):
            writer(run / data / f"{prefix}_{i + base}.bin", a)
        truth[f"{folder.split('/')[0]}/{prefix}"] = (ts, arrays)

    for radar, n, rate in (("cascade", n_cascade, 5.0), ("single_chip", n_single, 10.0)):
        rc = calib.radar(radar)
        adc = [(rng.integers(-2000, 2000, rc.frame_shape)
                + 1j * rng.integers(-2000, 2000, rc.frame_shape)).astype(np.complex64) for _ in range(n)]
        frames(f"{radar}/adc_samples", f"{radar}/adc_samples/data", "frame", adc, rate, fm.write_adc)
        hm = [rng.random((*rc.heatmap_shape, 2), dtype=np.float32) for _ in range(n)]
        frames(f"{radar}/heatmaps", f"{radar}/heatmaps/data", "heatmap", hm, rate, fm.write_heatmap)
    pcs = [rng.standard_normal((int(rng.integers(5, 40)), 5)).astype(np.float32) for _ in range(n_single)]
    frames("single_chip/pointclouds", "single_chip/pointclouds/data", "radar_pointcloud", pcs, 10.0,
           fm.write_radar_pointcloud)
    lid = [rng.standard_normal((100, 4)).astype(np.float32) for _ in range(n_lidar)]
    frames("lidar", "lidar/pointclouds", "lidar_pointcloud", lid, 10.0, fm.write_lidar_pointcloud)

    imu_t = t0 + np.arange(n_imu) / 300.0
    imu = rng.standard_normal((n_imu, 6))
    fm.write_timestamps(run / "imu" / "timestamps.txt", imu_t)
    fm.write_imu(run / "imu" / "imu_data.txt", imu)
    truth["imu"] = (imu_t, imu)
    for kind, n in (("groundtruth", n_gt),) + ((("vicon", n_gt),) if vicon else ()):
        gt_t = t0 + np.arange(n) / 10.0
        q = rng.standard_normal((n, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        poses = np.hstack([rng.standard_normal((n, 3)), q])
        fm.write_timestamps(run / kind / "timestamps.txt", gt_t)
        fm.write_poses(run / kind / f"{kind}_poses.txt", poses)
        truth[kind] = (gt_t, poses)
    if write_calib:
        write_calibration(calib, root / "calib")
    return truth


def zip_folder(folder: Path, archive: Path, top: str | None = None) -> Path:
    """Zip ``folder``'s content, under the folder name ``top`` (None: at the archive's root)."""
    with zipfile.ZipFile(archive, "w", compression=zipfile.ZIP_STORED) as zf:
        for p in sorted(folder.rglob("*")):
            rel = p.relative_to(folder).as_posix()
            zf.write(p, f"{top}/{rel}" if top else rel)
    return archive
