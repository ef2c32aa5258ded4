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
# Environment: CARGO_TARGET_DIR (default ./target), SOAK_DIR (where the recording and logs go;
# default a new /tmp/vic-soak.* folder, kept).
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
OUT=${SOAK_DIR:-$(mktemp -d /tmp/vic-soak.XXXXXX)}
mkdir -p "$OUT"
CONFIG=$ROOT/config/two_link_divergent.toml
PLAN=$ROOT/tests/data/realtime/two_link_divergent_sigma002_sooc.json
SIGMA=noise.sigma=0.02

BOARD_PID=""
LOOP_PID=""
TOOL_PID=""

cleanup() {
    local code=$?
    trap - EXIT INT TERM
    # Only the processes this script started, by their ids.
    if [[ -n $LOOP_PID ]]; then
        kill "$LOOP_PID" 2>/dev/null || true
        pkill -TERM -P "$LOOP_PID" 2>/dev/null || true
    fi
    [[ -n $TOOL_PID ]] && kill "$TOOL_PID" 2>/dev/null || true
    [[ -n $BOARD_PID ]] && kill "$BOARD_PID" 2>/dev/null || true
    wait 2>/dev/null || true
    # What transport::remove_namespace removes: the namespace's files in /dev/shm and under
    # iceoryx2's root folder.
    # iceoryx2's root folder (the user's private /tmp/vic-UID), then the node folders that held
    # this namespace's files and are empty now (rmdir leaves any other).
    local root dirs
    root=/tmp/vic-$(id -u)
    dirs=$(find "$root/nodes" -mindepth 2 -maxdepth 2 -name "vic_${NS}.*" -printf '%h\n' 2>/dev/null | sort -u)
    find /dev/shm -maxdepth 1 -name "vic_${NS}.*" -delete 2>/dev/null || true
    find "$root" -name "vic_${NS}.*" -delete 2>/dev/null || true
    for d in $dirs; do rmdir "$d" 2>/dev/null || true; done
    local left
    left=$(find /dev/shm -maxdepth 1 -name "vic_${NS}.*" | wc -l)
    echo "cleanup: namespace $NS, $left files left in /dev/shm" >&2
    exit "$code"
}
trap cleanup EXIT
trap 'echo "interrupted" >&2; exit 130' INT TERM

echo "building (release)…" >&2
cargo build --release --bins --example malformed 2>&1 | tail -n 2 >&2

rss_kb() { awk '/^VmRSS/ { print $2 }' "/proc/$1/status"; }

"$BIN/vic-board" --config "$CONFIG" --set "$SIGMA" --namespace "$NS" --json \
    --record "$OUT/soak.csv" >"$OUT/board.json" 2>"$OUT/board.err" &
BOARD_PID=$!
sleep 1
kill -0 "$BOARD_PID" || { cat "$OUT/board.err" >&2; exit 1; }

(
    trap 'exit 0' TERM
    i=0
    while true; do
        i=$((i + 1))
        "$BIN/vic-planner" --config "$CONFIG" --set "$SIGMA" --namespace "$NS" --json \
            --plan "$PLAN" --strategy stiffness --latency-ms 200 --seed "$i" --trials 5 \
            >>"$OUT/planner.jsonl" 2>>"$OUT/planner.err" || echo "planner run $i failed" >>"$OUT/planner.err"
    done
) &
LOOP_PID=$!

"$BIN/examples/malformed" "$NS" "$SECONDS_TOTAL" 1000 >"$OUT/malformed.log" 2>&1 &
TOOL_PID=$!

sleep 2
RSS_START=$(rss_kb "$BOARD_PID")
echo "soak: $MINUTES min in namespace $NS, board pid $BOARD_PID, files in $OUT" >&2
END=$(($(date +%s) + SECONDS_TOTAL - 2))
while (($(date +%s) < END)); do
    kill -0 "$BOARD_PID" 2>/dev/null || { echo "the board died" >&2; cat "$OUT/board.err" >&2; exit 1; }
    sleep 5
done
RSS_END=$(rss_kb "$BOARD_PID")

wait "$TOOL_PID" || true
TOOL_PID=""
kill "$LOOP_PID" 2>/dev/null || true
pkill -TERM -P "$LOOP_PID" 2>/dev/null || true
wait "$LOOP_PID" 2>/dev/null || true
LOOP_PID=""
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
COUNTED=$((REJECTED + DROPPED))
# Per reason, what the hostile messages explain (wrong trial, overflow and drops share the burst
# and the slices for trial 0xFFFF); the rest is the planner's.
WTO=$(($(k seq-u64-max) + $(k nan-torque) + $(k stiffness-unbounded) + $(k flood-burst)))
BEYOND=$(jq -r --argjson shape "$(k knot-dt-1e15)" --argjson version "$(k bad-version)" \
    --argjson stale "$(k stale)" --argjson joints "$(k wrong-joints)" --argjson wto "$WTO" '
    (.rejected_by_reason // {}) as $r | def g($k): ($r[$k] // 0);
    ($r | to_entries | map(select(.key as $k
        | ["shape", "version", "stale", "joints", "wrong-trial", "overflow"] | index($k) | not))
        | map("\(.key) \(.value)"))
      + ["shape \(g("shape") - $shape)", "version \(g("version") - $version)",
         "stale \(g("stale") - $stale)", "joints \(g("joints") - $joints)",
         "wrong-trial + overflow + dropped \(g("wrong-trial") + g("overflow") + .dropped_messages - $wto)"]
    | map(select(test(" 0$") | not)) | join(", ")' "$S")
echo "hostile counted    $REJECTED rejected + $DROPPED dropped = $COUNTED for $HOSTILE hostile messages ($SINGLE single, $BURSTS bursts of 2000); beyond the hostile ones: $((COUNTED - HOSTILE)) (${BEYOND:-none}; the planner's own, e.g. slices sent into a latched fault; $TRIALS trials)"
FAIL=0
check() { # name, counted, at least
    if (($2 < $3)); then
        echo "FAIL: $1: the board counted $2, at least $3 expected" >&2
        FAIL=1
    fi
}
((HOSTILE > 0)) || { echo "FAIL: no hostile message sent" >&2; FAIL=1; }
check "knot_dt 1e15 (shape)" "$(r shape)" "$(k knot-dt-1e15)"
check "bad version" "$(r version)" "$(k bad-version)"
check "stale" "$(r stale)" "$(k stale)"
check "wrong joints" "$(r joints)" "$(k wrong-joints)"
check "seq u64::MAX, NaN, unbounded stiffness, bursts (wrong trial, overflow, dropped)" \
    $(($(r wrong-trial) + $(r overflow) + DROPPED)) "$WTO"
check "all hostile messages (rejected + dropped)" "$COUNTED" "$HOSTILE"
if [[ $TRIALS == "?" ]] || ((TRIALS == 0)); then
    echo "FAIL: the planner ran no trial beside the hostile sender" >&2
    FAIL=1
fi
exit "$FAIL"
