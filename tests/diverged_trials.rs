//! A diverged trial is counted, never averaged: the errors and the Monte Carlo cost of a report
//! with some diverged trials equal those of the report of the other trials alone.

use std::path::Path;
use vic_core::policy::Feedback;
use vic_plan::evaluation::summarize;
use vic_plan::montecarlo::run_trials;
use vic_plan::plan::{Method, plan, setup};
use vic_plan::scenario::Scenario;

#[test]
fn diverged_trials_never_enter_the_means() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/single_joint_delay.toml");
    let s = Scenario::load(&path, &["task.delay_ms=0".to_string()]).expect("scenario");
    let p = plan(&s, Method::Ilqg, None).expect("plan");
    let set = setup(&s).expect("setup");
    let policy = p.policy(&set).expect("policy");
    let mut trials = run_trials(&set, &policy, Feedback::Full, 10, 5);
    let divergence = 10.0; // degrees
    let clean = summarize(&set, &trials, divergence);
    assert_eq!(clean.diverged, 0, "the feedback plan keeps every trial");
    // Three trials leave the workspace: one far off, one blown up (not finite), one whose
    // final state alone is off by more than the divergence distance.
    let steps = trials[0].x.len() - 1;
    for x in &mut trials[1].x {
        x[0] += 1e6;
    }
    trials[1].cost = 1e30;
    trials[4].x[steps][0] = f64::NAN;
    trials[4].cost = f64::INFINITY;
    trials[7].x[steps][0] += 20f64.to_radians();
    trials[7].cost = 1e12;
    let mixed = summarize(&set, &trials, divergence);
    assert_eq!(mixed.diverged, 3);
    assert!((mixed.diverged_fraction - 0.3).abs() < 1e-12);
    let kept: Vec<_> = trials
        .iter()
        .enumerate()
        .filter(|(i, _)| ![1, 4, 7].contains(i))
        .map(|(_, t)| t.clone())
        .collect();
    let alone = summarize(&set, &kept, divergence);
    assert_eq!(alone.diverged, 0);
    assert_eq!(mixed.final_error_mean, alone.final_error_mean);
    assert_eq!(mixed.final_error_max, alone.final_error_max);
    assert_eq!(mixed.rms_error, alone.rms_error);
    assert_eq!(mixed.expected_cost_mc, alone.expected_cost_mc);
    assert_eq!(mixed.expected_cost_se, alone.expected_cost_se);
    // ... and the mean is the mean of the seven final errors, computed here from the angles.
    let target = set.reference[steps].q_d[0];
    let mean = kept
        .iter()
        .map(|t| (t.x[steps][0] - target).abs().to_degrees())
        .sum::<f64>()
        / 7.0;
    let got = mixed.final_error_mean.expect("seven trials kept");
    assert!(
        (got - mean).abs() < 1e-9 * mean.max(1e-9),
        "{got} vs {mean}"
    );
    let cost = kept.iter().map(|t| t.cost).sum::<f64>() / 7.0;
    assert!((mixed.expected_cost_mc.unwrap() - cost).abs() < 1e-9 * cost);

    // Every trial diverged: no number at all, never a sentinel.
    for t in &mut trials {
        t.x[steps][0] = f64::NAN;
    }
    let none = summarize(&set, &trials, divergence);
    assert_eq!(none.diverged, 10);
    assert_eq!(none.final_error_mean, None);
    assert_eq!(none.final_error_max, None);
    assert_eq!(none.rms_error, None);
    assert_eq!(none.expected_cost_mc, None);
    let json = serde_json::to_value(&none).unwrap();
    assert!(json["final_error_mean"].is_null() && json["expected_cost_mc"].is_null());
}
