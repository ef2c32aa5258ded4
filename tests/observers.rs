//! Observers never lock out the controller (issue 66, finding 3): 32 observers of mixed kinds —
//! `vic monitor`s and, where a Python with the client is at hand (`VIC_PYTHON`), Python clients
//! that only watch — then the planner runs a trial, `vic inject` is acknowledged and `vic status`
//! answers. Observers take no publisher (the Python client opens its publishers at its first
//! send), and 32 of them leave the subscribers and listeners the senders need. Real processes,
//! a namespace of their own; everything started here is killed by the test's `Daemons`.

use crate::common;

use common::cli::{inject, status, text, wait_for_board};
use common::daemons::{Daemons, run_planner, sooc_plan, unique_namespace};
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

const OBSERVERS: usize = 32;
/// Of them, Python clients (when `VIC_PYTHON` is set).
const PYTHON_WATCHERS: usize = 8;

/// Counts the lines of `child`'s stdout that start with `prefix`, on a thread of its own.
fn count_lines(child: &mut Child, prefix: &'static str) -> Arc<AtomicUsize> {
    let out = child.stdout.take().expect("stdout piped");
    let n = Arc::new(AtomicUsize::new(0));
    let seen = n.clone();
    std::thread::spawn(move || {
        for line in BufReader::new(out).lines().map_while(Result::ok) {
            if line.starts_with(prefix) {
                seen.fetch_add(1, Ordering::Relaxed);
            }
        }
    });
    n
}

/// A Python client of this checkout that connects, takes one poll and then only watches.
fn python_watcher(python: &str, ns: &str) -> Child {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let script = "import sys, time\nfrom vic_client import Board\nb = Board(sys.argv[1], \
                  timeout=20)\nb.poll()\nprint('watching', flush=True)\ntime.sleep(300)\n";
    Command::new(python)
        .args(["-c", script, ns])
        .env("PYTHONPATH", root.join("python"))
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .unwrap()
}

#[test]
fn thirty_two_observers_leave_the_planner_inject_and_status_working() {
    let ns = unique_namespace("obs");
    let mut d = Daemons::default();
    d.board(&ns, &["--no-rt"]);
    wait_for_board(&ns);
    let python = std::env::var("VIC_PYTHON").ok();
    let pythons = if python.is_some() { PYTHON_WATCHERS } else { 0 };
    let mut shown = Vec::new();
    for k in 0..OBSERVERS {
        let mut child = match (&python, k < pythons) {
            (Some(p), true) => python_watcher(p, &ns),
            _ => Command::new(env!("CARGO_BIN_EXE_vic"))
                .args(["monitor", "--namespace", &ns, "--interval-s", "0.2"])
                .stdout(Stdio::piped())
                .stderr(Stdio::inherit())
                .spawn()
                .unwrap(),
        };
        let prefix = if k < pythons { "watching" } else { "mode=" };
        shown.push(count_lines(&mut child, prefix));
        d.children.push(child);
    }
    // Every observer is attached and showing (a monitor refused a port would exit 1 instead).
    let t0 = Instant::now();
    while shown.iter().any(|n| n.load(Ordering::Relaxed) == 0) {
        let waiting = shown
            .iter()
            .filter(|n| n.load(Ordering::Relaxed) == 0)
            .count();
        for c in &mut d.children[1..] {
            if let Some(status) = c.try_wait().unwrap() {
                panic!("an observer ended ({status}) with {waiting} not yet showing");
            }
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "{waiting} of {OBSERVERS} observers not showing"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    eprintln!(
        "{OBSERVERS} observers ({pythons} Python) attached after {:.1} s",
        t0.elapsed().as_secs_f64()
    );

    // With every observer attached: status, inject and a planner's trial.
    let s = status(&ns);
    assert!(s.status.success(), "status: {}", text(&s));
    let i = inject(&ns);
    assert!(i.status.success(), "inject: {}", text(&i));
    let r = run_planner(&ns, &sooc_plan(), "stiffness", 1, false);
    assert_eq!((r.trials, r.diverged), (1, 0), "the planner's trial");
    // The observers are still there.
    for c in &mut d.children[1..] {
        assert!(c.try_wait().unwrap().is_none(), "an observer ended");
    }
}
