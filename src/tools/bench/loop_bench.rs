//! `vic bench loop`: the board's 1 kHz loop with its real work ([`crate::rt::realtime::board_tick`]
//! on a scenario's plant, a 50 Hz planner thread streaming hold commands over the real
//! transport), under each combination of the options real-time loops use, and `cyclictest` at
//! the same interval for the same duration in the same run (sequentially: the variants one after
//! the other, then the baselines).

use super::{Dist, cyclictest, ratio};
use crate::planning::scenario::Scenario;
use crate::rt::board::{Board, Inputs};
use crate::rt::realtime::{
    BoardHistograms, Periodic, board_tick, lock_memory, set_timer_slack_1ns,
};
use crate::rt::sched::{self, SchedPolicy};
use crate::rt::transport::{
    BoardPorts, CentralPorts, CommandSlice, Control, ControlKind, Header, MAX_JOINTS, MAX_KNOTS,
    monotonic_ns, remove_namespace,
};
pub use crate::tools::launch::board_config;
use serde::Serialize;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// The loop's period [ns]: 1 kHz, cyclictest's `-i1000`.
pub const PERIOD_NS: u64 = 1_000_000;
/// `SCHED_FIFO` priority of the real-time variants (cyclictest's `-p80`).
pub const FIFO_PRIORITY: i32 = 80;
/// Spin before each deadline in the spin variants [µs].
pub const SPIN_US: u64 = 100;

