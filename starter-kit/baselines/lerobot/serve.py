#!/usr/bin/env python3
"""Serve a trained LeRobot checkpoint (lerobot-train's `pretrained_model` folder) over the
Kitchen-R policy contract (gRPC), on the standard track.

    kitchen-r-serve-lerobot --policy.path=outputs/train/act/checkpoints/last/pretrained_model \\
        [--listen 127.0.0.1:50051] [--policy.device auto] [--execute K] [--token T]

Any LeRobot policy whose inputs are features of `kitchen-r collect --format lerobot`
(`observation.images.<camera>`, `observation.state`, `observation.joints`,
`observation.base_pose`: features.py says what each is made of) and whose action is the export's
10-value `action`; ACT and diffusion are tested. GetSpec asks for each camera the policy reads at
the size it was trained on, an observation history of the policy's `n_obs_steps`, and `--execute`
actions of each 16-action chunk (default: the policy's `n_action_steps`, at most 16). Each Act runs
LeRobot's own pre-processor (normalisation, device), the policy's `predict_action_chunk` and its
post-processor (unnormalisation), as lerobot-eval does; an ActBatch call (`--max-batch`) runs its
episodes' decisions through them in one batch; the chunk is padded with its last action or
cut to 16, each quaternion normalised and the gripper clipped to [0, 1]. Prints
`listening grpc=HOST:PORT` once it accepts calls.
"""

if __name__ == "__main__" and not __package__:  # run as a file: hand over to the installed package's module
    import runpy

    runpy.run_module("kitchen_r_baselines.lerobot.serve", run_name="__main__", alter_sys=True)
    raise SystemExit

import argparse
import logging
import os
import sys
import threading
from pathlib import Path
from typing import Any

import numpy as np

from .. import serving
from ..observation import frames
from . import features as F

HORIZON = 16
MAX_HISTORY = 8


