//! `vic bench bridge`: the one-way latency of a command and a state through two bridges on
//! loopback, beside the same ping–pong over shared memory (one namespace, no bridge) and over
//! bare Zenoh (two sessions, the same payload size, no iceoryx2), all measured in the same run.
//!
//! One-way latency is half the round trip of a command answered by a state: the echo thread
//! plays the board (it answers each command with a state of the same sequence number), the
//! measuring thread plays the central process. They sleep until the other end's publisher
//! notifies, or spin on their subscribers (`spin`), so the figures are the transport's and the
//! bridges', not a reader's poll period. With `trace` the hops through the bridges are timed too
//! ([`super::bridge_hops`]).

use super::bridge_hops::{ECHO_AT, HopPoint, Hops};
use hdrhistogram::Histogram;
use serde::Serialize;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use vic_rt::bridge::{self, BridgeOptions, Link, Side};
use vic_rt::transport::protocol::{CommandSlice, Header, StateMsg};
use vic_rt::transport::relay::{Relay, RelayListener};
use vic_rt::transport::{BoardPorts, CentralPorts, monotonic_ns, remove_namespace};
use zenoh::Wait;

/// What to measure.
#[derive(Debug, Clone)]
pub(crate) struct Options {
    /// Round trips per channel (after 10 % more for warm-up).
    pub(crate) iterations: u64,
    /// Loopback TCP port of the link (the bare Zenoh pair uses the next one).
    pub(crate) port: u16,
    /// The endpoints spin on their subscribers instead of sleeping until notified.
    pub(crate) spin: bool,
    /// Also time each hop through the bridges ([`super::bridge_hops`]).
    pub(crate) trace: bool,
}

/// One channel's one-way latency [µs].
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Latency {
    pub(crate) p50_us: f64,
    pub(crate) p99_us: f64,
    pub(crate) max_us: f64,
    pub(crate) n: u64,
}

/// The report; `bridge` is the object the issue's scripts read.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Report {
    pub(crate) iterations: u64,
    /// Whether the endpoints spun (else they slept until notified).
    pub(crate) spin: bool,
    /// The bridges' safety interval (they are woken by events; this only bounds a missed one).
    pub(crate) safety_interval_ms: f64,
    pub(crate) payload_bytes: usize,
    pub(crate) shared_memory: Latency,
    pub(crate) zenoh: Latency,
    pub(crate) through_bridge: Latency,
    pub(crate) bridge: Ratios,
    /// With `trace`: the time from each one-way's start to each point on the way.
    pub(crate) hops: Option<Vec<HopPoint>>,
}

/// The bridge against bare Zenoh.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Ratios {
    pub(crate) p50_us: f64,
    pub(crate) p99_us: f64,
    pub(crate) zenoh_p50_us: f64,
    pub(crate) zenoh_p99_us: f64,
    pub(crate) ratio_p50: f64,
    pub(crate) ratio_p99: f64,
}

