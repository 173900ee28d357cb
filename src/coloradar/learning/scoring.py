"""Scoring a folder of predicted point clouds against a run's lidar targets (``coloradar score``).

Predictions are files named by radar frame: the last integer in a file's stem is the number
in the radar frame's file name (``frame_id``: ``12.npy``, ``pred_000012.pcd`` and
``heatmap_12.bin`` are all frame 12), holding points in that radar's frame at that frame's time:

* ``.npy``: float ``(N, ≥3)``, x y z first;
* ``.pcd`` / ``.ply``: fields x y z first (:func:`coloradar.geometry.read_point_file`);
* ``.bin``: float32 rows, x y z first: coloradar's own point clouds by their kind
  (``radar_pointcloud_<i>.bin``, what ``coloradar process`` writes: 5 values a row;
  ``lidar_pointcloud_<i>.bin``: 4), any other name ``bin_columns`` values a row (KITTI-style,
  3 by default). Every file's size is checked against its row length before any is scored.

The targets are the samples' ``lidar_target`` of a run folder (the run's lidar map is fused
first) or of an exported ``.h5`` file that holds them.
"""

from __future__ import annotations

import json
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FormatError, MissingDataError, ReadError, SettingsError
from ..formats.atomic import atomic_write_text, new_output_path
from ..geometry import read_point_file
from .metrics import CloudScores, mean_scores, score_clouds
from .samples import SyncedSamples
from .targets import TargetSettings
from .views import BevGrid, BevProjector

__all__ = ["PREDICTION_SUFFIXES", "ScoreReport", "format_score_report", "read_prediction",
           "score_folder", "write_score_report"]

PREDICTION_SUFFIXES = (".npy", ".pcd", ".ply", ".bin")
# Columns of the .bin files whose kind the name says (coloradar.formats.binary), and names of
# .bin files that are not point clouds at all.
_BIN_KINDS = {"radar_pointcloud": 5, "lidar_pointcloud": 4}
# (folder the dataset keeps them in, what they are): a frame_12.bin of the user's own elsewhere is
# a prediction like any other.
_NOT_POINTS = {"heatmap": ("heatmaps", "a heatmap"), "frame": ("adc_samples", "a raw ADC frame")}
_TRAILING_INT = re.compile(r"(\d+)(?!.*\d)")


def bin_columns_of(path: str | os.PathLike[str], bin_columns: int | None = None) -> int:
    """Float32 values per row of a ``.bin`` prediction file: 5 for ``radar_pointcloud_<i>.bin``,
    4 for ``lidar_pointcloud_<i>.bin`` (the dataset's kinds), else ``bin_columns`` (None: 3).

    Raises
    ------
    FormatError
        The name is that of a coloradar file that is not a point cloud (a heatmap, an ADC
        frame).
    SettingsError
        ``bin_columns`` contradicts the kind the name says.
    """
    p = Path(path)
    prefix = _TRAILING_INT.sub("", p.stem).rstrip("_")
    if prefix in _NOT_POINTS and _NOT_POINTS[prefix][0] in p.resolve().parts:
        raise FormatError(f"{p}: {_NOT_POINTS[prefix][1]} (by its name and folder), not a point "
                          "cloud")
    kind = _BIN_KINDS.get(prefix)
    if kind is not None and bin_columns is not None and bin_columns != kind:
        raise SettingsError(f"{p}: a {prefix.replace('_', ' ')} file has {kind} values a row, "
                            f"not {bin_columns} (--bin-columns)")
    return kind or bin_columns or 3


def _check_bin_size(p: Path, columns: int) -> None:
    size = p.stat().st_size
    if size % (4 * columns):
        raise FormatError(f"{p}: {size:,} bytes is not a whole number of rows of {columns} "
                          f"float32 values ({4 * columns} bytes); expected x y z first"
                          + ("" if p.stem.startswith(tuple(_BIN_KINDS)) else
                             " (pass the right --bin-columns)"))


