"""The gymnasium environment (docs/participant/python.md): it passes gymnasium's checker, is deterministic, refuses
bad input with Python exceptions, and the expert stepped through it is the episode
``kitchen-r eval --policy builtin:oracle`` runs, task by task and bit for bit in sim time.

``KITCHEN_R_BIN`` names the ``kitchen-r`` binary to compare with (``scripts/test.sh`` passes the
one the Rust tests built).
"""

import json
import math
import os
import subprocess

import gym_kitchen_r
import gymnasium as gym
import numpy as np
import pytest
from gym_kitchen_r import KitchenREnv
from gymnasium.utils.env_checker import check_env

# The first 8 dev instructions: every kitchen, 2 to 3 times (CI time; the randomised test below adds 3).
EPISODES = 8


def first_ids(n):
    env = KitchenREnv(images=False)
    ids = env.instruction_ids()[:n]
    env.close()
    return ids


def drive_expert(env, instruction, seed=0):
    """The expert's chunk every `EXECUTE` steps, as `eval` runs the oracle; the episode info."""
    env.reset(seed=seed, options={"instruction": instruction})
    terminated = False
    while not terminated:
        _, _, terminated, truncated, info = env.step_chunk(env.expert_chunk())
        assert not truncated
    return info


def test_gymnasium_checker_passes():
    env = gym.make("KitchenR/Plan-v0", max_tasks=1)
    check_env(env.unwrapped, skip_render_check=True)
    env.close()


def test_the_same_seed_gives_the_same_observations():
    env = KitchenREnv(depth=True)
    runs = []
    for _ in range(2):
        obs, _ = env.reset(seed=7)
        trace = [obs]
        for a in env.expert_chunk()[:5]:
            trace.append(env.step(a)[0])
        runs.append(trace)
    for a, b in zip(*runs):
        assert a["sub_task"] == b["sub_task"]
        np.testing.assert_array_equal(a["state"], b["state"])
        for cam in a["images"]:
            np.testing.assert_array_equal(a["images"][cam], b["images"][cam])
            np.testing.assert_array_equal(a["depth"][cam], b["depth"][cam])
    # Another seed is another episode (robot start, background objects).
    other, _ = env.reset(seed=8)
    assert not np.array_equal(other["state"], runs[0][0]["state"]) or other["sub_task"] != runs[0][0]["sub_task"]
    env.close()


def test_spaces_name_their_fields_and_hold_the_observations():
    env = KitchenREnv(history=3)
    obs, info = env.reset(seed=1)
    assert env.observation_space.contains(obs), "the observation is in the observation space"
    assert obs["state"].shape == (3, len(gym_kitchen_r.STATE_FIELDS))
    assert obs["images"]["base"].shape == (3, 128, 128, 3)
    assert len(gym_kitchen_r.ACTION_FIELDS) == 10 and gym_kitchen_r.ACTION_FIELDS[-1] == "gripper"
    assert info["sub_task"] == info["instruction"]["plan"][0]
    a = env.action_space.sample()
    assert env.action_space.contains(a) and math.isclose(np.linalg.norm(a[5:9]), 1.0)
    env.close()


def test_bad_input_raises_python_exceptions_and_executes_nothing():
    env = KitchenREnv(images=False)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros(10))
    with pytest.raises(KeyError, match="no instruction"):
        env.reset(seed=0, options={"instruction": "dev-9999"})
    with pytest.raises(KeyError):
        KitchenREnv(instruction="nope")
    with pytest.raises(ValueError, match="split"):
        KitchenREnv(split="train")
    obs, _ = env.reset(seed=0)
    still = np.concatenate([[0.0, 0.0], obs["state"][12:19], [1.0]])
    for bad in (np.zeros(9), np.zeros((2, 10))):
        with pytest.raises(ValueError, match="shape"):
            env.step(bad)
    nan = still.copy()
    nan[0] = np.nan
    not_unit = still.copy()
    not_unit[5:9] = [2.0, 0.0, 0.0, 0.0]
    for bad in (nan, not_unit):
        with pytest.raises(ValueError, match="invalid action"):
            env.step(bad)
    obs, reward, terminated, truncated, info = env.step(still)
    assert obs["state"][-10:].tolist() == still.tolist(), "only the legal action was executed"
    assert (reward, terminated, truncated) == (0.0, False, False)
    env.close()


