"""What the Python environment costs over the Rust runner, and what a vector env gains.

    python3 benchmarks/bench_python_env.py [--episodes N] [--bin target/release/kitchen-r]

Three runs over the same first N dev instructions (run seed 0), the expert choosing every
action and both 128x128 RGB cameras rendered at every control step in all three:

1. Rust: ``kitchen-r eval --policy builtin:oracle --jobs 1`` with ``execute = 1`` (the oracle
   asked at every step, so a frame is rendered at every step);
2. Python, one env built with ``expert=True``: ``env.step(info["expert_chunk"][0])`` at every
   step (the expert's chunk rides with each observation, as a DAgger or BC loop reads it);
3. Python, a vector env of 2 (or ``--envs``; ``gymnasium.make_vec``) stepped the same way
   through its public ``step``, with gymnasium's autoreset: its episodes are dev instructions
   drawn by the seeded env (not the same N), run until it has made as many steps as run 2.

Prints control steps per second of each and the ratios: the binding's overhead is 2 against 1
on one core, the vector env's gain 3 against 2. With ``--repeat R`` the three runs are repeated
R times, interleaved (a shared or virtual machine drifts by more than the overhead between
runs), and the median of each ratio is printed too.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import tempfile
import time

import gym_kitchen_r
import gymnasium as gym


def rust(binary: str, n: int) -> tuple[int, float]:
    with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
        f.write("execute = 1\nteleport_on_failure = false\n")
        cfg = f.name
    try:
        started = time.perf_counter()
        out = subprocess.run(
            [
                binary,
                "eval",
                "--policy",
                "builtin:oracle",
                "--episodes",
                str(n),
                "--jobs",
                "1",
                "--seed",
                "0",
                "--config",
                cfg,
                "--json",
            ],
            check=True,
            capture_output=True,
            text=True,
        )
        wall = time.perf_counter() - started
    finally:
        os.unlink(cfg)
    report = json.loads(out.stdout)
    steps = sum(round(e["sim_time"] / 0.1) for e in report["episodes"])
    return steps, wall


def one_env(ids: list[str]) -> tuple[int, float]:
    env = gym_kitchen_r.KitchenREnv(teleport_on_failure=False, expert=True)
    steps = 0
    started = time.perf_counter()
    for i in ids:
        _, info = env.reset(seed=0, options={"instruction": i})
        done = False
        while not done:
            _, _, done, _, info = env.step(info["expert_chunk"][0])
            steps += 1
    wall = time.perf_counter() - started
    env.close()
    return steps, wall


def vector_env(n_envs: int, total: int) -> tuple[int, float]:
    v = gym.make_vec(
        "KitchenR/Plan-v0",
        num_envs=n_envs,
        vectorization_mode="vector_entry_point",
        teleport_on_failure=False,
        expert=True,
    )
    _, infos = v.reset(seed=0)
    steps = 0
    started = time.perf_counter()
    while steps < total:
        # An env that autoresets this step ignores its action; its chunk is zeros then.
        _, _, _, _, infos = v.step(infos["expert_chunk"][:, 0] + _unit_if_zero(infos))
        steps += n_envs
    wall = time.perf_counter() - started
    v.close()
    return steps, wall


def _unit_if_zero(infos):
    """A legal placeholder (unit quaternion) for the action of an env that autoresets."""
    import numpy as np

    fix = np.zeros_like(infos["expert_chunk"][:, 0])
    fix[~infos["_expert_chunk"], 5] = 1.0
    return fix


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--episodes", type=int, default=6)
    p.add_argument("--envs", type=int, default=2)
    p.add_argument("--repeat", type=int, default=1, help="repeat the three runs, interleaved; print the medians")
    p.add_argument("--bin", default=os.environ.get("KITCHEN_R_BIN", "target/release/kitchen-r"))
    a = p.parse_args()
    ids = gym_kitchen_r.KitchenREnv(images=False).instruction_ids()[: a.episodes]
    overheads, gains = [], []
    for _ in range(a.repeat):
        rows = {"rust runner (1 core)": rust(a.bin, a.episodes)}
        rows["python env (1)"] = one_env(ids)
        rows[f"python vector env ({a.envs})"] = vector_env(a.envs, rows["python env (1)"][0])
        for name, (steps, wall) in rows.items():
            print(f"{name:28s} {steps:6d} steps {wall:7.2f} s {steps / wall:8.1f} steps/s")
        r, o, v = (s / w for s, w in rows.values())
        overheads.append(100 * (r / o - 1))
        gains.append(v / o)
        print(f"binding overhead: {overheads[-1]:+.1f} % (python env time over the rust runner's)")
        print(f"vector env of {a.envs}: {gains[-1]:.2f}x one env", flush=True)
    if a.repeat > 1:
        print(
            f"median of {a.repeat}: binding overhead {statistics.median(overheads):+.1f} %, "
            f"vector env of {a.envs} {statistics.median(gains):.2f}x one env"
        )


if __name__ == "__main__":
    main()
