#!/usr/bin/env bash
# Network tax of the control track: the oracle evaluated in-process (`eval --policy
# builtin:oracle`) against the same oracle served over gRPC on loopback (`policy oracle
# --listen` + `eval --policy http://...`), one episode at a time, same instructions and seeds.
# Both render two 128x128 RGB-D cameras for every policy query; the gRPC path also encodes them
# and sends them over the socket. Prints episodes/min for each and their ratio.
#
#   KITCHEN_R_BIN=target/release/kitchen-r bash benchmarks/bench-network-tax.sh [EPISODES]
set -euo pipefail
bin=${KITCHEN_R_BIN:-target/release/kitchen-r}
n=${1:-10}
work=$(mktemp -d)
trap 'kill "${pid:-}" 2>/dev/null || true; rm -rf "$work"' EXIT

# The same settings for both paths; teleport-on-failure off so the gRPC path does not run the
# expert pre-pass the in-process oracle never needs.
cat > "$work/eval.toml" <<TOML
task_time_limit = 120.0
execute = 8
seed = 0
teleport_on_failure = false
TOML

"$bin" policy oracle --listen 127.0.0.1:0 > "$work/policy.out" 2>/dev/null &
pid=$!
for _ in $(seq 100); do
  grep -q '^listening grpc=' "$work/policy.out" 2>/dev/null && break
  sleep 0.1
done
addr=$(sed -n 's/^listening grpc=//p' "$work/policy.out")
[ -n "$addr" ] || { echo "the oracle policy server did not start" >&2; exit 1; }

field() { python3 -c "import json,sys; print(json.load(open(sys.argv[1]))[sys.argv[2]])" "$1" "$2"; }
"$bin" eval --policy builtin:oracle --episodes "$n" --jobs 1 --json --config "$work/eval.toml" > "$work/local.json"
"$bin" eval --policy "http://$addr" --privileged --episodes "$n" --jobs 1 --json --config "$work/eval.toml" > "$work/grpc.json"
local_s=$(field "$work/local.json" total_wall_s)
grpc_s=$(field "$work/grpc.json" total_wall_s)
python3 - "$n" "$local_s" "$grpc_s" <<'PY'
import sys
n, local, grpc = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
print(f"in-process oracle: {n / local * 60:.1f} episodes/min ({local / n:.3f} s/episode)")
print(f"oracle over gRPC:  {n / grpc * 60:.1f} episodes/min ({grpc / n:.3f} s/episode)")
print(f"network tax: gRPC takes {grpc / local:.3f}x the in-process wall time")
PY
