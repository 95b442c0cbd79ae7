#!/usr/bin/env bash
# Batched decisions, measured side by side in one run (docs/participant/policy-contract.md,
# "Batched decisions"): the camera baseline served once, declaring max_batch, and evaluated on
# the same episodes twice, batched (ActBatch) and unbatched (`eval --max-batch 1`: every decision
# its own Act); then the oracle served over gRPC on the same episodes, the ceiling. Prints one
# JSON object with episodes per minute for each, and writes each run's report beside it.
#
#   bash starter-kit/baselines/camera/batch_speed.sh CKPT [EPISODES] [JOBS]
#
# CKPT: a camera checkpoint (starter-kit/baselines/camera/results/*/ckpt.pt); EPISODES [103]
# dev instructions from the first; JOBS [16] episodes at once (and the policy's max_concurrency
# and max_batch). Environment: KITCHEN_R_BIN [target/release/kitchen-r], DEVICE [auto],
# OUT [/tmp/kr-batch-speed], SEED [0], GATHER_MS [2] (the gather window), EVAL_ARGS (more
# `kitchen-r eval` flags for every run, e.g. `--config short.toml` for a quick try). Needs python3 with the
# baselines installed (pip install -e ./starter-kit -e "./starter-kit/baselines[control]").
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/../../.." && pwd)"
cd "$REPO"
CKPT="${1:?usage: batch_speed.sh CKPT [EPISODES] [JOBS]}"
EPISODES="${2:-103}"
JOBS="${3:-16}"
BIN="${KITCHEN_R_BIN:-target/release/kitchen-r}"
DEVICE="${DEVICE:-auto}"
OUT="${OUT:-/tmp/kr-batch-speed}"
SEED="${SEED:-0}"
GATHER_MS="${GATHER_MS:-2}"
read -r -a EXTRA <<<"${EVAL_ARGS:-}"
mkdir -p "$OUT"
PIDS=()
URL=""
trap 'for p in "${PIDS[@]}"; do kill "$p" 2>/dev/null || true; done' EXIT

# Start a server command in the background; its `listening grpc=HOST:PORT` line gives URL.
serve() {
  local log="$1"
  shift
  "$@" >"$log" 2>&1 &
  local pid=$!
  PIDS+=("$pid")
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

# `kitchen-r eval` of URL on the episodes; the report goes to $OUT/NAME.json.
evaluate() {
  local name="$1" url="$2"
  shift 2
  "$BIN" eval --policy "$url" --episodes "$EPISODES" --jobs "$JOBS" --seed "$SEED" \
    --batch-gather-ms "$GATHER_MS" --json "${EXTRA[@]}" "$@" >"$OUT/$name.json" 2>"$OUT/$name.log"
}

serve "$OUT/camera_serve.log" python3 "$HERE/serve.py" --checkpoint "$CKPT" --listen 127.0.0.1:0 \
  --device "$DEVICE" --concurrency "$JOBS" --max-batch "$JOBS"
evaluate camera_batched "$URL"
evaluate camera_unbatched "$URL" --max-batch 1
serve "$OUT/oracle_serve.log" "$BIN" policy oracle --listen 127.0.0.1:0 --max-concurrency "$JOBS" --max-batch "$JOBS"
evaluate oracle "$URL" --privileged

python3 - "$OUT" "$EPISODES" "$JOBS" <<'EOF'
import json
import sys

out, episodes, jobs = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
result = {"episodes": episodes, "jobs": jobs}
for name in ("camera_batched", "camera_unbatched", "oracle"):
    r = json.load(open(f"{out}/{name}.json"))
    n = len(r["episodes"])
    result[name] = {
        "episodes": n,
        "wall_s": round(r["total_wall_s"], 1),
        "episodes_per_minute": round(60 * n / r["total_wall_s"], 1),
        "sr": r["sr"],
        "mean_batch": round(r["batching"]["mean_batch"], 2),
    }
b, u = result["camera_batched"], result["camera_unbatched"]
result["camera_speedup"] = round(b["episodes_per_minute"] / u["episodes_per_minute"], 2)
# Batching changes no rule: the same episodes, the same outcomes (up to the float rounding of a
# network run at another batch size, which may move a task's outcome).
cmp = lambda name: [[t["success"] for t in e["tasks"]] for e in json.load(open(f"{out}/{name}.json"))["episodes"]]
result["camera_same_outcomes"] = cmp("camera_batched") == cmp("camera_unbatched")
print(json.dumps(result, indent=1))
EOF
