#!/usr/bin/env python3
"""How long the served camera baseline takes per decision, apart from gRPC: the features of one
observation (`CameraRunner.inputs`, on a synthetic 128x128 two-camera observation with a
history of 2), then one pass of the network at batch sizes 1 to 64 (`Batcher._decide`: resize,
forward, chunks made valid), wall and CPU milliseconds. Equal wall and CPU times mean the pass
is bound by launching kernels, not by the GPU: batching then costs almost nothing per decision.

    python3 starter-kit/baselines/camera/forward_speed.py CKPT [--device auto] [--repeats 20] [--eager]

On CUDA the passes replay the served CUDA graphs unless `--eager`; run it both ways to compare.
"""

if __name__ == "__main__" and not __package__:  # run as a file: hand over to the installed package's module
    import runpy

    runpy.run_module("kitchen_r_baselines.camera.forward_speed", run_name="__main__", alter_sys=True)
    raise SystemExit

import argparse
import json
import time
import types

import numpy as np
import torch

from .. import serving
from .model import Batcher
from .serve import CameraRunner


def synthetic_observation(size=128):
    """What a worker sends this policy (gRPC field names), with random images."""
    rng = np.random.default_rng(0)

    def frame(step):
        images = [
            types.SimpleNamespace(
                camera=c, width=size, height=size, data=rng.integers(0, 255, (size, size, 3), np.uint8).tobytes()
            )
            for c in ("base", "gripper")
        ]
        robot = types.SimpleNamespace(
            base_v=0.1,
            base_omega=0.0,
            arm_joints=[0.0] * 6,
            gripper=0.0,
            ee_pose=[0.0] * 6 + [1.0],
            base_x=0.0,
            base_y=0.0,
            base_yaw=0.0,
        )
        return types.SimpleNamespace(images=images, depth=[], robot=robot, previous_action=[0.0] * 10, step=step)

    obs = frame(5)
    obs.history, obs.sub_task, obs.episode_id, obs.task_index = [frame(4)], "pick up the red cup", "e", 0
    return obs


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("checkpoint")
    ap.add_argument("--device", default="auto")
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--eager", action="store_true", help="no CUDA graphs (as serve.py --no-cuda-graphs)")
    args = ap.parse_args(argv)
    device = serving.torch_device(args.device)
    sync = torch.cuda.synchronize if device.type == "cuda" else (lambda: None)
    runner = CameraRunner(args.checkpoint, device, max_batch=64, graphs=not args.eager)
    obs = synthetic_observation()
    x = runner.inputs(obs)
    t = time.perf_counter()
    for _ in range(200):
        runner.inputs(obs)
    result = {
        "device": str(device),
        "cuda_graphs": runner.batcher.graphs is not None and device.type == "cuda",
        "inputs_ms": round((time.perf_counter() - t) / 200 * 1e3, 3),
        "passes": [],
    }
    for n in (1, 2, 4, 8, 16, 32, 64):
        for _ in range(3):
            runner.batcher._decide([x] * n)
        sync()
        t, c = time.perf_counter(), time.process_time()
        for _ in range(args.repeats):
            runner.batcher._decide([x] * n)
        sync()
        wall = (time.perf_counter() - t) / args.repeats * 1e3
        cpu = (time.process_time() - c) / args.repeats * 1e3
        result["passes"].append(
            {"batch": n, "wall_ms": round(wall, 2), "cpu_ms": round(cpu, 2), "per_decision_ms": round(wall / n, 3)}
        )
    if result["cuda_graphs"]:
        # A replayed graph must answer what the eager pass answers (bf16 kernels may differ in
        # the last bits between the two, not more).
        eager = Batcher(runner.model, max_batch=64, graphs=False)
        for n in (1, 16):
            a, b = runner.batcher._decide([x] * n), eager._decide([x] * n)
            result[f"graph_vs_eager_max_abs_diff_batch_{n}"] = float(np.abs(np.array(a) - np.array(b)).max())
    print(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
