#!/usr/bin/env bash
# Scale-out of the control track (docs/control-track-worker.md): the server with no simulation slots of its
# own (`serve --workers 0`) and K standalone `kitchen-r worker` processes (one slot and one
# episode at a time each, so K counts simulation processes) evaluate
# the oracle reference run over gRPC on loopback. Prints episodes per minute for K = 1 and K = 2
# and the scaling efficiency, then a second run in which a worker is added mid-run and another
# stopped with SIGTERM, and checks that no episode was lost or counted twice.
#
#   KITCHEN_R_BIN=target/release/kitchen-r bash benchmarks/bench-scale-out.sh [INSTRUCTIONS]
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

source "$(dirname "$0")/bench-lib.sh"

"$bin" policy oracle --listen 127.0.0.1:0 --max-concurrency 8 > "$work/policy.out" 2>/dev/null &
pids+=($!)
policy=$(wait_line "$work/policy.out" 'listening grpc=')

declare -A rate
for k in 1 2; do
  read -r done total state failed secs rate[$k] _ < <(measure "k$k" "$k" --slots 1 --max-episodes 1)
  printf 'K=%s workers: %s/%s episodes in %.1f s, %.1f episodes/min (run %s, %s failed)\n' \
    "$k" "$done" "$total" "$secs" "${rate[$k]}" "$state" "$failed"
done
python3 -c "import sys; r1, r2 = map(float, sys.argv[1:]); print(f'scaling efficiency K=2: {r2 / r1 / 2:.2f} ({r2 / r1:.2f}x the rate of one worker)')" "${rate[1]}" "${rate[2]}"

# Elastic run: one worker, a second joins at a third of the episodes, the first is stopped with
# SIGTERM at two thirds. Every episode must be done exactly once.
read -r http grpc < <(start_server elastic)
id=$(register "$http")
first=$(start_worker "$grpc" elastic-w1 --slots 1); pids+=("$first")
second=""
elastic_hook() { # DONE TOTAL
  if [ -z "$second" ] && (( $1 * 3 >= $2 )); then
    second=$(start_worker "$grpc" elastic-w2 --slots 1); pids+=("$second")
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