/// Why the benchmark could not run.
#[derive(Debug, thiserror::Error)]
pub(crate) enum BenchError {
    #[error(transparent)]
    Bridge(#[from] bridge::BridgeError),
    #[error(transparent)]
    Transport(#[from] vic_rt::transport::TransportError),
    #[error("zenoh: {0}")]
    Zenoh(String),
    #[error("no answer within 2 s on the {0} channel (round trip {1})")]
    Timeout(&'static str, u64),
}

fn latency(h: &Histogram<u64>) -> Latency {
    // Recorded in nanoseconds of one-way time.
    let us = |v: u64| v as f64 / 1000.0;
    Latency {
        p50_us: us(h.value_at_quantile(0.5)),
        p99_us: us(h.value_at_quantile(0.99)),
        max_us: us(h.max()),
        n: h.len(),
    }
}

fn histogram() -> Histogram<u64> {
    Histogram::new_with_bounds(1, 10_000_000_000, 3).expect("valid bounds")
}

/// The echo: answers every command in `ns` with a state of the same sequence number, spinning,
/// until `stop`.
fn echo(
    ns: String,
    spin: bool,
    stop: Arc<AtomicBool>,
    ready: Arc<AtomicBool>,
) -> Result<(), BenchError> {
    let board = BoardPorts::open(&ns)?;
    let woken = RelayListener::open(board.session(), Relay::ToBoard)?;
    ready.store(true, Ordering::Release);
    while !stop.load(Ordering::Relaxed) {
        board.drain_commands(|c| {
            ECHO_AT.store(monotonic_ns(), Ordering::Relaxed);
            let s = StateMsg {
                header: Header::new(c.header.seq, monotonic_ns()),
                ..Default::default()
            };
            let _ = board.publish_state(&s);
        });
        pause(spin, &woken);
    }
    Ok(())
}

/// Ping–pong from a central process in `ns` (the echo answers somewhere behind it).
fn ping_pong(
    ns: &str,
    iterations: u64,
    spin: bool,
    channel: &'static str,
    mut hops: Option<&mut Hops>,
) -> Result<Histogram<u64>, BenchError> {
    let central = CentralPorts::open(ns)?;
    let woken = RelayListener::open(central.session(), Relay::FromBoard)?;
    let mut h = histogram();
    let warm = iterations / 10;
    for i in 1..=warm + iterations {
        let c = CommandSlice {
            header: Header::new(i, monotonic_ns()),
            ..Default::default()
        };
        if let Some(h) = &hops {
            h.clear();
        }
        let t0 = monotonic_ns();
        let t = Instant::now();
        central.publish_command(&c)?;
        let mut answered = false;
        while !answered {
            central.drain_states(|s| answered |= s.header.seq == i);
            if t.elapsed() > Duration::from_secs(2) {
                return Err(BenchError::Timeout(channel, i));
            }
            if !answered {
                pause(spin, &woken);
            }
        }
        if i > warm {
            let _ = h.record((t.elapsed().as_nanos() / 2) as u64);
            if let Some(hops) = hops.as_deref_mut() {
                hops.record(t0, monotonic_ns());
            }
        }
    }
    Ok(h)
}

/// Between two looks at the subscribers: spin, or sleep until the other end's publisher
/// notifies (the relay event every publisher rings; a notification that came since the last
/// look returns at once).
fn pause(spin: bool, woken: &RelayListener) {
    if spin {
        std::hint::spin_loop();
    } else {
        woken.wait(Duration::from_millis(10));
    }
}

/// Runs the echo in a thread beside `f`, stops it after.
fn with_echo<T>(
    ns: &str,
    spin: bool,
    f: impl FnOnce() -> Result<T, BenchError>,
) -> Result<T, BenchError> {
    let stop = Arc::new(AtomicBool::new(false));
    let ready = Arc::new(AtomicBool::new(false));
    let echo = {
        let (ns, stop, ready) = (ns.to_string(), stop.clone(), ready.clone());
        std::thread::spawn(move || echo(ns, spin, stop, ready))
    };
    while !ready.load(Ordering::Acquire) && !echo.is_finished() {
        std::thread::sleep(Duration::from_millis(1));
    }
    let result = if echo.is_finished() {
        Err(BenchError::Timeout("echo start", 0))
    } else {
        f()
    };
    stop.store(true, Ordering::Relaxed);
    let echoed = echo.join().expect("the echo thread does not panic");
    let value = result?;
    echoed?;
    Ok(value)
}

fn unique(tag: &str) -> String {
    format!("{tag}{}x{}", std::process::id(), monotonic_ns() % 1_000_000)
}

/// Bare Zenoh: two sessions on loopback, a ping answered (inside the callback) by a pong of the
/// state's size, with the bridge's publisher QoS.
fn bare_zenoh(port: u16, iterations: u64) -> Result<Histogram<u64>, BenchError> {
    let z = |e: zenoh::Error| BenchError::Zenoh(e.to_string());
    let endpoint = format!(r#"["tcp/127.0.0.1:{port}"]"#);
    let session = |key: &str| -> Result<zenoh::Session, BenchError> {
        let mut c = zenoh::Config::default();
        c.insert_json5(key, &endpoint).map_err(z)?;
        c.insert_json5("scouting/multicast/enabled", "false")
            .map_err(z)?;
        zenoh::open(c).wait().map_err(z)
    };
    let a = session("listen/endpoints")?;
    let b = session("connect/endpoints")?;
    // The bridge's QoS (drop, real-time priority, express), so only the bridging differs.
    let qos = |s: &zenoh::Session, key: &str| bridge::control_publisher(s, key.to_string());
    let pong = qos(&b, "vicbench/pong")?;
    let _echo = b
        .declare_subscriber("vicbench/ping")
        .callback(move |s| {
            let _ = pong.put(s.payload().to_bytes().to_vec()).wait();
        })
        .wait()
        .map_err(z)?;
    let answers = a.declare_subscriber("vicbench/pong").wait().map_err(z)?;
    let ping = qos(&a, "vicbench/ping")?;
    // Let the two sessions learn each other's subscribers.
    let payload = vec![0u8; size_of::<StateMsg>()];
    let t0 = Instant::now();
    loop {
        ping.put(payload.clone()).wait().map_err(z)?;
        if answers
            .recv_timeout(Duration::from_millis(100))
            .map_err(z)?
            .is_some()
        {
            break;
        }
        if t0.elapsed() > Duration::from_secs(5) {
            return Err(BenchError::Timeout("zenoh", 0));
        }
    }
    let mut h = histogram();
    let warm = iterations / 10;
    for i in 0..warm + iterations {
        let t = Instant::now();
        ping.put(payload.clone()).wait().map_err(z)?;
        if answers
            .recv_timeout(Duration::from_secs(2))
            .map_err(z)?
            .is_none()
        {
            return Err(BenchError::Timeout("zenoh", i));
        }
        if i >= warm {
            let _ = h.record((t.elapsed().as_nanos() / 2) as u64);
        }
    }
    let _ = a.close().wait();
    let _ = b.close().wait();
    Ok(h)
}

/// Two bridges in threads, the echo behind the board-side one, the ping–pong in front of the
/// central-side one.
fn through_bridges(o: &Options) -> Result<(Histogram<u64>, Option<Vec<HopPoint>>), BenchError> {
    let (host_a, host_b) = (unique("bba"), unique("bbb"));
    let endpoint = format!("tcp/127.0.0.1:{}", o.port);
    let stop = Arc::new(AtomicBool::new(false));
    let spawn = |side, ns: &str, link| {
        let options = BridgeOptions {
            namespace: ns.to_string(),
            link_name: format!("bench{}", std::process::id()),
            side,
            link,
            security: bridge::Security::PlainLoopback,
            safety_interval: bridge::DEFAULT_SAFETY_INTERVAL,
            stamps: bridge::Stamps::Keep,
            clock_skew_ns: 0,
        };
        let stop = stop.clone();
        std::thread::spawn(move || bridge::run(&options, &stop, |_| {}))
    };
    let result = with_echo(&host_a, o.spin, || {
        let a = spawn(Side::Board, &host_a, Link::Listen(endpoint.clone()));
        let b = spawn(Side::Central, &host_b, Link::Connect(endpoint.clone()));
        // The link is up when a first round trip comes back.
        let t0 = Instant::now();
        let h = loop {
            match ping_pong(&host_b, 10, o.spin, "bridge", None) {
                Ok(_) => {
                    let mut hops = o.trace.then(Hops::start);
                    let h = ping_pong(&host_b, o.iterations, o.spin, "bridge", hops.as_mut());
                    break h.map(|h| (h, hops.map(Hops::finish)));
                }
                Err(_) if t0.elapsed() < Duration::from_secs(10) => continue,
                Err(e) => break Err(e),
            }
        };
        stop.store(true, Ordering::Relaxed);
        for t in [a, b] {
            t.join().expect("a bridge thread does not panic")?;
        }
        h
    });
    remove_namespace(&host_a);
    remove_namespace(&host_b);
    result
}

/// Runs the three channels in turn.
pub(crate) fn run(o: &Options, mut progress: impl FnMut(&str)) -> Result<Report, BenchError> {
    progress("shared memory (one namespace, no bridge)");
    let direct_ns = unique("bbd");
    let direct = with_echo(&direct_ns, o.spin, || {
        ping_pong(&direct_ns, o.iterations, o.spin, "shared memory", None)
    });
    remove_namespace(&direct_ns);
    let direct = direct?;
    progress("bare Zenoh on loopback");
    let zenoh = bare_zenoh(o.port + 1, o.iterations)?;
    progress("through two bridges on loopback");
    let (bridged, hops) = through_bridges(o)?;
    let (z, b) = (latency(&zenoh), latency(&bridged));
    Ok(Report {
        iterations: o.iterations,
        spin: o.spin,
        safety_interval_ms: bridge::DEFAULT_SAFETY_INTERVAL.as_secs_f64() * 1e3,
        payload_bytes: size_of::<StateMsg>(),
        shared_memory: latency(&direct),
        bridge: Ratios {
            p50_us: b.p50_us,
            p99_us: b.p99_us,
            zenoh_p50_us: z.p50_us,
            zenoh_p99_us: z.p99_us,
            ratio_p50: b.p50_us / z.p50_us,
            ratio_p99: b.p99_us / z.p99_us,
        },
        zenoh: z,
        through_bridge: b,
        hops,
    })
}

/// The report as a table.
pub(crate) fn print(r: &Report) {
    println!(
        "one-way latency, {} round trips each, payload {} B, bridges woken by events \
         (safety interval {:.0} ms)",
        r.iterations, r.payload_bytes, r.safety_interval_ms
    );
    println!(
        "{:<34} {:>9} {:>9} {:>9}",
        "channel", "p50 µs", "p99 µs", "max µs"
    );
    for (name, l) in [
        ("shared memory (no bridge)", &r.shared_memory),
        ("bare Zenoh (loopback TCP)", &r.zenoh),
        ("through two bridges", &r.through_bridge),
    ] {
        println!(
            "{name:<34} {:>9.1} {:>9.1} {:>9.1}",
            l.p50_us, l.p99_us, l.max_us
        );
    }
    println!(
        "bridge / bare Zenoh: p50 {:.2}×, p99 {:.2}×",
        r.bridge.ratio_p50, r.bridge.ratio_p99
    );
    if let Some(h) = &r.hops {
        super::bridge_hops::print(h);
    }
}
