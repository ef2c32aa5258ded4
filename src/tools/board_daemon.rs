//! `vic-board`: the simulated robot board as a process. It builds the board of a scenario (its
//! plant under the impedance law, Eq. 4, and the `[board]` limits), opens the board's transport
//! ports, optionally records every tick, asks for memory locking, a CPU and SCHED_FIFO (a refusal
//! is a warning: the loop runs on), runs the periodic loop until the duration ends or SIGINT /
//! SIGTERM, and prints its statistics.

use crate::planning::plan::setup;
use crate::planning::scenario::{ConfigError, Scenario};
use crate::rt::board::Board;
use crate::rt::realtime::{BoardLoopOptions, BoardStats, PercentilesJson, run_board};
use crate::rt::record::{RecordOptions, Recorder};
use crate::rt::transport::BoardPorts;
use crate::tools::cli::{Classify, input_error, non_negative_seconds, print_json, stop_on_signal};
use std::path::PathBuf;

/// What `vic-board` was asked for.
#[derive(Debug, Clone)]
pub struct BoardOptions {
    pub config: PathBuf,
    pub overrides: Vec<String>,
    pub namespace: String,
    /// Tick rate [Hz], 1 to 10 000.
    pub rate_hz: u64,
    /// Spin before each deadline [µs] (0: sleep only).
    pub spin_us: u64,
    /// Stiffness of the safe hold [N m/rad] (default: the scenario's `board.hold_stiffness`).
    pub hold_stiffness: Option<f64>,
    /// SCHED_FIFO priority of the loop.
    pub fifo: Option<i32>,
    /// The CPU the loop is pinned to (None: the last CPU when there are several, unless no_rt).
    pub cpu: Option<usize>,
    /// The old behaviour: no SCHED_FIFO, no pinning (and no spin unless spin_us says so).
    pub no_rt: bool,
    /// Run this long [s] (0: until SIGINT/SIGTERM).
    pub duration_s: f64,
    pub json: bool,
    /// Record every tick to this file (CSV or MCAP, by its extension).
    pub record: Option<PathBuf>,
    /// Capacity of the recording queue [ticks].
    pub record_queue: usize,
}

/// Runs the board until the duration ends or a signal stops it, then prints its statistics.
pub fn run(o: &BoardOptions) -> anyhow::Result<()> {
    if o.rate_hz == 0 || o.rate_hz > 10_000 {
        return Err(input_error(format!(
            "--rate-hz {}: use 1 to 10000",
            o.rate_hz
        )));
    }
    non_negative_seconds("--duration-s", o.duration_s)?;
    crate::rt::transport::validate_namespace(&o.namespace).input()?;
    let scenario = load_with_hold_stiffness(o)?;
    let period_ns = 1_000_000_000 / o.rate_hz;
    let mut board = board_of(&scenario, period_ns)?;
    let stop = stop_on_signal()?;
    let ep = BoardPorts::open(&o.namespace)?;
    let cleaned_dead_nodes = ep.session().cleaned_dead_nodes();
    if cleaned_dead_nodes > 0 {
        eprintln!(
            "vic-board: removed the resources of {} dead process(es) in namespace \"{}\"",
            cleaned_dead_nodes, o.namespace
        );
    }
    let memory_locked = crate::rt::realtime::lock_memory();
    let loop_options = BoardLoopOptions {
        spin_ns: o.spin_us * 1000,
        max_ticks: (o.duration_s * o.rate_hz as f64) as u64,
        ..BoardLoopOptions::default()
    };
    let mut recorder = match &o.record {
        Some(path) => Some(start_recorder(o, path, scenario.model.dof())?),
        None => None,
    };
    // After the recorder's writer thread exists: it must not inherit the real-time policy.
    let realtime = apply_scheduling(o, memory_locked);
    let mut stats = run_board(
        &ep,
        &mut board,
        period_ns,
        &loop_options,
        &stop,
        recorder.as_mut().map(|r| r.producer()),
    );
    if let Some(r) = recorder.take() {
        let path = r.path().display().to_string();
        let summary = r
            .finish()
            .map_err(|e| format!("--record {path}: {e}"))
            .runtime()?;
        stats.recorded = Some(summary.written);
        stats.dropped = Some(summary.dropped);
    }
    stats.realtime = Some(realtime);
    if o.json {
        print_json(&stats)
    } else {
        print_stats(&stats);
        Ok(())
    }
}

