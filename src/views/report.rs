//! The results of live or lockstep trials, summarised like the offline evaluation: the JSON that
//! `vic-planner` prints and `vic demo` reads.

use nalgebra::DVector;
use vic_core::cost::Cost;
use vic_plan::montecarlo::Trial;
use vic_plan::plan::Setup;
use vic_rt::central::{Central, TrialRecord};

/// Turns records into the offline simulation's trials (with the realised cost) for
/// [`vic_plan::evaluation::summarize`].
pub(crate) fn to_trials(setup: &Setup, records: &[TrialRecord]) -> Vec<Trial> {
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

/// The trials' recorded states (per trial, per knot) and commands (per trial, per step): what
/// `vic-planner --trajectories` writes and `vic demo` draws. A value that is not finite (a
/// diverged or faulted trial) is `null`.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub(crate) struct Trajectories {
    pub(crate) x: Vec<Vec<Vec<Option<f64>>>>,
    pub(crate) u: Vec<Vec<Vec<Option<f64>>>>,
}

impl Trajectories {
    pub(crate) fn from_records(records: &[TrialRecord]) -> Self {
        let rows = |v: &[DVector<f64>]| {
            v.iter()
                .map(|r| r.iter().map(|e| e.is_finite().then_some(*e)).collect())
                .collect()
        };
        Trajectories {
            x: records.iter().map(|r| rows(&r.x)).collect(),
            u: records.iter().map(|r| rows(&r.u)).collect(),
        }
    }

    /// As the Monte Carlo's trials (`null` as NaN; the cost is not recorded: NaN).
    pub(crate) fn to_trials(&self) -> Vec<Trial> {
        let vecs = |v: &[Vec<Option<f64>>]| {
            v.iter()
                .map(|r| DVector::from_iterator(r.len(), r.iter().map(|e| e.unwrap_or(f64::NAN))))
                .collect()
        };
        self.x
            .iter()
            .zip(&self.u)
            .map(|(x, u)| Trial {
                x: vecs(x),
                u: vecs(u),
                cost: f64::NAN,
            })
            .collect()
    }
}

/// The results of a strategy's trials (the JSON `vic-planner` prints and `vic demo` reads).
/// Errors are over the trials that completed and did not diverge, `None` (`null`) when none did:
/// a diverged trial is counted in `diverged`, never averaged in as a huge number.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct StrategyResult {
    pub(crate) name: String,
    pub(crate) latency_ms: f64,
    pub(crate) sensor_latency_ms: f64,
    pub(crate) command_latency_ms: f64,
    pub trials: usize,
    /// Unit of the errors: "mm" (hand) or "deg" (joint).
    pub(crate) unit: vic_plan::unit::Unit,
    pub(crate) rms_error: Option<f64>,
    pub(crate) final_error_mean: Option<f64>,
    pub final_error_max: Option<f64>,
    /// Final error of every trial (`None`: diverged, stalled or not finite).
    pub final_errors: Vec<Option<f64>>,
    pub(crate) max_error: Option<f64>,
    /// Trials that ended further than the divergence distance from the target, blew up, or
    /// tripped the board's plant guard (a fault); not those cut short by a safe hold or a stall.
    pub diverged: usize,
    /// Trials during which the board fell back to safe hold (commands late or missing).
    pub safe_hold_trials: usize,
    pub fault_trials: usize,
    /// Trials that ended before their final state arrived (time limit, stop, board silent).
    #[serde(default)]
    pub(crate) stalled_trials: usize,
    /// Knots whose feedback used a state older than the latency (all trials).
    pub(crate) stale_feedback: usize,
    pub(crate) missing_states: usize,
    /// Knots whose state came from a later board tick than the knot's (all trials).
    #[serde(default)]
    pub(crate) off_knot_states: usize,
    /// Knots no slice brought to the board before their time (all trials): the board may have
    /// acted on another knot there.
    #[serde(default)]
    pub(crate) late_knots: usize,
    /// Monte Carlo expected cost over the trials that did not diverge.
    pub(crate) expected_cost: Option<f64>,
    /// The central loop's compute time per period and its overruns (all trials).
    #[serde(default)]
    pub(crate) central: vic_rt::central::ComputeTiming,
}

