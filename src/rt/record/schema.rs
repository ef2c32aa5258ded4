//! The JSON Schemas of the MCAP channels and the JSON encoding of each message.
//!
//! Every channel carries `json` messages described by a `jsonschema` schema: the encoding that
//! Foxglove and PlotJuggler decode with no plugin. A schema is generated from the same field
//! list that documents the message, so the two cannot disagree; numbers that are not finite
//! (a plant fault) are written as `null`, which the schemas allow.

use crate::rt::transport::{
    CommandSlice, Control, ControlKind, Disturbance, DisturbanceKind, Header, MAX_JOINTS,
    MAX_KNOTS, Percentiles, Rejection, StateMsg, Telemetry,
};
use serde_json::{Map, Value, json};

/// The type of one field.
#[derive(Debug, Clone, Copy)]
pub enum Kind {
    Int,
    Num,
    /// An array of numbers (one per joint).
    Nums,
    Str,
    /// An object with these fields.
    Obj(&'static [Field]),
    /// An array of objects with these fields.
    Objs(&'static [Field]),
    /// An object whose values are counts (keys not fixed).
    Counts,
}

/// One field of a message: its name, type and meaning (with its unit).
#[derive(Debug, Clone, Copy)]
pub struct Field {
    pub name: &'static str,
    pub kind: Kind,
    pub doc: &'static str,
}

const fn f(name: &'static str, kind: Kind, doc: &'static str) -> Field {
    Field { name, kind, doc }
}

/// A channel of an MCAP recording: its topic, schema name and fields.
#[derive(Debug, Clone, Copy)]
pub struct ChannelSpec {
    pub topic: &'static str,
    pub schema: &'static str,
    pub doc: &'static str,
    pub fields: &'static [Field],
}

fn field_schema(kind: Kind, doc: &str) -> Value {
    let number = json!({"type": ["number", "null"]});
    let mut v = match kind {
        Kind::Int => json!({"type": "integer"}),
        Kind::Num => number,
        Kind::Nums => json!({"type": "array", "items": number}),
        Kind::Str => json!({"type": "string"}),
        Kind::Obj(fields) => object_schema(fields),
        Kind::Objs(fields) => json!({"type": "array", "items": object_schema(fields)}),
        Kind::Counts => json!({"type": "object", "additionalProperties": {"type": "integer"}}),
    };
    v["description"] = Value::String(doc.to_string());
    v
}

fn object_schema(fields: &[Field]) -> Value {
    let mut props = Map::new();
    for field in fields {
        props.insert(field.name.into(), field_schema(field.kind, field.doc));
    }
    let required: Vec<&str> = fields.iter().map(|f| f.name).collect();
    json!({"type": "object", "properties": props, "required": required})
}

impl ChannelSpec {
    /// The JSON Schema (draft 2020-12) of the channel's messages.
    pub fn json_schema(&self) -> Vec<u8> {
        let mut v = object_schema(self.fields);
        v["$schema"] = json!("https://json-schema.org/draft/2020-12/schema");
        v["title"] = json!(self.schema);
        v["description"] = json!(self.doc);
        serde_json::to_vec(&v).expect("a JSON value serialises")
    }
}

const HEADER_FIELDS: [Field; 4] = [
    f("session", Kind::Int, "session id of the sending process"),
    f("seq", Kind::Int, "sequence number of the sender"),
    f("time_ns", Kind::Int, "publish time [ns, CLOCK_MONOTONIC]"),
    f("version", Kind::Int, "protocol version of the sender"),
];

fn header_json(h: &Header, m: &mut Map<String, Value>) {
    m.insert("session".into(), json!(h.session));
    m.insert("seq".into(), json!(h.seq));
    m.insert("time_ns".into(), json!(h.time_ns));
    m.insert("version".into(), json!(h.version));
}

/// Joints a message claims, bounded by what it can carry (a message is hostile).
fn joints(n: u32) -> usize {
    (n as usize).clamp(1, MAX_JOINTS)
}

macro_rules! with_header {
    ($($field:expr),* $(,)?) => {
        &[HEADER_FIELDS[0], HEADER_FIELDS[1], HEADER_FIELDS[2], HEADER_FIELDS[3], $($field),*]
    };
}

/// The board's state, one message per tick (`vic record`).
pub const STATE: ChannelSpec = ChannelSpec {
    topic: "/state",
    schema: "vic.State",
    doc: "The board's plant state, published every tick",
    fields: with_header![
        f("tick", Kind::Int, "board tick"),
        f("trial", Kind::Int, "trial (from the last reset)"),
        f("mode", Kind::Int, "0 idle, 1 running, 2 safe-hold, 3 fault"),
        f(
            "trial_time",
            Kind::Num,
            "plant time since the trial start [s]"
        ),
        f("q", Kind::Nums, "joint angles [rad]"),
        f("qd", Kind::Nums, "joint velocities [rad/s]"),
        f("tau", Kind::Nums, "joint torque applied [N m]"),
        f(
            "tau_ext",
            Kind::Nums,
            "external torque of the disturbances in force [N m]"
        ),
        f("stiffness", Kind::Nums, "stiffness in use [N m/rad]"),
        f(
            "command_seq",
            Kind::Int,
            "sequence number of the command slice in use"
        ),
        f("disturbance_seq", Kind::Int, "last disturbance applied"),
        f("disturbance_tick", Kind::Int, "tick it was applied at"),
        f(
            "watchdog_deadline_ns",
            Kind::Int,
            "trial time the watchdog expires [ns]"
        ),
        f(
            "reset_seq",
            Kind::Int,
            "sequence number of the reset of this trial"
        ),
    ],
};

/// Encodes a state message.
pub fn state_json(s: &StateMsg) -> Value {
    let mut m = Map::new();
    header_json(&s.header, &mut m);
    let n = joints(s.joints);
    m.insert("tick".into(), json!(s.tick));
    m.insert("trial".into(), json!(s.trial));
    m.insert("mode".into(), json!(s.mode));
    m.insert("trial_time".into(), json!(s.trial_time_ns as f64 * 1e-9));
    for (k, v) in [
        ("q", &s.q),
        ("qd", &s.qd),
        ("tau", &s.tau),
        ("tau_ext", &s.tau_ext),
        ("stiffness", &s.stiffness),
    ] {
        m.insert(k.into(), json!(&v[..n]));
    }
    m.insert("command_seq".into(), json!(s.command_seq));
    m.insert("disturbance_seq".into(), json!(s.disturbance_seq));
    m.insert("disturbance_tick".into(), json!(s.disturbance_tick));
    m.insert("watchdog_deadline_ns".into(), json!(s.watchdog_deadline_ns));
    m.insert("reset_seq".into(), json!(s.reset_seq));
    Value::Object(m)
}

const KNOT_FIELDS: [Field; 4] = [
    f("tau_ff", Kind::Nums, "feedforward torque [N m]"),
    f("stiffness", Kind::Nums, "stiffness K_P [N m/rad]"),
    f("q_d", Kind::Nums, "equilibrium [rad]"),
    f("qd_d", Kind::Nums, "equilibrium velocity [rad/s]"),
];

/// The central controller's command slices.
pub const COMMAND: ChannelSpec = ChannelSpec {
    topic: "/command",
    schema: "vic.CommandSlice",
    doc: "A slice of impedance-law inputs (Eq. 4) covering start + count * knot_dt of a trial",
    fields: with_header![
        f("joints", Kind::Int, "joints"),
        f("trial", Kind::Int, "trial the slice is for"),
        f("interpolation", Kind::Int, "0 zero-order hold, 1 linear"),
        f("count", Kind::Int, "valid knots"),
        f("start", Kind::Num, "trial time of the first knot [s]"),
        f("knot_dt", Kind::Num, "time between knots [s]"),
        f("knots", Kind::Objs(&KNOT_FIELDS), "the knots"),
    ],
};

/// Encodes a command slice (its valid knots only).
pub fn command_json(c: &CommandSlice) -> Value {
    let mut m = Map::new();
    header_json(&c.header, &mut m);
    let n = joints(c.joints);
    m.insert("joints".into(), json!(c.joints));
    m.insert("trial".into(), json!(c.trial));
    m.insert("interpolation".into(), json!(c.interpolation));
    m.insert("count".into(), json!(c.count));
    m.insert("start".into(), json!(c.start_ns as f64 * 1e-9));
    m.insert("knot_dt".into(), json!(c.knot_dt_ns as f64 * 1e-9));
    let knots: Vec<Value> = c.knots[..(c.count as usize).min(MAX_KNOTS)]
        .iter()
        .map(|k| {
            json!({"tau_ff": &k.tau_ff[..n], "stiffness": &k.stiffness[..n],
                   "q_d": &k.q_d[..n], "qd_d": &k.qd_d[..n]})
        })
        .collect();
    m.insert("knots".into(), Value::Array(knots));
    Value::Object(m)
}

/// Control requests (reset, stop).
pub const CONTROL: ChannelSpec = ChannelSpec {
    topic: "/control",
    schema: "vic.Control",
    doc: "A control request to the board",
    fields: with_header![
        f("kind", Kind::Int, "0 reset, 1 stop"),
        f("kind_name", Kind::Str, "reset, stop or unknown"),
        f("trial", Kind::Int, "trial"),
        f("seed", Kind::Int, "noise seed"),
        f("start_ns", Kind::Int, "trial start [ns, CLOCK_MONOTONIC]"),
        f("q0", Kind::Nums, "initial joint angles [rad]"),
        f("qd0", Kind::Nums, "initial joint velocities [rad/s]"),
    ],
};

/// Encodes a control request.
pub fn control_json(c: &Control) -> Value {
    let mut m = Map::new();
    header_json(&c.header, &mut m);
    let name = match c.kind {
        k if k == ControlKind::Reset as u32 => "reset",
        k if k == ControlKind::Stop as u32 => "stop",
        _ => "unknown",
    };
    m.insert("kind".into(), json!(c.kind));
    m.insert("kind_name".into(), json!(name));
    m.insert("trial".into(), json!(c.trial));
    m.insert("seed".into(), json!(c.seed));
    m.insert("start_ns".into(), json!(c.start_ns));
    m.insert("q0".into(), json!(c.q0));
    m.insert("qd0".into(), json!(c.qd0));
    Value::Object(m)
}

/// Disturbances sent to the board.
pub const DISTURBANCE: ChannelSpec = ChannelSpec {
    topic: "/disturbance",
    schema: "vic.Disturbance",
    doc: "A disturbance for the board to apply",
    fields: with_header![
        f("kind", Kind::Int, "0 pulse, 1 load, 2 field, 3 noise"),
        f(
            "kind_name",
            Kind::Str,
            "pulse, load, field, noise or unknown"
        ),
        f("torque", Kind::Nums, "joint torque [N m] (pulse, load)"),
        f("duration", Kind::Num, "pulse duration [s]"),
        f("value", Kind::Num, "field beta [N/m] or noise factor"),
    ],
};

/// Encodes a disturbance.
pub fn disturbance_json(d: &Disturbance) -> Value {
    let mut m = Map::new();
    header_json(&d.header, &mut m);
    let name = match DisturbanceKind::from_u32(d.kind) {
        Some(DisturbanceKind::Pulse) => "pulse",
        Some(DisturbanceKind::Load) => "load",
        Some(DisturbanceKind::Field) => "field",
        Some(DisturbanceKind::Noise) => "noise",
        None => "unknown",
    };
    m.insert("kind".into(), json!(d.kind));
    m.insert("kind_name".into(), json!(name));
    m.insert("torque".into(), json!(d.torque));
    m.insert("duration".into(), json!(d.duration_ns as f64 * 1e-9));
    m.insert("value".into(), json!(d.value));
    Value::Object(m)
}

const PERCENTILE_FIELDS: [Field; 5] = [
    f("p50", Kind::Num, "median [µs]"),
    f("p99", Kind::Num, "99th percentile [µs]"),
    f("p999", Kind::Num, "99.9th percentile [µs]"),
    f("max", Kind::Num, "maximum [µs]"),
    f("count", Kind::Int, "values recorded"),
];

fn percentiles_json(p: &Percentiles) -> Value {
    json!({"p50": p.p50, "p99": p.p99, "p999": p.p999, "max": p.max, "count": p.count})
}

/// The board's telemetry (10 Hz).
pub const TELEMETRY: ChannelSpec = ChannelSpec {
    topic: "/telemetry",
    schema: "vic.Telemetry",
    doc: "The board's telemetry",
    fields: with_header![
        f("mode", Kind::Int, "0 idle, 1 running, 2 safe-hold, 3 fault"),
        f("trial", Kind::Int, "trial"),
        f("tick", Kind::Int, "board tick"),
        f(
            "tick_rate_hz",
            Kind::Num,
            "tick rate over the last interval [Hz]"
        ),
        f(
            "jitter_us",
            Kind::Obj(&PERCENTILE_FIELDS),
            "wake-up lateness [µs]"
        ),
        f(
            "work_us",
            Kind::Obj(&PERCENTILE_FIELDS),
            "tick work time [µs]"
        ),
        f(
            "command_age_us",
            Kind::Obj(&PERCENTILE_FIELDS),
            "age of the command used [µs]"
        ),
        f(
            "late_ticks",
            Kind::Int,
            "ticks that woke more than a period late"
        ),
        f("missed_periods", Kind::Int, "periods skipped"),
        f("rejected_messages", Kind::Int, "messages rejected"),
        f(
            "rejected_by_reason",
            Kind::Counts,
            "messages rejected by reason"
        ),
        f(
            "dropped_messages",
            Kind::Int,
            "messages lost before the board read them (sequence gaps per sender)"
        ),
        f("safe_hold_ticks", Kind::Int, "ticks in the safe hold"),
        f(
            "watchdog_trips",
            Kind::Int,
            "times the watchdog ramped to the hold"
        ),
        f(
            "tracking_error",
            Kind::Num,
            "distance to the commanded equilibrium [rad]"
        ),
        f("stiffness", Kind::Nums, "stiffness [N m/rad]"),
        f("tau_ext", Kind::Nums, "external torque [N m]"),
        f("field_beta", Kind::Num, "divergent field beta [N/m]"),
        f("noise_factor", Kind::Num, "noise factor"),
        f(
            "fault_reason",
            Kind::Int,
            "why the board is in fault (0: none)"
        ),
        f("disturbance_seq", Kind::Int, "last disturbance applied"),
        f("disturbance_tick", Kind::Int, "tick it was applied at"),
    ],
};

/// Encodes telemetry.
pub fn telemetry_json(t: &Telemetry) -> Value {
    let mut m = Map::new();
    header_json(&t.header, &mut m);
    let n = joints(t.joints);
    m.insert("mode".into(), json!(t.mode));
    m.insert("trial".into(), json!(t.trial));
    m.insert("tick".into(), json!(t.tick));
    m.insert("tick_rate_hz".into(), json!(t.tick_rate_hz));
    m.insert("jitter_us".into(), percentiles_json(&t.jitter_us));
    m.insert("work_us".into(), percentiles_json(&t.work_us));
    m.insert("command_age_us".into(), percentiles_json(&t.command_age_us));
    m.insert("late_ticks".into(), json!(t.late_ticks));
    m.insert("missed_periods".into(), json!(t.missed_periods));
    m.insert("rejected_messages".into(), json!(t.rejected_messages));
    let reasons: Map<String, Value> = Rejection::ALL
        .iter()
        .map(|r| {
            (
                r.name().to_string(),
                json!(t.rejected_by_reason[*r as usize]),
            )
        })
        .collect();
    m.insert("rejected_by_reason".into(), Value::Object(reasons));
    m.insert("dropped_messages".into(), json!(t.dropped_messages));
    m.insert("safe_hold_ticks".into(), json!(t.safe_hold_ticks));
    m.insert("watchdog_trips".into(), json!(t.watchdog_trips));
    m.insert("tracking_error".into(), json!(t.tracking_error));
    m.insert("stiffness".into(), json!(&t.stiffness[..n]));
    m.insert("tau_ext".into(), json!(&t.tau_ext[..n]));
    m.insert("field_beta".into(), json!(t.field_beta));
    m.insert("noise_factor".into(), json!(t.noise_factor));
    m.insert("fault_reason".into(), json!(t.fault_reason));
    m.insert("disturbance_seq".into(), json!(t.disturbance_seq));
    m.insert("disturbance_tick".into(), json!(t.disturbance_tick));
    Value::Object(m)
}

/// A gap in a recording: ticks (or states) that did not reach the file.
pub const GAP: ChannelSpec = ChannelSpec {
    topic: "/gap",
    schema: "vic.Gap",
    doc: "Ticks missing from the recording just before this time",
    fields: &[
        f("first_tick", Kind::Int, "first tick missing"),
        f("ticks", Kind::Int, "ticks missing"),
        f("reason", Kind::Str, "why"),
    ],
};

/// Encodes a gap.
pub fn gap_json(first_tick: u64, ticks: u64, reason: &str) -> Value {
    json!({"first_tick": first_tick, "ticks": ticks, "reason": reason})
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every encoder writes exactly the fields its schema lists, with the listed types: a field
    /// added to one and not the other fails here.
    #[test]
    fn encoders_write_exactly_the_fields_of_their_schema() {
        fn check(spec: &ChannelSpec, v: &Value) {
            let obj = v.as_object().unwrap();
            let names: Vec<&str> = spec.fields.iter().map(|f| f.name).collect();
            let mut keys: Vec<&str> = obj.keys().map(String::as_str).collect();
            let mut want = names.clone();
            keys.sort();
            want.sort();
            assert_eq!(keys, want, "{}", spec.topic);
            for field in spec.fields {
                let x = &obj[field.name];
                let ok = match field.kind {
                    Kind::Int => x.is_u64(),
                    Kind::Num => x.is_number() || x.is_null(),
                    Kind::Nums => x
                        .as_array()
                        .is_some_and(|a| a.iter().all(|e| e.is_number() || e.is_null())),
                    Kind::Str => x.is_string(),
                    Kind::Obj(_) | Kind::Counts => x.is_object(),
                    Kind::Objs(_) => x.is_array(),
                };
                assert!(ok, "{}.{} = {x}", spec.topic, field.name);
            }
            let schema: Value = serde_json::from_slice(&spec.json_schema()).unwrap();
            assert_eq!(schema["properties"].as_object().unwrap().len(), names.len());
        }
        let mut c = CommandSlice {
            joints: 2,
            count: 3,
            ..Default::default()
        };
        c.knots[2].stiffness = [1.0, 2.0];
        check(
            &STATE,
            &state_json(&StateMsg {
                joints: 2,
                q: [f64::NAN, 1.0],
                ..Default::default()
            }),
        );
        check(&COMMAND, &command_json(&c));
        check(&CONTROL, &control_json(&Control::default()));
        check(&DISTURBANCE, &disturbance_json(&Disturbance::default()));
        check(&TELEMETRY, &telemetry_json(&Telemetry::default()));
        check(&GAP, &gap_json(3, 4, "x"));
        assert_eq!(command_json(&c)["knots"].as_array().unwrap().len(), 3);
        assert_eq!(command_json(&c)["knots"][2]["stiffness"], json!([1.0, 2.0]));
        // A hostile count is bounded by the slice's capacity.
        c.count = u32::MAX;
        assert_eq!(
            command_json(&c)["knots"].as_array().unwrap().len(),
            MAX_KNOTS
        );
    }
}
