"""The privileged baseline end to end on the CPU, in seconds: a few training steps on streamed
expert samples and one DAgger episode, the checkpoint reloads, serves over gRPC and passes
`kitchen-r check-policy`; and the features the policy is trained on (from the Python
environment) are the ones it is served (from a gRPC observation)."""

import os
import subprocess
import sys
import tempfile
import time
import unittest
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
BASE = HERE.parent
ROOT = BASE.parents[2]

try:
    import torch  # noqa: F401

    HAVE_TORCH = True
except ImportError:
    HAVE_TORCH = False

os.environ.setdefault("KITCHEN_R_ASSETS", str(ROOT / "assets"))
os.environ.setdefault("KITCHEN_R_CONFIGS", str(ROOT / "configs"))


def kitchen_r_bin():
    b = os.environ.get("KITCHEN_R_BIN")
    for c in ([b] if b else []) + [ROOT / "target/debug/kitchen-r", ROOT / "target/release/kitchen-r"]:
        if c and Path(c).is_file():
            return str(Path(c).resolve())
    raise unittest.SkipTest("no kitchen-r binary (set KITCHEN_R_BIN)")


@unittest.skipUnless(HAVE_TORCH, "torch is not installed")
class BatchedServingTest(unittest.TestCase):
    def test_an_actbatch_runs_one_forward_and_answers_each_as_its_act(self):
        """The committed checkpoint answers a batch of three episodes' observations (one MLP
        forward) with the chunks their single Acts get."""
        import policy_server as kit
        from kitchen_r_baselines.privileged.serve import PrivilegedRunner

        pb2, _ = kit.load_stubs(kit.proto_dir(None))
        runner = PrivilegedRunner(str(BASE / "results/h200-2026-11-26/ckpt.pt"))
        observations = []
        for i in range(3):
            goal = pb2.Goal()
            goal.approach.x, goal.approach.y, goal.approach.yaw = 1.0 + i, -0.5 * i, 0.3 * i
            observations.append(
                pb2.Observation(
                    episode_id=f"ep-{i}",
                    step=8 * i,
                    robot=pb2.RobotState(arm_joints=[0.1 * i] * 6, gripper=1.0, ee_pose=[0.35, 0, 0.95, 0, 1, 0, 0]),
                    privileged_observation=pb2.PrivilegedObservation(base_x=0.2 * i, goal=goal),
                )
            )
            runner.reset(f"ep-{i}", 0, "move to the blue zone")
        forwards = []
        chunk = runner.model.chunk
        runner.model.chunk = lambda x: forwards.append(len(x)) or chunk(x)
        batched = runner.decide_batch(observations)
        self.assertEqual(forwards, [3])
        singles = [runner.decide(o) for o in observations]
        self.assertEqual(len(batched), 3)
        for b, s in zip(batched, singles):
            self.assertEqual(np.asarray(b).shape, (16, 10))
            np.testing.assert_allclose(b, s, rtol=0, atol=1e-5)
        self.assertFalse(np.allclose(batched[0], batched[2]), "each observation has its own answer")


