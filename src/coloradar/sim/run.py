"""Write a complete simulated ColoRadar run: ``OUT/calib`` and ``OUT/<run name>``.

The run has the dataset's layout (``docs/layout.md``; ColoRadar by default, ColoRadar+ on
request), frames numbered from 0 (ColoRadar+: 1), every file written
atomically, the run folder itself assembled as ``OUT/.<name>.partial`` and renamed into place
at the end (an interrupted simulation leaves no half run behind). Streams and rates:

================  =======  ===========================================================
stream            rate     content
================  =======  ===========================================================
cascade ADC       5 Hz     12 TX × 16 RX × 16 loops × 256 samples, int16 I/Q
single-chip ADC   10 Hz    3 TX × 4 RX × 128 loops × 128 samples
heatmaps          same     through ``coloradar.dsp`` when it is importable
single-chip pts   10 Hz    the sensor's on-board detections (:func:`.radar.onboard_pointcloud`)
lidar             10 Hz    OS1-64 scans, 65,536 points (no-return rows zero)
imu               300 Hz   specific force and angular rate, IMU frame, bias + noise
groundtruth       10 Hz    ``base`` poses relative to the first one
vicon (option)    100 Hz   ``vicon`` body poses in the scene frame, 0.5 mm / 0.05° noise
================  =======  ===========================================================

Every stream has its own start offset and timestamp jitter (none is aligned with another);
all lie within the ground truth's time span. Everything random is drawn from generators keyed
by ``(seed, stream, frame)``, so a run is reproducible for a given seed whatever the sensors
selected or the number of worker threads. The radar boards' own errors (cascade channel
errors, coupling of both radars) come from ``board_seed``: runs with different seeds share
one ``calib`` folder, as the real dataset's runs do.
"""

from __future__ import annotations

import datetime
import functools
import json
import os
import shutil
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from .. import __version__
from ..calib import (
    PRESET_TRANSFORMS,
    RADARS,
    Calibration,
    CouplingCalib,
    PhaseFrequencyCalib,
    RadarCalib,
    format_antenna_cfg,
    format_coupling_calib,
    format_heatmap_cfg,
    format_phase_frequency_calib,
    format_transform,
    format_waveform_cfg,
    identity_phase_calib,
    preset_radar,
    read_phase_frequency_calib,
    with_coupling,
    write_calibration,
)
from ..errors import ColoradarError, FormatError, MissingDataError, OutputExistsError
from ..formats import (
    atomic_write_text,
    decode_adc,
    encode_adc,
    write_heatmap,
    write_imu,
    write_lidar_pointcloud,
    write_poses,
    write_radar_pointcloud,
    write_timestamps,
)
from ..formats.atomic import atomic_write_bytes
from ..formats.layout import COLORADAR, RunLayout, get_layout
from ..formats.source import read_file_text
from .imu import GX5_25, ImuModel, simulate_imu
from .lidar import LidarModel, simulate_scan
from .radar import (
    RADAR_MODELS,
    PhaseErrors,
    make_channel_errors,
    make_coupling,
    onboard_pointcloud,
    planted_coupling,
    radar_frame,
    visible_targets,
)
from .rest import RestStart
from .scene import Scatterers, Scene, load_scene
from .scenes import SCENES, builtin_scene
from .trajectory import MOTION_PROFILES, RigTrajectory, make_trajectory
from .truth import TRUTH_FILE, save_truth

__all__ = [
    "DEFAULT_START_TIME",
    "RATES",
    "SENSOR_CHOICES",
    "SimResult",
    "Simulation",
    "SimulationSpec",
    "heatmap_processor",
    "open_simulation",
    "resolve_scene",
    "run_name",
    "simulate_run",
    "simulated_calibration",
]

DEFAULT_START_TIME = 1_795_262_400.0
"""Unix time of a run's start unless given: 2026-11-21 12:00:00 UTC (fixed, for determinism)."""

SENSOR_CHOICES = ("cascade", "single_chip", "lidar", "imu", "groundtruth")
"""Sensors a run can have (plus ``vicon`` with ``vicon=True``)."""

RATES = {"cascade": 5.0, "single_chip": 10.0, "lidar": 10.0, "imu": 300.0,
         "groundtruth": 10.0, "vicon": 100.0}
"""Nominal rates [Hz]."""

_STREAM_KEY = {"cascade": 1, "single_chip": 2, "lidar": 3, "imu": 4, "groundtruth": 5,
               "vicon": 6, "timing": 7, "trajectory": 8}

Progress = Callable[[str, int, int], None]
"""``progress(stage, done, total)``; called from worker threads, possibly concurrently."""


@dataclass(frozen=True)
class SimResult:
    """What :func:`simulate_run` wrote.

    Attributes
    ----------
    run_path, calib_path
        The run folder and the calib folder.
    counts
        Frames or samples per stream (``"cascade/adc"``, ``"lidar/pointclouds"``, ``"imu"``…).
    seconds
        Wall time of the simulation.
    heatmaps
        Whether heatmaps were written.
    scene
        Scene name.
    """

    run_path: Path
    calib_path: Path
    counts: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0
    heatmaps: bool = False
    scene: str = ""


