//! `vic-board`: the simulated robot board as a process. It builds the board of a scenario (its
//! plant under the impedance law, Eq. 4, and the `[board]` limits), opens the board's transport
//! ports, optionally records every tick, asks for memory locking, a CPU and SCHED_FIFO (a refusal
//! is a warning: the loop runs on), runs the periodic loop until the duration ends or SIGINT /
//! SIGTERM, and prints its statistics.

use crate::cli::{
    Classify, DefaultScenarioArgs, JsonArg, NamespaceArgs, input_error, print_json, stop_on_signal,
};
use crate::ranges::{MAX_RUN_S, MAX_SPIN_US, real, whole};
use std::path::PathBuf;
use vic_plan::plan::setup;
use vic_plan::scenario::{ConfigError, Scenario};
use vic_rt::board::Board;
use vic_rt::board::live::{BoardLoopOptions, BoardStats, PercentilesJson, run_board};
use vic_rt::record::{RecordOptions, Recorder};
use vic_rt::sched::RtRequest;
use vic_rt::transport::BoardPorts;

/// The simulated board: plant, impedance law and disturbances at 1 kHz.
///
/// Example: vic-board --config config/two_link_divergent.toml --namespace lab1
#[derive(Debug, Clone, clap::Parser)]
#[command(name = "vic-board", version, about, long_about)]
#[command(
    mut_arg("config", |a| a.help("Scenario file (TOML): plant, actuator (type 2), field and noise")),
    mut_arg("json", |a| a.help("Print the final statistics as one JSON object")),
)]
pub struct BoardOptions {
    #[command(flatten)]
    pub(crate) scenario: DefaultScenarioArgs,
    #[command(flatten)]
    pub(crate) namespace: NamespaceArgs,
    /// Tick rate [Hz]. [range: 1 to 10000]
    #[arg(long, default_value_t = 1000, value_parser = whole(1u64, 10_000))]
    pub(crate) rate_hz: u64,
    #[command(flatten)]
    pub(crate) rt: RtArgs,
    /// Stiffness of the safe hold [N m/rad] (default: the scenario's board.hold_stiffness, 100).
    /// The scenario raises the lower bound to what holds its arm against gravity, its field and
    /// the largest load the board accepts, and lowers the upper one to what the board's step
    /// integrates stably (docs/CONFIG.md, board.hold_stiffness). The other limits (watchdog,
    /// ramp, joint and speed limits, disturbance limits) are keys of the scenario's [board]
    /// section: --set board.watchdog=0.1 [range: 0.001 to 1000]
    #[arg(long, value_name = "N_M_PER_RAD", value_parser = real(0.001, 1000.0))]
    pub(crate) hold_stiffness: Option<f64>,
    /// Stop after this many seconds (0: run until SIGINT/SIGTERM). [range: 0 to 604800]
    #[arg(long, default_value_t = 0.0, value_parser = real(0.0, MAX_RUN_S))]
    pub(crate) duration_s: f64,
    #[command(flatten)]
    pub(crate) json: JsonArg,
    /// Record every tick (state, command in use, disturbances) from a thread outside the loop:
    /// FILE.csv is the log `vic identify --log` reads, FILE.mcap opens in Foxglove and
    /// PlotJuggler (and `vic convert` turns it into the CSV). Gaps (queue full) are marked in
    /// the file and counted in the statistics. A new file: an existing one is refused without
    /// --record-force, a symbolic link never followed. What was written is handed to the
    /// kernel every 50 ms, so a board killed with SIGKILL leaves a file that `vic convert`
    /// reads, less its last 50 ms; a full disk is reported at once, the file kept readable,
    /// and the board runs on.
    #[arg(long, value_name = "FILE.csv|FILE.mcap")]
    pub(crate) record: Option<PathBuf>,
    /// Replace an existing --record file (a symbolic link is replaced, not followed).
    #[arg(long, requires = "record")]
    pub(crate) record_force: bool,
    /// Capacity of the recording queue [ticks]; it is locked in memory with the rest of the
    /// board (the largest, 131072, is 131 s at 1 kHz and about 48 MB). [range: 1 to 131072]
    #[arg(long, value_name = "TICKS", default_value_t = vic_rt::record::DEFAULT_CAPACITY,
          value_parser = whole(1usize, vic_rt::record::MAX_CAPACITY))]
    pub(crate) record_queue: usize,
    /// Level of the log on stderr: error, warn, info, debug, trace, off, or per target
    /// (vic=debug,warn). Default: RUST_LOG, else info. Nothing is logged inside the loop.
    #[arg(long, value_name = "LEVEL")]
    pub(crate) log_level: Option<String>,
}

