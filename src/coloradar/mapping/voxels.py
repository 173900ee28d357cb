"""The sparse, voxel-hashed log-odds occupancy map (:class:`OccupancyMap`).

Every voxel the map has evidence about is one row of a few flat arrays, found by an int64 key
(21 bits per axis: ±2^20 voxels, ±157 km at 0.15 m). The keys are kept sorted; a frame's
evidence is merged with :func:`numpy.searchsorted` (voxels the map already has) and new voxels
wait in a small sorted side table that is merged into the main one when it grows past a
fraction of it, so that adding a voxel costs O(log M) amortised and memory is that of the
voxels seen, not of the frames: a long run over a bounded area costs what the area costs.

The log-odds update and its clamping are those of OctoMap (Hornung et al., "OctoMap: an
efficient probabilistic 3D mapping framework based on octrees", Autonomous Robots 2013):
``L ← clip(L + l, L_min, L_max)``, with ``L = log(p / (1 − p))`` and the clamping bounds keeping
the map able to change its mind about a voxel (a door that opens).
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..errors import FormatError, SettingsError
from ..formats.atomic import atomic_output

__all__ = [
    "FREE",
    "OCCUPIED",
    "UNKNOWN",
    "OccupancyMap",
    "OccupancySettings",
    "keys_to_indices",
    "local_unique_keys",
    "logit",
    "voxel_keys",
]

OCCUPIED, FREE, UNKNOWN = 1, 0, -1
"""Values of :meth:`OccupancyMap.state`."""

_BITS = 21
_OFFSET = 1 << (_BITS - 1)
_MASK = (1 << _BITS) - 1


def logit(p: float) -> float:
    """``log(p / (1 − p))`` of a probability in (0, 1)."""
    if not 0.0 < p < 1.0:
        raise SettingsError(f"a probability in (0, 1) was expected, got {p}")
    return math.log(p / (1.0 - p))


@dataclass(frozen=True)
class OccupancySettings:
    """The occupancy map's grid and its log-odds model (probabilities, unitless).

    Attributes
    ----------
    voxel
        Voxel edge [m]; voxel ``k`` covers ``[k·voxel, (k+1)·voxel)`` on each axis (anchored
        at the world origin, so two maps of one voxel size share their grid).
    p_hit
        Occupancy evidence of one frame whose return falls wholly in a voxel: a voxel's
        log-odds rise by at most ``logit(p_hit)`` per frame (a return spread over several
        voxels by its uncertainty gives each a share: :mod:`.sensor_model`).
    p_miss
        Evidence of a frame whose ray passes through a voxel (free space).
    p_min, p_max
        Clamping bounds of a voxel's probability.
    p_occupied, p_free
        A voxel is occupied above ``p_occupied`` (and hit by ``min_hits`` frames), free below
        ``p_free``, and unknown otherwise or when no evidence reached it.
    min_hits
        Frames whose returns must have reached a voxel before it can be occupied: with 2 or
        more, one frame alone never makes a voxel occupied (a ghost of one frame leaves none).
    """

    voxel: float = 0.15
    p_hit: float = 0.75
    p_miss: float = 0.45
    p_min: float = 0.12
    p_max: float = 0.97
    p_occupied: float = 0.52
    p_free: float = 0.3
    min_hits: int = 2

    def __post_init__(self) -> None:
        if not (math.isfinite(self.voxel) and self.voxel > 0):
            raise SettingsError(f"OccupancySettings.voxel must be a positive size [m], got "
                                f"{self.voxel}")
        if self.min_hits < 1:
            raise SettingsError(f"OccupancySettings.min_hits must be >= 1, got {self.min_hits}")
        for name in ("p_hit", "p_miss", "p_min", "p_max", "p_occupied", "p_free"):
            logit(getattr(self, name))
        if not self.p_miss < 0.5 < self.p_hit:
            raise SettingsError("OccupancySettings: expected p_miss < 0.5 < p_hit, got "
                                f"{self.p_miss} and {self.p_hit}")
        if not self.p_min <= self.p_free < self.p_occupied <= self.p_max:
            raise SettingsError("OccupancySettings: expected p_min <= p_free < p_occupied <= "
                                f"p_max, got {self.p_min}, {self.p_free}, {self.p_occupied}, "
                                f"{self.p_max}")

    @property
    def l_hit(self) -> float:
        return logit(self.p_hit)

    @property
    def l_miss(self) -> float:
        return logit(self.p_miss)


def voxel_keys(xyz: np.ndarray, voxel: float) -> np.ndarray:
    """int64 ``(N,)``: the key of the voxel holding each point of float ``(N, 3)`` [m]; keys
    sort as the voxel indices ``(i, j, k)`` do, lexicographically."""
    v = np.floor(np.asarray(xyz, dtype=np.float64) / voxel).astype(np.int64) + _OFFSET
    if v.size and (v.min() < 0 or v.max() > _MASK):
        raise SettingsError(f"a point lies more than {_OFFSET:,} voxels ({_OFFSET * voxel:g} m) "
                            "from the origin; use a larger voxel")
    return (v[:, 0] << (2 * _BITS)) | (v[:, 1] << _BITS) | v[:, 2]


def keys_to_indices(keys: np.ndarray) -> np.ndarray:
    """int64 ``(N, 3)``: voxel indices ``(i, j, k)`` of keys (centre ``(ijk + ½)·voxel``)."""
    k = np.asarray(keys, dtype=np.int64)
    return np.stack([(k >> (2 * _BITS)) & _MASK, (k >> _BITS) & _MASK, k & _MASK],
                    axis=1) - _OFFSET


def local_unique_keys(xyz: np.ndarray, voxel: float) -> np.ndarray:
    """Distinct voxel keys (sorted) of float ``(N, 3)`` points [m] that lie close together
    (one frame's), by marking a dense boolean box rather than sorting (O(N) for the many free
    cells of a frame); falls back to :func:`numpy.unique` for a box too large."""
    if len(xyz) == 0:
        return np.zeros(0, np.int64)
    idx = np.floor(xyz / np.float32(voxel)).astype(np.int64)
    lo = idx.min(axis=0)
    dims = idx.max(axis=0) - lo + 1
    if np.prod(dims) > 1 << 24:
        return np.unique(voxel_keys((idx + 0.5) * voxel, voxel))
    lin = np.ravel_multi_index((idx - lo).T, tuple(int(d) for d in dims))
    mark = np.zeros(int(np.prod(dims)), bool)
    mark[lin] = True
    cells = np.stack(np.unravel_index(np.flatnonzero(mark), tuple(int(d) for d in dims)),
                     axis=1) + lo
    return voxel_keys((cells + 0.5) * voxel, voxel)


class _Table:
    """Sorted keys and their per-voxel values (log-odds, hits, misses)."""

    def __init__(self, keys: np.ndarray | None = None, logodds: np.ndarray | None = None,
                 hits: np.ndarray | None = None, misses: np.ndarray | None = None):
        self.keys = np.zeros(0, np.int64) if keys is None else keys
        self.logodds = np.zeros(0, np.float32) if logodds is None else logodds
        self.hits = np.zeros(0, np.uint32) if hits is None else hits
        self.misses = np.zeros(0, np.uint32) if misses is None else misses

    def find(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(found, rows)``: which ``keys`` the table holds, and their rows."""
        if self.keys.size == 0:
            return np.zeros(keys.size, bool), np.zeros(keys.size, np.int64)
        rows = np.searchsorted(self.keys, keys)
        rows = np.minimum(rows, self.keys.size - 1)
        return self.keys[rows] == keys, rows

    @staticmethod
    def merged(a: _Table, b: _Table) -> _Table:
        """One sorted table of two whose keys are disjoint."""
        keys = np.concatenate([a.keys, b.keys])
        order = np.argsort(keys, kind="stable")
        return _Table(keys[order], np.concatenate([a.logodds, b.logodds])[order],
                      np.concatenate([a.hits, b.hits])[order],
                      np.concatenate([a.misses, b.misses])[order])


