//! `vic bench ipc`: latency of the state and command channels against a bare iceoryx2
//! publish/subscribe ping-pong with the same payload sizes, both as two busy-polling threads of
//! this process (the same way for vic and the baseline, so the ratio is fair), then the
//! end-to-end figures of the running `vic-board` + `vic-planner` pair ([`super::pair`]).
//!
//! Ping-pong: the "board" thread publishes a state (time-stamped on the monotonic clock), the
//! "planner" thread receives it and answers with a command slice, the board thread receives that.
//! One-way latency = receive time − publish time stamp (one clock, two threads); round trip =
//! answer received − state published.

pub(crate) use super::pair::{Pair, PairOptions, run_pair};

use super::{BenchError, Dist, ratio};
use iceoryx2::prelude::*;
use serde::Serialize;
use std::sync::{Arc, Barrier};
use vic_rt::realtime::LatencyHistogram;
use vic_rt::transport::{
    BoardPorts, CentralPorts, CommandSlice, Header, StateMsg, monotonic_ns, remove_namespace,
};

/// Bytes of the state message (the ping payload).
pub(crate) const STATE_BYTES: usize = std::mem::size_of::<StateMsg>();
/// Bytes of a command slice (the pong payload).
pub(crate) const COMMAND_BYTES: usize = std::mem::size_of::<CommandSlice>();

/// Ping-pongs not recorded at the start.
const WARM_UP: u64 = 1000;
/// Re-send a ping not answered within this long (a message lost while connecting).
const RESEND_NS: u64 = 50_000_000;
/// Give up after this many re-sends.
const MAX_RESENDS: u64 = 100;

/// The three figures of a ping-pong.
#[derive(Debug, Clone, Copy, Serialize, Default)]
pub(crate) struct Channels {
    /// Board → planner, `StateMsg`-sized.
    pub(crate) state_one_way: Dist,
    /// Planner → board, `CommandSlice`-sized.
    pub(crate) command_one_way: Dist,
    pub(crate) round_trip: Dist,
    pub(crate) resends: u64,
}

/// One side of a ping-pong, whatever carries it.
trait Side {
    /// Sends `(seq, now)`.
    fn send(&mut self, seq: u64, time_ns: u64) -> Result<()>;
    /// Polls once: the newest `(seq, publish stamp, receive time)`, if any; the receive time is
    /// taken as soon as the message is in hand.
    fn poll(&mut self) -> Option<(u64, u64, u64)>;
}

/// A side of vic's own channels: `$ports` publishes `$out` messages with `$publish` and drains
/// the other side's with `$drain`, the sequence number and stamp in the shared header.
macro_rules! vic_side {
    ($name:ident, $ports:ty, $out:ident, $publish:ident, $drain:ident) => {
        struct $name($ports);

        impl Side for $name {
            fn send(&mut self, seq: u64, time_ns: u64) -> Result<()> {
                let m = $out {
                    header: Header::new(seq, time_ns),
                    ..Default::default()
                };
                Ok(self.0.$publish(&m)?)
            }
            fn poll(&mut self) -> Option<(u64, u64, u64)> {
                let mut last = None;
                self.0
                    .$drain(|m| last = Some((m.header.seq, m.header.time_ns, monotonic_ns())));
                last
            }
        }
    };
}

vic_side!(
    VicBoard,
    BoardPorts,
    StateMsg,
    publish_state,
    drain_commands
);
vic_side!(
    VicPlanner,
    CentralPorts,
    CommandSlice,
    publish_command,
    drain_states
);

type Bytes<const N: usize> = [u8; N];

/// A bare iceoryx2 side: publishes `[u8; OUT]`, subscribes to `[u8; IN]`, sequence number and
/// time stamp in the first 16 bytes. Default QoS, loan → write → send.
struct Bare<const OUT: usize, const IN: usize> {
    publisher: iceoryx2::port::publisher::Publisher<ipc::Service, Bytes<OUT>, ()>,
    subscriber: iceoryx2::port::subscriber::Subscriber<ipc::Service, Bytes<IN>, ()>,
    _node: Node<ipc::Service>,
}

impl<const OUT: usize, const IN: usize> Bare<OUT, IN> {
    fn open(ns: &str, out: &str, input: &str) -> Result<Self> {
        set_log_level(LogLevel::Error);
        let cfg = vic_rt::transport::namespace::config(ns)?;
        let node = NodeBuilder::new()
            .config(&cfg)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| BenchError::iceoryx("node", e))?;
        let name = |n: &str| ServiceName::new(n).map_err(|e| BenchError::iceoryx(n, e));
        let svc_out = node
            .service_builder(&name(out)?)
            .publish_subscribe::<Bytes<OUT>>()
            .open_or_create()
            .map_err(|e| BenchError::iceoryx(format!("service {out}"), e))?;
        let svc_in = node
            .service_builder(&name(input)?)
            .publish_subscribe::<Bytes<IN>>()
            .open_or_create()
            .map_err(|e| BenchError::iceoryx(format!("service {input}"), e))?;
        Ok(Bare {
            publisher: svc_out
                .publisher_builder()
                .create()
                .map_err(|e| BenchError::iceoryx("publisher", e))?,
            subscriber: svc_in
                .subscriber_builder()
                .create()
                .map_err(|e| BenchError::iceoryx("subscriber", e))?,
            _node: node,
        })
    }
}