def resolve_scene(scene: str | os.PathLike[str] | Scene) -> Scene:
    """A :class:`Scene` from a built-in name, a ``.json`` scene file, or a Scene."""
    if isinstance(scene, Scene):
        return scene
    s = str(scene)
    if s in SCENES:
        return builtin_scene(s)
    if s.endswith(".json") or Path(s).is_file():
        return load_scene(s)
    raise ColoradarError(f"unknown scene {s!r}; built-in scenes: {', '.join(SCENES)} "
                         "(or give a .json scene file)")


def run_name(scene: str, seed: int, start_time: float = DEFAULT_START_TIME) -> str:
    """The dataset-style run name, e.g. ``11_21_2026_sim_corridor_run0``."""
    d = datetime.datetime.fromtimestamp(start_time, tz=datetime.timezone.utc)
    safe = "".join(c if c.isalnum() else "_" for c in scene).strip("_") or "scene"
    return f"{d:%m_%d_%Y}_sim_{safe}_run{seed}"


def heatmap_processor(radar_calib: RadarCalib):
    """A ``coloradar.dsp.RadarProcessor`` for the radar, or None when dsp is not available."""
    try:
        from ..dsp import RadarProcessor
    except ImportError:
        return None
    proc = RadarProcessor(radar_calib)
    return proc if hasattr(proc, "heatmap") else None


def simulated_calibration(board_seed: int = 2021, true_angles: bool = True
                          ) -> tuple[Calibration, dict[str, np.ndarray]]:
    """The calibration of the simulated rig, and each radar's coupling term.

    Both radars get the preset waveform and antenna layout, the real rig's extrinsics, and a
    coupling calibration; the cascade also a phase/frequency calibration
    (:func:`.radar.make_channel_errors`), the single chip a unit one (its simulated channels
    are matched, and the calibration says so: the chain trusts only a calibrated array's
    phases to tell Doppler aliases apart). With ``true_angles`` and ``coloradar.dsp``
    available, the heatmap grids are the processor's true-angle grids (else the presets'
    shipped labelling).

    Returns
    -------
    calib : Calibration
    coupling_adc : dict
        Radar name -> complex64 ``(tx, rx, sample)`` leakage added to every chirp.
    """
    rng = np.random.default_rng([board_seed, 0])
    radars, coupling_adc = {}, {}
    for name in RADARS:
        base = preset_radar(name)
        adc, coupling = make_coupling(base, RADAR_MODELS[name], rng)
        w = base.waveform
        pf = (make_channel_errors(base, rng) if name == "cascade"
              else identity_phase_calib(w.num_tx, w.num_rx, w.slope, w.sample_rate))
        rc = replace(base, coupling=coupling, phase_frequency=pf, source="simulated")
        if true_angles:
            proc = heatmap_processor(rc)
            if proc is not None and hasattr(proc, "heatmap_config"):
                rc = replace(rc, heatmap=proc.heatmap_config())
        radars[name], coupling_adc[name] = rc, adc
    calib = Calibration(radars["cascade"], radars["single_chip"], dict(PRESET_TRANSFORMS),
                        "simulated")
    return calib, coupling_adc


def _with_coupling_calib(calib: Calibration, coupling_adc: dict[str, np.ndarray],
                         given: str | os.PathLike[str] | CouplingCalib | None
                         ) -> tuple[Calibration, dict[str, np.ndarray]]:
    """``SimulationSpec.coupling_calib``: the radar of the file's ``(tx, rx)`` gets it in its
    calibration, and its frames the file's coupling (:func:`.radar.planted_coupling`)."""
    if given is None:
        return calib, coupling_adc
    new = with_coupling(calib, given)
    adc = dict(coupling_adc)
    for name in RADARS:
        c = new.radar(name).coupling
        if c is not calib.radar(name).coupling and c is not None:
            adc[name] = planted_coupling(new.radar(name), c, coupling_adc[name])
    return new, adc


