//! `vic demo`: flags, then [`vic::tools::demo::run`].

use std::path::PathBuf;
use vic::tools::cli::{DefaultScenarioArgs, JsonArg, SeedArgs};
use vic::tools::demo::{DemoOptions, run};

#[derive(clap::Args)]
#[command(
    mut_arg("config", |a| a.help(
        "Scenario file (TOML): a two-link or single-joint plant with the impedance actuator"
    )),
    mut_arg("overrides", |a| a.help(
        "Override a configuration key (repeatable), for the plans and the board alike"
    )),
    mut_arg("seed", |a| a.help("Seed of the board's noise (the same for every strategy)")),
    mut_arg("json", |a| a.help("Print one JSON object instead of the table")),
)]
pub struct DemoArgs {
    #[command(flatten)]
    scenario: DefaultScenarioArgs,
    /// Feedback latency of the central controller [ms] (a whole number of plan steps).
    #[arg(long, default_value_t = 200.0)]
    latency_ms: f64,
    /// Trials per strategy.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u64).range(1..))]
    trials: u64,
    #[command(flatten)]
    seed: SeedArgs,
    /// Keep the plans in this folder and reuse them on the next run (default: plan afresh).
    #[arg(long, value_name = "DIR")]
    plans_dir: Option<PathBuf>,
    /// Use this plan for the `stiffness` strategy instead of planning (SOOC, `vic plan --out`).
    #[arg(long, value_name = "FILE")]
    stiffness_plan: Option<PathBuf>,
    /// Use this plan for `delayed-feedback` instead of planning (ILQG for the latency, zero
    /// stiffness).
    #[arg(long, value_name = "FILE")]
    feedback_plan: Option<PathBuf>,
    /// Board spin before each deadline [µs] (default: the board's, 100; 0 with --no-rt).
    #[arg(long, value_name = "US")]
    spin_us: Option<u64>,
    /// Run the board without its real-time settings (no SCHED_FIFO, pinning or spin).
    #[arg(long)]
    no_rt: bool,
    #[command(flatten)]
    json: JsonArg,
}

impl DemoArgs {
    pub fn run(self) -> anyhow::Result<()> {
        run(&DemoOptions {
            config: self.scenario.config,
            overrides: self.scenario.set.overrides,
            latency_ms: self.latency_ms,
            trials: self.trials,
            seed: self.seed.seed,
            plans_dir: self.plans_dir,
            stiffness_plan: self.stiffness_plan,
            feedback_plan: self.feedback_plan,
            spin_us: self.spin_us,
            no_rt: self.no_rt,
            json: self.json.json,
        })
    }
}