def read_prediction(path: str | os.PathLike[str], bin_columns: int | None = None) -> np.ndarray:
    """Points of one prediction file, float64 ``(N, 3)`` (see the module docstring)."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".npy":
        try:
            a = np.load(p, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise FormatError(f"{p}: not a numpy array file ({exc})") from None
    elif suffix in (".pcd", ".ply"):
        a = read_point_file(p)[0]
    elif suffix == ".bin":
        columns = bin_columns_of(p, bin_columns)
        _check_bin_size(p, columns)
        a = np.fromfile(p, dtype="<f4").reshape(-1, columns)
    else:
        raise FormatError(f"{p}: unknown prediction file type; expected one of "
                          f"{', '.join(PREDICTION_SUFFIXES)}")
    a = np.asarray(a)
    if a.ndim != 2 or a.shape[1] < 3:
        raise FormatError(f"{p}: expected points of shape (N, >=3), got {a.shape}")
    return a[:, :3].astype(np.float64)


@dataclass
class ScoreReport:
    """Scores of predictions against targets.

    Attributes
    ----------
    run
        The run scored.
    threshold
        F-score distance [m].
    grid
        BEV grid of the occupancy scores.
    frames
        ``frame_id`` -> :class:`CloudScores`, in frame order.
    missing
        ``frame_id`` of samples with no prediction file (not scored).
    unmatched
        Prediction files whose frame is not a sample of the run.
    mean
        Mean of every score over the scored frames (``nan`` skipped).
    """

    run: str
    threshold: float
    grid: BevGrid
    frames: dict[int, CloudScores] = field(default_factory=dict)
    missing: list[int] = field(default_factory=list)
    unmatched: list[str] = field(default_factory=list)
    mean: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"run": self.run, "threshold": self.threshold, "grid": self.grid.to_dict(),
                "mean": self.mean, "missing": self.missing, "unmatched": self.unmatched,
                "frames": {str(k): v.to_dict() for k, v in self.frames.items()}}


def _predictions(folder: Path) -> dict[int, Path]:
    if not folder.is_dir():
        raise ReadError(f"{folder}: not a folder of predicted clouds")
    out: dict[int, Path] = {}
    for p in sorted(folder.iterdir()):
        if p.suffix.lower() not in PREDICTION_SUFFIXES or not p.is_file():
            continue
        m = _TRAILING_INT.search(p.stem)
        if m is None:
            continue
        k = int(m.group(1))
        if k in out:
            raise SettingsError(f"{folder}: two predictions for frame {k}: {out[k].name} and {p.name}")
        out[k] = p
    if not out:
        raise MissingDataError(f"{folder}: no prediction files (*{', *'.join(PREDICTION_SUFFIXES)} "
                               "named by radar frame number)")
    return out


def score_folder(pred_dir: str | os.PathLike[str], source: Any, *, radar: str = "cascade",
                 threshold: float = 0.2, grid: BevGrid | None = None, cell: float = 0.1,
                 bin_columns: int | None = None,
                 target_settings: TargetSettings | None = None, calib: Any = None,
                 progress: Any = None) -> ScoreReport:
    """Score every prediction file of ``pred_dir`` against the lidar target of its frame.

    Parameters
    ----------
    pred_dir
        Folder of prediction files (module docstring).
    source
        A run (folder, zip, :class:`~coloradar.Sequence`) or an exported ``.h5`` with targets.
    radar
        The radar whose frames are predicted (an exported file says it itself).
    threshold
        F-score distance [m].
    grid, cell
        BEV grid of the occupancy scores (default: :meth:`BevGrid.for_radar` with ``cell``
        metres); only cells inside the radar's field of view are scored.
    bin_columns
        Values per row of ``.bin`` files whose name does not say their kind (None: 3); every
        ``.bin`` file's size is checked before anything is scored.
    target_settings
        How a run folder's targets are made.
    progress
        ``progress(done, total)`` after each frame.
    """
    preds = _predictions(Path(pred_dir))
    for p in preds.values():  # a file that cannot be read right fails before any score
        if p.suffix.lower() == ".bin":
            _check_bin_size(p, bin_columns_of(p, bin_columns))
    is_file = isinstance(source, (str, os.PathLike)) and Path(source).suffix.lower() in (".h5", ".hdf5")
    view = SyncedSamples(source, radar=None if is_file else radar,
                         products=None if is_file else ("heatmap",), lidar=False, targets=True,
                         target_settings=target_settings, calib=calib)
    if len(view.runs) != 1:
        raise SettingsError(f"score one run at a time ({len(view.runs)} given)")
    cfg = view.heatmap_config
    assert cfg is not None
    g = grid or BevGrid.for_radar(cfg, cell=cell)
    valid = BevProjector(cfg, g).valid
    report = ScoreReport(view.runs[0], float(threshold), g)
    # frame_id of every sample without reading frames: the anchor stream's file numbers.
    ids = _frame_ids(view)
    wanted = [(i, fid) for i, fid in enumerate(ids) if fid in preds]
    report.missing = [fid for fid in ids if fid not in preds]
    known = set(ids)
    report.unmatched = [p.name for k, p in preds.items() if k not in known]
    if not wanted:
        raise MissingDataError(f"{pred_dir}: no prediction file names a frame of "
                               f"{view.runs[0]} (frames {ids[0]}..{ids[-1]})")
    for n, (i, fid) in enumerate(wanted):
        target = view[i]["lidar_target"]
        report.frames[fid] = score_clouds(read_prediction(preds[fid], bin_columns), target,
                                          threshold, g, valid)
        if progress is not None:
            progress(n + 1, len(wanted))
    report.mean = mean_scores(list(report.frames.values()))
    return report


def _frame_ids(view: SyncedSamples) -> list[int]:
    run = view._runs[0]
    if hasattr(run, "seq"):
        stream = getattr(run.seq.radar(view.radar), run.anchor)
        return [int(x) for x in np.asarray(stream.frame_ids)[run.radar_k]]
    return [int(x) for x in run.frame_ids]


def format_score_report(r: ScoreReport) -> str:
    """The text ``coloradar score`` prints."""
    m = r.mean

    def f(key: str, unit: str = "", digits: int = 3) -> str:
        v = m.get(key, math.nan)
        return f"{v:.{digits}f}{unit}" if math.isfinite(v) else str(v)

    lines = [f"run {r.run}: {len(r.frames)} frames scored, {len(r.missing)} without a prediction, "
             f"{len(r.unmatched)} prediction files for no frame of the run",
             f"  Chamfer distance          {f('chamfer', ' m')}",
             f"  modified Hausdorff        {f('modified_hausdorff', ' m')}",
             f"  F-score @ {r.threshold:g} m        {f('f_score')}  (precision {f('precision')}, "
             f"recall {f('recall')})",
             f"  BEV occupancy ({r.grid.cell:g} m)   IoU {f('bev_iou')}  precision "
             f"{f('bev_precision')}  recall {f('bev_recall')}",
             f"  points per frame          predicted {f('num_pred', digits=0)}, "
             f"target {f('num_target', digits=0)}"]
    return "\n".join(lines) + "\n"


def write_score_report(r: ScoreReport, path: str | os.PathLike[str], overwrite: bool = False) -> Path:
    """Write the report as JSON (per-frame scores and the means), atomically."""
    p = new_output_path(path, overwrite)
    if p.suffix.lower() != ".json":
        raise SettingsError(f"{p}: the score report is JSON; name it *.json")

    def clean(x: Any) -> Any:
        if isinstance(x, float) and not math.isfinite(x):
            return None if math.isnan(x) else ("inf" if x > 0 else "-inf")
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, list):
            return [clean(v) for v in x]
        return x

    atomic_write_text(p, json.dumps(clean(r.to_dict()), indent=1) + "\n")
    return p
