"""N Kitchen-R environments stepped in parallel, as a gymnasium ``VectorEnv``.

Each environment's episode runs on a Rust thread of its own. A step is one native call
(``_native.step_many``): every action is checked, all are handed to their episodes' threads,
the N simulators step at the same time with the GIL released, and the results come back
together; resets that autoreset asks for run in the same call. Observations are written into
arrays preallocated once (``gymnasium.vector.utils.create_empty_array``).

Autoreset follows gymnasium's default, ``AutoresetMode.NEXT_STEP``: the step after an episode
ended resets that environment (its action is ignored) and returns the reset observation with
reward 0. ``gymnasium.make_vec("KitchenR/Plan-v0", num_envs=N, vectorization_mode="vector_entry_point")``
builds one.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array, iterate

from . import _native
from .env import KitchenREnv, KitchenRTaskEnv


class KitchenRVectorEnv(VectorEnv):
    """``num_envs`` copies of :class:`gym_kitchen_r.KitchenREnv` built with the same ``kwargs``."""

    metadata = {"autoreset_mode": AutoresetMode.NEXT_STEP, "render_modes": []}
    env_class: type[KitchenREnv] = KitchenREnv

    def __init__(self, num_envs: int = 2, **kwargs: Any):
        if num_envs < 1:
            raise ValueError("num_envs must be at least 1")
        self.num_envs = num_envs
        self.envs = [self.env_class(**kwargs) for _ in range(num_envs)]
        self.single_observation_space = self.envs[0].observation_space
        self.single_action_space = self.envs[0].action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._obs = create_empty_array(self.single_observation_space, n=num_envs, fn=np.zeros)
        self._rewards = np.zeros(num_envs, dtype=np.float64)
        self._terminations = np.zeros(num_envs, dtype=np.bool_)
        self._truncations = np.zeros(num_envs, dtype=np.bool_)
        self._autoreset = np.zeros(num_envs, dtype=np.bool_)
        self._natives = [e._native for e in self.envs]

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        seeds = seed if isinstance(seed, list) else [None if seed is None else seed + i for i in range(self.num_envs)]
        if len(seeds) != self.num_envs:
            raise ValueError(f"{len(seeds)} seeds for {self.num_envs} environments")
        args = [e._reset_args(s, options) for e, s in zip(self.envs, seeds)]
        progress = _native.step_many(self._natives, args)
        infos: dict[str, Any] = {}
        observations = []
        for i, (env, p, a) in enumerate(zip(self.envs, progress, args)):
            obs, info = env._after_reset(p, *a)
            observations.append(obs)
            infos = self._add_info(infos, info, i)
        self._obs = concatenate(self.single_observation_space, observations, self._obs)
        self._autoreset[:] = False
        return self._obs, infos

    def step(self, actions):
        actions = list(iterate(self.action_space, actions))
        if len(actions) != self.num_envs:
            raise ValueError(f"{len(actions)} actions for {self.num_envs} environments")
        # NEXT_STEP autoreset: an environment whose episode ended resets now, its action ignored.
        requests = [
            env._reset_args(None, None) if self._autoreset[i] else env._action(actions[i])
            for i, env in enumerate(self.envs)
        ]
        progress = _native.step_many(self._natives, requests)
        infos: dict[str, Any] = {}
        observations = []
        for i, (env, p, r) in enumerate(zip(self.envs, progress, requests)):
            if self._autoreset[i]:
                obs, info = env._after_reset(p, *r)
                reward, terminated, truncated = 0.0, False, False
            else:
                obs, reward, terminated, truncated, info = env._after_step(p)
            observations.append(obs)
            self._rewards[i] = reward
            self._terminations[i] = terminated
            self._truncations[i] = truncated
            infos = self._add_info(infos, info, i)
        self._obs = concatenate(self.single_observation_space, observations, self._obs)
        self._autoreset = np.logical_or(self._terminations, self._truncations)
        return self._obs, self._rewards.copy(), self._terminations.copy(), self._truncations.copy(), infos

    def expert_chunks(self) -> np.ndarray:
        """The expert's chunk for each environment's current state: ``(num_envs, 16, 10)``.
        An environment waiting to autoreset gives zeros. (With ``expert=True`` every step's
        ``infos["expert_chunk"]`` has them already, at no extra cost.)"""
        return np.stack(
            [np.zeros((16, 10)) if self._autoreset[i] else e.expert_chunk() for i, e in enumerate(self.envs)]
        )

    def close_extras(self, **kwargs: Any):
        for env in self.envs:
            env.close()


class KitchenRTaskVectorEnv(KitchenRVectorEnv):
    """``num_envs`` copies of :class:`gym_kitchen_r.KitchenRTaskEnv` (``KitchenR/Task-v0``)."""

    env_class = KitchenRTaskEnv
