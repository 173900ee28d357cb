"""Batching samples: numpy, and PyTorch (optional) with a dataset class that spawned
``DataLoader`` workers can unpickle."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import MissingDependencyError, SettingsError

__all__ = ["VARIABLE_KEYS", "collate_numpy", "collate_torch", "torch_dataset"]

VARIABLE_KEYS = ("points", "lidar", "lidar_target")
"""Sample keys whose arrays differ in length between samples (point clouds)."""


def collate_numpy(batch: list[dict[str, Any]]) -> dict[str, Any]:
    """Batch samples: fixed-size arrays stacked, point clouds concatenated with an index.

    ``points`` ``(N_i, 5)`` of B samples become ``points`` ``(ΣN_i, 5)``, ``points_batch``
    int64 ``(ΣN_i,)`` (the sample each point belongs to) and ``points_counts`` int64 ``(B,)``;
    the same for ``lidar`` and ``lidar_target``. Scalars become arrays ``(B,)``; strings a list.
    """
    if not batch:
        raise SettingsError("empty batch")
    out: dict[str, Any] = {}
    for key in batch[0]:
        vals = [s[key] for s in batch]
        if key in VARIABLE_KEYS:
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
    try:
        import torch
    except ImportError:
        raise MissingDependencyError("collate_torch needs PyTorch (pip install torch)") from None
    out = collate_numpy([{k: (v.numpy() if hasattr(v, "numpy") and not isinstance(v, np.ndarray)
                              else v) for k, v in s.items()} for s in batch])
    return {k: (torch.from_numpy(np.ascontiguousarray(v)) if isinstance(v, np.ndarray) else v)
            for k, v in out.items()}


def torch_dataset(view: Any) -> Any:
    """``view`` (a :class:`~coloradar.learning.SyncedSamples`) as a ``torch.utils.data.Dataset``
    whose samples hold tensors.

    The class, :class:`coloradar.learning.torch_data.TorchSamples`, lives at module level, so
    ``DataLoader(..., num_workers=N, multiprocessing_context="spawn")`` can pickle it; each
    worker opens its own files. Arrays keep their dtypes (float32 data, float64 poses and
    times); use with ``DataLoader(ds, batch_size=..., collate_fn=collate_torch)``.

    Raises
    ------
    MissingDependencyError
        torch is not installed.
    """
    try:
        from .torch_data import TorchSamples
    except ImportError:
        raise MissingDependencyError("torch_dataset needs PyTorch (pip install torch)") from None
    return TorchSamples(view)
