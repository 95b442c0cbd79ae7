#!/usr/bin/env python3
"""Where a camera-baseline checkpoint goes wrong on manipulation: each pick and place task of the
first N dev instructions runs alone (`KitchenR/Task-v0`, from the expert's state at its start,
randomised) with the policy driving, and every 4th decision prints the policy's first action
next to the expert's label for the same state: base command `v, w`, hand target `x, y, z` (base
frame) and gripper.

    python3 diagnose.py --checkpoint ckpt.pt [--instructions 3] [--max-steps 400] [--device cpu]
"""

if __name__ == "__main__" and not __package__:  # run as a file: hand over to the installed package's module
    import runpy

    runpy.run_module("kitchen_r_baselines.camera.diagnose", run_name="__main__", alter_sys=True)
    raise SystemExit

import argparse

import numpy as np
import torch

from . import features as F
from .model import Batcher, load


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--checkpoint", required=True)
    ap.add_argument("--instructions", type=int, default=3)
    ap.add_argument("--max-steps", type=int, default=400, help="control steps per task")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args()
    from gym_kitchen_r import KitchenRTaskEnv

    model, vocab, _ = load(args.checkpoint, args.device)
    index = {w: i for i, w in enumerate(vocab)}
    batcher = Batcher(model)
    depth = model.config.get("depth", False)
    env = KitchenRTaskEnv(images=True, depth=depth, history=2, expert=True, randomise=True)
    for ins in env.instruction_ids()[: args.instructions]:
        for ti, step in enumerate(env.instruction_of(ins)["plan"]):
            if not step.startswith(("pick", "place")):
                continue
            obs, info = env.reset(seed=args.seed, options={"instruction": ins, "task": ti})
            steps, done, rows, success = 0, False, [], False
            while not done and steps < args.max_steps:
                ims, st = F.from_env(obs, steps * F.CONTROL_DT, depth)
                chunk = batcher.decide(ims, st, F.encode(obs["sub_task"], index))
                rows.append((steps, chunk[0], np.asarray(info["expert_chunk"])[0]))
                for a in chunk[: F.EXECUTE]:
                    obs, _, done, _, info = env.step(a)
                    steps += 1
                    success |= any(t["success"] for t in info["tasks_ended"])
                    if done:
                        break
            print(f"{ins} task {ti} `{step}`: {'succeeded' if success else 'failed'} after {steps} steps")
            for t, p, e in rows[::4]:
                print(
                    f"  t={t * F.CONTROL_DT:5.1f}s  v,w policy {np.round(p[:2], 3)} expert {np.round(e[:2], 3)}"
                    f" | hand policy {np.round(p[2:5], 2)} expert {np.round(e[2:5], 2)}"
                    f" | gripper {p[9]:.2f} {e[9]:.2f}"
                )
    env.close()


if __name__ == "__main__":
    torch.set_num_threads(2)
    main()
