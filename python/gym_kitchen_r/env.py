"""The Kitchen-R twin as a gymnasium environment.

An episode is one instruction of the dataset: its whole ground-truth plan, task by task, exactly
as the leaderboard runs it (the native module relays each action into the same episode runner the
workers use; it adds no rule). The same instruction and seed give the episode that
``kitchen-r eval --seed SEED`` runs for that instruction.

Observation (a ``Dict``):

- ``images``: one ``uint8`` array ``(H, W, 3)`` per configured camera (``base``, ``gripper`` by
  default; ``(history, H, W, 3)`` with ``history > 1``); ``depth`` likewise in metres when asked;
- ``state``: ``float64`` ``(29,)`` (``(history, 29)``), fields named in ``STATE_FIELDS``:
  odometry relative to the episode's start, base velocities, the arm's joints, the gripper
  opening, the hand pose in the base frame and the previous action (zeros before the first one
  and after a teleport);
- ``sub_task``: the current plan step, e.g. ``"pick the bowl"``; ``task_index``.

Action: 10 values named in ``ACTION_FIELDS`` (base velocities, the hand's target pose in the base
frame, the gripper command). The action space holds only legal actions (a unit quaternion,
``g`` in [0, 1]); an illegal one raises ``ValueError`` and is not executed.

Reward: 1 for each task that succeeds (sparse). ``terminated`` when the plan's last task has
ended; ``truncated`` is never set (each task's 120 s limit is part of the episode).
``info``: ``task_index``, ``sub_task``, ``tasks_ended`` (records of the tasks that ended with this
step), ``is_success`` (False until the episode ends; then whether every task of it succeeded:
the whole plan, or ``Task-v0``'s one task, as gymnasium-robotics and LeRobot read it), and on request
``expert_chunk`` (the expert's 16x10 chunk for the current state) and ``privileged`` (robot pose
in the scene frame, the task's goal, the key objects' poses).
"""

from __future__ import annotations

import string
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from . import _native

ACTION_FIELDS = ("base_v", "base_w", "ee_x", "ee_y", "ee_z", "ee_qw", "ee_qx", "ee_qy", "ee_qz", "gripper")
# The robot state's fields, in order; the native module builds the state (one layout for the
# environment and the expert samples).
STATE_FIELDS = tuple(_native.STATE_FIELDS)
HORIZON = 16
# Actions of a chunk executed before the policy is asked again (the organiser's default).
EXECUTE = 8
MAX_TASKS = 16
_SUB_TASK_CHARSET = string.ascii_letters + string.digits + " -'"


class ActionSpace(spaces.Box):
    """The legal actions: a box on each value, a unit quaternion, ``g`` in [0, 1].

    Not every point of the box is an action (the hand's orientation is a unit quaternion), so
    ``sample`` normalises the quaternion and ``contains`` checks its norm.
    """

    def __init__(self, seed: int | None = None):
        low = np.array([-0.5, -1.5, -1.5, -1.5, -1.5, -1.0, -1.0, -1.0, -1.0, 0.0])
        high = np.array([0.5, 1.5, 1.5, 1.5, 1.5, 1.0, 1.0, 1.0, 1.0, 1.0])
        super().__init__(low=low, high=high, dtype=np.float64, seed=seed)

    def sample(self, mask: Any = None, probability: Any = None) -> np.ndarray:
        a = super().sample()
        q = a[5:9]
        while np.linalg.norm(q) < 1e-3:
            q = self.np_random.uniform(-1.0, 1.0, size=4)
        a[5:9] = q / np.linalg.norm(q)
        return a

    def contains(self, x: Any) -> bool:
        if not super().contains(x):
            return False
        return abs(float(np.linalg.norm(np.asarray(x, dtype=np.float64)[5:9])) - 1.0) <= 1e-6


