//! `vic-planner`: the central controller as a process. It plays a plan back to the board as
//! command slices at 50 Hz with a strategy (`naive-delayed`: Eq. 13; `predictor`: a Smith
//! predictor over the commands in flight; `stiffness`: the open-loop plan; `stiffness+predictor`), puts
//! delay lines on the state and command paths so that the feedback sees the state the configured
//! latency late, runs the trials live against a `vic-board` (or in lockstep with a board in this
//! process on a simulated clock) and reports their errors.

use crate::cli::{
    Classify, DefaultScenarioArgs, JsonArg, NamespaceArgs, SeedArgs, divergence_or_default,
    input_error, latency_arg, print_json, stop_on_signal,
};
use crate::ranges::{MAX_DIVERGENCE, MAX_LATENCY_MS, MAX_TRIALS, MAX_WAIT_S, real, seconds, whole};
use crate::views::report::{StrategyResult, Trajectories};
use std::path::PathBuf;
use std::time::Duration;
use vic_plan::plan::{PlanFile, setup};
use vic_plan::scenario::Scenario;
use vic_plan::strategy::{Latency, Strategy, StrategyPlan};
use vic_rt::central::{Central, DelayLines, LiveError, Timing, TrialRecord, lockstep, run_live};
use vic_rt::transport::CentralPorts;

/// The central controller: streams a plan's commands to the board at 50 Hz and runs trials.
///
/// Example: vic-planner --config config/two_link_divergent.toml --plan sooc.json --strategy stiffness
#[derive(Debug, Clone, clap::Parser)]
#[command(name = "vic-planner", version, about, long_about)]
#[command(
    mut_arg("config", |a| a.help("Scenario file (TOML) the plan runs on")),
    mut_arg("seed", |a| a.help("Seed of the board's noise (trial i uses the stream of (seed, i)) [range: 0 to 18446744073709551615]")),
    mut_arg("json", |a| a.help("Print one JSON object")),
)]
pub struct CentralOptions {
    #[command(flatten)]
    pub(crate) scenario: DefaultScenarioArgs,
    /// Plan file from `vic plan --out` (default: plan at start-up: SOOC for `stiffness`, ILQG
    /// for the latency for `naive-delayed`, undelayed ILQG for the predictor strategies; no
    /// stiffness for `naive-delayed` and `predictor`).
    #[arg(long, value_name = "FILE")]
    pub(crate) plan: Option<PathBuf>,
    /// How the plan is played: `naive-delayed` (the plan's gains on the state seen
    /// --latency-ms late, Eq. 13, no stiffness), `predictor` (the gains on the present state
    /// predicted from the delayed one over the commands in flight, no stiffness), `stiffness`
    /// (the plan's torque and stiffness, no central feedback), `stiffness+predictor` (both) or
    /// `replan` (SOOC re-solved every period from the predicted present, warm-started from the
    /// previous plan; a re-solve takes tens of ms, so at 50 Hz it can overrun on a slow machine).
    #[arg(long, default_value = "stiffness", value_parser = Strategy::from_name)]
    pub(crate) strategy: Strategy,
    /// Feedback latency [ms]: knot k feeds back the state of k − latency (default: the plan's
    /// delay; a whole number of plan steps). [range: 0 to 1000]
    #[arg(long, value_name = "MS", value_parser = real(0.0, MAX_LATENCY_MS))]
    pub(crate) latency_ms: Option<f64>,
    /// Delay line on the state path [ms] (default: half of latency − lookahead).
    /// [range: 0 to 1000]
    #[arg(long, value_name = "MS", value_parser = real(0.0, MAX_LATENCY_MS))]
    pub(crate) sensor_latency_ms: Option<f64>,
    /// Delay line on the command path [ms] (default: half of latency − lookahead).
    /// [range: 0 to 1000]
    #[arg(long, value_name = "MS", value_parser = real(0.0, MAX_LATENCY_MS))]
    pub(crate) command_latency_ms: Option<f64>,
    /// Loop rate [Hz] (default: the slowest of 50, 100 and 250 Hz whose own delay, three
    /// periods from computing a knot to its action, fits in the latency, so that the strategy
    /// executes as the offline Monte Carlo does; 50 Hz for `stiffness` and `replan`).
    /// [range: 1 to 1000]
    #[arg(long, value_parser = whole(1u64, 1000))]
    pub(crate) rate_hz: Option<u64>,
    /// Number of trials. [range: 1 to 100000]
    #[arg(long, default_value_t = 5, value_parser = whole(1usize, MAX_TRIALS as usize))]
    pub(crate) trials: usize,
    #[command(flatten)]
    pub(crate) seed: SeedArgs,
    #[command(flatten)]
    pub(crate) namespace: NamespaceArgs,
    /// A trial diverged when it ends further than this from the target [mm arm, deg joint].
    /// [range: 0.001 to 100000]
    #[arg(long, value_name = "DIST", value_parser = real(0.001, MAX_DIVERGENCE))]
    pub(crate) divergence: Option<f64>,
    /// Run board and planner in lockstep on a simulated clock in this process (no daemon).
    #[arg(long)]
    pub(crate) lockstep: bool,
    /// Seconds to wait for a board before giving up. [range: 0 to 3600]
    #[arg(long, default_value_t = 5.0, value_parser = real(0.0, MAX_WAIT_S))]
    pub(crate) board_timeout_s: f64,
    /// Also write the trials' recorded states and commands here (JSON: `x` per trial per knot,
    /// `u` per trial per step), e.g. for a figure.
    #[arg(long, value_name = "FILE")]
    pub(crate) trajectories: Option<PathBuf>,
    #[command(flatten)]
    pub(crate) json: JsonArg,
    /// Level of the log on stderr: error, warn, info, debug, trace, off, or per target
    /// (vic=debug,warn). Default: RUST_LOG, else info. Nothing is logged inside the 50 Hz loop.
    #[arg(long, value_name = "LEVEL")]
    pub(crate) log_level: Option<String>,
}

