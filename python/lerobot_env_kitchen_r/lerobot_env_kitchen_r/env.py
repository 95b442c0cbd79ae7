"""The Kitchen-R episode as LeRobot's evaluation loop expects to step it.

A thin adapter over ``gym_kitchen_r.KitchenREnv`` (``KitchenR/Plan-v0``): the episode, its tasks,
success checks, time limits, teleport on failure and action corrections are the leaderboard's,
unchanged. The adapter only renames and regroups the observation into LeRobot's keys, names the
episode's task text the way ``lerobot-eval`` reads it, and reports ``info["is_success"]`` for the
whole plan. It needs gymnasium and gym-kitchen-r, not LeRobot.

Observation (a ``Dict``), named as ``kitchen-r collect --format lerobot`` names its features:

- ``pixels``: ``{camera: uint8 (H, W, 3)}`` -> ``observation.images.<camera>``;
- ``agent_pos``: ``float64 (10,)`` -> ``observation.state``: ``base_v, base_w`` (measured base
  velocities), the hand pose in the base frame ``ee_x, ee_y, ee_z, ee_qw, ee_qx, ee_qy, ee_qz``
  and the ``gripper`` opening (the export's ``v, omega, x, y, z, qw, qx, qy, qz, gripper``);
- ``joints``: ``float64 (7,)`` -> ``observation.joints``: ``joint_0 .. joint_5, gripper``;
- ``base_pose``: ``float64 (3,)`` -> ``observation.base_pose``: odometry ``x, y, yaw`` relative to
  the episode's start.

The task text: ``env.task_description`` is the current sub-task sentence (``"pick the bowl"``,
what the export's ``task`` column holds and a control-track policy is given), or the whole
instruction with ``task_text="instruction"``; ``env.task`` is the instruction's sentence.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gym_kitchen_r import STATE_FIELDS, KitchenREnv
from gymnasium import spaces

# The control rate of the episode runner and of the exported dataset (frames per second).
FPS = 10

# LeRobot observation keys -> the gym_kitchen_r state fields they hold, in order.
AGENT_POS_FIELDS = ("base_v", "base_w", "ee_x", "ee_y", "ee_z", "ee_qw", "ee_qx", "ee_qy", "ee_qz", "gripper")
JOINT_FIELDS = tuple(f"joint_{i}" for i in range(6)) + ("gripper",)
BASE_POSE_FIELDS = ("odom_x", "odom_y", "odom_yaw")
STATE_KEYS = {"agent_pos": AGENT_POS_FIELDS, "joints": JOINT_FIELDS, "base_pose": BASE_POSE_FIELDS}

INSTRUCTION_ORDERS = ("seed", "random")
TASK_TEXTS = ("sub_task", "instruction")
INVALID_ACTIONS = ("fail", "raise")

_INDEX = {name: i for i, name in enumerate(STATE_FIELDS)}
_PICK = {key: np.array([_INDEX[f] for f in fields]) for key, fields in STATE_KEYS.items()}


def _camera_list(cameras: str | Sequence[str] | None) -> list[str] | None:
    if cameras is None:
        return None
    names = cameras.split(",") if isinstance(cameras, str) else list(cameras)
    names = [n.strip() for n in names if n.strip()]
    if not names:
        raise ValueError("cameras: name at least one camera (e.g. 'base,gripper')")
    return names


class KitchenRLeRobotEnv(gym.Env):
    """``gymnasium.make("lerobot_env_kitchen_r/Plan-v0", **kwargs)``; see the module documentation.

    Parameters (the ``kitchen_r`` env config's fields of the same names):

    - ``cameras``: comma-separated cameras to observe (default: every camera of
      ``configs/sensors.toml``, ``base,gripper``); ``observation_height`` / ``observation_width``,
      when given, must be those cameras' size (the adapter does not resize);
    - ``instruction``: run this instruction id in every episode; otherwise
      ``instruction_order``: ``"seed"`` (episode ``reset(seed=S)`` runs instruction
      ``ids[S mod N]``: ``lerobot-eval --seed 0 --eval.n_episodes 163`` covers the dev split once)
      or ``"random"`` (gym_kitchen_r's own seeded draw);
    - ``sim_seed``: the simulator seed of every episode (``kitchen-r eval --seed``); default: the
      episode's reset seed;
    - ``episode_length``: a cap on control steps, after which the episode is truncated as a
      failure (not a leaderboard rule: default ``None`` never cuts an episode short);
    - ``task_text``: ``"sub_task"`` or ``"instruction"`` (what ``task_description`` holds);
    - ``invalid_action``: an action beyond the leaderboard's tolerance (non-finite values,
      quaternion norm off by more than 0.1, gripper outside [-0.05, 1.05]) is never executed; the
      leaderboard fails the task for it. ``"fail"`` ends the episode there as a failure
      (``info["invalid_action"]`` says why: the plan's success is what the leaderboard would
      report, later tasks are not run); ``"raise"`` raises ``ValueError``;
    - ``split``, ``ground_truth``, ``teleport_on_failure``, ``task_time_limit``, ``max_tasks``:
      passed to ``gym_kitchen_r.KitchenREnv`` as they are.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": FPS}

    def __init__(
        self,
        cameras: str | Sequence[str] | None = None,
        observation_height: int | None = None,
        observation_width: int | None = None,
        instruction: str | None = None,
        instruction_order: str = "seed",
        sim_seed: int | None = None,
        episode_length: int | None = None,
        task_text: str = "sub_task",
        invalid_action: str = "fail",
        split: str = "dev",
        ground_truth: str | None = None,
        teleport_on_failure: bool = True,
        task_time_limit: float = 120.0,
        max_tasks: int = 0,
        render_mode: str | None = "rgb_array",
    ):
        for name, value, allowed in (
            ("instruction_order", instruction_order, INSTRUCTION_ORDERS),
            ("task_text", task_text, TASK_TEXTS),
            ("invalid_action", invalid_action, INVALID_ACTIONS),
        ):
            if value not in allowed:
                raise ValueError(f"{name} is {value!r}: one of {', '.join(allowed)}")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode {render_mode!r}: only 'rgb_array' is supported")
        if episode_length is not None and episode_length < 1:
            raise ValueError(f"episode_length is {episode_length}: at least 1 control step, or None")
        # The gym_kitchen_r env stepping the episode (its expert_chunk() labels the current state).
        self.inner = KitchenREnv(
            split=split,
            ground_truth=ground_truth,
            images=True,
            depth=False,
            history=1,
            teleport_on_failure=teleport_on_failure,
            task_time_limit=task_time_limit,
            max_tasks=max_tasks,
        )
        # gym_kitchen_r has no public list of instruction ids; its own tests read the native one.
        self.instruction_ids: list[str] = self.inner.instruction_ids()
        if instruction is not None and instruction not in self.instruction_ids:
            raise KeyError(f"no instruction {instruction!r} in the {split} split")
        sizes = {name: (h, w) for name, (h, w) in self._camera_sizes().items()}
        wanted = _camera_list(cameras) or list(sizes)
        unknown = [c for c in wanted if c not in sizes]
        if unknown:
            raise ValueError(f"no camera {', '.join(unknown)}: the cameras are {', '.join(sizes)}")
        for c in wanted:
            h, w = sizes[c]
            if (observation_height not in (None, h)) or (observation_width not in (None, w)):
                raise ValueError(
                    f"camera {c!r} renders {h}x{w} (configs/sensors.toml), the config asks "
                    f"{observation_height}x{observation_width}: the adapter does not resize"
                )
        self.cameras = wanted
        self._instruction, self._order, self._sim_seed = instruction, instruction_order, sim_seed
        self._task_text, self._invalid = task_text, invalid_action
        self.render_mode = render_mode
        # lerobot-eval runs at most `_max_episode_steps` steps (`env.call("_max_episode_steps")`).
        # By default the longest plan's every task at its time limit: every episode ends by itself.
        per_task = math.ceil(task_time_limit * FPS) + 1
        longest = max(len(self.inner.instruction_of(i)["plan"]) for i in self.instruction_ids)
        tasks = min(longest, max_tasks) if max_tasks > 0 else longest
        self._limit = episode_length
        self._max_episode_steps = episode_length if episode_length is not None else tasks * per_task
        self.action_space = self.inner.action_space
        self.observation_space = spaces.Dict(
            {
                "pixels": spaces.Dict({c: spaces.Box(0, 255, sizes[c] + (3,), np.uint8) for c in self.cameras}),
                **{key: spaces.Box(-np.inf, np.inf, (len(fields),), np.float64) for key, fields in STATE_KEYS.items()},
            }
        )
        self.task = ""
        self.task_description = ""
        self.instruction: dict | None = None
        self._steps = 0
        self._task_index = 0
        self._ended = True
        self._last: dict | None = None

    def _camera_sizes(self) -> dict[str, tuple[int, int]]:
        images = self.inner.observation_space["images"]
        return {name: (int(box.shape[0]), int(box.shape[1])) for name, box in images.spaces.items()}

    # Conversions --------------------------------------------------------------------------

    def _obs(self, obs: dict) -> dict:
        state = obs["state"]
        out: dict[str, Any] = {"pixels": {c: obs["images"][c] for c in self.cameras}}
        for key, pick in _PICK.items():
            out[key] = state[pick]
        self._last = out
        return out

    def _set_task(self, sub_task: str | None):
        if self._task_text == "sub_task":
            if sub_task is not None:
                self.task_description = sub_task
        else:
            self.task_description = self.task

    def _info(self, info: dict, *, ended: bool) -> dict:
        """Scalars only (a vector env stacks them): the whole plan's success, and progress."""
        out: dict[str, Any] = {
            "is_success": bool(ended and info.get("is_success", False)),
            "task_index": int(info.get("task_index", self._task_index)),
            "sub_task": str(info.get("sub_task", self.task_description)),
            "instruction_id": self.instruction["id"] if self.instruction else "",
            "tasks_succeeded": self._succeeded,
            "tasks_failed": self._failed,
        }
        self._task_index = out["task_index"]
        return out

    def _count(self, info: dict):
        for t in info.get("tasks_ended", []):
            if t["success"]:
                self._succeeded += 1
            else:
                self._failed += 1

    # The gymnasium API --------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = dict(options or {})
        instruction = options.pop("instruction", self._instruction)
        if instruction is None:
            if self._order == "seed" and seed is not None:
                instruction = self.instruction_ids[seed % len(self.instruction_ids)]
            else:
                instruction = self.instruction_ids[int(self.np_random.integers(len(self.instruction_ids)))]
        elif isinstance(instruction, int):
            instruction = self.instruction_ids[instruction]
        sim_seed = self._sim_seed if self._sim_seed is not None else seed
        if sim_seed is None:
            sim_seed = int(self.np_random.integers(2**63))
        obs, info = self.inner.reset(seed=int(sim_seed), options={"instruction": instruction})
        self.instruction = info["instruction"]
        self.task = self.instruction["instruction"]
        self._steps, self._succeeded, self._failed, self._task_index = 0, 0, 0, 0
        self._ended = False
        self._set_task(obs["sub_task"])
        out = self._info(info, ended=False)
        out["sim_seed"] = int(sim_seed)
        return self._obs(obs), out

    def step(self, action):
        if self._ended:
            raise RuntimeError("call reset() before step(), and again after the episode has ended")
        a = np.asarray(action, dtype=np.float64)
        try:
            obs, reward, terminated, truncated, info = self.inner.step(a)
        except ValueError as e:
            if self._invalid == "raise" or a.shape != (10,):
                raise
            # Not executed; the leaderboard would fail the task, and so the plan.
            self._ended = True
            self._failed += 1
            out = self._info({}, ended=True)
            out["invalid_action"] = str(e)
            return self._last, 0.0, True, False, out
        self._steps += 1
        self._count(info)
        if not terminated:
            self._set_task(obs["sub_task"])
        if not terminated and self._limit is not None and self._steps >= self._limit:
            truncated = True
        self._ended = terminated or truncated
        # A truncated plan has not succeeded: is_success only when the env ended it.
        out = self._info(info, ended=terminated)
        return self._obs(obs), float(reward), terminated, truncated, out

    def render(self):
        if self.render_mode != "rgb_array" or self._last is None:
            return None
        return np.concatenate([self._last["pixels"][c] for c in self.cameras], axis=1)

    def close(self):
        self.inner.close()


__all__ = [
    "AGENT_POS_FIELDS",
    "BASE_POSE_FIELDS",
    "FPS",
    "JOINT_FIELDS",
    "KitchenRLeRobotEnv",
    "STATE_KEYS",
]
