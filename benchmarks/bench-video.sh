#!/usr/bin/env bash
# What the episode video costs (docs/measured/video.md): the same episodes evaluated through the
# workers' runner against a policy served on loopback, once without and once with `--record DIR`,
# one episode at a time (--jobs 1, one core). Prints, per episode, the wall time without and with
# the video, the time spent composing and encoding frames (from `eval --record`), frames and
# bytes; the rest of the difference is the extra camera renders (every control step instead of
# every policy query).
#
#   KITCHEN_R_BIN=target/release/kitchen-r [POLICY=oracle|still|sweep] bash benchmarks/bench-video.sh [EPISODES]
#
# POLICY=oracle (default): `kitchen-r policy oracle`, whose tasks end as soon as they succeed.
# POLICY=still: the starter kit's policy (starter-kit/policy_server.py; needs
# starter-kit/requirements.txt), which stands still, so every task runs to its time limit: the
# most frames and encoding time an episode makes.
# POLICY=sweep: benchmarks/sweep_policy.py, which also fails every task but keeps both cameras
# moving: the most bytes an episode makes, what storage budgets must plan for.
# EPISODES (default 3): the first dev instructions. Everything listens on 127.0.0.1 and is
# stopped on exit.
set -euo pipefail
bin=${KITCHEN_R_BIN:-target/release/kitchen-r}
n=${1:-3}
work=$(mktemp -d)
cleanup() {
  for p in $(cat "$work/pids" 2>/dev/null); do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT

source "$(dirname "$0")/bench-lib.sh"

case ${POLICY:-oracle} in
  oracle)
    "$bin" policy oracle --listen 127.0.0.1:0 --max-concurrency 4 > "$work/policy.out" 2>/dev/null &
    extra=(--privileged) ;;
  still)
    python3 "$(dirname "$0")/../starter-kit/policy_server.py" --listen 127.0.0.1:0 \
      > "$work/policy.out" 2> "$work/policy.err" &
    extra=() ;;
  sweep)
    python3 "$(dirname "$0")/sweep_policy.py" --listen 127.0.0.1:0 > "$work/policy.out" 2> "$work/policy.err" &
    extra=() ;;
  *) echo "POLICY must be oracle, still or sweep" >&2; exit 2 ;;
esac
echo $! >> "$work/pids"
policy=$(wait_line "$work/policy.out" 'listening grpc=')

run() { # run NAME [eval flags...]: the report JSON in $work/NAME.json
  local name=$1
  shift
  "$bin" eval --policy "http://$policy" "${extra[@]}" --mode online --episodes "$n" --jobs 1 --json "$@" \
    > "$work/$name.json" 2> "$work/$name.err"
}
run plain
run video --record "$work/videos"

python3 - "$work/plain.json" "$work/video.json" <<'PY'
import json, sys
plain, video = (json.load(open(p)) for p in sys.argv[1:3])
rows = list(zip(plain["episodes"], video["episodes"]))
print(f"{'episode':<10} {'wall s':>7} {'+video s':>8} {'encode s':>8} {'frames':>6} {'bytes':>8} {'tasks ok':>8}")
tot = dict(wall=0.0, extra=0.0, enc=0.0, frames=0, bytes=0)
for p, v in rows:
    vid = v.get("video") or {}
    extra = v["wall_s"] - p["wall_s"]
    tasks = v.get("tasks") or []
    ok = f"{sum(1 for t in tasks if t.get('success'))}/{len(tasks)}"
    print(f"{p['episode_key']:<10} {p['wall_s']:7.2f} {extra:8.2f} {vid.get('encode_s', 0):8.2f} "
          f"{vid.get('frames', 0):6d} {vid.get('bytes', 0):8d} {ok:>8}")
    tot["wall"] += p["wall_s"]; tot["extra"] += extra; tot["enc"] += vid.get("encode_s", 0)
    tot["frames"] += vid.get("frames", 0); tot["bytes"] += vid.get("bytes", 0)
k = max(len(rows), 1)
print(f"mean per episode: wall {tot['wall']/k:.2f} s without video, +{tot['extra']/k:.2f} s with it "
      f"({tot['enc']/k:.2f} s composing and encoding, the rest rendering), {tot['frames']/k:.0f} frames, "
      f"{tot['bytes']/k/1024:.0f} KiB ({8*tot['bytes']/max(tot['frames'],1)/1024*10:.0f} kbit/s); "
      f"{1000*tot['enc']/max(tot['frames'],1):.1f} ms encoding per frame")
PY
