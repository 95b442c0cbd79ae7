"""The camera baseline end to end on CPU: features from an environment observation and from the
equivalent gRPC observation agree; a tiny training run (2 expert episodes, 3 steps, first plan
step only) writes a checkpoint that reloads and answers a valid 16x10 chunk through serve.py's
runner. Skipped without torch or gym_kitchen_r (KITCHEN_R_ASSETS / KITCHEN_R_CONFIGS must point
at the repository's assets/ and configs/; they default to them here)."""

import json
import os
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path
from types import SimpleNamespace

import numpy as np

HERE = Path(__file__).resolve().parent.parent
REPO = HERE.parent.parent.parent
os.environ.setdefault("KITCHEN_R_ASSETS", str(REPO / "assets"))
os.environ.setdefault("KITCHEN_R_CONFIGS", str(REPO / "configs"))

try:
    import gym_kitchen_r  # noqa: F401
    import torch  # noqa: F401
except ImportError:  # pragma: no cover
    torch = None


def grpc_like(obs, step, episode="ep-0"):
    """A stand-in for a gRPC Observation with history 2, built from an environment observation
    (history 2): what the worker sends for the same state."""
    state = np.asarray(obs["state"]).reshape(-1, 29)

    def frame(k):
        s = state[k]
        prev = s[19:29]
        return SimpleNamespace(
            step=step,
            images=[
                SimpleNamespace(
                    camera=c, width=128, height=128, data=np.ascontiguousarray(obs["images"][c][k]).tobytes()
                )
                for c in ("base", "gripper")
            ],
            depth=[
                SimpleNamespace(
                    camera=c,
                    width=128,
                    height=128,
                    data=np.ascontiguousarray(obs["depth"][c][k], dtype="<f4").tobytes(),
                )
                for c in ("base", "gripper")
            ]
            if "depth" in obs
            else [],
            robot=SimpleNamespace(
                base_x=s[0],
                base_y=s[1],
                base_yaw=s[2],
                base_v=s[3],
                base_omega=s[4],
                arm_joints=list(s[5:11]),
                gripper=s[11],
                ee_pose=list(s[12:19]),
            ),
            previous_action=[] if not prev.any() else list(prev),
        )

    newest = frame(len(state) - 1)
    return SimpleNamespace(
        history=[frame(k) for k in range(len(state) - 1)],
        episode_id=episode,
        step=step,
        task_index=obs["task_index"],
        sub_task=obs["sub_task"],
        **{k: getattr(newest, k) for k in ("images", "depth", "robot", "previous_action")},
    )


@unittest.skipIf(torch is None, "torch or gym_kitchen_r missing")
class CameraBaselineTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        from gym_kitchen_r import KitchenREnv

        env = KitchenREnv(images=True, depth=True, history=2, expert=True, randomise=True, max_tasks=1)
        obs0, info = env.reset(seed=3, options={"instruction": env.instruction_ids()[0]})
        obs1 = obs0
        for a in info["expert_chunk"][:8]:
            obs1, _, done, _, info = env.step(a)
            if done or info["tasks_ended"]:
                break
        env.close()
        cls.observations = [(obs0, 0), (obs1, 8)]

    def test_features_env_equals_grpc_with_and_without_depth(self):
        from kitchen_r_baselines.camera import features as F

        for obs, step in self.observations:
            ims_e, st_e = F.from_env(obs, step * F.CONTROL_DT)
            ims_g, st_g = F.from_grpc(grpc_like(obs, step), step * F.CONTROL_DT)
            self.assertEqual(ims_e.shape, (2, F.HISTORY, 128, 128, 3))
            np.testing.assert_array_equal(ims_e, ims_g)
            np.testing.assert_allclose(st_e, st_g, rtol=0, atol=1e-6)
            self.assertEqual(st_e.shape, (F.STATE_DIM,))
            d_e, _ = F.from_env(obs, step * F.CONTROL_DT, depth=True)
            d_g, _ = F.from_grpc(grpc_like(obs, step), step * F.CONTROL_DT, depth=True)
            self.assertEqual(d_e.shape, (4, F.HISTORY, 128, 128, 3))
            np.testing.assert_array_equal(d_e, d_g)
            np.testing.assert_array_equal(d_e[:2], ims_e)
            # Depth views carry the scene: not one flat value (a lost or misread depth image would be).
            self.assertGreater(len(np.unique(d_e[2:])), 10)
        vocab = F.dev_vocab()
        ids = F.encode("pick the red cup", {w: i for i, w in enumerate(vocab)})
        self.assertEqual(len(ids), F.MAX_WORDS)
        self.assertNotIn(F.UNK, ids[:4].tolist())

    def test_tiny_training_run_serves_a_valid_chunk(self):
        with tempfile.TemporaryDirectory() as d:
            # One DAgger round of one pick step (KitchenR/Task-v0, cut at 3 s): the closed-loop
            # expert labels the policy's states in a pick. With depth, which the served runner reads too.
            cmd = tiny_round(d, "--bc-steps", "3", "--round-task-seconds", "3", "--depth")
            subprocess.run(cmd, check=True, capture_output=True, timeout=600)
            logbook = json.loads((Path(d) / "train_log.json").read_text())
            self.assertEqual(logbook["instructions"], {"split": "dev", "range": "1-3", "count": 3})
            (round1,) = logbook["rounds"]
            self.assertEqual(round1["episodes"], 1)
            self.assertEqual(round1["sr_while_driving"]["pick"]["tasks"], 1)
            self.assertGreater(round1["rows_added"], 0)
            ck = Path(d) / "ckpt.pt"
            self.assertLessEqual(ck.stat().st_size, 16 * 2**20)
            from kitchen_r_baselines.camera.serve import CameraRunner

            runner = CameraRunner(str(ck), "cpu")
            obs, step = self.observations[1]
            runner.reset("ep-0", 0, obs["sub_task"])
            chunk = np.asarray(runner.decide(grpc_like(obs, step)))
            self.assertEqual(chunk.shape, (16, 10))
            self.assertTrue(np.isfinite(chunk).all())
            np.testing.assert_allclose(np.linalg.norm(chunk[:, 5:9], axis=1), 1.0, atol=1e-6)
            self.assertTrue(((chunk[:, 9] >= 0) & (chunk[:, 9] <= 1)).all())
            # An ActBatch of two episodes runs one forward and answers each as its Act.
            obs0, step0 = self.observations[0]
            runner.reset("ep-1", 0, obs0["sub_task"])
            batched = runner.decide_batch([grpc_like(obs, step), grpc_like(obs0, step0, "ep-1")])
            single = np.asarray(runner.decide(grpc_like(obs0, step0, "ep-1")))
            self.assertEqual(len(batched), 2)
            np.testing.assert_allclose(batched[0], chunk, rtol=0, atol=1e-4)
            np.testing.assert_allclose(batched[1], single, rtol=0, atol=1e-4)


