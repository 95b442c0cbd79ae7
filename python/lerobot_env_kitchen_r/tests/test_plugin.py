"""The LeRobot env plugin (docs/participant/lerobot.md) without LeRobot: the adapter's observation keys,
shapes and dtypes, ``is_success``, the gym id, determinism for a seed, the instruction and seed
choices, and its refusals. The tests marked ``lerobot`` need LeRobot and are skipped without it;
scripts/test.sh runs them in the test venv (scripts/test-venv.sh, LeRobot 0.4.4). They check
the ``kitchen_r`` env config and LeRobot's own ``make_env`` / ``preprocess_observation`` /
``add_envs_task`` on the plugin.
"""

import importlib.util

import gymnasium as gym
import lerobot_env_kitchen_r as plugin
import numpy as np
import pytest
from gym_kitchen_r import STATE_FIELDS, KitchenREnv
from lerobot_env_kitchen_r import GYM_ID, KitchenRLeRobotEnv

HAS_LEROBOT = importlib.util.find_spec("lerobot") is not None
_skip_without_lerobot = pytest.mark.skipif(not HAS_LEROBOT, reason="lerobot is not installed")


def needs_lerobot(test):
    """Skipped without LeRobot; marked `lerobot`, so scripts/test.sh runs only these (`-m lerobot`)
    in the LeRobot venv, the others having run in the test venv."""
    return pytest.mark.lerobot(_skip_without_lerobot(test))


@pytest.fixture(scope="module")
def env():
    e = KitchenRLeRobotEnv()
    yield e
    e.close()


def hold(obs):
    """A legal action that keeps the hand where it is and the base still."""
    return np.concatenate([[0.0, 0.0], obs["agent_pos"][2:9], [1.0]])


def test_the_gym_id_is_registered_without_wrappers():
    assert GYM_ID == "lerobot_env_kitchen_r/Plan-v0"
    assert GYM_ID in gym.registry
    e = gym.make(GYM_ID, disable_env_checker=True, max_tasks=1)
    try:
        # LeRobot reads task_description / task / _max_episode_steps with hasattr() on what
        # gym.make returns; gymnasium 1.x wrappers would hide them.
        assert isinstance(e, KitchenRLeRobotEnv)
        for attr in ("task_description", "task", "_max_episode_steps"):
            assert hasattr(e, attr), attr
    finally:
        e.close()


def test_observation_keys_shapes_and_dtypes(env):
    obs, info = env.reset(seed=0)
    assert set(obs) == {"pixels", "agent_pos", "joints", "base_pose"}
    assert set(obs["pixels"]) == {"base", "gripper"}
    for img in obs["pixels"].values():
        assert img.shape == (128, 128, 3) and img.dtype == np.uint8
    assert obs["agent_pos"].shape == (10,) and obs["agent_pos"].dtype == np.float64
    assert obs["joints"].shape == (7,) and obs["joints"].dtype == np.float64
    assert obs["base_pose"].shape == (3,) and obs["base_pose"].dtype == np.float64
    assert env.observation_space.contains(obs)
    assert env.action_space.shape == (10,)
    assert info["is_success"] is False


def test_state_keys_are_the_named_fields_of_gym_kitchen_r(env):
    obs, info = env.reset(seed=1)
    same = KitchenREnv(max_tasks=1)  # the same episode through gym_kitchen_r's own names
    try:
        state = same.reset(seed=1, options={"instruction": info["instruction_id"]})[0]["state"]
    finally:
        same.close()
    for key, fields in plugin.STATE_KEYS.items():
        expected = [state[STATE_FIELDS.index(f)] for f in fields]
        np.testing.assert_array_equal(obs[key], expected)
    # The export's observation.state order: v, omega, x, y, z, qw, qx, qy, qz, gripper.
    assert plugin.AGENT_POS_FIELDS == (
        "base_v",
        "base_w",
        "ee_x",
        "ee_y",
        "ee_z",
        "ee_qw",
        "ee_qx",
        "ee_qy",
        "ee_qz",
        "gripper",
    )


def test_task_text_is_the_sub_task_and_task_the_instruction(env):
    obs, info = env.reset(seed=0)
    assert env.task_description == info["sub_task"] and env.task_description
    assert env.task == env.instruction["instruction"]
    e = KitchenRLeRobotEnv(task_text="instruction", max_tasks=1)
    try:
        e.reset(seed=0)
        assert e.task_description == e.task == e.instruction["instruction"]
    finally:
        e.close()


