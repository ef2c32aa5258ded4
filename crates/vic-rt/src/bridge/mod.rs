//! A namespace across two hosts: the board on one, the central process on the other, joined by
//! Zenoh. One bridge runs on each host, beside the local daemon:
//!
//! ```text
//!  host A                                         host B
//!  board ⇄ iceoryx2 ⇄ bridge --side board ⇄ Zenoh ⇄ bridge --side central ⇄ iceoryx2 ⇄ central
//! ```
//!
//! - towards the board: command slices, control requests (resets) and disturbances;
//! - back: state, telemetry and the board's events.
//!
//! To the central process the bridge on host B *is* the board (it holds the board's ports, so a
//! second board there is refused); to the board the bridge on host A is a central process and a
//! tool. Messages cross as their bytes ([`wire`]) with the sender's session, sequence number
//! and time stamp untouched, so the board validates them as it does local ones; the bridge only
//! refuses what is not a message of this protocol (size, version) and counts it.
//!
//! **Time stamps.** The board checks a message's age against its own monotonic clock; across
//! hosts the sender's stamp is on another clock. The bridge beside the board measures the offset
//! between the two hosts' clocks over the link and translates every stamp it forwards (a reset's
//! start time too) into the board's clock ([`clock`]), so the board's age check covers the whole
//! path, link included, to within ± half the best probe's round trip. [`Stamps::Keep`] forwards
//! the senders' stamps unchanged: exact when both daemons share one machine's clock.
//!
//! **From the link** a message is published into the namespace inside the Zenoh callback that
//! received it (decoded and checked by [`wire`], its stamps translated, counted), with ports of
//! the thread-safe service type ([`crate::transport::link_ports`]): no other thread is woken
//! on the way. **To the link** (event-driven, no polling): iceoryx2 publish–subscribe has no
//! wake-up of its own, so the local publishers notify a relay event service per message
//! ([`crate::transport::relay`]: the board per state, telemetry and event; the central
//! process per command slice and control; `vic inject` per disturbance); only a bridge listens
//! there, and while none does a notification costs the publisher one atomic load. The bridge's
//! thread sleeps in an iceoryx2 wait set on that listener and puts what it drains on the link. A
//! slow safety interval (`safety_interval`, default 100 ms) drains the local side anyway, so a
//! message from a client that does not notify is late, not lost.
//!
//! **The link is authenticated.** A `tls/` endpoint (the default way) runs Zenoh's TLS with
//! mutual authentication: each bridge presents its side's certificate and accepts only a peer
//! whose certificate the pair's private authority signed ([`keys`]; `vic bridge keygen`). Any
//! other Zenoh peer fails the handshake before a message, a subscription or a clock answer
//! crosses. Plain `tcp/` ([`Security::PlainLoopback`]) has no authentication at all (any process
//! that reaches the port drives the board) and is accepted on a loopback address only.
//!
//! [`trace`] marks each hop's time for `vic bench bridge --trace` (off otherwise).

pub mod clock;
pub mod keys;
mod looper;
pub mod trace;
pub mod wire;

use crate::transport::link_ports::{FromBoardLink, ToBoardLink};
use crate::transport::ports::Topic;
use crate::transport::protocol::{
    BoardEvent, CommandSlice, Control, Disturbance, StateMsg, Telemetry,
};
use crate::transport::relay::{Relay, RelayListener};
use crate::transport::{BoardPorts, CentralPorts, TransportError};
use clock::skewed;
use looper::Looper;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};
use wire::{Malformed, Plain, decode, encode};
use zenoh::Wait;

/// Which daemon this bridge stands beside.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// Beside the board: forwards its state out, commands in.
    Board,
    /// Beside the central process: plays the board to it.
    Central,
}

/// How this bridge reaches the other one.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Link {
    /// Wait for the other bridge on this Zenoh endpoint (e.g. `tcp/0.0.0.0:7447`).
    Listen(String),
    /// Connect to the other bridge's endpoint (e.g. `tcp/robot.local:7447`).
    Connect(String),
}

