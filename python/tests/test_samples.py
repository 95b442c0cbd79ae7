"""Expert samples from parallel simulators (docs/participant/python.md): the same seed gives the same samples
whatever the thread count, shards split a collection without overlap, the samples are the
expert's decisions with the stacked history a policy is sent, and bad arguments raise."""

import gym_kitchen_r
import numpy as np
import pytest
from gym_kitchen_r import ExpertSamples


def collect(**kwargs):
    return list(ExpertSamples(max_tasks=2, **kwargs).episodes_iter())


def assert_same(a, b):
    assert [e["index"] for e in a] == [e["index"] for e in b]
    for ea, eb in zip(a, b):
        assert ea["tasks"] == eb["tasks"] and ea["sim_time"] == eb["sim_time"]
        assert len(ea["samples"]) == len(eb["samples"])
        for sa, sb in zip(ea["samples"], eb["samples"]):
            assert sa["step"] == sb["step"] and sa["sub_task"] == sb["sub_task"]
            np.testing.assert_array_equal(sa["action"], sb["action"])
            np.testing.assert_array_equal(sa["state"], sb["state"])
            for cam in sa["images"]:
                np.testing.assert_array_equal(sa["images"][cam], sb["images"][cam])


def test_the_same_seed_gives_the_same_samples_whatever_the_worker_count():
    one = collect(episodes=3, workers=1, seed=5)
    three = collect(episodes=3, workers=3, seed=5)
    assert_same(one, three)
    other = collect(episodes=1, workers=1, seed=6)
    assert not np.array_equal(other[0]["samples"][0]["state"], one[0]["samples"][0]["state"])


def test_shards_split_the_collection_without_overlap():
    whole = collect(episodes=4, workers=2)
    even = collect(episodes=2, workers=1, shard=(0, 2))
    odd = collect(episodes=2, workers=1, shard=(1, 2))
    assert [e["index"] for e in even] == [0, 2] and [e["index"] for e in odd] == [1, 3]
    assert_same(whole, sorted(even + odd, key=lambda e: e["index"]))


def test_a_training_set_of_named_instructions_never_runs_another():
    env = gym_kitchen_r.KitchenREnv(images=False)
    ids = env.instruction_ids()
    env.close()
    chosen = [ids[4], ids[2]]
    eps = list(ExpertSamples(episodes=3, workers=2, images=False, max_tasks=1, instructions=chosen).episodes_iter())
    assert [e["instruction_id"] for e in eps] == [ids[4], ids[2], ids[4]]
    with pytest.raises(ValueError, match="no instruction .dev-9999. in the dev split"):
        ExpertSamples(episodes=1, instructions=["dev-9999"])
    with pytest.raises(ValueError, match="instructions is empty"):
        ExpertSamples(episodes=1, instructions=[])


def test_a_sample_is_a_decision_with_its_history_and_the_experts_chunk():
    ep = collect(episodes=1, workers=1, history=3, execute=4)[0]
    samples = ep["samples"]
    assert samples, "the expert's decisions are samples"
    s = samples[0]
    assert s["images"]["base"].shape == (3, 128, 128, 3) and s["images"]["base"].dtype == np.uint8
    assert s["state"].shape == (3, len(gym_kitchen_r.STATE_FIELDS))
    assert s["action"].shape == (16, 10)
    assert np.allclose(np.linalg.norm(s["action"][:, 5:9], axis=1), 1.0), "the expert's quaternions are unit"
    # At a task's start the history is padded with its oldest frame, as the contract pads it.
    np.testing.assert_array_equal(s["state"][0], s["state"][2])
    # Decisions of a task are `execute` control steps apart.
    same_task = [x["step"] for x in samples if x["task_index"] == s["task_index"]]
    assert all(b - a == 4 for a, b in zip(same_task, same_task[1:]))
    assert s["sub_task"] == ep["plan"][0] and s["episode_index"] == 0
    # The state's previous action is the chunk action executed just before.
    later = next(x for x in samples[1:] if x["task_index"] == s["task_index"])
    prev = later["state"][-1][-10:]
    assert np.allclose(prev, s["action"][3], atol=1e-6)


def test_without_images_a_sample_has_the_state_only():
    s = next(iter(ExpertSamples(episodes=1, workers=1, images=False, max_tasks=1)))
    assert "images" not in s and s["state"].shape == (29,)


@pytest.mark.parametrize(
    "kwargs",
    [dict(execute=0), dict(execute=17), dict(history=9), dict(workers=0), dict(shard=(2, 2)), dict(split="nope")],
)
def test_bad_arguments_raise_value_error(kwargs):
    with pytest.raises(ValueError):
        ExpertSamples(episodes=1, **kwargs)


def test_samples_carry_the_privileged_observation_when_asked():
    s = next(iter(ExpertSamples(episodes=1, workers=1, images=False, max_tasks=1, privileged_observation=True)))
    assert s["privileged_observation"]["goal"]["kind"] == "move"
    assert len(s["privileged_observation"]["base_pose"]) == 3
    plain = next(iter(ExpertSamples(episodes=1, workers=1, images=False, max_tasks=1)))
    assert "privileged_observation" not in plain
