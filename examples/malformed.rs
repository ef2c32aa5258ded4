//! A hidden helper for `scripts/soak.sh`: every `--every-ms` it publishes into a namespace one
//! disturbance (a small pulse, as a tool would) and one malformed command slice, cycling through
//! NaN torque, a wrong protocol version, an out-of-order sequence number, a stiffness above any
//! bound and a wrong joint count. The board must reject every malformed slice and go on.
//!
//! cargo run --release --example malformed -- NAMESPACE [SECONDS] [EVERY_MS]

use std::time::{Duration, Instant};
use vic::rt::transport::{
    CentralPorts, CommandSlice, Disturbance, DisturbanceKind, Header, PROTOCOL_VERSION, ToolPorts,
    monotonic_ns,
};

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
    // Malformed commands go out on a planner's port, disturbances on a tool's.
    let planner = CentralPorts::open(ns).unwrap_or_else(|e| {
        eprintln!("malformed: {e}");
        std::process::exit(1)
    });
    let tool = ToolPorts::open(ns).unwrap_or_else(|e| {
        eprintln!("malformed: {e}");
        std::process::exit(1)
    });
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let (mut sent_bad, mut sent_dist, mut n) = (0u64, 0u64, 0u64);
    while Instant::now() < end && !stop.load(std::sync::atomic::Ordering::Relaxed) {
        n += 1;
        let d = Disturbance {
            header: Header::new(vic::rt::transport::session_seq() + n, monotonic_ns()),
            kind: DisturbanceKind::Pulse as u32,
            torque: [0.2, -0.1],
            duration_ns: 10_000_000,
            value: 0.0,
            ..Default::default()
        };
        sent_dist += tool.publish_disturbance(&d).is_ok() as u64;
        let mut c = CommandSlice {
            joints: 2,
            // Sequence 0 is never newer than the last slice: always out of order.
            header: Header::new(0, monotonic_ns()),
            trial: 0,
            start_ns: 0,
            knot_dt_ns: 10_000_000,
            count: 4,
            ..Default::default()
        };
        match n % 5 {
            0 => c.knots[1].tau_ff[0] = f64::NAN,
            1 => c.header.version = PROTOCOL_VERSION + 7,
            2 => {} // out of order only
            3 => c.knots[0].stiffness = [f64::MAX, 1e9],
            _ => c.joints = 9,
        }
        sent_bad += planner.publish_command(&c).is_ok() as u64;
        std::thread::sleep(every);
    }
    println!("malformed: sent {sent_bad} malformed commands and {sent_dist} disturbances");
}
