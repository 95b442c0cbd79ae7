#!/usr/bin/env bash
# The planning baseline's EM through a real server, as docs/measured/baseline-planning.md reports it:
#   bash starter-kit/baselines/planner/eval/measure.sh                      # dev + the public test sample
#   bash starter-kit/baselines/planner/eval/measure.sh --test-set DIR       # dev + a generated (private-phrasing) test set
#   bash starter-kit/baselines/planner/eval/measure.sh -- --llm URL --model M   # planner options after --
# Starts `kitchen-r serve` on free loopback ports with a fresh database in a temporary
# directory (no simulation slots), creates a team, runs the planner on dev and test, submits
# both with `kitchen-r submit plans`, prints the scores and stops the server.
# KITCHEN_R_BIN names the binary (default: kitchen-r on PATH, else target/release/kitchen-r).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
root="$(cd "$here/../../../.." && pwd)"
bin="${KITCHEN_R_BIN:-$(command -v kitchen-r || echo "$root/target/release/kitchen-r")}"
test_set=()
while [ $# -gt 0 ]; do
  case "$1" in
    --test-set) test_set=(--test-set "$(cd "$2" && pwd)"); shift 2 ;;
    --) shift; break ;;
    *) echo "usage: $0 [--test-set DIR] [-- planner options]" >&2; exit 2 ;;
  esac
done
tmp="$(mktemp -d)"
server_pid=""
cleanup() { [ -n "$server_pid" ] && kill "$server_pid" 2>/dev/null; wait 2>/dev/null; rm -rf "$tmp"; }
trap cleanup EXIT
export KITCHEN_R_ADMIN_TOKEN="measure-$(od -An -N8 -tx8 /dev/urandom | tr -d ' ')"
export KITCHEN_R_WORKER_TOKEN="worker-$(od -An -N8 -tx8 /dev/urandom | tr -d ' ')"
# Run from the temporary directory so that no configs/server.toml of the working directory
# applies: the defaults, this checkout's assets.
(cd "$tmp" && KITCHEN_R_ASSETS="$root/assets" exec "$bin" serve --http 127.0.0.1:0 --grpc 127.0.0.1:0 \
  --db "sqlite://$tmp/db.sqlite" --workers 0 "${test_set[@]}") >"$tmp/server.log" 2>&1 &
server_pid=$!
for _ in $(seq 1 300); do
  grep -q '^listening' "$tmp/server.log" 2>/dev/null && break
  kill -0 "$server_pid" 2>/dev/null || { cat "$tmp/server.log" >&2; exit 1; }
  sleep 0.1
done
addr="$(sed -n 's/^listening http=\([^ ]*\).*/\1/p' "$tmp/server.log")"
[ -n "$addr" ] || { echo "the server did not start:" >&2; cat "$tmp/server.log" >&2; exit 1; }
export KITCHEN_R_SERVER="http://$addr"
grep '^test set' "$tmp/server.log" || true
token="$("$bin" team create "Baseline planner" | sed -n 's/^token: //p')"
export KITCHEN_R_TOKEN="$token"
for split in dev test; do
  python3 "$here/../run.py" --split "$split" --out "$tmp/$split.jsonl" "$@"
  "$bin" submit plans "$tmp/$split.jsonl" --split "$split"
done
