#!/usr/bin/env bash
# The diffusion-policy baseline from nothing to leaderboard on one GPU machine:
# collect -> train -> serve -> check-policy -> eval (online SR, offline MSE) -> reference run on a
# local server's dev control leaderboard. Run from anywhere; long, so in the background:
#
#   KR_BIN=/path/kitchen-r EPISODES=1000 TRAIN_MIN=60 EVAL_EPISODES=50 WORK=/data/kr \
#     setsid nohup bash starter-kit/baselines/diffusion_policy/device_pipeline.sh >/data/kr.out 2>&1 &
#   tail -f /data/kr/pipeline.log
#
# Settings (environment):
#   KR_BIN         the kitchen-r binary                       [REPO/target/release/kitchen-r]
#   EPISODES       training episodes to collect (dev instructions, collect seed COLLECT_SEED) [1000]
#   COLLECT_SEED   collection seed; eval uses seed 0, so a seed != 0 keeps eval episodes unseen [1]
#   TRAIN_INSTRUCTIONS  collect only from these dev instructions (1-based inclusive range, e.g.
#                  1-100), cycled, so the rest stay held out (held_out.sh's TRAIN=diff) [every one]
#   TRAIN_MIN      training minutes                           [60]
#   TRAIN_ARGS     extra train.py arguments (e.g. "--batch 128")               []
#   DEVICE         torch device for training and serving       [cuda if available, else cpu]
#   EVAL_EPISODES  dev instructions for eval and for the leaderboard run [50]
#   EVAL_JOBS      parallel eval episodes                      [16]
#   TASK_TIME_LIMIT, MAX_PLAN_STEPS  eval and leaderboard run: sim seconds per task, plan steps
#                  per episode (0 = all); smaller only for a quick trial [120, 0]
#   INIT           start training from this checkpoint (train.py --init: fine-tune on new data) []
#   STOP_AFTER     stop after this step (collect, train, check_policy, eval_online, eval_offline) []
#   WORK           working directory                          [/tmp/kr-diffusion]
#   PYTHON         python with the baselines installed (pip install -e ./starter-kit -e "./starter-kit/baselines[control]":
#                  torch, torchvision, pyarrow, av, grpcio(-tools, -health-checking)) [python3]
#   KITCHEN_R_ASSETS, KITCHEN_R_CONFIGS                       [REPO/assets, REPO/configs]
#
# Every step logs to $WORK/pipeline.log (timestamped) and leaves its result in $WORK/results/
# (collect.json, train_log.json + ckpt.pt, check_policy.txt, eval_dev.json, eval_dev_offline.json,
# submission.json, leaderboard_dev_control.json, summary.json). A step whose result exists is
# skipped, so rerunning the script resumes where it stopped.
set -euo pipefail

HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/../../.." && pwd)"
KR_BIN="${KR_BIN:-$REPO/target/release/kitchen-r}"
EPISODES="${EPISODES:-1000}"
COLLECT_SEED="${COLLECT_SEED:-1}"
TRAIN_MIN="${TRAIN_MIN:-60}"
TRAIN_ARGS="${TRAIN_ARGS:-}"
EVAL_EPISODES="${EVAL_EPISODES:-50}"
EVAL_JOBS="${EVAL_JOBS:-16}"
TASK_TIME_LIMIT="${TASK_TIME_LIMIT:-120}"
MAX_PLAN_STEPS="${MAX_PLAN_STEPS:-0}"
WORK="${WORK:-/tmp/kr-diffusion}"
PYTHON="${PYTHON:-python3}"
export KITCHEN_R_ASSETS="${KITCHEN_R_ASSETS:-$REPO/assets}"
export KITCHEN_R_CONFIGS="${KITCHEN_R_CONFIGS:-$REPO/configs}"
export RUST_LOG="${RUST_LOG:-warn}"
RES="$WORK/results"
LOG="$WORK/pipeline.log"
mkdir -p "$RES"
KR_BIN="$(cd "$(dirname "$KR_BIN")" && pwd)/$(basename "$KR_BIN")"
WORK="$(cd "$WORK" && pwd)"
RES="$WORK/results"
LOG="$WORK/pipeline.log"

log() { echo "$(date -u +%Y-%m-%dT%H:%M:%SZ) $*" | tee -a "$LOG"; }
die() {
  log "FAILED: $*"
  exit 1
}
[ -x "$KR_BIN" ] || die "KR_BIN=$KR_BIN is not an executable kitchen-r binary"
if [ -z "${DEVICE:-}" ]; then
  DEVICE="$("$PYTHON" -c 'import torch; print("cuda" if torch.cuda.is_available() else "cpu")')" ||
    die "$PYTHON cannot import torch"
fi

PIDS=()
cleanup() {
  for p in "${PIDS[@]}"; do kill "$p" 2>/dev/null || true; done
}
trap cleanup EXIT

