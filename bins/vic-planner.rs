//! `vic-planner`: the central controller. A 50 Hz loop that plays a plan back to `vic-board` as
//! command slices, with a strategy (`stiffness`, `delayed-feedback`, `both`) and delay lines on the
//! state and command paths; runs N trials and prints their errors.

use clap::{Parser, ValueEnum};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use vic::planning::plan::{Method, PlanFile};
use vic::planning::scenario::Scenario;
use vic::rt::central::{Central, Strategy, Timing, lockstep, run_live, split_latency_ms};
use vic::rt::transport::{DEFAULT_NAMESPACE, Endpoint, Role};

#[derive(Clone, Copy, ValueEnum)]
enum StrategyArg {
    /// The SOOC plan's torque and stiffness, no central feedback.
    Stiffness,
    /// Zero stiffness, the ILQG plan plus its gains on the state seen --latency-ms late (Eq. 13).
    DelayedFeedback,
    /// The plan's torque and stiffness plus the delayed feedback.
    Both,
}

/// The central controller: streams a plan's commands to the board at 50 Hz and runs trials.
///
/// Example: vic-planner --config config/two_link_divergent.toml --plan sooc.json --strategy stiffness
#[derive(Parser)]
#[command(name = "vic-planner", version, about, long_about)]
struct Args {
    /// Scenario file (TOML) the plan runs on.
    #[arg(
        long,
        short,
        value_name = "FILE",
        default_value = "config/two_link_divergent.toml"
    )]
    config: PathBuf,
    /// Override a configuration key (repeatable).
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    overrides: Vec<String>,
    /// Plan file from `vic plan --out` (default: plan at start-up: SOOC for `stiffness`, ILQG
    /// for the latency otherwise, with zero stiffness for `delayed-feedback`).
    #[arg(long, value_name = "FILE")]
    plan: Option<PathBuf>,
    #[arg(long, value_enum, default_value = "stiffness")]
    strategy: StrategyArg,
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
    /// Seed of the board's noise (trial i uses the stream of (seed, i)).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Namespace of the services.
    #[arg(long, default_value = DEFAULT_NAMESPACE)]
    namespace: String,
    /// A trial diverged when it ends further than this from the target [mm arm, deg joint].
    #[arg(long, value_name = "DIST")]
    divergence: Option<f64>,
    /// Run board and planner in lockstep on a simulated clock in this process (no daemon).
    #[arg(long)]
    lockstep: bool,
    /// Seconds to wait for a board before giving up.
    #[arg(long, default_value_t = 5.0)]
    board_timeout_s: f64,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

fn main() -> ExitCode {
    match run(Args::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err((code, message)) => {
            eprintln!("vic-planner: error: {message}");
            ExitCode::from(code)
        }
    }
}

