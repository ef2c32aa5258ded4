//! `vic status` lists the namespace's processes (issue 14, finding 5: a "too many" error must
//! say who holds the slots): with a real board and two real `vic monitor`s, `vic status --json`
//! lists each with its pid and role, a SIGKILLed monitor as dead, and when the board is gone the
//! error still lists who is left.

use crate::common;

use common::daemons::{Daemons, unique_namespace};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn status(ns: &str, json: bool) -> (u32, Output) {
    let mut c = Command::new(env!("CARGO_BIN_EXE_vic"));
    c.args(["status", "--namespace", ns, "--timeout-s", "3"]);
    if json {
        c.arg("--json");
    }
    let child = c
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    (pid, child.wait_with_output().unwrap())
}

/// (name, pid, state) of every node `vic status --json` lists.
fn nodes(v: &serde_json::Value) -> Vec<(String, u32, String)> {
    // An empty list is left out of the JSON.
    v["nodes"]
        .as_array()
        .map(Vec::as_slice)
        .unwrap_or_default()
        .iter()
        .map(|n| {
            (
                n["name"].as_str().unwrap().to_string(),
                n["pid"].as_u64().unwrap() as u32,
                n["state"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

fn has(list: &[(String, u32, String)], name: &str, pid: u32, state: &str) -> bool {
    list.iter()
        .any(|(n, p, s)| n == name && *p == pid && s == state)
}

#[test]
fn status_lists_the_board_and_the_monitors_with_their_pids() {
    let ns = unique_namespace("sn");
    let mut d = Daemons::default();
    let board = d.board(&ns, &[]);
    let board_pid = d.pid(board) as u32;
    let mut monitors = Vec::new();
    for _ in 0..2 {
        let child = Command::new(env!("CARGO_BIN_EXE_vic"))
            .args(["monitor", "--namespace", &ns, "--interval-s", "0.1"])
            .stdout(Stdio::null())
            .spawn()
            .unwrap();
        monitors.push(child.id());
        d.children.push(child);
    }
    // Until the board answers and both monitors hold their nodes.
    let t0 = Instant::now();
    let (own_pid, list) = loop {
        let (pid, o) = status(&ns, true);
        if o.status.success() {
            let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            let list = nodes(&v);
            if monitors
                .iter()
                .all(|m| has(&list, "vic-observer", *m, "alive"))
            {
                break (pid, list);
            }
        }
        assert!(t0.elapsed() < Duration::from_secs(30), "{o:?}");
        std::thread::sleep(Duration::from_millis(100));
    };
    eprintln!("nodes: {list:?}");
    assert!(list.len() >= 3, "{list:?}");
    assert!(has(&list, "vic-board", board_pid, "alive"), "{list:?}");
    // Nothing else: the status tool lists the others (not itself).
    let known = [board_pid, monitors[0], monitors[1]];
    assert!(!list.iter().any(|(_, p, _)| *p == own_pid), "{list:?}");
    assert!(list.iter().all(|(_, p, _)| known.contains(p)), "{list:?}");

    // The text form names them too.
    let (_, o) = status(&ns, false);
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains(&format!("vic-board pid {board_pid}"))
            && text.contains(&format!("vic-observer pid {}", monitors[1])),
        "{text}"
    );

    // A monitor killed: listed as dead by the next status (which then cleans it up).
    // SAFETY: kill(2) on a child this test started.
    unsafe { libc::kill(monitors[0] as i32, libc::SIGKILL) };
    d.children[1].wait().unwrap();
    let (_, o) = status(&ns, true);
    assert!(o.status.success(), "{o:?}");
    let list = nodes(&serde_json::from_slice(&o.stdout).unwrap());
    assert!(has(&list, "vic-observer", monitors[0], "dead"), "{list:?}");
    assert!(has(&list, "vic-observer", monitors[1], "alive"), "{list:?}");

    // The board killed: status fails (exit 1, no board) and still says who is left.
    d.signal_and_wait(board, libc::SIGKILL);
    let (_, o) = status(&ns, true);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("no board")
            && err.contains(&format!("vic-observer pid {}", monitors[1]))
            && err.contains(&format!("vic-board pid {board_pid} (dead)")),
        "{err}"
    );
}
