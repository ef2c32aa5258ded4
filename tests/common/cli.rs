//! Running `vic` from a test and showing what it said.

use std::process::{Command, Output};
use std::time::{Duration, Instant};

/// `vic ARGS` to the end, its output captured.
pub fn vic(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vic"))
        .args(args)
        .output()
        .unwrap()
}

/// Exit code, stdout and stderr of `o`, for an assertion's message.
pub fn text(o: &Output) -> String {
    format!(
        "exit {:?}\nstdout {}\nstderr {}",
        o.status.code(),
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// `vic status --json` until a board answers (it needs a moment to start).
pub fn wait_for_board(ns: &str) {
    let t0 = Instant::now();
    loop {
        let o = vic(&["status", "--namespace", ns, "--json"]);
        if o.status.success() {
            return;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(20),
            "no board: {}",
            text(&o)
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// `vic status --json` with a 3 s timeout.
pub fn status(ns: &str) -> Output {
    vic(&["status", "--namespace", ns, "--json", "--timeout-s", "3"])
}

/// `vic inject noise --factor 1` (a disturbance that changes nothing) with a 3 s timeout.
pub fn inject(ns: &str) -> Output {
    vic(&[
        "inject",
        "--namespace",
        ns,
        "--json",
        "--timeout-s",
        "3",
        "noise",
        "--factor",
        "1",
    ])
}