# Run step NAME (result file RESULT) with the command after `--`, unless RESULT exists.
step() {
  local name="$1" result="$2"
  shift 3
  if [ -s "$result" ]; then
    log "step $name: done before ($result), skipped"
    return 0
  fi
  log "step $name: start"
  local t0=$SECONDS
  "$@" || die "step $name exited with $? (see $LOG and $WORK/$name.log)"
  log "step $name: done in $((SECONDS - t0)) s -> $result"
  echo "{\"step\":\"$name\",\"seconds\":$((SECONDS - t0)),\"at\":\"$(date -u +%Y-%m-%dT%H:%M:%SZ)\"}" >>"$RES/steps.jsonl"
}
# Stop here when STOP_AFTER names step NAME (a later run resumes after it).
stop_after() {
  if [ "${STOP_AFTER:-}" = "$1" ]; then
    log "stopping after step $1 (STOP_AFTER)"
    exit 0
  fi
}

# Wait for a line starting with PREFIX in FILE (from a background process PID); print the line.
await_line() {
  local file="$1" prefix="$2" pid="$3" i
  for i in $(seq 1 600); do
    if grep -q "^$prefix" "$file" 2>/dev/null; then
      grep -m1 "^$prefix" "$file"
      return 0
    fi
    kill -0 "$pid" 2>/dev/null || return 1
    sleep 0.5
  done
  return 1
}

log "pipeline: KR_BIN=$KR_BIN EPISODES=$EPISODES COLLECT_SEED=$COLLECT_SEED TRAIN_INSTRUCTIONS=${TRAIN_INSTRUCTIONS:-all} TRAIN_MIN=$TRAIN_MIN EVAL_EPISODES=$EVAL_EPISODES DEVICE=$DEVICE WORK=$WORK cores=$(nproc)"
{
  uname -a
  nproc
  free -g 2>/dev/null || true
  nvidia-smi 2>/dev/null || true
  "$PYTHON" -c 'import torch; print("torch", torch.__version__, torch.cuda.get_device_name(0) if torch.cuda.is_available() else "cpu")'
} >"$RES/hardware.txt" 2>&1 || true

# 1. Collect the training set (oracle expert, LeRobot v3.0 export, both cameras, no depth).
collect() {
  local which=(--episodes "$EPISODES")
  if [ -n "${TRAIN_INSTRUCTIONS:-}" ]; then
    # The range's instructions only, as a batch of episodes (randomised with the collection seed).
    local first="${TRAIN_INSTRUCTIONS%-*}" last="${TRAIN_INSTRUCTIONS#*-}"
    sed -n "${first},${last}p" "$KITCHEN_R_ASSETS/dataset/dev.jsonl" >"$WORK/train_instructions.jsonl"
    [ -s "$WORK/train_instructions.jsonl" ] || die "TRAIN_INSTRUCTIONS=$TRAIN_INSTRUCTIONS selects no dev instruction"
    "$KR_BIN" episodes generate --from-dataset --instructions "$WORK/train_instructions.jsonl" --count "$EPISODES" \
      --seed "$COLLECT_SEED" --out "$WORK/train_episodes.json" 2>>"$WORK/collect.log" || die "episodes generate failed"
    which=(--episodes-file "$WORK/train_episodes.json")
  fi
  "$KR_BIN" collect "${which[@]}" --seed "$COLLECT_SEED" --out "$WORK/collect" --format lerobot \
    --cameras base,gripper --no-depth --jobs "$(nproc)" --json >"$WORK/collect.json.part" 2>"$WORK/collect.log" &&
    mv "$WORK/collect.json.part" "$RES/collect.json"
}
step collect "$RES/collect.json" -- collect
stop_after collect

# 2. Train on the GPU (the checkpoint is rewritten every 10 min; train_log.json comes last).
train() {
  rm -f "$RES/train_log.json"
  # shellcheck disable=SC2086
  "$PYTHON" "$HERE/train.py" --dataset "$WORK/collect/lerobot" --out "$RES/ckpt.pt" --minutes "$TRAIN_MIN" \
    --device "$DEVICE" --log "$WORK/train_log.json.part" ${INIT:+--init "$INIT"} $TRAIN_ARGS >"$WORK/train.log" 2>&1 &&
    mv "$WORK/train_log.json.part" "$RES/train_log.json"
}
step train "$RES/train_log.json" -- train
# (No train.log when the checkpoint came from elsewhere and the step was skipped.)
if [ -f "$WORK/train.log" ]; then tail -n 2 "$WORK/train.log" | while read -r l; do log "train: $l"; done; fi
stop_after train

# 3. Serve the checkpoint (for every later step; stopped when the script exits).
ADDR=""
serve_policy() {
  "$PYTHON" "$HERE/serve.py" --checkpoint "$RES/ckpt.pt" --listen 127.0.0.1:0 --device "$DEVICE" \
    --concurrency "$EVAL_JOBS" >"$WORK/serve.log" 2>&1 &
  PIDS+=($!)
  local line
  line="$(await_line "$WORK/serve.log" "listening grpc=" $!)" || die "serve.py did not start (see $WORK/serve.log)"
  ADDR="${line#listening grpc=}"
  log "policy served at $ADDR"
}
need_policy=0
for f in check_policy.txt eval_dev.json eval_dev_offline.json leaderboard_dev_control.json; do
  [ -s "$RES/$f" ] || need_policy=1
