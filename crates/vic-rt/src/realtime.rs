//! Periodic real-time loops: absolute deadlines on `CLOCK_MONOTONIC` (no drift), 1 ns timer
//! slack, an optional spin before each deadline, missed periods skipped and counted (never caught
//! up in a burst), and fixed-size latency histograms that never allocate while recording.

use crate::board::{Board, Inputs, Outputs, Rejection};
use crate::record::{RecordProducer, Sample};
use crate::transport::{BoardEvent, BoardPorts, Header, Percentiles, Telemetry, monotonic_ns};
use hdrhistogram::Histogram;
use std::sync::atomic::{AtomicBool, Ordering};

/// Sets this thread's timer slack to 1 ns (`prctl(PR_SET_TIMERSLACK, 1)`; no privilege needed).
/// The default 50 µs slack is otherwise the median lateness of every wake-up.
pub fn set_timer_slack_1ns() -> bool {
    // SAFETY: prctl with PR_SET_TIMERSLACK takes one integer argument and touches no memory.
    unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) == 0 }
}

/// Tries to lock the process's memory (`mlockall`); a failure is only a warning for callers.
pub fn lock_memory() -> bool {
    // SAFETY: mlockall takes flags only.
    unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) == 0 }
}

/// Sleeps until the monotonic time `deadline_ns` (absolute, so no drift accumulates), then spins
/// the last `spin_ns` if asked.
pub fn sleep_until(deadline_ns: u64, spin_ns: u64) {
    sleep_until_preparing(deadline_ns, spin_ns, || {});
}

/// [`sleep_until`], running `prepare` once at the start of the spin when there is one and the
/// deadline has not passed: work that may be done before the deadline, done in time the thread
/// would otherwise spend polling the clock. Without a spin `prepare` does not run.
pub fn sleep_until_preparing(deadline_ns: u64, spin_ns: u64, prepare: impl FnOnce()) {
    let wake = deadline_ns.saturating_sub(spin_ns);
    let ts = libc::timespec {
        tv_sec: (wake / 1_000_000_000) as libc::time_t,
        tv_nsec: (wake % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: `ts` is a valid timespec; a null remainder is allowed with TIMER_ABSTIME.
        let r = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        if r != libc::EINTR {
            break;
        }
    }
    if spin_ns > 0 {
        if monotonic_ns() < deadline_ns {
            prepare();
        }
        while monotonic_ns() < deadline_ns {
            std::hint::spin_loop();
        }
    }
}

/// What one wake-up of a [`Periodic`] loop looked like.
#[derive(Debug, Clone, Copy, Default)]
pub struct Wake {
    /// The deadline this tick was for [ns, monotonic].
    pub deadline_ns: u64,
    /// When the thread actually ran [ns, monotonic].
    pub woke_ns: u64,
    /// `woke − deadline` [ns].
    pub lateness_ns: u64,
    /// Whole periods skipped because the wake-up came after the next deadline.
    pub skipped: u64,
}

/// An absolute-deadline periodic schedule.
#[derive(Debug, Clone)]
pub struct Periodic {
    pub period_ns: u64,
    pub spin_ns: u64,
    next_ns: u64,
    /// Ticks that woke more than one period late, and the periods they skipped.
    pub late_ticks: u64,
    pub skipped_periods: u64,
}

impl Periodic {
    /// A schedule with deadlines at whole multiples of `period_ns`, starting at the next one.
    pub fn new(period_ns: u64, spin_ns: u64) -> Self {
        let now = monotonic_ns();
        Periodic {
            period_ns,
            spin_ns: spin_ns.min(period_ns / 2),
            next_ns: (now / period_ns + 1) * period_ns,
            late_ticks: 0,
            skipped_periods: 0,
        }
    }

    /// The deadline the next [`Periodic::wait`] waits for [ns, monotonic].
    pub fn next_deadline(&self) -> u64 {
        self.next_ns
    }

    /// Waits for the next deadline. A wake-up later than a whole period skips the missed
    /// deadlines: the next one is the first still in the future.
    pub fn wait(&mut self) -> Wake {
        self.wait_preparing(|| {})
    }

    /// [`Periodic::wait`], running `prepare` in the spin before the deadline
    /// ([`sleep_until_preparing`]). The wake-up is taken after it, so a `prepare` that ran past
    /// the deadline shows as lateness.
    pub fn wait_preparing(&mut self, prepare: impl FnOnce()) -> Wake {
        let deadline = self.next_ns;
        sleep_until_preparing(deadline, self.spin_ns, prepare);
        let woke = monotonic_ns();
        let lateness = woke.saturating_sub(deadline);
        let skipped = lateness / self.period_ns;
        if skipped > 0 {
            self.late_ticks += 1;
            self.skipped_periods += skipped;
        }
        self.next_ns = deadline + (skipped + 1) * self.period_ns;
        Wake {
            deadline_ns: deadline + skipped * self.period_ns,
            woke_ns: woke,
            lateness_ns: lateness,
            skipped,
        }
    }
}

/// A latency histogram in ns with fixed bounds (1 ns to 60 s, 3 significant digits), allocated
/// once: recording saturates instead of resizing, so it never allocates.
pub struct LatencyHistogram {
    h: Histogram<u64>,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self::new()
    }
}

