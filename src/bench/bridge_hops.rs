//! `vic bench bridge --trace`: where the one-way time through the two bridges goes. The bridges
//! run in the benchmark's process, so their marks ([`vic_rt::bridge::trace`]) and the ping–pong
//! ends' stamps are on one clock; after every round trip the marks are read relative to the start
//! of each one-way (the central end's publish of the command; the echo's read of it, which
//! publishes the state at once) and recorded per point.

use hdrhistogram::Histogram;
use serde::Serialize;
use std::sync::atomic::{AtomicU64, Ordering};
use vic_rt::bridge::Side;
use vic_rt::bridge::trace::{self, Point};

/// When the echo last read a command (monotonic ns): the end of the command's one-way and the
/// start of the state's.
pub(super) static ECHO_AT: AtomicU64 = AtomicU64::new(0);

/// A point of a one-way: a bridge's mark, or the reading end.
#[derive(Debug, Clone, Copy)]
enum At {
    Bridge(Side, Point),
    /// The end of the one-way (the echo's read, or the central end's).
    End,
}

/// The command's way (central → board) and the state's (board → central); the central-side
/// bridge is "B", the board-side one "A".
const COMMAND: [(&str, At); 5] = [
    (
        "B woke (relay event)",
        At::Bridge(Side::Central, Point::LocalWoke),
    ),
    ("B put returned", At::Bridge(Side::Central, Point::Put)),
    ("A Zenoh callback", At::Bridge(Side::Board, Point::Callback)),
    (
        "A published to iceoryx2",
        At::Bridge(Side::Board, Point::Published),
    ),
    ("echo read the command", At::End),
];
const STATE: [(&str, At); 5] = [
    (
        "A woke (relay event)",
        At::Bridge(Side::Board, Point::LocalWoke),
    ),
    ("A put returned", At::Bridge(Side::Board, Point::Put)),
    (
        "B Zenoh callback",
        At::Bridge(Side::Central, Point::Callback),
    ),
    (
        "B published to iceoryx2",
        At::Bridge(Side::Central, Point::Published),
    ),
    ("central read the state", At::End),
];

/// One point of a one-way, over the measured round trips.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct HopPoint {
    /// `command` (central → board) or `state` (board → central).
    pub(crate) way: &'static str,
    pub(crate) point: &'static str,
    /// Time from the one-way's start to this point [µs].
    pub(crate) since_start_p50_us: f64,
    pub(crate) since_start_p99_us: f64,
    /// This point's median minus the previous point's (the hop's share of the median one-way).
    pub(crate) hop_p50_us: f64,
    /// Round trips in which the point was passed within its one-way (a mark after the reading
    /// end's is left out: the end may read before the publisher's mark, just after its send).
    pub(crate) n: u64,
}

/// The marks of the round trips so far.
pub(super) struct Hops {
    command: Vec<Histogram<u64>>,
    state: Vec<Histogram<u64>>,
}

fn histograms() -> Vec<Histogram<u64>> {
    (0..5)
        .map(|_| Histogram::new_with_bounds(1, 10_000_000_000, 3).expect("valid bounds"))
        .collect()
}

impl Hops {
    /// Turns the bridges' marks on.
    pub(super) fn start() -> Hops {
        trace::enable(true);
        Hops {
            command: histograms(),
            state: histograms(),
        }
    }

    /// Before a round trip: forget the last one's marks.
    pub(super) fn clear(&self) {
        trace::clear();
        ECHO_AT.store(0, Ordering::Relaxed);
    }

    /// After a round trip that started at `t0` (the command's publish) and ended at `t_end` (the
    /// state read): records each point passed within its one-way (a point not passed, or marked
    /// by another message, is left out).
    pub(super) fn record(&mut self, t0: u64, t_end: u64) {
        let echo = ECHO_AT.load(Ordering::Relaxed);
        if echo < t0 || echo > t_end {
            return;
        }
        let take = |hs: &mut [Histogram<u64>], way: &[(&str, At); 5], start: u64, end: u64| {
            for (h, (_, at)) in hs.iter_mut().zip(way) {
                let t = match at {
                    At::Bridge(side, p) => trace::at(*side, *p),
                    At::End => end,
                };
                if (start..=end).contains(&t) {
                    let _ = h.record((t - start).max(1));
                }
            }
        };
        take(&mut self.command, &COMMAND, t0, echo);
        take(&mut self.state, &STATE, echo, t_end);
    }

    /// The points in order, and turns the marks off.
    pub(super) fn finish(self) -> Vec<HopPoint> {
        trace::enable(false);
        let mut out = Vec::new();
        for (way, names, hs) in [
            ("command", &COMMAND, &self.command),
            ("state", &STATE, &self.state),
        ] {
            let mut previous = 0.0;
            for ((point, _), h) in names.iter().zip(hs) {
                let us = |q: f64| h.value_at_quantile(q) as f64 / 1000.0;
                let n = h.len();
                let p50 = if n > 0 { us(0.5) } else { f64::NAN };
                out.push(HopPoint {
                    way,
                    point,
                    since_start_p50_us: p50,
                    since_start_p99_us: if n > 0 { us(0.99) } else { f64::NAN },
                    hop_p50_us: if n > 0 { p50 - previous } else { f64::NAN },
                    n,
                });
                if n > 0 {
                    previous = p50;
                }
            }
        }
        out
    }
}

/// The points as a table.
pub(super) fn print(points: &[HopPoint]) {
    println!(
        "\nper hop (through two bridges; B beside the central end, A beside the echo):\n\
         {:<8} {:<28} {:>12} {:>12} {:>10} {:>7}",
        "way", "point", "since p50 µs", "since p99 µs", "hop p50 µs", "n"
    );
    for p in points.iter().filter(|p| p.n > 0) {
        println!(
            "{:<8} {:<28} {:>12.1} {:>12.1} {:>10.1} {:>7}",
            p.way, p.point, p.since_start_p50_us, p.since_start_p99_us, p.hop_p50_us, p.n
        );
    }
}
