//! `vic simulate`: flags, then [`vic::tools::simulate::run`].

use clap::ValueEnum;
use std::path::PathBuf;
use vic::tools::cli::{JsonArg, ScenarioArgs, SeedArgs};
use vic::tools::simulate::{Execution, SimulateOptions, run};

#[derive(Clone, Copy, ValueEnum)]
enum PolicyArg {
    /// The planned commands, no feedback at all.
    OpenLoop,
    /// The plan's gains on the current state.
    Feedback,
    /// The plan's gains on the state seen --delay-ms late (Eq. 13; default: the plan's delay).
    #[value(alias = "delayed-feedback")]
    NaiveDelayed,
    /// The gains of an undelayed plan on the present state predicted from the one seen
    /// --delay-ms late, over the commands applied since (a Smith predictor).
    Predictor,
    /// The central strategy `stiffness`: the plan's commands with no feedback (as open-loop).
    Stiffness,
    /// The central strategy `stiffness+predictor`: the plan's torque and stiffness plus the
    /// predictor's feedback (as predictor; give it a plan with stiffness).
    #[value(name = "stiffness+predictor")]
    StiffnessPredictor,
    /// The central strategy `replan`: the plan (give it a SOOC plan) re-solved every 20 ms from
    /// the present predicted from the state seen --delay-ms late (default 0), played open loop
    /// between re-solves. Slow: seconds per trial on the arm.
    Replan,
}

#[derive(clap::Args)]
#[command(mut_arg("config", |a| a.help(
    "Scenario file (TOML): the plant the plan runs on (it may differ from the plan's, e.g. in noise)"
)))]
pub struct SimulateArgs {
    #[command(flatten)]
    scenario: ScenarioArgs,
    /// Plan file written by `vic plan --out`.
    #[arg(long, value_name = "FILE")]
    plan: PathBuf,
    /// How the plan is executed.
    #[arg(long, value_enum, default_value = "open-loop")]
    policy: PolicyArg,
    /// Number of trials.
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u64).range(2..))]
    trials: u64,
    #[command(flatten)]
    seed: SeedArgs,
    /// Feedback latency for --policy delayed-feedback [ms] (default: the plan's delay) and for
    /// --policy predictor and replan (default 0).
    #[arg(long, value_name = "D")]
    delay_ms: Option<f64>,
    /// A trial has diverged when it ends further than this from the target [mm for the arm,
    /// degrees for a single joint] (default 50 mm / 10°).
    #[arg(long, value_name = "DIST")]
    divergence: Option<f64>,
    /// Write every trial's states and commands to this CSV file.
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
    /// Plot the trials (paths or angles, velocities, commands) to this PNG (and an SVG beside it).
    #[arg(long, value_name = "FILE.png")]
    plot: Option<PathBuf>,
    #[command(flatten)]
    json: JsonArg,
}

impl SimulateArgs {
    pub fn run(self) -> anyhow::Result<()> {
        let execution = match self.policy {
            PolicyArg::OpenLoop | PolicyArg::Stiffness => Execution::OpenLoop,
            PolicyArg::Feedback => Execution::Feedback,
            PolicyArg::NaiveDelayed => Execution::DelayedFeedback {
                delay_ms: self.delay_ms,
            },
            PolicyArg::Predictor | PolicyArg::StiffnessPredictor => Execution::Predictor {
                delay_ms: self.delay_ms.unwrap_or(0.0),
            },
            PolicyArg::Replan => Execution::Replan {
                delay_ms: self.delay_ms.unwrap_or(0.0),
            },
        };
        run(&SimulateOptions {
            config: self.scenario.config,
            overrides: self.scenario.set.overrides,
            plan: self.plan,
            execution,
            trials: self.trials as usize,
            seed: self.seed.seed,
            divergence: self.divergence,
            csv: self.csv,
            plot: self.plot,
            json: self.json.json,
        })
    }
}