/// How the link between the two bridges is secured.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Security {
    /// Mutual TLS with the pair's keys: `tls/` endpoints only.
    MutualTls(keys::KeyFiles),
    /// Plain TCP without any authentication: `tcp/` endpoints on a loopback address only (one
    /// machine; every local process can join the link).
    PlainLoopback,
}

/// What a bridge is asked for.
#[derive(Debug, Clone)]
pub struct BridgeOptions {
    /// The local iceoryx2 namespace.
    pub namespace: String,
    /// The name both bridges share: the key expressions are `vic/{link_name}/...`.
    pub link_name: String,
    pub side: Side,
    pub link: Link,
    /// How the link is secured (which endpoints are accepted).
    pub security: Security,
    /// The longest the bridge sleeps before draining the local subscribers without having been
    /// notified (messages are forwarded as they are notified; this only bounds the delay of one
    /// whose notification was missed).
    pub safety_interval: Duration,
    /// What the board-side bridge does with the stamps it forwards.
    pub stamps: Stamps,
    /// Central side, tests only: pretend this host's clock is ahead by this much (the stamps of
    /// what it forwards and its answers to the clock probes), as another host's would be.
    pub clock_skew_ns: i64,
}

/// What the bridge beside the board does with the senders' time stamps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stamps {
    /// Measure the other host's clock and translate every stamp into this one's (two hosts).
    Translate,
    /// Forward them unchanged (both daemons on one machine, one clock).
    Keep,
}

/// Messages counted per direction and kind.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct BridgeStats {
    /// Forwarded from the local namespace to the link.
    pub sent: Counts,
    /// Forwarded from the link into the local namespace.
    pub received: Counts,
    /// Bytes from the link that were not a message of the expected size, or of this protocol
    /// version (the board would refuse them; they are not forwarded).
    pub malformed_size: u64,
    pub malformed_version: u64,
    /// Local publishes that failed (the local daemon gone, ports full).
    pub local_errors: u64,
    /// The clock probes and the offset between the hosts' clocks.
    pub clock: clock::ClockStats,
}

/// One count per kind of message.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct Counts {
    pub state: u64,
    pub telemetry: u64,
    pub event: u64,
    pub command: u64,
    pub control: u64,
    pub disturbance: u64,
}

/// Why a bridge could not run.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error(transparent)]
    Transport(#[from] TransportError),
    #[error("zenoh: {what}: {message}")]
    Zenoh { what: String, message: String },
    #[error("--link-name {0:?}: use 1–32 characters of [A-Za-z0-9_-]")]
    LinkName(String),
    /// An endpoint this bridge will not use (wrong scheme for the security asked, plain TCP
    /// off loopback, Zenoh endpoint metadata).
    #[error("endpoint {endpoint:?}: {why}")]
    Endpoint { endpoint: String, why: String },
    /// The bridge thread's wait set could not be set up.
    #[error("waiting for messages: {0}")]
    Wait(String),
}

/// The default of [`BridgeOptions::safety_interval`].
pub const DEFAULT_SAFETY_INTERVAL: Duration = Duration::from_millis(100);

fn zenoh_error(what: impl Into<String>) -> impl FnOnce(zenoh::Error) -> BridgeError {
    let what = what.into();
    move |e| BridgeError::Zenoh {
        what,
        message: e.to_string(),
    }
}

/// What the link's callbacks count (they run on Zenoh's threads, beside the bridge's).
#[derive(Debug, Default)]
struct LinkCounts {
    state: AtomicU64,
    telemetry: AtomicU64,
    event: AtomicU64,
    command: AtomicU64,
    control: AtomicU64,
    disturbance: AtomicU64,
    malformed_size: AtomicU64,
    malformed_version: AtomicU64,
    /// Local publishes of what came from the link that failed.
    local_errors: AtomicU64,
}

fn add(c: &AtomicU64) {
    c.fetch_add(1, Ordering::Relaxed);
}

