"""Feel the stiffness: start a board, hold the arm, push it, and plot how it springs back.

    python python/examples/live_stiffness.py [--board target/release/vic-board] [--out push.png]
        [--torque 2,-1] [--duration-ms 50] [--hold-stiffness 100]

Starts ``vic-board`` in a namespace of its own (no central process: after the reset the board's
watchdog ramps into the safe hold, the hold stiffness at the reset posture), streams its state,
injects a torque pulse, and plots the joint angles, the torque and the external torque against
time (matplotlib with the Agg backend, saved as a PNG; without matplotlib the plot is skipped with
a message). Run it again with another --hold-stiffness to see a stiffer or softer arm. The board
is stopped (by its pid) and its shared memory removed at the end.
"""

import argparse
import os
import signal
import subprocess
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))  # the package from a checkout
import vic_client as vc  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--board", default=os.path.join(ROOT, "target/release/vic-board"))
    ap.add_argument("--config", default=os.path.join(ROOT, "config/two_link_divergent.toml"))
    ap.add_argument("--out", default="live_stiffness.png")
    ap.add_argument("--torque", default="2,-1", help="pulse torque per joint [N m]")
    ap.add_argument("--duration-ms", type=float, default=50.0)
    ap.add_argument("--hold-stiffness", type=float, default=100.0, help="[N m/rad]")
    args = ap.parse_args()
    torque = [float(t) for t in args.torque.split(",")]
    if not os.access(args.board, os.X_OK):
        sys.exit(f"{args.board}: no such program (cargo build --release, or --board PATH)")

    ns = f"example{os.getpid()}"
    board = subprocess.Popen(
        [args.board, "--config", args.config, "--namespace", ns, "--no-rt",
         "--hold-stiffness", str(args.hold_stiffness)],
        stdout=subprocess.DEVNULL,
    )
    try:
        with vc.Board(ns, timeout=10) as b:
            b.set_noise(0.0)  # a clean response (the plant noise scales with the speed)
            b.set_field(0.0)  # no divergent field: the hold alone
            q0 = [0.43, 2.12]  # the reach's start posture [rad]
            b.reset(q0)
            b.wait_state(lambda s: s["mode"] == vc.Mode.SAFE_HOLD, 2.0)
            b.collect(0.2)  # past the ramp into the hold
            before = b.latest["tick"]
            ack = b.inject_pulse(torque, args.duration_ms / 1e3)
            print(f"pulse {torque} N m for {args.duration_ms} ms applied at tick {ack['tick']}")
            b.collect(1.0)
            s = b.since_tick(before - 100)
    finally:
        board.send_signal(signal.SIGTERM)
        board.wait(timeout=10)
        for path in vc.namespace_files(ns):  # what a killed process might have left
            os.remove(path)

    # Plant time (a late tick integrates several periods at once, so ticks are not time).
    t = (s["trial_time_ns"].astype(np.int64) - int(ack["trial_time_ns"])) * 1e-9
    dq = (s["q"] - np.asarray(q0)) * 1e3
    peak = np.abs(dq).max(axis=0)
    print(f"{len(s)} states; peak deflection {peak.round(2)} mrad; stiffness {s['stiffness'][-1]}")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot (pip install matplotlib)")
        return
    fig, ax = plt.subplots(3, 1, sharex=True, figsize=(7, 7))
    for j in range(2):
        ax[0].plot(t, dq[:, j], label=f"joint {j + 1}")
        ax[1].plot(t, s["tau"][:, j] - s["tau_ext"][:, j], label=f"joint {j + 1}")
        ax[2].plot(t, s["tau_ext"][:, j], label=f"joint {j + 1}")
    ax[0].set_ylabel("q − q0 [mrad]")
    ax[1].set_ylabel("actuator torque [N m]")
    ax[2].set_ylabel("pulse τ_ext [N m]")
    ax[2].set_xlabel("time since the pulse [s]")
    ax[0].set_title(f"A {args.duration_ms:.0f} ms push on the held arm (K = {args.hold_stiffness:g} N m/rad)")
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"plot: {args.out}")


if __name__ == "__main__":
    main()
