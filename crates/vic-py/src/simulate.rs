//! `vic.simulate` (the Monte Carlo of `vic simulate`) and `vic.sweep_latency` (`vic sweep
//! latency`, offline or in lockstep).

use crate::convert::{array, json_to_py};
use crate::errors::{Failure, detached};
use crate::plan::{Plan, latency_of};
use crate::scenario::Scenario;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use vic::studies::sweep::{Engine, Pulse, Strategy, SweepError, SweepOptions};
use vic_plan::evaluation::summarize;
use vic_plan::montecarlo::run_trials;
use vic_plan::plan::setup;
use vic_plan::strategy::{Feedback, Latency};
use vic_plan::unit::Unit;

/// The command line's ranges: trials per run, the divergence threshold, a pulse's torque [N m]
/// and duration [ms].
const MAX_TRIALS: usize = 100_000;
const MAX_DIVERGENCE: f64 = 100_000.0;
const MAX_TORQUE_NM: f64 = 200.0;
const MAX_PULSE_MS: f64 = 10_000.0;

/// The policies of `vic simulate --policy`, and the strategy each executes as (`None`: no
/// latency enters; `open-loop` and `feedback`).
const POLICIES: [(&str, Option<Strategy>); 8] = [
    ("open-loop", None),
    ("feedback", None),
    ("naive-delayed", Some(Strategy::NaiveDelayed)),
    ("delayed-feedback", Some(Strategy::NaiveDelayed)),
    ("predictor", Some(Strategy::Predictor)),
    ("stiffness", Some(Strategy::Stiffness)),
    ("stiffness+predictor", Some(Strategy::StiffnessPredictor)),
    ("replan", Some(Strategy::Replan)),
];

fn check_trials(trials: usize) -> PyResult<()> {
    if (2..=MAX_TRIALS).contains(&trials) {
        Ok(())
    } else {
        Err(PyValueError::new_err(format!(
            "trials={trials}: 2 to {MAX_TRIALS} (a spread needs two)"
        )))
    }
}

fn check_divergence(divergence: Option<f64>) -> PyResult<()> {
    match divergence {
        Some(d) if !(d.is_finite() && (0.001..=MAX_DIVERGENCE).contains(&d)) => {
            Err(PyValueError::new_err(format!(
                "divergence={d}: 0.001 to {MAX_DIVERGENCE} (mm for the arm, degrees for a joint)"
            )))
        }
        _ => Ok(()),
    }
}

/// How `policy` at `latency_ms` executes `plan` on a grid of `dt` s, as `vic simulate` does:
/// the naive law's latency defaults to the plan's delay (its gains were made for it), the
/// others' to 0.
fn feedback_of(policy: &str, latency_ms: Option<f64>, plan: &Plan, dt: f64) -> PyResult<Feedback> {
    let Some(&(_, strategy)) = POLICIES.iter().find(|(name, _)| *name == policy) else {
        let names: Vec<&str> = POLICIES.iter().map(|(n, _)| *n).collect();
        return Err(PyValueError::new_err(format!(
            "policy {policy:?}: one of {}",
            names.join(", ")
        )));
    };
    let Some(strategy) = strategy else {
        return Ok(if policy == "feedback" {
            Feedback::Full
        } else {
            Feedback::OpenLoop
        });
    };
    let latency = match (latency_ms, strategy) {
        (Some(ms), _) => latency_of("latency_ms", ms, dt)?,
        (None, Strategy::NaiveDelayed) => Latency::from_knots(plan.file.summary.delay_steps, dt),
        (None, _) => Latency::ZERO,
    };
    Ok(strategy.feedback(latency.knots()))
}

/// Runs `trials` trials of `plan` on `scenario` (`vic simulate`): the trials' states, commands
/// and costs as arrays and the summary `vic simulate --json` prints.
#[pyfunction]
#[pyo3(signature = (scenario, plan, policy = "open-loop", trials = 20, seed = 1, latency_ms = None, divergence = None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn simulate<'py>(
    py: Python<'py>,
    scenario: PyRef<'py, Scenario>,
    plan: PyRef<'py, Plan>,
    policy: &str,
    trials: usize,
    seed: u64,
    latency_ms: Option<f64>,
    divergence: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    check_trials(trials)?;
    check_divergence(divergence)?;
    let s = &scenario.inner;
    let feedback = feedback_of(policy, latency_ms, &plan, s.task.dt)?;
    let file = &plan.file;
    let (trials_run, summary) = detached(py, move || {
        let fail = |e: vic_plan::plan::PlanError| {
            Failure::Plan(format!("the plan on {}: {e}", s.source.display()))
        };
        let setup = setup(s).map_err(fail)?;
        let policy = file.policy(&setup).map_err(fail)?;
        let divergence = divergence
            .unwrap_or_else(|| Unit::for_model(&setup.dynamics.model).default_divergence());
        let trials_run = run_trials(&setup, &policy, feedback, trials, seed);
        let report = summarize(&setup, &trials_run, divergence);
        let predicted = vic_plan::prediction::predicted_cost(&setup, &policy, feedback)
            .unwrap_or(file.summary.expected_cost);
        let json = || -> serde_json::Result<serde_json::Value> {
            let mut v = serde_json::to_value(&report)?;
            v["policy"] = serde_json::to_value(feedback)?;
            v["expected_cost_predicted"] = predicted.into();
            v["seed"] = seed.into();
            Ok(v)
        };
        let summary = json().map_err(|e| Failure::Value(e.to_string()))?;
        Ok((trials_run, summary))
    })?;
    let (n, nx, nu) = (
        file.u.len(),
        file.state_names.len(),
        file.control_names.len(),
    );
    let x: Vec<f64> = trials_run
        .iter()
        .flat_map(|t| t.x.iter().flat_map(|v| v.iter().copied()))
        .collect();
    let u: Vec<f64> = trials_run
        .iter()
        .flat_map(|t| t.u.iter().flat_map(|v| v.iter().copied()))
        .collect();
    let cost: Vec<f64> = trials_run.iter().map(|t| t.cost).collect();
    let out = PyDict::new(py);
    out.set_item("x", array(py, &[trials, n + 1, nx], &x)?)?;
    out.set_item("u", array(py, &[trials, n, nu], &u)?)?;
    out.set_item("cost", array(py, &[trials], &cost)?)?;
    out.set_item("summary", json_to_py(py, &summary)?)?;
    Ok(out)
}