class FeaturesTest(unittest.TestCase):
    def test_training_and_serving_features_agree(self):
        """One decision of the environment, turned into the gRPC observation the worker would
        send, gives the same feature vector both ways."""
        from kitchen_r_baselines.privileged import features as F
        import policy_server as kit
        from gym_kitchen_r import KitchenREnv

        pb2, _ = kit.load_stubs(kit.proto_dir(None))
        env = KitchenREnv(images=False, privileged_observation=True, expert=True)
        obs, info = env.reset(seed=3, options={"instruction": "dev-0001"})
        for _ in range(30):  # into the task, so velocities and the previous action are not zero
            obs, _, _, _, info = env.step(info["expert_chunk"][0])
        s, p = np.asarray(obs["state"]), info["privileged_observation"]
        env.close()
        g = p["goal"]
        goal = pb2.Goal()
        if g["kind"] == "move":
            goal.approach.x, goal.approach.y, goal.approach.yaw = g["pose"]
        elif g["kind"] == "pick":
            goal.pick.object = g["object"]
            goal.pick.pose.extend(g["pose"])
        else:
            goal.place.object = g["object"]
            goal.place.target.extend(g["position"])
        o = pb2.Observation(
            step=130,
            robot=pb2.RobotState(
                base_x=s[0],
                base_y=s[1],
                base_yaw=s[2],
                base_v=s[3],
                base_omega=s[4],
                arm_joints=s[5:11],
                gripper=s[11],
                ee_pose=s[12:19],
            ),
            previous_action=s[19:29],
            privileged_observation=pb2.PrivilegedObservation(
                base_x=p["base_pose"][0],
                base_y=p["base_pose"][1],
                base_yaw=p["base_pose"][2],
                goal=goal,
                objects=[pb2.PrivilegedObject(name=x["name"], pose=x["pose"]) for x in p["objects"]],
            ),
        )
        a, b = F.from_env(s, p, 3.0), F.from_grpc(o, 3.0)
        self.assertEqual(a.shape, (F.FEATURES,))
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)
        self.assertGreater(np.abs(a[:2]).sum(), 0.0, "the base was moving 3 s into the task")

    def test_a_place_goal_carries_the_held_object_in_the_robot_frame(self):
        from kitchen_r_baselines.privileged import features as F

        base = (1.0, 2.0, np.pi / 2)
        held = [1.0, 3.0, 0.9, 1.0, 0.0, 0.0, 0.0]  # 1 m ahead of a base facing +y
        v = F.vector(np.zeros(F.ROBOT), base, "place", (0.5, 0.0, 0.9), held, 0.0)
        x, y, z, qw, qx, qy, qz = v[-7:]
        self.assertAlmostEqual(x, 1.0, places=6)
        self.assertAlmostEqual(y, 0.0, places=6)
        self.assertAlmostEqual(z, 0.9, places=6)
        self.assertAlmostEqual(abs(qz), np.sqrt(0.5), places=6)  # the object's yaw seen from the base: -90 deg


@unittest.skipUnless(HAVE_TORCH, "torch is not installed")
class TrainServeTest(unittest.TestCase):
    def test_a_few_steps_train_a_checkpoint_that_serves_and_passes_check_policy(self):
        kr = kitchen_r_bin()
        with tempfile.TemporaryDirectory() as d:
            run = subprocess.run(
                [
                    sys.executable,
                    str(BASE / "train.py"),
                    "--out",
                    d,
                    "--episodes",
                    "2",
                    "--workers",
                    "2",
                    "--bc-steps",
                    "5",
                    "--rounds",
                    "1",
                    "--round-episodes",
                    "1",
                    "--round-steps",
                    "5",
                    "--envs",
                    "1",
                    "--batch",
                    "32",
                    "--width",
                    "64",
                    "--depth",
                    "2",
                    "--max-tasks",
                    "1",
                    "--device",
                    "cpu",
                ],
                capture_output=True,
                text=True,
                timeout=600,
            )
            self.assertEqual(run.returncode, 0, run.stdout + run.stderr)
            ck = Path(d) / "ckpt.pt"
            self.assertLess(ck.stat().st_size, 16 * 2**20)
            log = __import__("json").loads((Path(d) / "train_log.json").read_text())
            self.assertEqual(log["rounds"][0]["round"], 1)
            self.assertGreater(log["expert"]["rows"], 0)

            from kitchen_r_baselines.privileged import features as F
            from kitchen_r_baselines.privileged.model import load

            model, meta = load(ck)
            self.assertEqual(meta["stage"], "final")
            chunk = F.finish(model.chunk(torch.zeros(1, F.FEATURES))[0].numpy())
            self.assertEqual(chunk.shape, (16, 10))
            np.testing.assert_allclose(np.linalg.norm(chunk[:, 5:9], axis=1), 1.0, atol=1e-9)

            serve = subprocess.Popen(
                [sys.executable, str(BASE / "serve.py"), "--checkpoint", str(ck), "--listen", "127.0.0.1:0"],
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
            )
            try:
                addr = None
                t0 = time.time()
                while addr is None and time.time() - t0 < 60:
                    line = serve.stdout.readline()
                    if not line:
                        break
                    if "listening grpc=" in line:
                        addr = line.split("listening grpc=")[1].split()[0]
                self.assertIsNotNone(addr, "serve.py did not print its address")
                check = subprocess.run(
                    [kr, "check-policy", f"http://{addr}"], capture_output=True, text=True, timeout=300
                )
                self.assertEqual(check.returncode, 0, check.stdout + check.stderr)
                self.assertIn("privileged", check.stdout)
                self.assertNotIn("FAIL", check.stdout)
            finally:
                serve.terminate()
                serve.wait(timeout=30)


