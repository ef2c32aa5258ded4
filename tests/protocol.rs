//! Hostile messages against the protocol's limits (issue 14, item 3), through the board's state
//! machine: a knot interval of 1e15 ns, a sequence number of `u64::MAX`, a stale message, a
//! slice that reaches far ahead. Each is rejected by its reason, and the watchdog trips 50 ms
//! after the last fresh valid command whatever that command claimed to cover.

use std::path::Path;
use vic_plan::scenario::Scenario;
use vic_rt::board::*;
use vic_rt::transport::*;

const MS: u64 = 1_000_000;

fn board() -> (Board, [f64; 2]) {
    let s = Scenario::load(
        Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/config/two_link_divergent.toml"
        )),
        &[],
    )
    .unwrap();
    let setup = vic_plan::plan::setup(&s).unwrap();
    let q0 = [setup.x0[0], setup.x0[1]];
    let cfg = vic::daemons::launch::board_config(&s, MS);
    assert_eq!(cfg.watchdog_ns, 50 * MS, "the scenario's watchdog changed");
    (Board::new(s.model.clone(), cfg, &q0).unwrap(), q0)
}

/// A reset of trial 1 sent at `time` by `session`, starting at `start`.
fn reset(q0: [f64; 2], session: u32, seq: u64, time: u64, start: u64) -> Control {
    Control {
        header: Header::in_session(session, seq, time),
        kind: ControlKind::Reset as u32,
        trial: 1,
        seed: 5,
        start_ns: start,
        q0,
        ..Default::default()
    }
}

/// A valid slice holding `q0` (stiffness 150) over `count` knots of `dt` from trial time
/// `start`, sent at `time` by `session`.
fn slice(q0: [f64; 2], h: Header, start: u64, dt: u64, count: u32) -> CommandSlice {
    let mut c = CommandSlice {
        header: h,
        joints: 2,
        trial: 1,
        start_ns: start,
        knot_dt_ns: dt,
        count,
        ..Default::default()
    };
    for k in &mut c.knots[..count as usize] {
        k.q_d = q0;
        k.stiffness = [150.0; 2];
    }
    c
}

/// A board reset at 1 ms whose trial started at 2 ms, stepped to `until` ms.
fn running(until: u64) -> (Board, [f64; 2], Inputs) {
    let (mut b, q0) = board();
    let mut inp = Inputs::default();
    inp.push_control(&reset(q0, 7, 1, MS, 2 * MS));
    b.step(MS, &mut inp);
    for t in 2..=until {
        b.step(t * MS, &mut inp);
    }
    (b, q0, inp)
}

fn rejected(b: &Board, r: Rejection) -> u64 {
    b.counters.rejected_by[r as usize]
}

#[test]
fn shapes_that_could_overflow_or_reach_far_are_rejected_by_reason() {
    let (mut b, q0, mut inp) = running(10);
    let now = 10 * MS;
    let h = |seq| Header::in_session(9, seq, now);
    // The finding: knot_dt 1e15 kept a command in force for seconds.
    let huge_dt = slice(q0, h(1), 0, 1_000_000_000_000_000, 32);
    assert_eq!(b.validate(&huge_dt), Err(Rejection::Shape));
    // count × knot_dt wraps around u64 (it would pass an end-overflow check in release).
    let wraps = slice(q0, h(1), 0, u64::MAX / 16, 32);
    assert_eq!(b.validate(&wraps), Err(Rejection::Shape));
    // Each bound by itself: the interval, then the duration (32 × 100 ms = 3.2 s > 1 s).
    assert_eq!(
        b.validate(&slice(q0, h(1), 0, MAX_KNOT_DT_NS + 1, 2)),
        Err(Rejection::Shape)
    );
    assert_eq!(
        b.validate(&slice(q0, h(1), 0, MIN_KNOT_DT_NS - 1, 2)),
        Err(Rejection::Shape)
    );
    assert_eq!(
        b.validate(&slice(q0, h(1), 0, MAX_KNOT_DT_NS, 32)),
        Err(Rejection::Shape)
    );
    assert_eq!(b.validate(&slice(q0, h(1), 0, MAX_KNOT_DT_NS, 10)), Ok(()));
    // Ends more than 2 s after the present trial time (8 ms): too far ahead; a start near
    // u64::MAX too, without overflow.
    let far = slice(q0, h(1), 2 * MAX_REACH_NS, 10 * MS, 10);
    assert_eq!(b.validate(&far), Err(Rejection::TooFarAhead));
    let edge = slice(q0, h(1), u64::MAX - 5, 10 * MS, 10);
    assert_eq!(b.validate(&edge), Err(Rejection::TooFarAhead));
    let t = b.trial_time_ns();
    let just = slice(q0, h(1), t + MAX_REACH_NS - 100 * MS, 10 * MS, 10);
    assert_eq!(b.validate(&just), Ok(()));
    // Through a step: counted by reason, nothing applied.
    for (i, c) in [huge_dt, wraps, far, edge].iter().enumerate() {
        let mut c = *c;
        c.header.seq = i as u64 + 1;
        inp.push_command(&c);
        b.step(now + (i as u64 + 1) * MS, &mut inp);
    }
    assert_eq!(rejected(&b, Rejection::Shape), 2);
    assert_eq!(rejected(&b, Rejection::TooFarAhead), 2);
    assert_eq!(b.counters.rejected, 4);
    // A reset scheduled more than 2 s ahead would park the board: refused too.
    let late = reset(q0, 7, 2, 20 * MS, 20 * MS + MAX_REACH_NS + MS);
    inp.push_control(&late);
    b.step(20 * MS, &mut inp);
    assert_eq!(rejected(&b, Rejection::TooFarAhead), 3);
    assert_eq!(b.counters.resets, 1);
}

