//! One variant of `vic bench loop`: the board's loop thread at 1 kHz with its real work, fed by a
//! 50 Hz planner stand-in over the real transport.

use super::{Options, PERIOD_NS, Variant, VariantResult, board_config};
use crate::bench::{BenchError, Dist};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::Sender;
use vic_plan::scenario::Scenario;
use vic_rt::board::live::{BoardHistograms, board_tick, board_wait};
use vic_rt::board::{Board, Inputs};
use vic_rt::realtime::{Periodic, set_timer_slack_1ns};
use vic_rt::sched::{self, SchedPolicy, lock_memory};
use vic_rt::transport::{
    BoardPorts, CentralPorts, CommandSlice, Control, ControlKind, Header, MAX_JOINTS, MAX_KNOTS,
    monotonic_ns, remove_namespace,
};

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
pub(super) struct Plant {
    scenario: Scenario,
    q0: Vec<f64>,
}

pub(super) fn load(opts: &Options) -> Result<Plant, BenchError> {
    let scenario = Scenario::load(&opts.config, &opts.overrides)?;
    let setup = vic_plan::plan::setup(&scenario)?;
    let dof = scenario.model.dof();
    let q0 = setup.x0[..dof].to_vec();
    // Fail early (bad actuator) rather than inside a thread.
    Board::new(
        scenario.model.clone(),
        board_config(&scenario, PERIOD_NS),
        &q0,
    )?;
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
pub(super) fn run_variant(
    plant: &Plant,
    v: &Variant,
    seconds: u64,
) -> Result<VariantResult, BenchError> {
    let ns = crate::bench::unique_namespace("bl");
    let result = run_variant_in(plant, v, seconds, &ns);
    remove_namespace(&ns);
    result
}

fn run_variant_in(
    plant: &Plant,
    v: &Variant,
    seconds: u64,
    ns: &str,
) -> Result<VariantResult, BenchError> {
    let mut refused = Vec::new();
    let locked = v.mlock && lock_memory();
    if v.mlock && !locked {
        refused.push(format!("mlockall: {}", std::io::Error::last_os_error()));
    }
    let stop = Arc::new(AtomicBool::new(false));
    let (ready_tx, ready_rx) = std::sync::mpsc::channel::<()>();
    let looper = {
        let (scenario, q0, variant) = (plant.scenario.clone(), plant.q0.clone(), v.clone());
        let (ns, stop) = (ns.to_string(), stop.clone());
        std::thread::spawn(move || {
            let figures = measure_loop(&ns, &scenario, &q0, &variant, seconds, ready_tx);
            stop.store(true, Ordering::Relaxed);
            figures
        })
    };
    // The planner connects once the board's subscribers exist, so the reset is not lost.
    let planner = ready_rx.recv().is_ok().then(|| {
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
    let figures = out
        .map_err(|_| BenchError::Panicked("loop"))
        .and_then(|r| r)
        .map_err(|e| BenchError::Variant {
            name: v.name,
            source: Box::new(e),
        })?;
    refused.extend(figures.refused);
    Ok(VariantResult {
        variant: v.clone(),
        jitter: figures.jitter,
        work: figures.work,
        cpu_percent: figures.cpu_percent,
        late_ticks: figures.late_ticks,
        missed_periods: figures.missed_periods,
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

/// What the loop thread measured over its window.
struct LoopFigures {
    jitter: Dist,
    work: Dist,
    cpu_percent: f64,
    late_ticks: u64,
    missed_periods: u64,
    /// Options of the variant the system refused.
    refused: Vec<String>,
}

/// The loop thread: applies the variant's options, opens the board's ports (then says `ready`),
/// warms up for 200 ms and measures `seconds` of deadlines.
fn measure_loop(
    ns: &str,
    scenario: &Scenario,
    q0: &[f64],
    variant: &Variant,
    seconds: u64,
    ready: Sender<()>,
) -> Result<LoopFigures, BenchError> {
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
    let ep = BoardPorts::open(ns)?;
    let mut board = Board::new(
        scenario.model.clone(),
        board_config(scenario, PERIOD_NS),
        q0,
    )?;
    let _ = ready.send(());
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
        let w = board_wait(&mut periodic, &ep, &mut inputs);
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
        let w = board_wait(&mut periodic, &ep, &mut inputs);
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
    Ok(LoopFigures {
        jitter: Dist::from_histogram(&hist.jitter),
        work: Dist::from_histogram(&hist.work),
        cpu_percent: 100.0 * cpu as f64 / wall.max(1) as f64,
        late_ticks: periodic.late_ticks,
        missed_periods: periodic.skipped_periods,
        refused,
    })
}
