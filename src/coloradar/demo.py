"""``coloradar demo``: the whole chain on built-in data, no download.

1. Simulate a short run (:func:`coloradar.sim.simulate_run`, corridor scene by default): raw ADC
   of both radars, the single chip's own point clouds, lidar, IMU, ground truth, calibration.
2. Process both radars' raw ADC frames with :func:`coloradar.batch.run_processing.process_run`
   (what ``coloradar process`` runs: :class:`coloradar.dsp.RadarProcessor` with the calibration
   the simulator wrote — coupling removal, cascade phase/frequency correction, TDM
   compensation) into heatmaps and CFAR point clouds, written in the dataset's formats under
   ``OUT/processed/<run>/<radar>/``.
3. Compare the detections with the truth the simulator recorded (which scatterers each radar
   saw, where, and how fast they moved), and draw pictures.
4. Close a loop (with the extra ``[slam]``): radar SLAM (:func:`coloradar.slam.slam_from_clouds`)
   on a simulated 1.3-lap walk of the corridor at the point level (the single chip's on-board
   detections, the IMU and the ground truth, :func:`coloradar.sim.point_runs.simulate_point_run`),
   the odometry's ATE beside SLAM's.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import OutputExistsError
from .formats.atomic import atomic_write_text

__all__ = ["DemoReport", "LoopDemo", "RadarResult", "run_demo"]

MATCH_RADIUS = 0.3
"""A detection matches the truth when a scatterer the radar saw lies within this [m]."""


@dataclass
class RadarResult:
    """Processing and truth comparison of one radar's frames.

    Attributes
    ----------
    name
        ``cascade`` or ``single_chip``.
    frames
        Frames processed.
    seconds
        Processing time (heatmap + point cloud of every frame) [s].
    detections
        Detections over all frames.
    matched, matched_rate
        Detections within :data:`MATCH_RADIUS` of a truth scatterer, and of one whose range
        rate also agrees within one Doppler bin.
    median_distance, median_rate_error
        Of the matched detections [m], [m/s].
    onboard
        For the single chip: the same figures for the sensor's own point clouds.
    """

    name: str
    frames: int = 0
    seconds: float = 0.0
    detections: int = 0
    matched: int = 0
    matched_rate: int = 0
    median_distance: float = float("nan")
    median_rate_error: float = float("nan")
    onboard: dict | None = None

    @property
    def match_fraction(self) -> float:
        return self.matched / self.detections if self.detections else float("nan")

    @property
    def match_rate_fraction(self) -> float:
        return self.matched_rate / self.detections if self.detections else float("nan")


@dataclass
class LoopDemo:
    """The demo's loop closure: radar SLAM on a simulated walk that comes back.

    Attributes
    ----------
    laps, distance, duration
        Laps of the corridor, path length [m] and duration [s] of the walk.
    keyframes, loops, candidates
        Keyframes, loop candidates accepted and verified.
    odometry_ate, slam_ate
        ATE RMSE (SE(3)-aligned) of the front end's and SLAM's trajectories [m].
    scale
        :meth:`coloradar.slam.scale.ScaleEstimate.as_dict` (as ``slam.json`` records it).
    seconds
        Simulation and SLAM [s].
    picture
        ``pictures/slam.png`` (None without pictures).
    map_picture
        ``pictures/map.png``: the occupancy map of the walk's frames placed by SLAM
        (:mod:`coloradar.mapping`), its 2-D grid from above (None without pictures).
    """

    laps: float
    distance: float
    duration: float
    keyframes: int
    loops: int
    candidates: int
    odometry_ate: float
    slam_ate: float
    scale: dict
    seconds: float
    picture: Path | None = None
    map_picture: Path | None = None

    def lines(self) -> list[str]:
        sc = self.scale
        scale = (f"odometry scale {sc['measured']:.4f} ({'applied' if sc['used'] else 'not applied'})"
                 if sc["pairs"] else "no odometry scale measured")
        pct = 100.0 / max(self.distance, 1e-9)
        return [f"loop closure (radar SLAM, single chip + IMU; a {self.laps}-lap walk of the "
                "corridor, simulated at the detection level)",
                f"  {self.distance:.0f} m in {self.duration:.0f} s, {self.keyframes} keyframes, "
                f"{self.loops} of {self.candidates} loop candidates accepted; {scale}; "
                f"{self.seconds:.1f} s",
                f"  ATE: odometry {self.odometry_ate:.3f} m ({pct * self.odometry_ate:.2f} %), "
                f"SLAM {self.slam_ate:.3f} m ({pct * self.slam_ate:.2f} %)"]


@dataclass
class DemoReport:
    """What :func:`run_demo` did."""

    run_path: Path
    processed_path: Path
    counts: dict[str, int]
    simulate_seconds: float
    radars: dict[str, RadarResult] = field(default_factory=dict)
    pictures: list[Path] = field(default_factory=list)
    picture_note: str = ""
    ego: list[dict] = field(default_factory=list)
    total_seconds: float = 0.0
    engine: str = ""
    """Heatmap engine the processing used (``"numba"`` or ``"numpy"``)."""
    loop: LoopDemo | None = None
    loop_note: str = ""
    """Why the loop closure was skipped (empty when it ran or was not asked for)."""

    def text(self) -> str:
        """The printed report."""
        c = self.counts
        lines = [
            f"coloradar demo: simulated run {self.run_path.name}",
            f"  simulated in {self.simulate_seconds:.1f} s: "
            f"{c.get('cascade/adc', 0)} cascade + {c.get('single_chip/adc', 0)} single-chip "
            f"ADC frames, {c.get('lidar/pointclouds', 0)} lidar scans, {c.get('imu', 0)} IMU "
            f"samples, {c.get('groundtruth', 0)} ground-truth poses",
            f"  run:       {self.run_path}",
            f"  processed: {self.processed_path}",
            "",
            "radar processing (heatmaps + CFAR point clouds) against the simulator's truth",
            f"  heatmap engine: {self.engine}" + (
                "" if self.engine != "numpy" else
                " (pip install 'coloradar[accel]' for the compiled engine, several times faster)"),
            f"  match: a scatterer the radar saw lies within {MATCH_RADIUS} m; "
            "+rate: and its range rate within one Doppler bin",
            f"  {'radar':<22}{'frames':>7}{'time':>8}{'points/frame':>14}{'match':>8}"
            f"{'+rate':>8}{'dist':>8}{'rate err':>10}",
        ]

        def row(label, frames, seconds, det, m, mr, dist, rerr):
            pf = det / frames if frames else 0.0
            f = (m / det) if det else float("nan")
            fr = (mr / det) if det else float("nan")
            t = f"{seconds:.1f} s" if seconds == seconds else "-"
            return (f"  {label:<22}{frames:>7}{t:>8}{pf:>14.1f}{f:>8.0%}{fr:>8.0%}"
                    f"{dist:>7.2f}m{rerr:>8.3f}m/s")

        for r in self.radars.values():
            lines.append(row(f"{r.name} (dsp)", r.frames, r.seconds, r.detections, r.matched,
                             r.matched_rate, r.median_distance, r.median_rate_error))
            if r.onboard:
                o = r.onboard
                lines.append(row(f"{r.name} (on-board)", r.frames, float("nan"),
                                 int(o["detections"]), int(o["matched"]),
                                 int(o["matched_rate"]), o["median_distance"],
                                 o["median_rate_error"]))
        if self.ego:
            lines += ["", "ego-velocity (RANSAC on range rates of static points) against the "
                          "ground-truth rig velocity"]
            lines += [f"  {e['text']}" for e in self.ego]
        lines.append("")
        if self.loop is not None:
            lines += [*self.loop.lines(), ""]
        elif self.loop_note:
            lines += [self.loop_note, ""]
        if self.pictures:
            lines.append("pictures:")
            lines += [f"  {p}" for p in self.pictures]
        if self.picture_note:
            lines.append(self.picture_note)
        lines.append(f"done in {self.total_seconds:.1f} s")
        return "\n".join(lines)


def _sum_match(acc: dict, m: dict) -> None:
    for k in ("detections", "matched", "matched_rate"):
        acc[k] = acc.get(k, 0.0) + m[k]
    if m["matched"]:
        acc.setdefault("_dist", []).append((m["median_distance"], m["matched"]))
        if m["median_rate_error"] == m["median_rate_error"]:
            acc.setdefault("_rerr", []).append((m["median_rate_error"], m["matched"]))


def _weighted(pairs) -> float:
    if not pairs:
        return float("nan")
    v, w = np.array(pairs).T
    return float(np.sum(v * w) / np.sum(w))


def _finish(acc: dict) -> dict:
    return {"detections": acc.get("detections", 0.0), "matched": acc.get("matched", 0.0),
            "matched_rate": acc.get("matched_rate", 0.0),
            "median_distance": _weighted(acc.get("_dist")),
            "median_rate_error": _weighted(acc.get("_rerr"))}


def _process_radar(seq, truth, radar: str, out: Path, show_progress: bool
                   ) -> tuple[RadarResult, dict]:
    """Heatmaps and point clouds of every frame of one radar (``coloradar process``'s library
    function, writing under ``out/<radar>/``), compared with the truth. Returns the result and
    the data for the pictures."""
    from .batch.output_folder import frame_file
    from .batch.run_processing import output_paths, process_run
    from .calib import parse_heatmap_cfg
    from .formats import read_heatmap, read_radar_pointcloud
    from .sim.truth import match_detections

    calib = seq.calib.radar(radar)
    w = calib.waveform
    t0 = time.perf_counter()
    process_run(seq.location, out, calib=seq.calib, radars=radar, progress=show_progress)
    seconds = time.perf_counter() - t0
    stream = seq.radar(radar).adc
    n = len(stream)
    hm_folder = output_paths(out, radar, "heatmaps")[0]
    acc: dict = {}
    onboard: dict = {}
    for i, fid in enumerate(np.asarray(stream.frame_ids)):
        pts = read_radar_pointcloud(frame_file(out, radar, "pointclouds", fid))
        tg = truth.targets(radar, i)
        kw = dict(radius=MATCH_RADIUS, rate_tolerance=w.velocity_bin_width,
                  max_velocity=w.max_velocity)
        _sum_match(acc, match_detections(pts, tg["position"], tg["range_rate"], **kw))
        if radar == "single_chip":
            own = seq.single_chip.pointclouds[i]
            _sum_match(onboard, match_detections(own, tg["position"], tg["range_rate"], **kw))
    mid = n // 2
    fid = int(stream.frame_ids[mid])
    cfg = parse_heatmap_cfg((hm_folder / "heatmap_cfg.txt").read_text(), "heatmap_cfg.txt")
    picture = {"heatmap": read_heatmap(frame_file(out, radar, "heatmaps", fid), cfg.shape),
               "config": cfg,
               "points": read_radar_pointcloud(frame_file(out, radar, "pointclouds", fid)),
               "truth": truth.targets(radar, mid)["position"], "frame": mid}
    s = _finish(acc)
    res = RadarResult(radar, n, seconds, int(s["detections"]), int(s["matched"]),
                      int(s["matched_rate"]), s["median_distance"], s["median_rate_error"],
                      _finish(onboard) if radar == "single_chip" else None)
    return res, picture


def _pictures(seq, pictures: dict, folder: Path, overwrite: bool) -> tuple[list[Path], str]:
    """Range–azimuth image and detections-vs-truth view per radar, and a scene view."""
    try:
        from matplotlib.figure import Figure  # a Figure needs no display and no backend
    except ImportError:
        return [], ("no pictures: matplotlib is not installed "
                    "(pip install 'coloradar[viz]')")
    from .viz import plot_range_azimuth, plot_scene, save_figure
    from .viz._figure import colorbar_beside

    written: list[Path] = []

    def save(fig, name):
        save_figure(fig, folder / name, overwrite=overwrite)
        written.append(folder / name)

    for radar, pic in pictures.items():
        if not pic:
            continue
        cfg = pic["config"]
        power = pic["heatmap"][..., 0].max(axis=0)                       # (az, range)
        title = f"{radar} range–azimuth, frame {pic['frame']} (max over elevation)"
        fig = Figure(figsize=(13, 5.5), dpi=100, layout="constrained")
        ax1, ax2 = fig.subplots(1, 2, width_ratios=(2, 1))
        plot_range_azimuth(power, cfg.range_bins, cfg.azimuth_bins, mode="polar", ax=ax1,
                           title=title)
        t, p = pic["truth"], pic["points"]
        ax2.scatter(t[:, 1], t[:, 0], s=2, c="0.7", label="truth scatterers seen")
        sc = ax2.scatter(p[:, 1], p[:, 0], s=10, c=p[:, 4], cmap="coolwarm",
                         label="detections (colour: range rate)")
        # limits of what is drawn (a corridor is a narrow strip), and a colour bar as tall as
        # the equal-aspect panel
        both = np.vstack([t[:, :2], p[:, :2]]) if len(p) else t[:, :2]
        if len(both):
            ax2.set_xlim(both[:, 1].max() + 0.5, both[:, 1].min() - 0.5)
            ax2.set_ylim(0, both[:, 0].max() + 0.5)
        ax2.set_aspect("equal")
        colorbar_beside(fig, sc, ax2, "range rate [m/s] (+ receding)")
        ax2.set_xlabel("y [m] (left +)")
        ax2.set_ylabel("x [m] (boresight)")
        ax2.set_title(f"{radar} detections vs truth, radar frame", fontsize="medium")
        ax2.legend(loc="upper right", fontsize="small")
        save(fig, f"{radar}_range_azimuth.png")
    fig = plot_scene(seq, index=len(seq.cascade.adc) // 2, stream="cascade/adc")
    save(fig, "scene.png")
    return written, ""


LOOP_LAPS = 1.3
"""Laps of the corridor in the demo's loop closure: the second lap's first part revisits the
first's."""


