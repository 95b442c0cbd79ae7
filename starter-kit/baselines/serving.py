"""A checkpoint's serve command, as each control baseline's serve.py runs it: the flags they
share, the device, and the starter kit's policy server (`policy_server.serve`: stub generation,
health service, bearer token, `listening grpc=HOST:PORT` once it accepts calls) around the
baseline's runner, an object with `reset(episode_id, task_index, sub_task)` and `decide(obs)`."""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Sequence
from typing import Any

import policy_server as kit


def parser(description: str, execute: int, device: bool = True) -> argparse.ArgumentParser:
    """The flags every serve.py takes; a baseline adds its own to the parser returned."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--checkpoint", required=True, help="checkpoint written by train.py")
    if device:
        ap.add_argument("--device", default="auto", help="auto (CUDA if available), cpu, cuda, ...")
    add_server_flags(ap, execute, "actions of each 16-action chunk executed before the next Act (contract v1.1)")
    return ap


def add_server_flags(
    ap: argparse.ArgumentParser,
    execute: int,
    execute_help: str,
    concurrency: int = 16,
    concurrency_help: str = "Act calls the policy accepts at once (max_concurrency)",
) -> None:
    """The policy server's flags (what `serve` reads): `--listen`, `--execute`, `--concurrency`,
    `--max-batch`, `--token`, `--proto-dir`; shared with serve commands that name their model
    their own way (kitchen-r-serve-lerobot's `--policy.path`)."""
    ap.add_argument("--listen", default="127.0.0.1:50051", help="HOST:PORT; port 0 picks a free port")
    ap.add_argument("--execute", type=int, default=execute, help=execute_help)
    ap.add_argument("--concurrency", type=int, default=concurrency, help=concurrency_help)
    ap.add_argument(
        "--max-batch",
        type=int,
        default=16,
        help="batched decisions: GetSpec's max_batch, the most episodes' decisions one ActBatch call carries "
        "(one forward pass for them all); 0 or 1 = Acts only",
    )
    ap.add_argument("--token", default=os.environ.get("POLICY_TOKEN"), help="require this bearer token")
    ap.add_argument("--proto-dir", default=None, help="directory with kitchen_r/policy/v1/policy.proto")


def parse(ap: argparse.ArgumentParser, argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The parsed flags, `--execute` and `--max-batch` checked; logging set up."""
    args = ap.parse_args(argv)
    if not 1 <= args.execute <= kit.HORIZON:
        sys.exit(f"--execute must be between 1 and {kit.HORIZON}")
    if args.max_batch < 0:
        sys.exit("--max-batch must be at least 0")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    return args


def torch_device(name: str) -> Any:
    """`--device`: `auto` is CUDA where torch sees a GPU, else the CPU."""
    import torch

    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def serve(
    args: argparse.Namespace,
    runner: Any,
    *,
    history: int,
    name: str,
    privileged: bool = False,
    cameras: list[tuple[Any, ...]] | None = None,
    threads: int | None = None,
) -> None:
    """Serve `runner` with the parsed flags until interrupted: `history` frames per Act,
    `cameras` as `policy_server.serve` takes them (None: both at 128x128), `threads` gRPC
    threads (default `--concurrency` + 4), `--max-batch` declared for ActBatch calls, which
    the runner's `decide_batch(observations)` answers."""
    kit.serve(
        args.listen,
        args.token,
        args.proto_dir,
        threads or args.concurrency + 4,
        runner,
        history,
        args.execute,
        name=name,
        max_concurrency=args.concurrency,
        privileged=privileged,
        cameras=cameras,
        max_batch=args.max_batch,
    )
