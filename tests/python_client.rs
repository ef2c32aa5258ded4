//! The Python client (`python/vic_client`, over iceoryx2's official Python bindings) against
//! docs/PROTOCOL.md and a real board: python/tests/test_client.py, run by the interpreter named
//! in `VIC_PYTHON` (`.ci/run` makes a venv with iceoryx2 0.10.0, numpy and mcap), checks
//!
//! - `doc`: the ctypes layouts (every offset, size and type), type names, enumerations,
//!   constants and service settings equal the document's tables;
//! - `live`, with a board recording to MCAP in a namespace of its own: states with increasing
//!   ticks on the 1 kHz schedule (every period a tick or a counted miss); field, noise, reset, pulse and load acknowledged in the state; with no
//!   central process the reset arm stays put in the safe hold, a pulse moves it and it springs
//!   back, every torque the hold law of the previous state; the telemetry agrees; an oversized
//!   pulse is counted as rejected, not acknowledged;
//! - `compare`, after the board stopped: every state the client received equals the board's own
//!   record of that tick (its MCAP file, and the CSV `vic convert` made of it); a plan file loads;
//!   with the wheel of the package `vic` installed, `vic.read_mcap` reads that MCAP file to the
//!   client's values.
//!
//! Without `VIC_PYTHON` the test says why it skips (outside CI only).

use crate::common;

use common::daemons::{Daemons, sooc_plan, unique_namespace};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The interpreter to use, or None (skip) outside CI.
fn python() -> Option<String> {
    match std::env::var("VIC_PYTHON") {
        Ok(p) => Some(p),
        Err(_) => {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI must set VIC_PYTHON (a Python with iceoryx2==0.10.0, numpy and mcap)"
            );
            eprintln!(
                "VIC_PYTHON not set: the Python client test is skipped (make a venv with \
                 `pip install iceoryx2==0.10.0 numpy mcap ./python` and point VIC_PYTHON at its \
                 python)"
            );
            None
        }
    }
}

/// Runs one phase of test_client.py (the package from this checkout first on the path), at
/// most `limit`; its output is shown, and a failed phase fails the test.
fn run_phase(python: &str, args: &[&Path], limit: Duration) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut child = Command::new(python)
        .arg(root.join("python/tests/test_client.py"))
        .args(args)
        .env("PYTHONPATH", root.join("python"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + limit;
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "test_client.py {:?} took over {limit:?}:\n{}{}",
                args[0],
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!("test_client.py {}:\n{stdout}", args[0].display());
    assert!(
        out.status.success(),
        "test_client.py {} failed:\n{stdout}{}",
        args[0].display(),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains(" passed, 0 failed"), "{stdout}");
}

#[test]
fn the_python_client_follows_the_protocol_and_matches_the_boards_record() {
    let Some(python) = python() else { return };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    run_phase(
        &python,
        &[Path::new("doc"), &root.join("docs/PROTOCOL.md")],
        Duration::from_secs(60),
    );

    let ns = unique_namespace("py");
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let file = |ext: &str| -> PathBuf { dir.join(format!("{ns}.{ext}")) };
    let (mcap, csv, states) = (file("mcap"), file("csv"), file("npz"));
    let mut d = Daemons::default();
    let board = d.board(&ns, &["--record", mcap.to_str().unwrap()]);
    run_phase(
        &python,
        &[Path::new("live"), Path::new(&ns), &states],
        Duration::from_secs(120),
    );
    let out = d.signal_and_wait(board, libc::SIGTERM);
    assert!(out.status.success(), "the board exited with {}", out.status);
    let stats: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        stats["dropped"].as_u64(),
        Some(0),
        "the board's record is whole"
    );
    drop(d);
    assert!(
        vic_rt::transport::namespace_files(&ns).is_empty(),
        "the namespace left files: {:?}",
        vic_rt::transport::namespace_files(&ns)
    );

    let out = Command::new(env!("CARGO_BIN_EXE_vic"))
        .arg("convert")
        .arg(&mcap)
        .arg("--csv")
        .arg(&csv)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    run_phase(
        &python,
        &[Path::new("compare"), &states, &mcap, &csv, &sooc_plan()],
        Duration::from_secs(120),
    );
    board_recording_through_the_package(&python, &mcap);
    for f in [&mcap, &csv, &states] {
        std::fs::remove_file(f).unwrap();
    }
}

/// The board's recording read by the package `vic` (`vic.read_mcap`, its own MCAP reader in
/// crates/vic-py) equals the client's reading of it: python/tests/bindings/board_recording.py,
/// run without PYTHONPATH so that the installed wheel is imported (CI installs it; elsewhere a
/// Python without it skips this part, saying so).
fn board_recording_through_the_package(python: &str, mcap: &Path) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let run = |args: &[&std::ffi::OsStr]| {
        Command::new(python)
            .args(args)
            .env_remove("PYTHONPATH")
            .current_dir(std::env::temp_dir())
            .output()
            .unwrap()
    };
    let probe = run(&["-c".as_ref(), "import vic._vic".as_ref()]);
    if !probe.status.success() {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI's {python} has no vic wheel: {}",
            String::from_utf8_lossy(&probe.stderr)
        );
        eprintln!("{python} has no vic wheel: vic.read_mcap of the board's record is not checked");
        return;
    }
    let script = root.join("python/tests/bindings/board_recording.py");
    let out = run(&[script.as_os_str(), mcap.as_os_str()]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!("board_recording.py:\n{stdout}");
    assert!(
        out.status.success() && stdout.contains(" passed, 0 failed"),
        "board_recording.py failed:\n{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
}
