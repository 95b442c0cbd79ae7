#!/usr/bin/env python3
"""The learnability gates: evaluate a served baseline on randomised dev episodes and write its
results folder.

    python3 starter-kit/baselines/gate.py --track privileged --out RESULTS \
        --serve "python3 starter-kit/baselines/privileged/serve.py --checkpoint ckpt.pt --listen 127.0.0.1:0" \
        [--episodes 60 | --instructions 101-163] [--split dev|test] [--seed 0] [--held-out] [--jobs N] \
        [--bin target/release/kitchen-r] [--train-log train_log.json] [--leaderboard] \
        [--gate navigation=0.9,pick=0.7,place=0.7]
    python3 starter-kit/baselines/gate.py --track standard --out RESULTS --combine RESULTS_A RESULTS_B

Steps, each through the real binary (`--bin`):
1. `kitchen-r episodes generate --from-dataset --count N --seed S`: the episodes of the first N
   instructions of `--split` (or of the 1-based, inclusive range `--instructions A-B`), with the
   paper's randomisation on (fixed seed: the same episodes for every policy and run). The test
   split's plans come from `--ground-truth` (default `assets/dataset/test_ground_truth.jsonl`);
2. the policy is started with `--serve` (it prints `listening grpc=HOST:PORT`);
3. `kitchen-r check-policy` (it announces the privileged track) -> `check_policy.txt`;
4. `kitchen-r eval --episodes-file` online (the policy drives; SR) -> `eval_SPLIT.json`, and
   offline (the expert drives, the policy predicts; MSE) -> `eval_SPLIT_offline.json`;
5. with `--leaderboard`: a local `kitchen-r serve` (the privileged track on when `--track
   privileged`), the run submitted as the organiser's reference (a baseline row), its dev control
   board -> `leaderboard_dev_control.json`;
6. `summary.json`: the track, SR and task counts per kind with 95 % Wilson intervals, where
   failed tasks ended (median distance to their goal per kind), offline MSE, the training
   figures from `--train-log`, whether each gate (`--gate`) was met, and what was evaluated:
   `eval_split`, `eval_instructions` (`A-B`), `eval_seed` and `held_out` (`--held-out`: the
   training script never saw these instructions or this seed and no checkpoint was chosen on
   them; the flag records the claim, the training log's `instructions` lets a reader check it).

`--combine DIR...` sums the online (and offline) results of several such folders (for example
the held-out dev instructions and the first 100 test instructions) into one `summary.json`, so a
gate is judged on enough tasks of each kind, with each part's figures kept under `parts`; its
`eval_split`, `eval_instructions` and `eval_seed` name the parts (`dev+test`, `dev 101-163, test
1-100`, and their seed when they share one).
"""

if __name__ == "__main__" and not __package__:  # run as a file: hand over to the installed package's module
    import runpy

    runpy.run_module("kitchen_r_baselines.gate", run_name="__main__", alter_sys=True)
    raise SystemExit

import argparse
import json
import math
import os
import re
import shlex
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .common import instruction_range

KINDS = ("navigation", "pick", "place")
GATES = {
    "privileged": {"navigation": 0.9, "pick": 0.7, "place": 0.7},
    # The camera baseline's targets (docs/measured/baseline-gates.md; the first ones were 0.5 / 0.3 / 0.3).
    "standard": {"navigation": 0.8, "pick": 0.5, "place": 0.5},
}


def log(msg):
    print(f"[gate {time.strftime('%H:%M:%S')}] {msg}", flush=True)


def wilson(successes, n, z=1.96):
    """95 % Wilson score interval of a success rate (sound at 0 and 1, unlike the normal one)."""
    if n == 0:
        return [None, None]
    p = successes / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return [max(0.0, c - h), min(1.0, c + h)]


def kind_of(step):
    w = step.split()[0]
    return {"move": "navigation"}.get(w, w)


DISTANCE = re.compile(r"(\d+\.\d+) m from")


