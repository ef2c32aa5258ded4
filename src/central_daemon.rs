//! `vic-planner`: the central controller as a process. It plays a plan back to the board as
//! command slices at 50 Hz with a strategy (`naive-delayed`: Eq. 13; `predictor`: a Smith
//! predictor over the commands in flight; `stiffness`: the open-loop plan; `stiffness+predictor`), puts
//! delay lines on the state and command paths so that the feedback sees the state the configured
//! latency late, runs the trials live against a `vic-board` (or in lockstep with a board in this
//! process on a simulated clock) and reports their errors.

use crate::cli::{
    Classify, DefaultScenarioArgs, JsonArg, NamespaceArgs, SeedArgs, divergence_or_default,
    input_error, non_negative_seconds, print_json, stop_on_signal, whole_steps,
};
use crate::plan_command::read_plan;
use crate::report::{StrategyResult, Trajectories};
use std::path::PathBuf;
use std::time::Duration;
use vic_plan::plan::{Method, PlanFile, plan, setup};
use vic_plan::scenario::Scenario;
use vic_rt::central::{
    Central, LiveError, Strategy, Timing, TrialRecord, lockstep, run_live, split_latency_ms,
};
use vic_rt::transport::CentralPorts;

/// The central controller: streams a plan's commands to the board at 50 Hz and runs trials.
///
/// Example: vic-planner --config config/two_link_divergent.toml --plan sooc.json --strategy stiffness
#[derive(Debug, Clone, clap::Parser)]
#[command(name = "vic-planner", version, about, long_about)]
#[command(
    mut_arg("config", |a| a.help("Scenario file (TOML) the plan runs on")),
    mut_arg("seed", |a| a.help("Seed of the board's noise (trial i uses the stream of (seed, i))")),
    mut_arg("json", |a| a.help("Print one JSON object")),
)]
pub struct CentralOptions {
    #[command(flatten)]
    pub scenario: DefaultScenarioArgs,
    /// Plan file from `vic plan --out` (default: plan at start-up: SOOC for `stiffness`, ILQG
    /// for the latency for `naive-delayed`, undelayed ILQG for the predictor strategies; no
    /// stiffness for `naive-delayed` and `predictor`).
    #[arg(long, value_name = "FILE")]
    pub plan: Option<PathBuf>,
    /// How the plan is played: `naive-delayed` (the plan's gains on the state seen
    /// --latency-ms late, Eq. 13, no stiffness), `predictor` (the gains on the present state
    /// predicted from the delayed one over the commands in flight, no stiffness), `stiffness`
    /// (the plan's torque and stiffness, no central feedback), `stiffness+predictor` (both) or
    /// `replan` (SOOC re-solved every period from the predicted present, warm-started from the
    /// previous plan; a re-solve takes tens of ms, so at 50 Hz it can overrun on a slow machine).
    #[arg(long, default_value = "stiffness", value_parser = Strategy::from_name)]
    pub strategy: Strategy,
    /// Feedback latency [ms]: knot k feeds back the state of k − latency (default: the plan's
    /// delay; a whole number of plan steps).
    #[arg(long, value_name = "MS")]
    pub latency_ms: Option<f64>,
    /// Delay line on the state path [ms] (default: half of latency − lookahead).
    #[arg(long, value_name = "MS")]
    pub sensor_latency_ms: Option<f64>,
    /// Delay line on the command path [ms] (default: half of latency − lookahead).
    #[arg(long, value_name = "MS")]
    pub command_latency_ms: Option<f64>,
    /// Loop rate [Hz].
    #[arg(long, default_value_t = 50)]
    pub rate_hz: u64,
    /// Number of trials.
    #[arg(long, default_value_t = 5)]
    pub trials: usize,
    #[command(flatten)]
    pub seed: SeedArgs,
    #[command(flatten)]
    pub namespace: NamespaceArgs,
    /// A trial diverged when it ends further than this from the target [mm arm, deg joint].
    #[arg(long, value_name = "DIST")]
    pub divergence: Option<f64>,
    /// Run board and planner in lockstep on a simulated clock in this process (no daemon).
    #[arg(long)]
    pub lockstep: bool,
    /// Seconds to wait for a board before giving up.
    #[arg(long, default_value_t = 5.0)]
    pub board_timeout_s: f64,
    /// Also write the trials' recorded states and commands here (JSON: `x` per trial per knot,
    /// `u` per trial per step), e.g. for a figure.
    #[arg(long, value_name = "FILE")]
    pub trajectories: Option<PathBuf>,
    #[command(flatten)]
    pub json: JsonArg,
    /// Level of the log on stderr: error, warn, info, debug, trace, off, or per target
    /// (vic=debug,warn). Default: RUST_LOG, else info. Nothing is logged inside the 50 Hz loop.
    #[arg(long, value_name = "LEVEL")]
    pub log_level: Option<String>,
}