#[test]
fn the_watchdog_trips_50_ms_after_the_last_fresh_command_whatever_it_covers() {
    let (mut b, q0, mut inp) = running(10);
    // One valid slice covering a whole second (10 knots of 100 ms), sent at 10 ms; then the
    // sender goes quiet.
    let c = slice(q0, Header::in_session(9, 1, 10 * MS), 0, 100 * MS, 10);
    inp.push_command(&c);
    let mut entered = None;
    for t in 10..400u64 {
        let o = b.step(t * MS, &mut inp);
        if o.state.mode == Mode::SafeHold as u32 && entered.is_none() {
            entered = Some(t);
        }
        if entered.is_none() && t > 10 {
            assert_eq!(
                o.state.stiffness, [150.0; 2],
                "the command in force at {t} ms"
            );
        }
    }
    // The first period that starts 50 ms after the arrival (10 ms) is held: the state of the
    // step at 61 ms (the period 60–61 ms).
    assert_eq!(
        entered,
        Some(61),
        "safe hold entered at board time {entered:?} ms"
    );
    assert_eq!(b.counters.watchdog_trips, 1);
    // A replay of the same slice is refused (same session, same number); the same slice from
    // a stale clock is refused as stale; neither ends the hold.
    inp.push_command(&c);
    let mut old = c;
    old.header = Header::in_session(10, 1, 10 * MS);
    inp.push_command(&old);
    let o = b.step(400 * MS, &mut inp);
    assert_eq!(o.state.mode, Mode::SafeHold as u32);
    assert_eq!(rejected(&b, Rejection::OutOfOrder), 1);
    assert_eq!(rejected(&b, Rejection::Stale), 1);
    // A fresh one covering the present resumes the movement.
    let now = b.trial_time_ns();
    inp.push_command(&slice(
        q0,
        Header::in_session(9, 2, 401 * MS),
        now,
        10 * MS,
        10,
    ));
    let o = b.step(401 * MS, &mut inp);
    assert_eq!(o.state.mode, Mode::Running as u32);
}

