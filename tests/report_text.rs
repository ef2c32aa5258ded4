//! What `vic experiment` and `vic simulate` print, as a reader sees it (issue 65's smaller
//! items): a diverged column says `diverged`, never a number glued to it; the policy by its flag
//! name and the ellipse as numbers, not Rust's debug output; the iCub costs beside the paper's
//! with a word on the scale; `--latency-ms` naming only policies that exist.

use crate::common::cli::{text, vic};
use std::path::{Path, PathBuf};

/// A fresh directory under the system temp dir, removed on drop.
struct TempDir(PathBuf);

impl TempDir {
    fn new(tag: &str) -> TempDir {
        let dir = std::env::temp_dir().join(format!("vic-report-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn config(file: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(file)
        .display()
        .to_string()
}

fn stdout_of(args: &[&str]) -> String {
    let out = vic(args);
    assert!(out.status.success(), "{args:?}: {}", text(&out));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn a_diverged_column_says_diverged_in_a_column_of_its_own() {
    let dir = TempDir::new("fig2");
    let out_dir = dir.0.display().to_string();
    let out = stdout_of(&["experiment", "fig2", "--trials", "3", "--out-dir", &out_dir]);
    // Fig. 2's delayed feedback diverges in every trial.
    let row = out
        .lines()
        .find(|l| l.starts_with("delayed_feedback"))
        .unwrap_or_else(|| panic!("no delayed_feedback row:\n{out}"));
    let cells: Vec<&str> = row.split_whitespace().collect();
    assert!(cells.contains(&"diverged"), "{row}");
    for glued in ["degdiverged", "diverged deg", "mmdiverged", "diverged mm"] {
        assert!(!out.contains(glued), "{glued:?} in\n{out}");
    }
}

#[test]
fn the_icub_costs_stand_beside_the_papers_with_a_word_on_the_scale() {
    let dir = TempDir::new("icub");
    let out_dir = dir.0.display().to_string();
    let out = stdout_of(&["experiment", "icub", "--trials", "3", "--out-dir", &out_dir]);
    let line = out
        .lines()
        .find(|l| l.contains("0.29") && l.contains("0.41"))
        .unwrap_or_else(|| panic!("no line with the paper's costs:\n{out}"));
    assert!(
        line.contains("scale") && line.contains("ratio"),
        "the paper's costs without a word on the scale: {line}"
    );
}

#[test]
fn simulate_prints_the_policy_by_its_flag_name_and_the_ellipse_as_numbers() {
    let dir = TempDir::new("simulate");
    let plan = dir.0.join("plan.json").display().to_string();
    let scenario = config("single_joint_delay.toml");
    stdout_of(&["plan", "--config", &scenario, "--out", &plan]);
    let out = stdout_of(&[
        "simulate", "--config", &scenario, "--plan", &plan, "--trials", "3",
    ]);
    assert!(out.contains("policy open-loop"), "{out}");
    assert!(!out.contains("OpenLoop"), "{out}");
    let ellipse = out
        .lines()
        .find(|l| l.contains("ellipse"))
        .unwrap_or_else(|| panic!("no ellipse line:\n{out}"));
    assert!(
        !ellipse.contains('[') && !ellipse.contains('"'),
        "{ellipse}"
    );
}

#[test]
fn the_latency_help_names_only_policies_that_exist() {
    let help = stdout_of(&["simulate", "--help"]);
    let values: Vec<&str> = help
        .lines()
        .filter_map(|l| l.trim().strip_prefix("- ")?.split(':').next())
        .collect();
    assert!(values.contains(&"naive-delayed"), "{values:?}");
    let latency = help
        .split("--latency-ms <MS>")
        .nth(1)
        .and_then(|s| s.split("\n\n").next())
        .unwrap_or_else(|| panic!("no --latency-ms in\n{help}"));
    let named: Vec<&str> = latency
        .split("--policy ")
        .skip(1)
        .filter_map(|s| s.split([' ', ',', '[', ')']).next())
        .collect();
    assert!(!named.is_empty(), "{latency}");
    for name in named {
        assert!(
            values.contains(&name),
            "--latency-ms names --policy {name}: {values:?}"
        );
    }
}
