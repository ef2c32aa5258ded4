#!/usr/bin/env bash
# Soak test of the real-time pair (not run in CI): scripts/soak.sh [MINUTES=10]
#
# Builds release, starts vic-board with --record in a namespace of its own and vic-planner running
# trials in a loop, and every second injects a disturbance (a 10 ms pulse) and one hostile message
# in turn (examples/malformed.rs, from a raw sender's node beside the planner): a slice with
# knot_dt 1e15, a slice with seq u64::MAX, a stale message, a wrong protocol version, a flood
# burst of 2000 slices, NaN torque, an unbounded stiffness, a wrong joint count. Samples the
# board's RSS at start and end, then stops everything and prints deadlines missed, messages
# rejected, memory, and ticks recorded vs ticks run, and the hostile messages sent vs counted;
# fails (exit 1) unless every hostile message was counted by the board (rejected by its reason, or
# dropped and counted from the sequence gaps of its session) and the planner's trials kept running.
# Processes and shared-memory files are cleaned up on exit, Ctrl-C included.
#
# Across the bridge (SOAK_BRIDGE=1, issue 16; needs the zenoh feature, built here): the board and a
# board-side `vic bridge` in one namespace, a central-side bridge, the planner and the hostile sender
# in another, sharing nothing but a Zenoh TCP link on loopback. Besides the hostile messages above
# (which now cross the link), every second examples/link_junk.rs puts a malformed message straight
# onto the link (7 bytes, or a slice of another protocol version); the board-side bridge must count
# each and forward none. Messages of another version are refused (and counted) by the bridge
# before they reach the board, so they count as counted there.
#
# Environment: CARGO_TARGET_DIR (default ./target), SOAK_DIR (where the recording and logs go;
# default a new /tmp/vic-soak.* folder, kept), SOAK_BRIDGE (1: across the bridge).
set -euo pipefail

MINUTES=${1:-10}
if ! [[ $MINUTES =~ ^[0-9]+([.][0-9]+)?$ ]]; then
    echo "usage: $0 [MINUTES=10]" >&2
    exit 2
fi
SECONDS_TOTAL=$(awk -v m="$MINUTES" 'BEGIN { printf "%d", m * 60 }')
cd "$(dirname "$0")/.."
ROOT=$PWD
export CARGO_TARGET_DIR=${CARGO_TARGET_DIR:-$ROOT/target}
BIN=$CARGO_TARGET_DIR/release
NS=soak$$
BRIDGE=${SOAK_BRIDGE:-0}
# Where the central process and the hostile sender run: the board's namespace, or across the link.
NS_C=$NS
if [[ $BRIDGE == 1 ]]; then
    NS_C=soakc$$
    PORT=$((20000 + $$ % 20000))
    LINK=soak$$
fi
OUT=${SOAK_DIR:-$(mktemp -d /tmp/vic-soak.XXXXXX)}
mkdir -p "$OUT"
CONFIG=$ROOT/config/two_link_divergent.toml
PLAN=$ROOT/tests/data/realtime/two_link_divergent_sigma002_sooc.json
SIGMA=noise.sigma=0.02

BOARD_PID=""
LOOP_PID=""
TOOL_PID=""
BRIDGE_PIDS=()
JUNK_PID=""