def test_the_expert_through_the_env_is_the_eval_episode_task_by_task():
    binary = os.environ.get("KITCHEN_R_BIN", "target/debug/kitchen-r")
    assert os.path.exists(binary), f"{binary} is missing: build it (cargo build) or set KITCHEN_R_BIN"
    out = subprocess.run(
        [binary, "eval", "--policy", "builtin:oracle", "--episodes", str(EPISODES), "--seed", "0", "--json"],
        check=True,
        capture_output=True,
        text=True,
    )
    report = json.loads(out.stdout)
    env = KitchenREnv(images=False)
    ids = first_ids(EPISODES)
    assert [e["episode_id"] for e in report["episodes"]] == ids
    succeeded = 0
    for want in report["episodes"]:
        info = drive_expert(env, want["episode_id"])
        got = info["episode"]
        assert got["sim_time"] == want["sim_time"], want["episode_id"]
        for g, w in zip(got["tasks"], want["tasks"], strict=True):
            assert (g["index"], g["step"], g["success"], g["failure"]) == (
                w["index"],
                w["step"],
                w["success"],
                w["failure"],
            )
            assert g["sim_time"] == w["sim_time"], (want["episode_id"], g["index"])
        succeeded += sum(t["success"] for t in got["tasks"])
        assert info["is_success"] == all(t["success"] for t in want["tasks"])
    assert succeeded == report["overall"]["succeeded"]
    env.close()


def test_a_vector_env_steps_its_envs_and_autoresets_on_the_next_step():
    v = gym.make_vec("KitchenR/Plan-v0", num_envs=2, vectorization_mode="vector_entry_point", images=False, max_tasks=1)
    env = v.unwrapped
    obs, _ = v.reset(seed=3)
    assert env.observation_space.contains(obs)
    assert obs["state"].shape == (2, len(gym_kitchen_r.STATE_FIELDS))
    # The same seeds give the same first observations as single environments.
    for i in range(2):
        single = KitchenREnv(images=False, max_tasks=1)
        o, _ = single.reset(seed=3 + i)
        np.testing.assert_array_equal(o["state"], obs["state"][i])
        single.close()
    ended = np.zeros(2, dtype=bool)
    for _ in range(3000):
        obs, reward, terminated, truncated, info = v.step(env.expert_chunks()[:, 0])
        assert not truncated.any()
        if terminated.any():
            assert all(reward[terminated] == 1.0), "the expert's one task succeeded"
            first = np.flatnonzero(terminated)[0]
            # NEXT_STEP autoreset: the following step resets that env, reward 0, not terminated.
            obs, reward, terminated, _, _ = v.step(env.expert_chunks()[:, 0])
            assert reward[first] == 0.0 and not terminated[first]
            assert obs["task_index"][first] == 0
            ended[first] = True
        if ended.all():
            break
    assert ended.all(), "both environments finished their task"
    v.close()


def test_the_package_leaves_the_contracts_protobuf_namespace_alone():
    """`kitchen_r.policy.v1` is the policy contract's protobuf package, which the starter kit
    generates into a namespace package at run time; a regular `kitchen_r` package installed by
    us would shadow it and break every Python policy server in the same environment."""
    import importlib.util

    assert gym_kitchen_r.__name__ == "gym_kitchen_r"
    spec = importlib.util.find_spec("kitchen_r")
    # None, or a namespace package (no loader) that generated modules can join.
    assert spec is None or spec.loader is None, f"a regular kitchen_r package is installed: {spec}"


def test_the_readme_snippet_steps_the_expert_to_success():
    # The lines of docs/participant/python.md (once the README's), as a newcomer types them.
    import gymnasium as gym  # noqa: E401,F401

    env = gym.make("KitchenR/Plan-v0", expert=True)
    obs, info = env.reset(seed=0, options={"instruction": "dev-0001"})
    assert info["is_success"] is False  # nothing has succeeded yet
    done = False
    while not done:
        obs, reward, done, _, info = env.step(info["expert_chunk"][0])  # noqa: E701
    assert info["is_success"] and len(info["episode"]["tasks"]) == len(info["episode"]["tasks"]) > 0
    env.close()


def test_task_env_runs_one_sub_task_from_the_experts_state_at_its_start():
    env = gym.make("KitchenR/Task-v0")
    plan = env.unwrapped.instruction_of("dev-0001")["plan"]
    j = next(i for i, step in enumerate(plan) if step.startswith("place"))
    obs, info = env.reset(seed=0, options={"instruction": "dev-0001", "task": j})
    assert obs["sub_task"] == plan[j] and obs["task_index"] == j and info["task"] == j
    # A reset is no success; only the task's end can be one (docs/participant/python.md).
    assert info["is_success"] is False
    # The robot starts holding what the expert picked before this step: the gripper is closed on it.
    assert obs["state"][gym_kitchen_r.STATE_FIELDS.index("gripper")] < 0.9
    terminated, steps = False, 0
    while not terminated:
        _, reward, terminated, _, info = env.unwrapped.step_chunk(env.unwrapped.expert_chunk())
        steps += 1
    assert info["is_success"] and reward == 1.0
    assert [t["index"] for t in info["episode"]["tasks"]] == [j], "only that step runs"
    with pytest.raises(ValueError, match="plan steps"):
        env.reset(seed=0, options={"instruction": "dev-0001", "task": len(plan)})
    # Without a task, the seeded generator draws one.
    _, a = env.reset(seed=4, options={"instruction": "dev-0001"})
    _, b = env.reset(seed=4, options={"instruction": "dev-0001"})
    assert a["task"] == b["task"]
    env.close()


