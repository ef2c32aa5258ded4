//! A namespace served live to Foxglove (`vic view`, feature `foxglove`): the Foxglove SDK's
//! WebSocket server carries the channels of a recording, with the topics and JSON schemas of
//! `vic record`'s MCAP files (so one layout, `docs/foxglove-layout.json`, opens a live board and
//! a recording alike), and two channels derived from them:
//!
//! - `/reference`: at each state shown, the knot of the command slice the board is executing
//!   (its `command_seq`), at the state's trial time: the plan the joints are held to (paper
//!   Eq. 4's `q_d`, `K_P`, `τ_ff`), and the joints' error from it;
//! - `/hand`: the hand's position and its planned position, when the caller gives the plant's
//!   kinematics.
//!
//! States come at 1 kHz; a plot needs far fewer, so every `state_every`-th state is shown (with
//! its `/reference` and `/hand`); the other channels pass whole. The viewer is an observer
//! ([`RecorderPorts`]): it publishes nothing into the namespace.

use super::error::RecordError;
use super::external::TopicCount;
use super::observe::{Item, SPECS, StateTrack, drain};
use crate::transport::{CommandSlice, MAX_JOINTS, MAX_KNOTS, RecorderPorts, StateMsg};
use foxglove::{ChannelBuilder, Context, RawChannel, Schema, WebSocketServer};
use serde::Serialize;
use serde_json::{Value, json};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The plant's hand position [m] from its joint angles [rad].
pub type Kinematics = dyn Fn(&[f64]) -> [f64; 2];

/// What `vic view` was asked for.
#[derive(Debug, Clone)]
pub struct ViewOptions {
    /// Address and port to listen on (port 0: any free port).
    pub host: String,
    pub port: u16,
    /// Show every this-many-th state (1: all 1000 a second).
    pub state_every: u64,
    /// Stop this long after the first state [ns] (0: when `stop` is set).
    pub duration_ns: u64,
    /// How long to wait for the board's first state before giving up [ms].
    pub wait_for_board_ms: u64,
}

/// What a view served.
#[derive(Debug, Clone, Serialize)]
pub struct ViewSummary {
    pub namespace: String,
    /// The port it listened on.
    pub port: u16,
    /// States received, and shown (every `state_every`-th).
    pub states: u64,
    pub states_shown: u64,
    /// States the board published that the viewer missed, and the gaps they came in.
    pub states_lost: u64,
    pub gaps: u64,
    /// Messages per channel.
    pub topics: Vec<TopicCount>,
    /// Seconds from the first state to the end.
    pub seconds: f64,
}

/// The derived channels' topics.
pub const REFERENCE_TOPIC: &str = "/reference";
pub const HAND_TOPIC: &str = "/hand";

/// The last command slices received, to find the one a state names (its `command_seq`).
struct Slices {
    ring: [Option<CommandSlice>; 8],
    next: usize,
}

impl Slices {
    fn push(&mut self, c: &CommandSlice) {
        self.ring[self.next % self.ring.len()] = Some(*c);
        self.next += 1;
    }

    /// The knot of slice `seq` the board holds at trial time `t_ns` (zero-order hold, or linear
    /// between knots when the slice says so; the last knot past its end), as (q_d, qd_d,
    /// stiffness, tau_ff) per joint.
    fn knot_at(&self, s: &StateMsg) -> Option<[Vec<f64>; 4]> {
        let c = self.ring.iter().flatten().find(|c| {
            c.header.seq == s.command_seq && c.trial == s.trial && c.count > 0 && c.knot_dt_ns > 0
        })?;
        let n = (c.joints as usize).min(MAX_JOINTS);
        let count = (c.count as usize).min(MAX_KNOTS);
        let since = s.trial_time_ns.saturating_sub(c.start_ns) as f64 / c.knot_dt_ns as f64;
        let i = (since.floor() as usize).min(count - 1);
        let (a, b) = (&c.knots[i], &c.knots[(i + 1).min(count - 1)]);
        let w = if c.interpolation == 1 && i + 1 < count {
            since - i as f64
        } else {
            0.0
        };
        let mix = |x: &[f64; MAX_JOINTS], y: &[f64; MAX_JOINTS]| -> Vec<f64> {
            (0..n).map(|j| x[j] + w * (y[j] - x[j])).collect()
        };
        Some([
            mix(&a.q_d, &b.q_d),
            mix(&a.qd_d, &b.qd_d),
            mix(&a.stiffness, &b.stiffness),
            mix(&a.tau_ff, &b.tau_ff),
        ])
    }
}

