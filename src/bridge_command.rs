//! `vic bridge`: one end of a namespace split across two hosts (see [`vic_rt::bridge`]).
//! Runs until SIGINT/SIGTERM or `--duration-s`, printing the counts once a second on stderr and
//! a summary at the end (`--json`: one object). The board side's line ends with the offset
//! between the hosts' clocks (board − central), its uncertainty (± half the best probe's round
//! trip), that round trip and the drift; the central side's with the probes it answered.

use crate::cli::{Classify, print_json, stop_on_signal};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};
use vic_rt::bridge::clock::ClockStats;
use vic_rt::bridge::{self, BridgeError, BridgeOptions, BridgeStats, Side, Stamps};

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
         (safety interval {} ms){}",
        o.namespace,
        o.side,
        o.link_name,
        o.link,
        o.safety_interval.as_millis(),
        match (o.side, o.stamps) {
            (Side::Board, Stamps::Translate) => ", stamps translated into this host's clock",
            (Side::Board, Stamps::Keep) => ", senders' stamps kept (one machine)",
            (Side::Central, _) => "",
        }
    );
    let result = bridge::run(o, &stop, |s| {
        if !json {
            eprintln!("{}{}", line(s), clock_line(o.side, &s.clock));
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
        println!("{}{}", line(&stats), clock_line(o.side, &stats.clock));
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

/// The clock's part of the line: the estimate on the board side, the answers on the central
/// side.
fn clock_line(side: Side, c: &ClockStats) -> String {
    let ms = |ns: i64| ns as f64 * 1e-6;
    match (side, c.offset_ns, c.uncertainty_ns, c.round_trip_ns) {
        (Side::Central, ..) => format!(
            " | clock: {} probes answered, {} malformed",
            c.probes_answered, c.probes_malformed
        ),
        (Side::Board, Some(offset), Some(u), Some(rtt)) => format!(
            " | clock: offset {:+.3} ms ± {:.3} ms (round trip {:.3} ms, drift {:+.1} ppm), \
             {} probes, {} answers, {} refused, {} held back",
            ms(offset),
            ms(u as i64),
            ms(rtt as i64),
            c.drift_ppb.unwrap_or(0) as f64 / 1000.0,
            c.probes_sent,
            c.answers,
            c.answers_refused,
            c.held_back
        ),
        (Side::Board, ..) if c.probes_sent > 0 => format!(
            " | clock: no answer to {} probes yet, {} messages held back",
            c.probes_sent, c.held_back
        ),
        (Side::Board, ..) => String::new(),
    }
}