if __name__ == "__main__":
    unittest.main()


class GateSummaryTest(unittest.TestCase):
    def test_the_summary_reads_each_trainers_log(self):
        # The camera and privileged trainers log expert.episodes, rows and train_seconds; the
        # diffusion pipeline episodes, samples and train_minutes (run 7's summary had nulls).
        from kitchen_r_baselines import gate

        online = {"episodes": [], "overall": {}, "seed": 0}
        diffusion = gate.summarise(
            online, None, {"episodes": 198, "samples": 206737, "train_minutes": 8.0}, "standard", {}
        )
        self.assertEqual(
            (diffusion["training_episodes"], diffusion["training_samples"], diffusion["train_seconds"]),
            (198, 206737, 480),
        )
        camera = gate.summarise(
            online, None, {"expert": {"episodes": 3000}, "rows": 5, "train_seconds": 61.5}, "standard", {}
        )
        self.assertEqual(
            (camera["training_episodes"], camera["training_samples"], camera["train_seconds"]), (3000, 5, 61.5)
        )


@unittest.skipUnless(HAVE_TORCH, "torch is not installed")
class HeldOutGateTest(unittest.TestCase):
    def test_the_gate_runs_a_test_split_range_and_combines_folders(self):
        # gate.py's held-out path (docs/measured/baseline-gates.md): a range of the test split from the organiser's
        # ground truth, recorded in summary.json, then summed with --combine.
        import json

        ckpt = BASE / "results/h200-2026-11-26/ckpt.pt"
        serve = f"{sys.executable} {BASE / 'serve.py'} --checkpoint {ckpt} --listen 127.0.0.1:0"
        gate = [sys.executable, str(BASE.parent / "gate.py"), "--track", "privileged", "--bin", kitchen_r_bin()]
        with tempfile.TemporaryDirectory() as d:
            for split, rng in (("test", "2-2"), ("dev", "150-150")):
                subprocess.run(
                    gate
                    + [
                        "--out",
                        f"{d}/{split}",
                        "--split",
                        split,
                        "--instructions",
                        rng,
                        "--seed",
                        "2",
                        "--held-out",
                        "--no-offline",
                        "--jobs",
                        "2",
                        "--serve",
                        serve,
                    ],
                    check=True,
                    capture_output=True,
                    text=True,
                    timeout=600,
                )
            part = json.loads(Path(f"{d}/test/summary.json").read_text())
            self.assertEqual(
                (part["eval_split"], part["eval_instructions"], part["eval_seed"], part["held_out"]),
                ("test", "2-2", 2, True),
            )
            self.assertEqual(part["eval_episodes"], 1)
            subprocess.run(
                gate + ["--out", f"{d}/all", "--combine", f"{d}/test", f"{d}/dev"],
                check=True,
                capture_output=True,
                text=True,
                timeout=60,
            )
            both = json.loads(Path(f"{d}/all/summary.json").read_text())
            self.assertTrue(both["held_out"])
            self.assertEqual(both["eval_episodes"], 2)
            self.assertEqual(
                (both["eval_split"], both["eval_instructions"], both["eval_seed"]),
                ("test+dev", "test 2-2, dev 150-150", 2),
            )
            dev = json.loads(Path(f"{d}/dev/summary.json").read_text())
            for k in ("navigation", "pick", "place"):
                self.assertEqual(both["tasks_by_kind"][k], part["tasks_by_kind"][k] + dev["tasks_by_kind"][k])
