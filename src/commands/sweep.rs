//! `vic sweep latency`: the final error, divergence and cost against the feedback latency per
//! strategy ([`crate::studies::sweep`]), as a table or JSON, and the figure in `--out-dir`.

use crate::cli::{Classify, JsonArg, ScenarioArgs, SeedArgs};
use crate::progress::Progress;
use crate::studies::sweep::{
    Engine, Strategy, SweepError, SweepOptions, pulse_from_flags, sweep_latency,
    sweep_stiffness_lag, write_lag_outputs, write_outputs,
};
use std::path::PathBuf;

/// The user's input at fault (scenario, overrides, latencies): exit 2; else the run's: exit 1.
fn classify(e: SweepError) -> anyhow::Error {
    match e.is_input() {
        true => crate::cli::input_error(e),
        false => anyhow::Error::new(e),
    }
}

#[derive(clap::Args)]
pub(crate) struct Args {
    #[command(subcommand)]
    what: SweepWhat,
}

#[derive(clap::Subcommand)]
enum SweepWhat {
    /// Final error against the feedback latency, per strategy (Monte Carlo, offline; or the
    /// board and the central controller in lockstep; or the live daemons).
    ///
    /// Example: vic sweep latency --config config/single_joint_delay.toml --latencies 0,50,200
    /// --out-dir sweep
    Latency(LatencyArgs),
    /// The stiffness mechanism's lag: for each time constant τ_K of a first-order stiffness
    /// (0: the ideal actuator) the stiffness the SOOC plan realises and the latency up to which
    /// the predictor beats the planned stiffness (offline Monte Carlo).
    ///
    /// Example: vic sweep stiffness-lag --config config/two_link_divergent.toml
    /// --time-constants 0,0.1,0.2,0.3,0.5 --out-dir docs/figures
    StiffnessLag(LagArgs),
}

#[derive(clap::Args)]
struct LagArgs {
    /// An impedance scenario (ideal stiffness; the study sets the lag).
    #[command(flatten)]
    scenario: ScenarioArgs,
    /// Time constants τ_K [s] of the stiffness mechanism; 0 is the ideal actuator.
    /// [range: 0 to 10]
    #[arg(long, value_delimiter = ',', default_value = "0,0.05,0.1,0.2,0.3,0.5",
          value_parser = crate::ranges::real(0.0, 10.0))]
    time_constants: Vec<f64>,
    /// Feedback latencies [ms] of each crossing's sweep. [range: 0 to 1000]
    #[arg(long, value_delimiter = ',', default_value = "0,20,50,100,150,200,300",
          value_parser = crate::ranges::real(0.0, crate::ranges::MAX_LATENCY_MS))]
    latencies: Vec<f64>,
    /// Monte Carlo trials per point. [range: 2 to 100000]
    #[arg(long, default_value_t = 20, value_parser = crate::ranges::trials(2, "a spread needs two"))]
    trials: u64,
    #[command(flatten)]
    seed: SeedArgs,
    /// Write the figure (stiffness_lag.png, .svg) and the numbers (stiffness_lag.json) here.
    #[arg(long, value_name = "DIR")]
    out_dir: Option<PathBuf>,
    #[command(flatten)]
    json: JsonArg,
}

fn run_lag(a: LagArgs) -> anyhow::Result<()> {
    let opts = SweepOptions {
        latencies_ms: a.latencies,
        strategies: Vec::new(),
        trials: a.trials as usize,
        seed: a.seed.seed,
        divergence: None,
        pulse: None,
        execution: Engine::Offline,
    };
    let n = a.time_constants.len();
    let progress = Progress::steps("stiffness lag", n as u64);
    let done = std::cell::Cell::new(0);
    let sweep = sweep_stiffness_lag(
        &a.scenario.config,
        &a.scenario.set.overrides,
        &a.time_constants,
        &opts,
        &|p| {
            progress.step(done.get(), n, p);
            done.set(done.get() + 1);
        },
    )
    .map_err(classify)?;
    drop(progress);
    if let Some(dir) = &a.out_dir {
        write_lag_outputs(&sweep, dir)?;
    }
    if a.json.json {
        println!("{}", serde_json::to_string(&sweep)?);
    } else {
        print!("{}", sweep.table());
    }
    Ok(())
}

