//! Running `vic` from a test and showing what it said.

use std::process::{Command, Output};

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
