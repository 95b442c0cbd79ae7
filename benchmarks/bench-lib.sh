# Shared by the control-track benchmark scripts (bench-scale-out.sh, bench-slow-policy.sh):
# starting a loopback server without slots of its own, standalone workers and a reference run,
# and following the run to its end. Source it after setting `bin`, `work` (a scratch directory),
# `n` (instructions per run) and `policy` (the served oracle's address); every process started
# here is listed in `$work/pids` for the caller's clean-up.

export KITCHEN_R_ADMIN_TOKEN=bench-admin-token-0123456789
export KITCHEN_R_WORKER_TOKEN=bench-worker-token-0123456789

wait_line() { # FILE PREFIX: print what follows PREFIX on its first line, waiting up to 60 s
  for _ in $(seq 600); do
    if grep -q "^$2" "$1" 2>/dev/null; then sed -n "s/^$2//p" "$1" | head -1; return; fi
    sleep 0.1
  done
  echo "timed out waiting for '$2' in $1" >&2; cat "$1" >&2; exit 1
}

start_server() { # NAME: a fresh server, prints "HTTP GRPC"
  "$bin" serve --workers 0 --http 127.0.0.1:0 --grpc 127.0.0.1:0 \
    --db "sqlite://$work/$1.db" > "$work/$1.out" 2> "$work/$1.err" &
  echo $! >> "$work/pids"
  local line
  line=$(wait_line "$work/$1.out" 'listening ')
  local http grpc
  http=$(sed -n 's/.*http=\([^ ]*\).*/\1/p' <<< "$line")
  grpc=$(sed -n 's/.*grpc=\([^ ]*\).*/\1/p' <<< "$line")
  echo "$http $grpc"
}

start_worker() { # GRPC NAME [WORKER FLAGS...]: a standalone worker; prints its pid
  local grpc=$1 name=$2
  shift 2
  "$bin" worker --server "http://$grpc" --worker-id "$name" "$@" > "$work/$name.log" 2>&1 &
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

scores() { # HTTP ID: "SR MSE" of the submission's latest run
  python3 - "$1" "$2" <<'PY'
import json, os, sys, urllib.request
req = urllib.request.Request(f"http://{sys.argv[1]}/api/v1/submissions/{sys.argv[2]}",
    headers={"Authorization": "Bearer " + os.environ["KITCHEN_R_ADMIN_TOKEN"]})
s = json.load(urllib.request.urlopen(req, timeout=10))["latest_run"]["scores"]
print(repr(s.get("sr")), repr(s.get("mse")))
PY
}

# Waits until the run finishes (at most 30 min); runs HOOK with the done fraction as it goes.
# Prints "DONE TOTAL STATE FAILED SECONDS".
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

# One measured run: a fresh server, a reference run of N instructions, and K workers started
# with WORKER FLAGS; the clock runs from registration to the run's end. Prints
# "DONE TOTAL STATE FAILED SECONDS EPISODES_PER_MIN SR MSE".
measure() { # NAME K [WORKER FLAGS...]
  local name=$1 k=$2
  shift 2
  local http grpc started_ns id secs rate
  read -r http grpc < <(start_server "$name")
  started_ns=$(date +%s%N)
  id=$(register "$http")
  for w in $(seq "$k"); do start_worker "$grpc" "$name-w$w" "$@" > /dev/null; done
  read -r done total state failed _ < <(follow "$http" "$id" no_hook)
  secs=$(python3 -c "import sys; print((int(sys.argv[2]) - int(sys.argv[1])) / 1e9)" "$started_ns" "$(date +%s%N)")
  rate=$(python3 -c "import sys; print(int(sys.argv[1]) / float(sys.argv[2]) * 60)" "$done" "$secs")
  echo "$done $total $state $failed $secs $rate $(scores "$http" "$id")"
}
