//! A plan file reads back as it was written, whatever the solver stopped on: a plan stopped at
//! its iteration limit holds figures that are `+∞` by design (SOOC's predicted decrease when the
//! last model was not the exact one), which JSON writes as `null`.

use std::path::Path;
use std::process::Command;
use vic_plan::method::Method;
use vic_plan::plan::plan;
use vic_plan::plan_file::PlanFile;
use vic_plan::scenario::Scenario;

fn config(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(name)
}

/// The first SOOC step of the divergent arm is a Gauss–Newton one, so a plan cut there has no
/// exact model's prediction: the file says `null`, and reads back as `+∞` with everything else
/// equal to the bit.
#[test]
fn a_plan_stopped_at_its_iteration_limit_reads_back_equal() {
    let overrides = ["solver.max_iterations=1".to_string()];
    let s = Scenario::load(&config("two_link_divergent.toml"), &overrides).expect("loads");
    let written = plan(&s, Method::Sooc, None).expect("plans");
    let optimality = written
        .summary
        .optimality
        .expect("a SOOC plan has its criterion");
    assert!(!written.summary.converged);
    assert_eq!(optimality.predicted_decrease, f64::INFINITY);
    let text = serde_json::to_string(&written).unwrap();
    assert!(text.contains("\"predicted_decrease\":null"), "{text:.0}");
    let read: PlanFile = serde_json::from_str(&text).expect("the file reads back");
    assert_eq!(read.summary, written.summary);
    assert_eq!(read.u, written.u);
    assert_eq!(read.x, written.x);
}

/// The same through the binaries: `vic plan --out` at the iteration limit, then `vic simulate`
/// on that file (it said "not a plan file" before).
#[test]
fn vic_simulate_runs_a_plan_stopped_at_its_iteration_limit() {
    let dir = std::env::temp_dir().join(format!("vic-plan-file-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("plan.json");
    let vic = env!("CARGO_BIN_EXE_vic");
    let scenario = config("two_link_divergent.toml");
    let planned = Command::new(vic)
        .args([
            "plan",
            "--method",
            "sooc",
            "--set",
            "solver.max_iterations=1",
        ])
        .arg("--config")
        .arg(&scenario)
        .arg("--out")
        .arg(&file)
        .output()
        .unwrap();
    assert!(planned.status.success(), "{planned:?}");
    let simulated = Command::new(vic)
        .args(["simulate", "--trials", "2", "--json"])
        .arg("--config")
        .arg(&scenario)
        .arg("--plan")
        .arg(&file)
        .output()
        .unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(
        simulated.status.success(),
        "{}",
        String::from_utf8_lossy(&simulated.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&simulated.stdout).unwrap();
    assert_eq!(report["trials"], 2);
}

/// A plan file whose arrays have the wrong shape (one gains row short, one state row short) is
/// refused on load by `vic simulate` with exit code 2 and a message naming the file and the row
/// (it panicked with an index out of bounds, exit 101).
#[test]
fn vic_simulate_refuses_a_plan_file_of_the_wrong_shape() {
    let dir = std::env::temp_dir().join(format!("vic-plan-shape-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scenario = config("two_link_divergent.toml");
    let overrides = ["solver.max_iterations=1".to_string()];
    let s = Scenario::load(&scenario, &overrides).expect("loads");
    let written = plan(&s, Method::Sooc, None).expect("plans");
    let good = serde_json::to_value(&written).unwrap();
    type Spoil = fn(&mut serde_json::Value);
    let cases: [(&str, Spoil, &str); 3] = [
        (
            "gains",
            |v| {
                v["gains"][5][1].as_array_mut().unwrap().pop();
            },
            "gains[5] row 1 has",
        ),
        (
            "x",
            |v| {
                v["x"][3].as_array_mut().unwrap().pop();
            },
            "x[3] has",
        ),
        (
            "u",
            |v| {
                v["u"].as_array_mut().unwrap().pop();
            },
            "x needs one more",
        ),
    ];
    for (name, spoil, expected) in cases {
        let mut v = good.clone();
        spoil(&mut v);
        let file = dir.join(format!("{name}.json"));
        std::fs::write(&file, serde_json::to_string(&v).unwrap()).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_vic"))
            .args(["simulate", "--trials", "2", "--json"])
            .arg("--config")
            .arg(&scenario)
            .arg("--plan")
            .arg(&file)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {stderr}");
        assert!(
            stderr.contains(&file.display().to_string()) && stderr.contains(expected),
            "{name}: {stderr}"
        );
        assert!(!stderr.contains("panicked"), "{name}: {stderr}");
    }
    // The unspoilt plan still loads.
    let file = dir.join("good.json");
    std::fs::write(&file, serde_json::to_string(&good).unwrap()).unwrap();
    PlanFile::read(&file).expect("a plan as written reads back");
    std::fs::remove_dir_all(&dir).unwrap();
}
