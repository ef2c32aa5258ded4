//! Every scenario planned with its methods: `cargo bench --bench scenarios`.
//!
//! A small hand-written harness (SOOC solves take seconds each, too slow for criterion's
//! sampling): ILQG on every `config/*.toml` (3 runs, mean and min), SOOC on the scenarios its
//! targets name (1 run; `VIC_BENCH_SOOC=all` plans every scenario, `none` skips SOOC), then the
//! solver issue's targets beside the measured figures (the ratios to Crocoddyl come from
//! `scripts/bench_peers.sh`, which runs both in one process tree). Times are `vic plan`'s: the
//! solver's own `solve_ms` (summary) and the whole call's wall time (setup, solve, the
//! summary's rollouts).
//!
//! Filter: `cargo bench --bench scenarios -- divergent` runs the cases whose name contains the
//! word. The results also go to `$CARGO_TARGET_DIR/bench-scenarios.json`, with the machine
//! they ran on.

use std::path::{Path, PathBuf};
use std::time::Instant;
use vic_plan::plan::{Method, plan};
use vic_plan::scenario::Scenario;

#[derive(serde::Serialize)]
struct Case {
    name: String,
    method: &'static str,
    runs: usize,
    iterations: usize,
    converged: bool,
    solve_ms_mean: f64,
    solve_ms_min: f64,
    wall_ms_mean: f64,
    ms_per_iteration: f64,
}

fn config_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("config")
}

fn bench(name: &str, file: &str, overrides: &[&str], method: Method, runs: usize) -> Option<Case> {
    let o: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let s = match Scenario::load(&config_dir().join(file), &o) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{name}: skipped: {e}");
            return None;
        }
    };
    let mut solve = Vec::new();
    let mut wall = Vec::new();
    let mut last = None;
    for _ in 0..runs {
        let t0 = Instant::now();
        match plan(&s, method, None) {
            Ok(p) => {
                wall.push(t0.elapsed().as_secs_f64() * 1e3);
                solve.push(p.summary.solve_ms);
                last = Some(p.summary);
            }
            Err(e) => {
                eprintln!("{name} {}: skipped: {e}", method.name());
                return None;
            }
        }
    }
    let summary = last?;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let case = Case {
        name: name.to_string(),
        method: method.name(),
        runs,
        iterations: summary.iterations,
        converged: summary.converged,
        solve_ms_mean: mean(&solve),
        solve_ms_min: solve.iter().cloned().fold(f64::INFINITY, f64::min),
        wall_ms_mean: mean(&wall),
        ms_per_iteration: mean(&solve) / summary.iterations.max(1) as f64,
    };
    println!(
        "{:<38} {:<5} {:>3} runs {:>5} it {:>5} solve mean {:>10.2} ms  min {:>10.2} ms  {:>8.3} ms/it  wall {:>10.2} ms",
        case.name,
        case.method,
        case.runs,
        case.iterations,
        if case.converged { "conv" } else { "STOP" },
        case.solve_ms_mean,
        case.solve_ms_min,
        case.ms_per_iteration,
        case.wall_ms_mean
    );
    Some(case)
}

fn main() {
    let filter: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let wanted = |name: &str| filter.is_empty() || filter.iter().any(|f| name.contains(f));
    let sooc_mode = std::env::var("VIC_BENCH_SOOC").unwrap_or_default();
    let mut files: Vec<String> = std::fs::read_dir(config_dir())
        .expect("config/ exists")
        .flatten()
        .map(|e| e.file_name().to_string_lossy().to_string())
        .filter(|n| n.ends_with(".toml") && n != "iceoryx2.toml")
        .collect();
    files.sort();
    let sooc_default = [
        "two_link_divergent.toml",
        "two_link_vsa_divergent.toml",
        "icub_elbow.toml",
    ];
    let mut cases = Vec::new();
    // Absolute times are the host's: name it (a VM may move to another CPU between runs).
    let machine = vic::bench::Machine::detect();
    println!("machine: {}", machine.line());
    println!("ILQG on every scenario (3 runs), SOOC on the targeted ones (1 run)");
    for f in &files {
        let stem = f.trim_end_matches(".toml");
        if wanted(stem) {
            cases.extend(bench(stem, f, &[], Method::Ilqg, 3));
        }
    }
    // The planner-core targets' variants.
    let extra: [(&str, &str, &[&str]); 2] = [
        (
            "two_link_reach_box (torque_limit 0.25)",
            "two_link_reach.toml",
            &["actuator.torque_limit=0.25"],
        ),
        (
            "single_joint_delay deterministic",
            "single_joint_delay.toml",
            &["noise.kind=none"],
        ),
    ];
    for (name, f, o) in extra {
        if wanted(name) {
            cases.extend(bench(name, f, o, Method::Ilqg, 3));
        }
    }
    if sooc_mode != "none" {
        for f in &files {
            let stem = f.trim_end_matches(".toml");
            if (sooc_mode == "all" || sooc_default.contains(&f.as_str())) && wanted(stem) {
                cases.extend(bench(stem, f, &[], Method::Sooc, 1));
            }
        }
    }

    let find =
        |name: &str, method: &str| cases.iter().find(|c| c.name == name && c.method == method);
    println!();
    println!(
        "{:<46} {:>14} {:>14} {:>6}",
        "target", "target", "measured", "met"
    );
    // The solver issue's limits. The peers' times and the ratios to them come from
    // `scripts/bench_peers.sh`, measured in its own run: a number copied here would go stale.
    let rows: [(&str, &str, &str, f64, bool); 5] = [
        (
            "two-link torque reach N=100 [ms/iteration]",
            "two_link_reach",
            "ilqg",
            0.05,
            true,
        ),
        (
            "box-constrained reach [ms/solve]",
            "two_link_reach_box (torque_limit 0.25)",
            "ilqg",
            3.0,
            false,
        ),
        (
            "single joint, 200 ms delay [ms/solve]",
            "single_joint_delay",
            "ilqg",
            20.0,
            false,
        ),
        (
            "SOOC type-2 arm [ms/solve]",
            "two_link_divergent",
            "sooc",
            20.0,
            false,
        ),
        (
            "SOOC VSA arm [ms/solve]",
            "two_link_vsa_divergent",
            "sooc",
            100.0,
            false,
        ),
    ];
    let mut targets = Vec::new();
    for (label, name, method, target, per_it) in rows {
        let Some(c) = find(name, method) else {
            continue;
        };
        let v = if per_it {
            c.ms_per_iteration
        } else {
            c.solve_ms_mean
        };
        println!(
            "{label:<46} {:>14} {:>14.3} {:>6}",
            format!("≤ {target}"),
            v,
            if v <= target { "yes" } else { "NO" },
        );
        targets.push(serde_json::json!({
            "target": label, "case": name, "method": method, "limit": target,
            "measured": v, "met": v <= target,
        }));
    }
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("target"));
    let out = target.join("bench-scenarios.json");
    let doc = serde_json::json!({ "machine": machine, "cases": cases, "targets": targets });
    if std::fs::write(&out, doc.to_string()).is_ok() {
        println!("\nwritten {}", out.display());
    }
}
