"""A dataset root: ``calib/`` (or ``calib.zip``) and run folders and/or run zips.

ColoRadar keeps its runs in the root itself; ColoRadar+ in ``<root>/kitti/``
(:mod:`coloradar.formats.layout`).
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterator
from pathlib import Path

from ..calib import Calibration, load_calibration
from ..errors import CalibrationWarning, MissingDataError
from ..formats.layout import COLORADAR, COLORADAR_PLUS, RunLayout, get_layout
from ..formats.source import FolderSource, open_source
from .sequence import Sequence, is_run

__all__ = ["Dataset", "open_dataset"]


class Dataset:
    """The runs of a dataset root, each opened on demand.

    Attributes
    ----------
    root
        The dataset folder.
    calib
        The rig calibration shared by all runs.
    """

    def __init__(self, root: Path, calib: Calibration, runs: dict[str, Path],
                 layout: str | RunLayout = COLORADAR):
        self.root = root
        self.calib = calib
        self._runs = runs
        self.layout = get_layout(layout)

    @property
    def sequences(self) -> list[str]:
        """Names of the runs, sorted."""
        return sorted(self._runs)

    def path(self, name: str) -> Path:
        """The folder or zip of run ``name``."""
        return self._runs[self._check(name)]

    def _check(self, name: str) -> str:
        if name not in self._runs:
            raise MissingDataError(f"{self.root}: no run named {name!r} (runs: "
                                   f"{', '.join(self.sequences) or 'none'})")
        return name

    def __getitem__(self, name: str) -> Sequence:
        p = self._runs[self._check(name)]
        return Sequence(open_source(p, markers=self.layout.sensor_folders), self.calib, name,
                        self.layout)

    def __len__(self) -> int:
        return len(self._runs)

    def __iter__(self) -> Iterator[Sequence]:
        for name in self.sequences:
            yield self[name]

    def __contains__(self, name: object) -> bool:
        return name in self._runs

    def __repr__(self) -> str:
        return f"<Dataset {self.root}: {len(self)} runs>"


def is_run_folder(p: Path, layout: RunLayout | None = None) -> bool:
    """True when folder ``p`` is a run (see :func:`~coloradar.dataset.sequence.is_run`)."""
    return p.is_dir() and is_run(FolderSource(p), layout)


def find_runs(root: Path, layout: str | RunLayout = COLORADAR) -> dict[str, Path]:
    """Run folders and run zips in ``root`` (in ``root/kitti`` for ColoRadar+); a folder wins
    over a zip of the same name."""
    lay = get_layout(layout)
    runs: dict[str, Path] = {}
    folder = root / lay.runs_folder if lay.runs_folder else root
    if not folder.is_dir():
        return runs
    for p in sorted(folder.iterdir()):
        if p.name.startswith(".") or p.stem == "calib":
            continue
        if is_run_folder(p, lay):
            runs[p.name] = p
        elif p.suffix == ".zip" and p.is_file() and p.stem not in runs:
            runs[p.stem] = p
    return runs


def detect_dataset_layout(root: Path) -> RunLayout:
    """ColoRadar+ when ``root`` holds a ``kitti/`` folder of runs (and no ColoRadar run),
    ColoRadar otherwise."""
    plus = COLORADAR_PLUS.runs_folder
    if (root / plus).is_dir() and not find_runs(root, COLORADAR):
        return COLORADAR_PLUS
    return COLORADAR


def open_dataset(root: str | os.PathLike[str],
                 calib: Calibration | str | os.PathLike[str] | None = None,
                 layout: str | RunLayout | None = None) -> Dataset:
    """Open a dataset root holding ``calib/`` (or ``calib.zip``) and runs (folders or zips).

    Parameters
    ----------
    root
        The dataset folder (for ColoRadar+, the folder holding ``kitti/`` and ``calib/``).
    calib
        Overrides the root's calibration: a :class:`Calibration` or a calib path.
    layout
        ``"coloradar"``, ``"coloradar_plus"``, or None to recognise it
        (:func:`detect_dataset_layout`).

    Returns
    -------
    Dataset
    """
    r = Path(root)
    if not r.is_dir():
        raise MissingDataError(f"{r}: dataset root folder not found")
    lay = get_layout(layout) if layout is not None else detect_dataset_layout(r)
    if isinstance(calib, Calibration):
        cal = calib
    elif calib is not None:
        cal = load_calibration(calib, layout=lay)
    elif (r / "calib").exists() or (r / "calib.zip").exists():
        cal = load_calibration(r, layout=lay)
    else:
        warnings.warn(f"{r}: no calib/ or calib.zip; using the built-in sensor presets",
                      CalibrationWarning, stacklevel=2)
        cal = load_calibration(None)
    return Dataset(r, cal, find_runs(r, lay), lay)