/// The board loop's real-time flags: what to ask the OS for ([`RtArgs::request`]).
#[derive(Debug, Clone, clap::Args)]
pub(crate) struct RtArgs {
    /// Spin this long before each deadline [µs] (0: sleep only). Default 100 (10 % of a CPU,
    /// never enough to trip the kernel's real-time throttling), 0 with --no-rt.
    /// [range: 0 to 10000]
    #[arg(long, value_name = "US", value_parser = whole(0u64, MAX_SPIN_US))]
    pub(crate) spin_us: Option<u64>,
    /// SCHED_FIFO priority of the loop (1–99). Real-time is the default: the board asks for
    /// SCHED_FIFO, mlockall, a CPU of its own (the last one, where there are several) and a
    /// spin before each deadline, prints what it got and runs on with a warning when refused.
    /// [range: 1 to 99]
    #[arg(long, value_name = "PRIO", default_value_t = vic_rt::sched::DEFAULT_FIFO_PRIORITY,
          value_parser = whole(1i32, 99))]
    pub(crate) fifo: i32,
    /// Pin the loop to this CPU (default: the last CPU, where there are several).
    /// [range: 0 to 1023]
    #[arg(long, value_name = "N", value_parser = whole(0usize, 1023))]
    pub(crate) cpu: Option<usize>,
    /// Without the real-time settings: the normal scheduler instead of SCHED_FIFO, no pinning
    /// to a CPU and no spin before each deadline unless --spin-us asks (mlockall is still
    /// tried).
    #[arg(long)]
    pub(crate) no_rt: bool,
}

impl RtArgs {
    /// The request: the real-time defaults ([`RtRequest::default_rt`]) with the flags given, or
    /// with `--no-rt` the normal scheduler, no pinning and no spin unless `--spin-us` asks.
    pub(crate) fn request(&self) -> RtRequest {
        let mut req = if self.no_rt {
            RtRequest::none()
        } else {
            RtRequest::default_rt()
        };
        req.fifo = if self.no_rt { None } else { Some(self.fifo) };
        req.cpu = self.cpu;
        req.spin_us = self.spin_us.unwrap_or(req.spin_us);
        req
    }
}

/// Runs the board until the duration ends or a signal stops it, then prints its statistics.
pub fn run(o: &BoardOptions) -> anyhow::Result<()> {
    crate::daemons::logging::init(o.log_level.as_deref())?;
    let _log = tracing::info_span!("vic-board").entered();
    let namespace = o.namespace.validated()?;
    let scenario = load_with_hold_stiffness(o)?;
    let period_ns = 1_000_000_000 / o.rate_hz;
    let mut board = board_of(&scenario, period_ns)?;
    let stop = stop_on_signal()?;
    let ep = BoardPorts::open(namespace)?;
    let cleaned_dead_nodes = ep.session().cleaned_dead_nodes();
    if cleaned_dead_nodes > 0 {
        tracing::warn!(
            "removed the resources of {cleaned_dead_nodes} dead process(es) in namespace \"{namespace}\""
        );
    }
    let memory_locked = vic_rt::sched::lock_memory();
    let request = o.rt.request();
    let loop_options = BoardLoopOptions {
        spin_ns: request.spin_us * 1000,
        max_ticks: (o.duration_s * o.rate_hz as f64) as u64,
        ..BoardLoopOptions::default()
    };
    let mut recorder = match &o.record {
        Some(path) => Some(start_recorder(o, path, scenario.model.dof())?),
        None => None,
    };
    // After the recorder's writer thread exists: it must not inherit the real-time policy.
    let realtime = apply_scheduling(&request, memory_locked);
    tracing::info!(
        "running in namespace \"{namespace}\" at {} Hz ({} joints){}",
        o.rate_hz,
        scenario.model.dof(),
        match o.duration_s {
            0.0 => String::new(),
            d => format!(" for {d} s"),
        }
    );
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
    // After the loop: its counters, once.
    tracing::info!(
        "stopped after {} ticks ({} late, {} periods missed, {} rejected messages)",
        stats.ticks,
        stats.late_ticks,
        stats.missed_periods,
        stats.rejected_messages
    );
    if o.json.json {
        print_json(&stats)
    } else {
        print_stats(&stats);
        Ok(())
    }
}

