//! `vic simulate`: a Monte Carlo of a plan on the stochastic plant (Euler–Maruyama, Eq. 10),
//! executed open loop, with the plan's feedback gains (Eq. 9) or with them on a delayed state
//! (Eq. 13); the spread, the tracking errors, the divergence and the expected cost (Eq. 14) next
//! to the plan's prediction, optionally every trial as CSV and a plot.

use crate::cli::{Classify, JsonArg, ScenarioArgs, SeedArgs, divergence_or_default, latency_arg};
use clap::ValueEnum;
use std::io::Write;
use std::path::{Path, PathBuf};
use vic_plan::evaluation::{Report, summarize};
use vic_plan::montecarlo::{Trial, run_trials};
use vic_plan::plan::{PlanFile, setup};
use vic_plan::scenario::Scenario;
use vic_plan::strategy::{Feedback, Latency, Strategy};

/// `--policy`: how the plan is executed (the central strategies by their names too).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum PolicyArg {
    /// The planned commands, no feedback at all.
    OpenLoop,
    /// The plan's gains on the current state.
    Feedback,
    /// The plan's gains on the state seen --latency-ms late (Eq. 13; default: the plan's delay).
    #[value(alias = "delayed-feedback")]
    NaiveDelayed,
    /// The gains of an undelayed plan on the present state predicted from the one seen
    /// --latency-ms late, over the commands applied since (a Smith predictor).
    Predictor,
    /// The central strategy `stiffness`: the plan's commands with no feedback (as open-loop).
    Stiffness,
    /// The central strategy `stiffness+predictor`: the plan's torque and stiffness plus the
    /// predictor's feedback (as predictor; give it a plan with stiffness).
    #[value(name = "stiffness+predictor")]
    StiffnessPredictor,
    /// The central strategy `replan`: the plan (give it a SOOC plan) re-solved every 20 ms from
    /// the present predicted from the state seen --latency-ms late (default 0), played open loop
    /// between re-solves. Slow: seconds per trial on the arm.
    Replan,
}

/// What `vic simulate` was asked for: its flags.
#[derive(Debug, Clone, clap::Args)]
#[command(mut_arg("config", |a| a.help(
    "Scenario file (TOML): the plant the plan runs on (it may differ from the plan's, e.g. in noise)"
)))]
pub(crate) struct Args {
    #[command(flatten)]
    pub(crate) scenario: ScenarioArgs,
    /// Plan file written by `vic plan --out`.
    #[arg(long, value_name = "FILE")]
    pub(crate) plan: PathBuf,
    /// How the plan is executed.
    #[arg(long, value_enum, default_value = "open-loop")]
    pub(crate) policy: PolicyArg,
    /// Number of trials. [range: 2 to 100000]
    #[arg(long, default_value_t = 20, value_parser = crate::ranges::trials(2, "a spread needs two"))]
    pub(crate) trials: u64,
    #[command(flatten)]
    pub(crate) seed: SeedArgs,
    /// Feedback latency for --policy naive-delayed [ms] (default: the plan's delay) and for
    /// --policy predictor, stiffness+predictor and replan (default 0); a whole number of steps.
    /// [range: 0 to 1000]
    #[arg(long, value_name = "MS", alias = "delay-ms", value_parser = crate::ranges::real(0.0, crate::ranges::MAX_LATENCY_MS))]
    pub(crate) latency_ms: Option<f64>,
    /// A trial has diverged when it ends further than this from the target [mm for the arm,
    /// degrees for a single joint] (default 50 mm / 10°). [range: 0.001 to 100000]
    #[arg(long, value_name = "DIST", value_parser = crate::ranges::real(0.001, crate::ranges::MAX_DIVERGENCE))]
    pub(crate) divergence: Option<f64>,
    /// Write every trial's states and commands to this CSV file.
    #[arg(long, value_name = "FILE")]
    pub(crate) csv: Option<PathBuf>,
    /// Plot the trials (paths or angles, velocities, commands) to this PNG (and an SVG beside it).
    #[arg(long, value_name = "FILE.png")]
    pub(crate) plot: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) json: JsonArg,
}

impl PolicyArg {
    /// The central strategy this policy executes as (`None`: no latency enters).
    fn strategy(self) -> Option<Strategy> {
        match self {
            PolicyArg::OpenLoop | PolicyArg::Feedback => None,
            PolicyArg::NaiveDelayed => Some(Strategy::NaiveDelayed),
            PolicyArg::Predictor => Some(Strategy::Predictor),
            PolicyArg::Stiffness => Some(Strategy::Stiffness),
            PolicyArg::StiffnessPredictor => Some(Strategy::StiffnessPredictor),
            PolicyArg::Replan => Some(Strategy::Replan),
        }
    }
}

impl Args {
    /// How `--policy` at `--latency-ms` executes `plan` on a grid of `dt` s: the strategy's
    /// feedback at the latency (default: the plan's delay for the naive law, which its gains
    /// were made for, else 0).
    pub(crate) fn feedback(&self, plan: &PlanFile, dt: f64) -> anyhow::Result<Feedback> {
        let strategy = match self.policy.strategy() {
            Some(s) => s,
            None if self.policy == PolicyArg::Feedback => return Ok(Feedback::Full),
            None => return Ok(Feedback::OpenLoop),
        };
        let latency = match (self.latency_ms, strategy) {
            (Some(ms), _) => latency_arg("--latency-ms", ms, dt)?,
            (None, Strategy::NaiveDelayed) => Latency::from_knots(plan.summary.delay_steps, dt),
            (None, _) => Latency::ZERO,
        };
        Ok(strategy.feedback(latency.knots()))
    }
}

