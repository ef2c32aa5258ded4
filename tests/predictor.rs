//! The predictor policy (a Smith predictor across the feedback latency, `Feedback::Predicted`),
//! checked against what it must equal and against the naive delayed feedback of Eq. 13.

use std::path::Path;
use vic_core::policy::Feedback;
use vic_plan::montecarlo::{Trial, run_trials};
use vic_plan::plan::{Method, PlanFile, Setup, plan, setup};
use vic_plan::scenario::Scenario;

/// The single joint of Fig. 2 without stiffness (feedback is all it has), planned by ILQG for a
/// controller without delay; `sigma` sets the noise.
fn joint(sigma: f64) -> (Setup, PlanFile) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/single_joint_delay.toml");
    let overrides = [
        "task.delay_ms=0".to_string(),
        "actuator.stiffness_max=0".into(),
        "actuator.initial_stiffness=0".into(),
        format!("noise.sigma={sigma}"),
    ];
    let s = Scenario::load(&path, &overrides).expect("scenario");
    let p = plan(&s, Method::Ilqg, None).expect("plan");
    (setup(&s).expect("setup"), p)
}

fn trials(setup: &Setup, p: &PlanFile, feedback: Feedback, n: usize) -> Vec<Trial> {
    run_trials(setup, &p.policy(setup).expect("policy"), feedback, n, 11)
}

fn mean_cost(t: &[Trial]) -> f64 {
    t.iter().map(|t| t.cost).sum::<f64>() / t.len() as f64
}

#[test]
fn at_zero_latency_the_predictor_is_the_plain_feedback_policy() {
    let (s, p) = joint(0.03);
    let full = trials(&s, &p, Feedback::Full, 8);
    let pred = trials(&s, &p, Feedback::Predicted { latency_steps: 0 }, 8);
    for (a, b) in full.iter().zip(&pred) {
        assert_eq!(a.x, b.x);
        assert_eq!(a.u, b.u);
    }
}

#[test]
fn without_noise_the_delay_costs_the_predictor_almost_nothing() {
    // The paper's footnote 1: with a perfect model and no noise, prediction compensates the delay.
    // The arm starts 3° off the plan's start, so feedback has something to correct; only in the
    // first `D` steps, before any state has arrived, is the predictor blind.
    let (mut s, p) = joint(0.0);
    s.x0[0] += 3f64.to_radians();
    let target = s.reference.last().expect("reference").q_d[0];
    let miss = |t: &[Trial]| {
        (t[0].x.last().expect("final")[0] - target)
            .abs()
            .to_degrees()
    };
    let full = miss(&trials(&s, &p, Feedback::Full, 1));
    let open = miss(&trials(&s, &p, Feedback::OpenLoop, 1));
    assert!(open > 1.0, "open loop corrects nothing: {open}°");
    for h in [5, 10, 20] {
        let pred = miss(&trials(&s, &p, Feedback::Predicted { latency_steps: h }, 1));
        let naive = miss(&trials(&s, &p, Feedback::Delayed { latency_steps: h }, 1));
        eprintln!(
            "{h} steps: full {full:.4}°, predictor {pred:.4}°, naive {naive:.4}°, open {open:.4}°"
        );
        assert!(
            pred < full + 0.05,
            "{h} steps: predictor {pred}° vs {full}° without delay"
        );
        assert!(
            naive > pred,
            "{h} steps: naive {naive}° vs predictor {pred}°"
        );
    }
}

#[test]
fn with_noise_the_predictor_beats_the_naive_delayed_law_and_loses_to_no_delay() {
    let (s, p) = joint(0.03);
    let n = 200;
    let full = mean_cost(&trials(&s, &p, Feedback::Full, n));
    let mut last = full;
    for h in [2, 5, 10, 20] {
        let pred = mean_cost(&trials(&s, &p, Feedback::Predicted { latency_steps: h }, n));
        let naive = mean_cost(&trials(&s, &p, Feedback::Delayed { latency_steps: h }, n));
        assert!(pred < naive, "{h} steps: predictor {pred} vs naive {naive}");
        // The same noise for every latency: the prediction error grows with it.
        assert!(
            pred >= last * 0.98,
            "{h} steps: predictor {pred} after {last}"
        );
        last = pred;
    }
    assert!(
        last > full,
        "a 200 ms prediction costs nothing: {last} vs {full}"
    );
}