def summarise(online, offline, train_log, track, gates, evaluated=None):
    tasks = [t for e in online["episodes"] for t in e["tasks"]]
    by_kind, failed_at = {}, {}
    for k in KINDS:
        ts = [t for t in tasks if kind_of(t["step"]) == k]
        s = sum(1 for t in ts if t["success"])
        dists = [
            float(m.group(1))
            for t in ts
            if not t["success"] and (m := DISTANCE.search(t.get("failure_reason") or t.get("failure") or ""))
        ]
        reasons = {}
        for t in ts:
            if not t["success"]:
                r = DISTANCE.sub("D m from", t.get("failure_reason") or t.get("failure") or "none")
                reasons[r] = reasons.get(r, 0) + 1
        by_kind[k] = {
            "tasks": len(ts),
            "succeeded": s,
            "sr": s / len(ts) if ts else None,
            "sr_95": wilson(s, len(ts)),
            "gate": gates.get(k),
            "gate_met": (s / len(ts) >= gates[k]) if ts and k in gates else None,
        }
        failed_at[k] = {
            "failed": len(ts) - s,
            "median_distance_m": statistics.median(dists) if dists else None,
            "reasons": dict(sorted(reasons.items(), key=lambda kv: -kv[1])),
        }
    tr = train_log or {}
    # The camera and privileged trainers log `expert.episodes`, `rows` and `train_seconds`; the
    # diffusion pipeline logs `episodes`, `samples` and `train_minutes`.
    minutes = tr.get("train_minutes")
    return {
        "track": track,
        "hardware": tr.get("hardware"),
        "training_episodes": (tr.get("expert") or {}).get("episodes", tr.get("training_episodes", tr.get("episodes"))),
        "dagger_episodes": sum(r.get("episodes", 0) for r in tr.get("rounds", [])),
        "training_samples": tr.get("rows", tr.get("samples")),
        "sr_while_driving_by_round": [r.get("sr_while_driving") for r in tr.get("rounds", [])],
        "train_seconds": tr.get("train_seconds", None if minutes is None else round(minutes * 60)),
        "eval_episodes": len(online["episodes"]),
        "eval_seed": online.get("seed"),
        "sr": (online.get("overall") or {}).get("sr"),
        "sr_by_kind": {k: by_kind[k]["sr"] for k in KINDS},
        "tasks_by_kind": {k: by_kind[k]["tasks"] for k in KINDS},
        "sr_95_by_kind": {k: by_kind[k]["sr_95"] for k in KINDS},
        "gates": {k: {"target": by_kind[k]["gate"], "met": by_kind[k]["gate_met"]} for k in KINDS},
        "failed_tasks": failed_at,
        "offline_mse": (offline or {}).get("mse"),
        **(evaluated or {}),
    }


def split_file(split, ground_truth):
    """The JSON Lines file whose plans the split's episodes run."""
    root = Path(os.environ.get("KITCHEN_R_ASSETS", "assets"))
    if split == "dev":
        return root / "dataset" / "dev.jsonl"
    gt = Path(ground_truth) if ground_truth else root / "dataset" / "test_ground_truth.jsonl"
    if not gt.exists():
        raise SystemExit(f"--split test needs the organiser's ground truth: {gt} does not exist (--ground-truth)")
    return gt