/// The scenario with `--hold-stiffness` applied as `board.hold_stiffness`, so that the flag is
/// checked like the key (range, damping law, stability) and its error names the flag.
fn load_with_hold_stiffness(o: &BoardOptions) -> anyhow::Result<Scenario> {
    let (config, mut overrides) = (&o.scenario.config, o.scenario.set.overrides.clone());
    let Some(k) = o.hold_stiffness else {
        return Scenario::load(config, &overrides).input();
    };
    let value = match k {
        k if k.is_nan() => "nan".to_string(),
        k if k.is_infinite() => if k > 0.0 { "inf" } else { "-inf" }.to_string(),
        k => format!("{k:e}"),
    };
    overrides.push(format!("board.hold_stiffness={value}"));
    Scenario::load(config, &overrides).map_err(|e| match &e {
        ConfigError::Invalid { key, .. } if key == "hold_stiffness" => {
            input_error(format!("--hold-stiffness {k}: {e}"))
        }
        _ => input_error(e),
    })
}

/// The board of `scenario` ticking every `period_ns`, at rest at the scenario's start.
fn board_of(scenario: &Scenario, period_ns: u64) -> anyhow::Result<Board> {
    let setup = setup(scenario).input()?;
    let cfg = crate::daemons::launch::board_config(scenario, period_ns);
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
            o.scenario.config.display(),
            o.scenario.set.overrides.join(" "),
            o.rate_hz,
            o.namespace.namespace
        ),
        start_paused: false,
        metadata: [
            ("scenario", o.scenario.config.display().to_string()),
            ("overrides", o.scenario.set.overrides.join(" ")),
            ("rate_hz", o.rate_hz.to_string()),
            ("namespace", o.namespace.namespace.clone()),
            (
                "command_line",
                std::env::args().collect::<Vec<_>>().join(" "),
            ),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect(),
        period_ns: 1_000_000_000 / o.rate_hz,
        replace: o.record_force,
        report: Some(report_record_error),
    };
    Recorder::start(path, &options)
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::AlreadyExists => format!(
                "--record {}: it exists already; choose another name, or pass --record-force to \
                 replace it (a symbolic link is replaced, not followed)",
                path.display()
            ),
            _ => format!("--record: {e}"),
        })
        .input()
}

/// Logs a recording that stopped (a full disk) when it happens, from the writer thread.
fn report_record_error(message: &str) {
    tracing::error!("--record {message}; the board runs on");
}

/// Applies the real-time settings to the calling thread (the loop's) and logs what is in force
/// and what the OS refused (a warning; the loop runs on either way).
fn apply_scheduling(req: &RtRequest, memory_locked: bool) -> vic_rt::sched::RtSettings {
    let slack = vic_rt::realtime::set_timer_slack_1ns();
    let got = vic_rt::sched::apply_realtime(req, memory_locked, slack);
    if got.refused.is_empty() {
        tracing::info!("real-time: {}", got.describe());
    } else {
        tracing::warn!("real-time: {}", got.describe());
    }
    // Another real-time loop on the same CPU (a second board on its defaults): both miss
    // deadlines and nothing else says why.
    if let (Some(_), Some(cpu)) = (got.fifo, got.cpu) {
        for r in vic_rt::sched::fifo_threads_pinned_to(cpu, std::process::id()) {
            tracing::warn!(
                "CPU {cpu} is shared with another SCHED_FIFO loop: {} (pid {}, thread {}, \
                 priority {}); the two preempt each other. Give this board another CPU with \
                 --cpu N (or stop the other)",
                r.name,
                r.pid,
                r.tid,
                r.priority
            );
        }
    }
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

#[cfg(test)]
mod flags {
    /// clap's own consistency checks (every `mut_arg` names an argument that exists, no two
    /// flags clash), which it otherwise runs only when a command is parsed.
    #[test]
    fn are_consistent() {
        use clap::CommandFactory;
        super::BoardOptions::command().debug_assert();
    }
}
