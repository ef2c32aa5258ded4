//! The namespace split across two "hosts" over Zenoh: the board and the board-side bridge in one
//! namespace, the central-side bridge and the central process in another, sharing nothing but
//! the Zenoh TCP connection on loopback (two iceoryx2 namespaces never see each other's files).

#![cfg(feature = "zenoh")]

use crate::common;

use common::bridge::{bridge, port, status, two_hosts, wait_for};
use common::daemons::{Daemons, run_planner, sooc_plan, unique_namespace};
use std::time::{Duration, Instant};

#[test]
fn a_trial_across_the_bridge_ends_as_on_one_host_and_a_cut_link_holds_the_board() {
    let _one = common::bridge::one_link_at_a_time();
    let sooc = sooc_plan();
    let (host_a, host_b, alone) = (
        unique_namespace("bra"),
        unique_namespace("brb"),
        unique_namespace("brc"),
    );
    let link = unique_namespace("link");
    let endpoint = format!("tls/127.0.0.1:{}", port(0));
    let mut d = Daemons::default();
    // The board's telemetry reaches host B through the two bridges.
    let board_side = two_hosts(&mut d, [&host_a, &host_b], &link, &endpoint, [&[], &[]]);

    // The same trials (same seeds) on one host and across the link.
    d.board(&alone, &["--no-rt"]); // as the board across the link (common::bridge::two_hosts)
    let trials = 2;
    let across = run_planner(&host_b, &sooc, "stiffness", trials, false);
    let direct = run_planner(&alone, &sooc, "stiffness", trials, false);
    eprintln!("across the bridge: {across:?}\none host: {direct:?}");
    assert_eq!(across.trials, trials);
    assert_eq!(
        across.safe_hold_trials, 0,
        "commands arrived late across the link"
    );
    for (a, b) in across.final_errors.iter().zip(&direct.final_errors) {
        let (a, b) = (
            a.expect("diverged across the bridge"),
            b.expect("diverged on one host"),
        );
        assert!(
            (a - b).abs() < 0.5,
            "final error across the bridge {a} mm, on one host {b} mm"
        );
    }

    // Cut the link on the board's side mid-run: the board holds within its watchdog.
    d.planner(&host_b, &sooc, "stiffness", 20);
    assert!(
        wait_for(&host_a, Duration::from_secs(10), |s| s["mode"] == "running"),
        "the trial did not start on the board"
    );
    let cut = Instant::now();
    let out = d.signal_and_wait(board_side, libc::SIGKILL);
    assert!(!out.status.success());
    assert!(
        wait_for(&host_a, Duration::from_secs(2), |s| s["mode"]
            == "safe-hold"),
        "the board did not hold after the link was cut"
    );
    eprintln!("safe hold seen {:?} after the cut", cut.elapsed());
    // A new board-side bridge resumes the link: host B sees the board's clock move on again
    // (its last telemetry from before the cut stays readable, so compare ticks).
    let before = status(&host_b)
        .and_then(|s| s["tick"].as_u64())
        .unwrap_or(0);
    bridge(
        &mut d,
        "board",
        &host_a,
        &link,
        ["--listen", &endpoint],
        &[],
    );
    assert!(
        wait_for(&host_b, Duration::from_secs(10), |s| s["tick"]
            .as_u64()
            .is_some_and(|t| t > before + 100)),
        "the link did not resume"
    );
    // The planner and everything else are killed, and the namespaces removed, by `d`'s drop.
}

