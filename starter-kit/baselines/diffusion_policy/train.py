#!/usr/bin/env python3
"""Train the diffusion-policy baseline on a LeRobot export of `kitchen-r collect --format lerobot`.

    python train.py --dataset OUT/lerobot --out ckpt.pt --minutes 60 [--device auto] [--batch 256]

AdamW (vision encoders at 10% of the learning rate, as in the paper), warm-up then cosine decay
over the run (by steps, or by wall-clock time with --minutes), EMA of the weights (the EMA is
what is saved), bf16 autocast on CUDA. Prints a progress line every --log-every seconds, writes
the checkpoint (fp16 EMA weights, config, vocabulary, normalisation statistics; under 16 MiB)
every --save-every minutes and at the end, and `train_log.json` beside it.
"""

if __name__ == "__main__" and not __package__:  # run as a file: hand over to the installed package's module
    import runpy

    runpy.run_module("kitchen_r_baselines.diffusion_policy.train", run_name="__main__", alter_sys=True)
    raise SystemExit

import argparse
import copy
import json
import math
import os
import platform
import queue
import sys
import threading
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from .checkpoint import MAX_CHECKPOINT_BYTES, load_checkpoint, save_checkpoint
from .dataset import LeRobotExport
from .features import CAMERAS, HORIZON, Normaliser
from .model import DEFAULT_CONFIG, DiffusionPolicy


def pick_device(name):
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    d = torch.device(name)
    if d.type == "cuda" and not torch.cuda.is_available():
        sys.exit("--device cuda: torch sees no CUDA device (torch.cuda.is_available() is False)")
    return d


def random_shift(x, pad):
    """Random translation by up to `pad` pixels (Diffusion Policy's crop augmentation, without
    shrinking the image), the same shift for every frame of a sample. x: (B, n, S, S, 3)."""
    if pad <= 0:
        return x
    B, n, S = x.shape[0], x.shape[1], x.shape[2]
    img = x.permute(0, 1, 4, 2, 3).reshape(B, n * 3, S, S).float()
    img = F.pad(img, (pad, pad, pad, pad), mode="replicate")
    dx = torch.randint(0, 2 * pad + 1, (B,), device=x.device)
    dy = torch.randint(0, 2 * pad + 1, (B,), device=x.device)
    ar = torch.arange(S, device=x.device)
    rows = (dy[:, None] + ar[None]).view(B, 1, S, 1).expand(B, n * 3, S, S + 2 * pad)
    img = img.gather(2, rows)
    cols = (dx[:, None] + ar[None]).view(B, 1, 1, S).expand(B, n * 3, S, S)
    img = img.gather(3, cols)
    return img.view(B, n, 3, S, S).permute(0, 1, 3, 4, 2)


class Batches:
    """Random batches assembled by `threads` threads ahead of the training loop."""

    def __init__(self, data, batch, threads, seed):
        self.data, self.batch = data, batch
        self.q = queue.Queue(maxsize=max(2, 2 * threads))
        self.stop = False
        self.threads = [threading.Thread(target=self._run, args=(seed + i,), daemon=True) for i in range(threads)]
        for t in self.threads:
            t.start()

    def _run(self, seed):
        rng = np.random.default_rng(seed)
        while not self.stop:
            b = self.data.batch(rng.integers(0, len(self.data), self.batch))
            out = {
                "images": {
                    c: torch.from_numpy(v).pin_memory() if torch.cuda.is_available() else torch.from_numpy(v)
                    for c, v in b["images"].items()
                },
                "state": torch.from_numpy(b["state"]),
                "words": torch.from_numpy(b["words"]),
                "action": torch.from_numpy(b["action"]),
            }
            while not self.stop:
                try:
                    self.q.put(out, timeout=0.5)
                    break
                except queue.Full:
                    pass

    def next(self):
        return self.q.get()

    def close(self):
        self.stop = True


