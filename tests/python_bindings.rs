//! The Python package `vic` (the wheel of crates/vic-py, built by maturin) against this build's
//! `vic` command line: python/tests/bindings, run by pytest in the interpreter named in
//! `VIC_PYTHON` with the wheel installed (`.ci/run` builds it and installs it into its venv),
//! checks that `vic.plan`, `vic.simulate` and `vic.sweep_latency` give the command line's numbers
//! to the last bit, that `vic.read_mcap` reads what was written, and that bad input of every
//! kind raises a Python exception with a clear message (a panic inside vic too).
//!
//! Without `VIC_PYTHON`, or without the wheel in it, the test says why it skips (outside CI
//! only).

use std::path::Path;
use std::process::Command;

/// The interpreter with the package installed, or None (skip) outside CI.
fn python_with_vic() -> Option<String> {
    let in_ci = std::env::var_os("CI").is_some();
    let Ok(python) = std::env::var("VIC_PYTHON") else {
        assert!(
            !in_ci,
            "CI must set VIC_PYTHON (a Python with the vic wheel and pytest)"
        );
        eprintln!(
            "VIC_PYTHON not set: the Python bindings' tests are skipped (see python/README.md \
             to build the wheel and point VIC_PYTHON at a python that has it and pytest)"
        );
        return None;
    };
    let probe = Command::new(&python)
        .args(["-c", "import vic, vic._vic, pytest"])
        .current_dir(std::env::temp_dir())
        .output()
        .unwrap();
    if !probe.status.success() {
        let why = String::from_utf8_lossy(&probe.stderr);
        assert!(
            !in_ci,
            "CI's {python} has no vic wheel or no pytest (.ci/run installs them): {why}"
        );
        eprintln!("{python} cannot import vic and pytest, the bindings' tests are skipped: {why}");
        return None;
    }
    Some(python)
}

#[test]
fn the_python_package_gives_the_command_lines_numbers_and_clear_errors() {
    let Some(python) = python_with_vic() else {
        return;
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // No PYTHONPATH: python/vic without its extension module must not hide the installed wheel.
    let out = Command::new(&python)
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
        .arg(root.join("python/tests/bindings"))
        .env_remove("PYTHONPATH")
        .env("VIC_BIN", env!("CARGO_BIN_EXE_vic"))
        .current_dir(std::env::temp_dir())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    eprintln!("pytest python/tests/bindings:\n{stdout}");
    assert!(
        out.status.success(),
        "pytest failed:\n{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // In CI every test ran: none was skipped for a missing VIC_BIN or pandas.
    assert!(stdout.contains(" passed"), "{stdout}");
    if std::env::var_os("CI").is_some() {
        assert!(!stdout.contains("skipped"), "{stdout}");
    }
}
