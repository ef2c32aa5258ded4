//! `vic-board`: the simulated robot board. A 1 kHz absolute-deadline loop that integrates the
//! scenario's plant under the impedance law (Eq. 4), follows the command slices of `vic-planner`,
//! applies injected disturbances, and publishes its state every tick and telemetry at 10 Hz.
//! SIGINT/SIGTERM stop it at the end of the current tick; it prints its statistics and exits 0.

use clap::Parser;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use vic::planning::scenario::Scenario;
use vic::rt::board::Board;
use vic::rt::realtime::{BoardLoopOptions, run_board};
use vic::rt::transport::{DEFAULT_NAMESPACE, Endpoint, Role};

/// The simulated board: plant, impedance law and disturbances at 1 kHz.
///
/// Example: vic-board --config config/two_link_divergent.toml --namespace lab1
#[derive(Parser)]
#[command(name = "vic-board", version, about, long_about)]
struct Args {
    /// Scenario file (TOML): plant, actuator (type 2), field and noise.
    #[arg(
        long,
        short,
        value_name = "FILE",
        default_value = "config/two_link_divergent.toml"
    )]
    config: PathBuf,
    /// Override a configuration key (repeatable): --set noise.sigma=0.02
    #[arg(long = "set", value_name = "SECTION.KEY=VALUE")]
    overrides: Vec<String>,
    /// Namespace of the services (instances in different namespaces never see each other).
    #[arg(long, default_value = DEFAULT_NAMESPACE)]
    namespace: String,
    /// Tick rate [Hz].
    #[arg(long, default_value_t = 1000)]
    rate_hz: u64,
    /// Spin this long before each deadline [µs] (0: sleep only; spinning trades a CPU for
    /// lower jitter).
    #[arg(long, default_value_t = 0)]
    spin_us: u64,
    /// Stiffness of the safe hold [N m/rad] (default: the scenario's board.hold_stiffness, 100).
    /// The other limits (watchdog, ramp, joint and speed limits, disturbance limits) are keys
    /// of the scenario's [board] section: --set board.watchdog=0.1
    #[arg(long, value_name = "N_M_PER_RAD")]
    hold_stiffness: Option<f64>,
    /// Run the loop under SCHED_FIFO at this priority (1–99; needs CAP_SYS_NICE, else a
    /// warning). With --spin-us 100 this is what meets cyclictest's p99 here (docs/BENCHMARKS.md).
    #[arg(long, value_name = "PRIO", value_parser = clap::value_parser!(i32).range(1..=99))]
    fifo: Option<i32>,
    /// Pin the loop to this CPU.
    #[arg(long, value_name = "N")]
    cpu: Option<usize>,
    /// Stop after this many seconds (0: run until SIGINT/SIGTERM).
    #[arg(long, default_value_t = 0.0)]
    duration_s: f64,
    /// Print the final statistics as one JSON object.
    #[arg(long)]
    json: bool,
    /// Record every tick (state, command in use, disturbances) to this CSV file, in the log
    /// format `vic identify --log` reads, from a thread outside the loop. Gaps (queue full) are
    /// marked in the file and counted in the statistics.
    #[arg(long, value_name = "FILE.csv")]
    record: Option<PathBuf>,
    /// Capacity of the recording queue [ticks].
    #[arg(long, value_name = "TICKS", default_value_t = vic::rt::record::DEFAULT_CAPACITY)]
    record_queue: usize,
}

fn main() -> ExitCode {
    let args = Args::parse();
    match run(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err((code, message)) => {
            eprintln!("vic-board: error: {message}");
            ExitCode::from(code)
        }
    }
}

fn run(args: Args) -> Result<(), (u8, String)> {
    let input = |m: String| (2u8, m);
    if args.rate_hz == 0 || args.rate_hz > 10_000 {
        return Err(input(format!("--rate-hz {}: use 1 to 10000", args.rate_hz)));
    }
    vic::rt::transport::validate_namespace(&args.namespace).map_err(input)?;
    let scenario =
        Scenario::load(&args.config, &args.overrides).map_err(|e| input(e.to_string()))?;
    let setup = vic::planning::plan::setup(&scenario).map_err(|e| input(e.to_string()))?;
    let period_ns = 1_000_000_000 / args.rate_hz;
    let mut cfg = vic::tools::launch::board_config(&scenario, period_ns);
    if let Some(k) = args.hold_stiffness {
        cfg.hold_stiffness = k;
    }
    let mut board =
        Board::new(scenario.model.clone(), cfg, &setup.x0).map_err(|e| input(e.to_string()))?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
            .map_err(|e| (1, format!("cannot install the signal handler: {e}")))?;
    }
    let ep = Endpoint::open(&args.namespace, Role::Board).map_err(|e| (1, e.to_string()))?;
    if ep.cleaned_dead_nodes > 0 {
        eprintln!(
            "vic-board: removed the resources of {} dead process(es) in namespace \"{}\"",
            ep.cleaned_dead_nodes, args.namespace
        );
    }
    if !vic::rt::realtime::lock_memory() {
        eprintln!("vic-board: warning: mlockall failed; page faults may add jitter");
    }
    let opts = BoardLoopOptions {
        spin_ns: args.spin_us * 1000,
        max_ticks: (args.duration_s * args.rate_hz as f64) as u64,
        ..BoardLoopOptions::default()
    };
    let mut recorder = match &args.record {
        Some(path) => Some(
            vic::rt::record::Recorder::start(
                path,
                &vic::rt::record::RecordOptions {
                    capacity: args.record_queue,
                    joints: scenario.model.dof(),
                    banner: format!(
                        "{} {}, {} Hz, namespace {}",
                        args.config.display(),
                        args.overrides.join(" "),
                        args.rate_hz,
                        args.namespace
                    ),
                    start_paused: false,
                },
            )
            .map_err(|e| input(format!("--record: {e}")))?,
        ),
        None => None,
    };
    // After the recorder's writer thread exists: it must not inherit the real-time policy.
    if let Some(cpu) = args.cpu
        && let Err(e) = vic::rt::sched::pin_to_cpu(cpu)
    {
        eprintln!("vic-board: warning: cannot pin to CPU {cpu}: {e}");
    }
    if let Some(prio) = args.fifo
        && let Err(e) = vic::rt::sched::set_policy(vic::rt::sched::SchedPolicy::Fifo(prio))
    {
        eprintln!("vic-board: warning: SCHED_FIFO {prio} refused ({e}); running unprivileged");
    }
    let mut stats = run_board(
        &ep,
        &mut board,
        period_ns,
        &opts,
        &stop,
        recorder.as_mut().map(|r| r.producer()),
    );
    if let Some(r) = recorder.take() {
        let path = r.path().display().to_string();
        let summary = r
            .finish()
            .map_err(|e| (1, format!("--record {path}: {e}")))?;
        stats.recorded = Some(summary.written);
        stats.dropped = Some(summary.dropped);
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string(&stats).map_err(|e| (1, e.to_string()))?
        );
    } else {
        let p = |n: &str, v: &vic::rt::realtime::PercentilesJson| {
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
    Ok(())
}
