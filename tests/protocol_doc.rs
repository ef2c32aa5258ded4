//! `docs/PROTOCOL.md` read back and compared with the Rust types, so that the document a client
//! in another language is written from cannot drift: every payload's type name, size and field
//! table (offset, size, type), every enumeration's values, the constants and the services.

use iceoryx2::prelude::ZeroCopySend;
use std::collections::BTreeMap;
use std::mem::{offset_of, size_of, size_of_val};
use vic_rt::board::{FaultReason, gaps};
use vic_rt::transport::ports::{self, Topic};
use vic_rt::transport::*;

const DOC: &str = include_str!("../docs/PROTOCOL.md");

/// Rows of the table that follows the heading `heading` (cells trimmed, header and rule
/// skipped).
fn table(heading: &str) -> Vec<Vec<String>> {
    let lines: Vec<&str> = DOC.lines().collect();
    let start = lines
        .iter()
        .position(|l| l.starts_with('#') && l.trim_start_matches('#').trim() == heading)
        .unwrap_or_else(|| panic!("docs/PROTOCOL.md has no heading \"{heading}\""));
    lines[start + 1..]
        .iter()
        .skip_while(|l| !l.starts_with('|'))
        .take_while(|l| l.starts_with('|'))
        .skip(2)
        .map(|l| {
            l.trim_matches('|')
                .split('|')
                .map(|c| c.trim().trim_matches('`').to_string())
                .collect()
        })
        .collect()
}

/// The line `key: value` after a heading (first occurrence).
fn property(heading: &str, key: &str) -> String {
    let after = DOC
        .split_once(&format!("### {heading}\n"))
        .unwrap_or_else(|| panic!("no heading {heading}"))
        .1;
    after
        .lines()
        .find_map(|l| l.strip_prefix(&format!("{key}: ")))
        .unwrap_or_else(|| panic!("no \"{key}:\" under {heading}"))
        .trim_matches('`')
        .to_string()
}

/// A Rust type as the document writes it: `u64`, `f64[2]`, `Header`, `Knot[32]`.
fn doc_type(rust: &str) -> String {
    let short = |t: &str| t.rsplit("::").next().unwrap().to_string();
    match rust.strip_prefix('[').and_then(|r| r.strip_suffix(']')) {
        Some(inner) => {
            let (t, n) = inner.split_once("; ").unwrap();
            format!("{}[{n}]", short(t))
        }
        None => short(rust),
    }
}

/// Offset, size and type of each named field of a value.
macro_rules! fields {
    ($t:ty, $v:expr; $($f:ident),+ $(,)?) => {{
        let v: $t = $v;
        vec![$((
            stringify!($f).to_string(),
            offset_of!($t, $f),
            size_of_val(&v.$f),
            doc_type(std::any::type_name_of_val(&v.$f)),
        )),+]
    }};
}

type Fields = Vec<(String, usize, usize, String)>;

/// Checks one payload type: the table, the size, the type name; the fields must tile the
/// struct (no hidden padding, none left out of the list).
fn check_struct<T: ZeroCopySend>(name: &str, fields: Fields) {
    let mut end = 0;
    for (f, off, size, _) in &fields {
        assert_eq!(*off, end, "{name}.{f}: hidden padding or a field left out");
        end = off + size;
    }
    assert_eq!(
        end,
        size_of::<T>(),
        "{name}: trailing padding or a field left out"
    );
    let rows = table(name);
    let doc: Vec<(String, usize, usize, String)> = rows
        .iter()
        .map(|r| {
            let n = |i: usize| {
                r[i].parse::<usize>()
                    .unwrap_or_else(|_| panic!("{name}: {r:?}"))
            };
            (r[2].clone(), n(0), n(1), r[3].clone())
        })
        .collect();
    assert_eq!(doc, fields, "the table of {name} in docs/PROTOCOL.md");
    assert_eq!(
        property(name, "Size"),
        format!("{} bytes", size_of::<T>()),
        "{name}"
    );
    // SAFETY: reading the type name has no precondition (the layouts are checked above).
    let type_name = unsafe { <T as ZeroCopySend>::type_name() };
    assert_eq!(property(name, "Type name"), type_name, "{name}");
}

#[test]
fn payload_layouts_match_the_document() {
    check_struct::<Header>(
        "Header",
        fields!(Header, Header::default(); version, session, seq, time_ns),
    );
    check_struct::<StateMsg>(
        "StateMsg",
        fields!(StateMsg, StateMsg::default(); header, joints, trial, tick, mode, _pad,
            trial_time_ns, q, qd, tau, tau_ext, stiffness, command_seq, disturbance_seq,
            disturbance_tick, watchdog_deadline_ns, reset_seq),
    );
    check_struct::<Knot>(
        "Knot",
        fields!(Knot, Knot::default(); tau_ff, stiffness, q_d, qd_d),
    );
    check_struct::<CommandSlice>(
        "CommandSlice",
        fields!(CommandSlice, CommandSlice::default(); header, joints, trial, interpolation,
            count, start_ns, knot_dt_ns, knots),
    );
    check_struct::<Disturbance>(
        "Disturbance",
        fields!(Disturbance, Disturbance::default(); header, kind, _pad, torque, duration_ns,
            value),
    );
    check_struct::<Control>(
        "Control",
        fields!(Control, Control::default(); header, kind, trial, seed, start_ns, q0, qd0),
    );
    check_struct::<Percentiles>(
        "Percentiles",
        fields!(Percentiles, Percentiles::default(); p50, p99, p999, max, count),
    );
    check_struct::<Telemetry>(
        "Telemetry",
        fields!(Telemetry, Telemetry::default(); header, mode, trial, tick, tick_rate_hz,
            jitter_us, work_us, command_age_us, late_ticks, missed_periods, rejected_messages,
            safe_hold_ticks, tracking_error, stiffness, tau_ext, field_beta, noise_factor,
            joints, fault_reason, rejected_by_reason, watchdog_trips, disturbance_seq,
            disturbance_tick, dropped_messages),
    );
}