/// Event-driven, not polled: with a safety interval of 2 s (the longest either bridge sleeps
/// without a notification) states and commands still cross within milliseconds, and `stop` ends
/// both bridges long before the interval. With a poll at the safety interval the median one-way
/// latency would be about 1 s.
#[test]
fn messages_cross_promptly_without_a_poll_and_stop_is_prompt() {
    use std::sync::Arc;
    use std::sync::atomic::{AtomicBool, Ordering};
    use vic_rt::bridge::{self, BridgeOptions, Link, Side};
    use vic_rt::transport::{BoardPorts, CentralPorts, CommandSlice, Header, StateMsg};
    use vic_rt::transport::{monotonic_ns, remove_namespace};

    let safety = Duration::from_secs(2);
    let (host_a, host_b) = (unique_namespace("bea"), unique_namespace("beb"));
    let link_name = unique_namespace("evl");
    let endpoint = format!("tcp/127.0.0.1:{}", port(3));
    let stop = Arc::new(AtomicBool::new(false));
    let spawn = |side, ns: &str, link| {
        let options = BridgeOptions {
            namespace: ns.to_string(),
            link_name: link_name.clone(),
            side,
            link,
            security: bridge::Security::PlainLoopback,
            safety_interval: safety,
            stamps: vic_rt::bridge::Stamps::Keep,
            clock_skew_ns: 0,
        };
        let stop = stop.clone();
        std::thread::spawn(move || bridge::run(&options, &stop, |_| {}))
    };
    let board = BoardPorts::open(&host_a).unwrap();
    let central = CentralPorts::open(&host_b).unwrap();
    let bridges = [
        spawn(Side::Board, &host_a, Link::Listen(endpoint.clone())),
        spawn(Side::Central, &host_b, Link::Connect(endpoint.clone())),
    ];
    // One-way latency of `n` messages, each sent when the previous one arrived (or after 20 ms):
    // `send(seq)` publishes one, `arrived(seq)` says whether it has crossed.
    let measure = |n: u64, send: &dyn Fn(u64), arrived: &dyn Fn(u64) -> bool| {
        let mut lat = Vec::new();
        for seq in 1..=n {
            let t = Instant::now();
            send(seq);
            while !arrived(seq) && t.elapsed() < safety * 3 {
                std::thread::sleep(Duration::from_micros(200));
            }
            lat.push(t.elapsed());
        }
        lat.sort();
        lat[lat.len() / 2]
    };
    // The link is up once a state crosses (the subscribers learn of each other first).
    let t0 = Instant::now();
    let state = |seq| StateMsg {
        header: Header::new(seq, monotonic_ns()),
        ..Default::default()
    };
    let mut up = false;
    while !up && t0.elapsed() < Duration::from_secs(10) {
        board.publish_state(&state(1_000_000)).unwrap();
        std::thread::sleep(Duration::from_millis(20));
        central.drain_states(|_| up = true);
    }
    assert!(up, "no state crossed the link within 10 s");
    let last_state = std::cell::Cell::new(0);
    let states = measure(
        100,
        &|seq| board.publish_state(&state(seq)).unwrap(),
        &|seq| {
            central.drain_states(|s| last_state.set(s.header.seq));
            last_state.get() >= seq
        },
    );
    let last_command = std::cell::Cell::new(0);
    let commands = measure(
        100,
        &|seq| {
            let c = CommandSlice {
                header: Header::new(seq, monotonic_ns()),
                ..Default::default()
            };
            central.publish_command(&c).unwrap()
        },
        &|seq| {
            board.drain_commands(|c| last_command.set(c.header.seq));
            last_command.get() >= seq
        },
    );
    eprintln!(
        "median one-way: state {states:?}, command {commands:?} (safety interval {safety:?})"
    );
    for (what, median) in [("state", states), ("command", commands)] {
        assert!(
            median < safety / 40,
            "{what}s took {median:?} at the median: the bridge waited for its safety interval"
        );
    }
    let stopping = Instant::now();
    stop.store(true, Ordering::Relaxed);
    for b in bridges {
        b.join().unwrap().unwrap();
    }
    assert!(
        stopping.elapsed() < safety / 2,
        "stop took {:?}",
        stopping.elapsed()
    );
    drop((board, central));
    remove_namespace(&host_a);
    remove_namespace(&host_b);
}