def combine(args, gates):
    """One summary over several results folders' episodes."""
    onlines, offlines, parts = [], [], []
    for d in map(Path, args.combine):
        s = json.loads((d / "summary.json").read_text())
        split = s.get("eval_split", "dev")
        onlines.append(json.loads((d / f"eval_{split}.json").read_text()))
        off = d / f"eval_{split}_offline.json"
        offlines.append(json.loads(off.read_text()) if off.exists() else None)
        parts.append(
            {
                "folder": str(d),
                **{
                    k: s.get(k)
                    for k in (
                        "eval_split",
                        "eval_instructions",
                        "eval_seed",
                        "held_out",
                        "sr_by_kind",
                        "tasks_by_kind",
                        "sr_95_by_kind",
                        "offline_mse",
                    )
                },
            }
        )
    online = {"episodes": [e for o in onlines for e in o["episodes"]]}
    tasks = [t for e in online["episodes"] for t in e["tasks"]]
    online["overall"] = {"sr": sum(t["success"] for t in tasks) / len(tasks) if tasks else None}
    mses = [(o["mse"], len(o.get("episodes", [])) or 1) for o in offlines if o and o.get("mse") is not None]
    offline = {"mse": sum(m * n for m, n in mses) / sum(n for _, n in mses)} if mses else None
    train_log = json.loads(Path(args.train_log).read_text()) if args.train_log else None
    evaluated = {"held_out": all(p["held_out"] for p in parts), "parts": parts}
    summary = summarise(online, offline, train_log, args.track, gates, evaluated)
    summary.update(combined_range(parts))
    res = Path(args.out)
    res.mkdir(parents=True, exist_ok=True)
    (res / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    report(summary, res)


def combined_range(parts):
    """What a combined summary was evaluated on, named from its parts: `eval_split` ("dev+test"),
    `eval_instructions` ("dev 101-163, test 1-100") and `eval_seed` (the parts' seed when they
    share one, else None)."""
    seeds = {p["eval_seed"] for p in parts}
    return {
        "eval_split": "+".join(dict.fromkeys(p["eval_split"] for p in parts)),
        "eval_instructions": ", ".join(f"{p['eval_split']} {p['eval_instructions']}" for p in parts),
        "eval_seed": seeds.pop() if len(seeds) == 1 else None,
    }


def report(summary, res):
    for k in KINDS:
        lo, hi = summary["sr_95_by_kind"][k]
        sr = summary["sr_by_kind"][k]
        if sr is None:
            log(f"{k}: no tasks")
            continue
        g = summary["gates"][k]
        log(
            f"{k}: SR {sr:.3f} [{lo:.3f}, {hi:.3f}] over {summary['tasks_by_kind'][k]} tasks; "
            f"gate {g['target']}: {'met' if g['met'] else 'MISSED'}"
        )
    log(f"summary: {res / 'summary.json'}")


def wait_line(path, prefix, proc, timeout=300):
    t0 = time.time()
    while time.time() - t0 < timeout:
        if path.exists():
            for line in path.read_text(errors="replace").splitlines():
                if prefix in line:
                    return line[line.index(prefix) + len(prefix) :].split()[0]
        if proc.poll() is not None:
            tail = "".join(
                p.read_text(errors="replace")[-2000:] for p in (path, path.with_suffix(".err")) if p.exists()
            )
            raise SystemExit(f"{proc.args!r} exited with {proc.returncode} before printing {prefix!r}:\n{tail}")
        time.sleep(0.2)
    raise SystemExit(f"no {prefix!r} from {proc.args!r} in {timeout} s; see {path}")


def run(cmd, out=None, **kw):
    log("$ " + " ".join(shlex.quote(str(c)) for c in cmd))
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)
    if r.returncode != 0:
        sys.stderr.write(r.stdout[-4000:] + r.stderr[-4000:])
        raise SystemExit(f"{cmd[0]} {cmd[1]} failed with exit code {r.returncode}")
    if out is not None:
        Path(out).write_text(r.stdout)
    return r.stdout


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--serve", help="command that serves the policy and prints `listening grpc=HOST:PORT`")
    ap.add_argument("--track", required=True, choices=sorted(GATES), help="the observation track the policy runs on")
    ap.add_argument("--out", required=True, help="results folder")
    ap.add_argument(
        "--episodes", type=int, default=60, help="episodes of the split's first N instructions (dataset order)"
    )
    ap.add_argument(
        "--instructions", help="instead of --episodes: the 1-based inclusive range A-B of the split's instructions"
    )
    ap.add_argument("--split", choices=("dev", "test"), default="dev", help="the split whose instructions are run")
    ap.add_argument("--ground-truth", help="the test split's plans (default assets/dataset/test_ground_truth.jsonl)")
    ap.add_argument("--seed", type=int, default=0, help="batch seed of the randomised episodes")
    ap.add_argument(
        "--held-out",
        action="store_true",
        help="record in summary.json that neither these instructions nor this seed trained or chose the policy",
    )
    ap.add_argument(
        "--combine", nargs="+", metavar="DIR", help="sum these results folders into --out (no policy is run)"
    )
    ap.add_argument("--jobs", type=int, default=os.cpu_count(), help="parallel episodes")
    ap.add_argument("--bin", default=os.environ.get("KITCHEN_R_BIN", "target/release/kitchen-r"))
    ap.add_argument("--train-log", help="train_log.json of the run (training figures for summary.json)")
    ap.add_argument("--no-offline", action="store_true", help="skip the offline (MSE) evaluation")
    ap.add_argument(
        "--leaderboard", action="store_true", help="publish as a baseline row on a local server's dev board"
    )
    ap.add_argument(
        "--leaderboard-episodes",
        type=int,
        default=20,
        help="dev instructions of the reference run (the server's workers also record each episode's "
        "video, so this run costs more than eval's)",
    )
    ap.add_argument("--gate", help="override the gate, e.g. navigation=0.9,pick=0.7,place=0.7")
    args = ap.parse_args()
    gates = dict(GATES[args.track])
    if args.gate:
        gates = {k: float(v) for k, v in (kv.split("=") for kv in args.gate.split(","))}
    if args.combine:
        return combine(args, gates)
    if not args.serve:
        ap.error("--serve is required (or --combine)")
    lines = split_file(args.split, args.ground_truth).read_text().splitlines()
    lines = [ln for ln in lines if ln.strip()]
    lo, hi = (
        instruction_range(args.instructions, len(lines)) if args.instructions else (0, min(args.episodes, len(lines)))
    )
    # The batch seed the episodes were drawn with (eval's own "seed" is the run seed, 0).
    evaluated = {
        "eval_split": args.split,
        "eval_instructions": f"{lo + 1}-{hi}",
        "eval_seed": args.seed,
        "held_out": args.held_out,
    }
    res = Path(args.out)
    res.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="kr-gate-"))
    kr = Path(args.bin).resolve()
    procs = []
    try:
        episodes, chosen = work / "episodes.json", work / "instructions.jsonl"
        chosen.write_text("\n".join(lines[lo:hi]) + "\n")
        run(
            [
                kr,
                "episodes",
                "generate",
                "--from-dataset",
                "--instructions",
                chosen,
                "--count",
                hi - lo,
                "--seed",
                args.seed,
                "--out",
                episodes,
            ]
        )
        serve_log = work / "serve.log"
        p = subprocess.Popen(
            shlex.split(args.serve), stdout=open(serve_log, "w"), stderr=subprocess.STDOUT, start_new_session=True
        )
        procs.append(p)
        addr = wait_line(serve_log, "listening grpc=", p)
        log(f"policy at {addr}")
        run([kr, "check-policy", f"http://{addr}"], res / "check_policy.txt")
        t0 = time.time()
        run(
            [kr, "eval", "--policy", f"http://{addr}", "--episodes-file", episodes, "--json", "--jobs", args.jobs],
            res / f"eval_{args.split}.json",
        )
        online = json.loads((res / f"eval_{args.split}.json").read_text())
        log(f"online: {hi - lo} episodes in {time.time() - t0:.0f} s")
        offline = None
        if not args.no_offline:
            run(
                [
                    kr,
                    "eval",
                    "--policy",
                    f"http://{addr}",
                    "--mode",
                    "offline",
                    "--episodes-file",
                    episodes,
                    "--json",
                    "--jobs",
                    args.jobs,
                ],
                res / f"eval_{args.split}_offline.json",
            )
            offline = json.loads((res / f"eval_{args.split}_offline.json").read_text())
        train_log = json.loads(Path(args.train_log).read_text()) if args.train_log else None
        summary = summarise(online, offline, train_log, args.track, gates, evaluated)
        (res / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
        report(summary, res)
        if args.leaderboard:
            publish(kr, addr, args, res, work, procs)
    finally:
        for p in procs:
            try:
                os.killpg(p.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass


def publish(kr, addr, args, res, work, procs):
    """A reference run (the organiser's baseline row) on a fresh local server's dev board."""
    d = work / "server"
    d.mkdir()
    admin = f"gate-admin-{os.getpid()}"
    (d / "server.toml").write_text(
        f'http = "127.0.0.1:0"\ngrpc = "127.0.0.1:0"\ndb = "sqlite://{d}/kitchen-r.db"\nworkers = {args.jobs}\n\n'
        f"[control]\nprivileged_track = {'true' if args.track == 'privileged' else 'false'}\n"
    )
    out = d / "serve.out"
    env = dict(os.environ, KITCHEN_R_ADMIN_TOKEN=admin)
    p = subprocess.Popen(
        [str(kr), "serve", "--config", str(d / "server.toml")],
        stdout=open(out, "w"),
        stderr=open(d / "serve.err", "w"),
        env=env,
        start_new_session=True,
    )
    procs.append(p)
    http = "http://" + wait_line(out, "http=", p)
    run(
        [
            kr,
            "submit",
            "policy",
            f"http://{addr}",
            "--split",
            "dev",
            "--episodes",
            args.leaderboard_episodes,
            "--reference",
            "--token",
            admin,
            "--server",
            http,
            "--wait",
            "--json",
        ],
        res / "submission.json",
    )
    run(
        [
            kr,
            "leaderboard",
            "--track",
            "control",
            "--split",
            "dev",
            "--observations",
            args.track,
            "--format",
            "json",
            "--server",
            http,
        ],
        res / "leaderboard_dev_control.json",
    )


if __name__ == "__main__":
    main()