class KitchenREnv(gym.Env):
    """``gymnasium.make("KitchenR/Plan-v0", **kwargs)``; see the module documentation.

    Parameters: ``split`` (``"dev"``; ``"test"`` needs ``ground_truth``, the organiser's JSON
    Lines file), ``images`` / ``depth`` (render the cameras / their depth at every step),
    ``history`` (consecutive control steps each observation shows, 1 to 8),
    ``teleport_on_failure`` (after a failed task, continue from the expert's state at the next
    task's start, as the server does; costs one expert pre-run per reset), ``expert`` (put the
    expert's chunk in ``info`` at every step), ``privileged`` (put the full reference world state in
    ``info``), ``privileged_observation`` (put in ``info`` what the privileged track sends a policy
    that asks for it: the robot's pose in the scene frame, the current goal in the robot frame,
    the key objects the split allows; see docs/participant/privileged.md),
    ``randomise`` (apply the paper's randomisation, ``configs/episodes.toml`` ``[randomise]``, to
    each episode: with seed S the episode of an instruction is the one ``kitchen-r episodes
    generate --from-dataset --seed S`` writes for it; off by default, as ``kitchen-r eval`` runs
    the split), ``grasp_mode`` (``"abstract"`` or ``"physical"``, how the gripper holds objects,
    as a server's ``[control] grasp`` sets it; ``None`` keeps ``configs/sim.toml``'s
    ``[grasp] mode``; any other value is a ``ValueError`` naming the two),
    ``task_time_limit`` (sim seconds per task, 120), ``max_tasks`` (run only the first N plan
    steps; 0 = all), ``instruction`` (always this instruction id; otherwise ``reset`` picks
    one, or takes ``options={"instruction": id}``), ``ros2`` (publish each episode live as ROS 2
    topics over DDS, the topics, types and frames of ``kitchen-r eval --ros2``: both cameras,
    LiDAR, ``/tf``, ``/odom``, ``/imu``, ``/clock``, the action and the sub-task, at every step;
    best effort, the episode is the same with it on or off), ``ros2_config`` (a ``live.toml``
    whose ``[ros2]`` table sets domain, network and QoS; default ``configs/live.toml``: domain 0,
    loopback only; ``ROS_DOMAIN_ID`` overrides the domain), ``ros2_wait`` (with ``ros2``: wait
    up to this many seconds at construction for a ROS 2 subscriber, as ``--ros2-wait``; 0 waits
    not). All environments of a process share one publisher, one episode at a time holding it.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        split: str = "dev",
        ground_truth: str | None = None,
        images: bool = True,
        depth: bool = False,
        history: int = 1,
        teleport_on_failure: bool = True,
        expert: bool = False,
        privileged: bool = False,
        privileged_observation: bool = False,
        randomise: bool = False,
        grasp_mode: str | None = None,
        task_time_limit: float = 120.0,
        max_tasks: int = 0,
        instruction: str | None = None,
        render_mode: str | None = None,
        ros2: bool = False,
        ros2_config: str | None = None,
        ros2_wait: float = 0.0,
    ):
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode {render_mode!r}: only 'rgb_array' is supported")
        self._native = _native.NativeEnv(
            split=split,
            ground_truth=ground_truth,
            images=images,
            depth=depth,
            teleport_on_failure=teleport_on_failure,
            history=history,
            task_time_limit=task_time_limit,
            max_tasks=max_tasks,
            expert=True,
            # The expert's chunk rides with each decision: no second round trip per step.
            expert_inline=expert,
            privileged=privileged,
            privileged_observation=privileged_observation,
            randomise=randomise,
            grasp_mode=grasp_mode,
            ros2=ros2,
            ros2_config=None if ros2_config is None else str(ros2_config),
            ros2_wait=ros2_wait,
        )
        self.render_mode = render_mode
        self._images, self._depth, self._history = images, depth, history
        self._expert, self._privileged = expert, privileged
        self._privileged_observation = privileged_observation
        self._ids = self._native.instruction_ids()
        if instruction is not None and instruction not in self._ids:
            raise KeyError(f"no instruction {instruction!r} in the {split} split")
        self._fixed = instruction
        self._cameras = self._native.cameras()
        self._decision: dict | None = None
        self._last_obs: dict | None = None
        self.instruction: dict | None = None
        self.action_space = ActionSpace()
        self.observation_space = self._observation_space()

    # Spaces -------------------------------------------------------------------------------

    def _observation_space(self) -> spaces.Dict:
        lead = (self._history,) if self._history > 1 else ()
        obs: dict[str, spaces.Space] = {}
        if self._images:
            obs["images"] = spaces.Dict(
                {n: spaces.Box(0, 255, lead + (h, w, 3), np.uint8) for n, h, w in self._cameras}
            )
        if self._depth:
            obs["depth"] = spaces.Dict(
                {n: spaces.Box(0.0, np.inf, lead + (h, w), np.float32) for n, h, w in self._cameras}
            )
        obs["state"] = spaces.Box(-np.inf, np.inf, lead + (len(STATE_FIELDS),), np.float64)
        obs["sub_task"] = spaces.Text(max_length=128, min_length=1, charset=_SUB_TASK_CHARSET)
        obs["task_index"] = spaces.Discrete(MAX_TASKS)
        return spaces.Dict(obs)

    # Conversions --------------------------------------------------------------------------

    def _obs(self, frames: dict, sub_task: str, task_index: int) -> dict:
        """The observation from the native module's stacked frames (see ``unpack_frames``)."""
        obs = unpack_frames(frames, self._history, self._images, self._depth)
        obs["sub_task"] = sub_task
        obs["task_index"] = int(task_index)
        return obs

    def _decision_obs(self, decision: dict) -> dict:
        return self._obs(decision["frames"], decision["sub_task"], decision["task_index"])

    def _final_obs(self, ended: dict) -> dict:
        """The observation after the last action: the world as it was left, with the last
        decision's task (no decision follows)."""
        last = self._decision or {"sub_task": "", "task_index": 0}
        return self._obs(ended["frames"], last["sub_task"], last["task_index"])

    def _info(self, progress: dict) -> dict:
        info: dict[str, Any] = {"tasks_ended": progress["tasks_ended"]}
        # Nothing has succeeded before the episode's end (a reset is no success).
        info["is_success"] = False
        d = progress["decision"]
        if d is not None:
            info["task_index"] = d["task_index"]
            info["sub_task"] = d["sub_task"]
            if self._privileged:
                info["privileged"] = d["privileged"]
            if self._privileged_observation:
                info["privileged_observation"] = d["privileged_observation"]
            if self._expert:
                if "expert_error" in d:
                    raise RuntimeError(f"the expert has no chunk for this state: {d['expert_error']}")
                n, raw = d["expert"]
                info["expert_chunk"] = np.frombuffer(raw, dtype=np.float64).reshape(n, 10).copy()
        else:
            ended = progress["ended"]
            info["episode"] = {k: ended[k] for k in ("tasks", "sim_time", "success_rate")}
            info["is_success"] = all(t["success"] for t in ended["tasks"])
        return info

    # The gymnasium API --------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        args = self._reset_args(seed, options)
        return self._after_reset(self._native.reset(*args), *args)

    def _reset_args(self, seed: int | None, options: dict | None) -> tuple[str, int, int | None]:
        """The instruction, run seed and plan step (None: the whole plan) a reset starts (the
        vector env starts several at once)."""
        super().reset(seed=seed)
        options = options or {}
        instruction = options.get("instruction", self._fixed)
        if instruction is None:
            instruction = self._ids[int(self.np_random.integers(len(self._ids)))]
        elif isinstance(instruction, int):
            instruction = self._ids[instruction]
        run_seed = seed if seed is not None else int(self.np_random.integers(2**63))
        self.instruction = self._native.instruction(instruction)
        return instruction, int(run_seed), self._task(options)

    def _task(self, options: dict) -> int | None:
        """The plan step a reset runs alone; the whole plan here (``KitchenR/Task-v0`` picks one)."""
        return None

    def _after_reset(self, progress: dict, instruction: str, run_seed: int, task: int | None = None):
        if progress["decision"] is None:
            raise RuntimeError(f"instruction {instruction!r} has no task to run")
        self._decision = progress["decision"]
        obs = self._decision_obs(self._decision)
        self._last_obs = obs
        info = self._info(progress)
        info["instruction"] = self.instruction
        info["run_seed"] = run_seed
        if task is not None:
            info["task"] = task
        return obs, info

    def step(self, action):
        return self._after_step(self._native.step(self._action(action)))

    def _action(self, action) -> list[float]:
        """The action as the native step takes it; a wrong shape or a step with no episode raises."""
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (10,):
            raise ValueError(f"an action has shape {a.shape}; it must be (10,): {', '.join(ACTION_FIELDS)}")
        if self._decision is None:
            raise RuntimeError("call reset() before step(), and again after the episode has terminated")
        return a.tolist()

    def _after_step(self, progress: dict):
        reward = float(sum(1 for t in progress["tasks_ended"] if t["success"]))
        info = self._info(progress)
        if progress["decision"] is not None:
            self._decision = progress["decision"]
            obs = self._decision_obs(self._decision)
            terminated = False
        else:
            obs = self._final_obs(progress["ended"])
            self._decision = None
            terminated = True
        self._last_obs = obs
        return obs, reward, terminated, False, info

    def step_chunk(self, chunk, execute: int = EXECUTE):
        """Execute the first ``execute`` actions of a 16x10 chunk, as the leaderboard's runner
        does with a policy's chunk; stops early when the episode ends or a task ends (the
        runner asks the policy again at each task's start). Returns the last step's
        observation, the summed reward, and the last step's flags and info."""
        c = np.asarray(chunk, dtype=np.float64)
        if c.ndim != 2 or c.shape[1] != 10 or len(c) < 1:
            raise ValueError(f"a chunk has shape {c.shape}; it must be (N, 10), N >= 1")
        total = 0.0
        result = None
        for a in c[: max(1, min(execute, len(c)))]:
            obs, reward, terminated, truncated, info = self.step(a)
            total += reward
            result = (obs, total, terminated, truncated, info)
            if terminated or info["tasks_ended"]:
                break
        return result

    def expert_chunk(self) -> np.ndarray:
        """The expert's chunk (16 x 10) for the current state, from privileged state."""
        if self._decision is None:
            raise RuntimeError("call reset() first: there is no current decision")
        return np.asarray(self._native.expert_chunk(), dtype=np.float64)

    def instruction_ids(self) -> list[str]:
        """The split's instruction ids, in dataset order (what ``options={"instruction": ...}``
        takes)."""
        return list(self._ids)

    def instruction_of(self, instruction_id: str) -> dict:
        """``{"id", "scene", "instruction", "plan"}`` of an instruction of the split."""
        return self._native.instruction(instruction_id)

    def render(self):
        if self.render_mode != "rgb_array" or self._last_obs is None or "images" not in self._last_obs:
            return None
        views = [v[-1] if self._history > 1 else v for v in self._last_obs["images"].values()]
        return np.concatenate(views, axis=1)

    def ros2_stats(self) -> dict | None:
        """With ``ros2=True``: ``{"domain_id", "written", "dropped"}``, the samples the process's
        publisher wrote to DDS and those DDS dropped (a full send window); ``None`` otherwise or
        after ``close()``."""
        counts = self._native.ros2_counts()
        if counts is None:
            return None
        return dict(zip(("domain_id", "written", "dropped"), counts))

    def close(self):
        self._native.close()
        self._decision = None