impl LinkCounts {
    /// `s` (the bridge thread's counts) with the callbacks' counts in.
    fn merged(&self, s: &BridgeStats) -> BridgeStats {
        let l = |c: &AtomicU64| c.load(Ordering::Relaxed);
        BridgeStats {
            received: Counts {
                state: l(&self.state),
                telemetry: l(&self.telemetry),
                event: l(&self.event),
                command: l(&self.command),
                control: l(&self.control),
                disturbance: l(&self.disturbance),
            },
            malformed_size: l(&self.malformed_size),
            malformed_version: l(&self.malformed_version),
            local_errors: s.local_errors + l(&self.local_errors),
            ..*s
        }
    }
}

/// The key expression of a topic on a link: `vic/{link}/{service name without "vic/"}`.
pub fn key<T: Topic>(link_name: &str) -> String {
    let service = T::SERVICE.trim_start_matches("vic/");
    format!("vic/{link_name}/{service}")
}

fn event_key(link_name: &str) -> String {
    format!("vic/{link_name}/board-event")
}

fn check_link_name(name: &str) -> Result<(), BridgeError> {
    let ok = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == '-';
    if name.is_empty() || name.len() > 32 || !name.chars().all(ok) {
        return Err(BridgeError::LinkName(name.to_string()));
    }
    Ok(())
}

