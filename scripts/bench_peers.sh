#!/usr/bin/env bash
# Crocoddyl 3.2.1 (DDP, BoxDDP) against vic's ILQG on the same problems, in one run.
#
#   scripts/bench_peers.sh [OUT_DIR]          # default OUT_DIR: target/peers
#   RUNS=200 PY_RUNS=3 VENV=/tmp/croc scripts/bench_peers.sh
#
# Creates a Python venv (VENV, default OUT_DIR/venv) with crocoddyl==3.2.1, pin==4.0.0 and
# libpinocchio==4.0.0 (newer libpinocchio wheels are ABI-incompatible with that Crocoddyl), builds
# vic's side (examples/peer_problem.rs), and for each problem prints one JSON line per Crocoddyl
# solver with both medians, the ratio, and how far the two optima are apart
# (scripts/peer_crocoddyl.py). Problems (all the reach of config/two_link_reach.toml, N = 100,
# Δ = 10 ms, vic's initial guess for both):
#   reach_semi      semi-implicit Euler, no viscosity: Crocoddyl's built-in (C++) arm model
#   box_semi        the same with |τ| ≤ 0.25 N m (BoxDDP), a limit that binds
#   reach           vic's default problem (explicit Euler, joint viscosity): Crocoddyl with the
#                   arm as a Python action model (its time is Python's, not the solver's)
#   box             the same with |τ| ≤ 0.25 N m
# Both sides run on one thread (OMP_NUM_THREADS=1, RAYON_NUM_THREADS=1). Results also go to
# OUT_DIR/peers.jsonl.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-target/peers}
RUNS=${RUNS:-200}
PY_RUNS=${PY_RUNS:-3}
VENV=${VENV:-$OUT/venv}
mkdir -p "$OUT"
export OMP_NUM_THREADS=1 RAYON_NUM_THREADS=1

if ! "$VENV/bin/python" -c "import crocoddyl" 2>/dev/null; then
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install --quiet "crocoddyl==3.2.1" "pin==4.0.0" "libpinocchio==4.0.0" numpy
fi
"$VENV/bin/python" -c "import crocoddyl, pinocchio; print('crocoddyl', crocoddyl.__version__, 'pinocchio', pinocchio.__version__)" >&2

cargo build --release --example peer_problem >&2
BIN=${CARGO_TARGET_DIR:-target}/release/examples/peer_problem
SEMI=(task.integrator=semi_implicit "plant.viscosity=[[0.0,0.0],[0.0,0.0]]")
BOX=(actuator.torque_limit=0.25)

: > "$OUT/peers.jsonl"
run() { # name model runs overrides...
    local name=$1 model=$2 runs=$3
    shift 3
    "$BIN" "$name" "$RUNS" "$@" > "$OUT/$name.json"
    "$VENV/bin/python" scripts/peer_crocoddyl.py "$OUT/$name.json" "$model" "$runs" | tee -a "$OUT/peers.jsonl"
}
run reach_semi builtin "$RUNS" "${SEMI[@]}"
run box_semi builtin "$RUNS" "${SEMI[@]}" "${BOX[@]}"
run reach python "$PY_RUNS"
run box python "$PY_RUNS" "${BOX[@]}"