/// Runs the trials, writes the CSV and the plot if asked, prints the report.
pub(crate) fn run(o: Args) -> anyhow::Result<()> {
    let o = &o;
    let scenario = Scenario::load(&o.scenario.config, &o.scenario.set.overrides).input()?;
    let plan = PlanFile::read(&o.plan).input()?;
    let setup = setup(&scenario).input()?;
    let policy = plan
        .policy(&setup)
        .map_err(|e| format!("{}: {e}", o.plan.display()))
        .input()?;
    let feedback = o.feedback(&plan, scenario.task.dt)?;
    let divergence = divergence_or_default(o.divergence, &setup.dynamics.model);
    let trials = run_trials(&setup, &policy, feedback, o.trials as usize, o.seed.seed);
    let report = summarize(&setup, &trials, divergence);
    if let Some(path) = &o.csv {
        write_trials_csv(path, &plan, &trials)?;
    }
    if let Some(png) = &o.plot {
        plot_trials(png, feedback, &plan, &scenario, &trials, divergence)?;
    }
    // The executed law's own prediction (closed-loop covariance propagation); for the naive
    // delayed law, the plan's (that of the augmented policy it was planned as).
    let predicted = vic_plan::prediction::predicted_cost(&setup, &policy, feedback)
        .unwrap_or(plan.summary.expected_cost);
    if o.json.json {
        let mut v = serde_json::to_value(&report)?;
        v["policy"] = serde_json::to_value(feedback)?;
        v["expected_cost_predicted"] = predicted.into();
        v["seed"] = o.seed.seed.into();
        println!("{v}");
    } else {
        print_report(o, &plan, feedback, &report, divergence, predicted);
    }
    Ok(())
}

fn plot_trials(
    png: &Path,
    feedback: Feedback,
    plan: &PlanFile,
    scenario: &Scenario,
    trials: &[Trial],
    divergence: f64,
) -> anyhow::Result<()> {
    // The figure names the execution in words ("delayed feedback (20 steps)").
    let title = feedback.to_string();
    let column =
        crate::studies::experiment::column_plot(&title, plan, scenario, trials, divergence);
    let svg = png.with_extension("svg");
    if scenario.model.dof() == 2 {
        crate::views::plot::arm_figure(&[column], png, &svg).runtime()
    } else {
        crate::views::plot::joint_figure(&[column], png, &svg).runtime()
    }
}

fn print_report(
    o: &Args,
    plan: &PlanFile,
    feedback: Feedback,
    report: &Report,
    divergence: f64,
    predicted: f64,
) {
    let u = &report.unit;
    let policy = o
        .policy
        .to_possible_value()
        .map_or_else(String::new, |v| v.get_name().to_string());
    let latency = match feedback {
        Feedback::OpenLoop | Feedback::Full => String::new(),
        Feedback::Delayed { latency_steps }
        | Feedback::Predicted { latency_steps }
        | Feedback::Replan { latency_steps } => format!(", latency {latency_steps} knots"),
    };
    println!(
        "simulate   the plan of {} on {}, policy {policy}{latency}, {} trials, seed {}",
        plan.scenario,
        o.scenario.config.display(),
        report.trials,
        o.seed.seed
    );
    let axes: Vec<String> = report
        .ellipse_95
        .iter()
        .map(|v| format!("{v:.3}"))
        .collect();
    println!(
        "final      std {:.3} {u}, 95 % ellipse semi-axes {} {u}",
        report.final_std,
        axes.join(" × ")
    );
    let f = |v: Option<f64>| v.map_or_else(|| "diverged".to_string(), |v| format!("{v:.3}"));
    println!(
        "errors     RMS {} {u}, final mean {} / max {} {u} (over the trials that did not diverge)",
        f(report.rms_error),
        f(report.final_error_mean),
        f(report.final_error_max)
    );
    println!(
        "diverged   {} of {} (ending > {divergence} {u} from the target)",
        report.diverged, report.trials
    );
    let mc = match (report.expected_cost_mc, report.expected_cost_se) {
        (Some(m), Some(se)) => format!("{m:.6e} ± {se:.2e}"),
        (Some(m), None) => format!("{m:.6e}"),
        _ => "– (every trial diverged)".into(),
    };
    println!(
        "cost       Monte Carlo {mc} (trials that did not diverge), predicted {predicted:.6e}"
    );
}

/// Every trial's states and commands, one row per knot: `trial,k,t,<states>,<controls>` (the last
/// knot has no command: its control columns are empty).
pub(crate) fn write_trials_csv(
    path: &Path,
    plan: &PlanFile,
    trials: &[Trial],
) -> anyhow::Result<()> {
    write_csv(path, plan, trials)
        .map_err(|e| format!("cannot write {}: {e}", path.display()))
        .runtime()
}

fn write_csv(path: &Path, plan: &PlanFile, trials: &[Trial]) -> std::io::Result<()> {
    let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut header = vec!["trial".to_string(), "k".into(), "t".into()];
    header.extend(plan.state_names.iter().cloned());
    header.extend(plan.control_names.iter().cloned());
    writeln!(w, "{}", header.join(","))?;
    for (i, t) in trials.iter().enumerate() {
        for (k, x) in t.x.iter().enumerate() {
            write!(w, "{i},{k},{}", plan.dt * k as f64)?;
            for v in x.iter() {
                write!(w, ",{v}")?;
            }
            match t.u.get(k) {
                Some(u) => u.iter().try_for_each(|v| write!(w, ",{v}"))?,
                None => (0..plan.control_names.len()).try_for_each(|_| write!(w, ","))?,
            }
            writeln!(w)?;
        }
    }
    w.flush()
}
