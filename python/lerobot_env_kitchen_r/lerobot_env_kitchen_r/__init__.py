"""Kitchen-R as a LeRobot environment plugin.

Importing the package registers the gym id ``lerobot_env_kitchen_r/Plan-v0`` (gymnasium only) and,
when LeRobot is installed, the ``kitchen_r`` env config (``lerobot_env_kitchen_r.config``), so

    lerobot-eval --env.type=kitchen_r --env.discover_packages_path=lerobot_env_kitchen_r \\
        --policy.path=PATH --eval.n_episodes=4 --eval.batch_size=1

evaluates a LeRobot policy on the leaderboard's episodes. LeRobot 0.4.x imports an env plugin only
through ``--env.discover_packages_path``; releases that auto-discover installed ``lerobot_env_*``
distributions import it without that argument.
"""

from __future__ import annotations

import importlib.util
import warnings

from gymnasium.envs.registration import register, registry

from .env import AGENT_POS_FIELDS, BASE_POSE_FIELDS, FPS, JOINT_FIELDS, STATE_KEYS, KitchenRLeRobotEnv

GYM_ID = "lerobot_env_kitchen_r/Plan-v0"

__all__ = [
    "AGENT_POS_FIELDS",
    "BASE_POSE_FIELDS",
    "FPS",
    "GYM_ID",
    "JOINT_FIELDS",
    "STATE_KEYS",
    "KitchenRLeRobotEnv",
]

if GYM_ID not in registry:
    # No OrderEnforcing/TimeLimit wrappers: LeRobot reads `task_description`, `task` and
    # `_max_episode_steps` with hasattr() on the env gym.make returns, and gymnasium 1.x wrappers
    # do not forward attributes.
    register(
        id=GYM_ID,
        entry_point="lerobot_env_kitchen_r.env:KitchenRLeRobotEnv",
        order_enforce=False,
        disable_env_checker=True,
    )

if importlib.util.find_spec("lerobot") is not None:
    try:
        from .config import KitchenREnvConfig  # noqa: F401  (registers the `kitchen_r` env type)

        __all__.append("KitchenREnvConfig")
    except ImportError as e:  # an incompatible LeRobot: the gym env still works
        warnings.warn(f"lerobot_env_kitchen_r: the kitchen_r env config is not registered: {e}", stacklevel=2)
