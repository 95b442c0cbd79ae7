#!/usr/bin/env python3
"""Serve a trained diffusion-policy checkpoint over the Kitchen-R policy contract (gRPC).

    python serve.py --checkpoint ckpt.pt --listen 0.0.0.0:50051 [--device auto] [--steps 10] [--execute 8]

Reuses the starter kit's server (`starter-kit/policy_server.py`: stub generation, health
service, bearer token) and prints `listening grpc=HOST:PORT` once it accepts calls. GetSpec asks
for both cameras at 128x128 RAW_RGB8 (the export's resolution), an observation history of 2 and
`--execute` actions per chunk. Concurrent Act calls are denoised together in one batch.
"""

if __name__ == "__main__" and not __package__:  # run as a file: hand over to the installed package's module
    import runpy

    runpy.run_module("kitchen_r_baselines.diffusion_policy.serve", run_name="__main__", alter_sys=True)
    raise SystemExit

import hashlib
import logging
import sys

import numpy as np
import torch

from .. import observation, serving
from ..batching import RequestBatcher
from .checkpoint import load_checkpoint
from .features import CAMERAS, deadband, encode_sentence, finish_actions, resize_rgb, state_of_robot


class DiffusionRunner:
    """The policy object `policy_server.serve` drives: one Act in, 16 actions out."""

    def __init__(self, checkpoint, device, steps, max_batch=32, deadband=(0.0, 0.0)):
        self.device = device
        self.model, self.norm, self.vocab, self.meta = load_checkpoint(checkpoint, device)
        self.vocab_index = {w: i for i, w in enumerate(self.vocab)}
        self.cfg = self.model.config
        self.steps = steps
        self.deadband = deadband
        self.batcher = RequestBatcher(self._run, max_batch)

    def reset(self, episode_id, task_index, sub_task):
        pass  # no memory across Act calls: each observation carries its own history

    def features(self, obs):
        frames = observation.frames(obs, self.cfg["n_obs"])
        size = self.cfg["image_size"]
        images = {c: np.stack([resize_rgb(observation.rgb(f, c), size) for f in frames]) for c in CAMERAS}
        odometry = self.cfg.get("odometry", False)
        state = np.array([state_of_robot(f.robot, odometry) for f in frames], dtype=np.float32)
        words = np.array(encode_sentence(obs.sub_task, self.vocab_index), dtype=np.int64)
        # The same observation always gets the same noise, so answers are reproducible.
        seed = int.from_bytes(hashlib.sha256(f"{obs.episode_id}/{obs.step}".encode()).digest()[:8], "little")
        noise = torch.randn((self.cfg["horizon"], 10), generator=torch.Generator().manual_seed(seed))
        return images, self.norm.state(state), words, noise

    def decide(self, obs):
        return self.batcher.submit(self.features(obs)).tolist()

    def decide_batch(self, observations):
        """An ActBatch call's chunks (`--max-batch`): denoised together, as concurrent Acts are."""
        return [y.tolist() for y in self.batcher.submit_many([self.features(o) for o in observations])]

    @torch.no_grad()
    def _run(self, batch):
        """Denoise the chunks of a batch of `features` at once."""
        d = self.device
        images = {c: torch.from_numpy(np.stack([x[0][c] for x in batch])).to(d) for c in CAMERAS}
        state = torch.from_numpy(np.stack([x[1] for x in batch])).to(d)
        words = torch.from_numpy(np.stack([x[2] for x in batch])).to(d)
        noise = torch.stack([x[3] for x in batch])
        out = self.model.sample(images, state, words, steps=self.steps, noise=noise).float().cpu().numpy()
        return [finish_actions(deadband(self.norm.unaction(a), *self.deadband)) for a in out]


def main(argv=None):
    ap = serving.parser(__doc__.split("\n")[0], execute=8)
    ap.add_argument("--steps", type=int, default=10, help="DDIM denoising steps per chunk (of the 100 training steps)")
    ap.add_argument(
        "--deadband",
        default="0,0",
        help="V,OMEGA: base commands below V m/s and OMEGA rad/s are sent as 0 (e.g. 0.01,0.02); off by default",
    )
    ap.add_argument("--threads", type=int, default=None, help="gRPC threads (default: --concurrency + 4)")
    args = serving.parse(ap, argv)
    if not 1 <= args.steps <= 100:
        sys.exit("--steps must be between 1 and 100")
    device = serving.torch_device(args.device)
    try:
        band = tuple(float(x) for x in args.deadband.split(","))
        if len(band) != 2 or min(band) < 0:
            raise ValueError
    except ValueError:
        sys.exit(f"--deadband {args.deadband!r}: give two non-negative numbers, V,OMEGA (e.g. 0.01,0.02)")
    runner = DiffusionRunner(args.checkpoint, device, args.steps, deadband=band)
    meta = runner.meta
    logging.info(
        "checkpoint %s: %s episodes, %s steps, on %s; serving on %s with %d denoising steps",
        args.checkpoint,
        meta.get("episodes"),
        meta.get("steps"),
        meta.get("hardware"),
        device,
        args.steps,
    )
    serving.serve(
        args,
        runner,
        history=runner.cfg["n_obs"],
        name=f"diffusion-policy baseline ({meta.get('episodes')} episodes, {meta.get('steps')} steps)",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