fn number_array(doc: &str) -> Value {
    json!({"type": "array", "items": {"type": ["number", "null"]}, "description": doc})
}

fn object(title: &str, fields: &[(&str, Value)]) -> Vec<u8> {
    let properties: serde_json::Map<String, Value> = fields
        .iter()
        .map(|(k, v)| (k.to_string(), v.clone()))
        .collect();
    let required: Vec<&str> = fields.iter().map(|(k, _)| *k).collect();
    serde_json::to_vec(
        &json!({"type": "object", "title": title, "properties": properties,
        "required": required}),
    )
    .expect("a JSON value serialises")
}

fn reference_schema() -> Vec<u8> {
    let int = |d: &str| json!({"type": "integer", "description": d});
    object(
        "vic.Reference",
        &[
            ("tick", int("board tick of the state")),
            ("trial", int("trial")),
            ("command_seq", int("the command slice the board executes")),
            (
                "q_d",
                number_array("planned joint angles [rad] (Eq. 4's q_d)"),
            ),
            ("qd_d", number_array("planned joint velocities [rad/s]")),
            ("stiffness", number_array("planned stiffness K_P [N m/rad]")),
            ("tau_ff", number_array("planned feedforward torque [N m]")),
            ("q", number_array("joint angles [rad]")),
            ("q_error", number_array("q - q_d [rad]")),
        ],
    )
}

fn hand_schema() -> Vec<u8> {
    let num = |d: &str| json!({"type": ["number", "null"], "description": d});
    object(
        "vic.Hand",
        &[
            (
                "tick",
                json!({"type": "integer", "description": "board tick of the state"}),
            ),
            ("x", num("hand x [m], shoulder at the origin")),
            ("y", num("hand y [m]")),
            ("x_d", num("planned hand x [m] (from q_d)")),
            ("y_d", num("planned hand y [m]")),
        ],
    )
}

fn finite(v: f64) -> Value {
    if v.is_finite() { json!(v) } else { Value::Null }
}

fn channel(
    ctx: &Arc<Context>,
    topic: &str,
    name: &str,
    schema: Vec<u8>,
) -> Result<Arc<RawChannel>, RecordError> {
    ChannelBuilder::new(topic)
        .context(ctx)
        .message_encoding("json")
        .schema(Schema::new(name, "jsonschema", schema))
        .build_raw()
        .map_err(|e| RecordError::View {
            message: format!("channel {topic}: {e}"),
        })
}