def _with_phase_errors(calib: Calibration, planted: PhaseErrors | None, board_seed: int
                      ) -> tuple[Calibration, dict[str, PhaseFrequencyCalib | None]]:
    """``SimulationSpec.phase_errors``: the calibration to write and each radar's hardware
    errors (what its frames carry: the cascade's calibrated channel errors; the single chip's
    none), with the planted errors on top; the calib holds what ``planted.calibration``
    says."""
    hardware: dict[str, PhaseFrequencyCalib | None] = {
        "cascade": calib.cascade.phase_frequency, "single_chip": None}
    if planted is None:
        return calib, hardware
    if planted.radar not in RADARS:
        raise ColoradarError(f"phase_errors.radar must be one of {', '.join(RADARS)}, got "
                             f"{planted.radar!r}")
    rc = calib.radar(planted.radar)
    w = rc.waveform
    try:
        g = planted.gains(w.num_tx, w.num_rx, np.random.default_rng([board_seed, 7]))
    except ValueError as exc:
        raise ColoradarError(f"phase_errors ({planted.radar}): {exc}") from None
    base = rc.phase_frequency or identity_phase_calib(w.num_tx, w.num_rx, w.slope,
                                                      w.sample_rate)
    if planted.board is not None:
        f = read_phase_frequency_calib(planted.board)
        if f.phase.shape != base.phase.shape:
            raise ColoradarError(f"phase_errors.board {planted.board}: {f.num_tx} x {f.num_rx} "
                                 f"channels, the {planted.radar} has {w.num_tx} x {w.num_rx}")
        # its delays in the frame's own bins (the errors are imposed with the frame's slope)
        scale = (w.slope / f.slope) * (f.sample_rate / w.sample_rate)
        base = PhaseFrequencyCalib(f.frequency * scale, f.phase, w.slope, w.sample_rate,
                                   near_field=False)
    hw = PhaseFrequencyCalib(base.frequency, base.phase * g, base.slope, base.sample_rate,
                             near_field=base.near_field)
    hardware[planted.radar] = hw
    if planted.calibration not in ("none", "board", "all"):
        raise ColoradarError(f"phase_errors.calibration must be none, board or all, got "
                             f"{planted.calibration!r}")
    held = {"none": None, "board": base, "all": hw}[planted.calibration]
    new = replace(rc, phase_frequency=held)
    radars = {r: (new if r == planted.radar else calib.radar(r)) for r in RADARS}
    return replace(calib, cascade=radars["cascade"], single_chip=radars["single_chip"]), hardware


def _calib_texts(calib: Calibration, layout: RunLayout = COLORADAR) -> dict[str, str]:
    """Every file of the calib folder of ``layout`` (as :func:`write_calibration` writes it)."""
    out = {}
    for name in layout.calib_radars:
        rc = calib.radar(name)
        out[f"{name}/waveform_cfg.txt"] = format_waveform_cfg(rc.waveform)
        out[f"{name}/antenna_cfg.txt"] = format_antenna_cfg(rc.antenna, f"{name} layout")
        out[f"{name}/heatmap_cfg.txt"] = format_heatmap_cfg(rc.heatmap)
        if rc.coupling is not None:
            out[f"{name}/coupling_calib.txt"] = format_coupling_calib(rc.coupling)
        if rc.phase_frequency is not None:
            out[f"{name}/phase_frequency_calib.txt"] = format_phase_frequency_calib(
                rc.phase_frequency)
    for sensor, ext in calib.transforms.items():
        if layout is COLORADAR or sensor in layout.transforms:
            fname = layout.transforms.get(sensor, f"base_to_{sensor}.txt")
            out[f"transforms/{fname}"] = format_transform(ext)
    return out


SIM_CALIB_MARKER = "SIMULATED_CALIBRATION.txt"
"""File that marks a calib folder as written by the simulator (the only kind it may replace)."""


def _write_calib(calib: Calibration, folder: Path, overwrite: bool,
                 layout: RunLayout = COLORADAR) -> None:
    """Write the calib folder, or check that the one there is the same.

    A calib folder that the simulator did not write (a real dataset's, say) is never replaced,
    whatever ``overwrite`` says.
    """
    texts = _calib_texts(calib, layout)
    if folder.exists():
        differ = [rel for rel, text in texts.items()
                  if not (folder / rel).is_file()
                  or (folder / rel).read_text(encoding="utf-8") != text]
        if not differ:
            return
        if not (folder / SIM_CALIB_MARKER).is_file():
            raise OutputExistsError(
                f"{folder}: a calib folder that the simulator did not write is there and differs "
                f"from this simulation's ({', '.join(differ[:3])}{'…' if len(differ) > 3 else ''});"
                " not replacing it: write the simulation to another folder")
        if not overwrite:
            raise OutputExistsError(
                f"{folder}: a calib folder is there that differs from this simulation's "
                f"({', '.join(differ[:3])}{'…' if len(differ) > 3 else ''}); pass "
                "overwrite=True (--overwrite) to replace it, or write to another folder")
    write_calibration(calib, folder, layout=layout)
    atomic_write_text(folder / SIM_CALIB_MARKER,
                      "written by coloradar simulate: simulated sensors, not a real rig's calibration\n")


def _stream_times(rate: float, duration: float, busy: float, jitter: float,
                  rng: np.random.Generator) -> np.ndarray:
    """Run-relative timestamps: own random phase, jitter, all within ``[0, duration]``."""
    period = 1.0 / rate
    offset = rng.uniform(0.25, 1.0) * period
    n = int(np.floor((duration - busy - offset) / period + 1e-9)) + 1
    if n <= 0:
        return np.zeros(0)
    j = np.clip(rng.normal(0.0, jitter, n), -3 * jitter, 3 * jitter) if jitter > 0 else 0.0
    # Jitter (≪ period) must not push the last frame past the run's end.
    return np.minimum(offset + np.arange(n) * period + j, duration - busy)


def _sensor_pose(state, i: int, base_T_s: np.ndarray):
    """World pose, world velocity of the origin, own-frame angular velocity of a sensor."""
    r_wb = state.rotation[i]
    r_bs = Rotation.from_matrix(base_T_s[:3, :3])
    t_bs = base_T_s[:3, 3]
    w_b = state.angular_velocity[i]
    origin = state.position[i] + r_wb.apply(t_bs)
    vel = state.velocity[i] + r_wb.apply(np.cross(w_b, t_bs))
    return r_wb * r_bs, origin, vel, r_bs.inv().apply(w_b)


