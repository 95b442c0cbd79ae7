"""Kitchen-R from Python: the kitchen twin as a gymnasium environment.

    import gymnasium as gym
    import kitchen_r  # registers the environments

    env = gym.make("KitchenR/Plan-v0")
    obs, info = env.reset(seed=0, options={"instruction": "dev-0000"})

``KitchenR/Plan-v0``: an episode is one instruction's whole ground-truth plan, stepped one action
at a time through the same episode code the leaderboard runs (see ``kitchen_r.env``).
"""

from gymnasium.envs.registration import register

from .env import ACTION_FIELDS, EXECUTE, HORIZON, STATE_FIELDS, ActionSpace, KitchenREnv

__all__ = ["ACTION_FIELDS", "EXECUTE", "HORIZON", "STATE_FIELDS", "ActionSpace", "KitchenREnv"]

register(id="KitchenR/Plan-v0", entry_point="kitchen_r.env:KitchenREnv")
