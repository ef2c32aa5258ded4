//! The two hosts' clocks, matched over the link. The board checks a message's age against its
//! own monotonic clock; a message from the central host is stamped with *that* host's clock,
//! which differs from the board's by an unknown offset (seconds: each clock counts from its
//! host's boot) and drifts apart (crystals differ by tens of ppm). So the bridge beside the board
//! measures the offset, NTP-style, and translates every stamp it forwards into its own clock:
//! the board's age check then still covers the whole path, link included.
//!
//! **Probes.** The board-side bridge ([`Prober`]) sends a probe stamped `t0` (its clock) every
//! [`PROBE_PERIOD`]; the central-side bridge ([`Responder`]) stamps its arrival `t1` and its
//! answer `t2` (its clock); the answer arrives back at `t3` (board clock). With `d_out`, `d_back`
//! the two one-way delays and `offset` = board clock − central clock,
//!
//! ```text
//!   offset ≈ ((t0 − t1) + (t3 − t2)) / 2 = offset + (d_back − d_out) / 2
//!   round trip = (t3 − t0) − (t2 − t1)    = d_out + d_back
//! ```
//!
//! (the NTP offset `((t1 − t0) + (t2 − t3)) / 2` with the sign turned: it is the central clock
//! minus the board's). An unknown asymmetry of the delays cannot be measured from the two ends,
//! so the estimate is exact to within ± round trip / 2, and that bound is smallest for the probe
//! with the smallest round trip. The [`Estimator`] keeps the last [`WINDOW`] probes and uses the
//! one with the smallest round trip: a probe delayed in one direction (a busy host, a queued
//! packet) has a long round trip and is ignored rather than averaged in. The drift is the
//! least-squares slope of the offset through the best probe of each of the last [`BLOCKS`]
//! windows (about two minutes), applied from the best probe's time on, so that an estimate up to
//! a window old does not lag a drifting clock.
//!
//! **Before the first estimate** the board-side bridge forwards nothing in either direction: no
//! command (its stamp cannot be checked, and a reset's start time would be in the wrong clock),
//! and no state, so that the central process sees no board until the clocks are matched and does
//! not send a reset that would be held back. The first probes go out every
//! [`FIRST_PROBE_PERIOD`], so this lasts one round trip once the link is up.

mod estimator;

pub use estimator::{BLOCKS, Estimate, Estimator, Probe, Sample, WINDOW};

use super::{BridgeError, control_publisher, zenoh_error};
use crate::transport::monotonic_ns;
use crate::transport::protocol::{CommandSlice, Control, ControlKind, Disturbance};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use zenoh::Wait;

/// Probes per second once an estimate exists: 5.
pub(crate) const PROBE_PERIOD: Duration = Duration::from_millis(200);
/// Probe period until the first answer: the link counts as up one round trip after it is.
pub(crate) const FIRST_PROBE_PERIOD: Duration = Duration::from_millis(20);
/// A message whose stamps the bridge translates: its header's `time_ns` and, for a reset, the
/// monotonic time the trial starts at (both on the sender's clock).
pub trait Stamped {
    fn stamps(&mut self) -> (&mut u64, Option<&mut u64>);
}

impl Stamped for CommandSlice {
    fn stamps(&mut self) -> (&mut u64, Option<&mut u64>) {
        // `start_ns` of a slice is trial time, not a clock's.
        (&mut self.header.time_ns, None)
    }
}

impl Stamped for Disturbance {
    fn stamps(&mut self) -> (&mut u64, Option<&mut u64>) {
        (&mut self.header.time_ns, None)
    }
}

impl Stamped for Control {
    fn stamps(&mut self) -> (&mut u64, Option<&mut u64>) {
        let reset = self.kind == ControlKind::Reset as u32;
        (
            &mut self.header.time_ns,
            reset.then_some(&mut self.start_ns),
        )
    }
}

/// `m` with its stamps moved by `skew_ns` (the test-only skewed clock of a central host).
pub fn skewed<M: Stamped + Copy>(m: &M, skew_ns: i64) -> M {
    let mut m = *m;
    let (time, start) = m.stamps();
    *time = time.saturating_add_signed(skew_ns);
    if let Some(s) = start {
        *s = s.saturating_add_signed(skew_ns);
    }
    m
}

