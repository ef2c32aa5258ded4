//! What `vic status` and `vic monitor` tell about a real board: the messages it lost before
//! seeing them (`dropped_messages`, from gaps in a sender's sequence numbers that this test
//! chooses), and a board that is alive but stopped (SIGSTOP) is named as such with its pid,
//! not as "no board".

use crate::common;

use common::cli::{status, text, vic, wait_for_board};
use common::daemons::{Daemons, unique_namespace};
use serde_json::Value;
use std::time::{Duration, Instant};
use vic_rt::transport::{Disturbance, DisturbanceKind, Header, ToolPorts, monotonic_ns};

#[test]
fn status_and_monitor_show_the_messages_lost_in_sequence_gaps() {
    let ns = unique_namespace("drop");
    let mut d = Daemons::default();
    d.board(&ns, &[]);
    wait_for_board(&ns);
    let tool = ToolPorts::open(&ns).unwrap();
    // One session of our own: 1, 2, 10, 11, 30 misses 3..=9 and 12..=29, 7 + 18 = 25.
    let session = 0x5eed_0007;
    let seqs = [1u64, 2, 10, 11, 30];
    let expected = 25;
    for seq in seqs {
        tool.publish_disturbance(&Disturbance {
            header: Header::in_session(session, seq, monotonic_ns()),
            kind: DisturbanceKind::Noise as u32,
            value: 1.0,
            ..Default::default()
        })
        .unwrap();
        std::thread::sleep(Duration::from_millis(5));
    }
    let t0 = Instant::now();
    let v = loop {
        let o = status(&ns);
        assert!(o.status.success(), "{}", text(&o));
        let v: Value = serde_json::from_slice(&o.stdout).unwrap();
        if v["dropped_messages"].as_u64() >= Some(expected) {
            break v;
        }
        assert!(t0.elapsed() < Duration::from_secs(10), "status: {v}");
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(v["dropped_messages"].as_u64(), Some(expected), "{v}");
    let o = vic(&["status", "--namespace", &ns, "--timeout-s", "3"]);
    let shown = String::from_utf8_lossy(&o.stdout);
    assert!(
        shown
            .lines()
            .any(|l| l.starts_with("dropped messages") && l.contains(" 25 ")),
        "{shown}"
    );
    let o = vic(&[
        "monitor",
        "--namespace",
        &ns,
        "--count",
        "1",
        "--interval-s",
        "0.2",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains(" dropped=25 "),
        "{}",
        text(&o)
    );
}

#[test]
fn status_names_a_stopped_board_with_its_pid_instead_of_no_board() {
    let ns = unique_namespace("stop");
    let mut d = Daemons::default();
    let board = d.board(&ns, &[]);
    wait_for_board(&ns);
    let pid = d.pid(board);
    // SAFETY: kill(2) on a child we spawned and have not reaped.
    unsafe { libc::kill(pid, libc::SIGSTOP) };
    let o = vic(&["status", "--namespace", &ns, "--timeout-s", "0.5"]);
    // SAFETY: as above.
    unsafe { libc::kill(pid, libc::SIGCONT) };
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(
        err.contains(&format!("vic-board pid {pid}) is not responding"))
            && err.contains("stopped (SIGSTOP"),
        "{}",
        text(&o)
    );
    assert!(!err.contains("start one"), "{}", text(&o));
    // Resumed, it answers again.
    let o = status(&ns);
    assert!(o.status.success(), "after SIGCONT: {}", text(&o));
}
