#!/usr/bin/env bash
# Batched decisions, measured side by side in one run (docs/participant/policy-contract.md,
# "Batched decisions"): for each jobs count, the camera baseline served once, declaring
# max_batch, and evaluated on the same episodes twice, batched (ActBatch) and unbatched
# (`eval --max-batch 1`: every decision its own Act); then the oracle served over gRPC on the
# same episodes, the ceiling. Prints one JSON object with episodes per minute for each run and
# where the CPU went (the eval process's and the policy server's CPU seconds per decision), and
# writes each run's report beside it.
#
#   bash starter-kit/baselines/camera/batch_speed.sh CKPT [EPISODES] [JOBS...]
#
# CKPT: a camera checkpoint (starter-kit/baselines/camera/results/*/ckpt.pt); EPISODES [103]
# dev instructions from the first; JOBS [16] episodes at once, one or more counts (each the
# policy's max_concurrency and max_batch too). Environment: KITCHEN_R_BIN
# [target/release/kitchen-r], DEVICE [auto], OUT [/tmp/kr-batch-speed], SEED [0], GATHER_MS [2]
# (the gather window), EVAL_ARGS (more `kitchen-r eval` flags for every run, e.g. `--config
# short.toml` for a quick try), SERVE_ARGS (more camera serve.py flags, e.g. `--no-cuda-graphs`),
# REFERENCE (a jobs count: also run the setup before batched decisions and CUDA graphs, in the
# same run: eager passes, one Act per decision, REFERENCE jobs; each jobs count's result then
# has `speedup_vs_reference`). Needs python3 with the baselines installed (pip install -e
# ./starter-kit -e "./starter-kit/baselines[control]").
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/../../.." && pwd)"
cd "$REPO"
CKPT="${1:?usage: batch_speed.sh CKPT [EPISODES] [JOBS...]}"
EPISODES="${2:-103}"
shift $(($# < 2 ? $# : 2))
JOBS_LIST=("${@:-16}")
[ ${#JOBS_LIST[@]} -gt 0 ] || JOBS_LIST=(16)
BIN="${KITCHEN_R_BIN:-target/release/kitchen-r}"
DEVICE="${DEVICE:-auto}"
OUT="${OUT:-/tmp/kr-batch-speed}"
SEED="${SEED:-0}"
GATHER_MS="${GATHER_MS:-2}"
read -r -a EXTRA <<<"${EVAL_ARGS:-}"
read -r -a SERVE_EXTRA <<<"${SERVE_ARGS:-}"
mkdir -p "$OUT"
PIDS=()
URL=""
SERVER=""
trap 'for p in "${PIDS[@]}"; do kill "$p" 2>/dev/null || true; done' EXIT
TICK=$(getconf CLK_TCK)

# Start a server command in the background; its `listening grpc=HOST:PORT` line gives URL,
# its process SERVER.
serve() {
  local log="$1"
  shift
  "$@" >"$log" 2>&1 &
  local pid=$!
  PIDS+=("$pid")
  SERVER=$pid
  for _ in $(seq 1 1200); do
    if grep -q "^listening grpc=" "$log"; then
      URL="http://$(grep -m1 "^listening grpc=" "$log" | cut -d= -f2)"
      return
    fi
    kill -0 "$pid" 2>/dev/null || { cat "$log" >&2; exit 1; }
    sleep 0.1
  done
  echo "no listening line in $log" >&2
  exit 1
}

# Stop the server and reap it now: bash's `time` counts the CPU of every child reaped while it
# runs, so a server reaped during the next eval would be billed to that eval.
stop() {
  kill "$SERVER" 2>/dev/null || true
  wait "$SERVER" 2>/dev/null || true
}

# CPU seconds (user + system) a process has used so far.
cpu_of() { awk -v t="$TICK" '{ printf "%.2f", ($14 + $15) / t }' "/proc/$1/stat"; }

# `kitchen-r eval` of URL on the episodes with JOBS jobs; the report goes to $OUT/NAME.json,
# and to $OUT/NAME.cpu the eval's user and system CPU seconds, then the server's CPU seconds
# before and after.
evaluate() {
  local name="$1" url="$2" jobs="$3"
  shift 3
  local before TIMEFORMAT="%U %S"
  before=$(cpu_of "$SERVER")
  { time "$BIN" eval --policy "$url" --episodes "$EPISODES" --jobs "$jobs" --seed "$SEED" \
    --batch-gather-ms "$GATHER_MS" --json "${EXTRA[@]}" "$@" >"$OUT/$name.json" 2>"$OUT/$name.log"; } 2>"$OUT/$name.time"
  echo "$(cat "$OUT/$name.time") $before $(cpu_of "$SERVER")" >"$OUT/$name.cpu"
}

REFERENCE="${REFERENCE:-}"
if [ -n "$REFERENCE" ]; then
  serve "$OUT/reference_serve.log" python3 "$HERE/serve.py" --checkpoint "$CKPT" --listen 127.0.0.1:0 \
    --device "$DEVICE" --concurrency "$REFERENCE" --max-batch 1 --no-cuda-graphs
  evaluate reference "$URL" "$REFERENCE" --max-batch 1
  stop
fi

for J in "${JOBS_LIST[@]}"; do
  serve "$OUT/camera_serve_$J.log" python3 "$HERE/serve.py" --checkpoint "$CKPT" --listen 127.0.0.1:0 \
    --device "$DEVICE" --concurrency "$J" --max-batch "$J" "${SERVE_EXTRA[@]}"
  evaluate "camera_batched_$J" "$URL" "$J"
  evaluate "camera_unbatched_$J" "$URL" "$J" --max-batch 1
  stop
  serve "$OUT/oracle_serve_$J.log" "$BIN" policy oracle --listen 127.0.0.1:0 --max-concurrency "$J" --max-batch "$J"
  evaluate "oracle_$J" "$URL" "$J" --privileged
  stop
done

python3 - "$OUT" "$EPISODES" "$REFERENCE" "${JOBS_LIST[@]}" <<'PY'
import json
import sys

out, episodes, reference = sys.argv[1], int(sys.argv[2]), sys.argv[3]
jobs_list = [int(j) for j in sys.argv[4:]]
result = {"episodes": episodes, "jobs": jobs_list}


def run(name):
    r = json.load(open(f"{out}/{name}.json"))
    user, system, before, after = (float(x) for x in open(f"{out}/{name}.cpu").read().split())
    n = len(r["episodes"])
    return {
        "episodes": n,
        "wall_s": round(r["total_wall_s"], 1),
        "episodes_per_minute": round(60 * n / r["total_wall_s"], 1),
        "sr": r["sr"],
        "mean_batch": round(r["batching"]["mean_batch"], 2) if "batching" in r else 0.0,
        # Where the time went: the simulators (eval) and the policy server, CPU seconds.
        "eval_cpu_s": round(user + system, 1),
        "server_cpu_s": round(after - before, 1),
    }


def outcomes(name):
    return [[t["success"] for t in e["tasks"]] for e in json.load(open(f"{out}/{name}.json"))["episodes"]]


if reference:
    result["reference"] = dict(run("reference"), jobs=int(reference), setup="eager passes, one Act per decision")
for j in jobs_list:
    b, u = run(f"camera_batched_{j}"), run(f"camera_unbatched_{j}")
    result[f"jobs_{j}"] = {
        "camera_batched": b,
        "camera_unbatched": u,
        "oracle": run(f"oracle_{j}"),
        "camera_speedup": round(b["episodes_per_minute"] / u["episodes_per_minute"], 2),
        # Batching changes no rule: the same episodes, the same outcomes, up to the float rounding
        # of a network run at another batch size on a GPU, which may move a task's outcome.
        "camera_same_outcomes": outcomes(f"camera_batched_{j}") == outcomes(f"camera_unbatched_{j}"),
    }
    if reference:
        result[f"jobs_{j}"]["speedup_vs_reference"] = round(
            b["episodes_per_minute"] / result["reference"]["episodes_per_minute"], 2
        )
print(json.dumps(result, indent=1))
PY