def tiny_round(out, *extra):
    """A train.py run on the CPU small enough for CI: 2 expert episodes of dev 1-3, one DAgger
    round of one pick step (KitchenR/Task-v0) labelled by the expert; `extra` sets the rest."""
    return [
        sys.executable, str(HERE / "train.py"), "--out", out, "--episodes", "2", "--rounds", "1",
        "--round-episodes", "1", "--round-steps", "1", "--envs", "1", "--dagger-kinds", "pick",
        "--instructions", "1-3", "--max-tasks", "1", "--batch", "4", "--workers", "2", "--device", "cpu",
        *extra,
    ]  # fmt: skip


@unittest.skipIf(torch is None, "torch or gym_kitchen_r missing")
class TeacherTest(unittest.TestCase):
    def test_a_privileged_teacher_drives_the_rounds_to_a_completed_pick(self):
        # Learning by cheating: the committed privileged checkpoint drives every decision of a
        # round (--beta 1) while the expert labels them for the camera policy.
        teacher = REPO / "starter-kit/baselines/privileged/results/h200-2026-11-26/ckpt.pt"
        with tempfile.TemporaryDirectory() as d:
            cmd = tiny_round(
                d, "--bc-steps", "2", "--round-task-seconds", "40", "--teacher", str(teacher), "--beta", "1"
            )
            subprocess.run(cmd, check=True, capture_output=True, timeout=900)
            logbook = json.loads((Path(d) / "train_log.json").read_text())
            self.assertEqual(logbook["teacher"]["checkpoint"], str(teacher))
            (round1,) = logbook["rounds"]
            self.assertEqual(round1["sr_while_driving"]["pick"], {"success": 1, "tasks": 1, "sr": 1.0})
            self.assertGreater(round1["rows_added"], 0)


class AuxTargetTest(unittest.TestCase):
    def test_the_auxiliary_target_is_the_goal_its_kind_defines(self):
        from kitchen_r_baselines.camera import features as F

        v, m = F.aux_target({"goal": {"kind": "pick", "pose": [0.5, -0.6, 0.9, 1, 0, 0, 0]}})
        np.testing.assert_allclose(v[4:7], [0.5, -0.6, 0.9], rtol=0, atol=1e-6)
        self.assertEqual(m.tolist(), [0.0] * 4 + [1.0] * 3 + [0.0] * 3)
        v, m = F.aux_target({"goal": {"kind": "move", "pose": [1.0, 2.0, 0.0]}})
        np.testing.assert_allclose(v[:4], [1.0, 2.0, 0.0, 1.0], rtol=0, atol=1e-6)
        self.assertEqual(m.sum(), 4.0)
        v, m = F.aux_target({"goal": {"kind": "place", "position": [0.3, 0.1, 0.8]}})
        np.testing.assert_allclose(v[7:], [0.3, 0.1, 0.8], rtol=0, atol=1e-6)
        self.assertEqual(m.sum(), 3.0)


if __name__ == "__main__":
    unittest.main()