done
[ "$need_policy" = 1 ] && serve_policy

# 4. The contract checks.
check() {
  "$KR_BIN" check-policy "http://$ADDR" >"$WORK/check_policy.part" 2>&1 && mv "$WORK/check_policy.part" "$RES/check_policy.txt"
}
step check_policy "$RES/check_policy.txt" -- check
stop_after check_policy

# 5. Local evaluation on dev: online (SR per task kind) and offline (MSE against the expert).
sed -e "s/^task_time_limit = .*/task_time_limit = $TASK_TIME_LIMIT/" -e "s/^max_plan_steps = .*/max_plan_steps = $MAX_PLAN_STEPS/" \
  "$KITCHEN_R_CONFIGS/eval.toml" >"$WORK/eval.toml"
eval_online() {
  "$KR_BIN" eval --policy "http://$ADDR" --split dev --episodes "$EVAL_EPISODES" --json --jobs "$EVAL_JOBS" \
    --config "$WORK/eval.toml" >"$WORK/eval_dev.part" 2>"$WORK/eval_online.log" && mv "$WORK/eval_dev.part" "$RES/eval_dev.json"
}
step eval_online "$RES/eval_dev.json" -- eval_online
stop_after eval_online
eval_offline() {
  "$KR_BIN" eval --policy "http://$ADDR" --mode offline --split dev --episodes "$EVAL_EPISODES" --json \
    --jobs "$EVAL_JOBS" --config "$WORK/eval.toml" >"$WORK/eval_offline.part" 2>"$WORK/eval_offline.log" &&
    mv "$WORK/eval_offline.part" "$RES/eval_dev_offline.json"
}
step eval_offline "$RES/eval_dev_offline.json" -- eval_offline
stop_after eval_offline

# 6. An organiser reference run (baseline row) on a local server's dev control leaderboard.
leaderboard() {
  local dir="$WORK/server" admin line http
  mkdir -p "$dir"
  admin="baseline-admin-$(date +%s%N)"
  cat >"$dir/server.toml" <<EOF
http = "127.0.0.1:0"
grpc = "127.0.0.1:0"
db = "sqlite://$dir/kitchen-r.db"
workers = $EVAL_JOBS

[control]
task_time_limit_s = $TASK_TIME_LIMIT
max_plan_steps = $MAX_PLAN_STEPS
EOF
  KITCHEN_R_ADMIN_TOKEN="$admin" "$KR_BIN" serve --config "$dir/server.toml" >"$dir/serve.out" 2>"$WORK/leaderboard.log" &
  local spid=$!
  PIDS+=($spid)
  line="$(await_line "$dir/serve.out" "listening " $spid)" || die "kitchen-r serve did not start (see $WORK/leaderboard.log)"
  http="http://$(echo "$line" | tr ' ' '\n' | sed -n 's/^http=//p')"
  log "server at $http; submitting the reference run"
  "$KR_BIN" submit policy "http://$ADDR" --split dev --episodes "$EVAL_EPISODES" --reference --token "$admin" \
    --server "$http" --wait --json >"$RES/submission.json.part" 2>>"$WORK/leaderboard.log" || return 1
  mv "$RES/submission.json.part" "$RES/submission.json"
  "$KR_BIN" leaderboard --track control --split dev --format json --server "$http" >"$WORK/leaderboard.part" &&
    mv "$WORK/leaderboard.part" "$RES/leaderboard_dev_control.json"
  kill "$spid" 2>/dev/null || true
}
step leaderboard "$RES/leaderboard_dev_control.json" -- leaderboard

# 7. The figures in one file.
"$PYTHON" - "$RES" <<'PY'
import json, sys
from pathlib import Path
res = Path(sys.argv[1])
load = lambda n: json.loads((res / n).read_text()) if (res / n).is_file() else None
on, off, tr, col = load("eval_dev.json"), load("eval_dev_offline.json"), load("train_log.json"), load("collect.json")
kinds = (on or {}).get("by_kind", {})
summary = {
    "training_episodes": (tr or {}).get("episodes"),
    "training_frames": (tr or {}).get("frames"),
    "collect_wall_s": (col or {}).get("wall_s"),
    "train_minutes": (tr or {}).get("train_minutes"),
    "train_steps": (tr or {}).get("steps"),
    "final_loss": (tr or {}).get("final_loss"),
    "hardware": (tr or {}).get("hardware"),
    "eval_episodes": len((on or {}).get("episodes", [])),
    "sr": (on or {}).get("sr"),
    "sr_by_kind": {k: kinds.get(k, {}).get("sr") for k in ("navigation", "pick", "place")},
    "tasks_by_kind": {k: kinds.get(k, {}).get("tasks") for k in ("navigation", "pick", "place")},
    "offline_mse": (off or {}).get("mse"),
}
(res / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
print(json.dumps(summary))
PY
log "summary: $(cat "$RES/summary.json" | tr -d '\n ')"
log "pipeline finished"