/// How one trial ended, as the report counts it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Outcome {
    Completed,
    Diverged,
    /// Safe hold or stalled: the transport, not the control law, decided the ending.
    Interrupted,
}

/// Summarises records like the offline evaluation does (`divergence` in the report's unit).
pub(crate) fn summarize(
    setup: &Setup,
    central: &Central,
    records: &[TrialRecord],
    divergence: f64,
) -> StrategyResult {
    let trials = to_trials(setup, records);
    let model = &setup.dynamics.model;
    let scale = vic_plan::unit::Unit::for_model(model).scale();
    let steps = setup.reference.len() - 1;
    let target = |k: usize| {
        let mut x = DVector::zeros(model.nx());
        for i in 0..model.dof() {
            x[i] = setup.reference[k].q_d[i];
        }
        vic_plan::montecarlo::position(model, &x)
    };
    let dist = |k: usize, x: &DVector<f64>| {
        vic_plan::montecarlo::position(model, x)
            .iter()
            .zip(target(k))
            .map(|(p, q)| (p - q).powi(2))
            .sum::<f64>()
            .sqrt()
            * scale
    };
    let outcome: Vec<Outcome> = records
        .iter()
        .zip(&trials)
        .map(|(r, t)| {
            let e = dist(steps, &t.x[steps]);
            // A fault is the plant guard catching an arm that left its limits: the control
            // diverged. A safe hold or a stall is the transport's doing, not the law's.
            if r.fault {
                Outcome::Diverged
            } else if r.safe_hold || r.stalled {
                Outcome::Interrupted
            } else if !e.is_finite() || e > divergence {
                Outcome::Diverged
            } else {
                Outcome::Completed
            }
        })
        .collect();
    let kept: Vec<&vic_plan::montecarlo::Trial> = trials
        .iter()
        .zip(&outcome)
        .filter(|(_, o)| **o == Outcome::Completed)
        .map(|(t, _)| t)
        .collect();
    let final_errors: Vec<Option<f64>> = trials
        .iter()
        .zip(&outcome)
        .map(|(t, o)| (*o != Outcome::Diverged).then(|| dist(steps, &t.x[steps])))
        .map(|e| e.filter(|e| e.is_finite()))
        .collect();
    let finals: Vec<f64> = kept.iter().map(|t| dist(steps, &t.x[steps])).collect();
    let count = kept.len() as f64;
    let some = |v: f64| (!kept.is_empty() && v.is_finite()).then_some(v);
    let sq: f64 = kept
        .iter()
        .flat_map(|t| t.x.iter().enumerate().map(|(k, x)| dist(k, x).powi(2)))
        .sum();
    let t = &central.controller.timing;
    StrategyResult {
        name: central.controller.strategy.name().into(),
        latency_ms: t.latency_steps as f64 * central.controller.track.dt_ns as f64 * 1e-6,
        sensor_latency_ms: t.sensor_latency_ns as f64 * 1e-6,
        command_latency_ms: t.command_latency_ns as f64 * 1e-6,
        trials: records.len(),
        unit: vic_plan::unit::Unit::for_model(model),
        rms_error: some((sq / (count * (steps + 1) as f64)).sqrt()),
        final_error_mean: some(finals.iter().sum::<f64>() / count),
        final_error_max: some(finals.iter().copied().fold(0.0, f64::max)),
        final_errors,
        max_error: some(
            kept.iter()
                .flat_map(|t| t.x.iter().enumerate().map(|(k, x)| dist(k, x)))
                .fold(0.0, f64::max),
        ),
        diverged: outcome.iter().filter(|o| **o == Outcome::Diverged).count(),
        safe_hold_trials: records.iter().filter(|r| r.safe_hold).count(),
        fault_trials: records.iter().filter(|r| r.fault).count(),
        stalled_trials: records.iter().filter(|r| r.stalled).count(),
        stale_feedback: records.iter().map(|r| r.stale_feedback).sum(),
        missing_states: records.iter().map(|r| r.missing_states).sum(),
        off_knot_states: records.iter().map(|r| r.off_knot_states).sum(),
        late_knots: records.iter().map(|r| r.late_knots).sum(),
        expected_cost: some(kept.iter().map(|t| t.cost).sum::<f64>() / count),
        central: central.compute_timing(),
    }
}