/// Serves namespace `ns` to Foxglove until `stop` is set or the duration ends. `ready` gets
/// the port once the server listens (before the board is waited for); `hand` gives `/hand`.
pub fn serve_namespace(
    ns: &str,
    opts: &ViewOptions,
    hand: Option<&Kinematics>,
    stop: &AtomicBool,
    ready: impl FnOnce(u16),
) -> Result<ViewSummary, RecordError> {
    let ports = RecorderPorts::open_as(ns, "vic-view")?;
    let ctx = Context::new();
    let mut channels = Vec::with_capacity(SPECS.len());
    for spec in SPECS {
        channels.push(channel(&ctx, spec.topic, spec.schema, spec.json_schema())?);
    }
    let reference = channel(&ctx, REFERENCE_TOPIC, "vic.Reference", reference_schema())?;
    let hand_channel = match hand {
        Some(_) => Some(channel(&ctx, HAND_TOPIC, "vic.Hand", hand_schema())?),
        None => None,
    };
    let server = WebSocketServer::new()
        .name(format!("vic view {ns}"))
        .bind(opts.host.clone(), opts.port)
        .context(&ctx)
        .start_blocking()
        .map_err(|e| RecordError::View {
            message: format!("cannot listen on {}:{}: {e}", opts.host, opts.port),
        })?;
    let port = server.port();
    ready(port);

    let mut counts = [0u64; 8];
    let mut slices = Slices {
        ring: [None; 8],
        next: 0,
    };
    let mut track = StateTrack::default();
    let (mut states, mut shown) = (0u64, 0u64);
    let started = Instant::now();
    let mut first_state: Option<Instant> = None;
    let every = opts.state_every.max(1);
    let log = |c: &RawChannel, v: &Value| {
        c.log(&serde_json::to_vec(v).expect("a JSON value serialises"));
    };
    loop {
        let stopping = stop.load(Ordering::Relaxed)
            || first_state.is_some_and(|t| {
                opts.duration_ns > 0 && t.elapsed() >= Duration::from_nanos(opts.duration_ns)
            });
        drain(&ports, &mut track, |item| {
            let k = item.channel();
            match &item {
                Item::State(s) => {
                    states += 1;
                    if (states - 1) % every != 0 {
                        return;
                    }
                    shown += 1;
                    let n = (s.joints as usize).min(MAX_JOINTS);
                    let q = &s.q[..n];
                    if let Some([q_d, qd_d, k_p, tau_ff]) = slices.knot_at(s) {
                        let err: Vec<Value> =
                            q.iter().zip(&q_d).map(|(a, b)| finite(a - b)).collect();
                        log(
                            &reference,
                            &json!({"tick": s.tick, "trial": s.trial,
                                "command_seq": s.command_seq, "q_d": q_d, "qd_d": qd_d,
                                "stiffness": k_p, "tau_ff": tau_ff,
                                "q": q.iter().map(|v| finite(*v)).collect::<Vec<_>>(),
                                "q_error": err}),
                        );
                        counts[6] += 1;
                        if let (Some(f), Some(c)) = (hand, &hand_channel) {
                            let ([x, y], [x_d, y_d]) = (f(q), f(&q_d));
                            log(
                                c,
                                &json!({"tick": s.tick, "x": finite(x), "y": finite(y),
                                    "x_d": finite(x_d), "y_d": finite(y_d)}),
                            );
                            counts[7] += 1;
                        }
                    } else if let (Some(f), Some(c)) = (hand, &hand_channel) {
                        let [x, y] = f(q);
                        log(
                            c,
                            &json!({"tick": s.tick, "x": finite(x), "y": finite(y),
                                "x_d": null, "y_d": null}),
                        );
                        counts[7] += 1;
                    }
                }
                Item::Command(c) => slices.push(c),
                _ => {}
            }
            log(&channels[k], &item.json());
            counts[k] += 1;
        });
        if first_state.is_none() && states > 0 {
            first_state = Some(Instant::now());
        }
        if stopping {
            break;
        }
        if first_state.is_none()
            && started.elapsed() >= Duration::from_millis(opts.wait_for_board_ms)
        {
            server.stop().wait_blocking();
            return Err(RecordError::NoBoard {
                namespace: ns.into(),
                waited_ms: opts.wait_for_board_ms,
            });
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    server.stop().wait_blocking();
    let mut topics: Vec<TopicCount> = SPECS
        .iter()
        .zip(counts)
        .map(|(s, n)| TopicCount {
            topic: s.topic.into(),
            messages: n,
        })
        .collect();
    topics.push(TopicCount {
        topic: REFERENCE_TOPIC.into(),
        messages: counts[6],
    });
    if hand_channel.is_some() {
        topics.push(TopicCount {
            topic: HAND_TOPIC.into(),
            messages: counts[7],
        });
    }
    Ok(ViewSummary {
        namespace: ns.into(),
        port,
        states,
        states_shown: shown,
        states_lost: track.lost,
        gaps: track.gaps,
        topics,
        seconds: first_state.map_or(0.0, |t| t.elapsed().as_secs_f64()),
    })
}
