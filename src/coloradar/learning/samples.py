"""Map-style datasets of time-synchronised radar samples, from run folders or an exported file.

One sample per radar frame of the chosen radar, over one run, every run of a dataset root, or
files written by ``coloradar export RUN OUT.h5 --format hdf5`` (:mod:`coloradar.interop.hdf5`):

=================  =================================  ==============================================
key                type                               meaning
=================  =================================  ==============================================
``run``            str                                run name
``radar_frame``    int                                position in the radar stream
``frame_id``       int                                number in the radar file's name
``radar_time``     float (float64)                    the radar frame's time [s]
``heatmap``        float32 ``(el, az, range, 2)``     intensity, range rate [m/s] (product ``heatmap``)
``points``         float32 ``(N, 5)``                 x y z intensity range_rate, radar frame
``points_time``    float                              time of the associated point cloud [s]
``polar``          float32 ``(C, range, az)``         range–azimuth image (product ``polar``; views)
``bev``            float32 ``(C, nx, ny)``            bird's-eye image (product ``bev``; views)
``lidar``          float32 ``(M, 4)``                 nearest scan, x y z intensity, lidar frame
``lidar_time``     float                              time of the nearest lidar scan [s]
``radar_T_lidar``  float64 ``(4, 4)``                 maps that scan into the radar frame at
                                                      ``radar_time`` (both poses interpolated at
                                                      their own times: rig motion removed)
``lidar_target``   float32 ``(K, 4)``                 voxel map cut to the radar's view, radar
                                                      frame: x y z mean intensity (``targets``)
``lidar_polar``    float32 ``(3, range, az)``         ``lidar_target`` on the polar grid
``lidar_bev``      float32 ``(3, nx, ny)``            ``lidar_target`` on the BEV grid
``world_T_base``   float64 ``(4, 4)``                 ground-truth pose interpolated at ``radar_time``
``pose_knots``     float64 ``(2,)``                   the ground-truth times bracketing ``radar_time``
``world_T_radar``  float64 ``(4, 4)``                 ``world_T_base @ base_T_radar``
=================  =================================  ==============================================

The image channels are those of :mod:`coloradar.learning.views` (radar: intensity [dB], range
rate [m/s]; lidar: occupancy, height, intensity), the lidar targets those of
:mod:`coloradar.learning.targets`.

Frames are paired by nearest time (:func:`coloradar.geometry.nearest_indices`): a lidar scan
within half a lidar period of the radar time, a point cloud within half a radar period of the
heatmap. Radar frames with no partner, or outside the ground truth's span, are left out when the
view is built (``dropped`` counts them), so every index gives a complete sample. Nothing is
read until a sample is asked for, except that the first sample of a run that needs a lidar
target fuses that run's lidar scans into its voxel map (once per run and process; an exported
file holds the targets ready).
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..calib import Calibration, HeatmapConfig
from ..dataset import Dataset, Sequence, open_dataset, open_sequence
from ..dataset.dataset import is_run_folder
from ..errors import FrameIndexError, MissingDataError, SettingsError
from ..geometry import SE3, Trajectory, nearest_indices, sensor_to_base, trajectory_from_groundtruth
from .splits import split_runs
from .targets import TargetSettings, build_voxel_map, frame_target, prepare_cut
from .views import BevGrid, BevProjector, ViewOptions, lidar_bev, lidar_polar, radar_polar

__all__ = ["PRODUCTS", "SampleOptions", "SyncedSamples", "ViewOptions"]

PRODUCTS = ("heatmap", "points", "polar", "bev")
_FROM_HEATMAP = ("heatmap", "polar", "bev")
H5_SUFFIXES = (".h5", ".hdf5")


def _half_period(t: np.ndarray) -> float:
    return 0.5 * float(np.median(np.diff(t))) if t.size > 1 else float("inf")


def _is_h5(p: Any) -> bool:
    return isinstance(p, (str, os.PathLike)) and Path(p).suffix.lower() in H5_SUFFIXES


def _sequences(source: Any, calib: Calibration | str | os.PathLike[str] | None) -> list[Any]:
    """Sequences, or paths of exported files, in source order."""
    if isinstance(source, Sequence) or _is_h5(source):
        return [source]
    if isinstance(source, Dataset):
        return list(source)
    if isinstance(source, (str, os.PathLike)):
        p = Path(source)
        if p.is_dir() and not is_run_folder(p):
            return list(open_dataset(p, calib=calib))
        return [open_sequence(p, calib=calib)]
    items = list(source)
    out: list[Any] = []
    for s in items:
        if isinstance(s, Sequence) or _is_h5(s):
            out.append(s)
        elif isinstance(s, (str, os.PathLike)):
            out.append(open_sequence(s, calib=calib))
        else:
            raise SettingsError("source must be a run, a dataset, a path, an exported .h5 file "
                                "or a list of those")
    return out


@dataclass
class _FolderRun:
    """The samples of one run folder or zip (indices into its streams)."""

    seq: Sequence
    trajectory: Trajectory
    base_T_radar: SE3
    base_T_lidar: SE3 | None
    anchor: str
    config: HeatmapConfig | None
    # Per sample of this run (aligned arrays):
    radar_k: np.ndarray
    points_k: np.ndarray
    lidar_k: np.ndarray
    dropped: dict[str, int] = field(default_factory=dict)
    _cut: Any = None

    @property
    def name(self) -> str:
        return self.seq.name

    def __len__(self) -> int:
        return int(self.radar_k.size)

    def radar_times(self, radar: str) -> np.ndarray:
        return getattr(self.seq.radar(radar), self.anchor).timestamps[self.radar_k]

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_cut"] = None  # a KD-tree is rebuilt where it is needed (a spawned worker)
        return state


@dataclass(frozen=True)
class SampleOptions:
    """What a :class:`SyncedSamples` view holds and how it pairs frames (each field is also one
    of its keywords, documented there; None: the default, or for an exported file what it
    holds)."""

    radar: str | None = None
    products: Iterable[str] | None = None
    lidar: bool | None = None
    targets: bool | None = None
    target_settings: TargetSettings | None = None
    views: ViewOptions | None = None
    pose_source: str = "groundtruth"
    lidar_tolerance: float | None = None
    points_tolerance: float | None = None


class SyncedSamples:
    """Time-synchronised radar / lidar / ground-truth samples of one or more runs (map-style).

    Parameters
    ----------
    source
        A run (:class:`~coloradar.Sequence` or path), a dataset (:class:`~coloradar.Dataset`
        or root path), a file written by ``coloradar export ... --format hdf5`` (``.h5``), or a
        list of runs or such files.
    options
        A :class:`SampleOptions` (its fields are listed below); keyword arguments named like
        its fields replace them, so ``SyncedSamples(root, radar="cascade")`` works.
    runs
        Only these run names (in this order).
    calib
        Calibration for paths (default: found beside the runs).

    Other Parameters
    ----------------
    radar
        ``"cascade"`` or ``"single_chip"``: its frames define the samples.
    products
        Some of ``"heatmap"`` (``<radar>/heatmaps``), ``"points"`` (``<radar>/pointclouds``:
        the single chip's own, or those ``coloradar process`` / ``import`` wrote), ``"polar"``
        and ``"bev"`` (images of the heatmap, see :class:`ViewOptions`). The heatmap stream
        defines the samples when any heatmap product is asked, else the point clouds. Default
        ``("heatmap",)``; for an exported file, everything it holds.
    lidar
        Include the nearest lidar scan and ``radar_T_lidar`` (default True; for a file, what
        it holds).
    targets
        Include ``lidar_target`` (and ``lidar_polar`` / ``lidar_bev`` with those products):
        the run's lidar map cut to the radar's view (default False; for a file, what it holds).
    target_settings
        How the maps are made (:class:`~coloradar.learning.targets.TargetSettings`).
    views
        How images are made (:class:`ViewOptions`).
    pose_source
        ``"groundtruth"`` or ``"vicon"``.
    lidar_tolerance, points_tolerance
        Largest time difference of a pair [s]; default half the partner stream's period.

    Attributes
    ----------
    runs
        Run names, in sample order.
    dropped
        Radar frames left out, by reason, over all runs.
    grid
        The BEV grid (None without the ``bev`` product).
    heatmap_config
        The first run's heatmap grid used for images and targets (None without heatmaps).
    """

    def __init__(self, source: Any, options: SampleOptions | None = None, *,
                 runs: Iterable[str] | None = None,
                 calib: Calibration | str | os.PathLike[str] | None = None, **fields: Any):
        o = replace(options or SampleOptions(), **fields)
        radar, products, lidar, targets = o.radar, o.products, o.lidar, o.targets
        target_settings, views = o.target_settings, o.views
        items = _sequences(source, calib) if source is not None else []
        files = [s for s in items if not isinstance(s, Sequence)]
        if files and len(files) != len(items):
            raise SettingsError("mix of exported files and run folders: give one kind")
        self._runs: list[Any]
        if files:
            from .h5_file import H5Run  # lazily: h5py is an optional extra

            self._runs = [H5Run(f) for f in files]
            first = self._runs[0]
            radar = radar or first.radar
            products = tuple(products) if products is not None else first.products
            lidar = first.lidar if lidar is None else lidar
            targets = first.targets if targets is None else targets
            for r in self._runs:
                r.check(radar, products, lidar, targets)
            target_settings = target_settings or first.target_settings
            views = views or first.views
        radar = radar or "cascade"
        products = tuple(products) if products is not None else ("heatmap",)
        self.radar = radar
        self.products = tuple(products)
        if not self.products or any(p not in PRODUCTS for p in self.products):
            raise SettingsError(f"products must be some of {', '.join(PRODUCTS)}, got "
                                 f"{', '.join(self.products) or 'none'}")
        if radar not in ("cascade", "single_chip"):
            raise SettingsError(f"unknown radar {radar!r}; expected cascade or single_chip")
        self.lidar = True if lidar is None else bool(lidar)
        self.targets = bool(targets)
        self.target_settings = target_settings or TargetSettings()
        self.views = views or ViewOptions()
        self.pose_source = o.pose_source
        if runs is not None:
            # Select before indexing: the other runs may lack what this view needs.
            wanted = list(runs)
            have = {r.name: r for r in (self._runs if files else items)}
            missing = [r for r in wanted if r not in have]
            if missing:
                raise MissingDataError(f"no run named {', '.join(missing)} (runs: "
                                       f"{', '.join(sorted(have)) or 'none'})")
            if files:
                self._runs = [have[r] for r in wanted]
            else:
                items = [have[r] for r in wanted]
        if not files:
            self._runs = [self._index_run(s, o.lidar_tolerance, o.points_tolerance)
                          for s in items]
        if not self._runs and source is not None:
            raise MissingDataError(f"{source}: no runs")
        self.runs = [r.name for r in self._runs]
        counts = np.array([len(r) for r in self._runs], dtype=np.int64)
        self._offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.dropped: dict[str, int] = {}
        for r in self._runs:
            for why, n in r.dropped.items():
                self.dropped[why] = self.dropped.get(why, 0) + n
        self.heatmap_config = next((r.config for r in self._runs if r.config is not None), None)
        self.grid: BevGrid | None = None
        if "bev" in self.products and self._runs:
            if self.views.grid is None and self.heatmap_config is None:
                raise SettingsError("the bev product needs a heatmap grid")
            self.grid = self.views.grid or BevGrid.for_radar(self.heatmap_config)  # type: ignore[arg-type]
        self._projectors: dict[int, BevProjector] = {}

    @property
    def _anchor(self) -> str:
        return "heatmaps" if any(p in _FROM_HEATMAP for p in self.products) else "pointclouds"

    # -- index ------------------------------------------------------------------------------
    def _radar_config(self, seq: Sequence) -> HeatmapConfig:
        if self.views.angles == "true":
            from ..dsp import RadarProcessor

            return RadarProcessor(seq.calib.radar(self.radar)).heatmap_config()
        return seq.radar(self.radar).heatmap_config

    def _index_run(self, seq: Sequence, lidar_tol: float | None,
                   points_tol: float | None) -> _FolderRun:
        sensor = seq.radar(self.radar)
        have = seq.available()
        streams = {"heatmaps" if p in _FROM_HEATMAP else "pointclouds" for p in self.products}
        for st in sorted(streams):
            key = f"{self.radar}/{st}"
            if key not in have:
                hint = " (write them with 'coloradar process')" if st == "heatmaps" or \
                    self.radar == "cascade" else ""
                raise MissingDataError(f"{seq.location}: no {key} in this run{hint}; present: "
                                       f"{', '.join(have) or 'nothing'}")
        anchor = getattr(sensor, self._anchor)
        t = anchor.timestamps
        keep = np.ones(t.size, dtype=bool)
        dropped: dict[str, int] = {}
        traj = trajectory_from_groundtruth(seq, self.pose_source)
        covered = traj.covers(t)
        dropped["outside ground truth"] = int((~covered).sum())
        keep &= covered
        points_k = np.full(t.size, -1, dtype=np.int64)
        if "points" in self.products and self._anchor != "pointclouds":
            pts_t = sensor.pointclouds.timestamps
            tol = points_tol if points_tol is not None else _half_period(t)
            points_k = nearest_indices(t, pts_t, tol)
            dropped["no point cloud"] = int((keep & (points_k < 0)).sum())
            keep &= points_k >= 0
        elif "points" in self.products:
            points_k = np.arange(t.size, dtype=np.int64)
        lidar_k = np.full(t.size, -1, dtype=np.int64)
        base_T_lidar = None
        if self.lidar:
            lid_t = seq.lidar.pointclouds.timestamps
            tol = lidar_tol if lidar_tol is not None else _half_period(lid_t)
            lidar_k = nearest_indices(t, lid_t, tol)
            ok = lidar_k >= 0
            ok[ok] &= traj.covers(lid_t[lidar_k[ok]])
            dropped["no lidar scan"] = int((keep & ~ok).sum())
            keep &= ok
            base_T_lidar = sensor_to_base(seq.calib, "lidar")
        if self.targets and "lidar/pointclouds" not in have:
            raise MissingDataError(f"{seq.location}: no lidar scans in this run; lidar targets "
                                   f"need them (present: {', '.join(have) or 'nothing'})")
        needs_grid = self.targets or any(p in ("polar", "bev") for p in self.products)
        config = self._radar_config(seq) if needs_grid or "heatmap" in self.products else None
        idx = np.flatnonzero(keep)
        return _FolderRun(seq, traj, sensor_to_base(seq.calib, self.radar), base_T_lidar,
                          self._anchor, config, idx, points_k[idx], lidar_k[idx],
                          {k: v for k, v in dropped.items() if v})

    # -- container --------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(self._offsets[-1])

    def __repr__(self) -> str:
        return (f"<SyncedSamples {self.radar} {'+'.join(self.products)}"
                f"{' + lidar' if self.lidar else ''}{' + targets' if self.targets else ''}: "
                f"{len(self)} samples from {len(self.runs)} run(s)>")

    def locate(self, i: int) -> tuple[str, int]:
        """``(run name, radar frame position)`` of sample ``i``."""
        r, k = self._find(i)
        return self._runs[r].name, int(self._runs[r].radar_k[k])

    def _find(self, i: int) -> tuple[int, int]:
        n = len(self)
        if not -n <= int(i) < n:
            raise FrameIndexError(f"sample {i} out of range ({n} samples)")
        i = int(i) % n
        r = int(np.searchsorted(self._offsets, i, side="right") - 1)
        return r, i - int(self._offsets[r])

    def radar_times(self) -> np.ndarray:
        """float64 ``(len(self),)``: every sample's radar time [s] (reads no frame)."""
        out = [r.radar_times(self.radar) for r in self._runs]
        return np.concatenate(out) if out else np.zeros(0)

    def run_slices(self) -> dict[str, slice]:
        """Run name -> the slice of sample indices that belong to it."""
        return {r.name: slice(int(a), int(b)) for r, a, b in
                zip(self._runs, self._offsets[:-1], self._offsets[1:], strict=True)}

    def __getitem__(self, i: int) -> dict[str, Any]:
        r_i, k = self._find(i)
        run = self._runs[r_i]
        if not isinstance(run, _FolderRun):
            return run.sample(k, self.products, self.lidar, self.targets)
        return self._folder_sample(run, k)

    def _projector(self, config: HeatmapConfig) -> BevProjector:
        assert self.grid is not None
        key = id(config)
        if key not in self._projectors:
            self._projectors[key] = BevProjector(config, self.grid)
        return self._projectors[key]

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_projectors"] = {}  # index tables: rebuilt on demand in a worker
        return state

    def _folder_sample(self, run: _FolderRun, k: int) -> dict[str, Any]:
        sensor = run.seq.radar(self.radar)
        anchor = getattr(sensor, run.anchor)
        rk = int(run.radar_k[k])
        t = float(anchor.timestamps[rk])
        out: dict[str, Any] = {"run": run.seq.name, "radar_frame": rk,
                               "frame_id": int(anchor.frame_ids[rk]), "radar_time": t}
        v = self.views
        if any(p in _FROM_HEATMAP for p in self.products):
            hm = sensor.heatmaps[rk]
            assert run.config is not None
            if "heatmap" in self.products:
                out["heatmap"] = hm
            if "polar" in self.products:
                out["polar"] = radar_polar(hm, run.config, v.reduce, v.range_rate)  # type: ignore[arg-type]
            if "bev" in self.products:
                out["bev"] = self._projector(run.config)(hm, v.reduce, v.range_rate)  # type: ignore[arg-type]
        if "points" in self.products:
            pk = int(run.points_k[k])
            out["points"] = sensor.pointclouds[pk]
            out["points_time"] = float(sensor.pointclouds.timestamps[pk])
        world_T_base = run.trajectory.at(t)
        knots = run.trajectory.timestamps
        j = int(np.clip(np.searchsorted(knots, t, side="right") - 1, 0, max(knots.size - 2, 0)))
        out["world_T_base"] = world_T_base.matrix()
        out["pose_knots"] = knots[j:j + 2].copy() if knots.size > 1 else knots[:1].repeat(2)
        world_T_radar = world_T_base @ run.base_T_radar
        assert isinstance(world_T_radar, SE3)
        out["world_T_radar"] = world_T_radar.matrix()
        if self.lidar:
            lk = int(run.lidar_k[k])
            lid = run.seq.lidar.pointclouds
            tl = float(lid.timestamps[lk])
            out["lidar"] = lid[lk]
            out["lidar_time"] = tl
            assert run.base_T_lidar is not None
            world_T_lidar = run.trajectory.at(tl) @ run.base_T_lidar
            radar_T_lidar = world_T_radar.inverse() @ world_T_lidar
            assert isinstance(radar_T_lidar, SE3)
            out["radar_T_lidar"] = radar_T_lidar.matrix()
        if self.targets:
            assert run.config is not None
            st = self.target_settings
            if run._cut is None:
                vmap = build_voxel_map(run.seq, st, trajectory=run.trajectory)
                run._cut = prepare_cut(vmap, st.min_hits)
            tgt = frame_target(run._cut, out["world_T_radar"], run.config, st.target_min_range)
            out["lidar_target"] = tgt
            if "polar" in self.products:
                out["lidar_polar"] = lidar_polar(tgt, run.config)
            if "bev" in self.products:
                assert self.grid is not None
                out["lidar_bev"] = lidar_bev(tgt, self.grid)
        return out

    # -- splits -----------------------------------------------------------------------------
    def subset(self, runs: Iterable[str]) -> SyncedSamples:
        """The samples of some runs only (same settings; an empty list gives an empty view)."""
        wanted = set(runs)
        view = SyncedSamples.__new__(SyncedSamples)
        view.__dict__.update(self.__dict__)
        view._runs = [r for r in self._runs if r.name in wanted]
        view.runs = [r.name for r in view._runs]
        counts = np.array([len(r) for r in view._runs], dtype=np.int64)
        view._offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        view.dropped = {}
        for r in view._runs:
            for why, n in r.dropped.items():
                view.dropped[why] = view.dropped.get(why, 0) + n
        view._projectors = {}
        return view

    def split(self, fractions: Mapping[str, float] | None = None,
              seed: int = 0) -> dict[str, SyncedSamples]:
        """Views over disjoint sets of runs by a stable hash (:func:`split_runs`).

        Every part is returned, an empty one as an empty view (with the
        :class:`~coloradar.DataWarning` that :func:`split_runs` gives for it).
        """
        parts = split_runs(self.runs, fractions, seed)
        return {name: self.subset(rs) for name, rs in parts.items()}
