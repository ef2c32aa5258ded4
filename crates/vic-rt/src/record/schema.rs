//! The JSON Schemas of the MCAP channels and the JSON encoding of each message.
//!
//! Every channel carries `json` messages described by a `jsonschema` schema: the encoding that
//! Foxglove and PlotJuggler decode with no plugin. A schema is generated from the same field
//! list that documents the message, so the two cannot disagree; numbers that are not finite
//! (a plant fault) are written as `null`, which the schemas allow.

use crate::transport::{
    CommandSlice, Control, ControlKind, Disturbance, DisturbanceKind, Header, MAX_JOINTS,
    MAX_KNOTS, Percentiles, Rejection, StateMsg, Telemetry,
};
use serde_json::{Map, Value, json};

/// The type of one field.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Kind {
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

/// A channel of an MCAP recording: its topic, schema name and fields.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ChannelSpec {
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
    pub(crate) fn json_schema(&self) -> Vec<u8> {
        let mut v = object_schema(self.fields);
        v["$schema"] = json!("https://json-schema.org/draft/2020-12/schema");
        v["title"] = json!(self.schema);
        v["description"] = json!(self.doc);
        serde_json::to_vec(&v).expect("a JSON value serialises")
    }
}

/// A field table written one line a field, `name: Kind "doc"` (`Kind(FIELDS)` for the nested
/// kinds).
macro_rules! fields {
    ($($name:ident: $kind:ident$(($sub:expr))? $doc:literal),* $(,)?) => {
        &[$(Field { name: stringify!($name), kind: Kind::$kind$(($sub))?, doc: $doc }),*]
    };
}
pub(super) use fields;

/// The fields every message with a [`Header`] starts with.
const HEADER_FIELDS: &[Field] = fields![
    session: Int "session id of the sending process",
    seq: Int "sequence number of the sender",
    time_ns: Int "publish time [ns, CLOCK_MONOTONIC]",
    version: Int "protocol version of the sender",
];

fn header_json(h: &Header, m: &mut Map<String, Value>) {
    m.insert("session".into(), json!(h.session));
    m.insert("seq".into(), json!(h.seq));
    m.insert("time_ns".into(), json!(h.time_ns));
    m.insert("version".into(), json!(h.version));
}

/// The first `joints` entries of a per-joint array, `joints` bounded by what the message can
/// carry (a message is hostile).
fn per_joint(v: &[f64; MAX_JOINTS], joints: u32) -> &[f64] {
    &v[..(joints as usize).clamp(1, MAX_JOINTS)]
}

