//! `vic demo --distributed`: the board and the planners in two namespaces joined by Zenoh on
//! loopback give the trial the one-host demo gives (same plan, same seed), and report the
//! link's round trip; without the `zenoh` feature the flag says how to build it (exit 2).

use crate::common;

use common::daemons::{CONFIG, SIGMA, ilqg_plan, sooc_plan};
use std::path::Path;
use std::process::{Command, Stdio};

/// `vic demo` of the stiffness strategy alone, one trial, the fixtures' plans.
fn demo(out_dir: &Path, distributed: bool) -> Command {
    let plans = Path::new(env!("CARGO_TARGET_TMPDIR")).join("demo-plans");
    let mut c = Command::new(env!("CARGO_BIN_EXE_vic"));
    c.args(["demo", "--config", CONFIG, "--set", SIGMA])
        .args(["--trials", "1", "--only", "stiffness", "--no-rt", "--json"])
        .arg("--stiffness-plan")
        .arg(sooc_plan())
        .arg("--feedback-plan")
        .arg(ilqg_plan())
        .arg("--plans-dir")
        .arg(plans)
        .arg("--out-dir")
        .arg(out_dir);
    if distributed {
        c.arg("--distributed");
    }
    c
}

#[cfg(feature = "zenoh")]
#[test]
fn the_distributed_demo_ends_as_the_one_host_demo_and_reports_the_link() {
    let _one = common::bridge::one_link_at_a_time();
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("dd{}", std::process::id()));
    let run = |distributed: bool| -> serde_json::Value {
        let out = demo(&dir.join(distributed.to_string()), distributed)
            .stderr(Stdio::inherit())
            .output()
            .unwrap();
        assert!(out.status.success(), "vic demo failed: {:?}", out.status);
        serde_json::from_slice(&out.stdout).expect("vic demo printed JSON")
    };
    let (one, two) = (run(false), run(true));
    std::fs::remove_dir_all(&dir).ok();
    let final_error = |doc: &serde_json::Value| {
        let s = &doc["strategies"];
        assert_eq!(s.as_array().map(Vec::len), Some(1), "one strategy: {s}");
        assert_eq!(s[0]["name"], "stiffness");
        assert_eq!(s[0]["safe_hold_trials"], 0);
        s[0]["final_errors"][0].as_f64().expect("a final error")
    };
    let (a, b) = (final_error(&one), final_error(&two));
    // The verdict is the run's: its best row is the one strategy that ran, with its numbers,
    // and the offline curve of the same scenario says where the predictor stops beating the
    // stiffness plan.
    let v = &one["verdict"];
    assert_eq!(v["best"], "stiffness", "{v}");
    assert_eq!(
        v["best_final_error_mean"],
        one["strategies"][0]["final_error_mean"]
    );
    let c = &v["offline"]["crossings"][0];
    assert_eq!(
        (&c["feedback"], &c["stiffness"]),
        (&"predictor".into(), &"stiffness".into())
    );
    assert!(c["kind"].is_string(), "{v}");
    eprintln!(
        "final error: one host {a} mm, distributed {b} mm; link: {}",
        two["link"]
    );
    assert!((a - b).abs() < 0.5, "one host {a} mm, distributed {b} mm");
    assert!(one["link"].is_null());
    let link = &two["link"];
    let rtt = link["round_trip_best_us"]
        .as_f64()
        .expect("a measured round trip");
    let median = link["round_trip_median_us"].as_f64().unwrap();
    // Loopback: more than nothing, less than the board's watchdog.
    assert!(rtt > 0.0 && rtt <= median && median < 50_000.0, "{link}");
    // One machine, one clock: the offset measured is 0 within its uncertainty.
    let (offset, uncertainty) = (
        link["clock_offset_us"].as_f64().unwrap(),
        link["clock_uncertainty_us"].as_f64().unwrap(),
    );
    assert!(offset.abs() <= uncertainty + 1.0, "{link}");
    // The states and commands did cross the link.
    let bridges = &link["bridges"];
    assert!(bridges["board_side"]["received"]["command"].as_u64() > Some(0));
    assert!(bridges["central_side"]["received"]["state"].as_u64() > Some(0));
    assert_eq!(link["leftover_shm_files"], serde_json::json!([]));
    assert_eq!(two["leftover_shm_files"], serde_json::json!([]));
}

#[cfg(not(feature = "zenoh"))]
#[test]
fn without_the_bridge_the_distributed_demo_says_how_to_build_it() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("dn{}", std::process::id()));
    let out = demo(&dir, true).stderr(Stdio::piped()).output().unwrap();
    std::fs::remove_dir_all(&dir).ok();
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("--features zenoh"), "{stderr}");
}