cleanup() {
    local code=$?
    trap - EXIT INT TERM
    # Only the processes this script started, by their ids.
    if [[ -n $LOOP_PID ]]; then
        kill "$LOOP_PID" 2>/dev/null || true
        pkill -TERM -P "$LOOP_PID" 2>/dev/null || true
    fi
    [[ -n $TOOL_PID ]] && kill "$TOOL_PID" 2>/dev/null || true
    [[ -n $JUNK_PID ]] && kill "$JUNK_PID" 2>/dev/null || true
    for p in "${BRIDGE_PIDS[@]}"; do kill "$p" 2>/dev/null || true; done
    [[ -n $BOARD_PID ]] && kill "$BOARD_PID" 2>/dev/null || true
    wait 2>/dev/null || true
    # What transport::remove_namespace removes: the namespace's files in /dev/shm and under
    # iceoryx2's root folder.
    # iceoryx2's root folder (the user's private /tmp/vic-UID), then the node folders that held
    # this namespace's files and are empty now (rmdir leaves any other).
    local root dirs ns left
    root=/tmp/vic-$(id -u)
    for ns in $(printf '%s\n' "$NS" "$NS_C" | sort -u); do
        dirs=$(find "$root/nodes" -mindepth 2 -maxdepth 2 -name "vic_${ns}.*" -printf '%h\n' 2>/dev/null | sort -u)
        find /dev/shm -maxdepth 1 -name "vic_${ns}.*" -delete 2>/dev/null || true
        find "$root" -name "vic_${ns}.*" -delete 2>/dev/null || true
        for d in $dirs; do rmdir "$d" 2>/dev/null || true; done
        left=$(find /dev/shm -maxdepth 1 -name "vic_${ns}.*" | wc -l)
        echo "cleanup: namespace $ns, $left files left in /dev/shm" >&2
    done
    exit "$code"
}
trap cleanup EXIT
trap 'echo "interrupted" >&2; exit 130' INT TERM

echo "building (release)…" >&2
if [[ $BRIDGE == 1 ]]; then
    cargo build --release --features zenoh --bins --example malformed --example link_junk 2>&1 | tail -n 2 >&2
else
    cargo build --release --bins --example malformed 2>&1 | tail -n 2 >&2
fi

rss_kb() { awk '/^VmRSS/ { print $2 }' "/proc/$1/status"; }

"$BIN/vic-board" --config "$CONFIG" --set "$SIGMA" --namespace "$NS" --json \
    --record "$OUT/soak.csv" >"$OUT/board.json" 2>"$OUT/board.err" &
BOARD_PID=$!
sleep 1
kill -0 "$BOARD_PID" || { cat "$OUT/board.err" >&2; exit 1; }
if [[ $BRIDGE == 1 ]]; then
    "$BIN/vic" bridge --side board --namespace "$NS" --link-name "$LINK" \
        --listen "tcp/127.0.0.1:$PORT" --json >"$OUT/bridge_board.json" 2>"$OUT/bridge_board.err" &
    BRIDGE_PIDS+=($!)
    "$BIN/vic" bridge --side central --namespace "$NS_C" --link-name "$LINK" \
        --connect "tcp/127.0.0.1:$PORT" --json >"$OUT/bridge_central.json" 2>"$OUT/bridge_central.err" &
    BRIDGE_PIDS+=($!)
    sleep 2
    for p in "${BRIDGE_PIDS[@]}"; do
        kill -0 "$p" || { cat "$OUT"/bridge_*.err >&2; exit 1; }
    done
fi

(
    trap 'exit 0' TERM
    i=0
    while true; do
        i=$((i + 1))
        "$BIN/vic-planner" --config "$CONFIG" --set "$SIGMA" --namespace "$NS_C" --json \
            --plan "$PLAN" --strategy stiffness --latency-ms 200 --seed "$i" --trials 5 \
            >>"$OUT/planner.jsonl" 2>>"$OUT/planner.err" || echo "planner run $i failed" >>"$OUT/planner.err"
    done
) &
LOOP_PID=$!

"$BIN/examples/malformed" "$NS_C" "$SECONDS_TOTAL" 1000 >"$OUT/malformed.log" 2>&1 &
TOOL_PID=$!
if [[ $BRIDGE == 1 ]]; then
    "$BIN/examples/link_junk" "$LINK" "tcp/127.0.0.1:$PORT" "$((SECONDS_TOTAL - 3))" 1000 \
        >"$OUT/link_junk.log" 2>&1 &
    JUNK_PID=$!
fi

sleep 2
RSS_START=$(rss_kb "$BOARD_PID")
echo "soak: $MINUTES min in namespace $NS, board pid $BOARD_PID, files in $OUT" >&2
END=$(($(date +%s) + SECONDS_TOTAL - 2))
while (($(date +%s) < END)); do
    kill -0 "$BOARD_PID" 2>/dev/null || { echo "the board died" >&2; cat "$OUT/board.err" >&2; exit 1; }
    for p in "${BRIDGE_PIDS[@]}"; do
        kill -0 "$p" 2>/dev/null || { echo "a bridge died" >&2; cat "$OUT"/bridge_*.err >&2; exit 1; }
    done
    sleep 5
