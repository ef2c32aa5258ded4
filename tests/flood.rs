//! A flood of invalid commands at a running board (issue 14, finding 5: a 1.5 M-message flood
//! was only ~2 % counted). A real `vic-board` follows a valid trial, then the valid sender goes
//! quiet and this process sends N invalid command slices as fast as it can (wrong trial, a
//! `knot_dt_ns` of 1e15, stale, from the future, NaN stiffness). Checked against the board's own
//! telemetry:
//! - every message is accounted for: rejected (by reason, the reasons add up) or dropped by
//!   iceoryx2 (overwritten in the board's 8-slot receive buffer, counted by the board from the
//!   sequence gaps of the sender's session, once it has seen that session), and the two add up
//!   to exactly N;
//! - the 1 kHz loop keeps its rate (≥ 990 Hz over the flood) and few late ticks;
//! - the watchdog still trips 50 ms after the last valid command: junk never feeds it.
//!
//! N = 100 000 here (spread over 0.4 s so that the watchdog expires during the flood); `cargo test --release --test flood -- --ignored` runs the 1 M flood.

mod common;

use common::daemons::{CONFIG, Daemons, unique_namespace};
use std::time::{Duration, Instant};
use vic::planning::plan::setup;
use vic::planning::scenario::Scenario;
use vic::rt::transport::{
    CentralPorts, CommandSlice, Control, ControlKind, Disturbance, DisturbanceKind, Header, Mode,
    PROTOCOL_VERSION, Rejection, Telemetry, ToolPorts, monotonic_ns,
};
use vic::tools::bench::loop_bench::hold_slice;

const VALID_SESSION: u32 = 0x5AFE;
const JUNK_SESSION: u32 = 0xBAD;
const FLOOD_KINDS: u64 = 5;

/// Telemetry published after `after_ns` (the board publishes every 100 ms).
fn telemetry_after(ep: &CentralPorts, after_ns: u64) -> Telemetry {
    let t0 = Instant::now();
    loop {
        if let Some(t) = ep.wait_for_telemetry(Duration::from_millis(200))
            && t.header.time_ns > after_ns
        {
            return t;
        }
        assert!(t0.elapsed() < Duration::from_secs(5), "no telemetry");
    }
}

/// Junk message `i` of the flood: every one invalid, one reason in five.
fn junk(base: &CommandSlice, i: u64) -> CommandSlice {
    let now = monotonic_ns();
    let mut c = *base;
    c.header = Header::in_session(JUNK_SESSION, i + 1, now);
    match i % FLOOD_KINDS {
        0 => c.trial = 7,
        1 => c.knot_dt_ns = 1_000_000_000_000_000,
        2 => c.header.time_ns = now - 1_000_000_000,
        3 => c.header.time_ns = now + 1_000_000_000,
        _ => c.knots[3].stiffness[0] = f64::NAN,
    }
    c
}