def _concat(a: Scatterers, b: Scatterers) -> Scatterers:
    if len(b) == 0:
        return a
    return Scatterers(*(np.concatenate([getattr(a, f), getattr(b, f)])
                        for f in ("position", "velocity", "normal", "one_sided", "strength",
                                  "phase", "ident")))


class _Context:
    """Shared, read-only state of one simulation (threads only read it)."""

    def __init__(self, scene: Scene, traj: RigTrajectory, calib: Calibration,
                 coupling_adc: dict[str, np.ndarray], spec: SimulationSpec,
                 root: Path, progress: Progress | None, heatmaps: bool,
                 layout: RunLayout = COLORADAR, imu_model: ImuModel = GX5_25):
        self.scene, self.traj, self.calib = scene, traj, calib
        self.imu_model, self.radar_time_offset = imu_model, float(spec.radar_time_offset)
        self.coupling_adc, self.seed, self.start_time = coupling_adc, spec.seed, spec.start_time
        self.root, self.heatmaps, self.layout = root, heatmaps, layout
        self.hardware: dict[str, PhaseFrequencyCalib | None] = {}
        """Each radar's channel errors (what its frames carry; :func:`_with_phase_errors`)."""
        self._progress = progress
        self._lock = threading.Lock()

    def rng(self, stream: str, index: int = 0) -> np.random.Generator:
        return np.random.default_rng([self.seed, _STREAM_KEY[stream], index])

    def report(self, stage: str, done: int, total: int) -> None:
        if self._progress is not None:
            with self._lock:
                self._progress(stage, done, total)


def _radar_task(ctx: _Context, radar: str, times: np.ndarray) -> dict[str, np.ndarray]:
    calib = ctx.calib.radar(radar)
    model = RADAR_MODELS[radar]
    base_T_s = ctx.calib.transforms[radar].matrix()
    state = ctx.traj.state(times)
    proc = heatmap_processor(calib) if ctx.heatmaps else None
    lay = ctx.layout
    streams = lay.radar_streams(radar)
    first = lay.first_frame
    # The sensor's own point clouds: only the single chip makes them on board.
    onboard = radar == "single_chip" and "pointclouds" in streams
    static = ctx.scene.static_scatterers
    n = len(times)
    world_T = np.zeros((n, 4, 4))
    vel = np.zeros((n, 3))
    ang = np.zeros((n, 3))
    offsets = [0]
    acc: dict[str, list[np.ndarray]] = {k: [] for k in ("ident", "position", "velocity",
                                                          "range_rate", "amplitude")}
    for i, t in enumerate(times):
        r_ws, origin, v_world, w_s = _sensor_pose(state, i, base_T_s)
        scat = _concat(static, ctx.scene.object_scatterers(t))
        rects = ctx.scene.rect_arrays(np.array([t]))
        targets = visible_targets(calib, model, scat, r_ws, origin, v_world, w_s, rects)
        g = ctx.rng(radar, i)
        frame = radar_frame(calib, model, targets,
                            channel_errors=ctx.hardware.get(radar),
                            coupling_adc=ctx.coupling_adc[radar], rng=g)
        raw = encode_adc(frame)
        atomic_write_bytes(ctx.root / streams["adc"].frame_path(first + i), raw)
        if proc is not None:
            hm = proc.heatmap(decode_adc(raw, calib.frame_shape))
            write_heatmap(ctx.root / streams["heatmaps"].frame_path(first + i), hm)
        if onboard:
            pts = onboard_pointcloud(calib, model, targets, g)
            write_radar_pointcloud(ctx.root / streams["pointclouds"].frame_path(first + i), pts)
        m = np.eye(4)
        m[:3, :3] = r_ws.as_matrix()
        m[:3, 3] = origin
        world_T[i] = m
        vel[i] = r_ws.inv().apply(v_world)
        ang[i] = w_s
        acc["ident"].append(targets.ident)
        acc["position"].append(targets.position.astype(np.float32))
        acc["velocity"].append(targets.velocity.astype(np.float32))
        acc["range_rate"].append(targets.range_rate.astype(np.float32))
        acc["amplitude"].append(targets.received_amplitude.astype(np.float32))
        offsets.append(offsets[-1] + len(targets))
        ctx.report(radar, i + 1, n)
    # A radar clock that lags: the frame simulated at true time t is stamped t − t_d.
    stamps = ctx.start_time + times - ctx.radar_time_offset
    write_timestamps(ctx.root / streams["adc"].timestamps_path, stamps)
    if proc is not None:
        write_timestamps(ctx.root / streams["heatmaps"].timestamps_path, stamps)
        # The grid's true angles beside the heatmaps too (as `coloradar process` writes them).
        atomic_write_text(ctx.root / streams["heatmaps"].folder / "heatmap_cfg.txt",
                          format_heatmap_cfg(calib.heatmap))
    if onboard:
        write_timestamps(ctx.root / streams["pointclouds"].timestamps_path, stamps)
    out: dict[str, np.ndarray] = {f"{radar}/timestamps": stamps, f"{radar}/world_T_radar": world_T,
           f"{radar}/velocity": vel, f"{radar}/angular_velocity": ang,
           f"{radar}/offsets": np.asarray(offsets, dtype=np.int64),
           f"{radar}/coupling": np.fft.fft(ctx.coupling_adc[radar], axis=-1).astype(np.complex64)}
    hw = ctx.hardware.get(radar)
    if hw is not None:                   # x = g·ideal per channel (P[t,r]/P[0,0]), delays
        out[f"{radar}/channel_gain"] = (1.0 / hw.relative_phase()).astype(np.complex128)
        out[f"{radar}/channel_delay"] = hw.relative_frequency()
    for k, parts in acc.items():
        empty = np.zeros((0, 3) if k in ("position", "velocity") else 0,
                         dtype=np.int64 if k == "ident" else np.float32)
        out[f"{radar}/target_{k}"] = np.concatenate(parts) if parts else empty
    return out