done
RSS_END=$(rss_kb "$BOARD_PID")

wait "$TOOL_PID" || true
TOOL_PID=""
if [[ -n $JUNK_PID ]]; then
    wait "$JUNK_PID" || true
    JUNK_PID=""
fi
kill "$LOOP_PID" 2>/dev/null || true
pkill -TERM -P "$LOOP_PID" 2>/dev/null || true
wait "$LOOP_PID" 2>/dev/null || true
LOOP_PID=""
for p in "${BRIDGE_PIDS[@]}"; do
    kill -TERM "$p" 2>/dev/null || true
    wait "$p" || true
done
BRIDGE_PIDS=()
kill -TERM "$BOARD_PID"
wait "$BOARD_PID"
BOARD_PID=""

S=$OUT/board.json
ROWS=$(grep -vc '^#' "$OUT/soak.csv" || true)
ROWS=$((ROWS - 1))
GAPS=$(grep -c '^# gap' "$OUT/soak.csv" || true)
TRIALS=$(jq -s 'map(.trials) | add // 0' "$OUT/planner.jsonl" 2>/dev/null || echo "?")
HOLDS=$(jq -s 'map(.safe_hold_trials) | add // 0' "$OUT/planner.jsonl" 2>/dev/null || echo "?")
echo
echo "== soak: $MINUTES min =="
jq -r '"ticks run          \(.ticks)",
       "deadlines missed   \(.late_ticks) late ticks, \(.missed_periods) periods missed, \(.lost_periods) periods lost",
       "jitter [µs]        p50 \(.jitter_us.p50)  p99 \(.jitter_us.p99)  p99.9 \(.jitter_us.p999)  max \(.jitter_us.max)",
       "work [µs]          p50 \(.work_us.p50)  p99 \(.work_us.p99)  max \(.work_us.max)",
       "messages rejected  \(.rejected_messages) (total; by reason: \(.rejected_by_reason // "not reported by this board"))",
       "safe-hold ticks    \(.safe_hold_ticks)",
       "ticks recorded     \(.recorded) of \(.ticks) run, \(.dropped) dropped"' "$S"
echo "file rows          $ROWS rows, $GAPS gap markers ($OUT/soak.csv)"
echo "injected           $(cat "$OUT/malformed.log")"
echo "planner            $TRIALS trials, $HOLDS with safe hold"
echo "board RSS [kB]     start $RSS_START, end $RSS_END"

# Every hostile message counted: rejected by its reason, or (the part of a burst of 2000 that
# overruns the board's 8-slot receive buffer) dropped, counted from the burst session's sequence
# gaps even with the planner's slices in between (docs/PROTOCOL.md, sequence rules). The board's
# counts include the planner's own rejected or dropped slices (e.g. overflow in a burst's tick):
# what the board counted beyond the hostile messages is printed by reason.
M=$OUT/malformed.log
k() { jq -r --arg k "$1" '.hostile_by_kind[$k] // 0' "$M" 2>/dev/null || echo 0; }
r() { jq -r --arg k "$1" '.rejected_by_reason[$k] // 0' "$S"; }
HOSTILE=$(jq -r '.hostile // 0' "$M" 2>/dev/null || echo 0)
BURSTS=$(($(k flood-burst) / 2000))
SINGLE=$((HOSTILE - $(k flood-burst)))
REJECTED=$(jq -r '.rejected_messages' "$S")
DROPPED=$(jq -r '.dropped_messages' "$S")
# Across the bridge: what the board-side bridge refused (size, version) and what was put on the
# link past both namespaces. The bridge's version refusals are the hostile sender's bad-version
# messages (which crossed the link raw) plus the link's junk of another version.
BS=0 BV=0 JS=0 JV=0
if [[ $BRIDGE == 1 ]]; then
    BS=$(jq -r '.stats.malformed_size' "$OUT/bridge_board.json")
    BV=$(jq -r '.stats.malformed_version' "$OUT/bridge_board.json")
    JS=$(jq -r '.malformed_size // 0' "$OUT/link_junk.log" 2>/dev/null || echo 0)
    JV=$(jq -r '.malformed_version // 0' "$OUT/link_junk.log" 2>/dev/null || echo 0)
    echo "bridge (board side) $(jq -c '.stats' "$OUT/bridge_board.json")"
    echo "bridge (central)    $(jq -c '.stats' "$OUT/bridge_central.json")"
    echo "link junk          $JS of the wrong size, $JV of another version put on the link; the bridge refused $BS and $BV"