/// One way to run the loop.
#[derive(Debug, Clone, Serialize)]
pub struct Variant {
    pub name: &'static str,
    pub description: &'static str,
    /// `prctl(PR_SET_TIMERSLACK, 1)` (else the default 50 µs).
    pub timer_slack_1ns: bool,
    /// Spin this long before each deadline [µs] (0: sleep only).
    pub spin_us: u64,
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)`.
    pub mlock: bool,
    /// Pin the loop thread to the machine's last CPU.
    pub pin: bool,
    /// `SCHED_FIFO` priority.
    pub fifo: Option<i32>,
}

/// Every variant, from the plainest loop to everything at once.
pub fn variants() -> Vec<Variant> {
    let v = |name, description, slack, spin_us, mlock, pin, fifo| Variant {
        name,
        description,
        timer_slack_1ns: slack,
        spin_us,
        mlock,
        pin,
        fifo,
    };
    let rt = Some(FIFO_PRIORITY);
    vec![
        v(
            "sleep-slack50",
            "absolute clock_nanosleep, default 50 µs timer slack",
            false,
            0,
            false,
            false,
            None,
        ),
        v(
            "sleep",
            "absolute clock_nanosleep, timer slack 1 ns",
            true,
            0,
            false,
            false,
            None,
        ),
        v(
            "spin",
            "sleep, then spin the last 100 µs",
            true,
            SPIN_US,
            false,
            false,
            None,
        ),
        v(
            "spin-mlock",
            "spin + mlockall (vic-board where SCHED_FIFO is refused and there is one CPU)",
            true,
            SPIN_US,
            true,
            false,
            None,
        ),
        v(
            "spin-mlock-pin",
            "spin + mlockall + pinned to the last CPU",
            true,
            SPIN_US,
            true,
            true,
            None,
        ),
        v(
            "fifo",
            "sleep + SCHED_FIFO 80 + mlockall + pinned",
            true,
            0,
            true,
            true,
            rt,
        ),
        v(
            "fifo-spin",
            "spin + SCHED_FIFO 80 + mlockall + pinned (vic-board's default)",
            true,
            SPIN_US,
            true,
            true,
            rt,
        ),
    ]
}

/// The variant compared with cyclictest in the headline (the target names "the spin option").
pub const HEADLINE: &str = "spin-mlock";

/// Options of `vic bench loop`.
#[derive(Debug, Clone)]
pub struct Options {
    /// Duration of each variant and of each cyclictest run [s].
    pub seconds: u64,
    /// Scenario whose plant the board integrates (impedance actuator).
    pub config: PathBuf,
    pub overrides: Vec<String>,
    /// Names of the variants to run (empty: all).
    pub variants: Vec<String>,
    /// Run cyclictest (when found).
    pub baseline: bool,
}

/// The figures of one variant.
#[derive(Debug, Clone, Serialize)]
pub struct VariantResult {
    #[serde(flatten)]
    pub variant: Variant,
    /// Wake-up lateness (woke − deadline).
    pub jitter: Dist,
    /// Tick work: drain the transport, step the board, publish the state.
    pub work: Dist,
    /// CPU time of the loop thread over wall time [%].
    pub cpu_percent: f64,
    pub late_ticks: u64,
    pub missed_periods: u64,
    /// Options asked for that the system refused (the loop ran without them).
    pub refused: Vec<String>,
    /// The cyclictest run it is compared with (`cyclictest` or `cyclictest_fifo`).
    pub baseline: &'static str,
    pub ratio_p99: Option<f64>,
    pub ratio_p50: Option<f64>,
}

/// A cyclictest run's figures.
#[derive(Debug, Clone, Serialize)]
pub struct BaselineResult {
    #[serde(flatten)]
    pub dist: Dist,
    pub cpu_percent: f64,
    pub command: String,
}

/// The summary in the documented shape: `{p50_us, p99_us, p999_us, max_us, cpu_percent}`.
#[derive(Debug, Clone, Serialize)]
pub struct Headline {
    #[serde(flatten)]
    pub dist: Dist,
    pub cpu_percent: f64,
    pub variant: String,
    /// Tick work of the same run.
    pub work: Dist,
}

/// The whole report of `vic bench loop`.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub interval_us: u64,
    pub seconds: u64,
    pub order: String,
    pub scenario: String,
    pub vic: Headline,
    pub baseline: Option<BaselineResult>,
    pub ratio_p99: Option<f64>,
    pub variants: Vec<VariantResult>,
    pub baselines: Baselines,
    /// Why there is no baseline, when there is none.
    pub baseline_note: Option<String>,
    pub fifo_permitted: bool,
    pub machine: super::Machine,
}

/// Both cyclictest runs.
#[derive(Debug, Clone, Serialize, Default)]
pub struct Baselines {
    pub cyclictest: Option<BaselineResult>,
    pub cyclictest_fifo: Option<BaselineResult>,
}

/// A full command slice (32 knots) holding `q0` with `stiffness`, for `trial` from trial time
/// `start_ns`.
pub fn hold_slice(
    dof: usize,
    q0: &[f64],
    seq: u64,
    trial: u32,
    start_ns: u64,
    stiffness: f64,
) -> CommandSlice {
    let mut c = CommandSlice {
        header: Header::new(seq, monotonic_ns()),
        joints: dof as u32,
        trial,
        start_ns,
        knot_dt_ns: 10_000_000,
        count: MAX_KNOTS as u32,
        ..Default::default()
    };
    for k in &mut c.knots {
        k.q_d[..dof].copy_from_slice(&q0[..dof]);
        k.stiffness = [stiffness; MAX_JOINTS];
    }
    c
}

/// A loaded scenario, ready for boards.
struct Plant {
    scenario: Scenario,
    q0: Vec<f64>,
}

fn load(opts: &Options) -> Result<Plant, String> {
    let scenario = Scenario::load(&opts.config, &opts.overrides).map_err(|e| e.to_string())?;
    let setup = crate::planning::plan::setup(&scenario).map_err(|e| e.to_string())?;
    let dof = scenario.model.dof();
    let q0 = setup.x0[..dof].to_vec();
    // Fail early (bad actuator) rather than inside a thread.
    Board::new(
        scenario.model.clone(),
        board_config(&scenario, PERIOD_NS),
        &q0,
    )
    .map_err(|e| e.to_string())?;
    Ok(Plant { scenario, q0 })
}

/// The 50 Hz planner stand-in: resets the board into a trial, then streams hold slices over the
/// command channel and drains the states, as `vic-planner` does.
fn planner_thread(ns: String, dof: usize, q0: Vec<f64>, stiffness: f64, stop: Arc<AtomicBool>) {
    let Ok(ep) = CentralPorts::open(&ns) else {
        return;
    };
    let start = monotonic_ns() + 20_000_000;
    let mut reset = Control {
        header: Header::new(1, monotonic_ns()),
        kind: ControlKind::Reset as u32,
        trial: 1,
        seed: 1,
        start_ns: start,
        ..Default::default()
    };
    reset.q0[..dof].copy_from_slice(&q0[..dof]);
    let _ = ep.publish_control(&reset);
    let mut seq = 0;
    let mut p = Periodic::new(20_000_000, 0);
    while !stop.load(Ordering::Relaxed) {
        p.wait();
        let t = monotonic_ns().saturating_sub(start);
        seq += 1;
        let c = hold_slice(dof, &q0, seq, 1, t / 10_000_000 * 10_000_000, stiffness);
        let _ = ep.publish_command(&c);
        ep.drain_states(|_| {});
    }
}

/// Runs one variant for `seconds` (after a 200 ms warm-up that is not recorded).
fn run_variant(plant: &Plant, v: &Variant, seconds: u64) -> Result<VariantResult, String> {
    let ns = super::unique_namespace("bl");
    let result = run_variant_in(plant, v, seconds, &ns);
    remove_namespace(&ns);
    result
}

fn run_variant_in(
    plant: &Plant,
    v: &Variant,
    seconds: u64,
    ns: &str,
) -> Result<VariantResult, String> {
    let mut refused = Vec::new();
    let locked = v.mlock && lock_memory();
    if v.mlock && !locked {
        refused.push(format!("mlockall: {}", std::io::Error::last_os_error()));
    }
    let stop = Arc::new(AtomicBool::new(false));
    let (ready_tx, ready_rx) = std::sync::mpsc::channel::<Result<(), String>>();
    let scenario = plant.scenario.clone();
    let q0 = plant.q0.clone();
    let variant = v.clone();
    let ns_loop = ns.to_string();
    let stop_loop = stop.clone();
    let looper = std::thread::spawn(move || {
        let mut refused = Vec::new();
        if variant.timer_slack_1ns && !set_timer_slack_1ns() {
            refused.push("timer slack 1 ns".to_string());
        }
        if variant.pin {
            let cpu = sched::cpu_count().saturating_sub(1);
            if let Err(e) = sched::pin_to_cpu(cpu) {
                refused.push(format!("pin: {e}"));
            }
        }
        let ep = match BoardPorts::open(&ns_loop) {
            Ok(ep) => ep,
            Err(e) => {
                let _ = ready_tx.send(Err(e.to_string()));
                return Err(e.to_string());
            }
        };
        let mut board = Board::new(
            scenario.model.clone(),
            board_config(&scenario, PERIOD_NS),
            &q0,
        )
        .map_err(|e| e.to_string())?;
        let _ = ready_tx.send(Ok(()));
        if let Some(prio) = variant.fifo
            && let Err(e) = sched::set_policy(SchedPolicy::Fifo(prio))
        {
            refused.push(format!("SCHED_FIFO {prio}: {e}"));
        }
        let mut hist = BoardHistograms::default();
        let mut inputs = Inputs::default();
        let mut periodic = Periodic::new(PERIOD_NS, variant.spin_us * 1000);
        let mut seq = 0u64;
        let warm_end = monotonic_ns() + 200_000_000;
        while monotonic_ns() < warm_end {
            let w = periodic.wait();
            seq += 1;
            board_tick(&ep, &mut board, &mut inputs, &w, seq, &mut hist);
        }
        hist = BoardHistograms::default();
        periodic.late_ticks = 0;
        periodic.skipped_periods = 0;
        // The window is `seconds` of deadlines from the next one: every deadline in it is either
        // ticked or counted as skipped, exactly once.
        let t0 = periodic.next_deadline();
        let cpu0 = sched::thread_cpu_ns();
        let end = t0 + seconds * 1_000_000_000;
        loop {
            let w = periodic.wait();
            if w.deadline_ns >= end {
                // A late wake that crossed the end skipped deadlines on both sides of it: only
                // those before the end belong to the window.
                let first = w.deadline_ns - w.skipped * PERIOD_NS;
                let inside = end.saturating_sub(first).div_ceil(PERIOD_NS).min(w.skipped);
                periodic.skipped_periods -= w.skipped - inside;
                break;
            }
            seq += 1;
            board_tick(&ep, &mut board, &mut inputs, &w, seq, &mut hist);
        }
        let cpu = sched::thread_cpu_ns() - cpu0;
        let wall = monotonic_ns() - t0;
        let _ = sched::set_policy(SchedPolicy::Other);
        stop_loop.store(true, Ordering::Relaxed);
        Ok::<_, String>((
            Dist::from_histogram(&hist.jitter),
            Dist::from_histogram(&hist.work),
            100.0 * cpu as f64 / wall.max(1) as f64,
            periodic.late_ticks,
            periodic.skipped_periods,
            refused,
        ))
    });
    // The planner connects once the board's subscribers exist, so the reset is not lost.
    let ready = ready_rx
        .recv()
        .unwrap_or_else(|_| Err("the loop thread stopped".into()));
    let planner = ready.is_ok().then(|| {
        let (ns, dof, q0, stop) = (
            ns.to_string(),
            plant.scenario.model.dof(),
            plant.q0.clone(),
            stop.clone(),
        );
        let k = plant
            .scenario
            .bounds
            .upper
            .get(dof)
            .copied()
            .unwrap_or(100.0)
            .min(100.0);
        std::thread::spawn(move || planner_thread(ns, dof, q0, k, stop))
    });
    let out = looper.join();
    stop.store(true, Ordering::Relaxed);
    if let Some(p) = planner {
        let _ = p.join();
    }
    if locked {
        sched::unlock_memory();
    }
    let (jitter, work, cpu_percent, late_ticks, missed_periods, loop_refused) = out
        .map_err(|_| format!("variant {}: the loop thread panicked", v.name))?
        .map_err(|e| format!("variant {}: {e}", v.name))?;
    refused.extend(loop_refused);
    Ok(VariantResult {
        variant: v.clone(),
        jitter,
        work,
        cpu_percent,
        late_ticks,
        missed_periods,
        refused,
        baseline: if v.fifo.is_some() {
            "cyclictest_fifo"
        } else {
            "cyclictest"
        },
        ratio_p99: None,
        ratio_p50: None,
    })
}

/// Runs the chosen variants then cyclictest (default scheduler, and `SCHED_FIFO` 80 when a FIFO
/// variant ran and FIFO is permitted), each for `opts.seconds`.
pub fn run(opts: &Options, mut progress: impl FnMut(&str)) -> Result<Report, String> {
    let all = variants();
    for name in &opts.variants {
        if !all.iter().any(|v| v.name == name) {
            let names: Vec<_> = all.iter().map(|v| v.name).collect();
            return Err(format!(
                "unknown variant \"{name}\"; choose from {}",
                names.join(", ")
            ));
        }
    }
    let chosen: Vec<Variant> = all
        .into_iter()
        .filter(|v| opts.variants.is_empty() || opts.variants.iter().any(|n| n == v.name))
        .collect();
    let plant = load(opts)?;
    let machine = super::Machine::detect();
    let fifo_permitted = sched::fifo_permitted();
    let mut results = Vec::new();
    for v in &chosen {
        progress(&format!(
            "{} ({} s): {}",
            v.name, opts.seconds, v.description
        ));
        results.push(run_variant(&plant, v, opts.seconds)?);
    }
    let mut baselines = Baselines::default();
    let mut note = None;
    if opts.baseline {
        match cyclictest::find() {
            None => {
                note = Some(format!(
                    "cyclictest not found: {}",
                    cyclictest::INSTALL_HINT
                ))
            }
            Some(bin) => {
                let mut o = cyclictest::Options {
                    seconds: opts.seconds,
                    interval_us: PERIOD_NS / 1000,
                    ..Default::default()
                };
                progress(&format!(
                    "cyclictest ({} s), default scheduler",
                    opts.seconds
                ));
                let r = cyclictest::run(&bin, &o)?;
                baselines.cyclictest = Some(BaselineResult {
                    dist: r.histogram.dist(),
                    cpu_percent: r.cpu_percent,
                    command: r.command,
                });
                if fifo_permitted && chosen.iter().any(|v| v.fifo.is_some()) {
                    o.fifo_priority = Some(FIFO_PRIORITY);
                    progress(&format!("cyclictest ({} s), SCHED_FIFO 80", opts.seconds));
                    let r = cyclictest::run(&bin, &o)?;
                    baselines.cyclictest_fifo = Some(BaselineResult {
                        dist: r.histogram.dist(),
                        cpu_percent: r.cpu_percent,
                        command: r.command,
                    });
                }
            }
        }
    } else {
        note = Some("baseline not requested (--no-baseline)".into());
    }
    for r in &mut results {
        let b = if r.baseline == "cyclictest_fifo" {
            &baselines.cyclictest_fifo
        } else {
            &baselines.cyclictest
        };
        r.ratio_p99 = ratio(r.jitter.p99_us, b.as_ref().map(|b| b.dist.p99_us));
        r.ratio_p50 = ratio(r.jitter.p50_us, b.as_ref().map(|b| b.dist.p50_us));
    }
    let head = results
        .iter()
        .find(|r| r.variant.name == HEADLINE)
        .or_else(|| results.first())
        .ok_or("no variant ran")?;
    let baseline = if head.baseline == "cyclictest_fifo" {
        baselines.cyclictest_fifo.clone()
    } else {
        baselines.cyclictest.clone()
    };
    let names: Vec<_> = chosen.iter().map(|v| v.name).collect();
    Ok(Report {
        interval_us: PERIOD_NS / 1000,
        seconds: opts.seconds,
        order: format!(
            "sequential, {} s each: {}, then cyclictest",
            opts.seconds,
            names.join(", ")
        ),
        scenario: opts.config.display().to_string(),
        vic: Headline {
            dist: head.jitter,
            cpu_percent: head.cpu_percent,
            variant: head.variant.name.to_string(),
            work: head.work,
        },
        ratio_p99: head.ratio_p99,
        baseline,
        variants: results,
        baselines,
        baseline_note: note,
        fifo_permitted,
        machine,
    })
}

/// The report as a table.
pub fn print(r: &Report) {
    println!(
        "board loop at {} µs, {} s per run ({}); scenario {}",
        r.interval_us, r.seconds, r.order, r.scenario
    );
    println!("machine: {}", r.machine.line());
    println!(
        "{:<16} {:>8} {:>8} {:>8} {:>9} {:>6} {:>9} {:>9} {:>5}  refused",
        "wake-up [µs]", "p50", "p99", "p99.9", "max", "cpu%", "work p50", "work p99", "late"
    );
    for v in &r.variants {
        println!(
            "{:<16} {:>8.1} {:>8.1} {:>8.1} {:>9.1} {:>6.1} {:>9.2} {:>9.2} {:>5}  {}   ratio p99 {} vs {}",
            v.variant.name,
            v.jitter.p50_us,
            v.jitter.p99_us,
            v.jitter.p999_us,
            v.jitter.max_us,
            v.cpu_percent,
            v.work.p50_us,
            v.work.p99_us,
            v.late_ticks,
            if v.refused.is_empty() {
                "-".to_string()
            } else {
                v.refused.join("; ")
            },
            super::ratio_text(v.ratio_p99),
            v.baseline
        );
    }
    for (name, b) in [
        ("cyclictest", &r.baselines.cyclictest),
        ("cyclictest-fifo", &r.baselines.cyclictest_fifo),
    ] {
        if let Some(b) = b {
            println!(
                "{:<16} {:>8.1} {:>8.1} {:>8.1} {:>9.1} {:>6.1}",
                name, b.dist.p50_us, b.dist.p99_us, b.dist.p999_us, b.dist.max_us, b.cpu_percent
            );
        }
    }
    if let Some(n) = &r.baseline_note {
        println!("baseline: {n}");
    }
    println!(
        "headline: {} p99 {:.1} µs vs cyclictest p99 {} µs: ratio {} (target ≤ 1.5×); tick work p99 {:.2} µs (target < 5 µs)",
        r.vic.variant,
        r.vic.dist.p99_us,
        r.baseline
            .as_ref()
            .map_or("–".into(), |b| format!("{:.1}", b.dist.p99_us)),
        super::ratio_text(r.ratio_p99),
        r.vic.work.p99_us
    );
}
