"""Single-chip occupancy maps of runs another program wrote, scored against their own returns.

    nice python benchmarks/foreign_mapping.py [RUN.zip ...] [--calib DIR]
    nice python benchmarks/foreign_mapping.py --inject [CLEAN_RUN.zip] [--seeds 1 2 3]

For each run (default: ``../shared/foreign/*.zip``, calibration ``../shared/reference/
coloradar_calib``), the single chip's clouds are placed with the ground truth and mapped as
``coloradar map RUN`` maps them (the static test with the ground truth's velocity, the
default settings), and with the sensor model's angle spread replaced:

- ``default``: :func:`coloradar.mapping.radar_sensor_model` (the array's resolution at each
  return's SNR, never below the floors 1° / 2°);
- ``capped 1/2``: the same, at most the floors (no SNR rule above them);
- ``fixed A/E``: every return spread by A° in azimuth and E° in elevation.

The clean run's directions are exact and it has no ghosts, so every return lies on a scatterer
and the map can be scored against the returns themselves: **precision** (occupied voxels within
0.3 m of a return), **completeness** (returns within 0.3 m of an occupied voxel), completeness
by range, and what the returns allow, the share of returns within 0.15 / 0.3 m of a return from
another frame (a map that leaves a one-frame ghost unmapped cannot map the others). The
returns the map leaves out are counted by their voxel's state (free: carved by rays;
unknown: too little evidence). On a run with direction noise the returns are not on the
scatterers: its figures are printed for the record, not as scores.

``--inject`` (default: the clean run) asks what direction noise costs a map whatever its
thresholds: the clean run's returns are turned by Gaussian errors (0 / 2° in azimuth, 0 / 4° in
elevation, as ``benchmarks/mc_mapping.py`` degrades the simulator's clouds; ``--seeds`` draws),
mapped with the ground truth (default settings and sensor model, the static test), and each
map's voxels thresholded again at every ``min_hits`` in 1–3 and ``p_occupied`` in 0.50–0.70.
Scored against the clean returns (above): the best completeness among the settings with
precision ≥ 0.92, and the default setting's precision / completeness (means over the draws).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

import coloradar as cr
from coloradar.geometry import rig_velocity, trajectory_from_groundtruth
from coloradar.mapping import (
    OccupancySettings,
    PointSensorModel,
    StaticTest,
    occupancy_from_frames,
    radar_sensor_model,
    static_frames,
)
from coloradar.mapping.build import frame_evidence
from coloradar.mapping.voxels import FREE, UNKNOWN

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mc_mapping import frontier_best, threshold_sweep, turn_directions

SHARED = Path(__file__).resolve().parents[2] / "shared"
DEG = np.pi / 180
RANGES = ((0, 4), (4, 8), (8, 12), (12, 20))


class _Capped(PointSensorModel):
    """A model whose angle spread is at most its floors (no SNR rule above them)."""

    def angle_std(self, cloud: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        az, el = super().angle_std(cloud)
        return np.minimum(az, self.min_azimuth_std), np.minimum(el, self.min_elevation_std)


def models(base: PointSensorModel) -> dict[str, PointSensorModel]:
    """The variants of the module docstring."""
    fields = {f: getattr(base, f) for f in base.__dataclass_fields__}
    out: dict[str, PointSensorModel] = {"default": base, "capped 1/2": _Capped(**fields)}
    for a, e in ((0.5, 0.5), (1.0, 1.0), (2.0, 4.0)):
        out[f"fixed {a:g}/{e:g}"] = replace(base, azimuth_resolution=0.0,
                                            elevation_resolution=0.0,
                                            min_azimuth_std=a * DEG, min_elevation_std=e * DEG)
    return out


def placed_returns(seq, gt) -> tuple[list[np.ndarray], np.ndarray, np.ndarray, np.ndarray]:
    """The clouds inside the ground truth's span, ``world_T_radar`` per frame ``(F, 4, 4)``,
    their frame times, and every return in the world with its frame index and range."""
    stream = seq.single_chip.pointclouds
    t = np.asarray(stream.timestamps, np.float64)
    idx = np.flatnonzero((t > gt.timestamps[0]) & (t < gt.timestamps[-1]))
    clouds = [np.asarray(stream[int(k)], np.float32) for k in idx]
    m = gt.interpolate(t[idx], tolerance=1.0).matrices() @ \
        seq.calib.transforms["single_chip"].matrix()
    pts = [c[:, :3].astype(np.float64) @ m[j, :3, :3].T + m[j, :3, 3]
           for j, c in enumerate(clouds)]
    frame = np.concatenate([np.full(len(p), j) for j, p in enumerate(pts)])
    rng = np.concatenate([np.linalg.norm(c[:, :3], axis=1) for c in clouds])
    return clouds, m, t[idx], np.column_stack([np.vstack(pts), frame, rng])


def shared_share(ret: np.ndarray, radius: float) -> np.ndarray:
    """bool ``(N,)``: returns within ``radius`` of a return from another frame."""
    near = cKDTree(ret[:, :3]).query_ball_point(ret[:, :3], radius)
    frame = ret[:, 3]
    return np.array([bool(np.any(frame[n] != frame[i])) for i, n in enumerate(near)])


def open_run(path: Path, calib: Path):
    """``(clouds, world_T_radar, returns, radar calibration, velocities)`` of a run placed with
    its ground truth (:func:`placed_returns`; the single chip's velocity in its own frame)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        seq = cr.open_sequence(path, calib=calib)
        gt = trajectory_from_groundtruth(seq)
        clouds, m, t, ret = placed_returns(seq, gt)
        vel = rig_velocity(gt, t, calib=seq.calib, sensor="single_chip").linear
    return clouds, m, ret, seq.calib.radar("single_chip"), vel


def run_one(path: Path, calib: Path) -> None:
    clouds, m, ret, rc, vel = open_run(path, calib)
    mapped = static_frames(clouds, vel, StaticTest.for_radar(rc))
    settings = OccupancySettings()
    multi = {r: shared_share(ret, r) for r in (0.15, 0.3)}
    print(f"\n{path.name}: {len(ret)} returns in {len(clouds)} frames; within 0.15 / 0.3 m "
          f"of a return from another frame: {multi[0.15].mean():.3f} / {multi[0.3].mean():.3f}")
    print("  model          occupied  precision  completeness  by range "
          + " ".join(f"{a}-{b} m" for a, b in RANGES) + "   left out (multi-frame): free / unknown")
    for name, model in models(radar_sensor_model(rc)).items():
        occ_map = occupancy_from_frames(mapped, m[:, :3, :3], m[:, :3, 3],
                                        frame_evidence(model, settings), settings)
        occ = occ_map.occupied()[:, :3].astype(np.float64)
        if len(occ) == 0:
            print(f"  {name:14s} no occupied voxel")
            continue
        d_ret = cKDTree(occ).query(ret[:, :3])[0]
        d_occ = cKDTree(ret[:, :3]).query(occ)[0]
        by_range = [float(np.mean(d_ret[(ret[:, 4] >= a) & (ret[:, 4] < b)] <= 0.3))
                    for a, b in RANGES]
        miss = multi[0.15] & (d_ret > 0.3)
        st = occ_map.state(ret[miss, :3])
        print(f"  {name:14s} {len(occ):8d}  {np.mean(d_occ <= 0.3):9.3f}  "
              f"{np.mean(d_ret <= 0.3):12.3f}  " + "  ".join(f"{v:5.2f}" for v in by_range)
              + f"      {np.mean(st == FREE):.2f} / {np.mean(st == UNKNOWN):.2f}", flush=True)


def turned(clouds: list[np.ndarray], az_deg: float, el_deg: float, seed: int) -> list[np.ndarray]:
    """Each return's direction turned by Gaussian errors [deg], its range and columns kept."""
    rng = np.random.default_rng([seed, 4040])
    return [np.column_stack([turn_directions(c, az_deg, el_deg, rng), c[:, 3:]]).astype(np.float32)
            for c in clouds]


def inject(path: Path, calib: Path, seeds: list[int]) -> None:
    """The module docstring's ``--inject``."""
    clouds, m, ret, rc, vel = open_run(path, calib)
    settings = OccupancySettings()
    model = radar_sensor_model(rc)
    tree = cKDTree(ret[:, :3])
    print(f"\n{path.name}, directions turned: best completeness with precision >= 0.92 | "
          f"default P / C (0.3 m, against the clean returns; mean of {len(seeds)} draws)")
    for az, el in ((0.0, 0.0), (2.0, 0.0), (0.0, 4.0), (2.0, 4.0)):
        best, default = [], []
        for seed in seeds if (az or el) else seeds[:1]:
            mapped = static_frames(turned(clouds, az, el, seed), vel, StaticTest.for_radar(rc))
            occ = occupancy_from_frames(mapped, m[:, :3, :3], m[:, :3, 3],
                                        frame_evidence(model, settings), settings)
            scores = threshold_sweep(
                occ, lambda c: tree.query(c)[0] <= 0.3,
                lambda c: float(np.mean(cKDTree(c).query(ret[:, :3])[0] <= 0.3)))
            best.append(np.nan_to_num(frontier_best(scores)[0]))
            default.append(scores[(settings.min_hits, settings.p_occupied)])
        d = np.array(default)
        print(f"  azimuth {az:g}°, elevation {el:g}°: {np.mean(best):.3f} | "
              f"{np.nanmean(d[:, 0]):.3f} / {np.mean(d[:, 1]):.3f}", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("runs", nargs="*", type=Path)
    ap.add_argument("--calib", type=Path, default=SHARED / "reference" / "coloradar_calib")
    ap.add_argument("--inject", action="store_true", help="direction noise on the clean run")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    args = ap.parse_args()
    if args.inject:
        for p in args.runs or sorted((SHARED / "foreign").glob("*clean*.zip")):
            inject(p, args.calib, args.seeds)
        return
    runs = args.runs or sorted((SHARED / "foreign").glob("*.zip"))
    if not runs:
        raise SystemExit(f"no runs given and none in {SHARED / 'foreign'}")
    for p in runs:
        run_one(p, args.calib)


if __name__ == "__main__":
    main()
