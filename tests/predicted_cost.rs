//! The predicted expected cost of the executed policy (`vic_plan::prediction::predicted_cost`:
//! closed-loop covariance propagation of the plant augmented with the prediction error) against
//! the solvers' own predictions where they exist and against the Monte Carlo where they do not.

use std::path::Path;
use vic_core::policy::Feedback;
use vic_plan::montecarlo::run_trials;
use vic_plan::plan::{Method, PlanFile, Setup, plan, setup};
use vic_plan::prediction::predicted_cost;
use vic_plan::scenario::Scenario;

fn planned(config: &str, extra: &[&str], method: Method) -> (Setup, PlanFile) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("config")
        .join(config);
    let overrides: Vec<String> = extra.iter().map(|s| s.to_string()).collect();
    let s = Scenario::load(&path, &overrides).expect("scenario");
    let p = plan(&s, method, None).expect("plan");
    (setup(&s).expect("setup"), p)
}

/// The single joint of Fig. 2 without stiffness, planned for no delay.
fn joint_feedback() -> (Setup, PlanFile) {
    planned(
        "single_joint_delay.toml",
        &[
            "task.delay_ms=0",
            "actuator.stiffness_max=0",
            "actuator.initial_stiffness=0",
        ],
        Method::Ilqg,
    )
}

#[test]
fn full_feedback_and_open_loop_reproduce_the_solvers_predictions() {
    let (s, p) = joint_feedback();
    let policy = p.policy(&s).unwrap();
    let full = predicted_cost(&s, &policy, Feedback::Full).unwrap();
    let zero = predicted_cost(&s, &policy, Feedback::Predicted { latency_steps: 0 }).unwrap();
    eprintln!("full {full} vs ILQG s_0 {}", p.summary.expected_cost);
    assert_eq!(full, zero);
    let rel = (full - p.summary.expected_cost).abs() / p.summary.expected_cost;
    assert!(
        rel < 0.01,
        "full feedback {full} vs ILQG {}",
        p.summary.expected_cost
    );
    let (s, p) = planned(
        "single_joint_delay.toml",
        &["task.delay_ms=0"],
        Method::Sooc,
    );
    let policy = p.policy(&s).unwrap();
    let open = predicted_cost(&s, &policy, Feedback::OpenLoop).unwrap();
    eprintln!(
        "open loop {open} vs SOOC {}",
        p.summary.open_loop_expected_cost
    );
    let rel = (open - p.summary.open_loop_expected_cost).abs() / p.summary.open_loop_expected_cost;
    assert!(
        rel < 0.01,
        "open loop {open} vs {}",
        p.summary.open_loop_expected_cost
    );
}

#[test]
fn the_predictor_prediction_agrees_with_monte_carlo_at_every_latency() {
    let (s, p) = joint_feedback();
    let policy = p.policy(&s).unwrap();
    let n = 400;
    let mut last = 0.0;
    for steps in [0, 2, 5, 10, 15, 20, 30] {
        let fb = Feedback::Predicted {
            latency_steps: steps,
        };
        let predicted = predicted_cost(&s, &policy, fb).unwrap();
        let trials = run_trials(&s, &policy, fb, n, 7);
        let costs: Vec<f64> = trials.iter().map(|t| t.cost).collect();
        let mean = costs.iter().sum::<f64>() / n as f64;
        let var = costs.iter().map(|c| (c - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        let se = (var / n as f64).sqrt();
        eprintln!(
            "{:>3} ms: predicted {predicted:.2}, Monte Carlo {mean:.2} ± {se:.2}",
            steps * 10
        );
        assert!(
            (predicted - mean).abs() < 3.0 * se + 0.02 * mean,
            "{steps} steps: predicted {predicted} vs Monte Carlo {mean} ± {se}"
        );
        assert!(
            predicted >= last,
            "the prediction error grows with the latency"
        );
        last = predicted;
    }
}

/// The prediction flags where its own assumption, an unclamped linear law, fails: the ILQG plan
/// of the iCub elbow, whose stiffness gains are huge (stiffness is nearly free), has knots where
/// the feedback's predicted spread passes a bound, and there the Monte Carlo of the executed
/// (clamped) law is far above the prediction; the plans without such knots (the experiment's
/// elbow with its torque noise, the torque-only arm in the divergent field) agree with theirs.
/// The arm's torques limited to ±5 N m (its feedback's spread reaches about 0.4 N m) keep the
/// test from passing with a threshold far below the room to the bounds.
#[test]
fn clamped_feedback_is_flagged_where_the_monte_carlo_departs_from_the_prediction() {
    for (config, extra, flagged) in [
        ("icub_elbow.toml", None, true),
        ("icub_experiment.toml", None, false),
        (
            "two_link_torque_divergent.toml",
            Some("actuator.torque_limit=5"),
            false,
        ),
    ] {
        let (s, p) = planned(config, extra.as_slice(), Method::Ilqg);
        let knots = p
            .summary
            .clamped_feedback_knots
            .expect("an undelayed ILQG plan with noise");
        let policy = p.policy(&s).unwrap();
        let n = 300;
        let trials = run_trials(&s, &policy, Feedback::Full, n, 7);
        let costs: Vec<f64> = trials.iter().map(|t| t.cost).collect();
        assert!(
            costs.iter().all(|c| c.is_finite()),
            "{config}: a trial diverged"
        );
        let mean = costs.iter().sum::<f64>() / n as f64;
        let var = costs.iter().map(|c| (c - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        let se = (var / n as f64).sqrt();
        let predicted = p.summary.expected_cost;
        eprintln!(
            "{config}: {knots} clamped knots, predicted {predicted:.4e}, Monte Carlo {mean:.4e} ± {se:.1e}"
        );
        if flagged {
            assert!(knots > 0, "{config}: no clamped knot");
            assert!(
                mean > 5.0 * predicted,
                "{config}: Monte Carlo {mean} close to the prediction {predicted}"
            );
        } else {
            assert_eq!(knots, 0, "{config}: clamped knots");
            assert!(
                (mean - predicted).abs() < 3.0 * se + 0.03 * predicted,
                "{config}: predicted {predicted} vs Monte Carlo {mean} ± {se}"
            );
        }
    }
}