impl<const OUT: usize, const IN: usize> Side for Bare<OUT, IN> {
    fn send(&mut self, seq: u64, time_ns: u64) -> Result<()> {
        let mut b = [0u8; OUT];
        b[..8].copy_from_slice(&seq.to_le_bytes());
        b[8..16].copy_from_slice(&time_ns.to_le_bytes());
        let sample = self
            .publisher
            .loan_uninit()
            .map_err(|e| BenchError::iceoryx("loan", e))?;
        sample
            .write_payload(b)
            .send()
            .map(|_| ())
            .map_err(|e| BenchError::iceoryx("send", e))
    }
    fn poll(&mut self) -> Option<(u64, u64, u64)> {
        let s = self.subscriber.receive().ok()??;
        let now = monotonic_ns();
        let b: &Bytes<IN> = &s;
        let word = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().expect("8 bytes"));
        Some((word(0), word(8), now))
    }
}

/// The ping-pong: `pinger` plays the board, `ponger` the planner; each side is created inside its
/// own thread (iceoryx2 ports stay on the thread that made them).
fn ping_pong<P: Side, Q: Side>(
    iterations: u64,
    make_pinger: impl FnOnce() -> Result<P> + Send + 'static,
    make_ponger: impl FnOnce() -> Result<Q> + Send + 'static,
) -> Result<Channels> {
    let barrier = Arc::new(Barrier::new(2));
    let last = WARM_UP + iterations;
    let b = barrier.clone();
    let ponger = std::thread::spawn(move || -> Result<LatencyHistogram> {
        let side = make_ponger();
        b.wait();
        let mut side = side?;
        let mut h = LatencyHistogram::new();
        let mut answered = 0u64;
        let mut idle_since = monotonic_ns();
        while answered < last {
            match side.poll() {
                Some((seq, t, now)) if seq > answered => {
                    if seq > WARM_UP {
                        h.record(now.saturating_sub(t));
                    }
                    answered = seq;
                    side.send(seq, monotonic_ns())?;
                    idle_since = now;
                }
                _ => {
                    std::hint::spin_loop();
                    if monotonic_ns() - idle_since > RESEND_NS * MAX_RESENDS {
                        return Err(BenchError::Quiet);
                    }
                }
            }
        }
        Ok(h)
    });
    let pinger = {
        let b = barrier;
        std::thread::spawn(
            move || -> Result<(LatencyHistogram, LatencyHistogram, u64)> {
                let side = make_pinger();
                b.wait();
                let mut side = side?;
                let mut one_way = LatencyHistogram::new();
                let mut rtt = LatencyHistogram::new();
                let mut resends = 0u64;
                for seq in 1..=last {
                    let t0 = monotonic_ns();
                    side.send(seq, t0)?;
                    let mut sent = t0;
                    loop {
                        if let Some((s, t, now)) = side.poll()
                            && s >= seq
                        {
                            if seq > WARM_UP {
                                one_way.record(now.saturating_sub(t));
                                rtt.record(now - t0);
                            }
                            break;
                        }
                        std::hint::spin_loop();
                        let now = monotonic_ns();
                        if now - sent > RESEND_NS {
                            resends += 1;
                            if resends > MAX_RESENDS {
                                return Err(BenchError::NoAnswer(seq));
                            }
                            sent = now;
                            side.send(seq, now)?;
                        }
                    }
                }
                Ok((one_way, rtt, resends))
            },
        )
    };
    let pinged = pinger.join().map_err(|_| BenchError::Panicked("ping"))?;
    let ponged = ponger.join().map_err(|_| BenchError::Panicked("pong"))?;
    let (command, rtt, resends) = pinged?;
    let state = ponged?;
    Ok(Channels {
        state_one_way: Dist::from_histogram(&state),
        command_one_way: Dist::from_histogram(&command),
        round_trip: Dist::from_histogram(&rtt),
        resends,
    })
}

type Result<T, E = BenchError> = std::result::Result<T, E>;

/// vic's channels: [`BoardPorts`] and [`CentralPorts`], the real message types.
pub(crate) fn vic_ping_pong(iterations: u64) -> Result<Channels> {
    let ns = super::unique_namespace("bi");
    let (a, b) = (ns.clone(), ns.clone());
    let r = ping_pong(
        iterations,
        move || Ok(BoardPorts::open(&a).map(VicBoard)?),
        move || Ok(CentralPorts::open(&b).map(VicPlanner)?),
    );
    remove_namespace(&ns);
    r
}

/// The baseline: bare iceoryx2 with `[u8; size_of::<StateMsg>()]` one way and
/// `[u8; size_of::<CommandSlice>()]` back, default QoS, its own `global.prefix`.
pub(crate) fn bare_ping_pong(iterations: u64) -> Result<Channels> {
    let ns = super::unique_namespace("bb");
    let (a, b) = (ns.clone(), ns.clone());
    let r = ping_pong(
        iterations,
        move || Bare::<STATE_BYTES, COMMAND_BYTES>::open(&a, "bench/ping", "bench/pong"),
        move || Bare::<COMMAND_BYTES, STATE_BYTES>::open(&b, "bench/pong", "bench/ping"),
    );
    remove_namespace(&ns);
    r
}