impl CentralOptions {
    /// How long to wait for a board (`--board-timeout-s`, checked).
    fn board_timeout(&self) -> anyhow::Result<Duration> {
        non_negative_seconds("--board-timeout-s", self.board_timeout_s)
    }
}

/// The delay lines of a run, in ms.
struct Delays {
    sensor: f64,
    command: f64,
}

/// Plays the plan for the trials and prints their summary.
pub fn run(o: &CentralOptions) -> anyhow::Result<()> {
    crate::logging::init(o.log_level.as_deref())?;
    let _log = tracing::info_span!("vic-planner").entered();
    o.board_timeout()?;
    if o.rate_hz == 0 || o.rate_hz > 1000 || o.trials == 0 {
        return Err(input_error("--rate-hz must be 1..1000 and --trials ≥ 1"));
    }
    let namespace = o.namespace.validated()?;
    // The namespace is claimed before planning: a second central process is refused at once
    // (naming the first), not after minutes of planning, and the first is never disturbed.
    let ports = match o.lockstep {
        true => None,
        false => Some(CentralPorts::open(namespace).runtime()?),
    };
    let mut overrides = o.scenario.set.overrides.clone();
    if !o.strategy.uses_stiffness() {
        overrides.push("actuator.stiffness_max=0".into());
    }
    let base = Scenario::load(&o.scenario.config, &overrides).input()?;
    let plan = match &o.plan {
        Some(path) => read_plan(path)?,
        None => plan_at_start(o, &overrides)?,
    };
    let latency_ms = o.latency_ms.unwrap_or(plan.summary.delay_ms);
    let latency_steps = whole_steps("--latency-ms", latency_ms, base.task.dt * 1000.0)?;
    let period_ns = 1_000_000_000 / o.rate_hz;
    let lookahead_ms = 2.0 * period_ns as f64 * 1e-6;
    let delays = delay_lines(o, latency_ms, lookahead_ms)?;
    let setup = setup(&base).input()?;
    let track = crate::launch::track(&plan, &setup).input()?;
    let timing = Timing {
        latency_steps,
        sensor_latency_ns: (delays.sensor * 1e6) as u64,
        command_latency_ns: (delays.command * 1e6) as u64,
        lookahead_ns: (lookahead_ms * 1e6) as u64,
    };
    let mut central = Central::new(track, o.strategy, timing);
    tracing::info!(
        "{} trial(s), strategy {}, latency {latency_ms} ms (sensor {} + command {} + lookahead \
         {lookahead_ms} ms), {}",
        o.trials,
        o.strategy,
        delays.sensor,
        delays.command,
        match o.lockstep {
            true => "in lockstep on a simulated clock".to_string(),
            false => format!("live in namespace \"{namespace}\" at {} Hz", o.rate_hz),
        }
    );
    let (records, lost) = match run_trials(o, ports.as_ref(), &mut central, &setup.x0, period_ns)? {
        Ok(records) => (records, None),
        // The trials before the board was lost are results: print them, then fail.
        Err(e) => (e.records().to_vec(), Some(e)),
    };
    tracing::info!("{} trial(s) finished", records.len());
    if let Some(path) = &o.trajectories {
        let text = serde_json::to_string(&Trajectories::from_records(&records))?;
        std::fs::write(path, text)
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))?;
    }
    let divergence = divergence_or_default(o.divergence, &setup.dynamics.model);
    if !records.is_empty() || lost.is_none() {
        let result = crate::report::summarize(&setup, &central, &records, divergence);
        if o.json.json {
            print_json(&result)?;
        } else {
            print_result(&result, &delays);
        }
    }
    match lost {
        None => Ok(()),
        Some(e) => Err(anyhow::anyhow!(
            "{e} ({} trials finished before, reported above)",
            e.records().len()
        )),
    }
}

/// The trials, live against the board of the namespace or in lockstep with a board in this
/// process (the one the live daemon would run, same limits, at 1 kHz) on a simulated clock.
fn run_trials(
    o: &CentralOptions,
    ports: Option<&CentralPorts>,
    central: &mut Central,
    x0: &[f64],
    period_ns: u64,
) -> anyhow::Result<Result<Vec<TrialRecord>, LiveError>> {
    let Some(ep) = ports.filter(|_| !o.lockstep) else {
        let s = Scenario::load(&o.scenario.config, &o.scenario.set.overrides).input()?;
        let cfg = crate::launch::board_config(&s, 1_000_000);
        let mut board = vic_rt::board::Board::new(s.model.clone(), cfg, x0).input()?;
        return Ok(Ok(lockstep(
            &mut board,
            central,
            1_000_000,
            period_ns,
            o.trials,
            o.seed.seed,
        )));
    };
    let stop = stop_on_signal()?;
    // What arrived while planning is old: the board must answer afresh.
    ep.drain_states(|_| ());
    let _ = ep.latest_telemetry();
    match run_live(
        ep,
        central,
        o.trials,
        o.seed.seed,
        period_ns,
        o.board_timeout()?,
        &stop,
    ) {
        Err(LiveError::Transport(e)) => Err(e).runtime(),
        other => Ok(other),
    }
}

