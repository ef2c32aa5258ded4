//! What the live sweep's comparison with lockstep rests on: a planner that wakes late sends
//! its slices after the board needed them, and the board acts on the knot before in their
//! place (within the watchdog time, no safe hold). Even the open-loop plan then ends
//! elsewhere, with every state on its knot: only `late_knots` says so.

use vic_core::policy::Strategy;
use vic_plan::plan::{Method, plan, setup};
use vic_plan::scenario::Scenario;
use vic_rt::board::Board;
use vic_rt::central::{Central, Latency, Timing, Track, TrialRecord, lockstep_polled};

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
    let timing = Timing::split(Latency::from_ms(100.0, s.task.dt).unwrap(), PLANNER);
    let mut central = Central::new(track, Strategy::Stiffness, timing);
    let cfg = vic::daemons::launch::board_config(&s, BOARD);
    let mut board = Board::new(s.model.clone(), cfg, set.x0.as_slice()).expect("board");
    let mut records = lockstep_polled(&mut board, &mut central, (BOARD, PLANNER), 1, 1, polls);
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
