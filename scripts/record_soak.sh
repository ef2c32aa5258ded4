#!/usr/bin/env bash
# A long live run recorded both ways at once, to check that recording is lossless at 1 kHz:
# the board (`vic-board --record`) and an external `vic record`, a planner running trials
# throughout and a torque pulse every 10 s. At the end: the board's tick messages against the ticks
# it ran, its gap markers, the external recorder's own count of missed states, the file sizes, and
# (when PYTHON has the `mcap` package) every message of both files decoded against its schema.
# Usage: scripts/record_soak.sh [SECONDS] [OUT_DIR]    (default 600 s, a temporary directory)
set -euo pipefail
cd "$(dirname "$0")/.."
SECS=${1:-600}
T=${CARGO_TARGET_DIR:-target}/release
O=${2:-$(mktemp -d)}
mkdir -p "$O"
PY=${PYTHON:-python3}
CFG=config/two_link_divergent.toml; SET=noise.sigma=0.02
ns="rs$$"
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; }
trap cleanup EXIT
"$T/vic" plan --config $CFG --method sooc --set $SET --out "$O/plan.json" >/dev/null
"$T/vic-board" --config $CFG --set $SET --namespace "$ns" --duration-s "$SECS" --json \
  --record "$O/board.mcap" --record-force >"$O/board.json" 2>"$O/board.err" &
bp=$!; pids+=("$bp"); sleep 0.3
"$T/vic" record --namespace "$ns" --out "$O/ext.mcap" --force --plan "$O/plan.json" --json >"$O/ext.json" 2>"$O/ext.err" &
rp=$!; pids+=("$rp")
"$T/vic-planner" --config $CFG --set $SET --namespace "$ns" --plan "$O/plan.json" \
  --strategy stiffness --latency-ms 200 --trials 1000000 --json >/dev/null 2>&1 &
pids+=("$!")
pulses=0; refused=0
start=$(date +%s)
while kill -0 "$bp" 2>/dev/null; do
  sleep 10
  kill -0 "$bp" 2>/dev/null || break
  if "$T/vic" inject pulse --namespace "$ns" --torque 0.25,-0.125 --duration-ms 20 >/dev/null 2>&1; then
    pulses=$((pulses + 1)); else refused=$((refused + 1)); fi
done
wait "$bp" || true
sleep 0.2; kill -TERM "$rp"; wait "$rp" || true
echo "ran $(( $(date +%s) - start )) s; pulses acknowledged $pulses, not acknowledged $refused"
"$PY" - "$O" <<'PYEOF'
import json, sys, os
o = sys.argv[1]
b = json.load(open(f"{o}/board.json")); e = json.load(open(f"{o}/ext.json"))
print(f"board: ticks {b['ticks']} recorded {b.get('recorded')} dropped {b.get('dropped')} "
      f"late {b.get('late_ticks')} jitter p99 {b['jitter_us']['p99']:.1f} us")
print("vic record:", json.dumps(e))
for f in ("board.mcap", "ext.mcap"):
    print(f"{f}: {os.path.getsize(f'{o}/{f}')} bytes")
try:
    sys.path.insert(0, "python/tools")
    import check_recording
    for f in ("board.mcap", "ext.mcap"):
        c = check_recording.check(f"{o}/{f}")
        print(f"{f} decoded: {json.dumps(c['counts'])}")
        if f == "board.mcap":
            ok = c["counts"].get("/board/tick", 0) == b["ticks"] and "/board/gap" not in c["counts"]
            print(f"board file lossless (tick messages = ticks run, no gap marker): {ok}")
except ImportError as err:
    print(f"not decoded ({err}); set PYTHON to an interpreter with the mcap package")
PYEOF