def _lidar_task(ctx: _Context, times: np.ndarray) -> dict[str, np.ndarray]:
    model = LidarModel()
    base_T_l = ctx.calib.transforms["lidar"].matrix()
    st = ctx.layout.frame("lidar/pointclouds")
    for i, t in enumerate(times):
        pts = simulate_scan(ctx.scene, ctx.traj, base_T_l, t, model, ctx.rng("lidar", i))
        write_lidar_pointcloud(ctx.root / st.frame_path(ctx.layout.first_frame + i), pts)
        ctx.report("lidar", i + 1, len(times))
    write_timestamps(ctx.root / st.timestamps_path, ctx.start_time + times)
    return {"lidar/timestamps": ctx.start_time + times}


def _trajectory(scene: Scene, motion: str, seed: int, speed: float | None,
                rest: float) -> RigTrajectory:
    traj = make_trajectory(scene.rig_path, motion, [seed, _STREAM_KEY["trajectory"]], speed=speed)
    # RestStart has the RigTrajectory interface (state(t) -> RigState).
    return RestStart(traj, float(rest)) if rest else traj  # type: ignore[return-value]


def _check_target(final: Path, overwrite: bool) -> None:
    if not final.exists():
        return
    if not overwrite:
        raise OutputExistsError(f"{final}: the run exists; pass overwrite=True (--overwrite) "
                                "to replace it, or choose another seed, name or folder")
    if not (final / "truth" / "sim_config.json").is_file():
        raise OutputExistsError(f"{final}: exists and is not a simulated run; not replacing it")


@dataclass(frozen=True)
class SimulationSpec:
    """What run :func:`simulate_run` simulates: scene, motion, sensors, timing, naming, layout
    and sensor models (each field is documented there, and is also one of its keywords)."""

    scene: str | os.PathLike[str] | Scene = "corridor"
    duration: float = 10.0
    seed: int = 0
    motion: str = "smooth"
    speed: float | None = None
    sensors: Sequence[str] | None = None
    vicon: bool = False
    heatmaps: bool | None = None
    start_time: float = DEFAULT_START_TIME
    name: str | None = None
    board_seed: int = 2021
    layout: str | RunLayout = "coloradar"
    imu: ImuModel | None = None
    rest: float = 0.0
    radar_time_offset: float = 0.0
    coupling_calib: str | os.PathLike[str] | CouplingCalib | None = None
    phase_errors: PhaseErrors | None = None