/// Options of `vic bench ipc`.
#[derive(Debug, Clone)]
pub(crate) struct Options {
    pub(crate) iterations: u64,
    /// The running pair, or `None` to skip it.
    pub(crate) pair: Option<PairOptions>,
}

/// The whole report of `vic bench ipc`.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Report {
    pub(crate) iterations: u64,
    pub(crate) state_bytes: usize,
    pub(crate) command_bytes: usize,
    pub(crate) method: String,
    /// State channel one way (the documented summary).
    pub(crate) vic: Dist,
    pub(crate) baseline: Dist,
    pub(crate) ratio_p50: Option<f64>,
    pub(crate) ratio_p99: Option<f64>,
    pub(crate) vic_channels: Channels,
    pub(crate) baseline_channels: Channels,
    pub(crate) ratio_command_p50: Option<f64>,
    pub(crate) ratio_round_trip_p50: Option<f64>,
    pub(crate) pair: Option<Pair>,
    pub(crate) pair_note: Option<String>,
    pub(crate) machine: super::Machine,
}

/// Runs the baseline, vic, then the pair.
pub(crate) fn run(o: &Options, mut progress: impl FnMut(&str)) -> Result<Report> {
    let machine = super::Machine::detect();
    progress(&format!(
        "bare iceoryx2 ping-pong, {} + {} bytes, {} iterations",
        STATE_BYTES, COMMAND_BYTES, o.iterations
    ));
    let bare = bare_ping_pong(o.iterations)?;
    progress(&format!(
        "vic state/command ping-pong, {} iterations",
        o.iterations
    ));
    let vic = vic_ping_pong(o.iterations)?;
    let (pair, pair_note) = match &o.pair {
        Some(p) => {
            progress(&format!(
                "vic-board + vic-planner, {} trials of the stiffness strategy",
                p.trials
            ));
            (Some(run_pair(p)?), None)
        }
        None => (None, Some("the running pair was skipped".to_string())),
    };
    Ok(Report {
        iterations: o.iterations,
        state_bytes: STATE_BYTES,
        command_bytes: COMMAND_BYTES,
        method: "two busy-polling threads of one process for both vic and the baseline, \
                 baseline first; one-way = receive time − publish stamp on CLOCK_MONOTONIC"
            .into(),
        vic: vic.state_one_way,
        baseline: bare.state_one_way,
        ratio_p50: ratio(vic.state_one_way.p50_us, Some(bare.state_one_way.p50_us)),
        ratio_p99: ratio(vic.state_one_way.p99_us, Some(bare.state_one_way.p99_us)),
        ratio_command_p50: ratio(
            vic.command_one_way.p50_us,
            Some(bare.command_one_way.p50_us),
        ),
        ratio_round_trip_p50: ratio(vic.round_trip.p50_us, Some(bare.round_trip.p50_us)),
        vic_channels: vic,
        baseline_channels: bare,
        pair,
        pair_note,
        machine,
    })
}

/// The report as a table.
pub(crate) fn print(r: &Report) {
    println!(
        "transport, {} iterations; state {} B, command {} B; {}",
        r.iterations, r.state_bytes, r.command_bytes, r.method
    );
    println!("machine: {}", r.machine.line());
    let rows = [
        (
            "state one-way",
            &r.vic_channels.state_one_way,
            &r.baseline_channels.state_one_way,
        ),
        (
            "command one-way",
            &r.vic_channels.command_one_way,
            &r.baseline_channels.command_one_way,
        ),
        (
            "round trip",
            &r.vic_channels.round_trip,
            &r.baseline_channels.round_trip,
        ),
    ];
    for (name, v, b) in rows {
        println!("{name:<16} vic      {}", v.line());
        println!("{:<16} iceoryx2 {}", "", b.line());
        println!(
            "{:<16} ratio p50 {}  p99 {}",
            "",
            super::ratio_text(ratio(v.p50_us, Some(b.p50_us))),
            super::ratio_text(ratio(v.p99_us, Some(b.p99_us)))
        );
    }
    println!(
        "headline: state one-way p50 {:.2} µs vs bare {:.2} µs: ratio {} (target ≤ 1.2×)",
        r.vic.p50_us,
        r.baseline.p50_us,
        super::ratio_text(r.ratio_p50)
    );
    match &r.pair {
        Some(p) => {
            println!("running pair ({} trials):", p.trials);
            println!("  state age at a reader   {}", p.state_age_us.line());
            println!("  command age at board    {}", p.command_age_us.line());
            println!("  pulse → board state     {}", p.pulse_to_effect_us.line());
            println!(
                "  pulse → state observed  {}",
                p.pulse_to_observed_us.line()
            );
        }
        None => println!("running pair: {}", r.pair_note.as_deref().unwrap_or("-")),
    }
}
