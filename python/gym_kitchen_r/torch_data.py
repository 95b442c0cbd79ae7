"""``ExpertSamples`` as a PyTorch ``IterableDataset`` (torch is imported here only).

    from torch.utils.data import DataLoader
    from gym_kitchen_r.torch_data import ExpertDataset
    data = ExpertDataset(episodes=2700, workers=16, history=2)
    for batch in DataLoader(data, batch_size=256):
        batch["images"]["base"]   # uint8 (256, 2, 128, 128, 3)
        batch["action"]           # float64 (256, 16, 10)

With ``num_workers=0`` (the default) the dataset's own simulator threads do the work. With
``num_workers=K`` each loader process takes every K-th episode (``shard``), with
``workers // K`` simulator threads each.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
import torch
from torch.utils.data import IterableDataset, get_worker_info

from .samples import ExpertSamples


class ExpertDataset(IterableDataset):
    """Takes ``ExpertSamples``' parameters (except ``shard``, which it sets per loader worker)."""

    def __init__(self, episodes: int, workers: int | None = None, **kwargs: Any):
        super().__init__()
        self._episodes, self._workers, self._kwargs = episodes, workers, kwargs

    def __iter__(self) -> Iterator[dict[str, Any]]:
        info = get_worker_info()
        index, count = (0, 1) if info is None else (info.id, info.num_workers)
        episodes = len(range(index, self._episodes, count))
        workers = self._workers if self._workers is None else max(1, self._workers // count)
        samples = ExpertSamples(episodes=episodes, workers=workers, shard=(index, count), **self._kwargs)
        for s in samples:
            yield _tensors(s)


def _tensors(s: dict[str, Any]) -> dict[str, Any]:
    """Arrays as tensors (copied: the sample's arrays are read-only views); text and the
    privileged observation (nested values) as they are."""
    out: dict[str, Any] = {}
    for k, v in s.items():
        if isinstance(v, np.ndarray):
            out[k] = torch.from_numpy(v.copy())
        elif isinstance(v, dict) and all(isinstance(a, np.ndarray) for a in v.values()):
            out[k] = {n: torch.from_numpy(a.copy()) for n, a in v.items()}
        else:
            out[k] = v
    return out
