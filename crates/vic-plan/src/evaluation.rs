//! What a Monte Carlo evaluation reports: final spread, 95 % confidence ellipse, tracking and
//! final errors, divergence, and the Monte Carlo expected cost (the Eq. 14 cost averaged over
//! trials) next to the predicted one.

use crate::montecarlo::{Trial, position};
use crate::plan::Setup;
use crate::unit::Unit;
use nalgebra::DVector;
use serde::{Deserialize, Serialize};

/// χ²(2) quantile at 95 %: the 95 % ellipse of a 2-D Gaussian is `dᵀ Σ⁻¹ d ≤ 5.991`.
const CHI2_2_95: f64 = 5.991_464_547_107_979;

/// The summary of a set of trials. Positions are in `unit`: the hand [mm] for the arm, the joint
/// angle [deg] for a single joint.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Report {
    pub trials: usize,
    pub unit: Unit,
    /// Mean final position.
    pub(crate) final_mean: Vec<f64>,
    /// Standard deviation of the final position: the largest principal axis for the hand.
    pub final_std: f64,
    /// Semi-axes of the 95 % confidence ellipse of the final hand position (or the 95 % half-width
    /// for a joint), largest first.
    pub ellipse_95: Vec<f64>,
    /// Orientation of the ellipse's major axis [deg from the x axis] (0 for a joint).
    pub(crate) ellipse_angle_deg: f64,
    /// RMS distance to the reference over all knots of the trials that did not diverge (`None`
    /// when every trial diverged).
    pub rms_error: Option<f64>,
    /// Mean and largest distance of the final position to the target, over the trials that did
    /// not diverge (`None` when every trial diverged).
    pub final_error_mean: Option<f64>,
    pub final_error_max: Option<f64>,
    /// Standard error of `final_error_mean` (`None` with fewer than two trials kept): how far
    /// two runs of the same strategy with different noise may differ.
    #[serde(default)]
    pub final_error_se: Option<f64>,
    /// Trials that ended further than the divergence threshold from the target (or blew up).
    pub diverged: usize,
    pub diverged_fraction: f64,
    /// Fraction of trials ending further than [`Unit::far_threshold`] from the target.
    pub far_fraction: f64,
    /// Monte Carlo expected cost and its standard error over the trials that did not diverge
    /// (`None` when every trial diverged, or the standard error with fewer than two kept).
    pub expected_cost_mc: Option<f64>,
    pub expected_cost_se: Option<f64>,
}

/// Summarises `trials` run on `setup`; a trial diverged when its final position is further than
/// `divergence` (in the report's unit) from the target, or is not finite.
///
/// A diverged trial is counted, never averaged: the errors and the Monte Carlo cost are taken over
/// the other trials only (one trial that left the workspace would otherwise decide every mean),
/// and are `None` when no trial is left. The spread (`final_mean`, `final_std`, the ellipse) and
/// `far_fraction` describe every trial, as the paper's Fig. 1 plots them.
pub fn summarize(setup: &Setup, trials: &[Trial], divergence: f64) -> Report {
    let model = &setup.dynamics.model;
    let unit = Unit::for_model(model);
    let k = unit.scale();
    let steps = setup.reference.len() - 1;
    let target = |i: usize| -> Vec<f64> {
        let r = &setup.reference[i];
        let mut x = DVector::zeros(model.nx());
        x[0] = r.q_d[0];
        if model.dof() > 1 {
            x[1] = r.q_d[1];
        }
        position(model, &x)
    };
    let dist = |a: &[f64], b: &[f64]| -> f64 {
        a.iter()
            .zip(b)
            .map(|(p, q)| (p - q) * (p - q))
            .sum::<f64>()
            .sqrt()
            * k
    };
    let goal = target(steps);
    let finals: Vec<Vec<f64>> = trials
        .iter()
        .map(|t| position(model, &t.x[steps]))
        .collect();
    let count = trials.len() as f64;
    let Spread {
        mean,
        ellipse_95,
        angle,
        final_std,
    } = spread(&finals, goal.len(), k);
    let targets: Vec<Vec<f64>> = (0..=steps).map(target).collect();
    let final_errors: Vec<f64> = finals.iter().map(|f| dist(f, &goal)).collect();
    let is_diverged = |e: f64| !e.is_finite() || e > divergence;
    let kept: Vec<usize> = (0..trials.len())
        .filter(|&i| !is_diverged(final_errors[i]))
        .collect();
    let diverged = trials.len() - kept.len();
    let mut sq = 0.0;
    let mut n = 0.0;
    for &i in &kept {
        for (k, x) in trials[i].x.iter().enumerate() {
            let d = dist(&position(model, x), &targets[k]);
            sq += d * d;
            n += 1.0;
        }
    }
    let kept_errors: Vec<f64> = kept.iter().map(|&i| final_errors[i]).collect();
    let (final_error_mean, final_error_se) = mean_and_standard_error(&kept_errors);
    let costs: Vec<f64> = kept.iter().map(|&i| trials[i].cost).collect();
    let (cost_mean, cost_se) = mean_and_standard_error(&costs);
    let finite = |v: f64| v.is_finite().then_some(v);
    Report {
        trials: trials.len(),
        unit,
        final_mean: mean.iter().map(|m| m * k).collect(),
        final_std,
        ellipse_95,
        ellipse_angle_deg: angle,
        rms_error: (n > 0.0).then(|| (sq / n).sqrt()).and_then(finite),
        final_error_mean,
        final_error_se,
        final_error_max: kept_errors.iter().copied().reduce(f64::max),
        diverged,
        diverged_fraction: diverged as f64 / count,
        far_fraction: final_errors
            .iter()
            .filter(|e| !e.is_finite() || **e > unit.far_threshold())
            .count() as f64
            / count,
        expected_cost_mc: cost_mean,
        expected_cost_se: cost_se,
    }
}

