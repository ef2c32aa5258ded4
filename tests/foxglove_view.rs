//! `vic view` serves a live namespace to Foxglove: a WebSocket client speaking Foxglove's
//! protocol (`foxglove.sdk.v1`: JSON `serverInfo` and `advertise`, a `subscribe`, binary
//! message frames) decodes what a real board and planner produce, and finds in it what the
//! layout `docs/foxglove-layout.json` plots.

#![cfg(feature = "foxglove")]

use crate::common;

use common::daemons::{Daemons, run_planner, sooc_plan, unique_namespace};
use serde_json::Value;
use std::collections::HashMap;
use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};

type Socket = WebSocket<TcpStream>;

fn connect(port: u16) -> Socket {
    let mut request = format!("ws://127.0.0.1:{port}")
        .into_client_request()
        .unwrap();
    request
        .headers_mut()
        .insert("Sec-WebSocket-Protocol", "foxglove.sdk.v1".parse().unwrap());
    let stream = TcpStream::connect(("127.0.0.1", port)).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let (socket, response) = tungstenite::client(request, stream).expect("the handshake");
    assert_eq!(
        response.headers()["Sec-WebSocket-Protocol"],
        "foxglove.sdk.v1"
    );
    socket
}

/// The next message within `until`, or None.
fn next(ws: &mut Socket, until: Instant) -> Option<Message> {
    while Instant::now() < until {
        match ws.read() {
            Ok(m) => return Some(m),
            Err(tungstenite::Error::Io(e))
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(e) => panic!("the view's socket failed: {e}"),
        }
    }
    None
}

/// The value at a Foxglove message path's field part (`.a.b[1]`) of a decoded message.
fn at<'a>(v: &'a Value, path: &str) -> Option<&'a Value> {
    let mut v = v;
    for part in path.split('.').filter(|p| !p.is_empty()) {
        let (name, index) = match part.split_once('[') {
            Some((n, i)) => (n, Some(i.trim_end_matches(']').parse::<usize>().ok()?)),
            None => (part, None),
        };
        v = v.get(name)?;
        if let Some(i) = index {
            v = v.get(i)?;
        }
    }
    Some(v)
}

