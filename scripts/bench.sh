#!/usr/bin/env bash
# Runs the board-loop, transport and cargo benchmarks of docs/BENCHMARKS.md (each of its other
# sections names its own command) and keeps the outputs in bench-results/ (or $1):
#   vic bench loop  (board loop variants + cyclictest, 30 s each)
#   vic bench ipc   (transport vs bare iceoryx2, then the running pair)
#   vic bench sooc  (the SOOC iteration's cost against the state dimension)
#   cargo bench     (solver, scenarios, board, and vic-core's URDF chain dynamics)
# Installs cyclictest (Debian package rt-tests) with apt-get when it is missing.
# Environment: SECONDS_PER_RUN (default 30), ITERATIONS (default 100000), SKIP_CARGO_BENCH=1.
set -euo pipefail
cd "$(dirname "$0")/.."
out="${1:-bench-results}"
mkdir -p "$out"
secs="${SECONDS_PER_RUN:-30}"
iters="${ITERATIONS:-100000}"

if ! command -v cyclictest >/dev/null 2>&1; then
    echo "cyclictest not found: installing rt-tests" >&2
    if [ "$(id -u)" -eq 0 ]; then
        apt-get update -qq && apt-get install -y -qq rt-tests
    else
        sudo apt-get update -qq && sudo apt-get install -y -qq rt-tests
    fi
fi

cargo build --release --bins
vic=target/release/vic
if [ -n "${CARGO_TARGET_DIR:-}" ]; then vic="$CARGO_TARGET_DIR/release/vic"; fi

{ nproc; grep -m1 'model name' /proc/cpuinfo; uname -a; cat /proc/loadavg; } > "$out/machine.txt"

"$vic" bench loop --seconds "$secs" --json > "$out/loop.json"
"$vic" bench ipc --iterations "$iters" --json > "$out/ipc.json"
"$vic" bench sooc --json > "$out/sooc_scaling.json"
echo "loop, ipc and sooc results in $out/loop.json, $out/ipc.json, $out/sooc_scaling.json" >&2

if [ "${SKIP_CARGO_BENCH:-0}" != 1 ]; then
    cargo bench --bench board 2>&1 | tee "$out/cargo-bench-board.txt"
    cargo bench --bench scenarios 2>&1 | tee "$out/cargo-bench-scenarios.txt"
    cargo bench --bench solver 2>&1 | tee "$out/cargo-bench-solver.txt"
    cargo bench -p vic-core --bench dynamics 2>&1 | tee "$out/cargo-bench-dynamics.txt"
fi