#[derive(clap::Args)]
struct LatencyArgs {
    #[command(flatten)]
    scenario: ScenarioArgs,
    /// Feedback latencies [ms], each a whole number of the scenario's plan steps.
    /// [range: 0 to 1000]
    #[arg(long, value_delimiter = ',', default_value = "0,20,50,100,150,200,300",
          value_parser = crate::ranges::real(0.0, crate::ranges::MAX_LATENCY_MS))]
    latencies: Vec<f64>,
    /// Strategies: naive-delayed (Eq. 13, planned for the latency, no stiffness), predictor
    /// (a Smith predictor across the latency, no stiffness), stiffness (the open-loop SOOC plan),
    /// stiffness+predictor, replan (the SOOC plan re-solved every 20 ms from the predicted
    /// present; slow: seconds per trial on the arm).
    #[arg(long, value_delimiter = ',', value_parser = Strategy::from_name,
          default_value = "naive-delayed,predictor,stiffness")]
    strategies: Vec<Strategy>,
    /// Monte Carlo trials per point. [range: 2 to 100000]
    #[arg(long, default_value_t = 20, value_parser = crate::ranges::trials(2, "a spread needs two"))]
    trials: u64,
    #[command(flatten)]
    seed: SeedArgs,
    /// A trial has diverged when it ends further than this from the target [mm for the arm,
    /// degrees for a single joint] (default 50 mm / 10°). [range: 0.001 to 100000]
    #[arg(long, value_name = "DIST", value_parser = crate::ranges::real(0.001, crate::ranges::MAX_DIVERGENCE))]
    divergence: Option<f64>,
    /// Disturbance rejection: a torque pulse of this size [N m] on the first joint (or
    /// `T1,T2` per joint) in every trial of every strategy, unknown to the controllers.
    /// [range: -200 to 200]
    #[arg(long, value_name = "TORQUE", value_delimiter = ',', num_args = 1..=2,
          allow_negative_numbers = true,
          value_parser = crate::ranges::real(-crate::ranges::MAX_TORQUE_NM, crate::ranges::MAX_TORQUE_NM))]
    pulse: Vec<f64>,
    /// When the pulse starts [ms after the movement's start]. [range: 0 to 60000]
    #[arg(long, value_name = "MS", default_value_t = 400.0, value_parser = crate::ranges::real(0.0, 60_000.0))]
    pulse_at_ms: f64,
    /// How long the pulse lasts [ms]. [range: 0.001 to 10000]
    #[arg(long, value_name = "MS", default_value_t = 50.0,
          value_parser = crate::ranges::real(0.001, crate::ranges::MAX_PULSE_MS))]
    pulse_ms: f64,
    /// Run each point's trials through the real-time code instead of the Monte Carlo: the 1 kHz
    /// board (its own plant integration) and the central controller (the latency in its delay
    /// lines; 50 Hz, or 100 or 250 Hz below 60 ms so that its own delay fits in the latency) in
    /// lockstep on a simulated clock. Deterministic; no pulse.
    #[arg(long, conflicts_with = "live")]
    lockstep: bool,
    /// Run each point's trials on the live daemons, as `vic demo` does: one `vic-board` in real
    /// time for the whole sweep and a `vic-planner` per point over shared memory (about the
    /// movement's duration per trial; no pulse).
    #[arg(long)]
    live: bool,
    /// Write the figure (sweep.png, sweep.svg) and the numbers (sweep.json) into this folder.
    #[arg(long, value_name = "DIR")]
    out_dir: Option<PathBuf>,
    #[command(flatten)]
    json: JsonArg,
}

pub(crate) fn run(args: Args) -> anyhow::Result<()> {
    let a = match args.what {
        SweepWhat::Latency(a) => a,
        SweepWhat::StiffnessLag(a) => return run_lag(a),
    };
    let pulse = pulse_from_flags(&a.pulse, a.pulse_at_ms, a.pulse_ms).input()?;
    let opts = SweepOptions {
        latencies_ms: a.latencies,
        strategies: a.strategies,
        trials: a.trials as usize,
        seed: a.seed.seed,
        divergence: a.divergence,
        pulse,
        execution: match (a.lockstep, a.live) {
            (true, _) => Engine::Lockstep,
            (_, true) => Engine::Live,
            _ => Engine::Offline,
        },
    };
    // A bar over the points on a terminal (nothing in pipes and scripts).
    let points = opts.strategies.len() * opts.latencies_ms.len();
    let progress = Progress::steps("sweep", points as u64);
    let done = std::cell::Cell::new(0);
    let sweep = sweep_latency(&a.scenario.config, &a.scenario.set.overrides, &opts, &|p| {
        progress.step(done.get(), points, p);
        done.set(done.get() + 1);
    })
    .map_err(classify)?;
    drop(progress);
    if let Some(dir) = &a.out_dir {
        write_outputs(&sweep, dir)?;
    }
    if a.json.json {
        println!("{}", serde_json::to_string(&sweep)?);
        return Ok(());
    }
    print!("{}", sweep.table());
    for c in &sweep.crossings {
        println!("crossing: {}", c.sentence());
    }
    for note in sweep.schedule_notes() {
        println!("note: {note}");
    }
    Ok(())
}
