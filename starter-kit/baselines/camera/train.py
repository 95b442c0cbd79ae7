#!/usr/bin/env python3
"""Train the standard-track camera baseline from live simulators: behaviour cloning on the
expert's streamed samples (both cameras, 2-frame history), then DAgger rounds in which the policy
drives and the expert labels the states it reaches.

    python train.py --out runs/cam [--episodes 1200] [--workers N] [--bc-steps 20000]
                    [--rounds 2] [--round-episodes 64] [--round-steps 4000] [--envs N]
                    [--collect-minutes M] [--bc-minutes M] [--rollout-minutes M] [--round-minutes M]

1. `gym_kitchen_r.ExpertSamples(images=True, history=2, randomise=True)`: the oracle runs
   collection's episodes (seed `--seed`) on `--workers` Rust threads; one row per decision
   (features.py), images resized to `--image-size` on the training device and kept there as
   uint8, the expert's 16x10 chunk as the label.
2. model.py's network regresses the normalised chunk (MSE, AdamW, warm-up + cosine decay, bf16
   autocast on CUDA, random-shift augmentation); the EfficientNet trunk learns at
   `--encoder-lr-scale` (0.1) times the head's rate.
3. Each DAgger round runs `--round-episodes` randomised dev episodes in `KitchenREnv`s (one per
   thread, `--envs`) with the policy driving (8 of 16 actions per decision; the threads' decisions
   batched into one forward) and the expert's chunk recorded at every decision; the rows join
   the training set and training goes on (a fresh cosine at `--round-lr-scale` of the peak).

Every phase stops at its step/episode count or its `--*-minutes` budget (0: none), whichever
comes first; the cosine follows whichever is further along. Progress lines go to stdout;
`train_log.json` in `--out` keeps every phase's figures (rows, SR per task kind while the policy
drove, loss, seconds, hardware) and `ckpt.pt` is written after every phase.
"""

if __name__ == "__main__" and not __package__:  # run as a file: hand over to the installed package's module
    import runpy

    runpy.run_module("kitchen_r_baselines.camera.train", run_name="__main__", alter_sys=True)
    raise SystemExit

import argparse
import json
import math
import os
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import torch

from ..common import add_round_args, sr_by_kind, train_instructions
from . import features as F
from .model import Batcher, CameraPolicy, load, save

# id(model) -> its torch.compile wrapper (kept off the module: not in the state dict)
COMPILED: dict[int, torch.nn.Module] = {}


def log(msg):
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


class Rows:
    """The training set on the training device: images uint8 (N, cameras, HISTORY, S, S, 3),
    state float32, word ids int16, labels float32 (N, 160), the auxiliary goal target and its
    mask (N, AUX_DIM; zeros when no privileged observation was streamed). `capacity`: rows to
    allocate at once (the run's estimate): growing a tensor copies it, and at 2,700 episodes
    (about 40 GiB) the old and new copies together would not fit an 80 GiB card. Grows by 1.25x
    past it."""

    def __init__(self, size, device, capacity=1024):
        self.size, self.device, self.n, self.capacity = size, device, 0, capacity
        self.t = None

    def add(self, images, state, words, y, aux, aux_mask):
        """Raw rows (numpy; images at render size, resized here on the device)."""
        ims = F.resize_images(torch.from_numpy(np.stack(images)).to(self.device), self.size)
        new = {
            "images": ims,
            "state": torch.from_numpy(np.stack(state)).to(self.device),
            "words": torch.from_numpy(np.stack(words).astype(np.int16)).to(self.device),
            "y": torch.from_numpy(np.stack(y).astype(np.float32)).to(self.device),
            "aux": torch.from_numpy(np.stack(aux)).to(self.device),
            "aux_mask": torch.from_numpy(np.stack(aux_mask)).to(self.device),
        }
        k = len(ims)
        if self.t is None or self.n + k > len(self.t["y"]):
            cap = max(self.n + k, int(1.25 * len(self.t["y"])) if self.t else self.capacity, 1024)
            grown = {
                n: torch.empty((cap,) + tuple(v.shape[1:]), dtype=v.dtype, device=self.device) for n, v in new.items()
            }
            if self.t is not None:
                for n in grown:
                    grown[n][: self.n] = self.t[n][: self.n]
            self.t = grown
        for n, v in new.items():
            self.t[n][self.n : self.n + k] = v
        self.n += k

    def batch(self, idx):
        return self.t["images"][idx], self.t["state"][idx], self.t["words"][idx].long(), self.t["y"][idx]

    def aux_batch(self, idx):
        return self.t["aux"][idx], self.t["aux_mask"][idx]

    def view(self, name):
        return self.t[name][: self.n]

    def nbytes(self):
        return sum(v.element_size() * v.numel() for v in self.t.values()) if self.t else 0


