#!/usr/bin/env python3
"""Serve a camera-baseline checkpoint over the Kitchen-R policy contract (gRPC), on the standard
track (no privileged observation).

    python serve.py --checkpoint ckpt.pt --listen 127.0.0.1:50051 [--device auto] [--execute 8] [--token T]

Reuses the starter kit's server (`starter-kit/policy_server.py`) with `privileged=False`: GetSpec
asks for both cameras at the size the training images were rendered at (128x128 RAW_RGB8, the
sensors config; the policy resizes them to its training resolution with the same function
training used, features.resize_images), an observation history of 2 and `--execute` actions per
chunk. Concurrent Act calls run through the network in one batch (model.Batcher), and so do
ActBatch calls (`--max-batch`, 16 by default: GetSpec's max_batch, so workers send the pending
decisions of up to 16 episodes in one call), two of which in flight share one pass. On CUDA each
pass replays a CUDA graph captured at start-up for its (padded) batch size (`--no-cuda-graphs`:
eager passes). Prints `listening grpc=HOST:PORT` once it
accepts calls.
"""

if __name__ == "__main__" and not __package__:  # run as a file: hand over to the installed package's module
    import runpy

    runpy.run_module("kitchen_r_baselines.camera.serve", run_name="__main__", alter_sys=True)
    raise SystemExit

import logging
import os

import torch

from .. import serving
from ..common import TaskClock
from . import features as F
from .model import Batcher, load


class CameraRunner:
    """The policy object `policy_server.serve` drives; concurrent Acts run in one batch."""

    def __init__(self, checkpoint, device="cpu", max_batch=32, graphs=True):
        self.model, self.vocab, self.meta = load(checkpoint, device)
        self.vocab_index = {w: i for i, w in enumerate(self.vocab)}
        self.batcher = Batcher(self.model, max_batch=max_batch, graphs=graphs)
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

    def decide_batch(self, observations):
        """An ActBatch call's chunks: one forward pass for the whole batch (and for whatever
        else is waiting: another ActBatch in flight, concurrent Acts)."""
        return [c.tolist() for c in self.batcher.submit_many([self.inputs(o) for o in observations])]


def main(argv=None):
    ap = serving.parser(__doc__.split("\n")[0], F.EXECUTE)
    ap.add_argument(
        "--no-cuda-graphs",
        action="store_true",
        help="on CUDA, run every pass eagerly instead of replaying each batch size's captured CUDA graph",
    )
    args = serving.parse(ap, argv)
    device = serving.torch_device(args.device)
    if device.type == "cpu":
        torch.set_num_threads(max(1, min(8, os.cpu_count() or 1)))
    # Workers keep two ActBatch calls in flight (contract/src/batch.rs): both fit one pass.
    runner = CameraRunner(
        args.checkpoint, device, max_batch=max(args.concurrency, 2 * args.max_batch), graphs=not args.no_cuda_graphs
    )
    meta = runner.meta
    logging.info("checkpoint %s: %s; serving on %s", args.checkpoint, meta, device)
    size = int(meta.get("render_size", F.RENDER_SIZE))
    serving.serve(
        args,
        runner,
        history=F.HISTORY,
        name=f"camera baseline ({meta.get('stage')}, {meta.get('rows')} rows)",
        cameras=[(c, size, size, runner.model.config.get("depth", False)) for c in F.CAMERAS],
    )


if __name__ == "__main__":
    main()
