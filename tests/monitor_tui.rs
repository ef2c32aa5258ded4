//! `vic monitor` in a real terminal (issue 15, item 4): a tmux pane of its own server runs the live
//! view against a live `vic-board` in a namespace of its own. The pane shows the banner, the
//! joints' plots with data, a pushed pulse acknowledged by the board and counted; `q` exits 0 and
//! gives the terminal back (primary screen, canonical mode). Skipped, with the reason printed,
//! where tmux is not installed.

use crate::common;

use common::daemons::{Daemons, unique_namespace};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

/// A tmux server of this test's own (its socket named after the namespace), killed on drop: the
/// test never touches another tmux server or session.
struct Tmux {
    socket: String,
}

impl Tmux {
    fn run(&self, args: &[&str]) -> Output {
        Command::new("tmux")
            .args(["-L", &self.socket])
            .args(args)
            .output()
            .expect("tmux runs")
    }
    fn capture(&self) -> String {
        String::from_utf8_lossy(&self.run(&["capture-pane", "-p", "-t", "mon"]).stdout).into()
    }
    /// The pane once `ok` holds for it, or a failure with the last capture.
    fn wait_for(&self, what: &str, ok: impl Fn(&str) -> bool) -> String {
        let t0 = Instant::now();
        loop {
            let pane = self.capture();
            if ok(&pane) {
                return pane;
            }
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "{what} not seen; the pane:\n{pane}"
            );
            std::thread::sleep(Duration::from_millis(100));
        }
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        let _ = self.run(&["kill-server"]);
    }
}

fn status_json(ns: &str) -> Option<serde_json::Value> {
    let o = Command::new(env!("CARGO_BIN_EXE_vic"))
        .args(["status", "--namespace", ns, "--json", "--timeout-s", "2"])
        .output()
        .unwrap();
    o.status
        .success()
        .then(|| serde_json::from_slice(&o.stdout).unwrap())
}

#[test]
fn the_live_view_draws_pushes_and_quits_cleanly_in_a_real_terminal() {
    if Command::new("tmux").arg("-V").output().is_err() {
        eprintln!("skipped: tmux is not installed (the live view needs a real terminal)");
        return;
    }
    let ns = unique_namespace("tui");
    let mut d = Daemons::default();
    d.board(&ns, &[]);
    let t0 = Instant::now();
    while status_json(&ns).is_none() {
        assert!(t0.elapsed() < Duration::from_secs(20), "no board");
    }

    let tmux = Tmux {
        socket: format!("vic-test-{ns}"),
    };
    // After the monitor: its exit code and whether the terminal is back in canonical mode.
    let script = format!(
        "{} monitor --namespace {ns} --pulse-nm 1.5 --pulse-ms 60; echo EXIT=$?; \
         stty -a | tr ' ' '\\n' | grep -x -- '-*icanon'; sleep 120",
        env!("CARGO_BIN_EXE_vic")
    );
    let o = tmux.run(&[
        "new-session",
        "-d",
        "-s",
        "mon",
        "-x",
        "120",
        "-y",
        "40",
        &script,
    ]);
    assert!(o.status.success(), "tmux: {o:?}");
    let alternate = || {
        let o = tmux.run(&["display-message", "-p", "-t", "mon", "#{alternate_on}"]);
        String::from_utf8_lossy(&o.stdout).trim().to_string()
    };

    // The banner, a joint's label, and plots with data (braille dots).
    let pane = tmux.wait_for("the banner, joint 1 and plotted data", |p| {
        p.contains("IDLE")
            && p.contains("joint 1")
            && p.chars().any(|c| c > '\u{2800}' && c <= '\u{28ff}')
    });
    assert!(pane.contains(&format!("namespace \"{ns}\"")), "{pane}");
    assert_eq!(alternate(), "1", "the view is not on the alternate screen");

    // p: a pulse of the configured size, acknowledged by the board and counted.
    tmux.run(&["send-keys", "-t", "mon", "p"]);
    let pane = tmux.wait_for("the pulse acknowledged", |p| {
        p.contains("pulses sent 1, acknowledged 1")
    });
    assert!(pane.contains("pulse +1.50 N m, joint 1, 60 ms"), "{pane}");
    eprintln!("the live view after a pulse:\n{pane}");
    // The board agrees that it applied a disturbance.
    let s = status_json(&ns).expect("the board answers");
    assert!(s["last_disturbance_seq"].as_u64().unwrap() > 0, "{s}");

    // q: exit 0, the primary screen back, canonical mode back (not "-icanon").
    tmux.run(&["send-keys", "-t", "mon", "q"]);
    let pane = tmux.wait_for("the monitor's exit", |p| p.contains("EXIT="));
    assert!(pane.contains("EXIT=0"), "{pane}");
    let pane = tmux.wait_for("the terminal mode", |p| p.contains("icanon"));
    assert!(
        pane.lines().any(|l| l.trim() == "icanon"),
        "raw mode left on: {pane}"
    );
    assert_eq!(alternate(), "0", "still on the alternate screen");
    assert!(
        !pane.contains("pulses sent"),
        "the view was not cleared: {pane}"
    );
}
