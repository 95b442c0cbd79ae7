"""The ``kitchen_r`` env config for LeRobot (needs ``lerobot``; imported by the package when
LeRobot is installed, and by LeRobot's plugin loader).

``lerobot-eval --env.type=kitchen_r`` builds this config; LeRobot's ``make_env`` then imports
``package_name`` if the gym id is not registered yet and calls
``gym.make(gym_id, disable_env_checker=True, **gym_kwargs)`` for each env of its vector env.
``features`` / ``features_map`` tell LeRobot which observation keys are what: ``pixels/<camera>``
-> ``observation.images.<camera>``, ``agent_pos`` -> ``observation.state``, ``joints`` ->
``observation.joints``, ``base_pose`` -> ``observation.base_pose``, the names
``kitchen-r collect --format lerobot`` gives the same values.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig

from .env import AGENT_POS_FIELDS, BASE_POSE_FIELDS, FPS, JOINT_FIELDS

PACKAGE = "lerobot_env_kitchen_r"

_STATE_FEATURES = {
    "agent_pos": ("observation.state", len(AGENT_POS_FIELDS)),
    "joints": ("observation.joints", len(JOINT_FIELDS)),
    "base_pose": ("observation.base_pose", len(BASE_POSE_FIELDS)),
}


@EnvConfig.register_subclass("kitchen_r")
@dataclass
class KitchenREnvConfig(EnvConfig):
    """Fields (``--env.<field>=...``); see ``lerobot_env_kitchen_r.env.KitchenRLeRobotEnv``."""

    # The gym id's name: lerobot_env_kitchen_r/Plan-v0 (an episode = an instruction's whole plan).
    task: str | None = "Plan-v0"
    fps: int = FPS
    # Comma-separated cameras (configs/sensors.toml: base, gripper), each observation_height x
    # observation_width (the adapter does not resize; the sizes must be the cameras').
    cameras: str = "base,gripper"
    observation_height: int = 128
    observation_width: int = 128
    # One instruction id for every episode, or None: "seed" (episode with reset seed S runs
    # instruction ids[S mod N]) or "random" (gym_kitchen_r's seeded draw).
    instruction: str | None = None
    instruction_order: str = "seed"
    # The simulator seed of every episode (as `kitchen-r eval --seed`); None: the reset seed.
    sim_seed: int | None = None
    # A cap on control steps (truncation = failure); None: the env ends every episode itself.
    episode_length: int | None = None
    # What task_description (LeRobot's "task") holds: "sub_task" or "instruction".
    task_text: str = "sub_task"
    # An action beyond the leaderboard's tolerance: "fail" (the episode ends failed) or "raise".
    invalid_action: str = "fail"
    split: str = "dev"
    ground_truth: str | None = None
    teleport_on_failure: bool = True
    task_time_limit: float = 120.0
    max_tasks: int = 0
    render_mode: str = "rgb_array"
    features: dict[str, PolicyFeature] = field(
        default_factory=lambda: {"action": PolicyFeature(type=FeatureType.ACTION, shape=(10,))}
    )
    features_map: dict[str, str] = field(default_factory=lambda: {"action": "action"})

    def __post_init__(self):
        cameras = [c.strip() for c in self.cameras.split(",") if c.strip()]
        if not cameras:
            raise ValueError("env.cameras: name at least one camera (e.g. 'base,gripper')")
        for cam in cameras:
            self.features[f"pixels/{cam}"] = PolicyFeature(
                type=FeatureType.VISUAL, shape=(self.observation_height, self.observation_width, 3)
            )
            self.features_map[f"pixels/{cam}"] = f"observation.images.{cam}"
        for key, (policy_key, n) in _STATE_FEATURES.items():
            self.features[key] = PolicyFeature(type=FeatureType.STATE, shape=(n,))
            self.features_map[key] = policy_key

    @property
    def package_name(self) -> str:
        return PACKAGE

    @property
    def gym_kwargs(self) -> dict:
        return {
            "cameras": self.cameras,
            "observation_height": self.observation_height,
            "observation_width": self.observation_width,
            "instruction": self.instruction,
            "instruction_order": self.instruction_order,
            "sim_seed": self.sim_seed,
            "episode_length": self.episode_length,
            "task_text": self.task_text,
            "invalid_action": self.invalid_action,
            "split": self.split,
            "ground_truth": self.ground_truth,
            "teleport_on_failure": self.teleport_on_failure,
            "task_time_limit": self.task_time_limit,
            "max_tasks": self.max_tasks,
            "render_mode": self.render_mode,
        }
