"""The grasp mode from Python (docs/twin/robot.md): ``KitchenREnv(grasp_mode="physical")`` steps the same
physical twin as ``kitchen-r eval --grasp physical``, task by task and bit for bit in sim time,
and a mode that does not exist is refused naming the two that do.

``KITCHEN_R_BIN`` names the ``kitchen-r`` binary to compare with (``scripts/test.sh`` passes the
one the Rust tests built).
"""

import json
import os
import subprocess

import pytest
from gym_kitchen_r import KitchenREnv
from test_env import drive_expert


def test_an_unknown_grasp_mode_is_a_value_error_naming_both():
    with pytest.raises(ValueError, match="abstract.*physical"):
        KitchenREnv(images=False, grasp_mode="magic")


def test_the_physical_expert_through_the_env_is_the_physical_eval_episode():
    binary = os.environ.get("KITCHEN_R_BIN", "target/debug/kitchen-r")
    assert os.path.exists(binary), f"{binary} is missing: build it (cargo build) or set KITCHEN_R_BIN"
    out = subprocess.run(
        [
            binary,
            "eval",
            "--policy",
            "builtin:oracle",
            "--episodes",
            "1",
            "--seed",
            "0",
            "--grasp",
            "physical",
            "--json",
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    report = json.loads(out.stdout)
    assert report["grasp_mode"] == "physical"
    (want,) = report["episodes"]
    # `eval` runs the built-in oracle without teleports (they are for endpoint runs), so the env
    # does too; the episode then compares in full, a physically failed task included.
    env = KitchenREnv(images=False, grasp_mode="physical", teleport_on_failure=False)
    got = drive_expert(env, want["episode_id"])["episode"]
    assert got["sim_time"] == want["sim_time"]
    for g, w in zip(got["tasks"], want["tasks"], strict=True):
        assert (g["index"], g["step"], g["success"], g["failure"]) == (
            w["index"],
            w["step"],
            w["success"],
            w["failure"],
        )
        assert g["sim_time"] == w["sim_time"], g["index"]
    env.close()
