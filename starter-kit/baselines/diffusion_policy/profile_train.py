#!/usr/bin/env python3
"""Training steps per second of the baseline's network on this machine, for each way train.py can
run it (eager, channels-last vision weights, torch.compile), on random data of the real shapes:

    python profile_train.py [--batch 256] [--steps 30] [--device auto] [--json OUT]

No dataset is needed, so it can run while `kitchen-r collect` fills the cores. It prints one line
per variant and, last, the train.py flags of the fastest (`best: --compile ...`).
"""

if __name__ == "__main__" and not __package__:  # run as a file: hand over to the installed package's module
    import runpy

    runpy.run_module("kitchen_r_baselines.diffusion_policy.profile_train", run_name="__main__", alter_sys=True)
    raise SystemExit

import argparse
import json
import sys
import time
from pathlib import Path

import torch

from .features import CAMERAS, HORIZON, MAX_WORDS, state_dim
from .model import DEFAULT_CONFIG, DiffusionPolicy

VARIANTS = {
    "eager": [],
    "channels-last": ["--channels-last"],
    "compile": ["--compile"],
    "compile+channels-last": ["--compile", "--channels-last"],
}


def run(variant, args, device):
    torch.manual_seed(0)
    cfg = dict(DEFAULT_CONFIG)
    model = DiffusionPolicy(cfg, 64).to(device).train()
    flags = VARIANTS[variant]
    if "--channels-last" in flags:
        model.cams.to(memory_format=torch.channels_last)
    loss_fn = torch.compile(model.loss) if "--compile" in flags else model.loss
    opt = torch.optim.AdamW(model.parameters(), lr=1e-4)
    B, n, S = args.batch, cfg["n_obs"], cfg["image_size"]
    batch = {
        "images": {c: torch.randint(0, 255, (B, n, S, S, 3), dtype=torch.uint8, device=device) for c in CAMERAS},
        "state": torch.randn(B, n, state_dim(cfg), device=device),
        "words": torch.randint(0, 64, (B, MAX_WORDS), device=device),
        "action": torch.randn(B, HORIZON, 10, device=device).clamp(-1, 1),
    }
    amp = device.type == "cuda"

    def step():
        with torch.autocast(device_type=device.type, dtype=torch.bfloat16, enabled=amp):
            loss = loss_fn(batch["images"], batch["state"], batch["words"], batch["action"])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        return loss

    t = time.time()
    for _ in range(3):
        step()
    if amp:
        torch.cuda.synchronize()
    warm = time.time() - t
    t = time.time()
    for _ in range(args.steps):
        step()
    if amp:
        torch.cuda.synchronize()
    rate = args.steps / (time.time() - t)
    return {"variant": variant, "flags": flags, "steps_per_s": round(rate, 2), "warmup_s": round(warm, 1)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--device", default="auto")
    ap.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated: " + ", ".join(VARIANTS))
    ap.add_argument("--json", default=None, help="also write the results here")
    args = ap.parse_args()
    device = torch.device(("cuda" if torch.cuda.is_available() else "cpu") if args.device == "auto" else args.device)
    results = []
    for v in args.variants.split(","):
        if v not in VARIANTS:
            sys.exit(f"unknown variant {v!r}: choose from {', '.join(VARIANTS)}")
        try:
            r = run(v, args, device)
        except Exception as e:  # noqa: BLE001 — a variant that fails here is reported, not fatal
            r = {"variant": v, "flags": VARIANTS[v], "error": f"{type(e).__name__}: {e}"[:300]}
        results.append(r)
        print(json.dumps(r), flush=True)
    ok = [r for r in results if "steps_per_s" in r]
    if not ok:
        sys.exit("every variant failed")
    best = max(ok, key=lambda r: r["steps_per_s"])
    if args.json:
        Path(args.json).write_text(json.dumps({"device": str(device), "batch": args.batch, "results": results}) + "\n")
    print("best: " + " ".join(best["flags"]), flush=True)


if __name__ == "__main__":
    main()
