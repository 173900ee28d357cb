"""A learning view: map-style datasets of time-synchronised radar samples (numpy; torch optional).

One sample per radar frame of the chosen radar, over one run or every run of a dataset root:

=================  =============================  ==================================================
key                type                           meaning
=================  =============================  ==================================================
``run``            str                            run name
``radar_frame``    int                            position in the radar stream (``seq.<radar>.<stream>``)
``frame_id``       int                            number in the radar file's name
``radar_time``     float (float64)                the radar frame's time [s]
``heatmap``        float32 ``(el, az, range, 2)`` peak intensity, range rate [m/s] (if asked)
``points``         float32 ``(N, 5)``             x y z intensity range_rate, radar frame (if asked)
``points_time``    float                          time of the associated point cloud [s]
``lidar``          float32 ``(M, 4)``             x y z intensity, lidar frame (if asked)
``lidar_time``     float                          time of the nearest lidar scan [s]
``world_T_base``   float64 ``(4, 4)``             ground-truth pose interpolated at ``radar_time``
``pose_knots``     float64 ``(2,)``               the ground-truth times bracketing ``radar_time``
``world_T_radar``  float64 ``(4, 4)``             ``world_T_base @ base_T_radar``
``radar_T_lidar``  float64 ``(4, 4)``             maps the scan's points into the radar frame at
                                                  ``radar_time``: both poses interpolated at their
                                                  own times, so rig motion between them is removed
=================  =============================  ==================================================

Frames are paired by nearest time (:func:`coloradar.geometry.nearest_indices`): a lidar scan
within half a lidar period of the radar time, a point cloud within half a radar period of the
heatmap. Radar frames with no partner, or outside the ground truth's span, are left out when the
view is built (``dropped`` counts them), so every index gives a complete sample. Nothing is
read until a sample is asked for.

Splits are by run, never by frame (neighbouring frames of one run are nearly identical, so a
frame-level split would leak): :func:`split_runs` gives the same answer for the same run names
and seed on every machine.

With ``torch`` installed, :func:`torch_dataset` wraps a view as a ``torch.utils.data.Dataset``
and :func:`collate_torch` batches samples whose point clouds differ in size.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .calib import Calibration
from .dataset import Dataset, Sequence, open_dataset, open_sequence
from .dataset.dataset import is_run_folder
from .errors import FrameIndexError, MissingDataError, MissingDependencyError, SettingsError
from .geometry import SE3, Trajectory, nearest_indices, sensor_to_base, trajectory_from_groundtruth

__all__ = ["PRODUCTS", "SyncedSamples", "collate_numpy", "collate_torch", "split_runs",
           "torch_dataset"]

PRODUCTS = ("heatmap", "points")
_STREAM = {"heatmap": "heatmaps", "points": "pointclouds"}


@dataclass
class _Run:
    seq: Sequence
    trajectory: Trajectory
    base_T_radar: SE3
    base_T_lidar: SE3 | None
    # Per sample of this run (aligned arrays):
    radar_k: np.ndarray
    points_k: np.ndarray
    lidar_k: np.ndarray
    dropped: dict[str, int] = field(default_factory=dict)


def _half_period(t: np.ndarray) -> float:
    return 0.5 * float(np.median(np.diff(t))) if t.size > 1 else float("inf")


def _sequences(source: Any, calib: Calibration | str | os.PathLike[str] | None,
               runs: Iterable[str] | None) -> list[Sequence]:
    if isinstance(source, Sequence):
        seqs = [source]
    elif isinstance(source, Dataset):
        seqs = list(source)
    elif isinstance(source, (str, os.PathLike)):
        p = Path(source)
        if p.is_dir() and not is_run_folder(p):
            seqs = list(open_dataset(p, calib=calib))
        else:
            seqs = [open_sequence(p, calib=calib)]
    else:
        seqs = list(source)
        if not all(isinstance(s, Sequence) for s in seqs):
            raise SettingsError("source must be a run, a dataset, a path or a list of runs")
    if runs is not None:
        wanted = list(runs)
        have = {s.name: s for s in seqs}
        missing = [r for r in wanted if r not in have]
        if missing:
            raise MissingDataError(f"no run named {', '.join(missing)} (runs: "
                                   f"{', '.join(sorted(have)) or 'none'})")
        seqs = [have[r] for r in wanted]
    if not seqs:
        raise MissingDataError(f"{source}: no runs")
    return seqs


class SyncedSamples:
    """Time-synchronised radar / lidar / ground-truth samples of one or more runs (map-style).

    Parameters
    ----------
    source
        A run (:class:`~coloradar.Sequence` or path), a dataset (:class:`~coloradar.Dataset`
        or root path), or a list of runs.
    radar
        ``"cascade"`` or ``"single_chip"``: its frames define the samples.
    products
        Some of ``"heatmap"`` (``<radar>/heatmaps``) and ``"points"`` (``<radar>/pointclouds``:
        the single chip's own, or those ``coloradar process`` / ``import`` wrote). The first
        product's frames are the samples.
    lidar
        Include the nearest lidar scan and ``radar_T_lidar``.
    pose_source
        ``"groundtruth"`` or ``"vicon"``.
    runs
        Only these run names (in this order).
    calib
        Calibration for paths (default: found beside the runs).
    lidar_tolerance, points_tolerance
        Largest time difference of a pair [s]; default half the partner stream's period.

    Attributes
    ----------
    runs
        Run names, in sample order.
    dropped
        Radar frames left out, by reason, over all runs.
    """

    def __init__(self, source: Any, *, radar: str = "cascade",
                 products: Iterable[str] = ("heatmap",), lidar: bool = True,
                 pose_source: str = "groundtruth", runs: Iterable[str] | None = None,
                 calib: Calibration | str | os.PathLike[str] | None = None,
                 lidar_tolerance: float | None = None, points_tolerance: float | None = None):
        self.radar = radar
        self.products = tuple(products)
        if not self.products or any(p not in PRODUCTS for p in self.products):
            raise SettingsError(f"products must be some of {', '.join(PRODUCTS)}, got "
                                 f"{', '.join(self.products) or 'none'}")
        if radar not in ("cascade", "single_chip"):
            raise SettingsError(f"unknown radar {radar!r}; expected cascade or single_chip")
        self.lidar = lidar
        self.pose_source = pose_source
        self._options = dict(radar=radar, products=self.products, lidar=lidar,
                             pose_source=pose_source, lidar_tolerance=lidar_tolerance,
                             points_tolerance=points_tolerance)
        self._runs = [self._index_run(s, lidar_tolerance, points_tolerance)
                      for s in _sequences(source, calib, runs)]
        self.runs = [r.seq.name for r in self._runs]
        counts = np.array([r.radar_k.size for r in self._runs], dtype=np.int64)
        self._offsets = np.concatenate([[0], np.cumsum(counts)])
        self.dropped: dict[str, int] = {}
        for r in self._runs:
            for why, n in r.dropped.items():
                self.dropped[why] = self.dropped.get(why, 0) + n

    # -- index ------------------------------------------------------------------------------
    def _index_run(self, seq: Sequence, lidar_tol: float | None, points_tol: float | None) -> _Run:
        sensor = seq.radar(self.radar)
        have = seq.available()
        for p in self.products:
            key = f"{self.radar}/{_STREAM[p]}"
            if key not in have:
                hint = " (write them with 'coloradar process')" if p == "heatmap" or \
                    self.radar == "cascade" else ""
                raise MissingDataError(f"{seq.location}: no {key} in this run{hint}; present: "
                                       f"{', '.join(have) or 'nothing'}")
        anchor = getattr(sensor, _STREAM[self.products[0]])
        t = anchor.timestamps
        keep = np.ones(t.size, dtype=bool)
        dropped: dict[str, int] = {}
        traj = trajectory_from_groundtruth(seq, self.pose_source)
        covered = traj.covers(t)
        dropped["outside ground truth"] = int((~covered).sum())
        keep &= covered
        points_k = np.full(t.size, -1, dtype=np.int64)
        if "points" in self.products and self.products[0] != "points":
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
        idx = np.flatnonzero(keep)
        return _Run(seq, traj, sensor_to_base(seq.calib, self.radar), base_T_lidar, idx,
                    points_k[idx], lidar_k[idx], {k: v for k, v in dropped.items() if v})

    # -- container --------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(self._offsets[-1])

    def __repr__(self) -> str:
        return (f"<SyncedSamples {self.radar} {'+'.join(self.products)}"
                f"{' + lidar' if self.lidar else ''}: {len(self)} samples from "
                f"{len(self.runs)} run(s)>")

    def locate(self, i: int) -> tuple[str, int]:
        """``(run name, radar frame position)`` of sample ``i``."""
        r, k = self._find(i)
        return self._runs[r].seq.name, int(self._runs[r].radar_k[k])

    def _find(self, i: int) -> tuple[int, int]:
        n = len(self)
        if not -n <= int(i) < n:
            raise FrameIndexError(f"sample {i} out of range ({n} samples)")
        i = int(i) % n
        r = int(np.searchsorted(self._offsets, i, side="right") - 1)
        return r, i - int(self._offsets[r])

    def radar_times(self) -> np.ndarray:
        """float64 ``(len(self),)``: every sample's radar time [s] (reads no frame)."""
        out = []
        for r in self._runs:
            anchor = getattr(r.seq.radar(self.radar), _STREAM[self.products[0]])
            out.append(anchor.timestamps[r.radar_k])
        return np.concatenate(out) if out else np.zeros(0)

    def __getitem__(self, i: int) -> dict[str, Any]:
        r_i, k = self._find(i)
        run = self._runs[r_i]
        sensor = run.seq.radar(self.radar)
        anchor = getattr(sensor, _STREAM[self.products[0]])
        rk = int(run.radar_k[k])
        t = float(anchor.timestamps[rk])
        out: dict[str, Any] = {"run": run.seq.name, "radar_frame": rk,
                               "frame_id": int(anchor.frame_ids[rk]), "radar_time": t}
        if "heatmap" in self.products:
            out["heatmap"] = sensor.heatmaps[rk]
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
        return out

    # -- splits -----------------------------------------------------------------------------
    def subset(self, runs: Iterable[str]) -> SyncedSamples:
        """The samples of some runs only (same settings, no files re-indexed but these)."""
        return SyncedSamples([r.seq for r in self._runs if r.seq.name in set(runs)],
                             **self._options)  # type: ignore[arg-type]

    def split(self, fractions: Mapping[str, float] | None = None,
              seed: int = 0) -> dict[str, SyncedSamples]:
        """Views over disjoint sets of runs (see :func:`split_runs`); empty parts are left out."""
        parts = split_runs(self.runs, fractions, seed)
        return {name: self.subset(rs) for name, rs in parts.items() if rs}


def split_runs(runs: Iterable[str], fractions: Mapping[str, float] | None = None,
               seed: int = 0) -> dict[str, list[str]]:
    """Split run names into named parts, deterministically.

    The names are sorted, shuffled by a generator seeded with ``seed``, and cut into parts of
    ``round`` sizes (largest remainders first); every part with a positive fraction gets at
    least one run while there are runs enough. The result depends only on the set of names,
    the fractions and the seed.

    Parameters
    ----------
    runs
        Run names.
    fractions
        Part name -> share (normalised); default ``{"train": 0.8, "val": 0.1, "test": 0.1}``.
    seed
        Shuffle seed.

    Returns
    -------
    dict[str, list[str]]
        Part name -> sorted run names; every run in exactly one part.
    """
    fr = dict(fractions or {"train": 0.8, "val": 0.1, "test": 0.1})
    if not fr or any(v < 0 for v in fr.values()) or sum(fr.values()) <= 0:
        raise SettingsError(f"fractions must be non-negative with a positive sum, got {fr}")
    names = sorted(set(runs))
    order = np.random.default_rng(seed).permutation(len(names))
    shares = np.array(list(fr.values()), dtype=np.float64) / sum(fr.values())
    exact = shares * len(names)
    sizes = np.floor(exact).astype(int)
    for j in np.argsort(-(exact - sizes), kind="stable")[: len(names) - int(sizes.sum())]:
        sizes[j] += 1
    # Give an empty positive part one run from the largest part, while that part keeps one.
    for j in np.flatnonzero((sizes == 0) & (shares > 0)):
        big = int(np.argmax(sizes))
        if sizes[big] > 1:
            sizes[big] -= 1
            sizes[j] += 1
    out, start = {}, 0
    for name, n in zip(fr, sizes, strict=True):
        out[name] = sorted(names[i] for i in order[start:start + n])
        start += n
    return out


# -- batching ---------------------------------------------------------------------------------
_VARIABLE = ("points", "lidar")


def collate_numpy(batch: list[dict[str, Any]]) -> dict[str, Any]:
    """Batch samples: fixed-size arrays stacked, point clouds concatenated with an index.

    ``points`` ``(N_i, 5)`` of B samples become ``points`` ``(ΣN_i, 5)``, ``points_batch``
    int64 ``(ΣN_i,)`` (the sample each point belongs to) and ``points_counts`` int64 ``(B,)``;
    the same for ``lidar``. Scalars become arrays ``(B,)``; strings a list.
    """
    if not batch:
        raise ValueError("empty batch")
    out: dict[str, Any] = {}
    for key in batch[0]:
        vals = [s[key] for s in batch]
        if key in _VARIABLE:
            counts = np.array([v.shape[0] for v in vals], dtype=np.int64)
            out[key] = np.concatenate(vals, axis=0)
            out[f"{key}_batch"] = np.repeat(np.arange(len(vals), dtype=np.int64), counts)
            out[f"{key}_counts"] = counts
        elif isinstance(vals[0], str):
            out[key] = vals
        else:
            out[key] = np.stack([np.asarray(v) for v in vals])
    return out


def collate_torch(batch: list[dict[str, Any]]) -> dict[str, Any]:
    """:func:`collate_numpy` with every array as a ``torch.Tensor`` (for a ``DataLoader``)."""
    import torch

    out = collate_numpy([{k: (v.numpy() if hasattr(v, "numpy") and not isinstance(v, np.ndarray)
                              else v) for k, v in s.items()} for s in batch])
    return {k: (torch.from_numpy(np.ascontiguousarray(v)) if isinstance(v, np.ndarray) else v)
            for k, v in out.items()}


_TORCH_CLASS: Any = None


def torch_dataset(view: SyncedSamples) -> Any:
    """``view`` as a ``torch.utils.data.Dataset`` whose samples hold tensors.

    Arrays keep their dtypes (float32 data, float64 poses and times); use with
    ``DataLoader(ds, batch_size=..., collate_fn=collate_torch)``.

    Raises
    ------
    ColoradarError
        torch is not installed.
    """
    global _TORCH_CLASS
    try:
        import torch
        from torch.utils.data import Dataset as TorchDataset
    except ImportError:
        raise MissingDependencyError("torch_dataset needs PyTorch (pip install torch)") from None
    if _TORCH_CLASS is None:

        class TorchSyncedSamples(TorchDataset):
            """A :class:`SyncedSamples` view whose arrays are tensors."""

            def __init__(self, samples: SyncedSamples):
                self.samples = samples

            def __len__(self) -> int:
                return len(self.samples)

            def __getitem__(self, i: int) -> dict[str, Any]:
                return {k: (torch.from_numpy(np.ascontiguousarray(v)) if isinstance(v, np.ndarray)
                            else v) for k, v in self.samples[i].items()}

        _TORCH_CLASS = TorchSyncedSamples
    return _TORCH_CLASS(view)