/// Whether `host` (an endpoint's address without the port) names this machine's loopback.
fn is_loopback(host: &str) -> bool {
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host.eq_ignore_ascii_case("localhost")
        || host
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// Checks `endpoint` against `security`: `tls/HOST:PORT` with keys, `tcp/HOST:PORT` only on a
/// loopback host and only when plain TCP was asked for; no Zenoh metadata (`?`, `#`: it could
/// change the link's configuration behind the bridge's back).
pub fn check_endpoint(endpoint: &str, security: &Security) -> Result<(), BridgeError> {
    let refuse = |why: &str| {
        Err(BridgeError::Endpoint {
            endpoint: endpoint.to_string(),
            why: why.to_string(),
        })
    };
    if endpoint.len() > 300
        || endpoint.contains(['?', '#'])
        || endpoint.contains(char::is_whitespace)
    {
        return refuse("use PROTOCOL/HOST:PORT (at most 300 characters, no ?, # or spaces)");
    }
    let Some((scheme, address)) = endpoint.split_once('/') else {
        return refuse("use tls/HOST:PORT (or tcp/127.0.0.1:PORT with --insecure-plain-tcp)");
    };
    let Some((host, port)) = address.rsplit_once(':') else {
        return refuse("no port: use PROTOCOL/HOST:PORT");
    };
    if host.is_empty() || port.parse::<u16>().is_err() {
        return refuse("use PROTOCOL/HOST:PORT with a port of 0 to 65535");
    }
    match (scheme, security) {
        ("tls", Security::MutualTls(_)) => Ok(()),
        ("tls", Security::PlainLoopback) => {
            refuse("tls/ needs the pair's keys (--keys DIR, made by `vic bridge keygen`)")
        }
        ("tcp", Security::PlainLoopback) if is_loopback(host) => Ok(()),
        ("tcp", Security::PlainLoopback) => refuse(
            "plain TCP has no authentication (whoever reaches the port drives the board): \
             it is accepted on a loopback address only; between machines use tls/ with --keys",
        ),
        ("tcp", Security::MutualTls(_)) => refuse(
            "plain TCP has no authentication; with --keys use tls/HOST:PORT \
             (plain TCP only with --insecure-plain-tcp, on loopback)",
        ),
        _ => refuse("the protocol must be tls (or tcp on loopback with --insecure-plain-tcp)"),
    }
}

/// A Zenoh session for one end of the link: peer mode, no multicast scouting (the two bridges
/// find each other by the endpoint they are given, nothing else on the network joins); with
/// [`Security::MutualTls`] TLS 1.3 with client certificates, trusting the pair's authority.
fn open_session(link: &Link, security: &Security) -> Result<zenoh::Session, BridgeError> {
    let mut config = zenoh::Config::default();
    let (key, endpoint) = match link {
        Link::Listen(e) => ("listen/endpoints", e),
        Link::Connect(e) => ("connect/endpoints", e),
    };
    check_endpoint(endpoint, security)?;
    let set = |config: &mut zenoh::Config, k: &str, v: &str| {
        config
            .insert_json5(k, v)
            .map_err(zenoh_error(format!("config {k} = {v}")))
    };
    set(&mut config, key, &serde_json::json!([endpoint]).to_string())?;
    set(&mut config, "scouting/multicast/enabled", "false")?;
    // Learn no other peers' addresses from the one peer (only the given endpoint is dialled).
    set(&mut config, "scouting/gossip/enabled", "false")?;
    if let Security::MutualTls(k) = security {
        let path = |p: &std::path::Path| serde_json::json!(p.to_string_lossy()).to_string();
        let tls = "transport/link/tls";
        set(
            &mut config,
            &format!("{tls}/root_ca_certificate"),
            &path(&k.ca),
        )?;
        for role in ["listen", "connect"] {
            let cert = path(&k.certificate);
            set(&mut config, &format!("{tls}/{role}_certificate"), &cert)?;
            let key = path(&k.private_key);
            set(&mut config, &format!("{tls}/{role}_private_key"), &key)?;
        }
        set(&mut config, &format!("{tls}/enable_mtls"), "true")?;
        set(
            &mut config,
            &format!("{tls}/verify_name_on_connect"),
            "true",
        )?;
    }
    if matches!(link, Link::Connect(_)) {
        // Keep retrying a link that is not up yet or was cut: the bridge outlives its peer.
        set(&mut config, "connect/timeout_ms", "-1")?;
        set(&mut config, "connect/exit_on_failure", "false")?;
    }
    zenoh::open(config)
        .wait()
        .map_err(zenoh_error(format!("opening the session on {endpoint}")))
}

type ZPub = zenoh::pubsub::Publisher<'static>;

fn put<T: Plain>(side: Side, p: &ZPub, m: &T, stats: &mut u64, errors: &mut u64) {
    match p.put(encode(m).to_vec()).wait() {
        Ok(()) => {
            trace::mark(side, trace::Point::Put);
            *stats += 1
        }
        Err(_) => *errors += 1,
    }
}

/// Runs a bridge until `stop` is set; `report` is called about once a second with the counts.
pub fn run(
    o: &BridgeOptions,
    stop: &AtomicBool,
    mut report: impl FnMut(&BridgeStats),
) -> Result<BridgeStats, BridgeError> {
    check_link_name(&o.link_name)?;
    let session = open_session(&o.link, &o.security)?;
    let counts = Arc::new(LinkCounts::default());
    let mut stats = BridgeStats::default();
    let mut next_report = Instant::now() + Duration::from_secs(1);
    let mut tick = |stats: &BridgeStats| {
        if Instant::now() >= next_report {
            report(&counts.merged(stats));
            next_report += Duration::from_secs(1);
        }
    };
    let link = LinkEnd {
        session: &session,
        counts: &counts,
        name: &o.link_name,
        side: o.side,
    };
    let looper = Looper {
        side: o.side,
        safety: o.safety_interval,
        stop,
    };
    match o.side {
        Side::Board => board_side(o, &link, &looper, &mut tick, &mut stats)?,
        Side::Central => central_side(o, &link, &looper, &mut tick, &mut stats)?,
    }
    let _ = session.close().wait();
    Ok(counts.merged(&stats))
}

/// Where the board side's callbacks put what comes from the link: the namespace (as a central
/// process and a tool), with the stamps translated into the board's clock when there is one.
struct IntoBoard {
    ports: Arc<ToBoardLink>,
    clock: Option<Arc<clock::Prober>>,
}

impl IntoBoard {
    /// What the callbacks do with a message of type `T`: count it (`count`), translate its stamps
    /// and `publish` it into the namespace (false: the publish failed). Without a clock estimate
    /// yet the message is held back (counted by the clock), not an error.
    fn forward<T: clock::Stamped + Copy + 'static>(
        &self,
        count: fn(&LinkCounts) -> &AtomicU64,
        publish: fn(&ToBoardLink, &T) -> Result<(), TransportError>,
    ) -> impl Fn(T, &LinkCounts) -> bool + Send + Sync + 'static {
        let (ports, clock) = (self.ports.clone(), self.clock.clone());
        move |mut m, n| {
            add(count(n));
            let stamped = clock.as_ref().is_none_or(|c| c.translate(&mut m));
            !stamped || publish(&ports, &m).is_ok()
        }
    }
}

