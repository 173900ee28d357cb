"""An occupancy map written to a folder (what ``coloradar map --source`` and ``coloradar slam``
write), and read back.

| file | content |
|---|---|
| ``map.ply`` | the occupied voxels' centres, world frame: ``x y z probability hits misses`` |
| ``occupancy.npz`` | the whole map (:meth:`.voxels.OccupancyMap.save`): every voxel's log-odds and counts |
| ``grid.pgm``, ``grid.yaml`` | the 2-D grid of a height band, ROS ``map_server`` format (:mod:`.grid2d`) |
| ``poses.txt`` | TUM ``timestamp x y z qx qy qz qw``: ``world_T_base`` at every frame mapped |
| ``map.json`` | what was mapped with what: run, sensor, source, poses, settings, band, counts |
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..errors import OutputExistsError, WriteError
from ..formats.atomic import atomic_write_text, make_output_dir
from ..geometry import Trajectory, write_ply
from .grid2d import OccupancyGrid2D, write_map_server
from .voxels import OccupancyMap

__all__ = ["MAP_FILES", "default_band", "format_poses", "map_targets", "write_map_folder"]

MAP_FILES = ("map.ply", "occupancy.npz", "grid.pgm", "grid.yaml", "poses.txt", "map.json")
"""The files :func:`write_map_folder` writes."""

PLY_FIELDS = ("x", "y", "z", "probability", "hits", "misses")


def map_targets(folder: str | os.PathLike[str], overwrite: bool,
                extra: tuple[str, ...] = ()) -> dict[str, Path]:
    """The paths of :data:`MAP_FILES` (and ``extra``) in ``folder``, refusing a folder that is a
    file and files that exist unless ``overwrite`` (checked before any work)."""
    folder = Path(folder)
    for q in (folder, *folder.parents):
        if q.exists():
            if not q.is_dir():
                raise WriteError(f"{q}: expected an output folder, found a file")
            break
    targets = {n: folder / n for n in (*MAP_FILES, *extra)}
    existing = [n for n, p in targets.items() if p.exists()]
    if existing and not overwrite:
        raise OutputExistsError(f"{folder}: holds {', '.join(existing)} already; pass "
                                "overwrite=True (--overwrite) to replace them")
    return targets


def default_band(poses: Trajectory, below: float = 0.5, above: float = 0.5
                 ) -> tuple[float, float]:
    """``(z_min, z_max)`` [m]: the trajectory's median height − ``below`` to + ``above``
    (the band a ground robot's sensors sweep, floor and ceiling left out)."""
    z = float(np.median(np.asarray(poses.translations)[:, 2]))
    return z - below, z + above


def format_poses(poses: Trajectory, comment: str) -> str:
    """TUM text (``timestamp x y z qx qy qz qw``) with one ``#`` comment line."""
    q = poses.rotations.as_quat()
    rows = np.column_stack([poses.timestamps, poses.translations, q])
    body = "\n".join(f"{r[0]:.9f} " + " ".join(f"{v:.9g}" for v in r[1:]) for r in rows)
    return f"# {comment}\n# timestamp tx ty tz qx qy qz qw\n{body}\n"


def write_map_folder(targets: dict[str, Path], m: OccupancyMap, grid: OccupancyGrid2D,
                     poses: Trajectory, info: dict) -> list[Path]:
    """Write the map's files (module docstring) to ``targets`` (:func:`map_targets`), each
    atomically; ``info`` goes into ``map.json`` with the counts. Returns the paths written."""
    make_output_dir(targets["map.json"].parent)
    occ = m.occupied()
    write_ply(targets["map.ply"], occ, PLY_FIELDS, overwrite=True)
    m.save(targets["occupancy.npz"])
    write_map_server(grid, targets["grid.yaml"])
    atomic_write_text(targets["poses.txt"],
                      format_poses(poses, "world_T_base at every frame of the map"))
    x0, y0 = grid.origin
    full = {**info, "voxel_m": m.voxel, "voxels": len(m), "occupied_voxels": int(occ.shape[0]),
            "map_bytes": m.nbytes, "frames": m.frames,
            "grid": {"band_m": list(grid.band), "resolution_m": grid.resolution,
                     "origin_m": [x0, y0], "size_cells": list(grid.states.shape[::-1]),
                     **grid.counts()}}
    atomic_write_text(targets["map.json"], json.dumps(full, indent=2, default=float) + "\n")
    return [targets[n] for n in MAP_FILES]
