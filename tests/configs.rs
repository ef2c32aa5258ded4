//! Every scenario in `config/` loads and plans (with its configured method, ILQG unless it says
//! otherwise) to a converged solution.
//!
//! One test per file, so that each scenario reports on its own (and the harness runs them in
//! parallel); a further test fails when a file in `config/` has no test here.

use std::path::{Path, PathBuf};
use vic_plan::method::Method;
use vic_plan::plan::plan;
use vic_plan::plan_file::{PlanSummary, Stop};
use vic_plan::scenario::Scenario;

/// The scenarios, as file stems of `config/*.toml`.
const SCENARIOS: [&str; 12] = [
    "icub_elbow",
    "icub_experiment",
    "single_joint_delay",
    "two_link_curl",
    "two_link_deterministic",
    "two_link_divergent",
    "two_link_divergent_fast_vsa",
    "two_link_divergent_maccepa",
    "two_link_reach",
    "two_link_torque_divergent",
    "two_link_vsa_divergent",
    "two_link_vsa_light_divergent",
];

fn config_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("config")
}

fn check(stem: &str) {
    let path = config_dir().join(format!("{stem}.toml"));
    let scenario = Scenario::load(&path, &[]).unwrap_or_else(|e| panic!("{e}"));
    // The scenario's own method, as `vic plan` uses by default.
    check_with(stem, &scenario, scenario.solver.method);
}

/// The plan reports the values of its method's criterion, and `converged` (and the stop reason)
/// says what they say.
fn check_criterion(stem: &str, method: Method, s: &PlanSummary) {
    match method {
        Method::Ilqg => {
            let c = s
                .convergence
                .unwrap_or_else(|| panic!("{stem}: no ILQG convergence record"));
            assert_eq!(c.met(), s.converged, "{stem}: {c:?} vs converged");
            match s.stop {
                Stop::SmallGradient => assert!(c.gradient_met(), "{stem}: {c:?}"),
                Stop::SmallImprovement => assert!(c.improvement_met(), "{stem}: {c:?}"),
                _ => assert!(!c.met(), "{stem}: stopped {} but {c:?}", s.stop),
            }
            assert!(
                s.optimality.is_none(),
                "{stem}: SOOC figures on an ILQG plan"
            );
        }
        Method::Sooc => {
            let o = s
                .optimality
                .unwrap_or_else(|| panic!("{stem}: no SOOC optimality"));
            assert_eq!(o.met(), s.converged, "{stem}: {o:?} vs converged");
            assert!(
                s.convergence.is_none(),
                "{stem}: ILQG figures on a SOOC plan"
            );
        }
    }
}

fn check_with(stem: &str, scenario: &Scenario, method: Method) {
    let file = plan(scenario, method, None).unwrap_or_else(|e| panic!("{stem}: {e}"));
    let s = &file.summary;
    check_criterion(stem, method, s);
    let steps = scenario.task.steps;
    // The plan file is complete and finite.
    assert_eq!(file.x.len(), steps + 1, "{stem}: states");
    assert_eq!(file.u.len(), steps, "{stem}: controls");
    assert_eq!(file.gains.len(), steps, "{stem}: gains");
    assert!(
        file.x
            .iter()
            .chain(&file.u)
            .flatten()
            .all(|v| v.is_finite()),
        "{stem}: non-finite plan"
    );
    assert!(
        s.cost.is_finite() && s.expected_cost.is_finite(),
        "{stem}: cost {} / expected {}",
        s.cost,
        s.expected_cost
    );
    // Planned controls respect the scenario's limits.
    for (k, u) in file.u.iter().enumerate() {
        for (j, v) in u.iter().enumerate() {
            assert!(
                scenario.bounds.lower[j] <= *v && *v <= scenario.bounds.upper[j],
                "{stem}: u[{k}][{j}] = {v} outside its limits"
            );
        }
    }
    assert!(
        s.converged,
        "{stem}: not converged: stop {} after {} iterations, cost {:.6e}, expected cost {:.6e}, \
         final error {:.3} {}, {:.0} ms",
        s.stop,
        s.iterations,
        s.cost,
        s.expected_cost,
        s.final_error,
        s.final_error_unit,
        s.solve_ms
    );
}

#[test]
fn every_config_file_is_tested() {
    let mut found: Vec<String> = std::fs::read_dir(config_dir())
        .expect("config directory")
        .map(|e| e.expect("directory entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    found.sort();
    assert_eq!(found, SCENARIOS, "config/*.toml and SCENARIOS differ");
}

#[test]
fn icub_elbow() {
    check("icub_elbow");
}

#[test]
fn icub_experiment() {
    check("icub_experiment");
}

#[test]
fn single_joint_delay() {
    check("single_joint_delay");
}

#[test]
fn two_link_curl() {
    check("two_link_curl");
}

#[test]
fn two_link_deterministic() {
    check("two_link_deterministic");
}

#[test]
fn two_link_divergent() {
    check("two_link_divergent");
}

#[test]
fn two_link_divergent_fast_vsa() {
    check("two_link_divergent_fast_vsa");
}

#[test]
fn two_link_divergent_maccepa() {
    check("two_link_divergent_maccepa");
}

#[test]
fn two_link_reach() {
    check("two_link_reach");
}

#[test]
fn two_link_torque_divergent() {
    check("two_link_torque_divergent");
}

/// SOOC (`--method sooc`) converges on the scenarios that are cheap enough to plan in every test
/// run: the deterministic plant (the criterion's curvature cap; no stiffness start without
/// noise) and the torque actuator (the configured room). The VSA scenarios take minutes each
/// (docs/BENCHMARKS.md, "Every scenario").
#[test]
fn sooc_converges_without_noise_and_without_stiffness() {
    for stem in ["two_link_deterministic", "two_link_torque_divergent"] {
        let path = config_dir().join(format!("{stem}.toml"));
        let scenario = Scenario::load(&path, &[]).unwrap_or_else(|e| panic!("{e}"));
        check_with(stem, &scenario, Method::Sooc);
    }
}

#[test]
fn two_link_vsa_divergent() {
    check("two_link_vsa_divergent");
}

#[test]
fn two_link_vsa_light_divergent() {
    check("two_link_vsa_light_divergent");
}

/// A user who wrote a bad file must know which file and which key to fix: a misspelt key and a
/// value of the wrong type each name both.
#[test]
fn a_misspelt_key_and_a_wrong_type_name_the_file_and_the_key() {
    let path = config_dir().join("icub_elbow.toml");
    let text = std::fs::read_to_string(&path).expect("scenario file");
    let cases = [
        ("dt = 0.01", "dtt = 0.01", "[task] dtt"),
        ("dt = 0.01", "dt = \"0.01\"", "[task] dt"),
        (
            "type = \"impedance\"",
            "typ = \"impedance\"",
            "[actuator] type: missing, required",
        ),
        ("type = \"impedance\"", "type = 3", "[actuator] type"),
        ("w_p = 1e6", "w_p = [1e6]", "[cost] w_p"),
    ];
    for (from, to, key) in cases {
        assert!(
            text.contains(from),
            "icub_elbow.toml no longer contains {from}"
        );
        let bad = std::env::temp_dir().join(format!("vic_bad_key_{}.toml", std::process::id()));
        std::fs::write(&bad, text.replacen(from, to, 1)).expect("temporary file");
        let e = Scenario::load(&bad, &[])
            .expect_err(&format!("{to} must be refused"))
            .to_string();
        std::fs::remove_file(&bad).ok();
        assert!(
            e.contains(&bad.display().to_string()) && e.contains(key),
            "{to}: the message must name the file and {key}: {e}"
        );
    }
}
