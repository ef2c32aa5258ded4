//! The three binaries' error convention, on the real executables: bad input (a file, a key, a
//! flag) exits 2 with `PROGRAM: error:` and a message that names what is wrong; a failure of the
//! run (no board to talk to) exits 1.

use std::process::{Command, Output};

fn run(bin: &str, args: &[&str]) -> Output {
    Command::new(bin)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .args(args)
        .output()
        .unwrap()
}

/// Asserts the exit code and that stderr starts with `PROGRAM: error:` and names `what`.
fn assert_error(out: &Output, code: i32, program: &str, what: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(code), "{stderr}");
    assert!(
        stderr.starts_with(&format!("{program}: error: ")),
        "no '{program}: error:' prefix: {stderr}"
    );
    assert!(stderr.contains(what), "'{what}' not in: {stderr}");
}

const VIC: &str = env!("CARGO_BIN_EXE_vic");
const BOARD: &str = env!("CARGO_BIN_EXE_vic-board");
const PLANNER: &str = env!("CARGO_BIN_EXE_vic-planner");

#[test]
fn a_missing_scenario_file_is_named_by_every_binary() {
    let missing = "/nonexistent/scenario.toml";
    for (bin, program, args) in [
        (VIC, "vic", &["plan", "--config", missing][..]),
        (VIC, "vic", &["demo", "--config", missing]),
        (BOARD, "vic-board", &["--config", missing]),
        (PLANNER, "vic-planner", &["--config", missing]),
    ] {
        assert_error(&run(bin, args), 2, program, missing);
    }
}

#[test]
fn a_bad_override_names_its_key() {
    // A value of the wrong type, and values of the right type that the solver cannot use:
    // each named with its key.
    for (set, key) in [
        ("task.dt=abc", "dt"),
        (
            "solver.third_derivatives_below=0",
            "[solver] third_derivatives_below",
        ),
        (
            "solver.third_derivatives_below=-1e-2",
            "[solver] third_derivatives_below",
        ),
        (
            "solver.third_derivatives_below=nan",
            "[solver] third_derivatives_below",
        ),
    ] {
        let args = [
            "plan",
            "--config",
            "config/two_link_reach.toml",
            "--set",
            set,
        ];
        assert_error(&run(VIC, &args), 2, "vic", key);
    }
    let out = run(BOARD, &["--set", "nosuchkey"]);
    assert_error(&out, 2, "vic-board", "--set nosuchkey");
}

#[test]
fn bad_flags_are_the_users_input() {
    assert_error(
        &run(BOARD, &["--rate-hz", "0"]),
        2,
        "vic-board",
        "--rate-hz",
    );
    assert_error(
        &run(BOARD, &["--namespace", "no/slash"]),
        2,
        "vic-board",
        "no/slash",
    );
    assert_error(
        &run(PLANNER, &["--trials", "0"]),
        2,
        "vic-planner",
        "--trials",
    );
    assert_error(
        &run(VIC, &["demo", "--latency-ms", "3"]),
        2,
        "vic",
        "--latency-ms 3",
    );
    // The sweep's typed error: a latency off the plan grid is the user's, found after planning.
    assert_error(
        &run(
            VIC,
            &[
                "sweep",
                "latency",
                "--config",
                "config/single_joint_delay.toml",
                "--latencies",
                "5",
                "--strategies",
                "predictor",
                "--trials",
                "2",
                "--json",
            ],
        ),
        2,
        "vic",
        "latency 5 ms",
    );
    assert_error(
        &run(VIC, &["inject", "pulse", "--torque", "1,2,3"]),
        2,
        "vic",
        "--torque",
    );
    assert_error(
        &run(VIC, &["monitor", "--interval-s", "0.01"]),
        2,
        "vic",
        "--interval-s",
    );
}

#[test]
fn no_board_to_talk_to_is_a_failure_not_bad_input() {
    let out = run(
        VIC,
        &[
            "status",
            "--namespace",
            "exitcodes_nobody",
            "--timeout-s",
            "0.2",
        ],
    );
    assert_error(&out, 1, "vic", "no board in namespace \"exitcodes_nobody\"");
}

#[test]
fn too_few_trials_say_how_many_and_why() {
    // clap's range parser printed `not in 3..18446744073709551615`; the message says the range,
    // the minimum and the reason.
    for (args, minimum) in [
        (
            &["experiment", "fig1", "--trials", "2"][..],
            "at least 3 trials",
        ),
        (&["simulate", "--trials", "1"], "at least 2 trials"),
        (&["sweep", "latency", "--trials", "1"], "at least 2 trials"),
    ] {
        let out = run(VIC, args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(minimum), "{args:?}: {stderr}");
        assert!(!stderr.contains("18446744073709551615"), "{stderr}");
    }
    let out = run(VIC, &["experiment", "fig1", "--trials", "many"]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.starts_with("vic: error: ")
            && stderr.contains("not a whole number in the range 3 to"),
        "{stderr}"
    );
}

/// From a folder without `config/` (an installed `vic`), `config/NAME.toml` is the built-in copy
/// of the repository's scenario: the same plan as from the repository; a name that is not one of
/// them is still the user's error.
#[test]
fn from_any_folder_the_scenarios_of_config_are_built_in() {
    let elsewhere = std::env::temp_dir().join(format!("vic-elsewhere-{}", std::process::id()));
    std::fs::create_dir_all(&elsewhere).unwrap();
    let plan = |dir: &std::path::Path, config: &str| {
        Command::new(VIC)
            .current_dir(dir)
            .args(["plan", "--config", config, "--method", "ilqg", "--json"])
            .output()
            .unwrap()
    };
    let summary = |out: &Output| {
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let mut v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        v.as_object_mut().unwrap().remove("solve_ms");
        v
    };
    let repo = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let there = plan(&elsewhere, "config/icub_elbow.toml");
    let here = plan(repo, "config/icub_elbow.toml");
    assert_eq!(summary(&there), summary(&here));
    let missing = plan(&elsewhere, "config/no_such_scenario.toml");
    std::fs::remove_dir_all(&elsewhere).unwrap();
    assert_error(&missing, 2, "vic", "config/no_such_scenario.toml");
}