#[test]
fn a_new_session_works_after_a_u64_max_sequence_number() {
    let (mut b, q0, mut inp) = running(10);
    let now = |t: u64| t * MS;
    // A forger (or a broken sender) publishes a valid slice numbered u64::MAX.
    inp.push_command(&slice(
        q0,
        Header::in_session(66, u64::MAX, now(10)),
        0,
        10 * MS,
        10,
    ));
    b.step(now(10), &mut inp);
    assert_eq!(b.counters.rejected, 0);
    // Its own session can say nothing more ...
    inp.push_command(&slice(
        q0,
        Header::in_session(66, 5, now(11)),
        0,
        10 * MS,
        10,
    ));
    b.step(now(11), &mut inp);
    assert_eq!(rejected(&b, Rejection::OutOfOrder), 1);
    // ... but a (re)started sender with a session of its own is heard at once.
    let mut fresh = slice(q0, Header::in_session(67, 1, now(12)), 0, 10 * MS, 10);
    fresh.knots.iter_mut().for_each(|k| k.stiffness = [90.0; 2]);
    inp.push_command(&fresh);
    let o = b.step(now(13), &mut inp);
    assert_eq!(b.counters.rejected, 1);
    assert_eq!(
        o.state.stiffness, [90.0; 2],
        "the new session's command is in force"
    );
    // A new session cannot jump back in time, though: a stamp older than the last message
    // accepted is out of order (it is not a restart, it is a replay).
    inp.push_command(&slice(
        q0,
        Header::in_session(68, 1, now(11)),
        0,
        10 * MS,
        10,
    ));
    b.step(now(14), &mut inp);
    assert_eq!(rejected(&b, Rejection::OutOfOrder), 2);

    // Disturbances: u64::MAX poisons its session only, and a reset forgets it.
    let pulse = |h: Header| Disturbance {
        header: h,
        kind: DisturbanceKind::Pulse as u32,
        torque: [0.5, 0.0],
        duration_ns: 2 * MS,
        ..Default::default()
    };
    inp.push_disturbance(&pulse(Header::in_session(66, u64::MAX, now(15))));
    let o = b.step(now(15), &mut inp);
    assert_eq!(o.state.disturbance_seq, u64::MAX);
    inp.push_disturbance(&pulse(Header::in_session(66, 3, now(16))));
    b.step(now(16), &mut inp);
    assert_eq!(rejected(&b, Rejection::OutOfOrder), 3);
    inp.push_control(&reset(q0, 7, 2, now(17), now(18)));
    b.step(now(17), &mut inp);
    assert_eq!(b.counters.resets, 2);
    // After the reset even the poisoned session's numbers start afresh.
    inp.push_disturbance(&pulse(Header::in_session(66, 3, now(19))));
    let o = b.step(now(19), &mut inp);
    assert_eq!(o.state.disturbance_seq, 3);
    assert_eq!(rejected(&b, Rejection::OutOfOrder), 3);
    // Controls: a reset numbered u64::MAX blocks its session, not the next planner's.
    inp.push_control(&reset(q0, 70, u64::MAX, now(20), now(21)));
    b.step(now(20), &mut inp);
    inp.push_control(&reset(q0, 70, 1, now(22), now(23)));
    b.step(now(22), &mut inp);
    assert_eq!(rejected(&b, Rejection::OutOfOrder), 4);
    inp.push_control(&reset(q0, 71, 1, now(24), now(25)));
    b.step(now(24), &mut inp);
    assert_eq!(b.counters.resets, 4);
}

#[test]
fn stale_messages_are_rejected_even_by_a_fresh_board() {
    let (mut b, q0) = board();
    let mut inp = Inputs::default();
    let t0 = 5_000 * MS;
    // A reset published 150 ms before the board's clock: a stale one (100 ms at most).
    inp.push_control(&reset(q0, 7, 1, t0 - 150 * MS, t0));
    b.step(t0, &mut inp);
    assert_eq!(rejected(&b, Rejection::Stale), 1);
    assert_eq!(b.counters.resets, 0);
    // 99 ms old is still accepted.
    inp.push_control(&reset(q0, 7, 2, t0 - 99 * MS, t0 + MS));
    b.step(t0, &mut inp);
    assert_eq!(b.counters.resets, 1);
    // Commands and disturbances too.
    let stale = slice(q0, Header::in_session(9, 1, t0 - 101 * MS), 0, 10 * MS, 10);
    inp.push_command(&stale);
    inp.push_disturbance(&Disturbance {
        header: Header::in_session(9, 1, t0 - 200 * MS),
        kind: DisturbanceKind::Load as u32,
        ..Default::default()
    });
    b.step(t0 + MS, &mut inp);
    assert_eq!(rejected(&b, Rejection::Stale), 3);
    assert_eq!(b.counters.rejected, 3);
}

#[test]
fn sequence_gaps_are_counted_as_dropped() {
    let (mut b, q0, mut inp) = running(10);
    // Seq 1, 2, 5, 6, then 9 in one session: 2 + 2 messages never arrived. A new session and a
    // jump of more than 2^24 are not losses.
    for (i, seq) in [1u64, 2, 5, 6, 9].into_iter().enumerate() {
        let t = (11 + i as u64) * MS;
        inp.push_command(&slice(q0, Header::in_session(9, seq, t), 0, 10 * MS, 10));
        b.step(t, &mut inp);
    }
    inp.push_command(&slice(
        q0,
        Header::in_session(10, 100, 16 * MS),
        0,
        10 * MS,
        10,
    ));
    inp.push_command(&slice(
        q0,
        Header::in_session(10, 1 << 40, 16 * MS),
        0,
        10 * MS,
        10,
    ));
    b.step(16 * MS, &mut inp);
    assert_eq!(b.counters.dropped, 4);
    assert_eq!(b.counters.rejected, 0);
}