def unpack_frames(frames: dict, history: int, images: bool = True, depth: bool = False) -> dict:
    """The native module's stacked frames as arrays: ``images`` / ``depth`` per camera and
    ``state``, with a leading ``history`` axis when ``history > 1`` (the arrays are read-only
    views of the native bytes, no copy)."""

    def unpack(entry, dtype, tail: tuple) -> np.ndarray:
        n, raw = entry[0], entry[-1]
        a = np.frombuffer(raw, dtype=dtype).reshape((n,) + tail)
        return a if history > 1 else a[0]

    out: dict[str, Any] = {}
    if images:
        out["images"] = {n: unpack(e, np.uint8, (e[1], e[2], 3)) for n, e in frames["images"].items()}
    if depth:
        out["depth"] = {n: unpack(e, np.float32, (e[1], e[2])) for n, e in frames["depth"].items()}
    out["state"] = unpack(frames["state"], np.float64, (len(STATE_FIELDS),))
    return out


class KitchenRTaskEnv(KitchenREnv):
    """``gymnasium.make("KitchenR/Task-v0", **kwargs)``: one sub-task as an episode.

    ``reset(options={"instruction": id, "task": j})`` runs plan step ``j`` of the instruction
    alone, starting where the expert stood at that step's start (one expert pre-run per reset
    for ``j > 0``); without ``task`` a step is drawn from the seeded generator. The episode
    terminates when that task ends; ``info["is_success"]`` is its success. Parameters as
    ``KitchenR/Plan-v0`` (``max_tasks`` does not apply).
    """

    def _task(self, options: dict) -> int:
        assert self.instruction is not None, "reset() picks the instruction before its task"
        plan = self.instruction["plan"]
        task = options.get("task")
        if task is None:
            return int(self.np_random.integers(len(plan)))
        task = int(task)
        if not 0 <= task < len(plan):
            raise ValueError(f"task {task}: instruction {self.instruction['id']!r} has plan steps 0..{len(plan) - 1}")
        return task
