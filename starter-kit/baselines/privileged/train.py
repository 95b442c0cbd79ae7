#!/usr/bin/env python3
"""Train the privileged-track baseline from live simulators: behaviour cloning on the expert's
streamed samples, then DAgger rounds in which the policy drives and the expert labels the states
it reaches.

    python train.py --out runs/priv [--episodes 2700] [--workers N] [--bc-steps 30000]
                    [--rounds 4] [--round-episodes 200] [--round-steps 10000] [--device auto]

1. `gym_kitchen_r.ExpertSamples(images=False, privileged_observation=True)`: the oracle runs
   collection's episodes (the paper's randomisation, seed `--seed`, the same episodes as
   `kitchen-r collect --seed`) on `--workers` Rust threads; one row per decision, features as
   features.py computes them, the expert's 16x10 chunk as the label.
2. An MLP (model.py) regresses the normalised chunk (MSE, AdamW, cosine decay).
3. Each DAgger round runs `--round-episodes` randomised dev episodes in `KitchenR/Plan-v0`
   environments (one per thread, `--envs`) with the policy driving (8 of 16 actions per
   decision, as the leaderboard's runner) and the expert's chunk recorded at every decision;
   the rows join the training set and training goes on. Round seeds differ from the
   evaluation's (0) and from collection's.

Progress lines go to stdout; `train_log.json` in `--out` keeps every round's figures (rows,
SR per kind as the policy drove, loss, seconds) and `ckpt.pt` the final model.
"""

if __name__ == "__main__" and not __package__:  # run as a file: hand over to the installed package's module
    import runpy

    runpy.run_module("kitchen_r_baselines.privileged.train", run_name="__main__", alter_sys=True)
    raise SystemExit

import argparse
import json
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import torch

from ..common import add_round_args, sr_by_kind, train_instructions
from . import features as F
from .model import PrivilegedMLP, save


def log(msg):
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


def kind_of(step):
    return step.split()[0]


