"""The PyTorch dataset class (importing this module imports torch; use
:func:`coloradar.learning.torch_dataset`, which says clearly when torch is missing)."""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch.utils.data import Dataset

__all__ = ["TorchSamples"]


class TorchSamples(Dataset):
    """A :class:`~coloradar.learning.SyncedSamples` view whose arrays are tensors.

    Defined at module level so that spawned ``DataLoader`` workers can unpickle it.
    """

    def __init__(self, samples: Any):
        self.samples = samples

    def __len__(self) -> int:
        return len(self.samples)

    def __getitem__(self, i: int) -> dict[str, Any]:
        return {k: (torch.from_numpy(np.ascontiguousarray(v)) if isinstance(v, np.ndarray) else v)
                for k, v in self.samples[i].items()}