/// Nanoseconds as seconds.
fn seconds(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

/// A channel of messages that carry a [`Header`]: its [`ChannelSpec`] and its JSON encoder, both
/// from one table of `name: Kind = value, "doc";` lines, so that the schema a reader decodes
/// with and the JSON written cannot disagree on a name or a field.
macro_rules! header_channel {
    (
        $(#[$spec_doc:meta])*
        const $spec:ident = ($topic:literal, $schema:literal, $doc:literal);
        $(#[$encode_doc:meta])*
        fn $encode:ident($s:ident: &$msg:ty) {
            $($name:ident: $kind:ident$(($sub:expr))? = $value:expr, $field_doc:literal;)*
        }
    ) => {
        $(#[$spec_doc])*
        pub const $spec: ChannelSpec = ChannelSpec {
            topic: $topic,
            schema: $schema,
            doc: $doc,
            fields: &[
                HEADER_FIELDS[0], HEADER_FIELDS[1], HEADER_FIELDS[2], HEADER_FIELDS[3],
                $(Field { name: stringify!($name), kind: Kind::$kind$(($sub))?, doc: $field_doc }),*
            ],
        };
        $(#[$encode_doc])*
        pub fn $encode($s: &$msg) -> Value {
            let mut m = Map::new();
            header_json(&$s.header, &mut m);
            $(m.insert(stringify!($name).into(), json!($value));)*
            Value::Object(m)
        }
    };
}

header_channel! {
    /// The board's state, one message per tick (`vic record`).
    const STATE = ("/state", "vic.State", "The board's plant state, published every tick");
    /// Encodes a state message.
    fn state_json(s: &StateMsg) {
        tick: Int = s.tick, "board tick";
        trial: Int = s.trial, "trial (from the last reset)";
        mode: Int = s.mode, "0 idle, 1 running, 2 safe-hold, 3 fault";
        trial_time: Num = seconds(s.trial_time_ns), "plant time since the trial start [s]";
        q: Nums = per_joint(&s.q, s.joints), "joint angles [rad]";
        qd: Nums = per_joint(&s.qd, s.joints), "joint velocities [rad/s]";
        tau: Nums = per_joint(&s.tau, s.joints), "joint torque applied [N m]";
        tau_ext: Nums = per_joint(&s.tau_ext, s.joints),
            "external torque of the disturbances in force [N m]";
        stiffness: Nums = per_joint(&s.stiffness, s.joints), "stiffness in use [N m/rad]";
        command_seq: Int = s.command_seq, "sequence number of the command slice in use";
        disturbance_seq: Int = s.disturbance_seq, "last disturbance applied";
        disturbance_tick: Int = s.disturbance_tick, "tick it was applied at";
        watchdog_deadline_ns: Int = s.watchdog_deadline_ns, "trial time the watchdog expires [ns]";
        reset_seq: Int = s.reset_seq, "sequence number of the reset of this trial";
    }
}

const KNOT_FIELDS: &[Field] = fields![
    tau_ff: Nums "feedforward torque [N m]",
    stiffness: Nums "stiffness K_P [N m/rad]",
    q_d: Nums "equilibrium [rad]",
    qd_d: Nums "equilibrium velocity [rad/s]",
];

/// The valid knots of a command slice (a hostile count bounded by the slice's capacity).
fn knots_json(c: &CommandSlice) -> Vec<Value> {
    let n = c.joints;
    c.knots[..(c.count as usize).min(MAX_KNOTS)]
        .iter()
        .map(|k| {
            json!({"tau_ff": per_joint(&k.tau_ff, n), "stiffness": per_joint(&k.stiffness, n),
                   "q_d": per_joint(&k.q_d, n), "qd_d": per_joint(&k.qd_d, n)})
        })
        .collect()
}

header_channel! {
    /// The central controller's command slices.
    const COMMAND = (
        "/command",
        "vic.CommandSlice",
        "A slice of impedance-law inputs (Eq. 4) covering start + count * knot_dt of a trial"
    );
    /// Encodes a command slice (its valid knots only).
    fn command_json(c: &CommandSlice) {
        joints: Int = c.joints, "joints";
        trial: Int = c.trial, "trial the slice is for";
        interpolation: Int = c.interpolation, "0 zero-order hold, 1 linear";
        count: Int = c.count, "valid knots";
        start: Num = seconds(c.start_ns), "trial time of the first knot [s]";
        knot_dt: Num = seconds(c.knot_dt_ns), "time between knots [s]";
        knots: Objs(KNOT_FIELDS) = knots_json(c), "the knots";
    }
}

header_channel! {
    /// Control requests (reset, stop).
    const CONTROL = ("/control", "vic.Control", "A control request to the board");
    /// Encodes a control request.
    fn control_json(c: &Control) {
        kind: Int = c.kind, "0 reset, 1 stop";
        kind_name: Str = ControlKind::from_wire(c.kind).map_or("unknown", ControlKind::name), "reset, stop or unknown";
        trial: Int = c.trial, "trial";
        seed: Int = c.seed, "noise seed";
        start_ns: Int = c.start_ns, "trial start [ns, CLOCK_MONOTONIC]";
        q0: Nums = c.q0, "initial joint angles [rad]";
        qd0: Nums = c.qd0, "initial joint velocities [rad/s]";
    }
}

header_channel! {
    /// Disturbances sent to the board.
    const DISTURBANCE = ("/disturbance", "vic.Disturbance", "A disturbance for the board to apply");
    /// Encodes a disturbance.
    fn disturbance_json(d: &Disturbance) {
        kind: Int = d.kind, "0 pulse, 1 load, 2 field, 3 noise";
        kind_name: Str = DisturbanceKind::from_wire(d.kind).map_or("unknown", DisturbanceKind::name), "pulse, load, field, noise or unknown";
        torque: Nums = d.torque, "joint torque [N m] (pulse, load)";
        duration: Num = seconds(d.duration_ns), "pulse duration [s]";
        value: Num = d.value, "field beta [N/m] or noise factor";
    }
}

const PERCENTILE_FIELDS: &[Field] = fields![
    p50: Num "median [µs]",
    p99: Num "99th percentile [µs]",
    p999: Num "99.9th percentile [µs]",
    max: Num "maximum [µs]",
    count: Int "values recorded",
];

fn percentiles_json(p: &Percentiles) -> Value {
    json!({"p50": p.p50, "p99": p.p99, "p999": p.p999, "max": p.max, "count": p.count})
}

/// Rejected messages by the name of their reason.
fn rejections_json(t: &Telemetry) -> Map<String, Value> {
    Rejection::ALL
        .iter()
        .map(|r| {
            (
                r.name().to_string(),
                json!(t.rejected_by_reason[*r as usize]),
            )
        })
        .collect()
}

header_channel! {
    /// The board's telemetry (10 Hz).
    const TELEMETRY = ("/telemetry", "vic.Telemetry", "The board's telemetry");
    /// Encodes telemetry.
    fn telemetry_json(t: &Telemetry) {
        mode: Int = t.mode, "0 idle, 1 running, 2 safe-hold, 3 fault";
        trial: Int = t.trial, "trial";
        tick: Int = t.tick, "board tick";
        tick_rate_hz: Num = t.tick_rate_hz, "tick rate over the last interval [Hz]";
        jitter_us: Obj(PERCENTILE_FIELDS) = percentiles_json(&t.jitter_us), "wake-up lateness [µs]";
        work_us: Obj(PERCENTILE_FIELDS) = percentiles_json(&t.work_us), "tick work time [µs]";
        command_age_us: Obj(PERCENTILE_FIELDS) = percentiles_json(&t.command_age_us),
            "age of the command used [µs]";
        late_ticks: Int = t.late_ticks, "ticks that woke more than a period late";
        missed_periods: Int = t.missed_periods, "periods skipped";
        rejected_messages: Int = t.rejected_messages, "messages rejected";
        rejected_by_reason: Counts = rejections_json(t), "messages rejected by reason";
        dropped_messages: Int = t.dropped_messages,
            "messages lost before the board read them (sequence gaps per sender)";
        safe_hold_ticks: Int = t.safe_hold_ticks, "ticks in the safe hold";
        watchdog_trips: Int = t.watchdog_trips, "times the watchdog ramped to the hold";
        tracking_error: Num = t.tracking_error, "distance to the commanded equilibrium [rad]";
        stiffness: Nums = per_joint(&t.stiffness, t.joints), "stiffness [N m/rad]";
        tau_ext: Nums = per_joint(&t.tau_ext, t.joints), "external torque [N m]";
        field_beta: Num = t.field_beta, "divergent field beta [N/m]";
        noise_factor: Num = t.noise_factor, "noise factor";
        fault_reason: Int = t.fault_reason, "why the board is in fault (0: none)";
        disturbance_seq: Int = t.disturbance_seq, "last disturbance applied";
        disturbance_tick: Int = t.disturbance_tick, "tick it was applied at";
    }
}

/// A gap in a recording: ticks (or states) that did not reach the file.
pub(crate) const GAP: ChannelSpec = ChannelSpec {
    topic: "/gap",
    schema: "vic.Gap",
    doc: "Ticks missing from the recording just before this time",
    fields: fields![
        first_tick: Int "first tick missing",
        ticks: Int "ticks missing",
        reason: Str "why",
    ],
};

/// Encodes a gap.
pub(crate) fn gap_json(first_tick: u64, ticks: u64, reason: &str) -> Value {
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
