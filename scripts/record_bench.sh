#!/usr/bin/env bash
# The board's tick work and wake-up jitter with MCAP recording off and on, interleaved in one run
# (ROUNDS rounds of SECONDS each, a planner running trials throughout), then the sizes of a 60 s
# recording made by the board and by `vic record` at once. Usage: scripts/record_bench.sh [ROUNDS] [SECONDS]
set -euo pipefail
cd "$(dirname "$0")/.."
ROUNDS=${1:-3}; SECS=${2:-15}
T=${CARGO_TARGET_DIR:-target}/release
O=$(mktemp -d)
trap 'rm -rf "$O"' EXIT
CFG=config/two_link_divergent.toml; SET=noise.sigma=0.02
"$T/vic" plan --config $CFG --method sooc --set $SET --out "$O/plan.json" >/dev/null
planner() { "$T/vic-planner" --config $CFG --set $SET --namespace "$1" --plan "$O/plan.json" \
    --strategy stiffness --latency-ms 200 --trials 100000 --json >/dev/null 2>&1 & echo $!; }
run() { # NAME SECONDS [vic-board args]
  local name=$1 secs=$2; shift 2
  local ns="rb$$${name}"
  "$T/vic-board" --config $CFG --set $SET --namespace "$ns" --duration-s "$secs" --json "$@" >"$O/$name.json" 2>/dev/null &
  local bp=$!; sleep 0.3; local pp; pp=$(planner "$ns")
  wait $bp; kill $pp 2>/dev/null || true; wait $pp 2>/dev/null || true
  python3 -c "import json; d=json.load(open('$O/$name.json')); j=d['jitter_us']; w=d['work_us']; print(f\"$name: jitter p50 {j['p50']:.1f} p99 {j['p99']:.1f} p99.9 {j['p999']:.1f} µs; work p50 {w['p50']:.1f} p99 {w['p99']:.1f} µs; recorded {d.get('recorded')} dropped {d.get('dropped')}\")"
}
for i in $(seq "$ROUNDS"); do
  run "off$i" "$SECS"
  run "mcap$i" "$SECS" --record "$O/m$i.mcap"
done
ns="rb$$long"
"$T/vic-board" --config $CFG --set $SET --namespace $ns --duration-s 60 --json --record "$O/board60.mcap" >/dev/null 2>&1 &
bp=$!; sleep 0.3
"$T/vic" record --namespace $ns --out "$O/ext60.mcap" --json >"$O/ext60.json" 2>&1 &
rp=$!; pp=$(planner $ns)
wait $bp; sleep 0.2; kill -TERM $rp; wait $rp || true; kill $pp 2>/dev/null || true; wait $pp 2>/dev/null || true
"$T/vic" convert "$O/board60.mcap" --csv "$O/board60.csv" >/dev/null
ls -l "$O/board60.mcap" "$O/ext60.mcap" "$O/board60.csv" | awk '{print $9": "$5" bytes"}' | sed "s|$O/||"
cat "$O/ext60.json"