#[test]
fn a_foxglove_client_decodes_the_live_board_the_plan_and_the_hand_the_layout_plots() {
    let ns = unique_namespace("fox");
    let mut d = Daemons::default();
    d.board(&ns, &[]);
    let mut view = Command::new(env!("CARGO_BIN_EXE_vic"))
        .args([
            "view",
            "--namespace",
            &ns,
            "--port",
            "0",
            "--rate-hz",
            "200",
        ])
        .args(["--json", "--config", common::daemons::CONFIG])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let view_pid = view.id();
    // The port from the line it prints once it listens.
    let mut err = BufReader::new(view.stderr.take().unwrap());
    let mut line = String::new();
    err.read_line(&mut line).unwrap();
    let port: u16 = line
        .split("ws://127.0.0.1:")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|p| p.parse().ok())
        .unwrap_or_else(|| panic!("no port in {line:?}"));
    d.children.push(view);

    let mut ws = connect(port);
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut channels: HashMap<u64, (String, Value)> = HashMap::new();
    let mut server_info = None;
    while channels.len() < 8 {
        let Some(Message::Text(t)) = next(&mut ws, deadline) else {
            panic!("advertised so far: {channels:?}");
        };
        let v: Value = serde_json::from_str(&t).unwrap();
        match v["op"].as_str() {
            Some("serverInfo") => server_info = Some(v),
            Some("advertise") => {
                for c in v["channels"].as_array().unwrap() {
                    assert_eq!(c["encoding"], "json", "{c}");
                    assert_eq!(c["schemaEncoding"], "jsonschema", "{c}");
                    let schema: Value = serde_json::from_str(c["schema"].as_str().unwrap())
                        .expect("the schema is JSON");
                    channels.insert(
                        c["id"].as_u64().unwrap(),
                        (c["topic"].as_str().unwrap().to_string(), schema),
                    );
                }
            }
            _ => {}
        }
    }
    assert!(server_info.is_some(), "no serverInfo before the channels");
    let subscriptions: Vec<Value> = channels
        .keys()
        .enumerate()
        .map(|(i, id)| serde_json::json!({"id": i as u32 + 1, "channelId": id}))
        .collect();
    let by_sub: HashMap<u32, String> = channels
        .keys()
        .enumerate()
        .map(|(i, id)| (i as u32 + 1, channels[id].0.clone()))
        .collect();
    ws.send(Message::Text(
        serde_json::json!({"op": "subscribe", "subscriptions": subscriptions})
            .to_string()
            .into(),
    ))
    .unwrap();

    // One trial of the stiffness plan while the client reads.
    let plan = sooc_plan();
    let planner = {
        let ns = ns.clone();
        std::thread::spawn(move || run_planner(&ns, &plan, "stiffness", 1, false))
    };
    let mut got: HashMap<String, Vec<Value>> = HashMap::new();
    let until = Instant::now() + Duration::from_secs(20);
    while !planner.is_finished() && Instant::now() < until {
        if let Some(Message::Binary(b)) = next(&mut ws, until) {
            assert_eq!(b[0], 1, "a message-data frame");
            let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
            let v: Value = serde_json::from_slice(&b[13..]).expect("a JSON message");
            got.entry(by_sub[&sub].clone()).or_default().push(v);
        }
    }
    let result = planner.join().unwrap();
    assert_eq!(result.trials, 1);

    // Every message is its schema's: the schema's required fields, nothing else.
    for (topic, schema) in channels.values() {
        for m in got.get(topic).into_iter().flatten() {
            let props = schema["properties"].as_object().unwrap();
            let keys: Vec<&String> = m.as_object().unwrap().keys().collect();
            assert_eq!(keys.len(), props.len(), "{topic}: {m}");
            assert!(keys.iter().all(|k| props.contains_key(*k)), "{topic}: {m}");
        }
    }
    let count = |t: &str| got.get(t).map_or(0, Vec::len);
    // 200 of the 1000 states a second; the trial lasts about a second.
    assert!(count("/state") > 100, "{} states", count("/state"));
    assert!(
        count("/command") > 10 && count("/telemetry") > 3,
        "{:?}",
        got.keys()
    );
    let states = &got["/state"];
    let ticks: Vec<u64> = states.iter().map(|s| s["tick"].as_u64().unwrap()).collect();
    assert!(
        ticks.windows(2).all(|w| w[1] == w[0] + 5),
        "every fifth tick, in order"
    );
    // The plan the board executes: the reference's error is q − q_d, and the hand is the
    // two-link arm's kinematics (lengths from the scenario) of q and of q_d.
    let running: Vec<&Value> = got.get("/reference").into_iter().flatten().collect();
    assert!(running.len() > 100, "{} references", running.len());
    let scenario: toml::Table = std::fs::read_to_string(common::daemons::CONFIG)
        .unwrap()
        .parse()
        .unwrap();
    let length = |k: &str| scenario["plant"][k].as_float().unwrap();
    let (l1, l2) = (length("l1"), length("l2"));
    let fk = |q: &[f64]| {
        [
            l1 * q[0].cos() + l2 * (q[0] + q[1]).cos(),
            l1 * q[0].sin() + l2 * (q[0] + q[1]).sin(),
        ]
    };
    let hands: HashMap<u64, &Value> = got["/hand"]
        .iter()
        .map(|h| (h["tick"].as_u64().unwrap(), h))
        .collect();
    let nums = |v: &Value| -> Vec<f64> {
        v.as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let mut matched = 0;
    for r in &running {
        let (q, q_d, e) = (nums(&r["q"]), nums(&r["q_d"]), nums(&r["q_error"]));
        for j in 0..2 {
            assert!((e[j] - (q[j] - q_d[j])).abs() < 1e-12, "{r}");
        }
        assert!(nums(&r["stiffness"]).iter().all(|k| *k >= 0.0), "{r}");
        // The last ones may still be on their way when the reading stops.
        let Some(h) = hands.get(&r["tick"].as_u64().unwrap()) else {
            continue;
        };
        matched += 1;
        let ([x, y], [x_d, y_d]) = (fk(&q), fk(&q_d));
        for (got, want) in [
            (&h["x"], x),
            (&h["y"], y),
            (&h["x_d"], x_d),
            (&h["y_d"], y_d),
        ] {
            assert!(
                (got.as_f64().unwrap() - want).abs() < 1e-9,
                "{h} against {want}"
            );
        }
    }
    assert!(
        matched * 10 >= running.len() * 9,
        "{matched} of {} references have their hand",
        running.len()
    );
    // The planned stiffness moves over the trial (the SOOC plan is not constant).
    let k: Vec<f64> = running.iter().map(|r| nums(&r["stiffness"])[0]).collect();
    let spread =
        k.iter().cloned().fold(f64::MIN, f64::max) - k.iter().cloned().fold(f64::MAX, f64::min);
    assert!(spread > 1.0, "planned K₁ from {k:?}");

    // Every path the layout plots names a channel the view serves and a field its messages have.
    let layout: Value = serde_json::from_str(
        &std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/docs/foxglove-layout.json"
        ))
        .unwrap(),
    )
    .unwrap();
    let mut paths = vec![];
    for panel in layout["configById"].as_object().unwrap().values() {
        for p in panel["paths"].as_array().unwrap() {
            paths.push(p["value"].as_str().unwrap().to_string());
        }
        if let Some(x) = panel["xAxisPath"]["value"].as_str() {
            paths.push(x.to_string());
        }
    }
    assert!(paths.len() >= 10, "{paths:?}");
    for p in &paths {
        let (topic, field) = p.split_at(p.find('.').unwrap());
        let msgs = got
            .get(topic)
            .unwrap_or_else(|| panic!("{p}: no {topic} received"));
        assert!(
            msgs.iter()
                .any(|m| at(m, field).is_some_and(Value::is_number)),
            "{p}: no number at {field} in {topic}"
        );
    }

    // SIGTERM ends the view with its summary.
    drop(ws);
    let i = d.children.iter().position(|c| c.id() == view_pid).unwrap();
    let out = d.signal_and_wait(i, libc::SIGTERM);
    assert!(out.status.success(), "vic view: {:?}", out.status);
    let summary: Value = serde_json::from_slice(&out.stdout).expect("its JSON summary");
    assert_eq!(summary["port"], port);
    assert!(
        summary["states"].as_u64().unwrap() >= 5 * summary["states_shown"].as_u64().unwrap() - 5
    );
}