def simulate_run(out: str | os.PathLike[str], spec: SimulationSpec | None = None, *,
                 overwrite: bool = False, workers: int = 2, progress: Progress | None = None,
                 **fields: Any) -> SimResult:
    """Simulate one run and write it, with its calibration, under ``out``.

    Parameters
    ----------
    out
        Output root: gets ``calib/`` and ``<name>/`` (``kitti/<name>/`` for ColoRadar+),
        created if needed.
    spec
        A :class:`SimulationSpec`: what run to simulate (its fields are listed below); keyword
        arguments named like its fields replace them, so ``simulate_run(out, seed=3)`` works.
    overwrite
        Replace an existing simulated run of that name (and a differing ``calib/``).
    workers
        Threads (the lidar is simulated beside the radars).
    progress
        ``progress(stage, done, total)`` callback.

    Other Parameters
    ----------------
    scene
        A built-in scene name (``corridor``, ``courtyard``, ``mine``), a ``.json`` scene file or
        a :class:`~coloradar.sim.scene.Scene`.
    duration
        Length of the run [s].
    seed
        Seed of everything that varies between runs (motion perturbations, noise, timing).
    motion
        Motion profile: ``smooth``, ``handheld`` or ``aggressive``.
    speed
        Nominal rig speed [m/s] replacing the scene's (None: the scene's, scaled by the
        profile). Above ~1.76 m/s the cascade's Doppler folds (v_max), above ~2.45 m/s the
        single chip's.
    sensors
        Subset of :data:`SENSOR_CHOICES` to write; None: every sensor of the layout.
    vicon
        Also write ``vicon/`` (100 Hz).
    heatmaps
        Write heatmaps through ``coloradar.dsp``; None: when dsp is importable.
    start_time
        Unix time of the run start [s].
    name
        Run folder name; default :func:`run_name`.
    board_seed
        Seed of the radar boards' channel errors and coupling (shared by all runs in ``out``).
    layout
        ``"coloradar"`` or ``"coloradar_plus"`` (:mod:`coloradar.formats.layout`): folders,
        frame numbering and calib files as that release has them. ColoRadar+ has no
        single-chip radar and no Vicon; the simulator writes no camera images.
    imu
        The IMU's error model (default :data:`~coloradar.sim.imu.GX5_25`, the rig's
        3DM-GX5-25 from its datasheet; ``GX5_25.scaled(0)`` for an ideal IMU).
    rest
        Seconds the rig stands still at the start before it eases into its motion
        (:class:`~coloradar.sim.rest.RestStart`); 0: it moves from the start.
    radar_time_offset
        ``t_d`` [s]: both radars' timestamps lag the true frame times, ``stamp = t − t_d``
        (an estimator must read a radar frame stamped ``t`` as the motion at ``t + t_d`` of
        the IMU and ground-truth clock). Recorded in the truth as ``radar_time_offset``.
    coupling_calib
        A ``coupling_calib.txt`` (path, or a :class:`~coloradar.calib.CouplingCalib`) that
        the radar of its size carries instead of the simulator's own (the released single
        chip's, say); its frames carry it, and the simulator's own on an all-zero TX block.
    phase_errors
        :class:`~coloradar.sim.radar.PhaseErrors` planted on one radar (truth: channel_gain).

    Returns
    -------
    SimResult
    """
    t0 = time.perf_counter()
    spec = replace(spec or SimulationSpec(), **fields)
    lay, sensors = _check_spec(spec)
    imu_model = spec.imu or GX5_25
    sc = resolve_scene(spec.scene)
    out = Path(out)
    name = spec.name or run_name(sc.name, spec.seed, spec.start_time)
    runs = out / lay.runs_folder if lay.runs_folder else out
    final = runs / name
    _check_target(final, overwrite)
    want_heatmaps = spec.heatmaps is not False and any(r in sensors for r in RADARS)
    calib, coupling_adc = _with_coupling_calib(*simulated_calibration(spec.board_seed),
                                               spec.coupling_calib)
    calib, hardware = _with_phase_errors(calib, spec.phase_errors, spec.board_seed)
    has_proc = want_heatmaps and heatmap_processor(calib.cascade) is not None
    if spec.heatmaps and want_heatmaps and not has_proc:
        raise ColoradarError("heatmaps were asked for but coloradar.dsp (RadarProcessor."
                             "heatmap) is not available")
    _write_calib(calib, out / "calib", overwrite, lay)

    partial = runs / f".{name}.partial"
    if partial.exists():
        shutil.rmtree(partial)  # a previous, interrupted simulation of this run
    partial.mkdir(parents=True)
    traj = _trajectory(sc, spec.motion, spec.seed, spec.speed, spec.rest)
    ctx = _Context(sc, traj, calib, coupling_adc, spec, partial, progress, has_proc, lay,
                   imu_model)
    ctx.hardware = hardware
    times, gt_times = _schedule(ctx, spec.duration)
    try:
        truth = _simulate_scans(ctx, sensors, times, workers)
        truth.update(_write_slow_streams(ctx, sensors, spec.vicon, times, gt_times))
        counts = _counts(sensors, spec.vicon, times, gt_times, has_proc, lay)
        _write_run_info(ctx, partial, sc, dict(
            scene=sc.name, duration=spec.duration, seed=spec.seed, motion=spec.motion,
            speed=spec.speed, rest=float(spec.rest),
            radar_time_offset=float(spec.radar_time_offset),
            coupling_calib=_coupling_record(spec.coupling_calib),
            phase_errors=asdict(spec.phase_errors) if spec.phase_errors else None,
            imu_model=asdict(imu_model), sensors=list(sensors),
            vicon=spec.vicon, heatmaps=has_proc, start_time=spec.start_time, name=name,
            board_seed=spec.board_seed, coloradar_version=__version__, counts=counts,
            layout=lay.name), truth)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    _move_into_place(partial, final)
    return SimResult(final, out / "calib", counts, time.perf_counter() - t0, has_proc, sc.name)


def _coupling_record(given: str | os.PathLike[str] | CouplingCalib | None) -> str | None:
    """What ``sim_config.json`` says of ``SimulationSpec.coupling_calib``."""
    if given is None or isinstance(given, CouplingCalib):
        return None if given is None else "CouplingCalib given"
    return os.fspath(given)