def _loop_closure(folder: Path, seed: int, pictures: bool, overwrite: bool) -> tuple[LoopDemo | None, str]:
    """Step 4 of the module docstring; (None, why) without the extra ``[slam]``."""
    import importlib.util

    missing = [m for m in ("gtsam", "small_gicp") if importlib.util.find_spec(m) is None]
    if missing:
        return None, (f"loop closure: skipped ({' and '.join(missing)} not installed: "
                      "pip install 'coloradar[slam]')")
    import warnings

    from .odometry import ego_velocity_config
    from .odometry.metrics import absolute_trajectory_error
    from .sim.point_runs import laps_duration, simulate_point_run
    from .slam import slam_from_clouds

    t0 = time.perf_counter()
    run = simulate_point_run("corridor", laps_duration("corridor", LOOP_LAPS, rest=2.0), seed,
                             lidar_every=None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # the simulated walk's sparse frames, said elsewhere
        res = slam_from_clouds(run.clouds, run.timestamps, run.calib, run.imu_timestamps,
                               run.imu_data, radar="single_chip",
                               frontend=ego_velocity_config(run.calib.single_chip),
                               groundtruth=run.groundtruth)
    odo = absolute_trajectory_error(res.odometry, run.groundtruth)
    slam = absolute_trajectory_error(res.trajectory, run.groundtruth)
    loop = LoopDemo(LOOP_LAPS, odo.path_length, float(res.trajectory.duration),
                    int(res.keyframes.size), len(res.accepted_loops), len(res.loops), odo.rmse,
                    slam.rmse, res.scale.as_dict(), time.perf_counter() - t0)
    path = folder / "slam.png"
    if pictures and importlib.util.find_spec("matplotlib") is not None:
        if path.exists() and not overwrite:
            raise OutputExistsError(f"{path}: exists; pass --overwrite to replace it")
        from .slam.plot import plot_slam

        loop.picture = plot_slam(path, res, run.groundtruth,
                                 title=f"corridor, {LOOP_LAPS} laps (simulated)")
        loop.map_picture = _map_picture(folder / "map.png", run, res, overwrite)
    return loop, ""


def _map_picture(path: Path, run, res, overwrite: bool) -> Path:
    """``map.png``: the occupancy grid (rig height ± 0.5 m) of every frame of the walk placed
    by SLAM's trajectory (the points a static world explains, as ``coloradar map`` does)."""
    from .geometry import rig_velocity
    from .mapping import (
        OccupancySettings,
        StaticTest,
        frame_evidence,
        occupancy_from_frames,
        occupancy_grid,
        radar_sensor_model,
        static_frames,
    )
    from .mapping.output import default_band
    from .viz import save_figure
    from .viz.occupancy import occupancy_figure

    keep = res.trajectory.covers(run.timestamps)
    m = res.trajectory.interpolate(run.timestamps[keep]).matrices() @ \
        run.calib.transforms["single_chip"].matrix()
    s = OccupancySettings()
    vel = rig_velocity(res.trajectory, run.timestamps[keep], calib=run.calib,
                       sensor="single_chip").linear
    clouds = static_frames([c for c, k in zip(run.clouds, keep, strict=True) if k], vel,
                           StaticTest.for_radar(run.calib.single_chip))
    occ = occupancy_from_frames(clouds, m[:, :3, :3], m[:, :3, 3],
                                frame_evidence(radar_sensor_model(run.calib.single_chip), s), s)
    grid = occupancy_grid(occ, *default_band(res.trajectory))
    fig = occupancy_figure(grid, res.trajectory.translations, width=10.0, title=(
        f"occupancy map of the corridor walk (single chip, SLAM poses), z in "
        f"[{grid.band[0]:.2f}, {grid.band[1]:.2f}) m"))
    return save_figure(fig, path, overwrite=overwrite)


def run_demo(out: str | os.PathLike[str] = "coloradar_demo", *, scene: str = "corridor",
             duration: float = 3.0, seed: int = 0, overwrite: bool = False,
             pictures: bool = True, progress=None, loop: bool = True) -> DemoReport:
    """Simulate, process and evaluate a short run (see the module docstring).

    Parameters
    ----------
    out
        Output folder: ``calib/``, the run, ``processed/<run>/`` and ``pictures/``.
    scene, duration, seed
        Passed to :func:`coloradar.sim.simulate_run`.
    overwrite
        Replace the outputs of a previous demo in ``out``.
    pictures
        Draw pictures (needs matplotlib).
    progress
        ``progress(stage, done, total)`` callback of the simulation; when given, the
        processing shows its own progress line on stderr too.
    loop
        Also close a loop (step 4; skipped, and said, without the extra ``[slam]``).

    Returns
    -------
    DemoReport
        ``report.text()`` is what ``coloradar demo`` prints.
    """
    import shutil

    from .dataset import open_sequence
    from .sim.run import run_name, simulate_run
    from .sim.truth import load_truth

    t_start = time.perf_counter()
    out = Path(out)
    name = run_name(scene, seed)
    processed = out / "processed" / name
    if processed.exists() and not overwrite:
        raise OutputExistsError(f"{processed}: a previous demo's output is there; pass "
                                "--overwrite to replace it, or give another folder")
    sim = simulate_run(out, scene=scene, duration=duration, seed=seed, heatmaps=False,
                       overwrite=overwrite, progress=progress)
    if processed.exists():
        shutil.rmtree(processed)
    seq = open_sequence(sim.run_path)
    truth = load_truth(sim.run_path)
    report = DemoReport(sim.run_path, processed, sim.counts, sim.seconds)
    from .dsp.heatmap import resolve_engine

    report.engine = resolve_engine("auto")          # what process_run's default settings use
    pics: dict = {}
    for radar in ("cascade", "single_chip"):
        report.radars[radar], pics[radar] = _process_radar(seq, truth, radar, processed,
                                                           progress is not None)
    from .odometry import ego_velocity_report

    for radar, source in EGO_SOURCES:
        report.ego.append(ego_velocity_report(seq, radar=radar, source=source, max_frames=None))
    if pictures:
        report.pictures, report.picture_note = _pictures(seq, pics, out / "pictures", overwrite)
    if loop:
        if progress is not None:
            progress("loop closure", 0, 1)
        report.loop, report.loop_note = _loop_closure(out / "pictures", seed, pictures, overwrite)
        if report.loop is not None and report.loop.picture is not None:
            report.pictures.append(report.loop.picture)
        if report.loop is not None and report.loop.map_picture is not None:
            report.pictures.append(report.loop.map_picture)
    atomic_write_text(out / DEMO_MARKER, "output of `coloradar demo`; a later demo may replace it\n")
    report.total_seconds = time.perf_counter() - t_start
    return report


EGO_SOURCES = (("cascade", "adc"), ("single_chip", "adc"), ("single_chip", "pointclouds"))
"""(radar, point source) pairs whose ego-velocity the demo reports."""

DEMO_MARKER = ".coloradar-demo"
"""File that marks a folder as a demo's own output (which a later default demo may replace)."""


def is_demo_output(folder: str | os.PathLike[str]) -> bool:
    """True when ``folder`` holds the output of an earlier :func:`run_demo`."""
    return (Path(folder) / DEMO_MARKER).is_file()