/// The mean of `values` and its standard error (`None` for an empty set, the standard error
/// also for a single value, or when not finite).
pub(crate) fn mean_and_standard_error(values: &[f64]) -> (Option<f64>, Option<f64>) {
    if values.is_empty() {
        return (None, None);
    }
    let count = values.len() as f64;
    let mean = values.iter().sum::<f64>() / count;
    let se = (values.len() > 1).then(|| {
        let var = values.iter().map(|c| (c - mean).powi(2)).sum::<f64>() / (count - 1.0);
        (var / count).sqrt()
    });
    (
        mean.is_finite().then_some(mean),
        se.filter(|v| v.is_finite()),
    )
}

/// The spread of final positions (`dim` coordinates in SI units, `k` the report unit's scale).
struct Spread {
    /// Mean final position (SI units).
    mean: Vec<f64>,
    ellipse_95: Vec<f64>,
    /// Orientation of the major axis [deg].
    angle: f64,
    final_std: f64,
}

/// Sample mean and covariance of the final positions, and from them the 95 % confidence ellipse
/// (χ²(2) for the hand, the normal 95 % half-width for a joint).
fn spread(finals: &[Vec<f64>], dim: usize, k: f64) -> Spread {
    let count = finals.len() as f64;
    let mut mean = vec![0.0; dim];
    for f in finals {
        for (m, v) in mean.iter_mut().zip(f) {
            *m += v / count;
        }
    }
    let mut cov = [[0.0_f64; 2]; 2];
    for f in finals {
        for a in 0..dim {
            for b in 0..dim {
                cov[a][b] += (f[a] - mean[a]) * (f[b] - mean[b]) / (count - 1.0).max(1.0);
            }
        }
    }
    let (ellipse_95, angle, final_std) = if dim == 1 {
        let sd = cov[0][0].sqrt() * k;
        (vec![1.959_963_984_540_054 * sd], 0.0, sd)
    } else {
        let (a, b, c) = (cov[0][0], cov[0][1], cov[1][1]);
        let tr = a + c;
        let disc = ((a - c) * (a - c) / 4.0 + b * b).sqrt();
        let (l1, l2) = (tr / 2.0 + disc, (tr / 2.0 - disc).max(0.0));
        let angle = 0.5 * (2.0 * b).atan2(a - c);
        (
            vec![(CHI2_2_95 * l1).sqrt() * k, (CHI2_2_95 * l2).sqrt() * k],
            angle.to_degrees(),
            l1.sqrt() * k,
        )
    };
    Spread {
        mean,
        ellipse_95,
        angle,
        final_std,
    }
}
