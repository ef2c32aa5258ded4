//! The board's live runner: [`Board::step`] driven at its period by a [`Periodic`] loop, its
//! inputs drained from the transport, its state and telemetry published, every tick optionally
//! recorded, and the figures of the run reported at the end. The board itself stays a pure state
//! machine; this is the thin runtime around it (clock, ports, histograms).

use super::{Board, Inputs, Outputs, Rejection};
use crate::realtime::{LatencyHistogram, Periodic, Wake, set_timer_slack_1ns};
use crate::record::{RecordProducer, Sample};
use crate::transport::{BoardEvent, BoardPorts, Header, Percentiles, Telemetry, monotonic_ns};
use std::sync::atomic::{AtomicBool, Ordering};

/// The sample of a board step, made here so that `record` needs nothing of the board (the
/// board's runner uses `record`).
impl Sample {
    /// The sample of loop tick `tick` at `deadline_ns`, from what [`Board::step`] returned.
    /// Allocation-free.
    pub fn from_step(tick: u64, deadline_ns: u64, board: &Board, out: &Outputs) -> Sample {
        let s = &out.state;
        Sample {
            tick,
            dropped_before: 0,
            deadline_ns,
            trial: s.trial,
            mode: s.mode,
            trial_time_ns: s.trial_time_ns,
            periods: out.periods,
            command_seq: s.command_seq,
            disturbance_seq: s.disturbance_seq,
            q: s.q,
            qd: s.qd,
            qdd: out.qdd,
            tau: s.tau,
            tau_ext: s.tau_ext,
            tau_ff: out.knot.tau_ff,
            stiffness: out.knot.stiffness,
            damping: board.damping(&out.knot.stiffness),
            q_d: out.knot.q_d,
            qd_d: out.knot.qd_d,
        }
    }
}

/// Options of the live board loop.
#[derive(Debug, Clone)]
pub struct BoardLoopOptions {
    /// Spin the last part of each period [ns] (0: sleep only).
    pub spin_ns: u64,
    /// Publish telemetry every this many ticks (default 100: 10 Hz at 1 kHz).
    pub telemetry_every: u64,
    /// Stop after this many ticks (0: run until stopped).
    pub max_ticks: u64,
}

impl Default for BoardLoopOptions {
    fn default() -> Self {
        BoardLoopOptions {
            spin_ns: 0,
            telemetry_every: 100,
            max_ticks: 0,
        }
    }
}

/// The figures of a board run, for the final report.
#[derive(Debug, Clone, serde::Serialize)]
pub struct BoardStats {
    pub ticks: u64,
    pub late_ticks: u64,
    pub missed_periods: u64,
    pub rejected_messages: u64,
    /// Rejected messages by reason (only reasons that occurred).
    pub rejected_by_reason: std::collections::BTreeMap<String, u64>,
    /// Messages lost before the board saw them (sequence gaps within a sender session).
    pub dropped_messages: u64,
    pub safe_hold_ticks: u64,
    pub watchdog_trips: u64,
    pub faults: u64,
    pub lost_periods: u64,
    /// Dead nodes (killed processes) whose iceoryx2 resources the board removed at start.
    pub cleaned_dead_nodes: usize,
    pub jitter_us: PercentilesJson,
    pub work_us: PercentilesJson,
    pub command_age_us: PercentilesJson,
    /// Ticks recorded and dropped by `--record` (None without a recording).
    pub recorded: Option<u64>,
    pub dropped: Option<u64>,
    /// The real-time settings in force for the loop (filled in by the daemon that applied them).
    pub realtime: Option<crate::sched::RtSettings>,
}

/// [`Percentiles`] in JSON reports [µs]: the wire type serialises as it is.
pub type PercentilesJson = Percentiles;

/// The histograms a board loop fills.
#[derive(Default)]
pub struct BoardHistograms {
    pub jitter: LatencyHistogram,
    pub work: LatencyHistogram,
    pub(crate) command_age: LatencyHistogram,
}

/// One tick of the live board: drain the transport into `inputs`, step, publish the state. No
/// allocation, lock, I/O or logging (the transport's shared-memory calls excepted).
pub fn board_tick(
    ep: &BoardPorts,
    board: &mut Board,
    inputs: &mut Inputs,
    wake: &Wake,
    seq: u64,
    hist: &mut BoardHistograms,
) -> Outputs {
    drain_inputs(ep, inputs);
    inputs.received_ns = monotonic_ns();
    let out = board.step(wake.deadline_ns, inputs);
    let mut s = out.state;
    s.header = Header::new(seq, monotonic_ns());
    // A failed publish (no subscriber memory) is not a reason to stop the plant.
    let _ = ep.publish_state(&s);
    if board.applied() {
        // The acknowledgement is in the state just published; wake whoever waits for it.
        ep.notify(BoardEvent::Applied);
    }
    hist.jitter.record(wake.lateness_ns);
    if let Some(age) = out.command_age_ns {
        hist.command_age.record(age);
    }
    hist.work
        .record(monotonic_ns().saturating_sub(wake.woke_ns));
    out
}

