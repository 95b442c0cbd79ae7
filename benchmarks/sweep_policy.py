#!/usr/bin/env python3
"""A legal policy that fails every task while keeping both cameras moving: the base creeps and
turns, the hand sweeps side to side and the gripper opens and closes. Nearly static frames (the
starter kit's stand-still policy) compress far better, so this is the bench's worst case for
video bytes per episode (benchmarks/bench-video.sh, POLICY=sweep).

Run:  python3 benchmarks/sweep_policy.py --listen 127.0.0.1:0   (prints `listening grpc=HOST:PORT`)
"""

import argparse
import math

# The starter kit's policy server, installed with the baselines
# (pip install -e ./starter-kit -e ./starter-kit/baselines; scripts/test.sh's venv has it).
import policy_server as kit


class SweepPolicy(kit.StarterPolicy):
    def decide(self, obs):
        chunk = []
        for k in range(kit.HORIZON):
            t = 0.1 * (obs.step + k)  # sim seconds at the control rate
            v, w = 0.1, 0.6 * math.sin(0.3 * t)
            y = 0.2 * math.sin(1.5 * t)
            g = 0.5 + 0.5 * math.sin(0.8 * t)
            chunk.append([v, w, 0.35, y, 0.95, 0.0, 1.0, 0.0, 0.0, g])
        return chunk


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--listen", default="127.0.0.1:0")
    args = ap.parse_args()
    kit.serve(args.listen, None, None, 8, SweepPolicy(), 1, 0, name="bench sweep 1.0")
