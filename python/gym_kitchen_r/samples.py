"""Expert training samples straight from parallel simulators, at simulator speed.

``ExpertSamples`` runs the oracle expert over a collection of episodes on Rust threads (the
episodes ``kitchen-r collect --seed SEED`` builds, with the paper's randomisation) and yields
one sample per decision: what a policy asked at that moment is sent (its observation history
and sub-task) and the expert's 16x10 chunk as the label. Only the samples' frames are rendered;
nothing is encoded to video or decoded. Samples come in episode order whatever the worker
count: the same seed gives the same samples.

    from gym_kitchen_r import ExpertSamples
    for s in ExpertSamples(episodes=100, workers=8, history=2):
        s["images"]["base"]   # (2, 128, 128, 3) uint8
        s["state"]            # (2, 29) float64, fields in STATE_FIELDS
        s["action"]           # (16, 10) float64, fields in ACTION_FIELDS
        s["sub_task"]         # "pick the bowl"

A PyTorch ``IterableDataset`` wraps it in a few lines (``gym_kitchen_r.torch_data``).
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from typing import Any

import numpy as np

from . import _native
from .env import unpack_frames


class ExpertSamples:
    """Parameters: ``episodes`` (in the collection, or in this shard), ``split`` (``"dev"``;
    ``"test"`` needs ``ground_truth``), ``seed`` (the collection's), ``workers`` (simulator
    threads; default: the cores), ``execute`` (control steps between the expert's decisions,
    each a sample; 8 is the organiser's default execution count, 1 samples every step),
    ``history`` (frames a sample stacks, 1 to 8), ``images`` / ``depth``, ``randomise`` (the
    paper's randomisation, on), ``successful_only`` (drop the samples of tasks the expert
    failed, on), ``task_time_limit``, ``max_tasks`` (only the first N plan steps; 0 = all),
    ``shard`` (``(index, count)``: episodes ``n`` with ``n % count == index``, for data loader
    workers sharing one collection), ``privileged_observation`` (each sample carries what the
    privileged track sends a policy at that decision: robot pose, goal in the robot frame, the key
    objects the split allows), ``instructions`` (a list of instruction ids: episode ``n`` runs
    ``instructions[n % len]``, so a training set can leave held-out instructions out; ``None``:
    the whole split, in dataset order).

    Iterating starts the simulators afresh each time (an epoch gives the same samples; change
    ``seed`` for new episodes). ``episodes_iter()`` yields whole episodes with their outcome.
    """

    def __init__(
        self,
        episodes: int,
        split: str = "dev",
        ground_truth: str | None = None,
        seed: int = 0,
        workers: int | None = None,
        execute: int = 8,
        history: int = 1,
        images: bool = True,
        depth: bool = False,
        randomise: bool = True,
        successful_only: bool = True,
        task_time_limit: float = 120.0,
        max_tasks: int = 0,
        shard: tuple[int, int] = (0, 1),
        privileged_observation: bool = False,
        instructions: list[str] | None = None,
    ):
        if episodes < 0:
            raise ValueError("episodes must be 0 or more")
        self._kwargs = dict(
            split=split,
            ground_truth=ground_truth,
            episodes=int(episodes),
            seed=int(seed),
            workers=int(workers if workers is not None else (os.cpu_count() or 1)),
            execute=int(execute),
            history=int(history),
            images=images,
            depth=depth,
            randomise=randomise,
            successful_only=successful_only,
            task_time_limit=float(task_time_limit),
            max_tasks=int(max_tasks),
            shard_index=int(shard[0]),
            shard_count=int(shard[1]),
            privileged_observation=privileged_observation,
            instructions=None if instructions is None else [str(i) for i in instructions],
        )
        self._history, self._images, self._depth = history, images, depth
        # Check the arguments now rather than at the first iteration.
        _native.NativeSamples(**{**self._kwargs, "episodes": 0}).close()

    def episodes_iter(self) -> Iterator[dict[str, Any]]:
        """Whole episodes: ``index``, ``episode_id``, ``instruction_id``, ``seed``, ``scene``,
        ``plan``, ``tasks`` (each task's outcome), ``sim_time`` and ``samples`` (a list)."""
        native = _native.NativeSamples(**self._kwargs)
        try:
            while (ep := native.next_episode()) is not None:
                ep["samples"] = [self._sample(s, ep) for s in ep["samples"]]
                yield ep
        finally:
            native.close()

    def __iter__(self) -> Iterator[dict[str, Any]]:
        for ep in self.episodes_iter():
            yield from ep["samples"]

    def _sample(self, s: dict, ep: dict) -> dict[str, Any]:
        out = unpack_frames(s["frames"], self._history, self._images, self._depth)
        n, raw = s["action"]
        out["action"] = np.frombuffer(raw, dtype=np.float64).reshape(n, 10)
        out["sub_task"] = s["sub_task"]
        out["task_index"] = s["task_index"]
        out["step"] = s["step"]
        out["episode_index"] = ep["index"]
        out["instruction_id"] = ep["instruction_id"]
        if "privileged_observation" in s:
            out["privileged_observation"] = s["privileged_observation"]
        return out