def parser() -> argparse.ArgumentParser:
    """The flags, spelled as LeRobot's own tools spell the policy's (`--policy.path`)."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--policy.path",
        dest="policy_path",
        required=True,
        help="a pretrained_model folder written by lerobot-train (config.json, model.safetensors, processors)",
    )
    ap.add_argument(
        "--policy.device", dest="device", default="auto", help="auto (CUDA if available), cpu, cuda, cuda:1, ..."
    )
    serving.add_server_flags(
        ap,
        0,
        "actions of each 16-action chunk executed before the next Act; 0: the policy's n_action_steps (at most 16)",
        concurrency=4,
        concurrency_help="Act calls accepted at once (max_concurrency); they run one at a time",
    )
    return ap


class LeRobotRunner:
    """The policy object `policy_server.serve` drives: one LeRobot policy and its processors."""

    def __init__(self, path: str, device: str = "cpu"):
        import torch
        from lerobot.configs.policies import PreTrainedConfig
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors

        self.torch = torch
        cfg = PreTrainedConfig.from_pretrained(path)
        cfg.pretrained_path = path
        cfg.device = device
        self.policy = get_policy_class(cfg.type).from_pretrained(path, config=cfg)
        self.policy.to(device)
        self.policy.eval()
        self.preprocessor, self.postprocessor = make_pre_post_processors(
            cfg, pretrained_path=path, preprocessor_overrides={"device_processor": {"device": device}}
        )
        self.config = cfg
        self.keys = list(cfg.input_features)
        unknown = [k for k in self.keys if F.camera(k) is None and k not in F.VECTORS]
        if unknown:
            sys.exit(
                f"{path}: the policy reads {unknown}, which the Kitchen-R export has not: it has "
                f"{F.IMAGE_PREFIX}<camera>, {', '.join(F.VECTORS)} (train on `kitchen-r collect --format lerobot`)"
            )
        action = cfg.output_features.get("action")
        if action is None or tuple(action.shape) != (len(F.ACTION_NAMES),):
            sys.exit(f"{path}: the policy's action is {action}, not the export's 10 values {F.ACTION_NAMES}")
        self.history = max(1, int(getattr(cfg, "n_obs_steps", 1) or 1))
        if self.history > MAX_HISTORY:
            sys.exit(
                f"{path}: n_obs_steps {self.history} is more frames than the contract sends (at most {MAX_HISTORY})"
            )
        # The policy object keeps state (diffusion's observation queues), so Acts take turns.
        self.lock = threading.Lock()

    def cameras(self) -> list[tuple[str, int, int]]:
        """(name, width, height) of each camera the policy reads, at its training size."""
        out = []
        for key in self.keys:
            cam = F.camera(key)
            if cam is not None:
                _, height, width = self.config.input_features[key].shape
                out.append((cam, int(width), int(height)))
        return out

    def default_execute(self) -> int:
        return max(1, min(HORIZON, int(getattr(self.config, "n_action_steps", HORIZON) or HORIZON)))

    def reset(self, episode_id: str, task_index: int, sub_task: str) -> None:
        pass

    def batch(self, frames_: list[Any], tasks: list[str]) -> dict[str, Any]:
        """One frame of each episode as lerobot-eval hands a step to the pre-processor: a batch of
        images (N, 3, H, W) float in [0, 1], vectors (N, D) float32, and the task sentences."""
        torch = self.torch
        per = [F.frame_features(f, self.keys) for f in frames_]
        out: dict[str, Any] = {"task": list(tasks)}
        for key in self.keys:
            t = torch.from_numpy(np.stack([p[key] for p in per]))  # a copy: gRPC's bytes are read-only
            out[key] = t.permute(0, 3, 1, 2).float().div(255.0) if F.camera(key) is not None else t
        return self.preprocessor(out)

    def decide(self, obs: Any) -> list[list[float]]:
        return self.decide_batch([obs])[0]

    def decide_batch(self, observations: list[Any]) -> list[list[list[float]]]:
        """One chunk per observation (each from its own episode), in one forward pass."""
        torch = self.torch
        history = [frames(o, self.history) for o in observations]
        tasks = [o.sub_task for o in observations]
        with self.lock, torch.no_grad():
            batches = [self.batch([h[i] for h in history], tasks) for i in range(self.history)]
            actions = self.chunk(batches)  # (N, K, 10), normalised as in training
            real = [self.postprocessor(actions[:, i]) for i in range(actions.shape[1])]
            out = torch.stack([a.reshape(len(observations), -1) for a in real], dim=1).float().cpu().numpy()
        return [F.to_chunk(a, HORIZON) for a in out]

    def chunk(self, batches: list[dict[str, Any]]) -> Any:
        """The policy's chunks for the newest frames, the frames before them as their history: policies
        that keep their observations in queues (diffusion: `n_obs_steps` frames) get the queues
        filled from this Act's frames, so no state is carried from one Act (or episode) to the next."""
        policy = self.policy
        # The pre-processor's output carries an `action` entry (None here): no input of the policy.
        batches = [{k: v for k, v in b.items() if k != "action"} for b in batches]
        last = batches[-1]
        if hasattr(policy, "_queues"):
            from lerobot.policies.utils import populate_queues

            image_keys = list(getattr(self.config, "image_features", {}) or {})

            def stacked(b: dict[str, Any]) -> dict[str, Any]:
                if not image_keys:
                    return b
                return {**b, "observation.images": self.torch.stack([b[k] for k in image_keys], dim=-4)}

            policy.reset()
            for b in batches:
                populate_queues(policy._queues, stacked(b))
            last = stacked(last)
        return policy.predict_action_chunk(last)


def checkpoint_name(path: str) -> str:
    """`outputs/act/checkpoints/last/pretrained_model` -> `act/000003` (`last` is a link to the step)."""
    p = Path(path).resolve()
    if p.name == "pretrained_model":
        p = p.parent
    if p.parent.name == "checkpoints":
        return f"{p.parent.parent.name}/{p.name}"
    return p.name


def main(argv: list[str] | None = None) -> None:
    args = parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    device = str(serving.torch_device(args.device))
    if device == "cpu":
        import torch

        torch.set_num_threads(max(1, min(8, os.cpu_count() or 1)))
    runner = LeRobotRunner(args.policy_path, device)
    if args.execute == 0:
        args.execute = runner.default_execute()
    if not 1 <= args.execute <= HORIZON:
        sys.exit(f"--execute must be between 1 and {HORIZON}")
    if args.max_batch < 0:
        sys.exit("--max-batch must be at least 0")
    logging.info(
        "%s policy from %s on %s: inputs %s, %d frame(s) per Act, %d action(s) executed per chunk",
        runner.config.type,
        args.policy_path,
        device,
        runner.keys,
        runner.history,
        args.execute,
    )
    serving.serve(
        args,
        runner,
        history=runner.history,
        name=f"LeRobot {runner.config.type} ({checkpoint_name(args.policy_path)})",
        cameras=runner.cameras(),
    )


if __name__ == "__main__":
    main()