def test_privileged_observation_is_what_the_track_sends_goal_in_the_robot_frame():
    env = KitchenREnv(images=False, privileged=True, privileged_observation=True)
    _, info = env.reset(seed=0, options={"instruction": "dev-0001"})
    po, full = info["privileged_observation"], info["privileged"]
    assert po["base_pose"] == full["base_pose"]
    assert po["goal"]["kind"] == full["target"]["kind"] == "move"
    # The goal is the scene-frame approach pose seen from the robot: rotate it back and compare.
    x, y, yaw = full["base_pose"]
    gx, gy, gyaw = po["goal"]["pose"]
    sx, sy = x + math.cos(yaw) * gx - math.sin(yaw) * gy, y + math.sin(yaw) * gx + math.cos(yaw) * gy
    assert np.allclose([sx, sy], full["target"]["pose"][:2], atol=1e-9)
    # The dev split shows every key object of the episode.
    assert [o["name"] for o in po["objects"]] == [o["name"] for o in full["objects"]]
    env.close()


def test_randomise_gives_the_episodes_kitchen_r_episodes_generate_writes(tmp_path):
    """``randomise=True`` with seed S is the randomised episode ``kitchen-r episodes generate
    --from-dataset --seed S`` writes: the expert through the env ends each task as ``kitchen-r
    eval --episodes-file`` runs it, and the draw differs from the unrandomised episode."""
    binary = os.environ.get("KITCHEN_R_BIN", "target/debug/kitchen-r")
    batch = tmp_path / "episodes.json"
    subprocess.run(
        [binary, "episodes", "generate", "--from-dataset", "--count", "3", "--seed", "5", "--out", str(batch)],
        check=True,
        capture_output=True,
    )
    out = subprocess.run(
        [binary, "eval", "--episodes-file", str(batch), "--json", "--jobs", "1"],
        check=True,
        capture_output=True,
        text=True,
    )
    report = json.loads(out.stdout)
    env = KitchenREnv(images=False, randomise=True, privileged=True)
    plain = KitchenREnv(images=False, privileged=True)
    for want, instruction in zip(report["episodes"], first_ids(3), strict=True):
        _, info = env.reset(seed=5, options={"instruction": instruction})
        _, plain_info = plain.reset(seed=5, options={"instruction": instruction})
        assert info["privileged"]["base_pose"] != plain_info["privileged"]["base_pose"], "robot start not redrawn"
        got = drive_expert(env, instruction, seed=5)["episode"]["tasks"]
        for g, w in zip(got, want["tasks"], strict=True):
            assert (g["step"], g["success"], g["failure"]) == (w["step"], w["success"], w["failure"])
            assert g["sim_time"] == w["sim_time"], (instruction, g["index"])
    env.close()
    plain.close()


def test_the_expert_labels_a_state_a_lagging_policy_reached_and_finishes_from_it():
    """A policy that holds the hand still for 6 s of a place (the expert's own plan would have
    lowered and let go by then) gets a label at every step, and the expert, taking over from that
    state, completes the task."""
    env = gym.make("KitchenR/Task-v0", expert=True)
    plan = env.unwrapped.instruction_of("dev-0001")["plan"]
    j = next(i for i, step in enumerate(plan) if step.startswith("place"))
    obs, info = env.reset(seed=0, options={"instruction": "dev-0001", "task": j})
    f = gym_kitchen_r.STATE_FIELDS
    hand = [obs["state"][f.index(k)] for k in ("ee_x", "ee_y", "ee_z", "ee_qw", "ee_qx", "ee_qy", "ee_qz")]
    still = np.array([0.0, 0.0, *hand, 0.0])  # the gripper stays closed on what it holds
    still[5:9] /= np.linalg.norm(still[5:9])
    for _ in range(60):
        chunk = info["expert_chunk"]
        assert chunk.shape == (16, 10) and np.isfinite(chunk).all()
        obs, _, terminated, _, info = env.step(still)
        assert not terminated
    while not terminated:
        obs, reward, terminated, _, info = env.step(info["expert_chunk"][0])
    assert info["is_success"] and reward == 1.0
    env.close()
