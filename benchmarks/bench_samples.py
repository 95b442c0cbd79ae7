"""Expert training data per minute: streamed samples against the LeRobot export path.

    python3 benchmarks/bench_samples.py [--episodes N] [--workers W] [--collect M] [--bin BIN] [--json OUT]

1. ``gym_kitchen_r.ExpertSamples(episodes=N, workers=W)``: the expert over collection episodes
   0..N-1 (seed 0, the paper's randomisation), one sample per decision (every 8 control steps:
   both 128x128 cameras, the robot state and the expert's 16x10 chunk), each sample's arrays
   read once as a trainer would; episodes and samples per minute.
2. With ``--collect M``: ``kitchen-r collect --format lerobot --episodes M --jobs W`` (the same
   episodes' first M, H.264 video), then, when PyAV and pyarrow are importable, decoding the export
   into memory with the diffusion-policy baseline's loader (starter-kit/baselines/diffusion_policy/
   dataset.py, a process per core); episodes per minute of each and of both together.

Prints one line per path and the ratio; ``--json`` writes the figures.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import tempfile
import time
from pathlib import Path

import gym_kitchen_r

REPO = Path(__file__).resolve().parent.parent


def streamed(episodes: int, workers: int) -> dict:
    started = time.perf_counter()
    samples = frames = 0
    checksum = 0
    for s in gym_kitchen_r.ExpertSamples(episodes=episodes, workers=workers):
        samples += 1
        frames += len(s["images"])
        # Touch what a trainer reads (one byte per image, the chunk), so nothing is left lazy.
        checksum += int(s["images"]["base"][64, 64, 0]) + int(s["action"][0, 0] > 0)
    wall = time.perf_counter() - started
    return {
        "path": "ExpertSamples",
        "episodes": episodes,
        "samples": samples,
        "wall_s": round(wall, 2),
        "episodes_per_min": round(episodes / wall * 60, 1),
        "samples_per_s": round(samples / wall, 1),
    }


def exported(binary: str, episodes: int, workers: int) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory() as out:
        started = time.perf_counter()
        subprocess.run(
            [
                binary,
                "collect",
                "--format",
                "lerobot",
                "--episodes",
                str(episodes),
                "--jobs",
                str(workers),
                "--seed",
                "0",
                "--out",
                out,
                "--json",
            ],
            check=True,
            capture_output=True,
            text=True,
        )
        collect = time.perf_counter() - started
        rows.append(
            {
                "path": "collect --format lerobot",
                "episodes": episodes,
                "wall_s": round(collect, 2),
                "episodes_per_min": round(episodes / collect * 60, 1),
            }
        )
        try:
            import av  # noqa: F401
            import pyarrow  # noqa: F401
        except ImportError as e:
            rows.append({"path": "decode", "skipped": f"{e.name} is not installed"})
            return rows
        from kitchen_r_baselines.diffusion_policy.dataset import LeRobotExport

        started = time.perf_counter()
        LeRobotExport(Path(out) / "lerobot", image_size=128, workers=workers, log=lambda *a, **k: None)
        decode = time.perf_counter() - started
        rows.append(
            {
                "path": "decode (PyAV, baseline loader)",
                "episodes": episodes,
                "wall_s": round(decode, 2),
                "episodes_per_min": round(episodes / decode * 60, 1),
            }
        )
        both = collect + decode
        rows.append(
            {
                "path": "collect + decode",
                "episodes": episodes,
                "wall_s": round(both, 2),
                "episodes_per_min": round(episodes / both * 60, 1),
            }
        )
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    p.add_argument("--collect", type=int, default=0, help="also time the LeRobot export path on this many episodes")
    p.add_argument("--bin", default=os.environ.get("KITCHEN_R_BIN", str(REPO / "target/release/kitchen-r")))
    p.add_argument("--json", help="write the figures here")
    a = p.parse_args()
    rows = [streamed(a.episodes, a.workers)]
    if a.collect:
        rows += exported(a.bin, a.collect, a.workers)
    for r in rows:
        if "skipped" in r:
            print(f"{r['path']:32s} skipped: {r['skipped']}")
            continue
        extra = f" {r['samples']:7d} samples {r['samples_per_s']:8.1f}/s" if "samples" in r else ""
        print(
            f"{r['path']:32s} {r['episodes']:5d} episodes {r['wall_s']:8.2f} s {r['episodes_per_min']:8.1f} episodes/min{extra}"
        )
    last = [r for r in rows if "episodes_per_min" in r][-1]
    if last is not rows[0]:
        print(f"streamed samples: {rows[0]['episodes_per_min'] / last['episodes_per_min']:.1f}x {last['path']}")
    result = {"workers": a.workers, "cpus": os.cpu_count(), "rows": rows}
    if a.json:
        Path(a.json).write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
