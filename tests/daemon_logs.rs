//! The daemons log through `tracing` on stderr (issue 15, item 5): `info` by default, the level
//! from `--log-level` over `RUST_LOG`, a bad level refused as bad input, and nothing logged from
//! inside the loops (a run three times as long logs the same lines). Real `vic-board` processes
//! in a namespace of their own, each stopping by itself (`--duration-s`).

use crate::common;

use common::daemons::{CONFIG, unique_namespace};
use std::process::{Command, Output};

fn board(ns: &str, duration_s: &str, extra: &[&str], rust_log: Option<&str>) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_vic-board"));
    c.args([
        "--config",
        CONFIG,
        "--namespace",
        ns,
        "--duration-s",
        duration_s,
        "--json",
    ])
    .args(extra)
    .env_remove("RUST_LOG");
    if let Some(v) = rust_log {
        c.env("RUST_LOG", v);
    }
    c.output().unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The log's lines less their time stamps, without the warning that another test's board shares
/// this one's CPU (it depends on what runs beside, not on this board).
fn lines(o: &Output) -> Vec<String> {
    stderr(o)
        .lines()
        .filter(|l| !l.contains("is shared with another SCHED_FIFO loop"))
        .map(|l| {
            l.split_once(' ')
                .map_or(l, |(_, rest)| rest)
                .trim()
                .to_string()
        })
        .collect()
}

#[test]
fn the_board_logs_at_info_by_default_and_never_from_its_loop() {
    let ns = unique_namespace("log");
    let short = board(&ns, "0.2", &[], None);
    assert!(short.status.success(), "{}", stderr(&short));
    let log = lines(&short);
    let has = |needle: &str| {
        log.iter()
            .any(|l| l.starts_with("INFO vic-board: ") && l.contains(needle))
    };
    assert!(has("running in namespace"), "{log:#?}");
    assert!(has("stopped after 200 ticks"), "{log:#?}");
    assert!(
        log.iter().any(|l| l.contains("vic-board: real-time: ")),
        "{log:#?}"
    );
    // Three times as many ticks, the same lines (the counters differ, their number does not).
    let long = board(&ns, "0.6", &[], None);
    assert!(long.status.success(), "{}", stderr(&long));
    assert_eq!(lines(&long).len(), log.len(), "{:#?}", lines(&long));
    // The statistics stay on stdout, as JSON.
    let stats: serde_json::Value = serde_json::from_slice(&long.stdout).unwrap();
    assert_eq!(stats["ticks"].as_u64(), Some(600));
}

#[test]
fn the_level_comes_from_the_flag_then_rust_log() {
    let ns = unique_namespace("log");
    // warn: the info lines are gone (a refused real-time setting would still show, as a warning).
    let o = board(&ns, "0.1", &["--log-level", "warn"], Some("debug"));
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!stderr(&o).contains(" INFO "), "{}", stderr(&o));
    // RUST_LOG=off without the flag: nothing at all.
    let o = board(&ns, "0.1", &[], Some("off"));
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(stderr(&o), "");
    // The flag wins over RUST_LOG.
    let o = board(&ns, "0.1", &["--log-level", "info"], Some("off"));
    assert!(
        stderr(&o).contains("INFO vic-board: running"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_bad_level_is_bad_input_naming_its_source() {
    let ns = unique_namespace("log");
    let o = board(&ns, "0.1", &["--log-level", "loud"], None);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--log-level \"loud\""),
        "{}",
        stderr(&o)
    );
    let o = board(&ns, "0.1", &[], Some("vic=chatty"));
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("RUST_LOG"), "{}", stderr(&o));
}