def _check_spec(spec: SimulationSpec) -> tuple[RunLayout, tuple[str, ...]]:
    """Step 1: refuse what cannot be simulated; returns the layout and the sensors to write."""
    try:
        lay = get_layout(spec.layout)
    except MissingDataError as exc:
        raise ColoradarError(str(exc)) from None
    choices = tuple(s for s in SENSOR_CHOICES
                    if s in lay.sensor_folders and (s not in RADARS or s in lay.radars))
    sensors = choices if spec.sensors is None else tuple(spec.sensors)
    bad = [s for s in sensors if s not in choices]
    if bad:
        raise ColoradarError(f"unknown sensor(s) {', '.join(bad)}"
                             f"{'' if lay is COLORADAR else ' in the ' + lay.title + ' layout'}"
                             f"; expected some of {', '.join(choices)}")
    if spec.vicon and "vicon" not in lay.tables:
        raise ColoradarError(f"the {lay.title} layout has no Vicon poses")
    if spec.motion not in MOTION_PROFILES:
        raise ColoradarError(f"unknown motion profile {spec.motion!r}; expected one of "
                             f"{', '.join(MOTION_PROFILES)}")
    speed, duration = spec.speed, spec.duration
    if speed is not None and not (np.isfinite(speed) and 0 <= speed <= 30):
        raise ColoradarError(f"speed must be in [0, 30] m/s, got {speed}")
    if not 0 < duration <= 3600:
        raise ColoradarError(f"duration must be in (0, 3600] s, got {duration}")
    if not (np.isfinite(spec.rest) and 0 <= spec.rest < duration):
        raise ColoradarError(f"rest must be in [0, duration) s, got {spec.rest}")
    if not (np.isfinite(spec.radar_time_offset) and abs(spec.radar_time_offset) <= 0.5):
        raise ColoradarError("radar_time_offset must be within ±0.5 s, got "
                             f"{spec.radar_time_offset}")
    return lay, sensors


def _schedule(ctx: _Context, duration: float) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Step 2: every stream's sample times [s from the start], drawn in a fixed order whatever
    the sensor selection, and the ground truth's."""
    trng = ctx.rng("timing")
    calib = ctx.calib
    times = {
        "cascade": _stream_times(RATES["cascade"], duration,
                                 calib.cascade.waveform.frame_duration,
                                 RADAR_MODELS["cascade"].frame_jitter, trng),
        "single_chip": _stream_times(RATES["single_chip"], duration,
                                     calib.single_chip.waveform.frame_duration,
                                     RADAR_MODELS["single_chip"].frame_jitter, trng),
        "lidar": _stream_times(RATES["lidar"], duration, LidarModel().period,
                               LidarModel().jitter, trng),
        "imu": _stream_times(RATES["imu"], duration, 0.0, ctx.imu_model.jitter, trng),
        "vicon": _stream_times(RATES["vicon"], duration, 0.0, 1e-4, trng),
    }
    n_gt = int(np.ceil(duration * RATES["groundtruth"] - 1e-9)) + 1
    return times, np.arange(n_gt) / RATES["groundtruth"]


def _simulate_scans(ctx: _Context, sensors: Sequence[str], times: dict[str, np.ndarray],
                    workers: int) -> dict[str, np.ndarray]:
    """Step 3: the lidar and radar frames, on ``workers`` threads; returns their truth."""
    sc = ctx.scene
    # Lazily built scene data, built once here rather than raced for by the threads.
    _ = sc.static_scatterers, sc.static_rect_arrays, [o.num_scatterers for o in sc.objects]
    tasks: list[Callable[[], dict]] = []
    if "lidar" in sensors:
        tasks.append(lambda: _lidar_task(ctx, times["lidar"]))
    for r in RADARS:
        if r in sensors:
            tasks.append(functools.partial(_radar_task, ctx, r, times[r]))
    truth: dict[str, np.ndarray] = {}
    if workers > 1 and len(tasks) > 1:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            for res in [pool.submit(t) for t in tasks]:
                truth.update(res.result())
    else:
        for t in tasks:
            truth.update(t())
    return truth


