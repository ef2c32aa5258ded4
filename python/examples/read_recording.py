"""Load an MCAP recording (``vic-board --record run.mcap`` or ``vic record --out run.mcap``) and
print what each channel holds; with pandas installed every channel is a DataFrame.

    python python/examples/read_recording.py run.mcap [--plot run.png]

``summarize`` describes the channels (no matplotlib needed); ``--plot`` draws the board's joint
angles and stiffness against time with matplotlib's Agg backend.
"""

import argparse

import numpy as np

import vic


def summarize(path):
    """One line per channel: topic, messages, columns; and the recording as ``vic.read_mcap``
    returns it (dicts of NumPy arrays)."""
    rec = vic.read_mcap(path, pandas=False)
    lines = []
    for topic, cols in rec.items():
        n = len(cols["log_time"])
        span = (int(cols["log_time"][-1]) - int(cols["log_time"][0])) * 1e-9 if n else 0.0
        names = [k for k in cols if k not in ("log_time", "publish_time", "sequence")]
        lines.append(f"{topic}: {n} messages over {span:.3f} s; columns {', '.join(names)}")
    return lines, rec


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("mcap")
    ap.add_argument("--plot", metavar="FILE.png")
    args = ap.parse_args()
    lines, rec = summarize(args.mcap)
    print("\n".join(lines))
    ticks = rec.get("/board/tick")
    if ticks is None or not args.plot:
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = (ticks["log_time"] - ticks["log_time"][0]) * 1e-9
    fig, ax = plt.subplots(2, 1, sharex=True, figsize=(7, 5))
    ax[0].plot(t, ticks["q"])
    ax[0].set_ylabel("joint angle [rad]")
    ax[1].plot(t, ticks["stiffness"])
    ax[1].set_ylabel("stiffness [N m/rad]")
    ax[1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(args.plot, dpi=120)
    print(f"written {args.plot}; mean |q| {np.nanmean(np.abs(ticks['q'])):.3f} rad")


if __name__ == "__main__":
    main()
