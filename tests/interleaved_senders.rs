//! Two senders interleaving on the command service of a real `vic-board` (issue 14: every
//! hostile message counted as rejected or as dropped, also when a planner's slice comes between
//! two messages of a burst, which a board tracking the sequence gaps of the last sender session
//! only would miss).
//!
//! A valid sender (a planner's session, a hold slice every 20 ms) keeps a trial running while a
//! raw sender (`RawPorts`, the node of a hostile tool) publishes bursts of junk slices, each burst
//! larger than the board's receive buffer, so iceoryx2 overwrites most of each burst and the board
//! must count the losses from the junk session's sequence gaps, with the valid slices coming in
//! between. Checked against the board's own telemetry: every message sent is accepted (the valid
//! ones: the trial keeps running on them), rejected by reason, or counted as dropped, exactly.

use crate::common;

use common::trial::{LiveTrial, rejected_by_reason};
use std::time::{Duration, Instant};
use vic_rt::transport::{CommandSlice, Header, Mode, RawPorts, monotonic_ns};

const JUNK_SESSION: u32 = 0xB0057;
/// Junk slices per burst: more than the board's receive buffer, so most are overwritten.
const BURST: u64 = 40;

/// Junk slice `seq` (numbered from 1, consecutively): invalid one way in three.
fn junk(base: &CommandSlice, seq: u64) -> CommandSlice {
    let mut c = *base;
    c.header = Header::in_session(JUNK_SESSION, seq, monotonic_ns());
    match seq % 3 {
        0 => c.trial = 7,
        1 => c.knot_dt_ns = 1_000_000_000_000_000,
        _ => c.knots[2].stiffness[1] = f64::NAN,
    }
    c
}

/// Waits `d` while the valid sender goes on.
fn pause(trial: &mut LiveTrial, d: Duration) {
    let t0 = Instant::now();
    while t0.elapsed() < d {
        trial.keep_running();
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn two_interleaved_senders_every_message_is_accepted_rejected_or_counted_as_dropped() {
    let mut trial = LiveTrial::start("interleave");
    pause(&mut trial, Duration::from_millis(300));
    let raw = RawPorts::open(&trial.ns).unwrap();
    pause(&mut trial, Duration::from_millis(100));
    let before = trial.telemetry_after(monotonic_ns(), true);
    assert_eq!(Mode::from_u32(before.mode), Mode::Running, "{before:?}");
    assert_eq!((before.rejected_messages, before.dropped_messages), (0, 0));
    let valid_before = trial.seq;
    let base = trial.send_hold();

    // The junk session's first message alone: the board must have seen a session to count its
    // losses (its first number is arbitrary).
    let mut junk_seq = 1;
    raw.publish_command(&junk(&base, junk_seq)).unwrap();
    pause(&mut trial, Duration::from_millis(5));
    // Bursts every ~1 ms for 1.5 s. A valid slice that falls due goes out alone between two
    // bursts, 2 ms after the last (the board has drained it) and 2 ms before the next, so it is
    // never behind 4 junk slices in one tick (the board takes 4 a tick and rejects the rest as
    // overflow) and the valid and junk sessions alternate in what the board receives.
    let mut interleaved = 0u64;
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_millis(1500) {
        for _ in 0..BURST {
            junk_seq += 1;
            raw.publish_command(&junk(&base, junk_seq)).unwrap();
        }
        std::thread::sleep(Duration::from_millis(1));
        if Instant::now() + Duration::from_millis(2) >= trial.next_valid() {
            std::thread::sleep(Duration::from_millis(2));
            interleaved += trial.keep_running() as u64;
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    let after = trial.telemetry_after(monotonic_ns() + 150_000_000, true);
    let state = trial.ep.latest_state().expect("a state");

    let junk_sent = junk_seq;
    let valid_sent = trial.seq - valid_before;
    let rejected = after.rejected_messages - before.rejected_messages;
    let dropped = after.dropped_messages - before.dropped_messages;
    let by_reason = rejected_by_reason(&before, &after);
    eprintln!(
        "sent {valid_sent} valid ({interleaved} between bursts) + {junk_sent} junk: rejected \
         {rejected} {by_reason:?}, dropped {dropped}; mode {}, watchdog trips {} → {}",
        Mode::from_u32(after.mode).name(),
        before.watchdog_trips,
        after.watchdog_trips,
    );
    // Every message accounted for: sent = accepted + rejected + dropped, the valid slices all
    // accepted (a valid slice rejected or lost would make the sum exceed the junk sent).
    assert_eq!(
        valid_sent + junk_sent,
        valid_sent + rejected + dropped,
        "rejected {rejected} + dropped {dropped} of {junk_sent} junk"
    );
    assert_eq!(by_reason.iter().map(|(_, v)| v).sum::<u64>(), rejected);
    // A junk slice with a NaN knot reaches the order check before the finiteness check
    // (docs/PROTOCOL.md's order): it is out of order when the board received it after a valid
    // slice stamped later. The two publishers' queues are drained in no promised order, so that
    // happens now and then. A valid slice rejected for any reason
    // would break the exact count above instead.
    let junk_reasons = [
        "shape",
        "wrong-trial",
        "out-of-order",
        "not-finite",
        "overflow",
    ];
    assert!(
        by_reason.iter().all(|(r, _)| junk_reasons.contains(r)),
        "{by_reason:?}"
    );
    // The case that was missed: losses in the junk session with valid slices between.
    assert!(dropped > junk_sent / 2, "dropped {dropped} of {junk_sent}");
    assert!(
        interleaved >= 30,
        "{interleaved} valid slices between bursts"
    );
    // The valid sender's slices drove the trial throughout.
    assert_eq!(Mode::from_u32(after.mode), Mode::Running, "{after:?}");
    assert_eq!(after.watchdog_trips, before.watchdog_trips);
    assert!(state.command_seq + 2 >= trial.seq, "{state:?}");
}