impl CentralOptions {
    /// How long to wait for a board (`--board-timeout-s`, checked).
    fn board_timeout(&self) -> Duration {
        seconds(self.board_timeout_s)
    }
}

/// Plays the plan for the trials and prints their summary.
pub fn run(o: &CentralOptions) -> anyhow::Result<()> {
    crate::daemons::logging::init(o.log_level.as_deref())?;
    let _log = tracing::info_span!("vic-planner").entered();
    let namespace = o.namespace.validated()?;
    // The namespace is claimed before planning: a second central process is refused at once
    // (naming the first), not after minutes of planning, and the first is never disturbed.
    let ports = match o.lockstep {
        true => None,
        false => Some(CentralPorts::open(namespace).runtime()?),
    };
    let user = Scenario::load(&o.scenario.config, &o.scenario.set.overrides).input()?;
    let given = o.latency_ms;
    let given = given.map(|ms| latency_arg("--latency-ms", ms, user.task.dt));
    let given = given.transpose()?;
    // Without a plan file: the plan the strategy asks for at the latency given (SOOC for the
    // stiffness strategies, ILQG for the latency for `naive-delayed`, an undelayed ILQG plan for
    // the predictors, no stiffness for the feedback-only ones).
    let request = o.strategy.plan_request(given.unwrap_or(Latency::ZERO));
    let plan = match &o.plan {
        Some(path) => PlanFile::read(path).input()?,
        None => {
            tracing::info!("planning ({}) ...", request.method.name());
            request.plan(&user, None).runtime()?
        }
    };
    // The scenario the plan is played on: the feedback-only strategies command no stiffness.
    let base = request.scenario(&user);
    let latency = match given {
        Some(l) => l,
        None => latency_arg("the plan's delay", plan.summary.delay_ms, base.task.dt)?,
    };
    let rate_hz = o
        .rate_hz
        .unwrap_or_else(|| Timing::planner_rate_hz(o.strategy, latency));
    let period_ns = 1_000_000_000 / rate_hz;
    let lookahead_ms = Timing::lookahead_ms(period_ns);
    let lines = delay_lines(o, latency, period_ns)?;
    let setup = setup(&base).input()?;
    let track = crate::daemons::launch::track(&plan, &setup).input()?;
    let timing = Timing::new(latency, period_ns, lines);
    let mut central = Central::new(track, o.strategy, timing);
    tracing::info!(
        "{} trial(s), strategy {}, latency {latency} (sensor {} + command {} + lookahead \
         {lookahead_ms} ms), {}",
        o.trials,
        o.strategy,
        lines.sensor_ms,
        lines.command_ms,
        match o.lockstep {
            true => format!("in lockstep on a simulated clock at {rate_hz} Hz"),
            false => format!("live in namespace \"{namespace}\" at {rate_hz} Hz"),
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
        let result = crate::views::report::summarize(&setup, &central, &records, divergence);
        if o.json.json {
            print_json(&result)?;
        } else {
            print_result(&result, &lines);
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
        let cfg = crate::daemons::launch::board_config(&s, 1_000_000);
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
        o.board_timeout(),
        &stop,
    ) {
        Err(LiveError::Transport(e)) => Err(e).runtime(),
        other => Ok(other),
    }
}

/// The sensor and command delay lines (by default [`DelayLines::split`]); warns when they exceed
/// the latency the feedback was planned for.
fn delay_lines(o: &CentralOptions, latency: Latency, period_ns: u64) -> anyhow::Result<DelayLines> {
    let split = DelayLines::split(latency, period_ns);
    let lookahead_ms = Timing::lookahead_ms(period_ns);
    let latency_ms = latency.ms();
    let sensor = o.sensor_latency_ms.unwrap_or(split.sensor_ms);
    let command = o.command_latency_ms.unwrap_or(split.command_ms);
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
    Ok(DelayLines {
        sensor_ms: sensor,
        command_ms: command,
    })
}

/// A distance as printed in the tables: "diverged" when no trial completed.
pub(crate) fn distance_text(v: Option<f64>) -> String {
    v.map_or_else(|| "diverged".to_string(), |v| format!("{v:.2}"))
}

fn print_result(result: &StrategyResult, lines: &DelayLines) {
    let u = &result.unit;
    let f = distance_text;
    println!(
        "{} ({} trials, latency {} ms = sensor {} + command {} + lookahead)",
        result.name, result.trials, result.latency_ms, lines.sensor_ms, lines.command_ms
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
