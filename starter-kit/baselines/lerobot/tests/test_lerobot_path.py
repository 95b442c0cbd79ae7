"""The LeRobot path end to end (docs/participant/lerobot.md), tiny and on the CPU: our export
(`kitchen-r collect --format lerobot`, 2 episodes) -> `lerobot-train` (ACT and diffusion, a few
steps of tiny models) -> `kitchen-r-serve-lerobot --policy.path=...` -> `kitchen-r check-policy`
passes; and `lerobot-eval --env.type=kitchen_r` runs the trained ACT on the env plugin
(python/lerobot_env_kitchen_r) for one short episode. Also, with numpy only: the served features
are the export's (names and order) and a policy's actions become valid chunks.

scripts/test.sh runs this file in the test venv (scripts/test-venv.sh, LeRobot 0.4.4 from
scripts/test-requirements-lerobot.txt); without LeRobot the end-to-end tests are skipped. KITCHEN_R_BIN names the binary.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from kitchen_r_baselines.lerobot import features as F
from kitchen_r_baselines.lerobot.serve import HORIZON

ROOT = Path(__file__).resolve().parents[4]
BIN = Path(sys.executable).parent
HAS_LEROBOT = importlib.util.find_spec("lerobot") is not None
needs_lerobot = pytest.mark.skipif(not HAS_LEROBOT, reason="lerobot is not installed")
# No network here: LeRobot reads the export from its folder and downloads nothing.
OFFLINE = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_DATASETS_OFFLINE": "1", "WANDB_MODE": "disabled"}


def kitchen_r_bin() -> str:
    return str(ROOT / os.environ.get("KITCHEN_R_BIN", "target/debug/kitchen-r"))


def run(cmd: list[str], timeout: int = 600) -> subprocess.CompletedProcess:
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=OFFLINE, cwd=ROOT)
    assert out.returncode == 0, f"{cmd[0]} failed:\n{out.stdout[-4000:]}\n{out.stderr[-4000:]}"
    return out


@pytest.fixture(scope="module")
def export(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("export")
    run([kitchen_r_bin(), "collect", "--episodes", "2", "--format", "lerobot", "--jobs", "2", "--out", str(out)])
    return out / "lerobot"


# Tiny models, a few steps: what is tested is that the path runs, not what the policy learns.
COMMON = [
    "--dataset.repo_id=kitchen_r/tiny",
    "--dataset.video_backend=pyav",
    "--policy.device=cpu",
    "--policy.push_to_hub=false",
    "--policy.pretrained_backbone_weights=null",
    "--steps=3",
    "--batch_size=2",
    "--num_workers=0",
    "--save_freq=3",
    "--log_freq=1",
    "--wandb.enable=false",
]
TINY = {
    "act": [
        "--policy.chunk_size=16",
        "--policy.n_action_steps=8",
        "--policy.dim_model=64",
        "--policy.dim_feedforward=128",
        "--policy.n_heads=2",
        "--policy.n_encoder_layers=1",
        "--policy.n_decoder_layers=1",
        "--policy.use_vae=false",
    ],
    "diffusion": [
        "--policy.n_obs_steps=2",
        "--policy.horizon=16",
        "--policy.n_action_steps=8",
        "--policy.down_dims=[32,64]",
        "--policy.diffusion_step_embed_dim=32",
        "--policy.spatial_softmax_num_keypoints=8",
        "--policy.num_train_timesteps=10",
        "--policy.num_inference_steps=2",
        "--policy.crop_shape=[112,112]",
    ],
}


def train(export: Path, kind: str, out: Path) -> Path:
    run(
        [str(BIN / "lerobot-train"), f"--dataset.root={export}", f"--policy.type={kind}", f"--output_dir={out}"]
        + COMMON
        + TINY[kind]
    )
    model = out / "checkpoints" / "last" / "pretrained_model"
    assert (model / "config.json").is_file() and (model / "model.safetensors").is_file()
    return model


@pytest.fixture(scope="module")
def act_model(export, tmp_path_factory) -> Path:
    return train(export, "act", tmp_path_factory.mktemp("act") / "train")


def serve_and_check(model: Path) -> str:
    """Serve `model` with the new command, run check-policy against it; its stdout."""
    server = subprocess.Popen(
        [str(BIN / "kitchen-r-serve-lerobot"), f"--policy.path={model}", "--listen", "127.0.0.1:0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=OFFLINE,
    )
    try:
        addr, log = None, []
        assert server.stdout is not None
        for line in server.stdout:
            log.append(line)
            if "listening grpc=" in line:
                addr = line.split("listening grpc=")[1].split()[0]
                break
        assert addr, "kitchen-r-serve-lerobot did not start:\n" + "".join(log)
        check = subprocess.run(
            [kitchen_r_bin(), "check-policy", "--standard-only", f"http://{addr}"],
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert check.returncode == 0, check.stdout + check.stderr
        assert "FAIL" not in check.stdout, check.stdout
        return check.stdout
    finally:
        server.terminate()
        server.wait(timeout=30)


def test_the_export_names_the_features_the_server_builds(export):
    features = json.loads((export / "meta" / "info.json").read_text())["features"]
    for key, names in F.VECTORS.items():
        assert tuple(features[key]["names"]) == names, key
    assert tuple(features["action"]["names"]) == F.ACTION_NAMES
    cams = sorted(k for k in features if F.camera(k))
    assert cams == ["observation.images.base", "observation.images.gripper"]


def frame(**robot) -> SimpleNamespace:
    """A gRPC frame's fields as the features read them (robot state and one 6x4 image)."""
    r: dict[str, object] = dict(base_x=1.0, base_y=2.0, base_yaw=0.5, base_v=0.2, base_omega=-0.1, gripper=0.7)
    r.update(arm_joints=[0.1, 0.2, 0.3, 0.4, 0.5, 0.6], ee_pose=[0.3, 0.0, 0.9, 1.0, 0.0, 0.0, 0.0])
    r.update(robot)
    img = np.arange(4 * 6 * 3, dtype=np.uint8).reshape(4, 6, 3)
    return SimpleNamespace(
        robot=SimpleNamespace(**r),
        images=[SimpleNamespace(camera="base", width=6, height=4, data=img.tobytes())],
    )


