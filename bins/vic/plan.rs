//! `vic plan`: flags, then [`vic::plan_command::run`].

use clap::ValueEnum;
use std::path::PathBuf;
use vic::cli::{JsonArg, ScenarioArgs};
use vic::plan_command::{PlanOptions, run};

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    /// Iterative LQG: a nominal plan with locally optimal feedback gains (Todorov & Li 2005),
    /// made for the scenario's feedback delay.
    Ilqg,
    /// Stochastic optimal open-loop control: torque and stiffness for execution without any
    /// feedback, optimal for the open-loop plant's mean and covariance (Berret & Jean 2020).
    Sooc,
    /// The same open-loop problem by a method that scales: the exact gradient by the covariance
    /// adjoint and a model on the mean alone (zero-order robust optimisation in spirit).
    SoocFast,
}

#[derive(clap::Args)]
#[command(mut_arg("json", |a| a.help("Print one JSON object with the summary instead of the readable report")))]
pub struct PlanArgs {
    #[command(flatten)]
    scenario: ScenarioArgs,
    /// Planning method (default: the scenario's [solver] method, else ilqg).
    #[arg(long, value_enum)]
    method: Option<MethodArg>,
    /// Feedback latency of the central controller the plan is made for [ms] (a whole number of
    /// time steps); instead of task.delay_ms.
    #[arg(long, value_name = "MS", alias = "delay-ms")]
    latency_ms: Option<f64>,
    /// Write the plan (time grid, controls, states, gains, resolved config) to this JSON file.
    #[arg(long, short, value_name = "FILE")]
    out: Option<PathBuf>,
    #[command(flatten)]
    json: JsonArg,
}

impl PlanArgs {
    pub fn run(self) -> anyhow::Result<()> {
        use vic_plan::plan::Method;
        run(&PlanOptions {
            config: self.scenario.config,
            overrides: self.scenario.set.overrides,
            method: self.method.map(|m| match m {
                MethodArg::Ilqg => Method::Ilqg,
                MethodArg::Sooc => Method::Sooc,
                MethodArg::SoocFast => Method::SoocFast,
            }),
            latency_ms: self.latency_ms,
            out: self.out,
            json: self.json.json,
        })
    }
}