def _write_slow_streams(ctx: _Context, sensors: Sequence[str], vicon: bool,
                        times: dict[str, np.ndarray], gt_times: np.ndarray
                        ) -> dict[str, np.ndarray]:
    """IMU, ground truth, Vicon, and the rig/object truth at the ground-truth times."""
    root, traj, calib = ctx.root, ctx.traj, ctx.calib
    truth: dict[str, np.ndarray] = {}
    gt = traj.state(gt_times)
    start_rot, start_pos = gt.rotation[0], gt.position[0]
    world_T_start = np.eye(4)
    world_T_start[:3, :3] = start_rot.as_matrix()
    world_T_start[:3, 3] = start_pos
    truth.update({
        "world_T_start": world_T_start,
        "rig_timestamps": ctx.start_time + gt_times,
        "rig_pose_world": gt.poses(),
        "rig_velocity_world": gt.velocity,
        "rig_acceleration_world": gt.acceleration,
        "rig_angular_velocity_base": gt.angular_velocity,
    })
    if "groundtruth" in sensors:
        inv = start_rot.inv()
        rel_rot = inv * gt.rotation
        rel_pos = inv.apply(gt.position - start_pos)
        poses = np.hstack([rel_pos, rel_rot.as_quat(canonical=True)])
        poses[0] = [0, 0, 0, 0, 0, 0, 1]  # exactly the identity, as in the dataset
        gt_table = ctx.layout.tables["groundtruth"]
        write_timestamps(root / gt_table.timestamps_path, ctx.start_time + gt_times)
        write_poses(root / gt_table.path, poses)
    if "imu" in sensors:
        data, ab, gb = simulate_imu(traj, calib.transforms["imu"].matrix(), times["imu"],
                                    ctx.imu_model, ctx.rng("imu"))
        imu_table = ctx.layout.tables["imu"]
        write_timestamps(root / imu_table.timestamps_path, ctx.start_time + times["imu"])
        write_imu(root / imu_table.path, data)
        truth.update({"imu_timestamps": ctx.start_time + times["imu"],
                      "imu_accel_bias": ab, "imu_gyro_bias": gb})
    truth["radar_time_offset"] = np.float64(ctx.radar_time_offset)
    if vicon:
        vt = times["vicon"]
        st = traj.state(vt)
        base_T_v = calib.transforms["vicon"].matrix()
        g = ctx.rng("vicon")
        rot = (st.rotation * Rotation.from_matrix(base_T_v[:3, :3])
               * Rotation.from_rotvec(g.normal(0, np.radians(0.05), (len(vt), 3))))
        pos = st.position + st.rotation.apply(base_T_v[:3, 3]) + g.normal(0, 5e-4, (len(vt), 3))
        vicon_table = ctx.layout.tables["vicon"]
        write_timestamps(root / vicon_table.timestamps_path, ctx.start_time + vt)
        write_poses(root / vicon_table.path,
                    np.hstack([pos, rot.as_quat(canonical=True)]))
    sc = ctx.scene
    static = sc.static_scatterers
    truth.update({"static_position": static.position, "static_strength": static.strength,
                  "object_ident_offset": np.asarray(sc.object_ident_offsets(), dtype=np.int64),
                  "object_names": np.array([o.name for o in sc.objects], dtype=str)})
    if sc.objects:
        samples = [o.path.sample(gt_times) for o in sc.objects]
        truth["object_position"] = np.stack([s.position for s in samples])
        truth["object_velocity"] = np.stack([s.velocity for s in samples])
        truth["object_heading"] = np.stack([s.heading for s in samples])
    return truth


def _counts(sensors, vicon, times, gt_times, heatmaps, layout: RunLayout = COLORADAR
            ) -> dict[str, int]:
    counts = {}
    for r in RADARS:
        if r in sensors:
            counts[f"{r}/adc"] = len(times[r])
            if heatmaps:
                counts[f"{r}/heatmaps"] = len(times[r])
            if r == "single_chip" and f"{r}/pointclouds" in layout.frames:
                counts[f"{r}/pointclouds"] = len(times[r])
    if "lidar" in sensors:
        counts["lidar/pointclouds"] = len(times["lidar"])
    if "imu" in sensors:
        counts["imu"] = len(times["imu"])
    if "groundtruth" in sensors:
        counts["groundtruth"] = len(gt_times)
    if vicon:
        counts["vicon"] = len(times["vicon"])
    return counts


def _write_run_info(ctx: _Context, root: Path, scene: Scene, config: dict,
                    truth: dict[str, np.ndarray]) -> None:
    save_truth(root / TRUTH_FILE, truth)
    atomic_write_text(root / "truth" / "scene.json", scene.to_json())
    atomic_write_text(root / "truth" / "sim_config.json", json.dumps(config, indent=1) + "\n")


def _move_into_place(partial: Path, final: Path) -> None:
    if final.exists():
        old = final.with_name(f".{final.name}.replaced")
        if old.exists():
            shutil.rmtree(old)
        os.replace(final, old)
        os.replace(partial, final)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(partial, final)


@dataclass(frozen=True, eq=False)
class Simulation:
    """The models behind a simulated run, rebuilt from its ``truth/`` folder.

    Attributes
    ----------
    scene
        The scene (from ``truth/scene.json``).
    trajectory
        The rig trajectory (``world_T_base`` at run-relative times).
    start_time
        Unix time of the run start [s]: run time = timestamp − start_time.
    config
        The parameters the run was simulated with (``truth/sim_config.json``).
    """

    scene: Scene
    trajectory: RigTrajectory
    start_time: float
    config: dict

    def run_time(self, timestamps: np.ndarray) -> np.ndarray:
        """Run-relative times [s] of Unix ``timestamps``."""
        return np.asarray(timestamps, dtype=np.float64) - self.start_time


def open_simulation(run_path: str | os.PathLike[str]) -> Simulation:
    """Rebuild the scene and the exact rig trajectory of a simulated run (for evaluation)."""
    root = Path(run_path)
    cfg_path = root / "truth" / "sim_config.json"
    if not cfg_path.is_file():
        raise ColoradarError(f"{root}: not a simulated run (no truth/sim_config.json)")
    try:
        cfg = json.loads(read_file_text(cfg_path))
    except json.JSONDecodeError as exc:
        raise FormatError(f"{cfg_path}: expected the JSON the simulator writes ({exc})") from None
    scene = load_scene(root / "truth" / "scene.json")
    traj = _trajectory(scene, cfg["motion"], cfg["seed"], cfg.get("speed"), cfg.get("rest", 0.0))
    return Simulation(scene, traj, float(cfg["start_time"]), cfg)