impl LatencyHistogram {
    pub fn new() -> Self {
        let mut h = Histogram::new_with_bounds(1, 60_000_000_000, 3).expect("valid bounds");
        h.auto(false);
        LatencyHistogram { h }
    }
    /// Records a value in ns (allocation-free).
    #[inline]
    pub fn record(&mut self, ns: u64) {
        self.h.saturating_record(ns.max(1));
    }
    pub fn count(&self) -> u64 {
        self.h.len()
    }
    /// p50, p99, p99.9 and max in µs.
    pub fn percentiles(&self) -> Percentiles {
        if self.h.is_empty() {
            return Percentiles::default();
        }
        let us = |v: u64| v as f64 / 1000.0;
        Percentiles {
            p50: us(self.h.value_at_quantile(0.5)),
            p99: us(self.h.value_at_quantile(0.99)),
            p999: us(self.h.value_at_quantile(0.999)),
            max: us(self.h.max()),
            count: self.h.len(),
        }
    }
    pub fn reset(&mut self) {
        self.h.reset();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn periodic_loop_keeps_its_deadlines() {
        set_timer_slack_1ns();
        let mut p = Periodic::new(1_000_000, 0);
        let mut h = LatencyHistogram::new();
        let first = p.wait();
        // The first wake-up may itself have skipped periods (a loaded machine): they lie before
        // `first.deadline_ns`.
        let skipped_before = p.skipped_periods;
        let mut last = first.deadline_ns;
        for _ in 0..50 {
            let w = p.wait();
            assert_eq!((w.deadline_ns - last) % 1_000_000, 0);
            assert!(w.deadline_ns > last);
            last = w.deadline_ns;
            h.record(w.lateness_ns);
        }
        // No drift: 50 ticks later the deadline is 50 periods on, plus any skipped.
        assert_eq!(
            last - first.deadline_ns,
            (50 + p.skipped_periods - skipped_before) * 1_000_000
        );
        assert_eq!(h.count(), 50);
        assert!(h.percentiles().p50 >= 0.0);
    }

    #[test]
    fn the_spin_runs_its_preparation_once_before_the_deadline() {
        set_timer_slack_1ns();
        // With a spin: at most once, before the deadline, and the wake-up comes after both. A
        // sleep that returned past the deadline (a loaded machine) leaves no time for it.
        let mut p = Periodic::new(1_000_000, 200_000);
        let mut prepared = 0;
        for _ in 0..20 {
            let (deadline, mut ran) = (p.next_deadline(), Vec::new());
            let w = p.wait_preparing(|| ran.push(monotonic_ns()));
            assert!(ran.len() <= 1);
            if let Some(&at) = ran.first() {
                assert!(at < deadline, "prepared at {at} for {deadline}");
                assert!(w.woke_ns >= deadline);
                prepared += 1;
            }
        }
        assert!(prepared > 0, "no wake-up of 20 came before its deadline");
        // Without a spin the preparation never runs: there is no time before the deadline.
        let mut p = Periodic::new(1_000_000, 0);
        let mut ran = 0;
        for _ in 0..5 {
            p.wait_preparing(|| ran += 1);
        }
        assert_eq!(ran, 0);
        // A deadline already past: no time left, no preparation.
        let mut ran = false;
        sleep_until_preparing(monotonic_ns().saturating_sub(1_000_000), 100_000, || {
            ran = true
        });
        assert!(!ran);
    }

    #[test]
    fn histogram_saturates_instead_of_growing() {
        let mut h = LatencyHistogram::new();
        h.record(u64::MAX);
        h.record(0);
        assert_eq!(h.count(), 2);
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
    pub command_age: LatencyHistogram,
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
