//! The board and the central controller in lockstep on a simulated clock.

use super::{Central, TrialRecord};
use crate::rt::board::{Board, Inputs};

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
    run(
        board,
        central,
        (board_period_ns, planner_period_ns),
        trials,
        seed,
        &on_time,
    )
}

/// [`lockstep`], the controller polled at the board ticks where `polls(now, start)` (the
/// simulated time and the trial's start): at every planner tick on schedule; tests move a poll
/// later, as a live planner that woke late does.
fn run(
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
        let start = (now + central.lead_time_ns(planner_period_ns)).div_ceil(board_period_ns)
            * board_period_ns;
        let reset = central.begin_trial(trial, seed, start, now);
        inputs.push_control(&reset);
        let limit = start + (central.track.steps as u64 + 50) * central.track.dt_ns;
        while now < limit {
            if polls(now, start) {
                out.clear();
                central.poll(now, &mut out);
                for c in &out {
                    inputs.push_command(c);
                }
                central.sent(&out, now);
            }
            let o = board.step(now, &mut inputs);
            central.on_state(&o.state, now);
            now += board_period_ns;
            if central.trial_done() {
                break;
            }
        }
        inputs.push_control(&central.stop(now));
        board.step(now, &mut inputs);
        now += board_period_ns;
        now = now.div_ceil(planner_period_ns) * planner_period_ns;
        records.push(central.record());
    }
    records
}

#[cfg(test)]
mod a_late_planner {
    //! What the live sweep's comparison with lockstep rests on: a planner that wakes late sends
    //! its slices after the board needed them, and the board acts on the knot before in their
    //! place (within the watchdog time, no safe hold). Even the open-loop plan then ends
    //! elsewhere, with every state on its knot: only `late_knots` says so.

    use super::*;
    use crate::core::policy::Strategy;
    use crate::planning::plan::{Method, plan, setup};
    use crate::planning::scenario::Scenario;
    use crate::rt::central::{Timing, Track, split_latency_ms};

    const PLANNER: u64 = 20_000_000;
    const BOARD: u64 = 1_000_000;

    /// One noise-free open-loop (`stiffness`) trial of the single joint at 100 ms, the planner
    /// polled where `polls(now, start)`.
    fn trial(polls: &dyn Fn(u64, u64) -> bool) -> TrialRecord {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/single_joint_delay.toml");
        let s = Scenario::load(&path, &["noise.sigma=0".into(), "task.delay_ms=0".into()])
            .expect("scenario");
        let set = setup(&s).expect("setup");
        let p = plan(&s, Method::Ilqg, None).expect("plan");
        let track = Track::new(
            p.policy(&set).expect("policy"),
            set.dynamics.clone(),
            set.cost.clone(),
            set.x0.as_slice(),
        )
        .expect("track");
        let lookahead_ms = 2.0 * PLANNER as f64 * 1e-6;
        let (sensor, command) = split_latency_ms(100.0, lookahead_ms);
        let timing = Timing {
            latency_steps: 10,
            sensor_latency_ns: (sensor * 1e6) as u64,
            command_latency_ns: (command * 1e6) as u64,
            lookahead_ns: (lookahead_ms * 1e6) as u64,
        };
        let mut central = Central::new(track, Strategy::Stiffness, timing);
        let cfg = crate::tools::launch::board_config(&s, BOARD);
        let mut board = Board::new(s.model.clone(), cfg, set.x0.as_slice()).expect("board");
        let mut records = run(&mut board, &mut central, (BOARD, PLANNER), 1, 1, polls);
        records.pop().expect("one trial")
    }

    /// Polls on schedule, except that the planner ticks of trial time `[from_ms, to_ms)`
    /// (negative before the start) are replaced by one poll at `at_ms`.
    fn late_wake(from_ms: i64, to_ms: i64, at_ms: i64) -> impl Fn(u64, u64) -> bool {
        move |now, start| {
            let t = (now as i64 - start as i64) / 1_000_000;
            match now.is_multiple_of(PLANNER) {
                _ if t == at_ms => true,
                true => !(from_ms..to_ms).contains(&t),
                false => false,
            }
        }
    }

    /// The counts that said nothing of a late slice before `late_knots`.
    fn on_schedule_otherwise(r: &TrialRecord) {
        assert_eq!(
            (r.stale_feedback, r.missing_states, r.off_knot_states),
            (0, 0, 0)
        );
        assert!(
            !(r.safe_hold || r.fault || r.stalled),
            "a safe hold is counted already"
        );
    }

    #[test]
    fn is_counted_in_late_knots_and_moves_the_open_loop_plant() {
        let on_time = trial(&|now, _| now.is_multiple_of(PLANNER));
        on_schedule_otherwise(&on_time);
        assert_eq!(on_time.late_knots, 0);
        let n = on_time.x.len() - 1;
        // A wake 5 ms late: the lookahead covers it.
        let early = trial(&late_wake(400, 420, 405));
        on_schedule_otherwise(&early);
        assert_eq!(early.late_knots, 0);
        assert_eq!(early.x[n], on_time.x[n]);
        // 25 ms late: the slice due at 400 ms goes out at 425 ms with knot 42 (at 420 ms), and
        // the slice queued then misses the 440 ms tick: knots 44 and 45 go out at 460 ms. The
        // board held knot 41, then 43 in their place; no 50 ms went without a slice.
        let late = trial(&late_wake(400, 440, 425));
        on_schedule_otherwise(&late);
        assert_eq!(late.late_knots, 3);
        assert_ne!(
            late.x[n], on_time.x[n],
            "the open-loop plant should have moved"
        );
        // Asleep from the reset to 5 ms after the start: knot 0 is never sent, knots 1 to 3 go
        // out at 40 ms; the board held the reset state meanwhile.
        let start = trial(&late_wake(-60, 20, 5));
        on_schedule_otherwise(&start);
        assert_eq!(start.late_knots, 4);
        assert_ne!(start.x[n], on_time.x[n]);
    }
}
