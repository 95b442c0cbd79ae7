#!/usr/bin/env python3
"""Serve a privileged-baseline checkpoint over the Kitchen-R policy contract (gRPC), on the
privileged-information track.

    python serve.py --checkpoint ckpt.pt --listen 127.0.0.1:50051 [--execute 8] [--token T]

Reuses the starter kit's server (`starter-kit/policy_server.py`) with `privileged=True`: GetSpec
asks for privileged observations and one 8x8 image it does not read, so the server must run the track
(`control.privileged_track = true`) and ranks the policy on the privileged boards. Prints
`listening grpc=HOST:PORT` once it accepts calls. One forward of a small MLP per Act, on CPU.
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
from model import load  # noqa: E402


class PrivilegedRunner:
    """The policy object `policy_server.serve` drives: one MLP forward per Act."""

    def __init__(self, checkpoint):
        self.model, self.meta = load(checkpoint)
        self.clock = TaskClock(F.CONTROL_DT)

    def reset(self, episode_id, task_index, sub_task):
        self.clock.reset(episode_id)

    def decide(self, obs):
        x = F.from_grpc(obs, self.clock.seconds(obs))
        chunk = self.model.chunk(torch.as_tensor(x[None]))[0].numpy()
        return F.finish(chunk).tolist()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--checkpoint", required=True, help="checkpoint written by train.py")
    ap.add_argument("--listen", default="127.0.0.1:50051", help="HOST:PORT; port 0 picks a free port")
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
    torch.set_num_threads(1)
    runner = PrivilegedRunner(args.checkpoint)
    meta = runner.meta
    logging.info("checkpoint %s: %s", args.checkpoint, meta)
    kit.serve(
        args.listen,
        args.token,
        args.proto_dir,
        args.concurrency + 4,
        runner,
        1,
        args.execute,
        name=f"privileged MLP baseline ({meta.get('stage')}, {meta.get('rows')} rows)",
        max_concurrency=args.concurrency,
        privileged=True,
        # The contract always sends a camera (no request means the default two); this policy
        # reads none, so it asks for the smallest image, which costs the worker nearly nothing.
        cameras=[("base", 8, 8)],
    )


if __name__ == "__main__":
    main()