def expert_rows(episodes, seed, workers, max_tasks=0, instructions=None):
    """Features and labels of every decision of `episodes` expert episodes."""
    from gym_kitchen_r import ExpertSamples

    xs, ys = [], []
    first = {}
    t0 = time.time()
    n_ep = -1
    for s in ExpertSamples(
        episodes=episodes,
        workers=workers,
        images=False,
        privileged_observation=True,
        seed=seed,
        max_tasks=max_tasks,
        instructions=instructions,
    ):
        key = (s["episode_index"], s["task_index"])
        start = first.setdefault(key, s["step"])
        xs.append(F.from_env(s["state"], s["privileged_observation"], (s["step"] - start) * F.CONTROL_DT))
        ys.append(np.asarray(s["action"], dtype=np.float32).reshape(-1))
        if s["episode_index"] != n_ep:
            n_ep = s["episode_index"]
            if n_ep % max(1, episodes // 10) == 0:
                log(f"expert episodes {n_ep}/{episodes}: {len(xs)} rows, {time.time() - t0:.0f} s")
    log(f"expert data: {episodes} episodes, {len(xs)} rows in {time.time() - t0:.1f} s")
    return np.stack(xs), np.stack(ys), time.time() - t0


class Driver:
    """The policy, shared by the rollout threads (one forward at a time; the simulators step in
    parallel with the GIL released)."""

    def __init__(self, model):
        self.model = model
        self.lock = threading.Lock()

    def chunk(self, x):
        with self.lock, torch.no_grad():
            p = next(self.model.parameters())
            out = self.model.chunk(torch.as_tensor(x[None], device=p.device))[0]
        return F.finish(out.cpu().numpy())


def rollout(driver, instruction, seed, env, record, beta, rng, label_cap=0):
    """One randomised episode with the policy driving; returns (rows, task outcomes). `record`:
    the goal kinds whose decisions are labelled and kept; `label_cap`: at most this many labelled
    decisions per task (0: all)."""
    obs, info = env.reset(seed=seed, options={"instruction": instruction})
    xs, ys, outcomes = [], [], []
    task, start, steps, labelled = None, 0, 0, 0
    done = False
    while not done:
        if obs["task_index"] != task:
            task, start, labelled = obs["task_index"], steps, 0
        x = F.from_env(
            np.asarray(obs["state"]).reshape(-1, 29)[-1], info["privileged_observation"], (steps - start) * F.CONTROL_DT
        )
        expert = info.get("expert_chunk")
        kept = label_cap <= 0 or labelled < label_cap
        if expert is not None and kept and info["privileged_observation"]["goal"]["kind"] in record:
            labelled += 1
            xs.append(x)
            ys.append(np.asarray(expert, dtype=np.float32).reshape(-1))
        if expert is not None and beta > 0 and rng.random() < beta:
            chunk = np.asarray(expert, dtype=np.float64)
        else:
            chunk = driver.chunk(x)
        n0 = steps
        for a in chunk[: F.EXECUTE]:
            obs, _, done, _, info = env.step(a)
            steps += 1
            for t in info["tasks_ended"]:
                outcomes.append((kind_of(t["step"]), bool(t["success"]), t.get("reason")))
            if done or info["tasks_ended"]:
                break
        assert steps > n0
    return xs, ys, outcomes


def run_episodes(driver, jobs, envs, record, beta, seed, max_tasks=0, label_cap=0):
    """`jobs`: (instruction, run seed) pairs, spread over `envs` threads."""
    from gym_kitchen_r import KitchenREnv

    lock = threading.Lock()
    queue = list(jobs)
    xs, ys, outcomes = [], [], []

    def worker(i):
        env = KitchenREnv(images=False, expert=True, privileged_observation=True, randomise=True, max_tasks=max_tasks)
        rng = np.random.default_rng(seed * 1000 + i)
        while True:
            with lock:
                if not queue:
                    break
                ins, s = queue.pop()
            a, b, c = rollout(driver, ins, s, env, record, beta, rng, label_cap)
            with lock:
                xs.extend(a)
                ys.extend(b)
                outcomes.extend(c)
        env.close()

    with ThreadPoolExecutor(envs) as pool:
        list(pool.map(worker, range(envs)))
    return xs, ys, outcomes


def fit(model, opt, sched, X, Y, steps, batch, tag):
    model.train()
    n = len(X)
    t0 = time.time()
    loss = torch.tensor(float("nan"))
    for i in range(1, steps + 1):
        idx = torch.randint(0, n, (batch,), device=X.device)
        loss = ((model(X[idx]) - model.normalise_y(Y[idx])) ** 2).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
        if i % max(1, steps // 5) == 0:
            log(f"{tag}: step {i}/{steps} loss {loss.item():.5f} ({time.time() - t0:.0f} s)")
    model.eval()
    return float(loss.item()), time.time() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True, help="run folder: ckpt.pt, train_log.json")
    ap.add_argument("--episodes", type=int, default=2700, help="expert episodes streamed for behaviour cloning")
    ap.add_argument("--seed", type=int, default=1, help="collection seed of the expert episodes")
    ap.add_argument("--workers", type=int, default=os.cpu_count(), help="simulator threads for the expert stream")
    ap.add_argument("--bc-steps", type=int, default=30000)
    ap.add_argument("--rounds", type=int, default=4, help="DAgger rounds")
    ap.add_argument("--round-episodes", type=int, default=200)
    ap.add_argument("--round-steps", type=int, default=10000, help="training steps after each round")
    add_round_args(ap)
    ap.add_argument(
        "--beta", type=float, default=0.0, help="chance the expert drives a decision in round 1 (halves each round)"
    )
    ap.add_argument(
        "--label-cap",
        type=int,
        default=0,
        help="label at most this many decisions of each task in a round (0: all); a failing task "
        "otherwise adds up to 150 rows of the states it is stuck in",
    )
    ap.add_argument(
        "--no-task-time",
        action="store_true",
        help="read the task's time as 0 (an experiment: the expert's own data ties time to the "
        "pick-and-place phase, and its labels for a learner's states no longer do)",
    )
    ap.add_argument("--envs", type=int, default=os.cpu_count(), help="environments (threads) in DAgger rounds")
    ap.add_argument("--batch", type=int, default=1024)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--width", type=int, default=512)
    ap.add_argument("--depth", type=int, default=4)
    ap.add_argument("--max-tasks", type=int, default=0, help="only the first N plan steps of each episode (tests)")
    ap.add_argument("--device", default="auto")
    args = ap.parse_args()

    device = (
        "cuda"
        if args.device == "auto" and torch.cuda.is_available()
        else ("cpu" if args.device == "auto" else args.device)
    )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(0)
    logbook = {
        "args": vars(args),
        "device": device,
        "hardware": torch.cuda.get_device_name() if device == "cuda" else "cpu",
        "cpu_count": os.cpu_count(),
        "rounds": [],
    }
    t_start = time.time()

    ids = train_instructions(args.instructions)
    logbook["instructions"] = {"split": "dev", "range": args.instructions, "count": len(ids)}
    X, Y, collect_s = expert_rows(args.episodes, args.seed, args.workers, args.max_tasks, ids)
    logbook["expert"] = {"episodes": args.episodes, "rows": len(X), "seconds": collect_s}
    model = PrivilegedMLP(args.width, args.depth, task_time=not args.no_task_time).to(device)
    Xt, Yt = torch.tensor(X, device=device), torch.tensor(Y, device=device)
    model.set_statistics(Xt, Yt)
    total_steps = args.bc_steps + args.rounds * args.round_steps
    opt = torch.optim.AdamW(model.parameters(), args.lr, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, args.lr, total_steps=total_steps + 1, pct_start=0.02)
    loss, fit_s = fit(model, opt, sched, Xt, Yt, args.bc_steps, args.batch, "bc")
    logbook["bc"] = {"steps": args.bc_steps, "loss": loss, "seconds": fit_s}
    save(out / "ckpt.pt", model, {"stage": "bc"})

    # Rollouts run on a CPU copy: one small forward per decision is faster there than a GPU
    # round trip, and the training copy stays where it is.
    cpu_model = PrivilegedMLP(args.width, args.depth, task_time=not args.no_task_time)
    torch.set_num_threads(max(1, min(4, os.cpu_count() or 1)))
    for r in range(1, args.rounds + 1):
        cpu_model.load_state_dict({k: v.cpu() for k, v in model.state_dict().items()})
        cpu_model.eval()
        rng = np.random.default_rng(1000 + r)
        jobs = [(ids[int(rng.integers(len(ids)))], int(rng.integers(1, 2**62))) for _ in range(args.round_episodes)]
        t0 = time.time()
        beta = args.beta * 0.5 ** (r - 1)
        kinds = set(args.dagger_kinds.split(","))
        xs, ys, outcomes = run_episodes(
            Driver(cpu_model), jobs, args.envs, kinds, beta, r, args.max_tasks, args.label_cap
        )
        roll_s = time.time() - t0
        sr = sr_by_kind(outcomes)
        log(
            f"round {r}: policy drove {args.round_episodes} episodes in {roll_s:.0f} s, "
            + ", ".join(f"{k} {v['success']}/{v['tasks']}" for k, v in sr.items())
            + f"; {len(xs)} new rows"
        )
        if xs:
            Xt = torch.cat([Xt, torch.tensor(np.stack(xs), device=device)])
            Yt = torch.cat([Yt, torch.tensor(np.stack(ys), device=device)])
        loss, fit_s = fit(model, opt, sched, Xt, Yt, args.round_steps, args.batch, f"round {r}")
        logbook["rounds"].append(
            {
                "round": r,
                "episodes": args.round_episodes,
                "beta": beta,
                "rows_added": len(xs),
                "rows_total": len(Xt),
                "sr_while_driving": sr,
                "rollout_seconds": roll_s,
                "loss": loss,
                "fit_seconds": fit_s,
            }
        )
        save(out / "ckpt.pt", model, {"stage": f"dagger round {r}"})
        (out / "train_log.json").write_text(json.dumps(logbook, indent=1) + "\n")

    logbook["train_seconds"] = time.time() - t_start
    logbook["rows"] = len(Xt)
    save(
        out / "ckpt.pt",
        model,
        {
            "stage": "final",
            "rows": len(Xt),
            "expert_episodes": args.episodes,
            "dagger_episodes": args.rounds * args.round_episodes,
        },
    )
    (out / "train_log.json").write_text(json.dumps(logbook, indent=1) + "\n")
    log(
        f"done in {logbook['train_seconds']:.0f} s: {out / 'ckpt.pt'} ({(out / 'ckpt.pt').stat().st_size / 2**20:.1f} MiB)"
    )


if __name__ == "__main__":
    main()