/// Without a plan file: SOOC for `stiffness`, ILQG for the latency for `naive-delayed` (Eq. 13
/// needs the augmented plan's gains), an undelayed ILQG plan for the predictor strategies (zero
/// stiffness for the feedback-only ones, set in `overrides`).
fn plan_at_start(o: &CentralOptions, overrides: &[String]) -> anyhow::Result<PlanFile> {
    let mut overrides = overrides.to_vec();
    let method = match o.strategy {
        Strategy::Stiffness | Strategy::Replan => Method::Sooc,
        Strategy::NaiveDelayed => {
            overrides.push(format!("task.delay_ms={}", o.latency_ms.unwrap_or(0.0)));
            Method::Ilqg
        }
        Strategy::Predictor | Strategy::StiffnessPredictor => {
            overrides.push("task.delay_ms=0".into());
            Method::Ilqg
        }
    };
    let s = Scenario::load(&o.scenario.config, &overrides).input()?;
    tracing::info!("planning ({}) ...", method.name());
    plan(&s, method, None).runtime()
}

/// The sensor and command delay lines (by default the latency less the lookahead, split in
/// halves); warns when they exceed the latency the feedback was planned for.
fn delay_lines(o: &CentralOptions, latency_ms: f64, lookahead_ms: f64) -> anyhow::Result<Delays> {
    let (ds, dc) = split_latency_ms(latency_ms, lookahead_ms);
    let sensor = o.sensor_latency_ms.unwrap_or(ds);
    let command = o.command_latency_ms.unwrap_or(dc);
    if !(sensor >= 0.0 && command >= 0.0 && sensor.is_finite() && command.is_finite()) {
        return Err(input_error("latencies must be finite and ≥ 0"));
    }
    // (At 0 ms every knot uses the freshest state: stale by design, no warning.)
    if o.strategy != Strategy::Stiffness
        && latency_ms > 0.0
        && sensor + command + lookahead_ms > latency_ms + 1e-9
    {
        tracing::warn!(
            "sensor {sensor} ms + command {command} ms + lookahead \
             {lookahead_ms} ms exceed the feedback latency {latency_ms} ms: feedback will use \
             older states (counted as stale)"
        );
    }
    Ok(Delays { sensor, command })
}

/// A distance as printed in the tables: "diverged" when no trial completed.
pub fn distance_text(v: Option<f64>) -> String {
    v.map_or_else(|| "diverged".to_string(), |v| format!("{v:.2}"))
}

fn print_result(result: &StrategyResult, delays: &Delays) {
    let u = &result.unit;
    let f = distance_text;
    println!(
        "{} ({} trials, latency {} ms = sensor {} + command {} + lookahead)",
        result.name, result.trials, result.latency_ms, delays.sensor, delays.command
    );
    println!(
        "errors   RMS {} {u}, final mean {} / max {} {u}, max {} {u} (trials that completed)",
        f(result.rms_error),
        f(result.final_error_mean),
        f(result.final_error_max),
        f(result.max_error)
    );
    println!(
        "diverged {} of {}; safe hold in {}, fault in {}, stalled {} trials; {} stale feedback \
         knots, {} off-knot states, {} late knots",
        result.diverged,
        result.trials,
        result.safe_hold_trials,
        result.fault_trials,
        result.stalled_trials,
        result.stale_feedback,
        result.off_knot_states,
        result.late_knots
    );
    let c = &result.central;
    println!(
        "central  compute per period p50 {:.1} / p99 {:.1} / max {:.1} µs ({} periods), {} overruns \
         of the {:.0} µs budget (the previous slice sent again)",
        c.compute_us.p50,
        c.compute_us.p99,
        c.compute_us.max,
        c.compute_us.count,
        c.overruns,
        c.budget_us
    );
}

#[cfg(test)]
mod flags {
    /// clap's own consistency checks (every `mut_arg` names an argument that exists, no two
    /// flags clash), which it otherwise runs only when a command is parsed.
    #[test]
    fn are_consistent() {
        use clap::CommandFactory;
        super::CentralOptions::command().debug_assert();
    }
}
