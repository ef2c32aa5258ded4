//! Why the iCub plan alternates its torque and stiffness from knot to knot (docs/GUIDE.md, "Why
//! the iCub plan alternates"): not a flat direction of the expected cost but a real optimum of
//! the sampled model, bought by the torque noise whose amplitude `a + b q'` is set by the velocity
//! at each knot. Checked against the plan with each pair of knots averaged (predicted and by a
//! Monte Carlo with common random numbers) and against the same scenario with `b = 0`.

use nalgebra::DVector;
use std::path::Path;
use vic_core::policy::Feedback;
use vic_plan::montecarlo::run_trials;
use vic_plan::plan::{Method, PlanFile, Setup, plan, predict_open_loop, setup};
use vic_plan::scenario::Scenario;

const TRIALS: usize = 400;

fn planned(extra: &[&str]) -> (Setup, PlanFile) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/icub_experiment.toml");
    let overrides: Vec<String> = extra.iter().map(|s| s.to_string()).collect();
    let s = Scenario::load(&path, &overrides).expect("scenario");
    let p = plan(&s, Method::Sooc, None).expect("plan");
    assert!(
        p.summary.converged,
        "{extra:?}: the SOOC plan did not converge"
    );
    (setup(&s).expect("setup"), p)
}

/// The knots whose stiffness is a local extremum with jumps of more than 5 N m/rad on both
/// sides: the alternation.
fn alternating_knots(p: &PlanFile) -> Vec<usize> {
    let k: Vec<f64> = p.u.iter().map(|u| u[1]).collect();
    (1..k.len() - 1)
        .filter(|&i| {
            let (a, b) = (k[i] - k[i - 1], k[i + 1] - k[i]);
            a * b < 0.0 && a.abs() > 5.0 && b.abs() > 5.0
        })
        .collect()
}

/// The plan with the commands of knots 2j and 2j + 1 replaced by their average: the same
/// commands over each 20 ms, without the alternation.
fn pair_averaged(p: &PlanFile) -> PlanFile {
    let mut q = p.clone();
    for j in 0..p.u.len() / 2 {
        for i in 0..p.u[0].len() {
            let m = 0.5 * (p.u[2 * j][i] + p.u[2 * j + 1][i]);
            q.u[2 * j][i] = m;
            q.u[2 * j + 1][i] = m;
        }
    }
    q
}

/// The plan's open-loop expected cost: predicted (covariance propagation) and each trial's.
fn costs(s: &Setup, p: &PlanFile) -> (f64, Vec<f64>) {
    let acting: Vec<DVector<f64>> = p.u.iter().map(|u| DVector::from_column_slice(u)).collect();
    let predicted = predict_open_loop(s, &acting).expected_cost;
    let policy = p.policy(s).expect("policy");
    let trials = run_trials(s, &policy, Feedback::OpenLoop, TRIALS, 7);
    (predicted, trials.iter().map(|t| t.cost).collect())
}

fn mean_and_se(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

#[test]
fn the_icub_plan_alternates_because_the_noise_is_set_by_the_velocity_at_each_knot() {
    let (s, p) = planned(&[]);
    let alternating = alternating_knots(&p);
    assert!(
        alternating.len() >= 20,
        "{} alternating knots",
        alternating.len()
    );
    let smooth = pair_averaged(&p);
    assert!(alternating_knots(&smooth).is_empty());

    // Not a flat direction: averaging each pair costs more, predicted and by Monte Carlo (the
    // same noise for both plans, so the difference is measured trial by trial).
    let (predicted, mc) = costs(&s, &p);
    let (predicted_smooth, mc_smooth) = costs(&s, &smooth);
    let rise = predicted_smooth / predicted - 1.0;
    let diff: Vec<f64> = mc_smooth.iter().zip(&mc).map(|(b, a)| b - a).collect();
    let (d, d_se) = mean_and_se(&diff);
    let (m, m_se) = mean_and_se(&mc);
    eprintln!(
        "alternating knots {}; predicted {predicted:.4e}, pair-averaged {predicted_smooth:.4e} \
         ({:+.1} %); Monte Carlo {m:.4e} ± {m_se:.1e}, pair-averaged − plan {d:.3e} ± {d_se:.1e}",
        alternating.len(),
        100.0 * rise
    );
    assert!(rise > 0.02, "predicted rise {rise}");
    assert!(d > 4.0 * d_se, "Monte Carlo: {d} ± {d_se}");

    // The mechanism: the noise added over knot k has the amplitude a + b q'_k of the velocity at
    // its start, and knot k + 1 damps it (K_D = 0.075 K). Where the plan alternates, the knots
    // that follow a fast sample (a large kick) are the stiff ones.
    let k_max = p.u.iter().map(|u| u[1]).fold(0.0, f64::max);
    let (mut stiff, mut compliant) = (Vec::new(), Vec::new());
    for &j in &alternating {
        let v = p.x[j - 1][1];
        if p.u[j][1] > 0.95 * k_max {
            stiff.push(v);
        } else {
            compliant.push(v);
        }
    }
    let (v_stiff, _) = mean_and_se(&stiff);
    let (v_compliant, _) = mean_and_se(&compliant);
    eprintln!(
        "mean velocity at the sample before a stiff knot {v_stiff:.3} rad/s ({}), before a \
         compliant one {v_compliant:.3} rad/s ({})",
        stiff.len(),
        compliant.len()
    );
    assert!(v_stiff > v_compliant + 0.05, "{v_stiff} vs {v_compliant}");

    // Without the velocity's share of the noise (b = 0) the optimum does not alternate, and
    // averaging its pairs changes its cost by less than 0.5 %.
    let (s0, p0) = planned(&["noise.b=0"]);
    assert!(
        alternating_knots(&p0).is_empty(),
        "{:?}",
        alternating_knots(&p0)
    );
    let acting = |p: &PlanFile| -> Vec<DVector<f64>> {
        p.u.iter().map(|u| DVector::from_column_slice(u)).collect()
    };
    let c0 = predict_open_loop(&s0, &acting(&p0)).expected_cost;
    let c0_smooth = predict_open_loop(&s0, &acting(&pair_averaged(&p0))).expected_cost;
    eprintln!("b = 0: predicted {c0:.4e}, pair-averaged {c0_smooth:.4e}");
    assert!((c0_smooth / c0 - 1.0).abs() < 0.005, "{c0} vs {c0_smooth}");
}