/// `value → name` of an enumeration's table.
fn values(heading: &str) -> BTreeMap<u64, String> {
    table(heading)
        .into_iter()
        .map(|r| (r[0].parse().unwrap(), r[1].clone()))
        .collect()
}

fn map(v: &[(u64, &str)]) -> BTreeMap<u64, String> {
    v.iter().map(|(k, n)| (*k, n.to_string())).collect()
}

#[test]
fn enumerations_match_the_document() {
    let modes = [Mode::Idle, Mode::Running, Mode::SafeHold, Mode::Fault];
    let m: Vec<_> = modes.iter().map(|m| (*m as u64, m.name())).collect();
    assert_eq!(values("Mode"), map(&m));
    for (v, _) in &m {
        assert_eq!(Mode::from_u32(*v as u32) as u64, *v);
    }
    assert_eq!(
        values("Interpolation"),
        map(&[
            (Interpolation::Hold as u64, "hold"),
            (Interpolation::Linear as u64, "linear")
        ])
    );
    let kinds: Vec<_> = (0..8u32)
        .filter_map(|v| DisturbanceKind::from_wire(v).map(|k| (v as u64, format!("{k:?}"))))
        .collect();
    let doc: Vec<_> = values("DisturbanceKind").into_iter().collect();
    assert_eq!(
        doc,
        kinds
            .into_iter()
            .map(|(v, k)| (v, k.to_lowercase()))
            .collect::<Vec<_>>()
    );
    assert_eq!(
        values("ControlKind"),
        map(&[
            (ControlKind::Reset as u64, "reset"),
            (ControlKind::Stop as u64, "stop")
        ])
    );
    let reasons: Vec<_> = Rejection::ALL
        .iter()
        .map(|r| (*r as u64, r.name()))
        .collect();
    assert_eq!(values("Rejection"), map(&reasons));
    let faults = [
        FaultReason::None,
        FaultReason::JointLimit,
        FaultReason::VelocityLimit,
        FaultReason::NotFinite,
    ];
    let f: Vec<_> = faults.iter().map(|f| (*f as u64, f.name())).collect();
    assert_eq!(values("FaultReason"), map(&f));
    assert_eq!(
        values("BoardEvent"),
        map(&[
            (BoardEvent::Telemetry as u64, "telemetry"),
            (BoardEvent::Applied as u64, "applied")
        ])
    );
}

#[test]
fn constants_match_the_document() {
    let doc: BTreeMap<String, u64> = table("Constants")
        .into_iter()
        .map(|r| (r[0].clone(), r[1].replace('_', "").parse().unwrap()))
        .collect();
    let rust: BTreeMap<String, u64> = [
        ("PROTOCOL_VERSION", PROTOCOL_VERSION as u64),
        ("MAX_JOINTS", MAX_JOINTS as u64),
        ("MAX_KNOTS", MAX_KNOTS as u64),
        ("MIN_KNOT_DT_NS", MIN_KNOT_DT_NS),
        ("MAX_KNOT_DT_NS", MAX_KNOT_DT_NS),
        ("MAX_SLICE_NS", MAX_SLICE_NS),
        ("MAX_REACH_NS", MAX_REACH_NS),
        ("MAX_MESSAGE_AGE_NS", MAX_MESSAGE_AGE_NS),
        ("REJECTION_COUNT", Rejection::COUNT as u64),
        ("MAX_PUBLISHERS", ports::MAX_PUBLISHERS as u64),
        ("MAX_SUBSCRIBERS", ports::MAX_SUBSCRIBERS as u64),
        ("MAX_NODES", ports::MAX_NODES as u64),
        ("MAX_NOTIFIERS", ports::MAX_NOTIFIERS as u64),
        ("MAX_LISTENERS", ports::MAX_LISTENERS as u64),
        ("STATE_BUFFER", STATE_BUFFER as u64),
        ("GAP_SESSIONS", gaps::GAP_SESSIONS as u64),
        ("MAX_COUNTED_GAP", gaps::MAX_COUNTED_GAP),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    assert_eq!(doc, rust);
}

fn service<T: Topic>() -> Vec<String> {
    // SAFETY: reading the type name has no precondition.
    let name = unsafe { <T as ZeroCopySend>::type_name() };
    vec![
        T::SERVICE.to_string(),
        name.to_string(),
        T::HISTORY.to_string(),
        T::BUFFER.to_string(),
    ]
}

#[test]
fn services_and_prefix_match_the_document() {
    let rows: Vec<Vec<String>> = table("Services")
        .into_iter()
        .map(|r| r[..4].to_vec())
        .collect();
    let mut rust = vec![
        service::<StateMsg>(),
        service::<Telemetry>(),
        service::<CommandSlice>(),
        service::<Control>(),
        service::<Disturbance>(),
    ];
    rust.push(vec![
        ports::EVENT_SERVICE.to_string(),
        "event".into(),
        "-".into(),
        "-".into(),
    ]);
    assert_eq!(rows, rust);
    let example = property("Prefix", "Example");
    let (ns, prefix) = example.split_once(" → ").unwrap();
    assert_eq!(vic_rt::transport::prefix(ns), prefix);
}
