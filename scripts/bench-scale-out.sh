#!/usr/bin/env bash
# Scale-out of the control track (issue #13 item 7): the server with no simulation slots of its
# own (`serve --workers 0`) and K standalone `kitchen-r worker` processes (one slot each) evaluate
# the oracle reference run over gRPC on loopback. Prints episodes per minute for K = 1 and K = 2
# and the scaling efficiency, then a second run in which a worker is added mid-run and another
# stopped with SIGTERM, and checks that no episode was lost or counted twice.
#
#   KITCHEN_R_BIN=target/release/kitchen-r bash scripts/bench-scale-out.sh [INSTRUCTIONS]
#
# INSTRUCTIONS (default 8) dev instructions per run; with offline MSE on (the default) each
# gives an online and an offline episode. Everything listens on 127.0.0.1 and every process is
# stopped on exit. On a 2-core machine K = 2 is the most that can scale.
set -euo pipefail
bin=${KITCHEN_R_BIN:-target/release/kitchen-r}
n=${1:-8}
work=$(mktemp -d)
pids=()
cleanup() {
  # Workers started inside a subshell (the elastic hook) are recorded in $work/pids.
  for p in "${pids[@]}" $(cat "$work/pids" 2>/dev/null); do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT

export KITCHEN_R_ADMIN_TOKEN=bench-admin-token-0123456789
export KITCHEN_R_WORKER_TOKEN=bench-worker-token-0123456789

wait_line() { # FILE PREFIX: print what follows PREFIX on its first line, waiting up to 60 s
  for _ in $(seq 600); do
    if grep -q "^$2" "$1" 2>/dev/null; then sed -n "s/^$2//p" "$1" | head -1; return; fi
    sleep 0.1
  done
  echo "timed out waiting for '$2' in $1" >&2; cat "$1" >&2; exit 1
}

"$bin" policy oracle --listen 127.0.0.1:0 --max-concurrency 8 > "$work/policy.out" 2>/dev/null &
pids+=($!)
policy=$(wait_line "$work/policy.out" 'listening grpc=')

start_server() { # NAME: a fresh server, prints "HTTP GRPC"
  "$bin" serve --workers 0 --http 127.0.0.1:0 --grpc 127.0.0.1:0 \
    --db "sqlite://$work/$1.db" > "$work/$1.out" 2> "$work/$1.err" &
  pids+=($!)
  local line
  line=$(wait_line "$work/$1.out" 'listening ')
  local http grpc
  http=$(sed -n 's/.*http=\([^ ]*\).*/\1/p' <<< "$line")
  grpc=$(sed -n 's/.*grpc=\([^ ]*\).*/\1/p' <<< "$line")
  echo "$http $grpc"
}

start_worker() { # GRPC NAME: a standalone worker with one slot; prints its pid
  "$bin" worker --server "http://$1" --slots 1 --worker-id "$2" > "$work/$2.log" 2>&1 &
  echo $! >> "$work/pids"
  echo $!
}

register() { # HTTP: the reference run of N instructions; prints its submission id
  "$bin" submit policy "http://$policy" --split dev --episodes "$n" --reference \
    --server "http://$1" --token "$KITCHEN_R_ADMIN_TOKEN" --json |
    python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])'
}

progress() { # HTTP ID: "done total state failed"
  python3 - "$1" "$2" <<'PY'
import json, os, sys, urllib.request
req = urllib.request.Request(f"http://{sys.argv[1]}/api/v1/submissions/{sys.argv[2]}",
    headers={"Authorization": "Bearer " + os.environ["KITCHEN_R_ADMIN_TOKEN"]})
run = json.load(urllib.request.urlopen(req, timeout=10))["latest_run"]
ev = run["evaluation"]
failed = sum(1 for e in ev["episodes"] if e.get("failure"))
print(ev["episodes_done"], ev["episodes_total"], ev["state"], failed)
PY
}

# Waits until the run finishes (at most 30 min); runs HOOK with the done fraction as it goes.
follow() { # HTTP ID HOOK
  local started=$SECONDS
  while :; do
    read -r done total state failed < <(progress "$1" "$2")
    "$3" "$done" "$total"
    if [ "$state" != "queued" ] && [ "$state" != "running" ]; then
      echo "$done $total $state $failed $((SECONDS - started))"
      return
    fi
    if (( SECONDS - started > 1800 )); then echo "run $2 did not finish in 30 min" >&2; exit 1; fi
    sleep 0.5
  done
}
no_hook() { :; }

declare -A rate
for k in 1 2; do
  read -r http grpc < <(start_server "k$k")
  started_ns=$(date +%s%N)
  id=$(register "$http")
  for w in $(seq "$k"); do pids+=("$(start_worker "$grpc" "k$k-w$w")"); done
  read -r done total state failed _ < <(follow "$http" "$id" no_hook)
  secs=$(python3 -c "import sys; print((int(sys.argv[2]) - int(sys.argv[1])) / 1e9)" "$started_ns" "$(date +%s%N)")
  rate[$k]=$(python3 -c "import sys; print(int(sys.argv[1]) / float(sys.argv[2]) * 60)" "$done" "$secs")
  printf 'K=%s workers: %s/%s episodes in %.1f s, %.1f episodes/min (run %s, %s failed)\n' \
    "$k" "$done" "$total" "$secs" "${rate[$k]}" "$state" "$failed"
done
python3 -c "import sys; r1, r2 = map(float, sys.argv[1:]); print(f'scaling efficiency K=2: {r2 / r1 / 2:.2f} ({r2 / r1:.2f}x the rate of one worker)')" "${rate[1]}" "${rate[2]}"

# Elastic run: one worker, a second joins at a third of the episodes, the first is stopped with
# SIGTERM at two thirds. Every episode must be done exactly once.
read -r http grpc < <(start_server elastic)
id=$(register "$http")
first=$(start_worker "$grpc" elastic-w1); pids+=("$first")
second=""
elastic_hook() { # DONE TOTAL
  if [ -z "$second" ] && (( $1 * 3 >= $2 )); then
    second=$(start_worker "$grpc" elastic-w2); pids+=("$second")
    echo "  added a worker at $1/$2 episodes" >&2
  fi
  if [ -n "$first" ] && [ -n "$second" ] && (( $1 * 3 >= $2 * 2 )); then
    kill -TERM "$first" 2>/dev/null || true
    echo "  sent SIGTERM to the first worker at $1/$2 episodes" >&2
    first=""
  fi
}
read -r done total state failed secs < <(follow "$http" "$id" elastic_hook)
echo "elastic: $done/$total episodes, run $state, $failed failed, ${secs} s"
results=$(python3 - "$work/elastic.db" "$id" <<'PY'
import sqlite3, sys
db = sqlite3.connect(sys.argv[1])
rows = db.execute(
    "SELECT COUNT(*), COUNT(DISTINCT e.episode_key) FROM episode_results e "
    "JOIN scoring_runs r ON r.id = e.run_id WHERE r.submission_id = ?", (int(sys.argv[2]),)).fetchone()
print(*rows)
PY
)
read -r stored distinct <<< "$results"
if [ "$done" != "$total" ] || [ "$stored" != "$total" ] || [ "$distinct" != "$total" ]; then
  echo "LOST OR DOUBLED: $done done, $stored results stored ($distinct distinct) of $total" >&2
  exit 1
fi
echo "no episode lost or counted twice: $stored results for $total episodes"
