#!/usr/bin/env bash
# Deadline-hour load benchmark of the server (docs/measured/load-benchmark.md): `kitchen-r bench load`
# on a release build.
#
# What it measures, all on loopback and bounded in time:
#   1. It starts the release `kitchen-r serve` itself on 127.0.0.1 with free ports, a fresh SQLite
#      database in a temporary directory, no simulation slots, and every per-team limit lifted
#      (quota.dev_per_day, quota.test_per_day, quota.per_minute, quota.concurrent_runs = 0), so the
#      benchmark's own uploads are measured rather than refused. The server's other settings (its
#      request timeout, any load shedding) are the defaults.
#   2. Seeding: T teams (POST /api/v1/teams), then N plan files uploaded over HTTP round-robin over
#      the teams, 8 at a time. Each file is the first 163 instructions of the server's dev split
#      with their true plans, a random share of them with one step dropped, so EMs and ranks vary.
#   3. Measurement for D seconds: R readers in a closed loop on
#      GET /api/v1/leaderboard?track=planning&split=dev, beside an open-loop uploader at U files/s
#      spread over the teams. An upload's latency counts from when it was due, not from when it
#      could be sent (no coordinated omission). Printed: p50/p90/p99/max and throughput of both
#      sides; every non-2xx answer and transport error, by kind.
#   4. Afterwards: every acknowledged upload is looked up (present, with the EM it was answered
#      with), the leaderboard's best EM per team is compared with the acknowledged ones, and the
#      server is stopped with SIGTERM; the database (after folding in its WAL) divided by the plan
#      submissions stored gives KiB per submission.
#
# Defaults are the issue's target: 20,000 submissions from 100 teams, 32 readers, 20 uploads/s for
# 60 s. Arguments go to `kitchen-r bench load`, e.g.
#   benchmarks/load-bench.sh --submissions 2000 --teams 20 --readers 8 --seconds 10
#   benchmarks/load-bench.sh --json > load.json
#   benchmarks/load-bench.sh --server http://127.0.0.1:8080   # a running server (KITCHEN_R_ADMIN_TOKEN)
# See `kitchen-r bench load --help` for every flag. Honours CARGO_TARGET_DIR; KITCHEN_R_BIN=path
# uses an already built binary instead of building the release one.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN="${KITCHEN_R_BIN:-}"
if [ -z "$BIN" ]; then
  cargo build --release -p kitchen-r >&2
  BIN="${CARGO_TARGET_DIR:-target}/release/kitchen-r"
fi
exec "$BIN" bench load "$@"
