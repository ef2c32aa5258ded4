//! The results of live or lockstep trials, summarised like the offline evaluation: the JSON that
//! `vic-planner` prints and `vic demo` reads.

use crate::core::cost::Cost;
use crate::planning::montecarlo::Trial;
use crate::planning::plan::Setup;
use crate::rt::central::{Central, TrialRecord};
use nalgebra::DVector;

/// Turns records into the offline simulation's trials (with the realised cost) for
/// [`crate::planning::evaluation::summarize`].
pub fn to_trials(setup: &Setup, records: &[TrialRecord]) -> Vec<Trial> {
    records
        .iter()
        .map(|r| {
            let steps = r.u.len();
            let mut cost = 0.0;
            for k in 0..steps {
                cost += setup.cost.running(k, r.x[k].as_slice(), r.u[k].as_slice());
            }
            cost += setup.cost.terminal(r.x[steps].as_slice());
            Trial {
                x: r.x.clone(),
                u: r.u.clone(),
                cost,
            }
        })
        .collect()
}

/// The results of a strategy's trials (the JSON `vic-planner` prints and `vic demo` reads).
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct StrategyResult {
    pub name: String,
    pub latency_ms: f64,
    pub sensor_latency_ms: f64,
    pub command_latency_ms: f64,
    pub trials: usize,
    /// Unit of the errors: "mm" (hand) or "deg" (joint).
    pub unit: crate::planning::unit::Unit,
    pub rms_error: f64,
    pub final_error_mean: f64,
    pub final_error_max: f64,
    /// Final error of every trial.
    pub final_errors: Vec<f64>,
    pub max_error: f64,
    pub diverged: usize,
    /// Trials during which the board fell back to safe hold or faulted.
    pub safe_hold_trials: usize,
    pub fault_trials: usize,
    /// Knots whose feedback used a state older than the latency (all trials).
    pub stale_feedback: usize,
    pub missing_states: usize,
    pub expected_cost: f64,
}

/// Summarises records like the offline evaluation does (`divergence` in the report's unit).
pub fn summarize(
    setup: &Setup,
    central: &Central,
    records: &[TrialRecord],
    divergence: f64,
) -> StrategyResult {
    let trials = to_trials(setup, records);
    let report = crate::planning::evaluation::summarize(setup, &trials, divergence);
    let model = &setup.dynamics.model;
    let scale = report.unit.scale();
    let steps = setup.reference.len() - 1;
    let target = |k: usize| {
        let mut x = DVector::zeros(model.nx());
        for i in 0..model.dof() {
            x[i] = setup.reference[k].q_d[i];
        }
        crate::planning::montecarlo::position(model, &x)
    };
    let dist = |a: &[f64], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(p, q)| (p - q).powi(2))
            .sum::<f64>()
            .sqrt()
            * scale
    };
    let goal = target(steps);
    let final_errors: Vec<f64> = trials
        .iter()
        .map(|t| {
            let e = dist(
                &crate::planning::montecarlo::position(model, &t.x[steps]),
                &goal,
            );
            if e.is_finite() { e } else { f64::MAX }
        })
        .collect();
    let max_error = trials
        .iter()
        .flat_map(|t| {
            t.x.iter()
                .enumerate()
                .map(|(k, x)| dist(&crate::planning::montecarlo::position(model, x), &target(k)))
        })
        .fold(
            0.0,
            |m: f64, e| if e.is_finite() { m.max(e) } else { f64::MAX },
        );
    let t = &central.timing;
    StrategyResult {
        name: central.strategy.name().into(),
        latency_ms: t.latency_steps as f64 * central.track.dt_ns as f64 * 1e-6,
        sensor_latency_ms: t.sensor_latency_ns as f64 * 1e-6,
        command_latency_ms: t.command_latency_ns as f64 * 1e-6,
        trials: records.len(),
        unit: report.unit,
        rms_error: if report.rms_error.is_finite() {
            report.rms_error
        } else {
            f64::MAX
        },
        final_error_mean: (final_errors.iter().map(|e| e.min(1e12)).sum::<f64>()
            / final_errors.len().max(1) as f64)
            .min(f64::MAX),
        final_error_max: final_errors.iter().copied().fold(0.0, f64::max),
        diverged: final_errors
            .iter()
            .filter(|e| !e.is_finite() || **e > divergence)
            .count(),
        final_errors,
        max_error,
        safe_hold_trials: records.iter().filter(|r| r.safe_hold).count(),
        fault_trials: records.iter().filter(|r| r.fault).count(),
        stale_feedback: records.iter().map(|r| r.stale_feedback).sum(),
        missing_states: records.iter().map(|r| r.missing_states).sum(),
        expected_cost: if report.expected_cost_mc.is_finite() {
            report.expected_cost_mc
        } else {
            f64::MAX
        },
    }
}