/// Takes every message waiting on the board's three subscriptions into `inputs`.
fn drain_inputs(ep: &BoardPorts, inputs: &mut Inputs) {
    ep.drain_controls(|c| inputs.push_control(c));
    ep.drain_disturbances(|d| inputs.push_disturbance(d));
    ep.drain_commands(|c| inputs.push_command(c));
}

/// The board's wait for its next tick: with a spin before the deadline, the messages that have
/// arrived by then are taken in the spin ([`Periodic::wait_preparing`]), so that the tick, which
/// takes the ones that arrive after them, starts from caches the subscriptions have just warmed
/// instead of from cold shared memory. A message is applied at the same tick either way: both
/// takes come before the step of this deadline.
pub fn board_wait(periodic: &mut Periodic, ep: &BoardPorts, inputs: &mut Inputs) -> Wake {
    periodic.wait_preparing(|| drain_inputs(ep, inputs))
}

/// The telemetry of the board after tick `tick` (its step gave `out`).
fn telemetry(
    board: &Board,
    out: &Outputs,
    hist: &BoardHistograms,
    periodic: &Periodic,
    header: Header,
    tick: u64,
    tick_rate_hz: f64,
) -> Telemetry {
    let (disturbance_seq, disturbance_tick) = board.last_disturbance();
    Telemetry {
        header,
        mode: board.mode() as u32,
        tick,
        tick_rate_hz,
        jitter_us: hist.jitter.percentiles(),
        work_us: hist.work.percentiles(),
        command_age_us: hist.command_age.percentiles(),
        late_ticks: periodic.late_ticks,
        missed_periods: periodic.skipped_periods,
        rejected_messages: board.counters.rejected,
        safe_hold_ticks: board.counters.safe_hold_ticks,
        tracking_error: out.tracking_error,
        stiffness: board.stiffness(),
        tau_ext: out.state.tau_ext,
        field_beta: board.field_beta(),
        noise_factor: board.noise_factor(),
        trial: board.trial(),
        joints: out.state.joints,
        rejected_by_reason: board.counters.rejected_by,
        fault_reason: board.fault() as u32,
        watchdog_trips: board.counters.watchdog_trips,
        disturbance_seq,
        disturbance_tick,
        dropped_messages: board.counters.dropped,
    }
}

/// Runs the board at its period until `stop` is set (checked at the end of every tick). With
/// `record`, every tick is pushed to the recording queue (allocation-free; a full queue drops
/// the tick and the file marks the gap).
pub fn run_board(
    ep: &BoardPorts,
    board: &mut Board,
    period_ns: u64,
    opts: &BoardLoopOptions,
    stop: &AtomicBool,
    mut record: Option<&mut RecordProducer>,
) -> BoardStats {
    set_timer_slack_1ns();
    let mut hist = BoardHistograms::default();
    let mut inputs = Inputs::default();
    let mut periodic = Periodic::new(period_ns, opts.spin_ns);
    let mut seq = 0u64;
    let mut telemetry_seq = 0u64;
    let mut last_telemetry = (monotonic_ns(), 0u64);
    while !stop.load(Ordering::Relaxed) {
        let wake = board_wait(&mut periodic, ep, &mut inputs);
        seq += 1;
        let out = board_tick(ep, board, &mut inputs, &wake, seq, &mut hist);
        if let Some(r) = record.as_deref_mut() {
            r.push(&Sample::from_step(seq, wake.deadline_ns, board, &out));
        }
        if seq.is_multiple_of(opts.telemetry_every.max(1)) {
            let now = monotonic_ns();
            let rate =
                (seq - last_telemetry.1) as f64 * 1e9 / (now - last_telemetry.0).max(1) as f64;
            last_telemetry = (now, seq);
            telemetry_seq += 1;
            let header = Header::new(telemetry_seq, now);
            let t = telemetry(board, &out, &hist, &periodic, header, seq, rate);
            let _ = ep.publish_telemetry(&t);
            ep.notify(BoardEvent::Telemetry);
        }
        if opts.max_ticks > 0 && seq >= opts.max_ticks {
            break;
        }
    }
    BoardStats {
        ticks: seq,
        late_ticks: periodic.late_ticks,
        missed_periods: periodic.skipped_periods,
        rejected_messages: board.counters.rejected,
        rejected_by_reason: rejections_by_name(&board.counters.rejected_by),
        dropped_messages: board.counters.dropped,
        safe_hold_ticks: board.counters.safe_hold_ticks,
        watchdog_trips: board.counters.watchdog_trips,
        faults: board.counters.faults,
        lost_periods: board.counters.lost_periods,
        cleaned_dead_nodes: ep.session().cleaned_dead_nodes(),
        jitter_us: hist.jitter.percentiles(),
        work_us: hist.work.percentiles(),
        command_age_us: hist.command_age.percentiles(),
        recorded: record.as_ref().map(|r| r.pushed()),
        dropped: record.as_ref().map(|r| r.dropped()),
        realtime: None,
    }
}

/// Rejection counts by reason name, leaving out reasons that never occurred.
pub fn rejections_by_name(
    counts: &[u64; Rejection::COUNT],
) -> std::collections::BTreeMap<String, u64> {
    Rejection::ALL
        .iter()
        .filter(|r| counts[**r as usize] > 0)
        .map(|r| (r.name().to_string(), counts[*r as usize]))
        .collect()
}
