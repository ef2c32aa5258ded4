//! The central process when its board disappears (issue: "board lost" versus "control
//! diverged"): the real `vic-board` is SIGKILLed mid-trial; `vic-planner` must stop with exit 1
//! and "board lost" within a second, and still report the trials it finished before.

use crate::common;

use common::daemons::{Daemons, planner_command, sooc_plan, unique_namespace};
use std::io::Read;
use std::process::Stdio;
use std::time::{Duration, Instant};

#[test]
fn a_killed_board_stops_the_planner_with_board_lost_and_keeps_earlier_trials() {
    let sooc = sooc_plan();
    let ns = unique_namespace("lost");
    let mut d = Daemons::default();
    let board = d.board(&ns, &[]);
    let mut planner = planner_command(&ns, &sooc, "stiffness", 5)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // A trial lasts 1.5 s plus its lead: after 3.2 s the first one is over and the second runs.
    std::thread::sleep(Duration::from_millis(3200));
    assert!(
        planner.try_wait().unwrap().is_none(),
        "the planner ended before the board was killed"
    );
    let killed = Instant::now();
    let out = d.signal_and_wait(board, libc::SIGKILL);
    assert!(!out.status.success());
    // The planner must notice within a second (its silence limit is 200 ms).
    let status = loop {
        if let Some(s) = planner.try_wait().unwrap() {
            break s;
        }
        if killed.elapsed() > Duration::from_secs(5) {
            let _ = planner.kill();
            let _ = planner.wait();
            panic!("the planner did not stop within 5 s of the board's death");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let noticed = killed.elapsed();
    let (mut stdout, mut stderr) = (String::new(), String::new());
    planner
        .stdout
        .take()
        .unwrap()
        .read_to_string(&mut stdout)
        .unwrap();
    planner
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    eprintln!("after {noticed:?}: {status}\nstdout {stdout}\nstderr {stderr}");
    assert_eq!(status.code(), Some(1), "exit code");
    assert!(stderr.contains("board lost"), "stderr: {stderr}");
    assert!(
        noticed < Duration::from_secs(1),
        "noticed after {noticed:?}"
    );
    let result: vic::views::report::StrategyResult =
        serde_json::from_str(stdout.trim()).expect("the finished trials as JSON");
    assert!(
        (1..5).contains(&result.trials),
        "trials before the loss: {}",
        result.trials
    );
    assert_eq!(result.diverged, 0, "a lost board is not a divergence");
    assert!(
        result
            .final_errors
            .iter()
            .all(|e| e.is_some_and(|e| e < 10.0)),
        "{:?}",
        result.final_errors
    );
}
