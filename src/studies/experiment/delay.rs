//! The "Delay versus stiffness" section of docs/RESULTS.md: the latency sweep
//! ([`crate::studies::sweep`]) for the single joint of Fig. 2 and the two-link arm in the divergent
//! field of Fig. 1, its figures, its table and the latency at which the best delayed feedback
//! (the predictor) stops beating the open-loop stiffness plan.

use crate::studies::sweep::{Strategy, Sweep, SweepOptions, crossing, sweep_latency, write_figure};
use std::path::{Path, PathBuf};

/// The latencies of the section [ms].
pub(crate) const LATENCIES_MS: [f64; 7] = [0.0, 20.0, 50.0, 100.0, 150.0, 200.0, 300.0];
/// The strategies of the section: all five.
pub(crate) const STRATEGIES: [Strategy; 5] = Strategy::ALL;

/// One scenario's sweep.
#[derive(Debug, Clone)]
pub(crate) struct DelaySweep {
    /// File stem of its outputs (`delay_joint`, `delay_arm`).
    pub(crate) name: &'static str,
    pub(crate) title: &'static str,
    pub(crate) sweep: Sweep,
}

/// Why the section could not be made.
#[derive(Debug, thiserror::Error)]
pub(crate) enum DelaySweepError {
    #[error("{}: {source}", scenario.display())]
    Sweep {
        scenario: PathBuf,
        source: Box<crate::studies::sweep::SweepError>,
    },
    #[error(transparent)]
    Plot(#[from] crate::views::plot::PlotError),
    #[error("cannot write {}: {source}", path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// Runs both sweeps with the scenarios of `config_dir`.
pub(crate) fn run_delay_sweeps(
    config_dir: &Path,
    trials: usize,
    seed: u64,
    progress: &dyn Fn(&str),
) -> Result<Vec<DelaySweep>, DelaySweepError> {
    let opts = SweepOptions {
        latencies_ms: LATENCIES_MS.to_vec(),
        strategies: STRATEGIES.to_vec(),
        trials,
        seed,
        divergence: None,
        pulse: None,
        execution: Default::default(),
    };
    let cases = [
        (
            "delay_joint",
            "single joint (Fig. 2's setting, σ = 0.03)",
            "single_joint_delay.toml",
        ),
        (
            "delay_arm",
            "two-link arm in the divergent field (Fig. 1's setting, β = 50 N/m, σ = 0.05)",
            "two_link_divergent.toml",
        ),
    ];
    cases
        .iter()
        .map(|&(name, title, file)| {
            let path = config_dir.join(file);
            let sweep = sweep_latency(&path, &[], &opts, progress).map_err(|source| {
                DelaySweepError::Sweep {
                    scenario: path.clone(),
                    source: Box::new(source),
                }
            })?;
            Ok(DelaySweep { name, title, sweep })
        })
        .collect()
}

/// Writes `NAME.png`, `NAME.svg` and `NAME.json` into `dir`; returns their paths.
pub(crate) fn write_delay_outputs(
    s: &DelaySweep,
    dir: &Path,
) -> Result<Vec<PathBuf>, DelaySweepError> {
    let write_err = |path: &Path| {
        let path = path.to_path_buf();
        move |source| DelaySweepError::Write { path, source }
    };
    std::fs::create_dir_all(dir).map_err(write_err(dir))?;
    let png = dir.join(format!("{}.png", s.name));
    let svg = dir.join(format!("{}.svg", s.name));
    let json = dir.join(format!("{}.json", s.name));
    write_figure(&s.sweep, &png, &svg)?;
    let text = serde_json::to_string_pretty(&s.sweep).expect("a sweep serialises");
    std::fs::write(&json, text + "\n").map_err(write_err(&json))?;
    Ok(vec![png, svg, json])
}

/// The section's markdown: per scenario the figure, the table and the crossing latencies, then the
/// paragraph on what they show.
pub(crate) fn delay_markdown(sweeps: &[DelaySweep], figure_dir: &str) -> String {
    let mut md = String::from("## Delay versus stiffness\n\n");
    md.push_str(&format!(
        "`vic sweep latency` (offline Monte Carlo, {} trials per point, seed {}, the same noise \
         for every strategy): `naive-delayed` is Eq. 13 (the gains of an ILQG plan made for the \
         latency, on the state seen that late, no stiffness); `predictor` is the best delayed \
         feedback without stiffness (the undelayed ILQG gains on the present predicted from the \
         delayed state over the commands in flight, a Smith predictor); `stiffness` is the \
         open-loop SOOC plan of torque and stiffness, which no latency touches; \
         `stiffness+predictor` is the undelayed ILQG plan with stiffness allowed, its gains on the \
         predicted present; `replan` re-solves the SOOC plan every 20 ms (3 Newton steps, warm \
         started) from the present predicted from the delayed state, and plays it open loop \
         between re-solves. Final error: \
         mean over the trials that did not diverge, with a bar to the worst of them (hollow \
         where some trials diverged, a cross where all did); E[C] predicted is the \
         executed policy's cost by closed-loop covariance propagation (not modelled for the naive \
         law).\n\n",
        sweeps.first().map_or(0, |s| s.sweep.trials),
        sweeps.first().map_or(0, |s| s.sweep.seed),
    ));
    for s in sweeps {
        md.push_str(&scenario_markdown(s, figure_dir));
    }
    md.push_str(PARAGRAPH);
    md.push_str("\n\n");
    md
}

fn scenario_markdown(s: &DelaySweep, figure_dir: &str) -> String {
    let name = s.name;
    let mut md = format!(
        "### {}\n\n![{name}]({figure_dir}/{name}.png)\n\nVector version: \
         [{name}.svg]({figure_dir}/{name}.svg); numbers: [{name}.json]({figure_dir}/{name}.json).\n\n",
        s.title
    );
    let unit = s.sweep.points.first().map_or("", |p| p.unit.name());
    md.push_str(&format!(
        "| strategy | latency | final error mean / max [{unit}] | RMS error [{unit}] | diverged | \
         E[C] Monte Carlo | E[C] predicted | mean stiffness |\n|---|---|---|---|---|---|---|---|\n"
    ));
    let num = |v: Option<f64>, digits: usize| {
        v.map_or_else(|| "diverged".to_string(), |v| format!("{v:.digits$}"))
    };
    let sci = |v: Option<f64>| v.map_or_else(|| "–".to_string(), |v| format!("{v:.3e}"));
    for p in &s.sweep.points {
        md.push_str(&format!(
            "| {} | {} ms | {} / {} | {} | {:.0} % | {} | {} | {:.1} |\n",
            p.strategy.name(),
            p.latency_ms,
            num(p.final_error_mean, 3),
            num(p.final_error_max, 3),
            num(p.rms_error, 3),
            p.diverged_fraction * 100.0,
            sci(p.expected_cost_mc),
            sci(p.expected_cost_predicted),
            p.mean_stiffness
        ));
    }
    let (pr, st) = (Strategy::Predictor, Strategy::Stiffness);
    md.push_str(&format!(
        "\nThe predictor ends closer to the target than stiffness {}; its Monte Carlo expected \
         cost is lower {}; its RMS error over the movement is lower {}.",
        crossing(&s.sweep, pr, st, |p| p.final_error_mean).text(),
        crossing(&s.sweep, pr, st, |p| p.expected_cost_mc).text(),
        crossing(&s.sweep, pr, st, |p| p.rms_error).text(),
    ));
    let first_diverged = |strategy: Strategy| {
        s.sweep
            .points
            .iter()
            .find(|p| p.strategy == strategy && p.diverged_fraction > 0.0)
            .map_or_else(
                || "never diverges in the sweep".to_string(),
                |p| {
                    format!(
                        "loses trials from {} ms on ({:.0} % there)",
                        p.latency_ms,
                        p.diverged_fraction * 100.0
                    )
                },
            )
    };
    md.push_str(&format!(
        " Replanning ends closer to the target than stiffness {}; stiffness+predictor {}.",
        crossing(&s.sweep, Strategy::Replan, st, |p| p.final_error_mean).text(),
        crossing(&s.sweep, Strategy::StiffnessPredictor, st, |p| {
            p.final_error_mean
        })
        .text(),
    ));
    md.push_str(&format!(
        " The naive law {}; the predictor {}; stiffness {}; stiffness+predictor {}; replanning {}.\n\n",
        first_diverged(Strategy::NaiveDelayed),
        first_diverged(pr),
        first_diverged(st),
        first_diverged(Strategy::StiffnessPredictor),
        first_diverged(Strategy::Replan),
    ));
    md
}

/// What the curves say (the numbers above are regenerated; this reading of them was checked
/// against them when the section was written).
const PARAGRAPH: &str = "**Reading.** Stiffness is flat in the latency: the open-loop plan \
never looks at a measurement, and the joint's impedance acts on a disturbance in the tick it \
arrives. The naive Eq. 13 law is no baseline: it loses its trials from the first latency step \
on, because the gains of a plan made for the delay assume that the commands in flight are fed \
back, which Eq. 13 does not do. The predictor is the honest baseline and a good one at short \
latencies: with no latency it is the plain ILQG feedback, and for a few tens of milliseconds it \
keeps a lower expected cost than the stiffness plan on both plants (and, on the arm, a smaller \
final error). What it cannot know is the noise that entered during the latency, so its error \
and its cost grow with the latency (without noise it tracks as well as without latency, \
tests/predictor.rs). In the divergent field, where a deviation grows by itself, that costs \
centimetres and then whole trials at the longer latencies; on the single joint, without a \
field, its final error stays a fraction of a degree at every latency and only its expected \
cost (which also charges the path and the effort) passes the stiffness plan's. Where the curves \
cross is this sweep's answer to the paper's question for these two plants: beyond it, \
stiffness planned in advance beats the best feedback that a central controller this late can \
give.

**Replanning and feedback on top of stiffness.** `replan` re-solves the stiffness plan every \
20 ms from the present predicted over the latency. On the arm in the divergent field it ends \
closer to the target than the stiffness plan at every latency (2.8–4.3 mm against 5.3 mm) and \
never loses a trial; its expected cost is lower than the stiffness plan's up to 200 ms (25 % \
lower with no latency, 1 % at 200 ms) and 5 % higher at 300 ms (20 trials a point). What it does is buy stiffness: its re-solves command 34–39 N m/rad on \
average where the plan made in advance holds 24 (the column \"mean stiffness\" is what the \
trials commanded), as a controller that sees the field push the hand off its path, late, \
should. Its final error even shrinks at the longest latencies, where its first re-solve comes \
later in the movement (why that helps is not analysed yet). On the single joint, without a \
field, replanning buys a lower expected cost up to 200 ms (20 % lower with no latency, 0.1–1.2 % \
from 100 to 200 ms) and about the same at 300 ms (0.4 % higher) with a little less stiffness \
than the plan (12–14 N m/rad against 14.4), and \
ends a little farther from the target than the plan it replans: there the plan made in \
advance is already close to what a re-solve from a stale, noisy prediction can give. Each re-solve takes at most 3 Newton steps of a model without the flow's \
third derivatives (the exact Hessian costs about twice as much for the same gain from a warm \
start). `stiffness+predictor` (an undelayed ILQG plan with stiffness, its gains on the predicted \
present) improves the arm's final error at short latencies, but its feedback also drives the \
stiffness (on the arm it chatters between its bounds and averages 40–43 N m/rad): its expected \
cost is several times the stiffness plan's at every latency, the trap of optimising a feedback policy over the stiffness (the \
open-loop SOOC plan does better). Live, `replan` re-solves on a worker thread one period ahead, \
so a re-solve slower than the period delays the new plan rather than the slices (`vic demo`).";