/// The scenario with `--hold-stiffness` applied as `board.hold_stiffness`, so that the flag is
/// checked like the key (range, damping law, stability) and its error names the flag.
fn load_with_hold_stiffness(o: &BoardOptions) -> anyhow::Result<Scenario> {
    let mut overrides = o.overrides.clone();
    let Some(k) = o.hold_stiffness else {
        return Scenario::load(&o.config, &overrides).input();
    };
    let value = match k {
        k if k.is_nan() => "nan".to_string(),
        k if k.is_infinite() => if k > 0.0 { "inf" } else { "-inf" }.to_string(),
        k => format!("{k:e}"),
    };
    overrides.push(format!("board.hold_stiffness={value}"));
    Scenario::load(&o.config, &overrides).map_err(|e| match &e {
        ConfigError::Invalid { key, .. } if key == "hold_stiffness" => {
            input_error(format!("--hold-stiffness {k}: {e}"))
        }
        _ => input_error(e),
    })
}

/// The board of `scenario` ticking every `period_ns`, at rest at the scenario's start.
fn board_of(scenario: &Scenario, period_ns: u64) -> anyhow::Result<Board> {
    let setup = setup(scenario).input()?;
    let cfg = crate::tools::launch::board_config(scenario, period_ns);
    Board::new(scenario.model.clone(), cfg, &setup.x0).input()
}

fn start_recorder(
    o: &BoardOptions,
    path: &std::path::Path,
    joints: usize,
) -> anyhow::Result<Recorder> {
    let options = RecordOptions {
        capacity: o.record_queue,
        joints,
        banner: format!(
            "{} {}, {} Hz, namespace {}",
            o.config.display(),
            o.overrides.join(" "),
            o.rate_hz,
            o.namespace
        ),
        start_paused: false,
        metadata: [
            ("scenario", o.config.display().to_string()),
            ("overrides", o.overrides.join(" ")),
            ("rate_hz", o.rate_hz.to_string()),
            ("namespace", o.namespace.clone()),
            (
                "command_line",
                std::env::args().collect::<Vec<_>>().join(" "),
            ),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect(),
        period_ns: 1_000_000_000 / o.rate_hz,
    };
    Recorder::start(path, &options)
        .map_err(|e| format!("--record: {e}"))
        .input()
}

/// Applies the real-time settings to the calling thread (the loop's) and says on stderr what
/// is in force and what the OS refused (the loop runs on either way).
fn apply_scheduling(o: &BoardOptions, memory_locked: bool) -> crate::rt::sched::RtSettings {
    use crate::rt::sched::{RtRequest, apply_realtime};
    let mut req = if o.no_rt {
        RtRequest::none()
    } else {
        RtRequest::default_rt()
    };
    req.fifo = if o.no_rt { None } else { o.fifo };
    req.cpu = o.cpu;
    req.spin_us = o.spin_us;
    let slack = crate::rt::realtime::set_timer_slack_1ns();
    let got = apply_realtime(&req, memory_locked, slack);
    let label = if got.refused.is_empty() {
        "real-time"
    } else {
        "warning: real-time"
    };
    eprintln!("vic-board: {label}: {}", got.describe());
    got
}

fn print_stats(stats: &BoardStats) {
    let p = |n: &str, v: &PercentilesJson| {
        println!(
            "{n:<12} p50 {:>8.1} µs  p99 {:>8.1} µs  p99.9 {:>8.1} µs  max {:>9.1} µs",
            v.p50, v.p99, v.p999, v.max
        )
    };
    println!(
        "ticks        {} ({} late, {} periods missed, {} lost), {} rejected messages {:?}, {} safe-hold ticks",
        stats.ticks,
        stats.late_ticks,
        stats.missed_periods,
        stats.lost_periods,
        stats.rejected_messages,
        stats.rejected_by_reason,
        stats.safe_hold_ticks
    );
    if let (Some(r), Some(d)) = (stats.recorded, stats.dropped) {
        println!("recorded     {r} ticks, {d} dropped");
    }
    p("jitter", &stats.jitter_us);
    p("work", &stats.work_us);
    p("command age", &stats.command_age_us);
}
