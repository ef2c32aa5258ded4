//! The real-time pair end to end: the real `vic-board` and `vic-planner` processes in a unique
//! namespace, on the two-link arm in the divergent field with a 200 ms feedback latency.
//!
//! The scenario is `two_link_divergent.toml` with `noise.sigma = 0.02` (see
//! `common::daemons::SIGMA` for why). The plans are fixtures in tests/data/realtime (made by
//! `vic plan`); if they no longer parse they are re-made.

use crate::common;

use common::daemons::{
    Daemons, ilqg_plan, ilqg0_plan, planner_command_at, run_planner, sooc_plan, unique_namespace,
};

#[test]
fn stiffness_beats_delayed_feedback_in_the_divergent_field() {
    let (sooc, ilqg) = (sooc_plan(), ilqg_plan());
    let ns = unique_namespace("rt");
    let mut d = Daemons::default();
    let board = d.board(&ns, &[]);
    let trials = 3;
    let stiff = run_planner(&ns, &sooc, "stiffness", trials, false);
    let fb = run_planner(&ns, &ilqg, "naive-delayed", trials, false);
    // Without latency central feedback works: a plan for no delay, the planner at 250 Hz so
    // that its own loop adds only a few milliseconds.
    let out = planner_command_at(&ns, &ilqg0_plan(), "naive-delayed", trials, "0")
        .args(["--rate-hz", "250"])
        .stderr(std::process::Stdio::inherit())
        .output()
        .unwrap();
    assert!(out.status.success());
    let fb0: vic::views::report::StrategyResult = serde_json::from_slice(&out.stdout).unwrap();

    // SIGTERM: the board stops at the end of the tick, prints its statistics, exits 0.
    let out = d.signal_and_wait(board, libc::SIGTERM);
    assert!(out.status.success(), "the board exited with {}", out.status);
    let stats: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(stats["ticks"].as_u64().unwrap() > 1000);
    assert!(stats["jitter_us"]["p50"].as_f64().is_some());
    // The planners' slices all belong to a running trial: none crosses the stop that ends it
    // (one per trial did, sent in the same tick as the stop and checked after it).
    assert_eq!(
        stats["rejected_by_reason"]["wrong-trial"]
            .as_u64()
            .unwrap_or(0),
        0,
        "slices rejected as wrong-trial: {}",
        stats["rejected_by_reason"]
    );
    assert!(
        vic_rt::transport::namespace_files(&ns).is_empty(),
        "shared memory left behind: {:?}",
        vic_rt::transport::namespace_files(&ns)
    );

    eprintln!(
        "stiffness: {stiff:?}\ndelayed feedback: {fb:?}\nwithout latency: {fb0:?}\nboard: {stats}"
    );
    assert_eq!(stiff.trials, trials);
    assert_eq!(stiff.safe_hold_trials, 0, "commands arrived late");
    assert!(
        stiff
            .final_errors
            .iter()
            .all(|e| e.is_some_and(|e| e < 10.0)),
        "stiffness: every trial within 1 cm, got {:?} mm",
        stiff.final_errors
    );
    assert!(
        fb.diverged > 0 || fb.final_error_max.is_some_and(|e| e > 10.0),
        "delayed feedback without stiffness should miss by centimetres or diverge, got {:?} mm",
        fb.final_errors
    );
    assert!(
        fb0.final_errors.iter().all(|e| e.is_some_and(|e| e < 10.0)),
        "delayed feedback at 0 ms latency should work, got {:?} mm",
        fb0.final_errors
    );

    // Lockstep (simulated clock, same code, same seeds) agrees with the live run: the stiffness
    // strategy is open loop, so only late commands could make them differ.
    let lock = run_planner(&ns, &sooc, "stiffness", trials, true);
    for (a, b) in stiff.final_errors.iter().zip(&lock.final_errors) {
        let (a, b) = (a.unwrap(), b.unwrap());
        assert!((a - b).abs() < 0.5, "live {a} mm vs lockstep {b} mm");
    }
}