fn flood(n: u64, min_duration: Duration) {
    let scenario = Scenario::load(std::path::Path::new(CONFIG), &[]).unwrap();
    let q0 = setup(&scenario).unwrap().x0[..2].to_vec();
    let ns = unique_namespace("flood");
    let mut d = Daemons::default();
    d.board(&ns, &[]);
    let ep = CentralPorts::open(&ns).unwrap();
    assert!(ep.wait_for_telemetry(Duration::from_secs(20)).is_some());

    // A valid trial: reset, then hold slices at 50 Hz for 0.4 s.
    let start = (monotonic_ns() + 20_000_000) / 1_000_000 * 1_000_000;
    let mut reset = Control {
        header: Header::in_session(VALID_SESSION, 1, monotonic_ns()),
        kind: ControlKind::Reset as u32,
        trial: 1,
        seed: 1,
        start_ns: start,
        ..Default::default()
    };
    reset.q0[..2].copy_from_slice(&q0);
    ep.publish_control(&reset).unwrap();
    let mut last = hold_slice(2, &q0, 0, 1, 0, 100.0);
    for seq in 1..=20 {
        std::thread::sleep(Duration::from_millis(20));
        let t = monotonic_ns().saturating_sub(start);
        last = hold_slice(2, &q0, seq, 1, t / 10_000_000 * 10_000_000, 100.0);
        last.header = Header::in_session(VALID_SESSION, seq, monotonic_ns());
        ep.publish_command(&last).unwrap();
    }
    let last_valid_ns = last.header.time_ns;
    let before = telemetry_after(&ep, last_valid_ns - 100_000_000);
    assert_eq!(Mode::from_u32(before.mode), Mode::Running, "{before:?}");
    assert_eq!((before.rejected_messages, before.dropped_messages), (0, 0));

    // The flood, as fast as this process can publish, but spread over at least `min_duration`
    // (the watchdog must expire while it runs) in bursts of 1000. Telemetry seen during the
    // flood, more than 150 ms after the last valid command, must show the safe hold.
    // The board counts what iceoryx2 overwrote from the sequence gaps of a session, so it must
    // have seen the session once: the first message goes alone (a session's first numbers are
    // arbitrary, e.g. `session_seq()`, so losses before its first received message cannot be
    // told from its numbers).
    ep.publish_command(&junk(&last, 0)).unwrap();
    std::thread::sleep(Duration::from_millis(5));
    let t0 = Instant::now();
    let mut held_during = None;
    for i in 1..n {
        ep.publish_command(&junk(&last, i)).unwrap();
        if i % 1000 == 999 {
            let due = min_duration.mul_f64((i + 1) as f64 / n as f64);
            while t0.elapsed() < due {
                std::hint::spin_loop();
            }
            if let Some(t) = ep.latest_telemetry()
                && t.header.time_ns > last_valid_ns + 150_000_000
            {
                held_during = Some(Mode::from_u32(t.mode));
            }
        }
    }
    let sent_in = t0.elapsed();
    let flood_end_ns = monotonic_ns();
    // Telemetry from after the board took the last message (it drains every tick).
    let after = telemetry_after(&ep, flood_end_ns + 150_000_000);

    let rejected = after.rejected_messages - before.rejected_messages;
    let dropped = after.dropped_messages - before.dropped_messages;
    let by_reason: Vec<(&str, u64)> = Rejection::ALL
        .iter()
        .map(|r| {
            let i = *r as usize;
            (
                r.name(),
                after.rejected_by_reason[i] - before.rejected_by_reason[i],
            )
        })
        .filter(|(_, v)| *v > 0)
        .collect();
    let ticks = after.tick - before.tick;
    let seconds = (after.header.time_ns - before.header.time_ns) as f64 * 1e-9;
    let rate = ticks as f64 / seconds;
    let late = after.late_ticks - before.late_ticks;
    eprintln!(
        "flood of {n} in {sent_in:?} ({:.0} msg/s): rejected {rejected} {by_reason:?}, \
         dropped by iceoryx2 {dropped}; {ticks} ticks in {seconds:.3} s = {rate:.1} Hz, \
         {late} late, watchdog trips {} → {}, mode {}",
        n as f64 / sent_in.as_secs_f64(),
        before.watchdog_trips,
        after.watchdog_trips,
        Mode::from_u32(after.mode).name()
    );
    // Every message accounted for, and the reasons add up.
    assert_eq!(
        rejected + dropped,
        n,
        "rejected {rejected} + dropped {dropped}"
    );
    assert_eq!(by_reason.iter().map(|(_, v)| v).sum::<u64>(), rejected);
    assert!(rejected > 0 && by_reason.len() >= 3, "{by_reason:?}");
    // The loop kept its rate. The window is ~0.6 s, so one preemption of the board by the
    // shared machine (counted as a late tick below) costs ~1.5 % of it: 950 Hz allows that
    // and still fails if draining the flood pushes ticks past their period, which the late-tick
    // bound below also catches.
    assert!(rate >= 950.0, "tick rate {rate:.1} Hz during the flood");
    assert!(
        (late as f64) < 0.01 * ticks as f64 + 5.0,
        "{late} late ticks of {ticks}"
    );
    // Junk never fed the watchdog: it tripped after the last valid command.
    assert!(
        after.watchdog_trips > before.watchdog_trips,
        "no watchdog trip"
    );
    assert_eq!(
        held_during,
        Some(Mode::SafeHold),
        "mode seen during the flood"
    );
    assert_eq!(Mode::from_u32(after.mode), Mode::SafeHold);
    drop(ep);
}