class DeviceBatches:
    """Random batches gathered on the GPU from a copy of the whole dataset in GPU memory (no
    host-side assembly or transfer per step)."""

    def __init__(self, data, batch, device, seed):
        self.batch, self.device = batch, device
        self.images = {}
        for cam in CAMERAS:
            src = data.images[cam]
            dst = torch.empty(src.shape, dtype=torch.uint8, device=device)
            step = max(1, (1 << 30) // max(1, src[0].nbytes))
            for i in range(0, len(src), step):
                dst[i : i + step].copy_(torch.from_numpy(src[i : i + step]))
            self.images[cam] = dst
        self.state = torch.from_numpy(data.state).to(device)
        self.action = torch.from_numpy(data.action).to(device)
        self.k = torch.from_numpy(data.s_k).to(device)
        self.prev = torch.from_numpy(data.s_prev).to(device)
        self.end = torch.from_numpy(data.s_end).to(device)
        table = np.zeros((int(max(data.task_words)) + 1, len(next(iter(data.task_words.values())))), dtype=np.int64)
        for t, w in data.task_words.items():
            table[t] = w
        self.words = torch.from_numpy(table).to(device)[torch.from_numpy(data.s_task.astype(np.int64)).to(device)]
        self.ar = torch.arange(1, HORIZON + 1, device=device)
        self.gen = torch.Generator(device=device).manual_seed(seed)

    @staticmethod
    def fits(data, device):
        if device.type != "cuda":
            return False
        free, _ = torch.cuda.mem_get_info(device)
        need = sum(a.nbytes for a in data.images.values())
        return need < 0.75 * free

    def next(self):
        i = torch.randint(0, len(self.k), (self.batch,), device=self.device, generator=self.gen)
        k, prev, end = self.k[i], self.prev[i], self.end[i]
        obs = torch.stack([prev, k], dim=1)
        act = torch.minimum(k[:, None] + self.ar[None], end[:, None])
        return {
            "images": {c: v[obs] for c, v in self.images.items()},
            "state": self.state[obs],
            "words": self.words[i],
            "action": self.action[act],
        }

    def close(self):
        pass


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument(
        "--dataset",
        required=True,
        help="the LeRobot export (OUT or OUT/lerobot of `kitchen-r collect --format lerobot`)",
    )
    ap.add_argument("--out", required=True, help="checkpoint file to write (e.g. ckpt.pt)")
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--minutes", type=float, help="train for this many minutes of wall-clock time")
    g.add_argument("--steps", type=int, help="train for this many optimiser steps")
    ap.add_argument("--device", default="auto", help="auto (CUDA if available), cpu, cuda, cuda:1, ...")
    ap.add_argument("--batch", type=int, default=None, help="batch size (default 256 on CUDA, 16 on CPU)")
    ap.add_argument(
        "--workers",
        type=int,
        default=None,
        help="video-decoding processes and batch threads (default: the number of cores)",
    )
    ap.add_argument("--lr", type=float, default=3e-4, help="peak learning rate (vision encoders get 10%% of it)")
    ap.add_argument("--warmup", type=int, default=500, help="linear warm-up steps")
    ap.add_argument(
        "--image-size", type=int, default=DEFAULT_CONFIG["image_size"], help="images are resized to this (square)"
    )
    ap.add_argument(
        "--no-odometry",
        action="store_true",
        help="leave the odometry (base pose relative to the episode's start) out of the state",
    )
    ap.add_argument("--shift", type=int, default=4, help="random-shift augmentation, pixels")
    ap.add_argument("--max-episodes", type=int, default=None, help="use only the first N episodes of the export")
    ap.add_argument("--ema", type=float, default=0.999, help="EMA decay of the saved weights")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--log-every", type=float, default=10.0, help="seconds between progress lines")
    ap.add_argument("--save-every", type=float, default=10.0, help="minutes between intermediate checkpoints")
    ap.add_argument(
        "--data-on",
        choices=["auto", "host", "device"],
        default="auto",
        help="where batches are assembled: auto = in GPU memory when the images fit in 75%% of its free memory, "
        "else host",
    )
    ap.add_argument(
        "--compile",
        action="store_true",
        help="torch.compile the loss (fuses the many small GroupNorm/Mish/attention kernels; a minute "
        "or two of compiling first; see profile_train.py for what it gains on your GPU)",
    )
    ap.add_argument(
        "--channels-last", action="store_true", help="keep the vision encoders' weights in channels-last layout"
    )
    ap.add_argument(
        "--init",
        default=None,
        help="start from this checkpoint's weights, vocabulary and normalisation (fine-tuning on more data)",
    )
    ap.add_argument("--log", default=None, help="training log JSON (default: train_log.json beside --out)")
    args = ap.parse_args()

    torch.manual_seed(args.seed)
    device = pick_device(args.device)
    cores = os.cpu_count() or 1
    workers = args.workers or cores
    batch = args.batch or (256 if device.type == "cuda" else 16)
    if device.type == "cpu":
        torch.set_num_threads(max(1, min(cores, workers)))
    t_start = time.time()
    odometry = not args.no_odometry
    data = LeRobotExport(
        args.dataset, image_size=args.image_size, max_episodes=args.max_episodes, workers=workers, odometry=odometry
    )
    norm = Normaliser.from_export(data.stats, data.state)
    config = {**DEFAULT_CONFIG, "image_size": args.image_size, "odometry": odometry}
    vocab = data.vocab
    if args.init:
        start, norm, vocab, init_meta = load_checkpoint(args.init, "cpu")
        if start.config["odometry"] != odometry or start.config["image_size"] != args.image_size:
            sys.exit(f"--init {args.init}: its odometry/image size differ from this run's; pass the same settings")
        config = start.config
        # The checkpoint's vocabulary: a word it never saw maps to UNK, as when serving.
        data.retokenise(vocab)
        print(f"starting from {args.init} ({init_meta.get('steps')} steps on {init_meta.get('episodes')} episodes)")
    model = DiffusionPolicy(config, len(vocab)).to(device)
    if args.init:
        model.load_state_dict(start.state_dict())
    if args.channels_last:
        model.cams.to(memory_format=torch.channels_last)
    params = sum(p.numel() for p in model.parameters())
    if params * 2 + 1_000_000 > MAX_CHECKPOINT_BYTES:
        sys.exit(f"the model has {params} parameters: its fp16 checkpoint would not fit in 16 MiB")
    ema = copy.deepcopy(model).eval()
    for p in ema.parameters():
        p.requires_grad_(False)
    vision = {id(p) for p in model.vision_parameters()}
    groups = [
        {"params": [p for p in model.parameters() if id(p) in vision], "lr": args.lr * 0.1, "base": 0.1},
        {"params": [p for p in model.parameters() if id(p) not in vision], "lr": args.lr, "base": 1.0},
    ]
    opt = torch.optim.AdamW(groups, lr=args.lr, weight_decay=1e-6, betas=(0.95, 0.999))
    amp = device.type == "cuda"
    hw = (
        torch.cuda.get_device_name(device)
        if device.type == "cuda"
        else f"CPU ({platform.processor() or platform.machine()})"
    )
    print(
        f"training on {hw}: {len(data)} samples from {len(data.episodes)} episodes, batch {batch}, "
        f"{params / 1e6:.2f} M parameters, " + (f"{args.minutes} min" if args.minutes else f"{args.steps} steps"),
        flush=True,
    )
    s_mean, s_std = torch.tensor(norm.s_mean, device=device), torch.tensor(norm.s_std, device=device)
    a_mid, a_half = torch.tensor(norm.a_mid, device=device), torch.tensor(norm.a_half, device=device)
    on_device = args.data_on == "device" or (args.data_on == "auto" and DeviceBatches.fits(data, device))
    if on_device:
        t = time.time()
        feeder = DeviceBatches(data, batch, device, args.seed)
        print(f"dataset copied to {device} memory in {time.time() - t:.1f} s", flush=True)
    else:
        feeder = Batches(data, batch, max(1, min(workers, 6)), args.seed)
    extra = {"episodes": len(data.episodes), "init": args.init, "frames": int(data.frames), "dataset": str(data.root)}
    log_path = Path(args.log) if args.log else Path(args.out).resolve().parent / "train_log.json"
    losses, curve = [], []
    t0 = time.time()
    last_log = last_save = t0
    step = 0

    def progress():
        if args.minutes:
            return (time.time() - t0) / (args.minutes * 60)
        return step / args.steps

    def write(final):
        elapsed = (time.time() - t0) / 60
        recent = float(np.mean(losses[-200:])) if losses else float("nan")
        meta = {**extra, "steps": step, "train_minutes": round(elapsed, 2), "final_loss": recent, "hardware": hw}
        size = save_checkpoint(args.out, ema, config, vocab, norm, meta)
        log = {
            **meta,
            "samples": len(data),
            "batch": batch,
            "parameters": params,
            "total_minutes": round((time.time() - t_start) / 60, 2),
            "cpu_cores": cores,
            "torch": torch.__version__,
            "checkpoint_bytes": size,
            "finished": final,
            "loss_curve": curve,
        }
        log_path.write_text(json.dumps(log, indent=1) + "\n")
        return size

    model.train()
    loss_fn = torch.compile(model.loss) if args.compile else model.loss
    ema_params, model_params = list(ema.parameters()), list(model.parameters())
    pending = []
    while progress() < 1.0:
        b = feeder.next()
        images = {c: random_shift(b["images"][c].to(device, non_blocking=True), args.shift) for c in CAMERAS}
        state = (b["state"].to(device) - s_mean) / s_std
        action = ((b["action"].to(device) - a_mid) / a_half).clamp(-1.5, 1.5)
        words = b["words"].to(device)
        p = progress()
        scale = min(1.0, (step + 1) / args.warmup) * 0.5 * (1 + math.cos(math.pi * min(p, 1.0)))
        for gr in opt.param_groups:
            gr["lr"] = args.lr * gr["base"] * scale
        with torch.autocast(device_type=device.type, dtype=torch.bfloat16, enabled=amp):
            loss = loss_fn(images, state, words, action)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        decay = min(args.ema, (1 + step) / (10 + step))
        with torch.no_grad():
            torch._foreach_lerp_(ema_params, model_params, 1 - decay)
        step += 1
        pending.append(loss.detach())
        now = time.time()
        if now - last_log >= args.log_every or progress() >= 1.0:
            # One device sync per progress line, not per step.
            losses.extend(torch.stack(pending).float().cpu().tolist())
            pending.clear()
            rate = step / (now - t0)
            left = (1 - progress()) * ((args.minutes * 60) if args.minutes else args.steps / rate)
            recent = float(np.mean(losses[-100:]))
            curve.append([step, round(recent, 5)])
            print(
                f"step {step} loss {recent:.4f} {rate:.2f} it/s lr {args.lr * scale:.2e} ETA {left / 60:.1f} min",
                flush=True,
            )
            last_log = now
        if args.save_every and now - last_save >= args.save_every * 60:
            write(False)
            last_save = now
    feeder.close()
    size = write(True)
    print(f"saved {args.out} ({size / 2**20:.2f} MiB) after {step} steps; log {log_path}", flush=True)


if __name__ == "__main__":
    main()
