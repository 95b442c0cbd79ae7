"""Kitchen-R from Python: the kitchen twin as a gymnasium environment.

    import gymnasium as gym
    import gym_kitchen_r  # registers the environments

    env = gym.make("KitchenR/Plan-v0")
    obs, info = env.reset(seed=0, options={"instruction": "dev-0000"})

``gym.make_vec("KitchenR/Plan-v0", num_envs=N, vectorization_mode="vector_entry_point")``: N of them
stepped in parallel (``gym_kitchen_r.vector``). ``KitchenR/Plan-v0``: an episode is one instruction's whole ground-truth plan, stepped one action
at a time through the same episode code the leaderboard runs (see ``gym_kitchen_r.env``).
``ExpertSamples``: expert training samples from parallel simulators (``gym_kitchen_r.samples``;
as a PyTorch dataset, ``gym_kitchen_r.torch_data``).
"""

from gymnasium.envs.registration import register

from .env import ACTION_FIELDS, EXECUTE, HORIZON, STATE_FIELDS, ActionSpace, KitchenREnv
from .samples import ExpertSamples
from .vector import KitchenRVectorEnv

__all__ = [
    "ACTION_FIELDS",
    "EXECUTE",
    "HORIZON",
    "STATE_FIELDS",
    "ActionSpace",
    "ExpertSamples",
    "KitchenREnv",
    "KitchenRVectorEnv",
]

register(
    id="KitchenR/Plan-v0",
    entry_point="gym_kitchen_r.env:KitchenREnv",
    vector_entry_point="gym_kitchen_r.vector:KitchenRVectorEnv",
)
