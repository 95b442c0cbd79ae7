#!/usr/bin/env python3
"""What ``KitchenREnv(ros2=True)`` costs a step (docs/twin/live.md, "From Python and
from the workers"): the expert through the first three dev instructions' first two tasks, each
``env.step`` timed alone, with ros2 off, on with no subscriber, and on with
``scripts/ros2-watch.py`` reading every message; ``--rounds`` interleaved rounds, each mode in a
fresh process (one publisher per process).

    python3 benchmarks/bench_ros2_python.py [--rounds 3] [--no-images] [--domain 77]

Needs the ``gym_kitchen_r`` package (``pip install ./python``) and, for the subscriber,
``cyclonedds``. Publishes on loopback only, in ``--domain``.
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

WATCH = Path(__file__).resolve().parent / "ros2-watch.py"


def one(mode: str, images: bool, live_toml: str) -> None:
    from gym_kitchen_r import KitchenREnv

    kw: dict[str, Any] = {} if mode == "off" else {"ros2": True, "ros2_config": live_toml}
    if mode == "subscriber":
        kw["ros2_wait"] = 30
    env = KitchenREnv(images=images, max_tasks=2, **kw)
    steps, spent = 0, 0.0
    for ins in env.instruction_ids()[:3]:
        env.reset(seed=0, options={"instruction": ins})
        done = False
        while not done:
            for a in env.expert_chunk()[:8]:
                t0 = time.perf_counter()
                _, _, done, _, info = env.step(a)
                spent += time.perf_counter() - t0
                steps += 1
                if done or info["tasks_ended"]:
                    break
    print(f"{mode:>10}: {steps} steps, {spent / steps * 1e3:.3f} ms a step, ros2 {env.ros2_stats()}", flush=True)
    env.close()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--no-images", action="store_true", help="images=False (the hook renders for a camera subscriber)")
    ap.add_argument("--domain", type=int, default=77)
    ap.add_argument("--one", help=argparse.SUPPRESS)
    ap.add_argument("--live-toml", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        one(args.one, not args.no_images, args.live_toml)
        return 0
    with tempfile.TemporaryDirectory() as tmp:
        live_toml = os.path.join(tmp, "live.toml")
        Path(live_toml).write_text(f"[ros2]\ndomain_id = {args.domain}\n")
        env = {k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"}
        for _ in range(args.rounds):
            for mode in ("off", "on", "subscriber"):
                sub = None
                if mode == "subscriber":
                    sub = subprocess.Popen(
                        [
                            sys.executable,
                            str(WATCH),
                            "--domain",
                            str(args.domain),
                            "--count",
                            "100000000",
                            "--seconds",
                            "600",
                        ],
                        stdout=subprocess.DEVNULL,
                        stderr=subprocess.PIPE,
                        env=env,
                    )
                    assert sub.stderr is not None
                    sub.stderr.readline()  # "ready"
                cmd = [sys.executable, __file__, "--one", mode, "--live-toml", live_toml]
                cmd += ["--no-images"] if args.no_images else []
                subprocess.run(cmd, check=True, env=env)
                if sub is not None:
                    sub.kill()
                    sub.wait()
    return 0


if __name__ == "__main__":
    sys.exit(main())
