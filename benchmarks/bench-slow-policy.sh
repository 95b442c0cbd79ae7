#!/usr/bin/env bash
# A waiting episode does not hold a core (docs/control-track-worker.md): one standalone worker with 2 slots
# evaluates the oracle reference run against a policy that answers every Act after DELAY_MS
# (default 50, like a learned policy's inference), first holding one episode per slot (how
# workers ran before: an episode kept its slot while it waited), then with the default
# `max_episodes` (8 per slot; an episode holds a core only while it simulates). Prints episodes
# per minute of each and the ratio, and checks both runs scored exactly alike.
#
#   KITCHEN_R_BIN=target/release/kitchen-r bash benchmarks/bench-slow-policy.sh [INSTRUCTIONS] [DELAY_MS]
#
# INSTRUCTIONS (default 8) dev instructions per run; with offline MSE on (the default) each gives
# an online and an offline episode. Everything listens on 127.0.0.1 and is stopped on exit.
set -euo pipefail
bin=${KITCHEN_R_BIN:-target/release/kitchen-r}
n=${1:-8}
delay=${2:-50}
work=$(mktemp -d)
cleanup() {
  for p in $(cat "$work/pids" 2>/dev/null); do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT

source "$(dirname "$0")/bench-lib.sh"

"$bin" policy oracle --listen 127.0.0.1:0 --max-concurrency 64 --delay-ms "$delay" \
  > "$work/policy.out" 2>/dev/null &
echo $! >> "$work/pids"
policy=$(wait_line "$work/policy.out" 'listening grpc=')

declare -A rate score
for mode in one-per-slot default; do
  flags=(--slots 2)
  [ "$mode" = one-per-slot ] && flags+=(--max-episodes 2)
  read -r done total state failed secs rate[$mode] sr mse < <(measure "$mode" 1 "${flags[@]}")
  score[$mode]="SR $sr MSE $mse"
  printf '%s (%s): %s/%s episodes in %.1f s, %.1f episodes/min (run %s, %s failed; %s)\n' \
    "$mode" "${flags[*]}" "$done" "$total" "$secs" "${rate[$mode]}" "$state" "$failed" "${score[$mode]}"
done
python3 -c "import sys; a, b = map(float, sys.argv[1:]); print(f'policy answering after $delay ms, 2 slots: {b / a:.2f}x the episodes per minute')" \
  "${rate[one-per-slot]}" "${rate[default]}"
# Episodes in flight must not change a single number: the simulation is deterministic.
if [ "${score[one-per-slot]}" != "${score[default]}" ]; then
  echo "SCORES DIFFER: ${score[one-per-slot]} vs ${score[default]}" >&2
  exit 1
fi
echo "same scores both ways: ${score[default]}"
