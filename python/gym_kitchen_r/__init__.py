"""Kitchen-R from Python: the kitchen twin as a gymnasium environment.

    import gymnasium as gym
    import gym_kitchen_r  # registers the environments

    env = gym.make("KitchenR/Plan-v0")
    obs, info = env.reset(seed=0, options={"instruction": "dev-0000"})

``gym.make_vec("KitchenR/Plan-v0", num_envs=N, vectorization_mode="vector_entry_point")``: N of them
stepped in parallel (``gym_kitchen_r.vector``). ``KitchenR/Plan-v0``: an episode is one instruction's whole ground-truth plan, stepped one action
at a time through the same episode code the leaderboard runs (see ``gym_kitchen_r.env``).
``KitchenR/Task-v0``: one sub-task of a plan as an episode, from the expert's state at its
start (``gym_kitchen_r.env.KitchenRTaskEnv``). ``ExpertSamples``: expert training samples from parallel simulators (``gym_kitchen_r.samples``;
as a PyTorch dataset, ``gym_kitchen_r.torch_data``).
"""

from gymnasium.envs.registration import register

from .env import ACTION_FIELDS, EXECUTE, HORIZON, STATE_FIELDS, ActionSpace, KitchenREnv, KitchenRTaskEnv
from .samples import ExpertSamples
from .vector import KitchenRTaskVectorEnv, KitchenRVectorEnv

__all__ = [
    "ACTION_FIELDS",
    "EXECUTE",
    "HORIZON",
    "STATE_FIELDS",
    "ActionSpace",
    "ExpertSamples",
    "KitchenREnv",
    "KitchenRTaskEnv",
    "KitchenRTaskVectorEnv",
    "KitchenRVectorEnv",
]

register(
    id="KitchenR/Plan-v0",
    entry_point="gym_kitchen_r.env:KitchenREnv",
    vector_entry_point="gym_kitchen_r.vector:KitchenRVectorEnv",
)
register(
    id="KitchenR/Task-v0",
    entry_point="gym_kitchen_r.env:KitchenRTaskEnv",
    vector_entry_point="gym_kitchen_r.vector:KitchenRTaskVectorEnv",
)
