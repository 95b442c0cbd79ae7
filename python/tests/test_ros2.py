"""``KitchenREnv(ros2=True)`` (docs/twin/live.md): each step is published live as ROS 2 topics over DDS,
and a subscriber on another DDS implementation, Eclipse Cyclone DDS (the ``cyclonedds`` wheel,
driven by ``scripts/ros2-watch.py`` as in ``tests/e2e/ros2_live.rs``), reads typed messages with
sim-time stamps and ROS frame ids; observations and rewards are those of the same steps with
publishing off. Discovery stays on loopback on both sides (``configs/live.toml``'s default and the
script's Cyclone configuration); the domain id is this process's own, so parallel runs on one
machine do not see each other.

Without the ``cyclonedds`` module the test is skipped outside CI and fails in CI.
"""

import importlib.util
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from gym_kitchen_r import KitchenREnv

WATCH = Path(__file__).resolve().parents[2] / "scripts" / "ros2-watch.py"
STEPS = 24


def cyclonedds_ready() -> bool:
    if importlib.util.find_spec("cyclonedds") is not None:
        return True
    assert "CI" not in os.environ, "cyclonedds (scripts/test-requirements.txt) is required in CI"
    return False


def drive(env, actions=None):
    """``STEPS`` steps of the first dev instruction: the expert's actions (or ``actions``); the
    actions, observations and rewards."""
    obs, _ = env.reset(seed=3, options={"instruction": env.instruction_ids()[0]})
    if actions is None:
        chunk = env.expert_chunk()
        actions = [chunk[i % len(chunk)] for i in range(STEPS)]
    trace, rewards = [obs], []
    for a in actions:
        obs, reward, terminated, _, _ = env.step(a)
        trace.append(obs)
        rewards.append(reward)
        assert not terminated
    return actions, trace, rewards


def subscriber(domain: int) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k not in ("CYCLONEDDS_URI", "ROS_DOMAIN_ID")}
    proc = subprocess.Popen(
        [sys.executable, str(WATCH), "--domain", str(domain), "--count", "3", "--seconds", "60"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    assert proc.stderr is not None
    line = proc.stderr.readline()
    assert line.strip() == "ready", f"the subscriber did not start: {line}{proc.stderr.read()}"
    return proc


@pytest.mark.skipif(not cyclonedds_ready(), reason="the cyclonedds Python module is not installed")
def test_ros2_publishes_typed_stamped_messages_and_changes_nothing(tmp_path, monkeypatch):
    monkeypatch.delenv("ROS_DOMAIN_ID", raising=False)
    domain = 1 + (os.getpid() * 3 + 2) % 230
    live_toml = tmp_path / "live.toml"
    live_toml.write_text(f"[ros2]\ndomain_id = {domain}\n")

    plain = KitchenREnv(images=True, max_tasks=1)
    actions, plain_obs, plain_rewards = drive(plain)
    plain.close()

    watch = subscriber(domain)
    try:
        started = time.monotonic()
        env = KitchenREnv(images=True, max_tasks=1, ros2=True, ros2_config=str(live_toml), ros2_wait=20)
        waited = time.monotonic() - started
        _, live_obs, live_rewards = drive(env, actions)
        stats = env.ros2_stats()
        env.close()
        out, err = watch.communicate(timeout=30)
    finally:
        watch.kill()
    assert watch.returncode == 0, f"the subscriber missed topics (waited {waited:.1f} s):\n{out}\n{err}"

    assert live_rewards == plain_rewards
    for a, b in zip(plain_obs, live_obs):
        assert (a["sub_task"], a["task_index"]) == (b["sub_task"], b["task_index"])
        np.testing.assert_array_equal(a["state"], b["state"])
        for cam in a["images"]:
            np.testing.assert_array_equal(a["images"][cam], b["images"][cam])
    assert stats["domain_id"] == domain and stats["written"] > 0, stats

    msgs = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    of = lambda topic: [m for m in msgs if m.get("topic") == topic]  # noqa: E731
    last_stamp = STEPS * 100_000_000 + 1
    for topic, frame in [
        ("/odom", "odom"),
        ("/tf", "odom"),
        ("/imu", "base_link"),
        ("/camera/base/image_raw", "base_optical_frame"),
    ]:
        got = of(topic)
        assert got, f"no {topic}: {out}"
        for m in got:
            assert m["frame_id"] == frame, m
            # Stamped with sim time: control steps of 0.1 s, after the episode's start.
            assert 0 < m["stamp"] <= last_stamp, m
        stamps = [m["stamp"] for m in got]
        assert stamps == sorted(stamps), f"{topic} stamps out of order: {stamps}"
    assert all(m["child"] == "base_link" for m in of("/odom") + of("/tf"))
    assert all((m["width"], m["height"], m["encoding"]) == (128, 128, "rgb8") for m in of("/camera/base/image_raw"))
    assert len(of("/clock")) >= 3
