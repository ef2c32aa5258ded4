//! Clients by role (issue 14, finding 5): read-only tools take no publisher, so 8 `vic monitor`s
//! do not lock out `vic status` or `vic inject`; when a real iceoryx2 limit is reached the client
//! is told which limit, the configured number and which processes hold the slots (exit 1), never
//! a bare iceoryx2 error name. Real `vic-board`, real `vic monitor` / `status` / `inject`
//! processes, a namespace of their own.

use crate::common;

use common::cli::{inject, status, text, wait_for_board};
use common::daemons::{Daemons, unique_namespace};
use std::io::{BufRead, BufReader};
use std::process::{Command, Output, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};
use vic_rt::transport::limits::{MAX_PUBLISHERS, MAX_SUBSCRIBERS};
use vic_rt::transport::{ObserverPorts, PortKind, ToolPorts, TransportError};

const MONITORS: usize = 8;

/// Whether `o` is a clean "too many" refusal: exit 1, no iceoryx2 enum name.
fn assert_refused(o: &Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{}", text(o));
    for n in needles {
        assert!(err.contains(n), "missing {n:?} in: {err}");
    }
    assert!(!err.contains("Exceeds"), "raw iceoryx2 error: {err}");
}

#[test]
fn eight_monitors_leave_status_and_inject_working_and_a_full_service_names_its_limit() {
    let ns = unique_namespace("cli");
    let mut d = Daemons::default();
    d.board(&ns, &[]);
    wait_for_board(&ns);

    // 8 live monitors, each counting the snapshots it printed.
    let mut lines = Vec::new();
    let mut monitor_pids = Vec::new();
    for _ in 0..MONITORS {
        let mut child = Command::new(env!("CARGO_BIN_EXE_vic"))
            .args(["monitor", "--namespace", &ns, "--interval-s", "0.1"])
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let out = child.stdout.take().unwrap();
        let n = Arc::new(AtomicUsize::new(0));
        let seen = n.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                if line.starts_with("mode=") {
                    seen.fetch_add(1, Ordering::Relaxed);
                }
            }
        });
        monitor_pids.push(child.id());
        d.children.push(child);
        lines.push(n);
    }
    // Waits until monitor k has shown more than `shown[k]` snapshots.
    let all_showing = |shown: &[usize]| {
        let t0 = Instant::now();
        while lines
            .iter()
            .zip(shown)
            .any(|(n, s)| n.load(Ordering::Relaxed) <= *s)
        {
            let counts: Vec<usize> = lines.iter().map(|n| n.load(Ordering::Relaxed)).collect();
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "monitors' snapshots: {counts:?}"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    all_showing(&[1; MONITORS]);

    // With 8 monitors attached, status and inject work.
    let s = status(&ns);
    assert!(s.status.success(), "{}", text(&s));
    let s: serde_json::Value = serde_json::from_slice(&s.stdout).unwrap();
    assert!(s["tick"].as_u64().unwrap() > 0);
    let i = inject(&ns);
    assert!(i.status.success(), "{}", text(&i));
    let ack: serde_json::Value = serde_json::from_slice(&i.stdout).unwrap();
    assert!(ack["tick"].as_u64().unwrap() > 0, "{ack}");

    // The monitors hold no disturbance publisher: all of them are free for senders. Take every
    // one (hostile senders in this process); then vic inject is refused by name and number.
    let senders: Vec<ToolPorts> = (0..MAX_PUBLISHERS)
        .map(|k| ToolPorts::open(&ns).unwrap_or_else(|e| panic!("sender {k}: {e}")))
        .collect();
    let me = std::process::id().to_string();
    let full =
        format!("{MAX_PUBLISHERS} of {MAX_PUBLISHERS} publishers of service vic/disturbance");
    assert_refused(&inject(&ns), &[&ns, &full, "vic-inject pid", &me]);
    // ... while status and the monitors carry on.
    let s = status(&ns);
    assert!(s.status.success(), "{}", text(&s));
    drop(senders);
    let i = inject(&ns);
    assert!(i.status.success(), "after the senders left: {}", text(&i));

    // Observers share the telemetry subscribers: fill what the 8 monitors left.
    let mut observers = Vec::new();
    let refusal = loop {
        match ObserverPorts::open(&ns) {
            Ok(o) => observers.push(o),
            Err(e) => break e,
        }
        assert!(observers.len() <= MAX_SUBSCRIBERS, "no limit reached");
    };
    assert_eq!(observers.len(), MAX_SUBSCRIBERS - MONITORS, "{refusal}");
    match &refusal {
        TransportError::TooManyPorts {
            kind, in_use, max, ..
        } => {
            assert_eq!(*kind, PortKind::Subscriber, "{refusal}");
            assert_eq!((*in_use, *max), (MAX_SUBSCRIBERS, MAX_SUBSCRIBERS));
        }
        e => panic!("expected a full service, got {e}"),
    }
    let full =
        format!("{MAX_SUBSCRIBERS} of {MAX_SUBSCRIBERS} subscribers of service vic/telemetry");
    let one_monitor = monitor_pids[0].to_string();
    let o = status(&ns);
    assert_refused(&o, &[&full, "vic-observer pids", &one_monitor, &me]);
    eprintln!("{}", String::from_utf8_lossy(&o.stderr));
    drop(observers);
    let s = status(&ns);
    assert!(s.status.success(), "after the observers left: {}", text(&s));

    // Every monitor kept running through all of it and still shows fresh snapshots.
    let before: Vec<usize> = lines.iter().map(|n| n.load(Ordering::Relaxed)).collect();
    all_showing(&before);
    for c in &mut d.children[1..] {
        assert!(c.try_wait().unwrap().is_none(), "a monitor ended");
    }
}
