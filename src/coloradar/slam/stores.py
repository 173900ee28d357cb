"""Where SLAM keeps what grows with the run: on disk, so that memory stays flat in its length.

- :class:`Growing`: a numpy array that grows by doubling (a per-frame column costs its bytes,
  not a Python object per frame).
- :class:`FrameStore`: each frame's cloud and its static points, for the filter's
  point-by-point update and until the keyframes' submaps are built.
- :class:`SubmapStore`: every keyframe's submap (points, intensities, covariances, surface
  terms as float32, the descriptor), read back one at a time for loop verification and the
  map.

Both files are unlinked temporary files: nothing is left behind whatever happens to the
process, and the operating system's page cache, not the Python heap, holds what is read often.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import overload

import numpy as np

from ..formats.atomic import scratch_file
from .submaps import Submap

__all__ = ["Clouds", "FrameStore", "Growing", "SubmapStore"]


class Growing:
    """A 1-D (or ``(n, *shape)``) array of ``dtype`` appended to row by row."""

    def __init__(self, dtype: np.dtype | type, shape: tuple[int, ...] = (), capacity: int = 256
                 ) -> None:
        self._a = np.empty((capacity, *shape), dtype=dtype)
        self._n = 0

    def append(self, row) -> None:
        if self._n == self._a.shape[0]:
            grown = np.empty((2 * self._a.shape[0], *self._a.shape[1:]), dtype=self._a.dtype)
            grown[:self._n] = self._a
            self._a = grown
        self._a[self._n] = row
        self._n += 1

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, k):
        return self._a[:self._n][k]

    def array(self) -> np.ndarray:
        """A copy of the rows appended so far (exactly sized)."""
        return self._a[:self._n].copy()


class _TempFile:
    def __init__(self, prefix: str) -> None:
        self._f = scratch_file(prefix)
        self._offsets = Growing(np.int64)
        self._offsets.append(0)

    def _write(self, data: bytes) -> None:
        end = int(self._offsets[-1])
        self._f.seek(end)
        self._f.write(data)
        self._offsets.append(end + len(data))

    def _read(self, k: int) -> bytes:
        a, b = int(self._offsets[k]), int(self._offsets[k + 1])
        self._f.seek(a)
        return self._f.read(b - a)

    def __len__(self) -> int:
        return len(self._offsets) - 1

    def close(self) -> None:
        self._f.close()


class FrameStore(_TempFile):
    """Each frame's cloud, float32 ``(N, 5)`` ``x y z intensity range_rate``, and which of its
    points are static, by frame index.

    Memory holds 8 bytes per frame; the points live in an unlinked temporary file.
    """

    def __init__(self) -> None:
        super().__init__("coloradar_slam_frames_")

    def append(self, cloud: np.ndarray, static: np.ndarray) -> None:
        """Store the next frame's cloud ``(N, 5)`` and its bool ``(N,)`` static mask."""
        c = np.asarray(cloud, dtype=np.float32)
        c = c[:, :5] if c.ndim == 2 and c.shape[1] >= 5 else np.zeros((0, 5), np.float32)
        rows = np.column_stack([c, np.asarray(static, dtype=np.float32).reshape(-1)[:len(c)]])
        self._write(np.ascontiguousarray(rows, dtype=np.float32).tobytes())

    def _rows(self, k: int) -> np.ndarray:
        return np.frombuffer(self._read(k), dtype=np.float32).reshape(-1, 6)

    def read(self, k: int) -> np.ndarray:
        """float32 ``(K, 4)`` ``x y z intensity`` of frame ``k``'s static points."""
        rows = self._rows(k)
        return rows[rows[:, 5] > 0, :4]

    def cloud(self, k: int) -> np.ndarray:
        """float32 ``(N, 5)``: frame ``k``'s cloud."""
        return self._rows(k)[:, :5]

    def clouds(self) -> Clouds:
        """The clouds as a read-only sequence (each read from disk when asked for)."""
        return Clouds(self)


class Clouds(Sequence[np.ndarray]):
    """A :class:`FrameStore`'s clouds as a sequence, read one at a time (what the filter's
    point-by-point update takes, without every cloud in memory)."""

    def __init__(self, store: FrameStore) -> None:
        self._store = store

    def __len__(self) -> int:
        return len(self._store)

    @overload
    def __getitem__(self, k: int) -> np.ndarray: ...

    @overload
    def __getitem__(self, k: slice) -> list[np.ndarray]: ...

    def __getitem__(self, k: int | slice) -> np.ndarray | list[np.ndarray]:
        if isinstance(k, slice):
            return [self._store.cloud(i) for i in range(*k.indices(len(self)))]
        if not -len(self) <= k < len(self):
            raise IndexError(k)
        return self._store.cloud(k % len(self))

    def __iter__(self) -> Iterator[np.ndarray]:
        return (self._store.cloud(i) for i in range(len(self)))


_UPPER = np.triu_indices(3)


def _pack_sym(c: np.ndarray) -> np.ndarray:
    return c[:, _UPPER[0], _UPPER[1]].astype(np.float32)


def _unpack_sym(p: np.ndarray) -> np.ndarray:
    out = np.empty((p.shape[0], 3, 3))
    out[:, _UPPER[0], _UPPER[1]] = p
    out[:, _UPPER[1], _UPPER[0]] = p
    return out


class SubmapStore(_TempFile):
    """Every keyframe's :class:`~coloradar.slam.submaps.Submap`, in an unlinked temporary file.

    A submap of ``N`` points takes ``64·N`` bytes there (float32: points, intensity, the upper
    triangles of the covariance and surface terms) and its descriptor; memory holds 8 bytes
    per keyframe for the offsets and 4 for the frame. Read back as float64.
    """

    def __init__(self, descriptor_shape: tuple[int, int]) -> None:
        super().__init__("coloradar_slam_submaps_")
        self._shape = descriptor_shape
        self._frames = Growing(np.int64)
        self._sizes = Growing(np.int64)

    def append(self, s: Submap) -> None:
        """Store the next keyframe's submap."""
        n = s.points.shape[0]
        surface = s.surface if s.surface is not None else np.zeros((n, 3, 3))
        desc = np.ascontiguousarray(s.descriptor, dtype=np.float32).reshape(self._shape)
        rows = np.column_stack([s.points.astype(np.float32), s.intensity.astype(np.float32),
                                _pack_sym(s.covariances), _pack_sym(surface)])
        self._write(desc.tobytes() + np.ascontiguousarray(rows, dtype=np.float32).tobytes())
        self._frames.append(s.frame)
        self._sizes.append(n)

    def sizes(self) -> np.ndarray:
        """int64 ``(K,)``: the points of each submap."""
        return self._sizes.array()

    def descriptor(self, k: int) -> np.ndarray:
        """float32 ``(rings, sectors)`` of submap ``k`` (only that is read)."""
        a = int(self._offsets[k])
        self._f.seek(a)
        nbytes = 4 * self._shape[0] * self._shape[1]
        return np.frombuffer(self._f.read(nbytes), dtype=np.float32).reshape(self._shape)

    def __getitem__(self, k: int) -> Submap:
        raw = np.frombuffer(self._read(int(k)), dtype=np.float32)
        nd = self._shape[0] * self._shape[1]
        rows = raw[nd:].reshape(-1, 16).astype(np.float64)
        return Submap(int(self._frames[k]), rows[:, :3], rows[:, 3].astype(np.float32),
                      _unpack_sym(rows[:, 4:10]), raw[:nd].reshape(self._shape),
                      _unpack_sym(rows[:, 10:16]))
