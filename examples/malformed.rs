//! A hidden helper for `scripts/soak.sh`: every `--every-ms` it publishes into a namespace one
//! disturbance (a small pulse, as a tool would) and one hostile message, cycling through the
//! attacks of issue 14 and malformed slices:
//! a slice with `knot_dt_ns` = 1e15 (shape), a slice with `seq` = u64::MAX (wrong trial: it
//! must block nothing), a stale disturbance (1 s old), a wrong protocol version, a burst of
//! `BURST` junk slices at once (rejected, or dropped by iceoryx2 and counted from the sequence
//! gaps of its session, the planner's slices in between or not), NaN torque, a stiffness above any bound and a wrong
//! joint count.
//! After the last period one trailer slice goes out in the flood session with the sequence
//! number after the last burst's: a burst's tail that is dropped on the way (by iceoryx2's
//! receive buffer, or by Zenoh across a bridge) is then counted from the gap before it, not
//! lost with nothing after it to show the gap. It counts as a flood-burst message.
//! Hostile messages go out on a raw sender's node (`vic-raw-sender`), so the planner that the
//! soak runs beside it is not refused, each kind from a session of its own. At the end it prints
//! one JSON line: how many hostile messages it sent, by kind, and in total.
//!
//! cargo run --release --example malformed -- NAMESPACE [SECONDS] [EVERY_MS]

use std::collections::BTreeMap;
use std::time::{Duration, Instant};
use vic_rt::transport::{
    CommandSlice, Disturbance, DisturbanceKind, Header, PROTOCOL_VERSION, RawPorts, ToolPorts,
    monotonic_ns,
};

/// Junk slices in one flood burst.
const BURST: u64 = 2000;
/// The hostile kinds, one per period in turn.
const KINDS: [&str; 8] = [
    "knot-dt-1e15",
    "seq-u64-max",
    "stale",
    "bad-version",
    "flood-burst",
    "nan-torque",
    "stiffness-unbounded",
    "wrong-joints",
];

/// The session of hostile kind `kind`: one session per kind, so the sequence rules of one kind
/// never touch another's.
fn session_of(kind: usize) -> u32 {
    0x4057_0000 + kind as u32
}

/// A slice for no trial the board runs (trial 0xFFFF), otherwise well formed.
fn slice(session: u32, seq: u64) -> CommandSlice {
    CommandSlice {
        joints: 2,
        header: Header::in_session(session, seq, monotonic_ns()),
        trial: 0xFFFF,
        start_ns: 0,
        knot_dt_ns: 10_000_000,
        count: 4,
        ..Default::default()
    }
}

/// Sends hostile message number `n` (kind `n % KINDS.len()`); returns how many messages went out.
fn hostile(raw: &RawPorts, n: u64) -> u64 {
    let kind = (n % KINDS.len() as u64) as usize;
    let session = session_of(kind);
    // Consecutive within each kind's session: no gap the board would count as a loss.
    let round = n / KINDS.len() as u64;
    let seq = round + 1;
    let mut c = slice(session, seq);
    match KINDS[kind] {
        "knot-dt-1e15" => c.knot_dt_ns = 1_000_000_000_000_000,
        "seq-u64-max" => c.header.seq = u64::MAX,
        "stale" => {
            let d = Disturbance {
                header: Header::in_session(session, seq, monotonic_ns() - 1_000_000_000),
                kind: DisturbanceKind::Pulse as u32,
                torque: [0.2, 0.0],
                duration_ns: 10_000_000,
                ..Default::default()
            };
            return raw.publish_disturbance(&d).is_ok() as u64;
        }
        "bad-version" => c.header.version = PROTOCOL_VERSION + 7,
        "flood-burst" => {
            // The first alone: the board sees the session, so it can count later losses from
            // the sequence gaps (it tracks each session's, the planner's slices in between).
            let mut sent = 0;
            for i in 0..BURST {
                if i == 1 {
                    std::thread::sleep(Duration::from_millis(5));
                }
                let c = slice(session, round * BURST + i + 1);
                sent += raw.publish_command(&c).is_ok() as u64;
            }
            return sent;
        }
        "nan-torque" => c.knots[1].tau_ff[0] = f64::NAN,
        "stiffness-unbounded" => c.knots[0].stiffness = [f64::MAX, 1e9],
        _ => c.joints = 9,
    }
    raw.publish_command(&c).is_ok() as u64
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(ns) = args.get(1) else {
        eprintln!("usage: malformed NAMESPACE [SECONDS] [EVERY_MS]");
        std::process::exit(2);
    };
    let seconds: f64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(60.0);
    let every = Duration::from_millis(args.get(3).and_then(|s| s.parse().ok()).unwrap_or(1000));
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    {
        let stop = stop.clone();
        let _ = ctrlc::set_handler(move || stop.store(true, std::sync::atomic::Ordering::Relaxed));
    }
    let fail = |e: vic_rt::transport::TransportError| -> ! {
        eprintln!("malformed: {e}");
        std::process::exit(1)
    };
    let raw = RawPorts::open(ns).unwrap_or_else(|e| fail(e));
    let tool = ToolPorts::open(ns).unwrap_or_else(|e| fail(e));
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let mut by_kind: BTreeMap<&str, u64> = BTreeMap::new();
    let (mut hostile_sent, mut sent_dist, mut n) = (0u64, 0u64, 0u64);
    while Instant::now() < end && !stop.load(std::sync::atomic::Ordering::Relaxed) {
        n += 1;
        let d = Disturbance {
            header: Header::new(vic_rt::transport::session_seq() + n, monotonic_ns()),
            kind: DisturbanceKind::Pulse as u32,
            torque: [0.2, -0.1],
            duration_ns: 10_000_000,
            value: 0.0,
            ..Default::default()
        };
        sent_dist += tool.publish_disturbance(&d).is_ok() as u64;
        let sent = hostile(&raw, n);
        *by_kind
            .entry(KINDS[(n % KINDS.len() as u64) as usize])
            .or_default() += sent;
        hostile_sent += sent;
        std::thread::sleep(every);
    }
    // The trailer (see the module doc): the flood session's next sequence number after the
    // last burst, so the board counts a lost tail of that burst from the gap.
    let flood = KINDS
        .iter()
        .position(|k| *k == "flood-burst")
        .expect("a flood kind");
    let flood_rounds = (n + (KINDS.len() - flood) as u64) / KINDS.len() as u64;
    if flood_rounds > 0 {
        let last_round = flood_rounds - 1;
        std::thread::sleep(Duration::from_millis(200));
        let c = slice(session_of(flood), (last_round + 1) * BURST + 1);
        let sent = raw.publish_command(&c).is_ok() as u64;
        *by_kind.entry("flood-burst").or_default() += sent;
        hostile_sent += sent;
        // Time for it to cross a bridge before the soak stops the board.
        std::thread::sleep(Duration::from_millis(300));
    }
    println!(
        "{}",
        serde_json::json!({
            "hostile": hostile_sent,
            "hostile_by_kind": by_kind,
            "disturbances": sent_dist,
        })
    );
}
