"""Plan a movement and plot it: the nominal joint angles against the reference, the torque and
the stiffness of the plan, and the spread of 50 noisy trials executed open loop.

    pip install target/wheels/vic-*.whl matplotlib   # the wheel: python/README.md
    python python/examples/plan_and_plot.py [--config config/two_link_divergent.toml]
        [--method sooc] [--set noise.sigma=0.02] [--trials 50] [--out plan.png]

``compute`` does the work (no matplotlib needed); ``main`` draws the figure with matplotlib's
Agg backend and saves it as a PNG.
"""

import argparse
import os

import vic

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))


def parse_set(items):
    """``["noise.sigma=0.02", ...]`` as the dict ``vic.Scenario.load(set=...)`` takes (values as
    text: the command line's reading)."""
    out = {}
    for item in items or []:
        key, _, value = item.partition("=")
        out[key.strip()] = value.strip()
    return out


def compute(config, method="sooc", overrides=None, trials=50, seed=1):
    """The scenario, its plan and the trials of the plan executed open loop."""
    scenario = vic.Scenario.load(config, set=overrides or {})
    plan = vic.plan(scenario, method=method)
    sim = vic.simulate(scenario, plan, policy="open-loop", trials=trials, seed=seed)
    return scenario, plan, sim


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=os.path.join(ROOT, "config/two_link_divergent.toml"))
    ap.add_argument("--method", default="sooc", choices=["ilqg", "sooc"])
    ap.add_argument("--set", action="append", metavar="SECTION.KEY=VALUE")
    ap.add_argument("--trials", type=int, default=50)
    ap.add_argument("--out", default="plan.png")
    args = ap.parse_args()
    scenario, plan, sim = compute(args.config, args.method, parse_set(args.set), args.trials)
    print(plan)
    print(f"open loop, {sim.trials} trials: final std {sim.final_std:.3f} {sim.unit}, "
          f"{sim.diverged} diverged, Monte Carlo cost {sim.expected_cost_mc}")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    dof = plan.dof
    fig, ax = plt.subplots(3, 1, figsize=(7, 8), sharex=True)
    t, tu = plan.time, plan.time[:-1]
    for j in range(dof):
        for i in range(sim.x.shape[0]):
            ax[0].plot(t, sim.x[i, :, j], color=f"C{j}", alpha=0.15, lw=0.7)
        ax[0].plot(t, plan.x[:, j], color=f"C{j}", lw=2, label=f"{plan.state_names[j]} plan")
        ax[0].plot(t, plan.reference_q[:, j], "k--", lw=1)
        ax[1].plot(tu, plan.feedforward[:, j], color=f"C{j}", label=plan.control_names[j])
        if plan.stiffness is not None:
            ax[2].plot(tu, plan.stiffness[:, j], color=f"C{j}", label=f"k{j + 1}")
    ax[0].set_ylabel("joint angle [rad]")
    ax[1].set_ylabel("torque [N m]")
    ax[2].set_ylabel("stiffness [N m/rad]")
    ax[2].set_xlabel("time [s]")
    for a in ax:
        a.legend(loc="best", fontsize=8)
    ax[0].set_title(f"{os.path.basename(plan.scenario)}: {plan.method}, "
                    f"{sim.trials} trials open loop (thin), reference dashed")
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"written {args.out}")


if __name__ == "__main__":
    main()
