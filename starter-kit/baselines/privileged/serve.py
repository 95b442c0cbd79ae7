#!/usr/bin/env python3
"""Serve a privileged-baseline checkpoint over the Kitchen-R policy contract (gRPC), on the
privileged-information track.

    python serve.py --checkpoint ckpt.pt --listen 127.0.0.1:50051 [--execute 8] [--token T]

Reuses the starter kit's server (`starter-kit/policy_server.py`) with `privileged=True`: GetSpec
asks for privileged observations and one 8x8 image it does not read, so the server must run the track
(`control.privileged_track = true`) and ranks the policy on the privileged boards. Prints
`listening grpc=HOST:PORT` once it accepts calls. One forward of a small MLP per Act, on CPU, and
one per ActBatch call for all its observations (`--max-batch`, 16 by default).
"""

if __name__ == "__main__" and not __package__:  # run as a file: hand over to the installed package's module
    import runpy

    runpy.run_module("kitchen_r_baselines.privileged.serve", run_name="__main__", alter_sys=True)
    raise SystemExit

import logging

import numpy as np
import torch

from .. import serving
from ..common import TaskClock
from . import features as F
from .model import load


class PrivilegedRunner:
    """The policy object `policy_server.serve` drives: one MLP forward per Act or ActBatch."""

    def __init__(self, checkpoint):
        self.model, self.meta = load(checkpoint)
        self.clock = TaskClock(F.CONTROL_DT)

    def reset(self, episode_id, task_index, sub_task):
        self.clock.reset(episode_id)

    def decide(self, obs):
        x = F.from_grpc(obs, self.clock.seconds(obs))
        chunk = self.model.chunk(torch.as_tensor(x[None]))[0].numpy()
        return F.finish(chunk).tolist()

    def decide_batch(self, observations):
        """An ActBatch call's chunks: one forward of the MLP for the whole batch."""
        x = np.stack([F.from_grpc(o, self.clock.seconds(o)) for o in observations])
        chunks = self.model.chunk(torch.as_tensor(x)).numpy()
        return [F.finish(c).tolist() for c in chunks]


def main(argv=None):
    args = serving.parse(serving.parser(__doc__.split("\n")[0], F.EXECUTE, device=False), argv)
    torch.set_num_threads(1)
    runner = PrivilegedRunner(args.checkpoint)
    meta = runner.meta
    logging.info("checkpoint %s: %s", args.checkpoint, meta)
    serving.serve(
        args,
        runner,
        history=1,
        name=f"privileged MLP baseline ({meta.get('stage')}, {meta.get('rows')} rows)",
        privileged=True,
        # The contract always sends a camera (no request means the default two); this policy
        # reads none, so it asks for the smallest image, which costs the worker nearly nothing.
        cameras=[("base", 8, 8)],
    )


if __name__ == "__main__":
    main()