/// [`put`] from the central side, the stamps as the central host's clock has them
/// ([`skewed`]: by `skew_ns`, in tests only).
fn put_skewed<T: Plain + clock::Stamped + Copy>(
    p: &ZPub,
    m: &T,
    skew_ns: i64,
    sent: &mut u64,
    errors: &mut u64,
) {
    put(Side::Central, p, &skewed(m, skew_ns), sent, errors)
}

/// This bridge's end of the Zenoh link: its session, what its callbacks count, and the link's
/// name in the key expressions.
struct LinkEnd<'a> {
    session: &'a zenoh::Session,
    counts: &'a Arc<LinkCounts>,
    name: &'a str,
    side: Side,
}

type ZSub = zenoh::pubsub::Subscriber<()>;

impl LinkEnd<'_> {
    /// Subscribes topic `T`: every sample is checked ([`decode`]: size and protocol version;
    /// what fails is counted and dropped) and handed to `forward`, on the Zenoh thread that
    /// received it. `forward` counts the message and publishes it locally; false: the publish
    /// failed (counted).
    fn subscribe<T: Plain + Topic>(
        &self,
        forward: impl Fn(T, &LinkCounts) -> bool + Send + Sync + 'static,
    ) -> Result<ZSub, BridgeError> {
        let (counts, side) = (self.counts.clone(), self.side);
        let key = key::<T>(self.name);
        self.session
            .declare_subscriber(key.clone())
            .callback(move |sample| {
                trace::mark(side, trace::Point::Callback);
                match decode::<T>(&sample.payload().to_bytes()) {
                    Ok(m) => {
                        if !forward(m, &counts) {
                            add(&counts.local_errors);
                        }
                        trace::mark(side, trace::Point::Published);
                    }
                    Err(Malformed::Size { .. }) => add(&counts.malformed_size),
                    Err(Malformed::Version(_)) => add(&counts.malformed_version),
                }
            })
            .wait()
            .map_err(zenoh_error(format!("subscribing {key}")))
    }

    /// The publisher of topic `T` on the link.
    fn publisher<T: Topic>(&self) -> Result<ZPub, BridgeError> {
        self.declare_publisher(key::<T>(self.name))
    }

    fn declare_publisher(&self, key: String) -> Result<ZPub, BridgeError> {
        control_publisher(self.session, key)
    }
}

/// A publisher of control traffic on the link: a late sample is worth less than the next one,
/// so never block the bridge behind a congested link (drop), and send at once (express), at the
/// highest priority. Public so that `vic bench bridge` measures bare Zenoh with the same QoS.
pub fn control_publisher(session: &zenoh::Session, key: String) -> Result<ZPub, BridgeError> {
    session
        .declare_publisher(key.clone())
        .congestion_control(zenoh::qos::CongestionControl::Drop)
        .priority(zenoh::qos::Priority::RealTime)
        .express(true)
        .wait()
        .map_err(zenoh_error(format!("declaring {key}")))
}