/// Counts and the estimate, as the bridge reports them (all zero / absent on a bridge that
/// keeps the senders' stamps).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct ClockStats {
    /// Board side: probes sent, answers taken, answers refused (not to a probe of ours, or with
    /// impossible stamps), messages held back before the first estimate.
    pub probes_sent: u64,
    pub answers: u64,
    pub answers_refused: u64,
    pub held_back: u64,
    /// Central side: probes answered, and bytes on the probe key that were not a probe.
    pub probes_answered: u64,
    pub probes_malformed: u64,
    /// Board clock − central clock now [ns], and ± how much.
    pub offset_ns: Option<i64>,
    pub uncertainty_ns: Option<u64>,
    /// The best probe's round trip [ns], and the median over the window.
    pub round_trip_ns: Option<u64>,
    pub round_trip_median_ns: Option<u64>,
    pub drift_ppb: Option<i64>,
}

const PROBE_MAGIC: u32 = u32::from_le_bytes(*b"vclk");
const PROBE_LEN: usize = 24;
const ANSWER_LEN: usize = 40;

fn probe_key(link_name: &str) -> String {
    format!("vic/{link_name}/clock/probe")
}

fn answer_key(link_name: &str) -> String {
    format!("vic/{link_name}/clock/answer")
}

/// Little-endian: magic (u32), 0 (u32), then the u64s.
fn encode_words(words: &[u64]) -> Vec<u8> {
    let mut b = Vec::with_capacity(8 + 8 * words.len());
    b.extend_from_slice(&PROBE_MAGIC.to_le_bytes());
    b.extend_from_slice(&0u32.to_le_bytes());
    for w in words {
        b.extend_from_slice(&w.to_le_bytes());
    }
    b
}

/// The `N` words of a probe (N = 2: id, t0) or an answer (N = 4: id, t0, t1, t2), when `bytes`
/// are exactly that.
fn decode_words<const N: usize>(bytes: &[u8]) -> Option<[u64; N]> {
    if bytes.len() != 8 + 8 * N || bytes[..4] != PROBE_MAGIC.to_le_bytes() || bytes[4..8] != [0; 4]
    {
        return None;
    }
    let mut w = [0u64; N];
    for (i, c) in bytes[8..].chunks_exact(8).enumerate() {
        w[i] = u64::from_le_bytes(c.try_into().ok()?);
    }
    Some(w)
}

const _: () = assert!(PROBE_LEN == 8 + 8 * 2 && ANSWER_LEN == 8 + 8 * 4);

/// Probes in flight, by id modulo their number: an answer counts only for the probe it answers.
const IN_FLIGHT: usize = 16;

struct ProberShared {
    estimator: Mutex<Estimator>,
    /// What the estimator said after the last answer (read per message and per drain, so
    /// computed once per answer).
    current: Mutex<Current>,
    ready: AtomicBool,
    in_flight: Mutex<[(u64, u64); IN_FLIGHT]>,
    probes_sent: AtomicU64,
    answers: AtomicU64,
    answers_refused: AtomicU64,
    held_back: AtomicU64,
    stop: AtomicBool,
}

#[derive(Debug, Clone, Copy, Default)]
struct Current {
    estimate: Option<Estimate>,
    median_round_trip_ns: Option<u64>,
}

/// The board side's clock: probes the other bridge and translates stamps into this host's clock.
pub(crate) struct Prober {
    shared: Arc<ProberShared>,
    thread: Option<std::thread::JoinHandle<()>>,
    _answers: zenoh::pubsub::Subscriber<()>,
}

