//! `vic bridge`: one end of a namespace split across two hosts (see [`crate::rt::bridge`]).
//! Runs until SIGINT/SIGTERM or `--duration-s`, printing the counts once a second on stderr and
//! a summary at the end (`--json`: one object).

use crate::rt::bridge::{self, BridgeError, BridgeOptions, BridgeStats};
use crate::tools::cli::{Classify, print_json, stop_on_signal};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

/// Runs the bridge; `duration` of zero runs until a signal.
pub fn run(o: &BridgeOptions, duration: Duration, json: bool) -> anyhow::Result<()> {
    let stop = stop_on_signal()?;
    if !duration.is_zero() {
        let stop = stop.clone();
        std::thread::spawn(move || {
            std::thread::sleep(duration);
            stop.store(true, Ordering::Relaxed);
        });
    }
    let start = Instant::now();
    eprintln!(
        "vic bridge: namespace {} as the {:?} side of link \"{}\" ({:?}), woken by events \
         (safety interval {} ms)",
        o.namespace,
        o.side,
        o.link_name,
        o.link,
        o.safety_interval.as_millis()
    );
    let result = bridge::run(o, &stop, |s| {
        if !json {
            eprintln!("{}", line(s));
        }
    });
    let stats = match result {
        Err(e @ BridgeError::LinkName(_)) => return Err(e).input(),
        other => other.runtime()?,
    };
    if json {
        print_json(&serde_json::json!({
            "namespace": o.namespace,
            "link_name": o.link_name,
            "side": format!("{:?}", o.side).to_lowercase(),
            "seconds": start.elapsed().as_secs_f64(),
            "stats": stats,
        }))?;
    } else {
        println!("{}", line(&stats));
    }
    Ok(())
}

fn line(s: &BridgeStats) -> String {
    let (o, i) = (&s.sent, &s.received);
    format!(
        "out: state {} telemetry {} event {} command {} control {} disturbance {} | \
         in: state {} telemetry {} event {} command {} control {} disturbance {} | \
         malformed: size {} version {} | local errors {}",
        o.state,
        o.telemetry,
        o.event,
        o.command,
        o.control,
        o.disturbance,
        i.state,
        i.telemetry,
        i.event,
        i.command,
        i.control,
        i.disturbance,
        s.malformed_size,
        s.malformed_version,
        s.local_errors
    )
}
