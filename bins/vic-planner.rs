//! `vic-planner`: the central controller. A 50 Hz loop that plays a plan back to `vic-board` as
//! command slices, with a strategy (`naive-delayed`, `predictor`, `stiffness`,
//! `stiffness+predictor`) and delay lines on the
//! state and command paths; runs N trials and prints their errors. The flags are parsed here;
//! [`vic::tools::central_daemon::run`] does the rest.

use clap::Parser;
use std::path::PathBuf;
use std::process::ExitCode;
use vic::rt::central::Strategy;
use vic::tools::central_daemon::{CentralOptions, run};
use vic::tools::cli::{DefaultScenarioArgs, JsonArg, NamespaceArgs, SeedArgs, finish};

/// The central controller: streams a plan's commands to the board at 50 Hz and runs trials.
///
/// Example: vic-planner --config config/two_link_divergent.toml --plan sooc.json --strategy stiffness
#[derive(Parser)]
#[command(name = "vic-planner", version, about, long_about)]
#[command(
    mut_arg("config", |a| a.help("Scenario file (TOML) the plan runs on")),
    mut_arg("seed", |a| a.help("Seed of the board's noise (trial i uses the stream of (seed, i))")),
    mut_arg("json", |a| a.help("Print one JSON object")),
)]
struct Args {
    #[command(flatten)]
    scenario: DefaultScenarioArgs,
    /// Plan file from `vic plan --out` (default: plan at start-up: SOOC for `stiffness`, ILQG
    /// for the latency for `naive-delayed`, undelayed ILQG for the predictor strategies; no
    /// stiffness for `naive-delayed` and `predictor`).
    #[arg(long, value_name = "FILE")]
    plan: Option<PathBuf>,
    /// How the plan is played: `naive-delayed` (the plan's gains on the state seen
    /// --latency-ms late, Eq. 13, no stiffness), `predictor` (the gains on the present state
    /// predicted from the delayed one over the commands in flight, no stiffness), `stiffness`
    /// (the plan's torque and stiffness, no central feedback), `stiffness+predictor` (both) or
    /// `replan` (SOOC re-solved every period from the predicted present, warm-started from the
    /// previous plan; a re-solve takes tens of ms, so at 50 Hz it can overrun on a slow machine).
    #[arg(long, default_value = "stiffness", value_parser = Strategy::from_name)]
    strategy: Strategy,
    /// Feedback latency [ms]: knot k feeds back the state of k − latency (default: the plan's
    /// delay; a whole number of plan steps).
    #[arg(long, value_name = "MS")]
    latency_ms: Option<f64>,
    /// Delay line on the state path [ms] (default: half of latency − lookahead).
    #[arg(long, value_name = "MS")]
    sensor_latency_ms: Option<f64>,
    /// Delay line on the command path [ms] (default: half of latency − lookahead).
    #[arg(long, value_name = "MS")]
    command_latency_ms: Option<f64>,
    /// Loop rate [Hz].
    #[arg(long, default_value_t = 50)]
    rate_hz: u64,
    /// Number of trials.
    #[arg(long, default_value_t = 5)]
    trials: usize,
    #[command(flatten)]
    seed: SeedArgs,
    #[command(flatten)]
    namespace: NamespaceArgs,
    /// A trial diverged when it ends further than this from the target [mm arm, deg joint].
    #[arg(long, value_name = "DIST")]
    divergence: Option<f64>,
    /// Run board and planner in lockstep on a simulated clock in this process (no daemon).
    #[arg(long)]
    lockstep: bool,
    /// Seconds to wait for a board before giving up.
    #[arg(long, default_value_t = 5.0)]
    board_timeout_s: f64,
    /// Also write the trials' recorded states and commands here (JSON: `x` per trial per knot,
    /// `u` per trial per step), e.g. for a figure.
    #[arg(long, value_name = "FILE")]
    trajectories: Option<PathBuf>,
    #[command(flatten)]
    json: JsonArg,
}

fn run_args(a: Args) -> anyhow::Result<()> {
    let board_timeout =
        vic::tools::cli::non_negative_seconds("--board-timeout-s", a.board_timeout_s)?;
    run(&CentralOptions {
        config: a.scenario.config,
        overrides: a.scenario.set.overrides,
        plan: a.plan,
        strategy: a.strategy,
        latency_ms: a.latency_ms,
        sensor_latency_ms: a.sensor_latency_ms,
        command_latency_ms: a.command_latency_ms,
        rate_hz: a.rate_hz,
        trials: a.trials,
        seed: a.seed.seed,
        namespace: a.namespace.namespace,
        divergence: a.divergence,
        lockstep: a.lockstep,
        board_timeout,
        trajectories: a.trajectories,
        json: a.json.json,
    })
}

fn main() -> ExitCode {
    finish("vic-planner", run_args(Args::parse()))
}

#[cfg(test)]
mod tests {
    /// clap's own consistency checks (every `mut_arg` names an argument that exists, no two
    /// flags clash), which it otherwise runs only when a command is parsed.
    #[test]
    fn flags_are_consistent() {
        use clap::CommandFactory;
        super::Args::command().debug_assert();
    }
}