impl Prober {
    /// Subscribes the answers and starts the probing thread.
    pub fn start(session: &zenoh::Session, link_name: &str) -> Result<Prober, BridgeError> {
        let shared = Arc::new(ProberShared {
            estimator: Mutex::new(Estimator::default()),
            current: Mutex::new(Current::default()),
            ready: AtomicBool::new(false),
            in_flight: Mutex::new([(u64::MAX, 0); IN_FLIGHT]),
            probes_sent: AtomicU64::new(0),
            answers: AtomicU64::new(0),
            answers_refused: AtomicU64::new(0),
            held_back: AtomicU64::new(0),
            stop: AtomicBool::new(false),
        });
        let answers = session
            .declare_subscriber(answer_key(link_name))
            .callback({
                let shared = shared.clone();
                move |sample| {
                    let t3 = monotonic_ns();
                    shared.answer(&sample.payload().to_bytes(), t3);
                }
            })
            .wait()
            .map_err(zenoh_error("subscribing the clock probes' answers"))?;
        let key = probe_key(link_name);
        let publisher = control_publisher(session, key)?;
        let thread = std::thread::Builder::new()
            .name("vic-bridge-clock".into())
            .spawn({
                let shared = shared.clone();
                move || shared.probe(&publisher)
            })
            .map_err(|e| BridgeError::Zenoh {
                what: "starting the clock's thread".into(),
                message: e.to_string(),
            })?;
        Ok(Prober {
            shared,
            thread: Some(thread),
            _answers: answers,
        })
    }

    /// The estimate so far.
    pub fn estimate(&self) -> Option<Estimate> {
        lock(&self.shared.current).estimate
    }

    /// Whether a probe came back: the link is up and stamps can be translated.
    pub fn ready(&self) -> bool {
        self.shared.ready.load(Ordering::Relaxed)
    }

    /// Translates `m`'s stamps from the central host's clock into this one's; false when there
    /// is no estimate yet (the message is to be held back; counted).
    pub fn translate<M: Stamped + ?Sized>(&self, m: &mut M) -> bool {
        let Some(e) = self.estimate() else {
            self.hold_back();
            return false;
        };
        let now = monotonic_ns();
        let (time, start) = m.stamps();
        *time = e.to_local(*time, now);
        if let Some(s) = start {
            *s = e.to_local(*s, now);
        }
        true
    }

    /// Counts a message not forwarded for want of an estimate.
    pub(crate) fn hold_back(&self) {
        self.shared.held_back.fetch_add(1, Ordering::Relaxed);
    }

    pub fn stats(&self) -> ClockStats {
        let s = &self.shared;
        let Current {
            estimate: e,
            median_round_trip_ns: median,
        } = *lock(&s.current);
        ClockStats {
            probes_sent: s.probes_sent.load(Ordering::Relaxed),
            answers: s.answers.load(Ordering::Relaxed),
            answers_refused: s.answers_refused.load(Ordering::Relaxed),
            held_back: s.held_back.load(Ordering::Relaxed),
            offset_ns: e.map(|e| e.offset_at(monotonic_ns())),
            uncertainty_ns: e.map(|e| e.uncertainty_ns()),
            round_trip_ns: e.map(|e| e.round_trip_ns),
            round_trip_median_ns: median,
            drift_ppb: e.map(|e| e.drift_ppb),
            ..Default::default()
        }
    }
}

