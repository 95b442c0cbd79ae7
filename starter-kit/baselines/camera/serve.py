#!/usr/bin/env python3
"""Serve a camera-baseline checkpoint over the Kitchen-R policy contract (gRPC), on the standard
track (no privileged observation).

    python serve.py --checkpoint ckpt.pt --listen 127.0.0.1:50051 [--device auto] [--execute 8] [--token T]

Reuses the starter kit's server (`starter-kit/policy_server.py`) with `privileged=False`: GetSpec
asks for both cameras at the size the training images were rendered at (128x128 RAW_RGB8, the
sensors config; the policy resizes them to its training resolution with the same function
training used, features.resize_images), an observation history of 2 and `--execute` actions per
chunk. Concurrent Act calls run through the network in one batch (model.Batcher). Prints
`listening grpc=HOST:PORT` once it accepts calls.
"""

import argparse
import logging
import os
import sys
from pathlib import Path

import torch

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(1, str(HERE.parent.parent))  # starter-kit/, for policy_server
sys.path.insert(2, str(HERE.parent))  # baselines/, for common

import features as F  # noqa: E402
import policy_server as kit  # noqa: E402
from common import TaskClock  # noqa: E402
from model import Batcher, load  # noqa: E402


class CameraRunner:
    """The policy object `policy_server.serve` drives; concurrent Acts run in one batch."""

    def __init__(self, checkpoint, device="cpu", max_batch=32):
        self.model, self.vocab, self.meta = load(checkpoint, device)
        self.vocab_index = {w: i for i, w in enumerate(self.vocab)}
        self.batcher = Batcher(self.model, max_batch=max_batch)
        self.clock = TaskClock(F.CONTROL_DT)
        # Before the port opens: on CUDA the first forward of each batch shape autotunes for
        # seconds (8.4 s measured on an H100), which would land on an episode's first Act and
        # its 10 s deadline.
        self.batcher.warm_up()

    def reset(self, episode_id, task_index, sub_task):
        self.clock.reset(episode_id)

    def inputs(self, obs):
        images, state = F.from_grpc(obs, self.clock.seconds(obs), self.model.config.get("depth", False))
        return images, state, F.encode(obs.sub_task, self.vocab_index)

    def decide(self, obs):
        return self.batcher.decide(*self.inputs(obs)).tolist()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--checkpoint", required=True, help="checkpoint written by train.py")
    ap.add_argument("--listen", default="127.0.0.1:50051", help="HOST:PORT; port 0 picks a free port")
    ap.add_argument("--device", default="auto", help="auto (CUDA if available), cpu, cuda, ...")
    ap.add_argument("--execute", type=int, default=F.EXECUTE, help="actions of each chunk executed before the next Act")
    ap.add_argument(
        "--concurrency", type=int, default=16, help="Act calls the policy accepts at once (max_concurrency)"
    )
    ap.add_argument("--token", default=os.environ.get("POLICY_TOKEN"), help="require this bearer token")
    ap.add_argument("--proto-dir", default=None, help="directory with kitchen_r/policy/v1/policy.proto")
    args = ap.parse_args()
    if not 1 <= args.execute <= kit.HORIZON:
        sys.exit(f"--execute must be between 1 and {kit.HORIZON}")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    device = torch.device(
        "cuda"
        if args.device == "auto" and torch.cuda.is_available()
        else ("cpu" if args.device == "auto" else args.device)
    )
    if device.type == "cpu":
        torch.set_num_threads(max(1, min(8, os.cpu_count() or 1)))
    runner = CameraRunner(args.checkpoint, device, max_batch=args.concurrency)
    meta = runner.meta
    logging.info("checkpoint %s: %s; serving on %s", args.checkpoint, meta, device)
    size = int(meta.get("render_size", F.RENDER_SIZE))
    kit.serve(
        args.listen,
        args.token,
        args.proto_dir,
        args.concurrency + 4,
        runner,
        F.HISTORY,
        args.execute,
        name=f"camera baseline ({meta.get('stage')}, {meta.get('rows')} rows)",
        max_concurrency=args.concurrency,
        privileged=False,
        cameras=[(c, size, size, runner.model.config.get("depth", False)) for c in F.CAMERAS],
    )


if __name__ == "__main__":
    main()
