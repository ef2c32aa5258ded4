//! Two "hosts" whose clocks differ by 5 s (the central-side bridge's hidden `--clock-skew-ms`
//! stamps everything from host B on a clock 5 s ahead, as another machine's would be): the
//! board-side bridge measures the offset over the link and translates the stamps, so a trial
//! ends as on one host; with the senders' stamps kept, the board rejects every message from
//! host B as from the future.

#![cfg(feature = "zenoh")]

use crate::common;

use common::bridge::{port, status, stop_bridge, two_hosts};
use common::daemons::{Daemons, planner_command, run_planner, sooc_plan, unique_namespace};
use std::process::Stdio;

const SKEW_NS: i64 = 5_000_000_000;

#[test]
fn a_trial_between_hosts_whose_clocks_differ_by_5_s_ends_as_on_one_host() {
    let _one = common::bridge::one_link_at_a_time();
    let sooc = sooc_plan();
    let (host_a, host_b, alone) = (
        unique_namespace("cka"),
        unique_namespace("ckb"),
        unique_namespace("ckc"),
    );
    let link = unique_namespace("clk");
    let endpoint = format!("tls/127.0.0.1:{}", port(1));
    let mut d = Daemons::default();
    let skew = ["--clock-skew-ms", "5000"];
    let board_side = two_hosts(&mut d, [&host_a, &host_b], &link, &endpoint, [&[], &skew]);

    d.board(&alone, &["--no-rt"]); // as the board across the link (common::bridge::two_hosts)
    let across = run_planner(&host_b, &sooc, "stiffness", 1, false);
    let direct = run_planner(&alone, &sooc, "stiffness", 1, false);
    eprintln!("across the skewed link: {across:?}\none host: {direct:?}");
    assert_eq!(
        across.safe_hold_trials, 0,
        "the board held: commands refused"
    );
    let (a, b) = (
        across.final_errors[0].expect("diverged across the bridge"),
        direct.final_errors[0].expect("diverged on one host"),
    );
    assert!(
        (a - b).abs() < 0.5,
        "final error across {a} mm, on one host {b} mm"
    );
    let board = status(&host_a).expect("the board answers on host A");
    eprintln!("board's rejections: {}", board["rejected_by_reason"]);
    for reason in ["future-timestamp", "stale", "too-far-ahead"] {
        assert!(
            board["rejected_by_reason"].get(reason).is_none(),
            "the board rejected messages as {reason}"
        );
    }

    // The offset measured (board − central) is the injected skew within ± half the round trip
    // of the probe it comes from.
    let stats = stop_bridge(&mut d, board_side);
    let clock = &stats["stats"]["clock"];
    eprintln!("board-side clock: {clock}");
    let offset = clock["offset_ns"].as_i64().expect("an offset was measured");
    let (rtt, uncertainty) = (
        clock["round_trip_ns"].as_u64().unwrap(),
        clock["uncertainty_ns"].as_u64().unwrap(),
    );
    assert_eq!(uncertainty, rtt.div_ceil(2));
    assert!(
        (offset + SKEW_NS).unsigned_abs() <= uncertainty,
        "offset {offset} ns, skew −{SKEW_NS} ns, round trip {rtt} ns"
    );
    assert!(clock["answers"].as_u64().unwrap() > 0);
}

#[test]
fn without_the_translation_the_board_rejects_the_skewed_host_as_from_the_future() {
    let sooc = sooc_plan();
    let (host_a, host_b) = (unique_namespace("cna"), unique_namespace("cnb"));
    let link = unique_namespace("cln");
    let endpoint = format!("tls/127.0.0.1:{}", port(2));
    let mut d = Daemons::default();
    let (keep, skew) = (["--stamps", "keep"], ["--clock-skew-ms", "5000"]);
    two_hosts(&mut d, [&host_a, &host_b], &link, &endpoint, [&keep, &skew]);
    // The planner's reset is 5 s "in the future" for the board: never acknowledged.
    let out = planner_command(&host_b, &sooc, "stiffness", 1)
        .stderr(Stdio::null())
        .output()
        .unwrap();
    assert!(
        !out.status.success(),
        "the trial ran with untranslated stamps"
    );
    let board = status(&host_a).expect("the board answers on host A");
    eprintln!("board's rejections: {}", board["rejected_by_reason"]);
    assert!(
        board["rejected_by_reason"]["future-timestamp"]
            .as_u64()
            .is_some_and(|n| n > 0),
        "no message rejected as from the future"
    );
    assert_eq!(board["mode"], "idle", "a trial started");
}
