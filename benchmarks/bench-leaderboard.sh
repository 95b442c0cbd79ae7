#!/usr/bin/env bash
# Load benchmark of GET /api/v1/leaderboard with 10,000 stored submissions (target in docs/measured/performance.md:
# >= 5,000 req/s, p99 <= 20 ms on a 2-core machine). Not a test: it prints wrk's figures.
#
# How the data is seeded: the release server is started once on a fresh database in a temporary
# directory so it applies the migrations, then stopped; 100 teams and 10,000 test-split plan
# submissions, each with one scoring run (random EM), are inserted directly with SQL in one
# transaction (python3's sqlite3 module, about a second). Per-instruction rows are not seeded:
# the leaderboard does not read them. The server is then started again and loaded with wrk on
# loopback for a bounded time.
#
# Usage: benchmarks/bench-leaderboard.sh [DURATION_S=10] [CONNECTIONS=32]
# Needs: wrk (apt-get install -y wrk), python3, curl. Honours CARGO_TARGET_DIR; KITCHEN_R_BIN=path
# uses an already built binary instead of building the release one.
set -euo pipefail
cd "$(dirname "$0")/.."
DURATION="${1:-10}"
CONNECTIONS="${2:-32}"
SUBMISSIONS=10000
TEAMS=100

command -v wrk >/dev/null || { echo "wrk is not installed (apt-get install -y wrk)" >&2; exit 1; }
BIN="${KITCHEN_R_BIN:-}"
if [ -z "$BIN" ]; then
  cargo build --release --locked -p kitchen-r >&2
  BIN="${CARGO_TARGET_DIR:-target}/release/kitchen-r"
fi
TMP="$(mktemp -d)"
SERVER_PID=""
cleanup() {
  if [ -n "$SERVER_PID" ]; then kill "$SERVER_PID" 2>/dev/null || true; wait "$SERVER_PID" 2>/dev/null || true; fi
  rm -rf "$TMP"
}
trap cleanup EXIT

# Start the server on free ports; sets SERVER_PID and HTTP (host:port) from the readiness line.
start() {
  KITCHEN_R_ADMIN_TOKEN=bench-admin-token-0123456789 RUST_LOG=warn \
    "$BIN" serve --db "sqlite://$TMP/kitchen-r.db" --http 127.0.0.1:0 --grpc 127.0.0.1:0 >"$TMP/out" 2>"$TMP/err" &
  SERVER_PID=$!
  for _ in $(seq 1 300); do
    if grep -q '^listening ' "$TMP/out"; then
      HTTP="$(sed -n 's/^listening http=\([^ ]*\) .*/\1/p' "$TMP/out")"
      return 0
    fi
    sleep 0.1
  done
  echo "server did not start:" >&2; cat "$TMP/err" >&2; exit 1
}
stop() { kill "$SERVER_PID"; wait "$SERVER_PID" 2>/dev/null || true; SERVER_PID=""; }

start
stop
python3 - "$TMP/kitchen-r.db" "$TEAMS" "$SUBMISSIONS" <<'PY'
import json, random, sqlite3, sys, time
db, teams, subs = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
rng = random.Random(7)
con = sqlite3.connect(db)
now = int(time.time() * 1000) - subs * 1000
with con:
    con.executemany("INSERT INTO teams (name, token_hash, created_at) VALUES (?, ?, ?)",
                    [(f"team-{t:03}", f"{t:064x}", now) for t in range(teams)])
    ids = [r[0] for r in con.execute("SELECT id FROM teams")]
    body = '{"id": "test-0000", "plan": ["move to the red zone"]}\n'
    for i in range(subs):
        cur = con.execute("INSERT INTO submissions (team_id, split, kind, body, created_at) VALUES (?, 'test', 'plans', ?, ?)",
                          (ids[i % teams], body, now + i * 1000))
        em = round(rng.random(), 6)
        con.execute("INSERT INTO scoring_runs (submission_id, scorer_version, created_at, em) VALUES (?, 'seed', ?, ?)",
                    (cur.lastrowid, now + i * 1000, em))
print(f"seeded {teams} teams and {subs} submissions", file=sys.stderr)
PY
start
URL="http://$HTTP/api/v1/leaderboard?track=planning&split=test"
curl -fsS "$URL" | python3 -c 'import json,sys; print("leaderboard rows:", len(json.load(sys.stdin)["rows"]), file=sys.stderr)'
echo "wrk -t2 -c$CONNECTIONS -d${DURATION}s --latency $URL"
wrk -t2 -c"$CONNECTIONS" -d"${DURATION}s" --latency "$URL"