#[test]
fn a_flood_of_100k_invalid_commands_is_counted_and_does_not_feed_the_watchdog() {
    flood(100_000, Duration::from_millis(400));
}

#[test]
#[ignore = "1 M messages: run with --ignored (a few seconds)"]
fn a_flood_of_1m_invalid_commands_is_counted_and_does_not_feed_the_watchdog() {
    flood(1_000_000, Duration::from_millis(400));
}

const JUNK_CONTROLS: u32 = 0xC0DE;
const JUNK_DISTURBANCES: u32 = 0xD157;
const MIXED_KINDS: u64 = 6;

/// Junk control `i`: a reset, invalid one way in six (never a stop: a valid one would freeze
/// the plant).
fn junk_control(q0: &[f64], i: u64) -> Control {
    let now = monotonic_ns();
    let mut c = Control {
        header: Header::in_session(JUNK_CONTROLS, i + 1, now),
        kind: ControlKind::Reset as u32,
        trial: 9,
        seed: 1,
        start_ns: now + 20_000_000,
        ..Default::default()
    };
    c.q0[..2].copy_from_slice(q0);
    match i % MIXED_KINDS {
        0 => c.header.version = PROTOCOL_VERSION + 1,
        1 => c.kind = 77,
        2 => c.qd0[1] = f64::NAN,
        3 => c.header.time_ns = now - 1_000_000_000,
        4 => c.q0[0] = 100.0,
        _ => c.start_ns = now + 10_000_000_000,
    }
    c
}

/// Junk disturbance `i`: invalid one way in six.
fn junk_disturbance(i: u64) -> Disturbance {
    let now = monotonic_ns();
    let mut d = Disturbance {
        header: Header::in_session(JUNK_DISTURBANCES, i + 1, now),
        kind: DisturbanceKind::Pulse as u32,
        torque: [0.5, 0.0],
        duration_ns: 10_000_000,
        ..Default::default()
    };
    match i % MIXED_KINDS {
        0 => d.header.version = PROTOCOL_VERSION + 1,
        1 => d.kind = 77,
        2 => d.torque[0] = f64::INFINITY,
        3 => d.header.time_ns = now - 1_000_000_000,
        4 => d.header.time_ns = now + 1_000_000_000,
        _ => d.torque[1] = 1e6,
    }
    d
}