def test_the_same_seed_gives_the_same_episode(env):
    def trace(seed):
        obs, info = env.reset(seed=seed)
        out = [(info["instruction_id"], obs)]
        for _ in range(5):
            obs, reward, terminated, truncated, info = env.step(hold(obs))
            out.append((reward, obs))
        return out

    a, b = trace(5), trace(5)
    assert a[0][0] == b[0][0]
    for (_, x), (_, y) in zip(a, b):
        for key in ("agent_pos", "joints", "base_pose"):
            np.testing.assert_array_equal(x[key], y[key])
        for cam in x["pixels"]:
            np.testing.assert_array_equal(x["pixels"][cam], y["pixels"][cam])


def test_instruction_choice_and_sim_seed():
    e = KitchenRLeRobotEnv(max_tasks=1)
    try:
        ids = e.instruction_ids
        # "seed": reset seed S runs ids[S mod N], with S as the simulator seed.
        _, info = e.reset(seed=1)
        assert info["instruction_id"] == ids[1] and info["sim_seed"] == 1
        _, info = e.reset(seed=len(ids) + 2)
        assert info["instruction_id"] == ids[2]
        _, info = e.reset(seed=3, options={"instruction": ids[7]})
        assert info["instruction_id"] == ids[7]
    finally:
        e.close()
    e = KitchenRLeRobotEnv(max_tasks=1, instruction="dev-0004", sim_seed=11)
    try:
        _, info = e.reset(seed=40)
        assert info["instruction_id"] == "dev-0004" and info["sim_seed"] == 11
    finally:
        e.close()


def test_the_expert_succeeds_and_is_success_is_the_whole_plan():
    e = KitchenRLeRobotEnv(instruction="dev-0001")
    try:
        obs, info = e.reset(seed=0)
        steps, terminated, ended, seen_tasks = 0, False, 0, {e.task_description}
        while not terminated:
            # As the runner executes a chunk: 8 actions, asked again when a task ends.
            for a in e.inner.expert_chunk()[:8]:
                obs, reward, terminated, truncated, info = e.step(a)
                steps += 1
                assert not truncated
                if not terminated:
                    assert info["is_success"] is False  # only the end of the whole plan succeeds
                    seen_tasks.add(e.task_description)
                if terminated or info["tasks_succeeded"] + info["tasks_failed"] != ended:
                    ended = info["tasks_succeeded"] + info["tasks_failed"]
                    break
        assert info["is_success"] is True
        assert info["tasks_succeeded"] == len(e.instruction["plan"]) and info["tasks_failed"] == 0
        assert seen_tasks == set(e.instruction["plan"])
        assert steps <= e._max_episode_steps
        with pytest.raises(RuntimeError):
            e.step(hold(obs))
    finally:
        e.close()


def test_a_policy_that_does_nothing_fails_by_the_task_time_limit():
    e = KitchenRLeRobotEnv(max_tasks=1, task_time_limit=2.0)
    try:
        assert e._max_episode_steps == 21
        obs, _ = e.reset(seed=0)
        terminated, steps = False, 0
        while not terminated:
            obs, reward, terminated, truncated, info = e.step(hold(obs))
            steps += 1
        assert steps == 20 and info["is_success"] is False and info["tasks_failed"] == 1
        assert reward == 0.0
    finally:
        e.close()


def test_episode_length_truncates_as_a_failure():
    e = KitchenRLeRobotEnv(max_tasks=1, episode_length=3)
    try:
        obs, _ = e.reset(seed=0)
        for _ in range(3):
            obs, _, terminated, truncated, info = e.step(hold(obs))
        assert truncated and not terminated and info["is_success"] is False
        assert e._max_episode_steps == 3
    finally:
        e.close()


