//! A second central process in a namespace (issues 13 and 14, finding 4): it is refused at once
//! with exit 1, naming the namespace and the running one's pid, and the first one's trials carry
//! on undisturbed. Real `vic-board` and two real `vic-planner`s.

use crate::common;

use common::daemons::{Daemons, planner_command, sooc_plan, unique_namespace};
use std::process::Stdio;
use std::time::{Duration, Instant};
use vic::views::report::StrategyResult;

const TRIALS: usize = 3;

#[test]
fn a_second_planner_is_refused_and_the_first_finishes_its_trials() {
    let sooc = sooc_plan();
    let ns = unique_namespace("dup");
    let mut d = Daemons::default();
    d.board(&ns, &[]);
    let first = d.planner(&ns, &sooc, "stiffness", TRIALS);
    let first_pid = d.pid(first);
    // Let the first one connect and start its first trial.
    std::thread::sleep(Duration::from_millis(1500));
    assert!(
        d.children[first].try_wait().unwrap().is_none(),
        "the first planner ended early"
    );

    let t0 = Instant::now();
    let second = planner_command(&ns, &sooc, "stiffness", 1)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let took = t0.elapsed();
    let err = String::from_utf8_lossy(&second.stderr);
    eprintln!("second planner after {took:?}: {err}");
    assert_eq!(second.status.code(), Some(1), "stderr: {err}");
    assert!(err.contains(&format!("namespace \"{ns}\"")), "{err}");
    assert!(err.contains(&format!("pid {first_pid}")), "{err}");
    assert!(err.contains("already running"), "{err}");
    assert!(
        second.stdout.is_empty(),
        "the refused planner reported trials"
    );
    assert!(took < Duration::from_secs(5), "refused only after {took:?}");

    // The first planner was not disturbed: every trial done, none diverged, all on target.
    let out = d.wait(first);
    assert!(out.status.success(), "first planner: {:?}", out.status);
    let r: StrategyResult = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r.trials, TRIALS);
    assert_eq!(r.diverged, 0);
    assert!(
        r.final_errors.iter().all(|e| e.is_some_and(|e| e < 10.0)),
        "{:?}",
        r.final_errors
    );
}