/// The sweep of `vic sweep latency` on the scenario's file and overrides: the JSON it prints.
#[pyfunction]
#[pyo3(signature = (scenario, latencies_ms, strategies, trials = 20, seed = 1, divergence = None, pulse = None, pulse_at_ms = 400.0, pulse_ms = 50.0, engine = "offline"))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn sweep_latency<'py>(
    py: Python<'py>,
    scenario: PyRef<'py, Scenario>,
    latencies_ms: Vec<f64>,
    strategies: Vec<String>,
    trials: usize,
    seed: u64,
    divergence: Option<f64>,
    pulse: Option<Vec<f64>>,
    pulse_at_ms: f64,
    pulse_ms: f64,
    engine: &str,
) -> PyResult<Bound<'py, PyAny>> {
    check_trials(trials)?;
    check_divergence(divergence)?;
    if latencies_ms.is_empty() || strategies.is_empty() {
        return Err(PyValueError::new_err(
            "latencies_ms and strategies need at least one entry each",
        ));
    }
    for &ms in &latencies_ms {
        latency_of("latencies_ms", ms, scenario.inner.task.dt)?;
    }
    let strategies = strategies
        .iter()
        .map(|name| {
            Strategy::from_name(name).map_err(|_| {
                let all: Vec<&str> = Strategy::ALL.iter().map(|s| s.name()).collect();
                PyValueError::new_err(format!("strategy {name:?}: one of {}", all.join(", ")))
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    let execution = match engine {
        "offline" => Engine::Offline,
        "lockstep" => Engine::Lockstep,
        other => {
            return Err(PyValueError::new_err(format!(
                "engine {other:?}: \"offline\" (the Monte Carlo) or \"lockstep\" (the board and \
                 the central controller on a simulated clock); the live daemons run from `vic \
                 sweep latency --live`"
            )));
        }
    };
    let pulse = pulse_of(pulse, pulse_at_ms, pulse_ms)?;
    let opts = SweepOptions {
        latencies_ms,
        strategies,
        trials,
        seed,
        divergence,
        pulse,
        execution,
    };
    let (path, overrides) = (scenario.source().to_path_buf(), scenario.overrides.clone());
    let result = detached(py, move || {
        Ok(vic::studies::sweep::sweep_latency(
            &path,
            &overrides,
            &opts,
            &|_| {},
        ))
    })?;
    let sweep = result.map_err(|e| match e {
        SweepError::Config(c) => Failure::Config(c).into_py_err(py),
        e if e.is_input() => PyValueError::new_err(e.to_string()),
        e => Failure::Plan(e.to_string()).into_py_err(py),
    })?;
    let v = serde_json::to_value(&sweep).map_err(|e| PyValueError::new_err(e.to_string()))?;
    json_to_py(py, &v)
}

/// The pulse of `pulse` [N m, one per joint], `pulse_at_ms` and `pulse_ms` (`vic sweep latency
/// --pulse T1[,T2] --pulse-at-ms --pulse-ms`).
fn pulse_of(torque: Option<Vec<f64>>, at_ms: f64, ms: f64) -> PyResult<Option<Pulse>> {
    let Some(torque) = torque else {
        return Ok(None);
    };
    let torque_ok = (1..=2).contains(&torque.len())
        && torque
            .iter()
            .all(|t| t.is_finite() && t.abs() <= MAX_TORQUE_NM);
    if !torque_ok {
        return Err(PyValueError::new_err(format!(
            "pulse={torque:?}: one or two torques [N m], each within ±{MAX_TORQUE_NM}"
        )));
    }
    if !(at_ms.is_finite() && (0.0..=60_000.0).contains(&at_ms)) {
        return Err(PyValueError::new_err(format!(
            "pulse_at_ms={at_ms}: 0 to 60000 ms after the start"
        )));
    }
    if !(ms.is_finite() && (0.001..=MAX_PULSE_MS).contains(&ms)) {
        return Err(PyValueError::new_err(format!(
            "pulse_ms={ms}: 0.001 to {MAX_PULSE_MS} ms"
        )));
    }
    Ok(Some(Pulse {
        torque: [torque[0], torque.get(1).copied().unwrap_or(0.0)],
        start: at_ms * 1e-3,
        duration: ms * 1e-3,
    }))
}
