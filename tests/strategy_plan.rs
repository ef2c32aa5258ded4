//! The spine of the delay experiment (`vic_plan::strategy`): a strategy's typed scenario edits
//! are the overrides of the same keys, and no code builds such an override as a string.

use std::path::Path;
use vic_plan::scenario::Scenario;
use vic_plan::strategy::{Latency, Strategy, StrategyPlan};

fn load(overrides: &[&str]) -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/single_joint_delay.toml");
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    Scenario::load(&path, &overrides).expect("scenario")
}

/// The edited scenario is the one the file with the overrides of the same keys validates to.
#[test]
fn the_typed_edits_are_the_overrides_of_the_same_keys() {
    let base = load(&[]);
    let latency = Latency::from_ms(50.0, base.task.dt).unwrap();
    let cases: [(Strategy, &[&str]); 3] = [
        (
            Strategy::NaiveDelayed,
            &[
                "actuator.stiffness_min=0.0",
                "actuator.stiffness_max=0.0",
                "actuator.initial_stiffness=0.0",
                "task.delay_ms=50.0",
            ],
        ),
        (
            Strategy::Predictor,
            &[
                "actuator.stiffness_min=0.0",
                "actuator.stiffness_max=0.0",
                "actuator.initial_stiffness=0.0",
                "task.delay_ms=0.0",
            ],
        ),
        (Strategy::StiffnessPredictor, &["task.delay_ms=0.0"]),
    ];
    for (strategy, overrides) in cases {
        let edited = strategy.plan_request(latency).scenario(&base);
        let overridden = load(overrides);
        assert_eq!(edited.bounds.lower, overridden.bounds.lower, "{strategy}");
        assert_eq!(edited.bounds.upper, overridden.bounds.upper, "{strategy}");
        assert_eq!(
            edited.initial_stiffness, overridden.initial_stiffness,
            "{strategy}"
        );
        assert_eq!(edited.task, overridden.task, "{strategy}");
        assert_eq!(edited.resolved, overridden.resolved, "{strategy}");
    }
}

/// No code (outside the override parser's own tests) writes a stiffness or delay override as a
/// string: strategies and latencies reach a scenario through the typed edits.
#[test]
fn no_code_builds_a_strategy_or_latency_override_string() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut found = Vec::new();
    let mut dirs = vec![root.join("src"), root.join("crates"), root.join("bins")];
    while let Some(dir) = dirs.pop() {
        for entry in std::fs::read_dir(&dir).expect("readable folder") {
            let path = entry.expect("entry").path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|e| e == "rs")
                && !path.ends_with("crates/vic-plan/src/scenario/tests.rs")
            {
                let text = std::fs::read_to_string(&path).expect("readable source");
                for (i, line) in text.lines().enumerate() {
                    if [
                        "stiffness_max=",
                        "stiffness_min=",
                        "initial_stiffness=",
                        "delay_ms=",
                    ]
                    .iter()
                    .any(|p| line.contains(p))
                    {
                        found.push(format!("{}:{}: {line}", path.display(), i + 1));
                    }
                }
            }
        }
    }
    assert!(found.is_empty(), "string overrides:\n{}", found.join("\n"));
}