fn run(args: Args) -> Result<(), (u8, String)> {
    let input = |m: String| (2u8, m);
    if args.rate_hz == 0 || args.rate_hz > 1000 || args.trials == 0 {
        return Err(input("--rate-hz must be 1..1000 and --trials ≥ 1".into()));
    }
    vic::rt::transport::validate_namespace(&args.namespace).map_err(input)?;
    let strategy = match args.strategy {
        StrategyArg::Stiffness => Strategy::Stiffness,
        StrategyArg::DelayedFeedback => Strategy::DelayedFeedback,
        StrategyArg::Both => Strategy::Both,
    };
    let mut overrides = args.overrides.clone();
    if strategy == Strategy::DelayedFeedback {
        overrides.push("actuator.stiffness_max=0".into());
    }
    let base = Scenario::load(&args.config, &overrides).map_err(|e| input(e.to_string()))?;
    let dt_ms = base.task.dt * 1000.0;
    let plan: PlanFile = match &args.plan {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|e| input(format!("{}: cannot read: {e}", path.display())))?;
            serde_json::from_str(&text)
                .map_err(|e| input(format!("{}: not a plan file: {e}", path.display())))?
        }
        None => {
            let mut o = overrides.clone();
            let method = if strategy == Strategy::Stiffness {
                Method::Sooc
            } else {
                o.push(format!("task.delay_ms={}", args.latency_ms.unwrap_or(0.0)));
                Method::Ilqg
            };
            let s = Scenario::load(&args.config, &o).map_err(|e| input(e.to_string()))?;
            eprintln!("vic-planner: planning ({}) ...", method.name());
            vic::planning::plan::plan(&s, method, None).map_err(|e| (1, e))?
        }
    };
    let latency_ms = args.latency_ms.unwrap_or(plan.summary.delay_ms);
    let steps = latency_ms / dt_ms;
    if !(steps >= 0.0 && (steps - steps.round()).abs() < 1e-6) {
        return Err(input(format!(
            "--latency-ms {latency_ms}: not a whole number of {dt_ms} ms plan steps"
        )));
    }
    let period_ns = 1_000_000_000 / args.rate_hz;
    let lookahead_ms = 2.0 * period_ns as f64 * 1e-6;
    let (ds, dc) = split_latency_ms(latency_ms, lookahead_ms);
    let sensor = args.sensor_latency_ms.unwrap_or(ds);
    let command = args.command_latency_ms.unwrap_or(dc);
    if !(sensor >= 0.0 && command >= 0.0 && sensor.is_finite() && command.is_finite()) {
        return Err(input("latencies must be finite and ≥ 0".into()));
    }
    // (At 0 ms every knot uses the freshest state: stale by design, no warning.)
    if strategy != Strategy::Stiffness
        && latency_ms > 0.0
        && sensor + command + lookahead_ms > latency_ms + 1e-9
    {
        eprintln!(
            "vic-planner: warning: sensor {sensor} ms + command {command} ms + lookahead \
             {lookahead_ms} ms exceed the feedback latency {latency_ms} ms: feedback will use \
             older states (counted as stale)"
        );
    }
    let setup = vic::planning::plan::setup(&base).map_err(input)?;
    let track = vic::tools::launch::track(&plan, &setup).map_err(input)?;
    let timing = Timing {
        latency_steps: steps.round() as usize,
        sensor_latency_ns: (sensor * 1e6) as u64,
        command_latency_ns: (command * 1e6) as u64,
        lookahead_ns: (lookahead_ms * 1e6) as u64,
    };
    let mut central = Central::new(track, strategy, timing);
    let records = if args.lockstep {
        let s = Scenario::load(&args.config, &args.overrides).map_err(|e| input(e.to_string()))?;
        // The board the live daemon would run (same limits), at 1 kHz.
        let cfg = vic::tools::launch::board_config(&s, 1_000_000);
        let mut board =
            vic::rt::board::Board::new(s.model.clone(), cfg, &setup.x0).map_err(input)?;
        lockstep(
            &mut board,
            &mut central,
            1_000_000,
            period_ns,
            args.trials,
            args.seed,
        )
    } else {
        let stop = Arc::new(AtomicBool::new(false));
        {
            let stop = stop.clone();
            ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
                .map_err(|e| (1, format!("cannot install the signal handler: {e}")))?;
        }
        let ep = Endpoint::open(&args.namespace, Role::Planner).map_err(|e| (1, e.to_string()))?;
        run_live(
            &ep,
            &mut central,
            args.trials,
            args.seed,
            period_ns,
            std::time::Duration::from_secs_f64(args.board_timeout_s),
            &stop,
        )
        .map_err(|e| (1, e))?
    };
    let divergence = args
        .divergence
        .unwrap_or(if setup.dynamics.model.dof() == 1 {
            10.0
        } else {
            50.0
        });
    let result = vic::tools::report::summarize(&setup, &central, &records, divergence);
    if args.json {
        println!(
            "{}",
            serde_json::to_string(&result).map_err(|e| (1, e.to_string()))?
        );
    } else {
        let u = &result.unit;
        let f = |v: f64| {
            if v >= 1e9 {
                "diverged".to_string()
            } else {
                format!("{v:.2}")
            }
        };
        println!(
            "{} ({} trials, latency {} ms = sensor {} + command {} + lookahead)",
            result.name, result.trials, result.latency_ms, sensor, command
        );
        println!(
            "errors   RMS {} {u}, final mean {} / max {} {u}, max {} {u}",
            f(result.rms_error),
            f(result.final_error_mean),
            f(result.final_error_max),
            f(result.max_error)
        );
        println!(
            "diverged {} of {}; safe hold in {} trials; {} stale feedback knots",
            result.diverged, result.trials, result.safe_hold_trials, result.stale_feedback
        );
    }
    Ok(())
}