def test_an_action_beyond_the_tolerance_fails_the_episode_or_raises():
    bad = np.array([0.0, 0.0, 0.4, 0.0, 0.9, 2.0, 0.0, 0.0, 0.0, 1.0])  # quaternion norm 2
    e = KitchenRLeRobotEnv(max_tasks=1)
    try:
        obs, _ = e.reset(seed=0)
        obs2, reward, terminated, truncated, info = e.step(bad)
        assert terminated and not truncated and reward == 0.0
        assert info["is_success"] is False and "quaternion norm" in info["invalid_action"]
        np.testing.assert_array_equal(obs2["agent_pos"], obs["agent_pos"])  # not executed
        # Within the tolerance the env's own correction applies (as on the leaderboard).
        obs, _ = e.reset(seed=0)
        a = hold(obs)
        a[5:9] *= 1.05
        _, _, terminated, _, info = e.step(a)
        assert not terminated and "invalid_action" not in info
        with pytest.raises(ValueError):
            e.step(np.zeros(3))
    finally:
        e.close()
    e = KitchenRLeRobotEnv(max_tasks=1, invalid_action="raise")
    try:
        e.reset(seed=0)
        with pytest.raises(ValueError, match="quaternion"):
            e.step(bad)
    finally:
        e.close()


def test_bad_configuration_is_refused():
    with pytest.raises(ValueError, match="no camera"):
        KitchenRLeRobotEnv(cameras="base,top")
    with pytest.raises(ValueError, match="does not resize"):
        KitchenRLeRobotEnv(observation_height=96)
    with pytest.raises(ValueError, match="instruction_order"):
        KitchenRLeRobotEnv(instruction_order="sorted")
    with pytest.raises(KeyError):
        KitchenRLeRobotEnv(instruction="dev-9999")


def test_one_camera_and_render():
    e = KitchenRLeRobotEnv(cameras="gripper", max_tasks=1)
    try:
        obs, _ = e.reset(seed=0)
        assert set(obs["pixels"]) == {"gripper"}
        assert e.render().shape == (128, 128, 3)
    finally:
        e.close()


def test_a_vector_env_as_lerobot_builds_it_reports_final_success():
    """What LeRobot's make_env builds (SyncVectorEnv, SAME_STEP autoreset) reports
    ``info["final_info"]["is_success"]`` at the end, the key lerobot-eval reads."""
    vec = gym.vector.SyncVectorEnv(
        [lambda: gym.make(GYM_ID, disable_env_checker=True, max_tasks=1, task_time_limit=1.0)] * 2,
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,
    )
    try:
        obs, _ = vec.reset(seed=[0, 1])
        assert obs["pixels"]["base"].shape == (2, 128, 128, 3)
        assert obs["agent_pos"].shape == (2, 10)
        assert list(vec.call("task_description")) and vec.call("_max_episode_steps")[0] == 11
        done = np.zeros(2, bool)
        for _ in range(11):
            actions = np.stack([hold({"agent_pos": p}) for p in obs["agent_pos"]])
            obs, reward, terminated, truncated, info = vec.step(actions)
            if "final_info" in info:
                assert info["final_info"]["is_success"].tolist() == [False, False]
                done |= terminated
        assert done.all()
    finally:
        vec.close()


@needs_lerobot
def test_the_kitchen_r_env_config_is_registered():
    from lerobot.envs.configs import EnvConfig
    from lerobot.envs.utils import env_to_policy_features

    cls = EnvConfig.get_choice_class("kitchen_r")
    cfg = cls()
    assert cfg.type == "kitchen_r" and cfg.gym_id == GYM_ID and cfg.fps == 10
    features = env_to_policy_features(cfg)
    assert features["observation.images.base"].shape == (3, 128, 128)
    assert features["observation.images.gripper"].shape == (3, 128, 128)
    assert features["observation.state"].shape == (10,)
    assert features["observation.joints"].shape == (7,)
    assert features["observation.base_pose"].shape == (3,)
    assert features["action"].shape == (10,)
    assert set(cls(cameras="base").features_map) >= {"pixels/base", "agent_pos", "action"}


@needs_lerobot
def test_lerobot_make_env_and_its_observation_processing():
    from lerobot.envs.configs import EnvConfig
    from lerobot.envs.factory import make_env
    from lerobot.envs.utils import add_envs_task, preprocess_observation

    cfg = EnvConfig.get_choice_class("kitchen_r")(max_tasks=1)
    envs = make_env(cfg, n_envs=1)
    vec = envs["kitchen_r"][0]
    try:
        obs, _ = vec.reset(seed=[0])
        batch = add_envs_task(vec, preprocess_observation(obs))
        assert batch["observation.images.base"].shape == (1, 3, 128, 128)
        assert batch["observation.state"].shape == (1, 10)
        assert batch["task"] == [vec.envs[0].task_description]
    finally:
        vec.close()