class OccupancyMap:
    """A sparse 3-D log-odds occupancy map (module docstring).

    Parameters
    ----------
    settings
        :class:`OccupancySettings` (default values when None).

    Notes
    -----
    Evidence is added one frame at a time with :meth:`integrate` (what the inverse sensor
    models of :mod:`.sensor_model` and :mod:`.heatmap_model` compute); a frame's evidence about
    one voxel is one value, so that a frame counts once per voxel however many of its returns
    or rays fell in it.
    """

    def __init__(self, settings: OccupancySettings | None = None):
        self.settings = settings or OccupancySettings()
        self.frames = 0
        self._main = _Table()
        self._recent = _Table()
        s = self.settings
        self._lo, self._hi = np.float32(logit(s.p_min)), np.float32(logit(s.p_max))

    @property
    def voxel(self) -> float:
        """Voxel edge [m]."""
        return self.settings.voxel

    def __len__(self) -> int:
        return int(self._main.keys.size + self._recent.keys.size)

    @property
    def nbytes(self) -> int:
        """Bytes held by the map's arrays (memory grows with the voxels seen, not the run)."""
        return sum(a.nbytes for t in (self._main, self._recent)
                   for a in (t.keys, t.logodds, t.hits, t.misses))

    def integrate(self, keys: np.ndarray, delta: np.ndarray) -> None:
        """Add one frame's evidence.

        Parameters
        ----------
        keys
            int64 ``(K,)``: distinct voxel keys (:func:`voxel_keys`).
        delta
            float ``(K,)``: log-odds to add to each; > 0 counts as a hit of the voxel, < 0 as
            a miss (free space). Sums are clamped to ``[logit(p_min), logit(p_max)]``.
        """
        keys = np.asarray(keys, dtype=np.int64)
        d = np.asarray(delta, dtype=np.float32)
        if keys.shape != d.shape or keys.ndim != 1:
            raise SettingsError(f"keys and delta must be (K,) arrays of one length, got "
                                f"{keys.shape} and {d.shape}")
        self.frames += 1
        if keys.size == 0:
            return
        hit = (d > 0).astype(np.uint32)
        miss = (d < 0).astype(np.uint32)
        pending = np.ones(keys.size, bool)
        for table in (self._main, self._recent):
            found, rows = table.find(keys)
            found &= pending
            r = rows[found]
            table.logodds[r] = np.clip(table.logodds[r] + d[found], self._lo, self._hi)
            table.hits[r] += hit[found]
            table.misses[r] += miss[found]
            pending &= ~found
        if pending.any():
            new = _Table(keys[pending], np.clip(d[pending], self._lo, self._hi),
                         hit[pending], miss[pending])
            self._recent = _Table.merged(self._recent, new)
            if self._recent.keys.size > max(1 << 15, self._main.keys.size // 4):
                self._main = _Table.merged(self._main, self._recent)
                self._recent = _Table()

    def _all(self) -> _Table:
        if self._recent.keys.size:
            self._main = _Table.merged(self._main, self._recent)
            self._recent = _Table()
        return self._main

    def keys(self) -> np.ndarray:
        """int64 ``(M,)``: every voxel with evidence, sorted."""
        return self._all().keys.copy()

    def indices(self) -> np.ndarray:
        """int64 ``(M, 3)``: voxel indices of :meth:`keys`."""
        return keys_to_indices(self._all().keys)

    def centers(self) -> np.ndarray:
        """float64 ``(M, 3)``: voxel centres [m], world frame, order of :meth:`keys`."""
        return (self.indices() + 0.5) * self.voxel

    def logodds(self) -> np.ndarray:
        """float32 ``(M,)``: each voxel's log-odds (order of :meth:`keys`)."""
        return self._all().logodds.copy()

    def probability(self) -> np.ndarray:
        """float32 ``(M,)``: each voxel's occupancy probability (order of :meth:`keys`)."""
        return (1.0 / (1.0 + np.exp(-self._all().logodds))).astype(np.float32)

    def counts(self) -> tuple[np.ndarray, np.ndarray]:
        """uint32 ``(M,)`` twice: frames that hit each voxel and frames whose rays passed
        through it (order of :meth:`keys`)."""
        t = self._all()
        return t.hits.copy(), t.misses.copy()

    def states(self) -> np.ndarray:
        """int8 ``(M,)``: :data:`OCCUPIED`, :data:`FREE` or :data:`UNKNOWN` per voxel of
        :meth:`keys` (unknown: evidence between the two thresholds)."""
        t = self._all()
        lo = t.logodds
        s = self.settings
        out = np.full(lo.shape, UNKNOWN, np.int8)
        out[(lo > logit(s.p_occupied)) & (t.hits >= s.min_hits)] = OCCUPIED
        out[lo < logit(s.p_free)] = FREE
        return out

    def state(self, points: np.ndarray) -> np.ndarray:
        """int8 ``(N,)``: occupied / free / unknown at float ``(N, 3)`` points [m] (a voxel
        without evidence is unknown)."""
        t = self._all()
        out = np.full(len(points), UNKNOWN, np.int8)
        if t.keys.size == 0 or len(points) == 0:
            return out
        found, rows = t.find(voxel_keys(np.asarray(points)[:, :3], self.voxel))
        out[found] = self.states()[rows[found]]
        return out

    def occupied(self) -> np.ndarray:
        """float32 ``(N, 6)``: ``x y z probability hits misses`` of the occupied voxels
        (centres, world frame): what ``map.ply`` holds."""
        occ = self.states() == OCCUPIED
        h, m = self.counts()
        return np.column_stack([self.centers()[occ], self.probability()[occ], h[occ],
                                m[occ]]).astype(np.float32)

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the whole map (keys, log-odds, counts, settings) to an ``.npz`` file,
        atomically; :meth:`load` reads it."""
        t = self._all()
        with atomic_output(path, ".npz") as tmp:
            with open(tmp, "wb") as fh:
                np.savez_compressed(fh, keys=t.keys, logodds=t.logodds, hits=t.hits,
                                    misses=t.misses, frames=np.int64(self.frames),
                                    settings=np.array(list(asdict(self.settings).values())))
        return Path(path)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> OccupancyMap:
        """A map written by :meth:`save`; a :class:`~coloradar.FormatError` naming the file
        for anything else."""
        try:
            with np.load(path, allow_pickle=False) as z:
                names = list(OccupancySettings.__dataclass_fields__)
                vals = dict(zip(names, [float(v) for v in z["settings"]], strict=True))
                vals["min_hits"] = int(vals["min_hits"])
                m = cls(OccupancySettings(**vals))  # type: ignore[arg-type]
                m._main = _Table(z["keys"].astype(np.int64), z["logodds"].astype(np.float32),
                                 z["hits"].astype(np.uint32), z["misses"].astype(np.uint32))
                m.frames = int(z["frames"])
        except (OSError, KeyError, ValueError, TypeError) as exc:
            raise FormatError(f"{path}: expected an occupancy map written by coloradar "
                              f"(keys, logodds, hits, misses, frames, settings): {exc}") from None
        t = m._main
        if not (t.keys.ndim == 1 and t.keys.shape == t.logodds.shape == t.hits.shape
                == t.misses.shape) or np.any(np.diff(t.keys) <= 0):
            raise FormatError(f"{path}: expected an occupancy map's sorted keys and one value "
                              "of each kind per key")
        return m