def empty_rows():
    """Staged rows: images, state, words, label, auxiliary target, its mask."""
    return ([], [], [], [], [], [])


def aux_of(privileged):
    """The auxiliary target of a decision, zeros (masked out) without a privileged observation."""
    if privileged is None:
        return np.zeros(F.AUX_DIM, np.float32), np.zeros(F.AUX_DIM, np.float32)
    return F.aux_target(privileged)


def expert_rows(rows, vocab_index, args, training_ids):
    """Stream the expert's samples into `rows`; stops at `--collect-minutes`."""
    from gym_kitchen_r import ExpertSamples

    t0 = time.time()
    deadline = t0 + args.collect_minutes * 60 if args.collect_minutes > 0 else math.inf
    first, staged, n_ep, episodes = {}, empty_rows(), -1, 0
    aux = args.aux_weight > 0
    stream = ExpertSamples(
        episodes=args.episodes,
        workers=args.workers,
        seed=args.seed,
        images=True,
        history=F.HISTORY,
        randomise=True,
        max_tasks=args.max_tasks,
        privileged_observation=aux,
        depth=args.depth,
        instructions=training_ids,
    )
    for s in stream:
        start = first.setdefault((s["episode_index"], s["task_index"]), s["step"])
        ims, st = F.from_env(s, (s["step"] - start) * F.CONTROL_DT, args.depth)
        target = aux_of(s.get("privileged_observation"))
        for lst, v in zip(
            staged, (ims, st, F.encode(s["sub_task"], vocab_index), np.asarray(s["action"]).reshape(-1), *target)
        ):
            lst.append(v)
        if len(staged[0]) >= 512:
            rows.add(*staged)
            staged = empty_rows()
        if s["episode_index"] != n_ep:
            n_ep = s["episode_index"]
            episodes = n_ep  # episodes completed before this one
            if n_ep % max(1, args.episodes // 10) == 0:
                el = time.time() - t0
                log(
                    f"expert episodes {n_ep}/{args.episodes}: {rows.n + len(staged[0])} rows, {el:.0f} s "
                    f"({(rows.n + len(staged[0])) / max(el, 1e-9):.0f} rows/s)"
                )
            if time.time() > deadline:
                log("collection budget spent")
                break
    else:
        episodes = args.episodes
    if staged[0]:
        rows.add(*staged)
    secs = time.time() - t0
    log(
        f"expert data: {episodes} episodes, {rows.n} rows in {secs:.1f} s ({rows.n / max(secs, 1e-9):.0f} rows/s), "
        f"{rows.nbytes() / 2**30:.2f} GiB on {rows.device}"
    )
    return {"episodes": episodes, "rows": rows.n, "seconds": secs, "rows_per_s": rows.n / max(secs, 1e-9)}


def make_optimizer(model, args):
    groups = [
        {"params": model.head_parameters(), "base_lr": args.lr},
        {"params": model.encoder_parameters(), "base_lr": args.lr * args.encoder_lr_scale},
    ]
    return torch.optim.AdamW(groups, lr=args.lr, weight_decay=args.weight_decay, betas=(0.9, 0.98))


def fit(model, opt, rows, steps, minutes, peak, args, tag, device):
    """`steps` optimiser steps (or `minutes`), warm-up then cosine from `peak` x base lr."""
    model.train()
    net = COMPILED.get(id(model), model)
    amp = device.type == "cuda"
    t0 = time.time()
    budget = minutes * 60 if minutes > 0 else math.inf
    warm = min(args.warmup, max(1, steps // 10))
    total, count, loss_val, i = torch.zeros((), device=device), 0, float("nan"), 0
    report, last = max(1, steps // 10), t0
    while i < steps:
        progress = max(i / steps, (time.time() - t0) / budget)
        if progress >= 1:
            log(f"{tag}: time budget spent at step {i}")
            break
        f = peak * (min(1.0, (i + 1) / warm) if i < warm else 0.5 * (1 + math.cos(math.pi * progress)))
        for g in opt.param_groups:
            g["lr"] = g["base_lr"] * f
        idx = torch.randint(0, rows.n, (args.batch,), device=device)
        ims, st, wd, y = rows.batch(idx)
        with torch.autocast("cuda", dtype=torch.bfloat16, enabled=amp):
            out = net(ims, st, wd, shift=args.shift, with_aux=model.aux is not None)
        pred = out[0] if model.aux is not None else out
        loss = ((pred.float() - model.normalise_y(y)) ** 2).mean()
        if model.aux is not None:
            target, mask = rows.aux_batch(idx)
            loss = loss + args.aux_weight * (((out[1] - target) ** 2) * mask).sum() / mask.sum().clamp_min(1.0)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
        opt.step()
        total += loss.detach()
        count += 1
        i += 1
        if i % report == 0 or i == steps or time.time() - last > 30:
            last = time.time()
            loss_val = (total / count).item()
            el = time.time() - t0
            log(
                f"{tag}: step {i}/{steps} loss {loss_val:.4f} lr {f * args.lr:.2e} ({el:.0f} s, {el / i * 1000:.0f} ms/step)"
            )
            total, count = torch.zeros((), device=device), 0
    if count:
        loss_val = (total / count).item()
    model.eval()
    secs = time.time() - t0
    return {"steps": i, "loss": loss_val, "seconds": secs, "ms_per_step": 1000 * secs / max(i, 1)}


def rollout(batcher, vocab_index, env, job, beta, rng, deadline, record=("move",), depth=False, teacher=None):
    """One randomised episode with the policy driving; returns (rows, task outcomes). `job`:
    (instruction, run seed, plan step or None for the whole plan). `record`: the task kinds (a
    sub-task's first word) whose decisions the expert labels and keeps. A `beta` share of the
    decisions is driven by `teacher` (a PrivilegedTeacher) or, without one, by the expert."""
    ins, seed, step = job
    options = {"instruction": ins} if step is None else {"instruction": ins, "task": step}
    obs, info = env.reset(seed=seed, options=options)
    out, outcomes = empty_rows(), []
    task, start, steps, done = None, 0, 0, False
    while not done and time.time() < deadline:
        if obs["task_index"] != task:
            task, start = obs["task_index"], steps
        ims, st = F.from_env(obs, (steps - start) * F.CONTROL_DT, depth)
        wd = F.encode(obs["sub_task"], vocab_index)
        expert = info.get("expert_chunk")
        if expert is not None and obs["sub_task"].split()[0] in record:
            for lst, v in zip(
                out,
                (
                    ims,
                    st,
                    wd,
                    np.asarray(expert, dtype=np.float32).reshape(-1),
                    *aux_of(info.get("privileged_observation")),
                ),
            ):
                lst.append(v)
        if beta > 0 and rng.random() < beta and (teacher is not None or expert is not None):
            chunk = (
                teacher.chunk(obs, info, (steps - start) * F.CONTROL_DT)
                if teacher is not None
                else np.asarray(expert, dtype=np.float64)
            )
        else:
            chunk = batcher.decide(ims, st, wd)
        for a in chunk[: F.EXECUTE]:
            obs, _, done, _, info = env.step(a)
            steps += 1
            for t in info["tasks_ended"]:
                outcomes.append((F.kind_of(t["step"]), bool(t["success"])))
            if done or info["tasks_ended"]:
                break
    return out, outcomes, done


def run_round(batcher, vocab_index, jobs, args, seed, teacher=None):
    from gym_kitchen_r import KitchenREnv, KitchenRTaskEnv

    lock = threading.Lock()
    queue = list(jobs)
    rows, outcomes, finished = empty_rows(), [], [0, 0]
    deadline = time.time() + args.rollout_minutes * 60 if args.rollout_minutes > 0 else math.inf

    def worker(i):
        common = dict(
            images=True,
            depth=args.depth,
            history=F.HISTORY,
            expert=True,
            randomise=True,
            privileged_observation=args.aux_weight > 0 or teacher is not None,
        )
        if args.round_env == "task":
            env = KitchenRTaskEnv(task_time_limit=args.round_task_seconds, **common)
        else:
            env = KitchenREnv(max_tasks=args.max_tasks, **common)
        rng = np.random.default_rng(seed * 1000 + i)
        try:
            while time.time() < deadline:
                with lock:
                    if not queue:
                        break
                    job = queue.pop()
                r, o, done = rollout(
                    batcher,
                    vocab_index,
                    env,
                    job,
                    args.beta * 0.5 ** (seed - 1),
                    rng,
                    deadline,
                    tuple(args.dagger_kinds.split(",")),
                    args.depth,
                    teacher,
                )
                with lock:
                    for a, b in zip(rows, r):
                        a.extend(b)
                    outcomes.extend(o)
                    finished[0] += 1
                    finished[1] += not done
        finally:
            env.close()

    with ThreadPoolExecutor(args.envs) as pool:
        list(pool.map(worker, range(args.envs)))
    return rows, outcomes, finished


class PrivilegedTeacher:
    """A privileged-track checkpoint (privileged/train.py) driving a share of the rounds'
    decisions: learning by cheating. Its features come from what the environment puts in
    `info["privileged_observation"]`, which only the rounds' environments are asked for; the
    camera policy never sees it."""

    def __init__(self, path):
        from ..privileged import features, model

        self.F = features
        # On the CPU: one small forward per decision beats a GPU round trip (as privileged/train.py).
        self.model, self.meta = model.load(path, "cpu")
        self.lock = threading.Lock()

    def chunk(self, obs, info, task_time):
        x = self.F.from_env(np.asarray(obs["state"]).reshape(-1, 29)[-1], info["privileged_observation"], task_time)
        with self.lock, torch.no_grad():
            out = self.model.chunk(torch.as_tensor(x[None], dtype=torch.float32))[0]
        return self.F.finish(out.numpy())


def labelled_steps(ids, kinds):
    """(instruction, plan step) of every step of `kinds` (a sub-task's first word) in `ids`."""
    from gym_kitchen_r import KitchenREnv

    probe = KitchenREnv(images=False)
    try:
        return [(i, j) for i in ids for j, st in enumerate(probe.instruction_of(i)["plan"]) if st.split()[0] in kinds]
    finally:
        probe.close()


def round_jobs(ids, steps, args, rng):
    """A round's episodes: (instruction, run seed, plan step). `--round-env plan` runs whole plans
    of `ids`; `task` runs single plan steps drawn from `steps` (labelled_steps of the
    `--dagger-kinds`; KitchenR/Task-v0, from the expert's state at the step's start), so a
    round's time goes to the kinds it labels."""
    seeds = lambda: int(rng.integers(1, 2**62))  # noqa: E731
    if args.round_env == "plan":
        return [(ids[int(rng.integers(len(ids)))], seeds(), None) for _ in range(args.round_episodes)]
    picks = rng.integers(len(steps), size=args.round_episodes)
    return [(steps[k][0], seeds(), steps[k][1]) for k in picks]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="run folder: ckpt.pt, train_log.json")
    ap.add_argument("--episodes", type=int, default=1200, help="expert episodes streamed for behaviour cloning")
    ap.add_argument("--seed", type=int, default=1, help="collection seed of the expert episodes")
    ap.add_argument("--workers", type=int, default=os.cpu_count(), help="simulator threads for the expert stream")
    ap.add_argument("--bc-steps", type=int, default=20000)
    ap.add_argument("--rounds", type=int, default=2, help="DAgger rounds")
    ap.add_argument("--round-episodes", type=int, default=64)
    ap.add_argument("--round-steps", type=int, default=4000, help="training steps after each round")
    ap.add_argument(
        "--aux-weight",
        type=float,
        default=0.0,
        help="weight of the auxiliary loss: the network also predicts the privileged goal (a move's "
        "approach point, a pick's object, a place's target, robot frame) from what it sees, during "
        "training only, so the encoder learns to localise; 0 (default, the measured run) leaves it out",
    )
    ap.add_argument(
        "--init",
        help="start from this checkpoint (a run split over GPU leases; use another --seed "
        "for new expert episodes); its architecture and statistics are kept",
    )
    add_round_args(ap)
    ap.add_argument(
        "--round-env",
        choices=("task", "plan"),
        default="task",
        help="DAgger episodes: single plan steps of the labelled kinds (KitchenR/Task-v0), or whole plans",
    )
    ap.add_argument(
        "--round-task-seconds",
        type=float,
        default=60.0,
        help="with --round-env task: a step's time limit in the rounds (a drive that has not finished by "
        "then teaches little more)",
    )
    ap.add_argument(
        "--beta", type=float, default=0.0, help="chance the teacher drives a decision in round 1 (halves each round)"
    )
    ap.add_argument(
        "--teacher",
        default="expert",
        help="who drives the --beta share of the rounds' decisions: `expert`, or a privileged-track "
        "checkpoint (privileged/train.py's ckpt.pt; learning by cheating). The expert labels every "
        "decision either way",
    )
    ap.add_argument("--envs", type=int, default=os.cpu_count(), help="environments (threads) in DAgger rounds")
    ap.add_argument("--collect-minutes", type=float, default=0.0, help="wall budget of the expert stream (0: none)")
    ap.add_argument("--bc-minutes", type=float, default=0.0, help="wall budget of behaviour cloning (0: none)")
    ap.add_argument("--rollout-minutes", type=float, default=0.0, help="wall budget of each round's driving (0: none)")
    ap.add_argument("--round-minutes", type=float, default=0.0, help="wall budget of each round's training (0: none)")
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--lr", type=float, default=3e-4, help="peak learning rate of the head")
    ap.add_argument("--encoder-lr-scale", type=float, default=0.1, help="the trunk's rate relative to the head's")
    ap.add_argument(
        "--round-lr-scale", type=float, default=0.5, help="peak of each DAgger round's cosine, relative to --lr"
    )
    ap.add_argument("--weight-decay", type=float, default=1e-4)
    ap.add_argument("--warmup", type=int, default=500)
    ap.add_argument("--shift", type=int, default=4, help="random-shift augmentation, pixels (0: off)")
    ap.add_argument("--image-size", type=int, default=96, help="training resolution (the cameras render 128)")
    ap.add_argument(
        "--depth",
        action="store_true",
        help="also read both cameras' depth (two more views: twice the image memory and trunk work)",
    )
    ap.add_argument("--d-model", type=int, default=256)
    ap.add_argument("--layers", type=int, default=3)
    ap.add_argument("--max-tasks", type=int, default=0, help="only the first N plan steps of each episode (tests)")
    ap.add_argument("--no-pretrained", action="store_true", help="random trunk (no ImageNet weights)")
    ap.add_argument(
        "--compile",
        action="store_true",
        help="torch.compile the training forward (H100: 36 instead of 51 ms/step at batch 256, after ~60 s compiling)",
    )
    ap.add_argument("--device", default="auto")
    args = ap.parse_args()

    device = torch.device(
        "cuda"
        if args.device == "auto" and torch.cuda.is_available()
        else ("cpu" if args.device == "auto" else args.device)
    )
    if device.type == "cuda":
        # No cudnn.benchmark: on an H100 it autotuned ~50 s per new shape for the same step time.
        torch.backends.cuda.matmul.allow_tf32 = True
        torch.backends.cudnn.allow_tf32 = True
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(0)
    logbook = {
        "args": vars(args),
        "device": str(device),
        "hardware": torch.cuda.get_device_name() if device.type == "cuda" else "cpu",
        "cpu_count": os.cpu_count(),
        "torch": torch.__version__,
        "rounds": [],
    }
    t_start = time.time()

    def write_log():
        logbook["seconds_so_far"] = time.time() - t_start
        (out / "train_log.json").write_text(json.dumps(logbook, indent=1) + "\n")

    vocab = F.dev_vocab()
    vocab_index = {w: i for i, w in enumerate(vocab)}
    # About 132 expert rows an episode; a DAgger episode adds up to about 300 labelled rows.
    rows = Rows(args.image_size, device, capacity=int(args.episodes * 140 + args.rounds * args.round_episodes * 300))
    training_ids = train_instructions(args.instructions)
    logbook["instructions"] = {"split": "dev", "range": args.instructions, "count": len(training_ids)}
    logbook["expert"] = expert_rows(rows, vocab_index, args, training_ids)
    if rows.n == 0:
        sys.exit("no expert rows: raise --episodes or --collect-minutes")

    if args.init:
        # Go on from an earlier run (another lease, other expert episodes: change --seed): its
        # weights, architecture and normalisation statistics, so its features keep their scale.
        model, init_vocab, init_meta = load(args.init, device)
        if list(init_vocab) != list(vocab):
            sys.exit(f"--init {args.init}: its vocabulary differs from this checkout's dev vocabulary")
        if model.config.get("depth", False) != args.depth:
            sys.exit(
                f"--init {args.init} was trained {'with' if model.config.get('depth') else 'without'} --depth: "
                "pass the same"
            )
        if model.config["image_size"] != args.image_size:
            sys.exit(f"--init {args.init} was trained at --image-size {model.config['image_size']}: pass that")
        logbook["init"] = {"checkpoint": str(args.init), "meta": init_meta}
        if args.aux_weight > 0 and model.aux is None:
            sys.exit(f"--init {args.init} has no auxiliary head: train it afresh with --aux-weight, or leave that out")
    else:
        grid = max(1, math.ceil(args.image_size / 32))
        model = CameraPolicy(
            len(vocab),
            args.image_size,
            args.d_model,
            args.layers,
            grid=grid,
            pretrained=not args.no_pretrained,
            aux=args.aux_weight > 0,
            depth=args.depth,
        ).to(device)
        model.set_statistics(rows.view("state"), rows.view("y"))
    if args.compile:
        COMPILED[id(model)] = torch.compile(model)
    logbook["parameters"] = {
        "total": sum(p.numel() for p in model.parameters()),
        "encoder": sum(p.numel() for p in model.encoder_parameters()),
    }
    opt = make_optimizer(model, args)

    def meta(stage):
        return {
            "stage": stage,
            "rows": rows.n,
            "expert_episodes": logbook["expert"]["episodes"],
            "hardware": logbook["hardware"],
            "render_size": F.RENDER_SIZE,
        }

    logbook["bc"] = fit(model, opt, rows, args.bc_steps, args.bc_minutes, 1.0, args, "bc", device)
    save(out / "ckpt.pt", model, vocab, meta("bc"))
    if device.type == "cuda":
        logbook["max_memory_gib"] = torch.cuda.max_memory_allocated() / 2**30
    write_log()

    batcher = Batcher(model, max_batch=max(1, args.envs)) if args.rounds else None
    teacher = None
    if args.rounds and args.teacher != "expert":
        teacher = PrivilegedTeacher(args.teacher)
        logbook["teacher"] = {"checkpoint": args.teacher, "meta": teacher.meta}
    steps = []
    if args.rounds and args.round_env == "task":
        steps = labelled_steps(training_ids, set(args.dagger_kinds.split(",")))
        if not steps:
            sys.exit(f"no plan step of kinds {args.dagger_kinds!r} in the training instructions")
    for r in range(1, args.rounds + 1):
        model.eval()
        jobs = round_jobs(training_ids, steps, args, np.random.default_rng(1000 * args.seed + r))
        t0 = time.time()
        new, outcomes, (finished, cut) = run_round(batcher, vocab_index, jobs, args, r, teacher)
        roll_s = time.time() - t0
        sr = sr_by_kind(outcomes)
        log(
            f"round {r}: policy drove {finished}/{args.round_episodes} episodes "
            f"({cut} cut short at --rollout-minutes) in {roll_s:.0f} s, "
            + ", ".join(f"{k} {v['success']}/{v['tasks']}" for k, v in sr.items())
            + f"; {len(new[0])} new rows"
        )
        before = rows.n
        for k in range(0, len(new[0]), 512):
            with batcher.lock:
                rows.add(*(lst[k : k + 512] for lst in new))
        del new
        with batcher.lock:
            fit_log = fit(
                model, opt, rows, args.round_steps, args.round_minutes, args.round_lr_scale, args, f"round {r}", device
            )
        logbook["rounds"].append(
            {
                "round": r,
                "episodes": finished,
                "episodes_cut_short": cut,
                "beta": args.beta * 0.5 ** (r - 1),
                "rows_added": rows.n - before,
                "rows_total": rows.n,
                "sr_while_driving": sr,
                "rollout_seconds": roll_s,
                **fit_log,
            }
        )
        save(out / "ckpt.pt", model, vocab, meta(f"dagger round {r}"))
        if device.type == "cuda":
            logbook["max_memory_gib"] = torch.cuda.max_memory_allocated() / 2**30
        write_log()

    logbook["train_seconds"] = time.time() - t_start
    logbook["rows"] = rows.n
    save(out / "ckpt.pt", model, vocab, {**meta("final"), "dagger_rounds": args.rounds})
    write_log()
    log(
        f"done in {logbook['train_seconds']:.0f} s: {out / 'ckpt.pt'} ({(out / 'ckpt.pt').stat().st_size / 2**20:.1f} MiB)"
    )


if __name__ == "__main__":
    main()