impl Drop for Prober {
    fn drop(&mut self) {
        self.shared.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    // A panic elsewhere leaves plain data behind: keep using it.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

impl ProberShared {
    /// Sends a probe every period until stopped (fast until the first answer).
    fn probe(&self, publisher: &zenoh::pubsub::Publisher<'static>) {
        let mut next = std::time::Instant::now();
        let mut id = 0u64;
        while !self.stop.load(Ordering::Relaxed) {
            let t0 = monotonic_ns();
            lock(&self.in_flight)[id as usize % IN_FLIGHT] = (id, t0);
            if publisher.put(encode_words(&[id, t0])).wait().is_ok() {
                self.probes_sent.fetch_add(1, Ordering::Relaxed);
            }
            id += 1;
            let ready = self.ready.load(Ordering::Relaxed);
            next += if ready {
                PROBE_PERIOD
            } else {
                FIRST_PROBE_PERIOD
            };
            // Absolute deadlines; `Drop` unparks the thread to stop it at once.
            let now = std::time::Instant::now();
            if next > now {
                std::thread::park_timeout(next - now);
            } else {
                next = now;
            }
        }
    }

    /// Adds a probe to the estimator and publishes what it now says; false when refused.
    fn learn(&self, probe: &Probe) -> bool {
        let current = {
            let mut e = lock(&self.estimator);
            if !e.add(probe) {
                return false;
            }
            Current {
                estimate: e.estimate(),
                median_round_trip_ns: e.median_round_trip_ns(),
            }
        };
        *lock(&self.current) = current;
        self.ready.store(true, Ordering::Relaxed);
        true
    }

    /// An answer arrived at `t3`: taken when it answers a probe in flight (each once).
    fn answer(&self, bytes: &[u8], t3: u64) {
        let taken = decode_words::<4>(bytes).is_some_and(|[id, t0, t1, t2]| {
            let mine = {
                let mut f = lock(&self.in_flight);
                let slot = &mut f[id as usize % IN_FLIGHT];
                let mine = *slot == (id, t0);
                if mine {
                    *slot = (u64::MAX, 0);
                }
                mine
            };
            mine && self.learn(&Probe { t0, t1, t2, t3 })
        });
        let counter = if taken {
            &self.answers
        } else {
            &self.answers_refused
        };
        counter.fetch_add(1, Ordering::Relaxed);
    }
}

/// The central side's clock: answers the board side's probes, on its own clock plus a skew
/// (0 but in tests, which pretend the hosts' clocks differ).
pub struct Responder {
    answered: Arc<AtomicU64>,
    malformed: Arc<AtomicU64>,
    _probes: zenoh::pubsub::Subscriber<()>,
}

impl Responder {
    pub fn start(
        session: &zenoh::Session,
        link_name: &str,
        skew_ns: i64,
    ) -> Result<Responder, BridgeError> {
        let key = answer_key(link_name);
        let publisher = control_publisher(session, key)?;
        let answered = Arc::new(AtomicU64::new(0));
        let malformed = Arc::new(AtomicU64::new(0));
        let clock = move || monotonic_ns().saturating_add_signed(skew_ns);
        let probes = session
            .declare_subscriber(probe_key(link_name))
            .callback({
                let (answered, malformed) = (answered.clone(), malformed.clone());
                move |sample| {
                    let t1 = clock();
                    match decode_words::<2>(&sample.payload().to_bytes()) {
                        Some([id, t0]) => {
                            let answer = encode_words(&[id, t0, t1, clock()]);
                            if publisher.put(answer).wait().is_ok() {
                                answered.fetch_add(1, Ordering::Relaxed);
                            }
                        }
                        None => {
                            malformed.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                }
            })
            .wait()
            .map_err(zenoh_error("subscribing the clock probes"))?;
        Ok(Responder {
            answered,
            malformed,
            _probes: probes,
        })
    }

    pub fn stats(&self) -> ClockStats {
        ClockStats {
            probes_answered: self.answered.load(Ordering::Relaxed),
            probes_malformed: self.malformed.load(Ordering::Relaxed),
            ..Default::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::protocol::Header;

    #[test]
    fn probes_and_answers_cross_as_their_words() {
        let b = encode_words(&[7, 123]);
        assert_eq!(b.len(), PROBE_LEN);
        assert_eq!(decode_words::<2>(&b), Some([7, 123]));
        assert_eq!(decode_words::<4>(&b), None);
        let mut bad = b.clone();
        bad[0] ^= 1;
        assert_eq!(decode_words::<2>(&bad), None);
        assert_eq!(
            decode_words::<4>(&encode_words(&[1, 2, 3, 4])),
            Some([1, 2, 3, 4])
        );
    }

    #[test]
    fn a_reset_moves_its_start_time_and_a_slice_only_its_stamp() {
        let mut c = Control {
            kind: ControlKind::Reset as u32,
            start_ns: 2_000,
            header: Header::new(1, 1_000),
            ..Default::default()
        };
        let s = skewed(&c, 500);
        assert_eq!((s.header.time_ns, s.start_ns), (1_500, 2_500));
        c.kind = ControlKind::Stop as u32;
        assert_eq!(skewed(&c, 500).start_ns, 2_000);
        let slice = CommandSlice {
            header: Header::new(1, 1_000),
            start_ns: 30,
            ..Default::default()
        };
        let s = skewed(&slice, -400);
        assert_eq!((s.header.time_ns, s.start_ns), (600, 30));
    }
}