/// The bridge beside the board: commands, controls and disturbances from the link into the
/// namespace (as a central process and a tool); state, telemetry and events out.
fn board_side(
    o: &BridgeOptions,
    link: &LinkEnd,
    looper: &Looper,
    tick: &mut impl FnMut(&BridgeStats),
    stats: &mut BridgeStats,
) -> Result<(), BridgeError> {
    // The planner's role (its subscribers feed the link; its name refuses a second planner).
    let central = CentralPorts::open(&o.namespace)?;
    let ports = Arc::new(ToBoardLink::open(&o.namespace)?);
    let state = link.publisher::<StateMsg>()?;
    let telemetry = link.publisher::<Telemetry>()?;
    let events = link.declare_publisher(event_key(link.name))?;
    let relay = RelayListener::open(central.session(), Relay::FromBoard)?;
    let clock = match o.stamps {
        Stamps::Translate => Some(Arc::new(clock::Prober::start(link.session, link.name)?)),
        Stamps::Keep => None,
    };
    let into = IntoBoard {
        ports,
        clock: clock.clone(),
    };
    let _subs = (
        link.subscribe(into.forward(|n| &n.command, ToBoardLink::publish_command))?,
        link.subscribe(into.forward(|n| &n.control, ToBoardLink::publish_control))?,
        link.subscribe(into.forward(|n| &n.disturbance, ToBoardLink::publish_disturbance))?,
    );
    looper.run(
        &relay,
        |s| {
            // Until the clocks are matched the central process sees no board (see `clock`).
            let linked = clock.as_ref().is_none_or(|c| c.ready());
            let (sent, errors) = (&mut s.sent, &mut s.local_errors);
            central.drain_states(|m| match linked {
                true => put(Side::Board, &state, m, &mut sent.state, errors),
                false => clock.iter().for_each(|c| c.hold_back()),
            });
            if let Some(t) = central.latest_telemetry().filter(|_| linked) {
                put(Side::Board, &telemetry, &t, &mut sent.telemetry, errors);
            }
            if central.take_event() && linked {
                match events.put(Vec::<u8>::new()).wait() {
                    Ok(()) => {
                        trace::mark(Side::Board, trace::Point::Put);
                        sent.event += 1
                    }
                    Err(_) => *errors += 1,
                }
            }
            if let Some(c) = &clock {
                s.clock = c.stats();
            }
            tick(s);
        },
        stats,
    )
}

/// The bridge beside the central process, playing the board to it: state, telemetry and events
/// from the link into the namespace; commands, controls and disturbances out.
fn central_side(
    o: &BridgeOptions,
    link: &LinkEnd,
    looper: &Looper,
    tick: &mut impl FnMut(&BridgeStats),
    stats: &mut BridgeStats,
) -> Result<(), BridgeError> {
    // The board's role (its subscribers feed the link; its name refuses a second board).
    let board = BoardPorts::open(&o.namespace)?;
    let from = Arc::new(FromBoardLink::open(&o.namespace)?);
    let _subs = (
        link.subscribe::<StateMsg>({
            let from = from.clone();
            move |m, n| {
                add(&n.state);
                from.publish_state(&m).is_ok()
            }
        })?,
        link.subscribe::<Telemetry>({
            let from = from.clone();
            move |t, n| {
                add(&n.telemetry);
                from.publish_telemetry(&t).is_ok()
            }
        })?,
        link.session
            .declare_subscriber(event_key(link.name))
            .callback({
                let (from, n) = (from.clone(), link.counts.clone());
                move |_| {
                    trace::mark(Side::Central, trace::Point::Callback);
                    add(&n.event);
                    from.notify(BoardEvent::Applied);
                    trace::mark(Side::Central, trace::Point::Published);
                }
            })
            .wait()
            .map_err(zenoh_error("subscribing the board's events"))?,
    );
    let commands = link.publisher::<CommandSlice>()?;
    let controls = link.publisher::<Control>()?;
    let disturbances = link.publisher::<Disturbance>()?;
    let relay = RelayListener::open(board.session(), Relay::ToBoard)?;
    let responder = clock::Responder::start(link.session, link.name, o.clock_skew_ns)?;
    let skew = o.clock_skew_ns;
    looper.run(
        &relay,
        |s| {
            let (sent, errors) = (&mut s.sent, &mut s.local_errors);
            // The stamps as the central host's clock has them (skewed in tests only).
            let sk = skew;
            board.drain_commands(|m| put_skewed(&commands, m, sk, &mut sent.command, errors));
            board.drain_controls(|m| put_skewed(&controls, m, sk, &mut sent.control, errors));
            let n = &mut sent.disturbance;
            board.drain_disturbances(|m| put_skewed(&disturbances, m, sk, n, errors));
            s.clock = responder.stats();
            tick(s);
        },
        stats,
    )
}