/// A flood of `n` invalid controls and `n` invalid disturbances while a valid sender keeps a
/// trial running: every one counted (rejected by reason or dropped), none applied (the trial,
/// its reset, the disturbance state and the mode are those of the valid sender), the loop keeps
/// its rate.
fn flood_controls_and_disturbances(n: u64, min_duration: Duration) {
    let scenario = Scenario::load(std::path::Path::new(CONFIG), &[]).unwrap();
    let q0 = setup(&scenario).unwrap().x0[..2].to_vec();
    let ns = unique_namespace("floodcd");
    let mut d = Daemons::default();
    d.board(&ns, &[]);
    let ep = CentralPorts::open(&ns).unwrap();
    let tool = ToolPorts::open(&ns).unwrap();
    assert!(ep.wait_for_telemetry(Duration::from_secs(20)).is_some());

    let start = (monotonic_ns() + 20_000_000) / 1_000_000 * 1_000_000;
    let mut reset = Control {
        header: Header::in_session(VALID_SESSION, 1, monotonic_ns()),
        kind: ControlKind::Reset as u32,
        trial: 1,
        seed: 1,
        start_ns: start,
        ..Default::default()
    };
    reset.q0[..2].copy_from_slice(&q0);
    ep.publish_control(&reset).unwrap();
    let mut seq = 0;
    let mut next_valid = Instant::now();
    // A valid hold slice every 20 ms (the planner's rate), from the valid session.
    let mut keep_running = |seq: &mut u64| {
        if Instant::now() >= next_valid {
            *seq += 1;
            let t = monotonic_ns().saturating_sub(start);
            let mut c = hold_slice(2, &q0, *seq, 1, t / 10_000_000 * 10_000_000, 100.0);
            c.header = Header::in_session(VALID_SESSION, *seq, monotonic_ns());
            ep.publish_command(&c).unwrap();
            next_valid += Duration::from_millis(20);
        }
    };
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_millis(400) {
        keep_running(&mut seq);
        std::thread::sleep(Duration::from_millis(2));
    }
    // Telemetry published after `after_ns`, the valid sender going on meanwhile (a blocking
    // wait would let the watchdog expire).
    macro_rules! telemetry_running {
        ($after_ns:expr) => {{
            let after_ns: u64 = $after_ns;
            let t0 = Instant::now();
            loop {
                keep_running(&mut seq);
                if let Some(t) = ep.latest_telemetry()
                    && t.header.time_ns > after_ns
                {
                    break t;
                }
                assert!(t0.elapsed() < Duration::from_secs(5), "no telemetry");
                std::thread::sleep(Duration::from_millis(2));
            }
        }};
    }
    let before = telemetry_running!(monotonic_ns());
    assert_eq!(Mode::from_u32(before.mode), Mode::Running, "{before:?}");
    assert_eq!((before.rejected_messages, before.dropped_messages), (0, 0));

    // Each junk session is shown once, alone, so that the board counts its later losses.
    ep.publish_control(&junk_control(&q0, 0)).unwrap();
    tool.publish_disturbance(&junk_disturbance(0)).unwrap();
    std::thread::sleep(Duration::from_millis(5));
    let t0 = Instant::now();
    for i in 1..n {
        ep.publish_control(&junk_control(&q0, i)).unwrap();
        tool.publish_disturbance(&junk_disturbance(i)).unwrap();
        if i % 500 == 499 {
            let due = min_duration.mul_f64((i + 1) as f64 / n as f64);
            while t0.elapsed() < due {
                keep_running(&mut seq);
                std::hint::spin_loop();
            }
            keep_running(&mut seq);
        }
    }
    let sent_in = t0.elapsed();
    let flood_end_ns = monotonic_ns();
    let after = telemetry_running!(flood_end_ns + 150_000_000);
    let state = ep.latest_state().expect("a state");

    let rejected = after.rejected_messages - before.rejected_messages;
    let dropped = after.dropped_messages - before.dropped_messages;
    let by_reason: Vec<(&str, u64)> = Rejection::ALL
        .iter()
        .map(|r| {
            let i = *r as usize;
            (
                r.name(),
                after.rejected_by_reason[i] - before.rejected_by_reason[i],
            )
        })
        .filter(|(_, v)| *v > 0)
        .collect();
    let ticks = after.tick - before.tick;
    let seconds = (after.header.time_ns - before.header.time_ns) as f64 * 1e-9;
    let rate = ticks as f64 / seconds;
    let late = after.late_ticks - before.late_ticks;
    eprintln!(
        "flood of {n} controls + {n} disturbances in {sent_in:?}: rejected {rejected} \
         {by_reason:?}, dropped by iceoryx2 {dropped}; {ticks} ticks in {seconds:.3} s = \
         {rate:.1} Hz, {late} late, mode {}",
        Mode::from_u32(after.mode).name()
    );
    assert_eq!(
        rejected + dropped,
        2 * n,
        "rejected {rejected} + dropped {dropped}"
    );
    assert_eq!(by_reason.iter().map(|(_, v)| v).sum::<u64>(), rejected);
    assert!(rejected > 0 && by_reason.len() >= 5, "{by_reason:?}");
    // Nothing invalid applied: the valid sender's trial and reset, no disturbance, no change
    // of field or noise, and the valid commands kept the plant running.
    assert_eq!((state.trial, state.reset_seq), (1, 1), "{state:?}");
    assert_eq!((state.disturbance_seq, after.disturbance_seq), (0, 0));
    assert_eq!(after.tau_ext, [0.0; 2]);
    assert_eq!(
        (after.field_beta, after.noise_factor),
        (before.field_beta, before.noise_factor)
    );
    assert_eq!(Mode::from_u32(after.mode), Mode::Running, "{after:?}");
    assert_eq!(after.watchdog_trips, before.watchdog_trips);
    // The loop kept its rate (the same loose bound as the command flood's).
    assert!(rate >= 950.0, "tick rate {rate:.1} Hz during the flood");
    assert!(
        (late as f64) < 0.01 * ticks as f64 + 5.0,
        "{late} late ticks of {ticks}"
    );
}

#[test]
fn a_flood_of_invalid_controls_and_disturbances_is_counted_and_never_applied() {
    flood_controls_and_disturbances(50_000, Duration::from_millis(400));
}
