//! The central controller against a live board: trials streamed at the planner period, every
//! reset checked for its acknowledgement, and a board that stops answering told apart from a
//! movement that went wrong.

use super::{Central, TrialRecord};
use crate::realtime::Periodic;
use crate::transport::{CentralPorts, TransportError, monotonic_ns};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How long a reset may go unacknowledged (no state carrying its `reset_seq`) [ns].
pub(crate) const RESET_ACK_DEADLINE_NS: u64 = 500_000_000;
/// The board is lost when no state at all arrived for this many planner periods, and at least
/// this long [ns]: it publishes one every millisecond, so a pause this long is no scheduling hiccup.
pub(crate) const BOARD_LOST_PERIODS: u64 = 10;
pub(crate) const BOARD_LOST_MIN_NS: u64 = 200_000_000;

/// Why a live run stopped before its last trial. The trials finished before are kept.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    #[error(transparent)]
    Transport(#[from] TransportError),
    /// The board stopped publishing states (killed, stopped, its namespace removed).
    #[error("board lost: no state from the board for {silent_ms} ms during trial {trial}")]
    BoardLost {
        trial: u32,
        silent_ms: u64,
        records: Vec<TrialRecord>,
    },
    /// The board published states but none acknowledged the trial's reset.
    #[error(
        "board lost: the reset of trial {trial} was not acknowledged within {deadline_ms} ms \
         (a board publishes states but ignores this controller's resets)"
    )]
    ResetNotAcknowledged {
        trial: u32,
        deadline_ms: u64,
        records: Vec<TrialRecord>,
    },
}

impl LiveError {
    /// The trials finished before the run stopped.
    pub fn records(&self) -> &[TrialRecord] {
        match self {
            LiveError::Transport(_) => &[],
            LiveError::BoardLost { records, .. }
            | LiveError::ResetNotAcknowledged { records, .. } => records,
        }
    }
}

/// Runs `trials` trials live: waits for a board in the namespace, then for each trial resets it,
/// checks the reset is acknowledged, streams the slices at the planner period and collects the
/// states until the movement's end. The `replan` strategy re-solves on a worker thread
/// ([`Central::replan_in_background`]). Stops with [`LiveError::BoardLost`] when the board falls
/// silent, keeping the trials finished before.
pub fn run_live(
    ep: &CentralPorts,
    central: &mut Central,
    trials: usize,
    seed: u64,
    planner_period_ns: u64,
    board_timeout: Duration,
    stop: &AtomicBool,
) -> Result<Vec<TrialRecord>, LiveError> {
    crate::realtime::set_timer_slack_1ns();
    // Live, a re-solve may take longer than the period: it runs beside the loop.
    central.replan_in_background(false);
    let mut records = Vec::with_capacity(trials);
    let lost_after = (BOARD_LOST_PERIODS * planner_period_ns).max(BOARD_LOST_MIN_NS);
    for trial in 0..trials as u32 {
        if trial == 0 {
            wait_for_board(ep, board_timeout, stop)?;
        }
        let now = monotonic_ns();
        // Start on a whole millisecond, once the first slice has crossed the command line.
        let start = (now + central.controller.lead_time_ns(planner_period_ns) + 20_000_000)
            / 1_000_000
            * 1_000_000;
        ep.publish_control(&central.begin_trial(trial, seed, start, now))?;
        let limit = start
            + central.controller.track.steps as u64 * central.controller.track.dt_ns
            + 2_000_000_000;
        let watch = Watch {
            reset_ns: now,
            lost_after_ns: lost_after,
        };
        let end = stream_trial(ep, central, planner_period_ns, limit, stop, &watch)?;
        ep.publish_control(&central.controller.stop(monotonic_ns()))?;
        match end {
            TrialEnd::Done | TrialEnd::Stalled => records.push(central.controller.record()),
            TrialEnd::Silent { silent_ns } => {
                return Err(LiveError::BoardLost {
                    trial,
                    silent_ms: silent_ns / 1_000_000,
                    records,
                });
            }
            TrialEnd::Unacknowledged => {
                return Err(LiveError::ResetNotAcknowledged {
                    trial,
                    deadline_ms: RESET_ACK_DEADLINE_NS / 1_000_000,
                    records,
                });
            }
        }
        if stop.load(Ordering::Relaxed) {
            break;
        }
    }
    Ok(records)
}

/// Waits for a board's telemetry (woken by its events rather than polling), up to `timeout` or
/// until `stop`.
fn wait_for_board(
    ep: &CentralPorts,
    timeout: Duration,
    stop: &AtomicBool,
) -> Result<(), TransportError> {
    let t0 = Instant::now();
    while ep.wait_for_telemetry(Duration::from_millis(100)).is_none() {
        if t0.elapsed() > timeout || stop.load(Ordering::Relaxed) {
            return Err(TransportError::NoBoard {
                namespace: ep.session().namespace().to_string(),
            });
        }
    }
    Ok(())
}

/// The deadlines a trial is watched with.
struct Watch {
    /// When the reset was published [monotonic ns].
    reset_ns: u64,
    /// Silence after which the board is lost [ns].
    lost_after_ns: u64,
}

/// How a trial's loop ended.
enum TrialEnd {
    /// The final state arrived (or the board faulted).
    Done,
    /// The time limit or a stop request came first: the record says what arrived.
    Stalled,
    /// No state at all for `silent_ns`.
    Silent { silent_ns: u64 },
    /// States arrived, none acknowledging the reset, until the deadline.
    Unacknowledged,
}

/// One trial's loop at the planner period: feed the states received to `central`, publish the
/// slices it asks for, until the trial is done, the monotonic time `limit` passes, `stop`, or
/// the board falls silent.
fn stream_trial(
    ep: &CentralPorts,
    central: &mut Central,
    planner_period_ns: u64,
    limit: u64,
    stop: &AtomicBool,
    watch: &Watch,
) -> Result<TrialEnd, TransportError> {
    let mut periodic = Periodic::new(planner_period_ns, 0);
    let mut out = Vec::new();
    let mut last_state_ns = watch.reset_ns;
    loop {
        let wake = periodic.wait();
        let now = monotonic_ns();
        if ep.drain_states(|s| central.controller.on_state(s, now)) > 0 {
            last_state_ns = now;
        }
        // Done before sending: a slice published now would reach the board in the same tick
        // as the stop that follows, be checked after it (controls go first) and be rejected as
        // `wrong-trial`, one counted rejection per trial for slices past the movement's end.
        if central.controller.trial_done() {
            return Ok(TrialEnd::Done);
        }
        let silent = now.saturating_sub(last_state_ns);
        if silent > watch.lost_after_ns {
            central.controller.stalled = true;
            return Ok(TrialEnd::Silent { silent_ns: silent });
        }
        if !central.controller.acknowledged()
            && now.saturating_sub(watch.reset_ns) > RESET_ACK_DEADLINE_NS
        {
            return Ok(TrialEnd::Unacknowledged);
        }
        out.clear();
        central.poll(wake.deadline_ns.max(now), &mut out);
        for c in &out {
            ep.publish_command(c)?;
        }
        if !out.is_empty() {
            central.controller.sent(&out, monotonic_ns());
        }
        if now > limit || stop.load(Ordering::Relaxed) {
            central.controller.stalled = true;
            return Ok(TrialEnd::Stalled);
        }
    }
}