def test_a_frame_becomes_the_export_vectors_in_their_order():
    f = frame()
    got = F.frame_features(
        f, ["observation.state", "observation.joints", "observation.base_pose", "observation.images.base"]
    )
    np.testing.assert_allclose(got["observation.state"], [0.2, -0.1, 0.3, 0.0, 0.9, 1.0, 0.0, 0.0, 0.0, 0.7], rtol=1e-6)
    np.testing.assert_allclose(got["observation.joints"], [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7], rtol=1e-6)
    np.testing.assert_allclose(got["observation.base_pose"], [1.0, 2.0, 0.5], rtol=1e-6)
    assert got["observation.state"].dtype == np.float32
    assert got["observation.images.base"].shape == (4, 6, 3)
    with pytest.raises(ValueError, match="ee_pose"):
        F.frame_features(frame(ee_pose=[]), ["observation.state"])
    with pytest.raises(ValueError, match="no feature of the Kitchen-R export"):
        F.frame_features(f, ["observation.environment_state"])


def test_a_policy_chunk_becomes_a_valid_contract_chunk():
    a = np.zeros((5, 10))
    a[:, 5:9] = [2.0, 0.0, 0.0, 0.0]  # a regression head's quaternion, far from unit norm
    a[:, 9] = [-0.3, 0.2, 0.5, 1.4, 1.0]
    a[:, 0] = np.arange(5)
    chunk = np.array(F.to_chunk(a, HORIZON))
    assert chunk.shape == (HORIZON, 10)
    np.testing.assert_allclose(np.linalg.norm(chunk[:, 5:9], axis=1), 1.0)
    assert chunk[:5, 9].tolist() == [0.0, 0.2, 0.5, 1.0, 1.0]
    assert chunk[:, 0].tolist() == [0, 1, 2, 3, 4] + [4] * 11  # padded with the last action
    assert np.array(F.to_chunk(np.ones((40, 10)), HORIZON)).shape == (HORIZON, 10)  # cut


@needs_lerobot
def test_act_trains_on_the_export_serves_and_passes_check_policy(act_model):
    out = serve_and_check(act_model)
    assert "PASS" in out


@needs_lerobot
def test_a_batch_of_decisions_is_each_decision_alone(act_model):
    # ActBatch runs several episodes' decisions in one forward pass; a deterministic policy (ACT
    # without its VAE) answers each as it answers it alone.
    from kitchen_r_baselines.lerobot.serve import LeRobotRunner

    runner = LeRobotRunner(str(act_model), "cpu")
    observations = []
    for seed in range(3):
        rng = np.random.default_rng(seed)
        images = [
            SimpleNamespace(
                camera=c, width=128, height=128, data=rng.integers(0, 256, (128, 128, 3), np.uint8).tobytes()
            )
            for c in ("base", "gripper")
        ]
        f = frame(base_v=float(rng.normal()), arm_joints=list(rng.normal(size=6)))
        observations.append(SimpleNamespace(history=[], robot=f.robot, images=images, sub_task="pick the apple"))
    batched = np.array(runner.decide_batch(observations))
    alone = np.array([runner.decide(o) for o in observations])
    assert batched.shape == (3, HORIZON, 10)
    np.testing.assert_allclose(batched, alone, atol=1e-5)
    assert np.abs(batched[0] - batched[1]).max() > 1e-4  # the inputs differ, and so do the answers


@needs_lerobot
def test_diffusion_trains_on_the_export_serves_and_passes_check_policy(export, tmp_path):
    model = train(export, "diffusion", tmp_path / "train")
    out = serve_and_check(model)
    assert "PASS" in out


@needs_lerobot
def test_lerobot_eval_runs_the_trained_policy_on_the_env_plugin(act_model, tmp_path):
    out = tmp_path / "eval"
    run(
        [
            str(BIN / "lerobot-eval"),
            "--env.type=kitchen_r",
            "--env.discover_packages_path=lerobot_env_kitchen_r",
            "--env.max_tasks=1",
            "--env.episode_length=20",
            f"--policy.path={act_model}",
            "--policy.device=cpu",
            "--eval.n_episodes=1",
            "--eval.batch_size=1",
            "--seed=0",
            f"--output_dir={out}",
        ]
    )
    info = json.loads((out / "eval_info.json").read_text())
    overall = info["overall"]
    assert overall["n_episodes"] == 1
    # 20 steps is too short for any task: the episode is truncated, a failure by the plugin's rule.
    assert overall["pc_success"] == 0.0
