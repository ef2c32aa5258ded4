"""Delay versus stiffness: the final error of each strategy against the feedback latency (the
figure of ``vic sweep latency --out-dir``), from Python.

    python python/examples/delay_sweep.py [--config config/single_joint_delay.toml]
        [--latencies 0,20,50,100,150,200,300] [--trials 20] [--out sweep.png]

``compute`` runs the sweep (no matplotlib needed); ``main`` plots the mean final error of the
trials that did not diverge, a cross where some diverged, with matplotlib's Agg backend.
"""

import argparse
import os

import numpy as np

import vic

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def compute(config, latencies_ms, strategies=("naive-delayed", "predictor", "stiffness"),
            trials=20, seed=1):
    """The sweep as ``vic.sweep_latency`` returns it (a dict of arrays, one entry per point)."""
    return vic.sweep_latency(config, latencies_ms=latencies_ms, strategies=strategies,
                             trials=trials, seed=seed)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=os.path.join(ROOT, "config/single_joint_delay.toml"))
    ap.add_argument("--latencies", default="0,20,50,100,150,200,300")
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--out", default="sweep.png")
    args = ap.parse_args()
    latencies = [float(v) for v in args.latencies.split(",")]
    sw = compute(args.config, latencies, trials=args.trials)
    for c in sw["crossings"]:
        print("crossing:", c)

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for i, name in enumerate(dict.fromkeys(sw["strategy"])):
        at = sw["strategy"] == name
        lat, err = sw["latency_ms"][at], sw["final_error_mean"][at]
        ax.plot(lat, err, "o-", color=f"C{i}", label=name)
        lost = sw["diverged"][at] > 0
        ax.plot(lat[lost], np.nan_to_num(err[lost], nan=np.nanmax(sw["final_error_mean"])), "x",
                color=f"C{i}", ms=10)
    ax.set_xlabel("feedback latency [ms]")
    ax.set_ylabel(f"mean final error [{sw['unit']}]")
    ax.set_yscale("log")
    ax.legend()
    ax.set_title(f"{os.path.basename(args.config)}: {args.trials} trials a point (x: some diverged)")
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"written {args.out}")


if __name__ == "__main__":
    main()
