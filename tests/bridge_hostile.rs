//! What a hostile peer on the link can do to a bridge: the bridges publish what arrives into
//! iceoryx2 from Zenoh's callbacks, and that path refuses, counts and drops what is not a message
//! of this protocol (wrong size, other version), forwards the rest, and counts every kind.

#![cfg(feature = "zenoh")]

use crate::common;

use common::bridge::port;
use common::daemons::unique_namespace;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use vic_rt::bridge::wire::encode;
use vic_rt::bridge::{self, BridgeOptions, BridgeStats, Link, Side, key};
use vic_rt::transport::{
    BoardPorts, CentralPorts, CommandSlice, Control, Header, PROTOCOL_VERSION, StateMsg, Telemetry,
    remove_namespace,
};
use zenoh::Wait;

/// A bridge on `side` of namespace `ns` listening on `endpoint`, in a thread, until `stop`.
fn spawn(
    side: Side,
    ns: &str,
    link_name: &str,
    endpoint: &str,
    stop: &Arc<AtomicBool>,
) -> std::thread::JoinHandle<Result<BridgeStats, bridge::BridgeError>> {
    let options = BridgeOptions {
        namespace: ns.to_string(),
        link_name: link_name.to_string(),
        side,
        link: Link::Listen(endpoint.to_string()),
        security: bridge::Security::PlainLoopback,
        safety_interval: bridge::DEFAULT_SAFETY_INTERVAL,
        stamps: bridge::Stamps::Keep,
        clock_skew_ns: 0,
    };
    let stop = stop.clone();
    std::thread::spawn(move || bridge::run(&options, &stop, |_| {}))
}

/// The hostile peer: a plain Zenoh session connected to the bridge's endpoint.
fn peer(endpoint: &str) -> zenoh::Session {
    let mut c = zenoh::Config::default();
    c.insert_json5("connect/endpoints", &format!(r#"["{endpoint}"]"#))
        .unwrap();
    c.insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    zenoh::open(c).wait().unwrap()
}

/// Puts `valid(seq)` on `key` every 20 ms until `arrived` sees it (the peer learns of the
/// bridge's subscriptions first), for at most 10 s.
fn until_it_crosses(
    z: &zenoh::Session,
    key: &str,
    valid: &dyn Fn() -> Vec<u8>,
    arrived: &mut dyn FnMut() -> bool,
) {
    let t0 = Instant::now();
    while t0.elapsed() < Duration::from_secs(10) {
        z.put(key, valid()).wait().unwrap();
        std::thread::sleep(Duration::from_millis(20));
        if arrived() {
            return;
        }
    }
    panic!("nothing crossed on {key} within 10 s");
}

#[test]
fn the_callbacks_refuse_what_is_not_a_message_and_forward_the_rest() {
    let (host_a, host_b) = (unique_namespace("bha"), unique_namespace("bhb"));
    let link_name = unique_namespace("hl");
    let (end_a, end_b) = (
        format!("tcp/127.0.0.1:{}", port(5)),
        format!("tcp/127.0.0.1:{}", port(6)),
    );
    let stop = Arc::new(AtomicBool::new(false));
    let board = BoardPorts::open(&host_a).unwrap();
    let central = CentralPorts::open(&host_b).unwrap();
    let bridges = [
        spawn(Side::Board, &host_a, &link_name, &end_a, &stop),
        spawn(Side::Central, &host_b, &link_name, &end_b, &stop),
    ];
    let (za, zb) = (peer(&end_a), peer(&end_b));

    // Towards the board: valid commands cross; a short one, a wrong version and a short control
    // do not.
    let command = |seq| CommandSlice {
        header: Header::new(seq, 1),
        ..Default::default()
    };
    let command_key = key::<CommandSlice>(&link_name);
    let mut commands = Vec::new();
    until_it_crosses(
        &za,
        &command_key,
        &|| encode(&command(1)).to_vec(),
        &mut || board.drain_commands(|c| commands.push(c.header.seq)) > 0,
    );
    let bytes = encode(&command(2)).to_vec();
    za.put(&command_key, bytes[..bytes.len() - 1].to_vec())
        .wait()
        .unwrap();
    let mut old = command(3);
    old.header.version = PROTOCOL_VERSION + 1;
    za.put(&command_key, encode(&old).to_vec()).wait().unwrap();
    za.put(key::<Control>(&link_name), vec![0u8; 3])
        .wait()
        .unwrap();
    until_it_crosses(
        &za,
        &command_key,
        &|| encode(&command(4)).to_vec(),
        &mut || {
            board.drain_commands(|c| commands.push(c.header.seq));
            commands.contains(&4)
        },
    );
    assert!(
        commands.iter().all(|&s| s == 1 || s == 4),
        "a refused command reached the board: {commands:?}"
    );

    // Back: a state of another version and a short telemetry do not reach the planner.
    let state = |seq| StateMsg {
        header: Header::new(seq, 1),
        ..Default::default()
    };
    let state_key = key::<StateMsg>(&link_name);
    let mut states = Vec::new();
    until_it_crosses(&zb, &state_key, &|| encode(&state(1)).to_vec(), &mut || {
        central.drain_states(|s| states.push(s.header.seq)) > 0
    });
    let mut old = state(2);
    old.header.version = 0;
    zb.put(&state_key, encode(&old).to_vec()).wait().unwrap();
    zb.put(key::<Telemetry>(&link_name), vec![1u8; 7])
        .wait()
        .unwrap();
    until_it_crosses(&zb, &state_key, &|| encode(&state(3)).to_vec(), &mut || {
        central.drain_states(|s| states.push(s.header.seq));
        states.contains(&3)
    });
    assert!(
        states.iter().all(|&s| s == 1 || s == 3),
        "a refused state reached the planner: {states:?}"
    );
    assert!(central.latest_telemetry().is_none());

    // A repeated valid message still on its way when it was last looked for is counted too.
    std::thread::sleep(Duration::from_millis(200));
    board.drain_commands(|c| commands.push(c.header.seq));
    central.drain_states(|s| states.push(s.header.seq));
    stop.store(true, Ordering::Relaxed);
    let [a, b] = bridges.map(|b| b.join().unwrap().unwrap());
    // Every valid message sent was counted and forwarded (the ones before the link was up
    // included: the bridge had subscribed before the peer could put).
    assert_eq!(a.received.command, commands.len() as u64, "{a:?}");
    assert_eq!((a.malformed_size, a.malformed_version), (2, 1), "{a:?}");
    assert_eq!(b.received.state, states.len() as u64, "{b:?}");
    assert_eq!(b.received.telemetry, 0, "{b:?}");
    assert_eq!((b.malformed_size, b.malformed_version), (1, 1), "{b:?}");
    assert_eq!(a.local_errors + b.local_errors, 0, "{a:?} {b:?}");
    drop((za, zb, board, central));
    remove_namespace(&host_a);
    remove_namespace(&host_b);
}
