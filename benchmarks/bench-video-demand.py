#!/usr/bin/env python3
"""What videos on demand cost (docs/measured/video.md): a dev run through the real
server with local workers, then the wait from a first request of each episode's video to a
playable file.

    python3 benchmarks/bench-video-demand.py [--bin target/release/kitchen-r] [--episodes 6]
        [--policy oracle|still|sweep] [--videos on|off] [--ask 3] [--workers 2]

1. Starts a policy on loopback (`oracle`: `kitchen-r policy oracle`, whose tasks end as soon as
   they succeed; `still`: the starter kit's stand-still policy and `sweep`:
   benchmarks/sweep_policy.py, which fail every task so every task runs to its time limit: the
   longest videos; both need `pip install -r starter-kit/requirements.txt`).
2. Starts `kitchen-r serve --workers N` on a fresh SQLite file with `[video] enabled` as asked,
   registers the policy as an organiser reference run of the first EPISODES dev instructions,
   and prints the run's wall time (registration to finished) and the sum of its episodes' walls.
3. With videos on, asks for the first ASK episodes' videos one after another and prints, for
   each, the seconds until the server answered 200 (it answers 202 while a worker renders),
   its size and sha256 prefix; then the bytes stored as traces and as videos.

Everything listens on 127.0.0.1 and is stopped on exit, and the work folder is removed.
"""

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ADMIN = "bench-admin-token-0123456789"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", default=str(ROOT / "target/release/kitchen-r"))
    ap.add_argument("--episodes", type=int, default=6)
    ap.add_argument("--policy", choices=["oracle", "still", "sweep"], default="oracle")
    ap.add_argument("--videos", choices=["on", "off"], default="on")
    ap.add_argument("--ask", type=int, default=3, help="videos to request, one after another")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()

    work = Path(tempfile.mkdtemp(prefix="kr-video-demand-"))
    (work / "db").mkdir()
    (work / "server.toml").write_text(
        f'http = "127.0.0.1:0"\ngrpc = "127.0.0.1:0"\ndb = "sqlite://{work}/db/k.db"\n'
        'worker_token = "bench-worker-token-0123456789"\n'
        "[control]\noffline_mse = false\n[quota]\nconcurrent_runs = 0\n"
        f"[video]\nenabled = {'true' if a.videos == 'on' else 'false'}\n"
    )
    env = dict(os.environ, KITCHEN_R_ADMIN_TOKEN=ADMIN, RUST_LOG="warn")
    procs = []

    def ready(cmd, prefix):
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env, text=True, cwd=ROOT)
        procs.append(p)
        for line in p.stdout:
            if line.startswith(prefix):
                return line.strip()
        sys.exit(f"{' '.join(map(str, cmd))} exited without printing {prefix!r}")

    try:
        policy_cmd = {
            "oracle": [a.bin, "policy", "oracle", "--listen", "127.0.0.1:0", "--max-concurrency", "4"],
            "still": [sys.executable, str(ROOT / "starter-kit/policy_server.py"), "--listen", "127.0.0.1:0"],
            "sweep": [sys.executable, str(ROOT / "benchmarks/sweep_policy.py"), "--listen", "127.0.0.1:0"],
        }[a.policy]
        endpoint = "http://" + ready(policy_cmd, "listening grpc=").split("=", 1)[1]
        line = ready([a.bin, "serve", "--workers", str(a.workers), "--config", str(work / "server.toml")], "listening ")
        http = [w.split("=", 1)[1] for w in line.split() if w.startswith("http=")][0]
        http = http if http.startswith("http") else "http://" + http

        def req(path, body=None):
            r = urllib.request.Request(
                http + path,
                data=json.dumps(body).encode() if body else None,
                method="POST" if body else "GET",
                headers={"authorization": f"Bearer {ADMIN}", "content-type": "application/json"},
            )
            try:
                with urllib.request.urlopen(r) as resp:
                    return resp.status, resp.read()
            except urllib.error.HTTPError as e:
                return e.code, e.read()

        t0 = time.time()
        st, body = req(
            "/api/v1/submissions/policies",
            {"endpoint": endpoint, "split": "dev", "episodes": a.episodes, "reference": True},
        )
        if st != 201:
            sys.exit(f"registering the policy: HTTP {st} {body[:300]!r}")
        sid = json.loads(body)["id"]
        while True:
            st, body = req(f"/api/v1/submissions/{sid}")
            ev = json.loads(body)["latest_run"]["evaluation"]
            if ev["state"] in ("finished", "platform_failed"):
                break
            time.sleep(0.2)
        run_s = time.time() - t0
        eps = ev["episodes"]
        walls = sum(e["wall_ms"] for e in eps) / 1000
        print(
            f"policy {a.policy}, videos {a.videos}: {len(eps)} episodes, run wall {run_s:.1f} s "
            f"(episodes' walls sum to {walls:.1f} s), state {ev['state']}",
            flush=True,
        )
        if a.videos == "off":
            return
        time.sleep(2)  # the traces' uploads follow the results
        eps = json.loads(req(f"/api/v1/submissions/{sid}")[1])["latest_run"]["evaluation"]["episodes"]
        for e in eps[: a.ask]:
            t1 = time.time()
            while True:
                st, b = req(e["video_url"])
                if st != 202:
                    break
                time.sleep(0.25)
            print(
                f"  {e['key']}: HTTP {st} after {time.time() - t1:.1f} s, {len(b)} bytes, "
                f"sha256 {hashlib.sha256(b).hexdigest()[:16]}",
                flush=True,
            )
        sizes = {"trace (.json.gz)": 0, "video (.mp4)": 0}
        for root, _, files in os.walk(work / "db"):
            for f in files:
                size = os.path.getsize(os.path.join(root, f))
                if f.endswith(".json.gz"):
                    sizes["trace (.json.gz)"] += size
                elif f.endswith(".mp4"):
                    sizes["video (.mp4)"] += size
        print(f"  stored bytes: {sizes}")
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            p.wait()
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
