//! The board and the central controller in lockstep on a simulated clock.

use super::{Central, TrialRecord};
use crate::board::{Board, Inputs};

/// Runs `trials` trials of the board and the central controller in lockstep on a simulated clock
/// (no sleeping, deterministic): the board ticks every `board.period`, the controller every
/// `planner_period_ns`, messages arrive instantly (the delay lines still apply).
pub fn lockstep(
    board: &mut Board,
    central: &mut Central,
    board_period_ns: u64,
    planner_period_ns: u64,
    trials: usize,
    seed: u64,
) -> Vec<TrialRecord> {
    let on_time = |now: u64, _: u64| now.is_multiple_of(planner_period_ns);
    lockstep_polled(
        board,
        central,
        (board_period_ns, planner_period_ns),
        trials,
        seed,
        &on_time,
    )
}

/// [`lockstep`], the controller polled at the board ticks where `polls(now, start)` (the
/// simulated time and the trial's start): at every planner tick on schedule; a test or a study
/// moves a poll later, as a live planner that woke late does (`tests/late_knots.rs`).
pub fn lockstep_polled(
    board: &mut Board,
    central: &mut Central,
    (board_period_ns, planner_period_ns): (u64, u64),
    trials: usize,
    seed: u64,
    polls: &dyn Fn(u64, u64) -> bool,
) -> Vec<TrialRecord> {
    // Simulated time: the real clock still measures the compute time, but decides no overrun.
    central.real_clock_overruns = false;
    let mut now: u64 = 1_000_000_000;
    let mut inputs = Inputs::default();
    let mut out = Vec::new();
    let mut records = Vec::with_capacity(trials);
    for trial in 0..trials as u32 {
        let start = (now + central.controller.lead_time_ns(planner_period_ns))
            .div_ceil(board_period_ns)
            * board_period_ns;
        let reset = central.begin_trial(trial, seed, start, now);
        inputs.push_control(&reset);
        let limit =
            start + (central.controller.track.steps as u64 + 50) * central.controller.track.dt_ns;
        while now < limit {
            if polls(now, start) {
                out.clear();
                central.poll(now, &mut out);
                for c in &out {
                    inputs.push_command(c);
                }
                central.controller.sent(&out, now);
            }
            let o = board.step(now, &mut inputs);
            central.controller.on_state(&o.state, now);
            now += board_period_ns;
            if central.controller.trial_done() {
                break;
            }
        }
        inputs.push_control(&central.controller.stop(now));
        board.step(now, &mut inputs);
        now += board_period_ns;
        now = now.div_ceil(planner_period_ns) * planner_period_ns;
        records.push(central.controller.record());
    }
    records
}