fi
# Bad-version messages refused by the bridge before the board saw them.
BRIDGE_VERSION=$((BV - JV))
COUNTED=$((REJECTED + DROPPED + BRIDGE_VERSION))
# Per reason, what the hostile messages explain (wrong trial, overflow and drops share the burst
# and the slices for trial 0xFFFF); the rest is the planner's.
WTO=$(($(k seq-u64-max) + $(k nan-torque) + $(k stiffness-unbounded) + $(k flood-burst)))
BEYOND=$(jq -r --argjson shape "$(k knot-dt-1e15)" --argjson version "$(($(k bad-version) - BRIDGE_VERSION))" \
    --argjson stale "$(k stale)" --argjson joints "$(k wrong-joints)" --argjson wto "$WTO" '
    (.rejected_by_reason // {}) as $r | def g($k): ($r[$k] // 0);
    ($r | to_entries | map(select(.key as $k
        | ["shape", "version", "stale", "out-of-order", "joints", "wrong-trial", "overflow"] | index($k) | not))
        | map("\(.key) \(.value)"))
      + ["shape \(g("shape") - $shape)", "version \(g("version") - $version)",
         "stale + out-of-order \(g("stale") + g("out-of-order") - $stale)", "joints \(g("joints") - $joints)",
         "wrong-trial + overflow + dropped \(g("wrong-trial") + g("overflow") + .dropped_messages - $wto)"]
    | map(select(test(" 0$") | not)) | join(", ")' "$S")
echo "hostile counted    $REJECTED rejected + $DROPPED dropped + $BRIDGE_VERSION refused by the bridge = $COUNTED for $HOSTILE hostile messages ($SINGLE single, $BURSTS bursts of 2000); beyond the hostile ones: $((COUNTED - HOSTILE)) (${BEYOND:-none}; the planner's own, e.g. slices sent into a latched fault; $TRIALS trials)"
FAIL=0
check() { # name, counted, at least
    if (($2 < $3)); then
        echo "FAIL: $1: counted $2, at least $3 expected" >&2
        FAIL=1
    fi
}
((HOSTILE > 0)) || { echo "FAIL: no hostile message sent" >&2; FAIL=1; }
check "knot_dt 1e15 (shape)" "$(r shape)" "$(k knot-dt-1e15)"
check "bad version" "$(($(r version) + BRIDGE_VERSION))" "$(k bad-version)"
# A stale disturbance that arrives after a newer disturbance of another session was accepted in
# the same trial fails the order check first (docs/PROTOCOL.md: another session must not be
# older than the last accepted) and is counted as out-of-order; nothing else sends out of order.
check "stale (as stale, or out-of-order behind a newer disturbance)" \
    "$(($(r stale) + $(r out-of-order)))" "$(k stale)"
check "wrong joints" "$(r joints)" "$(k wrong-joints)"
check "seq u64::MAX, NaN, unbounded stiffness, bursts (wrong trial, overflow, dropped)" \
    $(($(r wrong-trial) + $(r overflow) + DROPPED)) "$WTO"
check "all hostile messages (rejected + dropped)" "$COUNTED" "$HOSTILE"
if [[ $BRIDGE == 1 ]]; then
    ((JS + JV > 0)) || { echo "FAIL: no junk put on the link" >&2; FAIL=1; }
    check "link junk of the wrong size (counted by the bridge)" "$BS" "$JS"
    check "link junk of another version (counted by the bridge)" "$BV" "$JV"
fi
if [[ $TRIALS == "?" ]] || ((TRIALS == 0)); then
    echo "FAIL: the planner ran no trial beside the hostile sender" >&2
    FAIL=1
fi
exit "$FAIL"
