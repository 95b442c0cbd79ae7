#!/usr/bin/env python3
"""Serve a trained diffusion-policy checkpoint over the Kitchen-R policy contract (gRPC).

    python serve.py --checkpoint ckpt.pt --listen 0.0.0.0:50051 [--device auto] [--steps 10] [--execute 8]

Reuses the starter kit's server (`starter-kit/policy_server.py`: stub generation, health
service, bearer token) and prints `listening grpc=HOST:PORT` once it accepts calls. GetSpec asks
for both cameras at 128x128 RAW_RGB8 (the export's resolution), an observation history of 2 and
`--execute` actions per chunk. Concurrent Act calls are denoised together in one batch.
"""

import argparse
import hashlib
import logging
import os
import sys
import threading
from pathlib import Path

import numpy as np
import torch

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(1, str(HERE.parent.parent))  # starter-kit/, for policy_server

import policy_server as kit  # noqa: E402
from checkpoint import load_checkpoint  # noqa: E402
from features import CAMERAS, deadband, encode_sentence, finish_actions, resize_rgb, state_of_robot  # noqa: E402


def image_of(frame, cam):
    for im in frame.images:
        if im.camera == cam:
            if len(im.data) != im.width * im.height * 3:
                raise ValueError(f"`{cam}` image is not RAW_RGB8 {im.width}x{im.height} (GetSpec asks for RAW_RGB8)")
            return np.frombuffer(im.data, dtype=np.uint8).reshape(im.height, im.width, 3)
    raise ValueError(f"observation has no `{cam}` image; the policy asked for cameras {CAMERAS}")


class DiffusionRunner:
    """The policy object `policy_server.serve` drives: one Act in, 16 actions out."""

    def __init__(self, checkpoint, device, steps, max_batch=32, deadband=(0.0, 0.0)):
        self.device = device
        self.model, self.norm, self.vocab, self.meta = load_checkpoint(checkpoint, device)
        self.vocab_index = {w: i for i, w in enumerate(self.vocab)}
        self.cfg = self.model.config
        self.steps = steps
        self.deadband = deadband
        self.max_batch = max_batch
        self.cond = threading.Condition()
        self.pending = []
        threading.Thread(target=self._loop, daemon=True).start()

    def reset(self, episode_id, task_index, sub_task):
        pass  # no memory across Act calls: each observation carries its own history

    def features(self, obs):
        frames = kit.frames(obs)
        n = self.cfg["n_obs"]
        frames = [frames[0]] * max(0, n - len(frames)) + frames[-n:]
        size = self.cfg["image_size"]
        images = {c: np.stack([resize_rgb(image_of(f, c), size) for f in frames]) for c in CAMERAS}
        odometry = self.cfg.get("odometry", False)
        state = np.array([state_of_robot(f.robot, odometry) for f in frames], dtype=np.float32)
        words = np.array(encode_sentence(obs.sub_task, self.vocab_index), dtype=np.int64)
        # The same observation always gets the same noise, so answers are reproducible.
        seed = int.from_bytes(hashlib.sha256(f"{obs.episode_id}/{obs.step}".encode()).digest()[:8], "little")
        noise = torch.randn((self.cfg["horizon"], 10), generator=torch.Generator().manual_seed(seed))
        return images, self.norm.state(state), words, noise

    def decide(self, obs):
        item = {"x": self.features(obs), "done": threading.Event()}
        with self.cond:
            self.pending.append(item)
            self.cond.notify()
        item["done"].wait()
        if "error" in item:
            raise item["error"]
        return item["y"].tolist()

    def _loop(self):
        while True:
            with self.cond:
                while not self.pending:
                    self.cond.wait()
                batch, self.pending = self.pending[: self.max_batch], self.pending[self.max_batch :]
            try:
                self._run(batch)
            except Exception as e:  # noqa: BLE001 — reported to each waiting call
                logging.exception("denoising failed")
                for it in batch:
                    it["error"] = e
            for it in batch:
                it["done"].set()

    @torch.no_grad()
    def _run(self, batch):
        d = self.device
        images = {c: torch.from_numpy(np.stack([it["x"][0][c] for it in batch])).to(d) for c in CAMERAS}
        state = torch.from_numpy(np.stack([it["x"][1] for it in batch])).to(d)
        words = torch.from_numpy(np.stack([it["x"][2] for it in batch])).to(d)
        noise = torch.stack([it["x"][3] for it in batch])
        out = self.model.sample(images, state, words, steps=self.steps, noise=noise).float().cpu().numpy()
        for it, a in zip(batch, out):
            it["y"] = finish_actions(deadband(self.norm.unaction(a), *self.deadband))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--checkpoint", required=True, help="checkpoint written by train.py")
    ap.add_argument("--listen", default="127.0.0.1:50051", help="HOST:PORT; port 0 picks a free port")
    ap.add_argument("--device", default="auto", help="auto (CUDA if available), cpu, cuda, ...")
    ap.add_argument("--steps", type=int, default=10, help="DDIM denoising steps per chunk (of the 100 training steps)")
    ap.add_argument(
        "--execute",
        type=int,
        default=8,
        help="actions of each 16-action chunk executed before the next Act (contract v1.1)",
    )
    ap.add_argument(
        "--concurrency", type=int, default=16, help="Act calls the policy accepts at once (max_concurrency)"
    )
    ap.add_argument(
        "--deadband",
        default="0,0",
        help="V,OMEGA: base commands below V m/s and OMEGA rad/s are sent as 0 (e.g. 0.01,0.02); off by default",
    )
    ap.add_argument("--token", default=os.environ.get("POLICY_TOKEN"), help="require this bearer token")
    ap.add_argument("--proto-dir", default=None, help="directory with kitchen_r/policy/v1/policy.proto")
    ap.add_argument("--threads", type=int, default=None, help="gRPC threads (default: --concurrency + 4)")
    args = ap.parse_args()
    if not 1 <= args.execute <= kit.HORIZON:
        sys.exit(f"--execute must be between 1 and {kit.HORIZON}")
    if not 1 <= args.steps <= 100:
        sys.exit("--steps must be between 1 and 100")
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    device = torch.device(
        "cuda"
        if args.device == "auto" and torch.cuda.is_available()
        else ("cpu" if args.device == "auto" else args.device)
    )
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
    kit.serve(
        args.listen,
        args.token,
        args.proto_dir,
        args.threads or args.concurrency + 4,
        runner,
        runner.cfg["n_obs"],
        args.execute,
        name=f"diffusion-policy baseline ({meta.get('episodes')} episodes, {meta.get('steps')} steps)",
        max_concurrency=args.concurrency,
    )


if __name__ == "__main__":
    main()
