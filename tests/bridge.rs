//! The namespace split across two "hosts" over Zenoh: the board and the board-side bridge in one
//! namespace, the central-side bridge and the central process in another, sharing nothing but
//! the Zenoh TCP connection on loopback (two iceoryx2 namespaces never see each other's files).

#![cfg(feature = "zenoh")]

mod common;

use common::bridge::{bridge, port, status, wait_for};
use common::daemons::{Daemons, run_planner, sooc_plan, unique_namespace};
use std::time::{Duration, Instant};

#[test]
fn a_trial_across_the_bridge_ends_as_on_one_host_and_a_cut_link_holds_the_board() {
    let sooc = sooc_plan();
    let (host_a, host_b, alone) = (
        unique_namespace("bra"),
        unique_namespace("brb"),
        unique_namespace("brc"),
    );
    let link = unique_namespace("link");
    let endpoint = format!("tcp/127.0.0.1:{}", port(0));
    let mut d = Daemons::default();
    d.board(&host_a, &[]);
    let board_side = bridge(
        &mut d,
        "board",
        &host_a,
        &link,
        ["--listen", &endpoint],
        &[],
    );
    bridge(
        &mut d,
        "central",
        &host_b,
        &link,
        ["--connect", &endpoint],
        &[],
    );
    // The board's telemetry reaches host B through the two bridges.
    assert!(
        wait_for(&host_b, Duration::from_secs(10), |_| true),
        "no board answered on host B through the bridge"
    );

    // The same trials (same seeds) on one host and across the link.
    d.board(&alone, &[]);
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
