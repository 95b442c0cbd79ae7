"""N Kitchen-R environments stepped in parallel, as a gymnasium ``VectorEnv``.

Each environment's episode runs on a Rust thread of its own and a step holds the GIL only to
hand the action over and to turn the result into numpy arrays, so the N simulators step at the
same time; a thread per environment waits for its own. Observations are written into arrays
preallocated once (``gymnasium.vector.utils.create_empty_array``).

Autoreset follows gymnasium's default, ``AutoresetMode.NEXT_STEP``: the step after an episode
ended resets that environment (its action is ignored) and returns the reset observation with
reward 0. ``gymnasium.make_vec("KitchenR/Plan-v0", num_envs=N, vectorization_mode="vector_entry_point")``
builds one.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array, iterate

from .env import KitchenREnv


class KitchenRVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`gym_kitchen_r.KitchenREnv` built with the same ``kwargs``."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}

    def __init__(self, num_envs: int = 2, **kwargs: Any):
        if num_envs < 1:
            raise ValueError("num_envs must be at least 1")
        self.num_envs = num_envs
        self.envs = [KitchenREnv(**kwargs) for _ in range(num_envs)]
        self.single_observation_space = self.envs[0].observation_space
        self.single_action_space = self.envs[0].action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._obs = create_empty_array(self.single_observation_space, n=num_envs, fn=np.zeros)
        self._rewards = np.zeros(num_envs, dtype=np.float64)
        self._terminations = np.zeros(num_envs, dtype=np.bool_)
        self._truncations = np.zeros(num_envs, dtype=np.bool_)
        self._autoreset = np.zeros(num_envs, dtype=np.bool_)
        self._pool = ThreadPoolExecutor(max_workers=num_envs, thread_name_prefix="kitchen-r-env")

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        seeds = seed if isinstance(seed, list) else [None if seed is None else seed + i for i in range(self.num_envs)]
        if len(seeds) != self.num_envs:
            raise ValueError(f"{len(seeds)} seeds for {self.num_envs} environments")
        results = list(self._pool.map(lambda i: self.envs[i].reset(seed=seeds[i], options=options), range(self.num_envs)))
        infos: dict[str, Any] = {}
        for i, (_, info) in enumerate(results):
            infos = self._add_info(infos, info, i)
        self._obs = concatenate(self.single_observation_space, [o for o, _ in results], self._obs)
        self._autoreset[:] = False
        return self._obs, infos

    def _step_one(self, i: int, action: np.ndarray):
        env = self.envs[i]
        if self._autoreset[i]:
            obs, info = env.reset()
            return obs, 0.0, False, False, info
        return env.step(action)

    def step(self, actions):
        actions = list(iterate(self.action_space, actions))
        if len(actions) != self.num_envs:
            raise ValueError(f"{len(actions)} actions for {self.num_envs} environments")
        results = list(self._pool.map(lambda i: self._step_one(i, actions[i]), range(self.num_envs)))
        infos: dict[str, Any] = {}
        for i, (_, reward, terminated, truncated, info) in enumerate(results):
            self._rewards[i] = reward
            self._terminations[i] = terminated
            self._truncations[i] = truncated
            infos = self._add_info(infos, info, i)
        self._obs = concatenate(self.single_observation_space, [r[0] for r in results], self._obs)
        self._autoreset = np.logical_or(self._terminations, self._truncations)
        return self._obs, self._rewards.copy(), self._terminations.copy(), self._truncations.copy(), infos

    def expert_chunks(self) -> np.ndarray:
        """The expert's chunk for each environment's current state: ``(num_envs, 16, 10)``.
        An environment waiting to autoreset gives zeros."""
        chunks = self._pool.map(
            lambda i: np.zeros((16, 10)) if self._autoreset[i] else self.envs[i].expert_chunk(),
            range(self.num_envs),
        )
        return np.stack(list(chunks))

    def close_extras(self, **kwargs: Any):
        for env in self.envs:
            env.close()
        self._pool.shutdown(wait=True)
