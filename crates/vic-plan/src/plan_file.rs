//! The plan file written by `vic plan` and read back by the other commands: the nominal
//! trajectory, the commands, the feedback gains (Eq. 9, or Eq. 13's plant block with a delay) and
//! the headline figures, with the policy that executes it.

use crate::bounded_read::{MAX_PLAN_BYTES, read_text_at_most};
use crate::method::Method;
use crate::scenario::Scenario;
use crate::setup::{PlanError, Setup};
use crate::unit::Unit;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use vic_core::dynamics::Dynamics;
use vic_core::latency::Latency;
use vic_core::model::{Actuator, ArmModel, Exogenous};
use vic_core::policy::Policy;
use vic_core::solver::{Solution, StopReason};

/// Plan-file format version; bumped on incompatible changes.
pub const PLAN_VERSION: u32 = 1;

/// Headline figures of a plan.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct PlanSummary {
    pub method: Method,
    pub converged: bool,
    pub stop: Stop,
    pub iterations: usize,
    /// Cost of the noise-free nominal trajectory.
    pub cost: f64,
    /// Predicted expected cost of the plan's policy.
    pub expected_cost: f64,
    pub solve_ms: f64,
    /// Largest planned stiffness [N m/rad] (0 without a stiffness control).
    pub max_stiffness: f64,
    /// Time-averaged planned stiffness over all joints [N m/rad].
    pub mean_stiffness: f64,
    /// Feedback delay the plan was made for, in steps and ms.
    pub delay_steps: usize,
    pub delay_ms: f64,
    /// Final position error of the nominal trajectory, in `final_error_unit`.
    pub final_error: f64,
    pub final_error_unit: Unit,
    /// Expected cost of executing the plan's commands open loop (gains ignored), by covariance
    /// propagation: the common footing of every method.
    pub open_loop_expected_cost: f64,
    /// Predicted standard deviation of the final position executed open loop, in the unit of
    /// `final_error` (for the arm, the square root of the largest eigenvalue of the hand
    /// covariance).
    pub open_loop_final_std: f64,
    /// SOOC: the convergence criterion's values and tolerances at the plan (`converged` says
    /// whether they were met).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub optimality: Option<vic_core::solver::sooc_newton::Optimality>,
    /// ILQG: the stop tests' values and tolerances at the plan (`converged` says whether one of
    /// them was met; see [`vic_core::solver::Convergence`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub convergence: Option<vic_core::solver::Convergence>,
    /// Total variation of the commands per control channel, `Σ_k |u[k+1] − u[k]|`, in the
    /// channel's unit (`control_names`): how much a plan chatters.
    #[serde(default)]
    pub(crate) total_variation: Vec<f64>,
    /// ILQG without delay, with noise: the knots at which the feedback's predicted standard
    /// deviation in some control exceeds the room to its nearer bound
    /// ([`crate::prediction::ClosedLoopPrediction::clamped_knots`]). Where this is not
    /// 0, `expected_cost` is that of a linear law the clamped plant does not execute (`vic
    /// simulate` measures what it does); `None` for other plans.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub clamped_feedback_knots: Option<usize>,
}

/// `Σ_k |u[k+1]_j − u[k]_j|` for every channel `j` of the command sequence `u`.
pub(crate) fn total_variation(u: &[nalgebra::DVector<f64>]) -> Vec<f64> {
    let nu = u.first().map_or(0, |v| v.len());
    (0..nu)
        .map(|j| u.windows(2).map(|w| (w[1][j] - w[0][j]).abs()).sum())
        .collect()
}

/// A plan as written by `vic plan`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PlanFile {
    pub version: u32,
    /// The scenario file the plan was made from.
    pub scenario: String,
    /// The configuration as resolved (after `--set` overrides).
    pub config: serde_json::Value,
    pub dt: f64,
    /// Knot times `0, Δ, …, N Δ` [s].
    pub time: Vec<f64>,
    pub state_names: Vec<String>,
    pub control_names: Vec<String>,
    /// Nominal states at the knots (the plant's state, without the commands in flight).
    pub x: Vec<Vec<f64>>,
    /// Commands issued at each step (with a delay of d steps, command k acts at step k + d).
    pub u: Vec<Vec<f64>>,
    /// Feedback gains per step, m×n row-major, on the plant state (Eq. 13's block when delayed).
    pub gains: Vec<Vec<Vec<f64>>>,
    /// Reference `q_d`, `q_d'` at the knots [rad, rad/s].
    pub reference: Vec<Exogenous>,
    /// Predicted covariance of the final state executed open loop (n×n, row-major).
    pub(crate) open_loop_final_covariance: Vec<Vec<f64>>,
    /// Predicted covariance of the final hand position [m²] (two-link) or of the final joint
    /// angle [rad²] (single joint, 1×1), executed open loop.
    pub(crate) open_loop_final_position_covariance: Vec<Vec<f64>>,
    pub summary: PlanSummary,
}

/// Why a plan file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum PlanFileError {
    #[error("{}: cannot read: {source}", path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: not a plan file: {source}", path.display())]
    Parse {
        path: PathBuf,
        source: serde_json::Error,
    },
    #[error("{}: {what}", path.display())]
    Shape { path: PathBuf, what: String },
    #[error("cannot write {}: {source}", path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
}

impl PlanFile {
    /// Reads a plan file written by [`PlanFile::write`] (`vic plan --out`); one larger than
    /// [`MAX_PLAN_BYTES`] is refused after reading that much.
    pub fn read(path: &Path) -> Result<PlanFile, PlanFileError> {
        let text = read_text_at_most(path, MAX_PLAN_BYTES, "plan file").map_err(|source| {
            PlanFileError::Read {
                path: path.to_path_buf(),
                source,
            }
        })?;
        let plan: PlanFile =
            serde_json::from_str(&text).map_err(|source| PlanFileError::Parse {
                path: path.to_path_buf(),
                source,
            })?;
        plan.check_shape().map_err(|what| PlanFileError::Shape {
            path: path.to_path_buf(),
            what,
        })?;
        Ok(plan)
    }

    /// The arrays' shapes agree: `time` and `x` have one row more than `u` (when `time` is
    /// given), every row of `x` has one value per state name and every row of `u` one per
    /// control name, and the gains are empty or one m×n matrix per step with every row of
    /// the same length. The message names the first array and row that is wrong.
    fn check_shape(&self) -> Result<(), String> {
        let (nx, nu, steps) = (
            self.state_names.len(),
            self.control_names.len(),
            self.u.len(),
        );
        if self.x.len() != steps + 1 {
            return Err(format!(
                "x has {} rows, u has {steps}: x needs one more",
                self.x.len()
            ));
        }
        if !self.time.is_empty() && self.time.len() != self.x.len() {
            return Err(format!(
                "time has {} values, x has {} rows",
                self.time.len(),
                self.x.len()
            ));
        }
        for (name, rows, width, names) in [
            ("x", &self.x, nx, "state_names"),
            ("u", &self.u, nu, "control_names"),
        ] {
            if let Some((k, row)) = rows.iter().enumerate().find(|(_, r)| r.len() != width) {
                return Err(format!(
                    "{name}[{k}] has {} values, {names} has {width}",
                    row.len()
                ));
            }
        }
        if self.gains.is_empty() {
            return Ok(());
        }
        if self.gains.len() != steps {
            return Err(format!(
                "gains has {} matrices, u has {steps} rows: one per step",
                self.gains.len()
            ));
        }
        let rows = self.gains[0].len();
        let cols = self.gains[0].first().map_or(0, |r| r.len());
        for (k, g) in self.gains.iter().enumerate() {
            if g.len() != rows {
                return Err(format!(
                    "gains[{k}] has {} rows, gains[0] has {rows}",
                    g.len()
                ));
            }
            if let Some((r, row)) = g.iter().enumerate().find(|(_, r)| r.len() != cols) {
                return Err(format!(
                    "gains[{k}] row {r} has {} values, every gain row has {cols} (gains[0] row 0)",
                    row.len()
                ));
            }
        }
        Ok(())
    }

    /// Writes the plan as JSON to `path`.
    pub fn write(&self, path: &Path) -> Result<(), PlanFileError> {
        let write_error = |source| PlanFileError::Write {
            path: path.to_path_buf(),
            source,
        };
        let text = serde_json::to_string(self).map_err(|e| write_error(e.into()))?;
        std::fs::write(path, text).map_err(write_error)
    }
}

/// What executing a command sequence open loop is predicted to give (covariance propagation).
#[derive(Debug, Clone)]
pub struct OpenLoopPrediction {
    /// Expected cost `E[C]` of the open-loop plant.
    pub expected_cost: f64,
    /// Mean states `m_0 ..= m_N`.
    pub mean: Vec<DVector<f64>>,
    /// Final state covariance `P_N`.
    pub final_covariance: DMatrix<f64>,
}

/// Why the solver stopped, as written in plan files (the names of the solver's
/// [`StopReason`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Stop {
    /// SOOC met its optimality criterion (see the summary's `optimality`).
    Converged,
    SmallGradient,
    SmallImprovement,
    MaxIterations,
    RegularizationLimit,
}

impl From<StopReason> for Stop {
    fn from(stop: StopReason) -> Self {
        match stop {
            StopReason::SmallGradient => Stop::SmallGradient,
            StopReason::SmallImprovement => Stop::SmallImprovement,
            StopReason::MaxIterations => Stop::MaxIterations,
            StopReason::RegularizationLimit => Stop::RegularizationLimit,
        }
    }
}

impl From<vic_core::solver::sooc_newton::SoocStop> for Stop {
    fn from(stop: vic_core::solver::sooc_newton::SoocStop) -> Self {
        use vic_core::solver::sooc_newton::SoocStop;
        match stop {
            SoocStop::Converged => Stop::Converged,
            SoocStop::MaxIterations => Stop::MaxIterations,
            SoocStop::RegularizationLimit => Stop::RegularizationLimit,
        }
    }
}

impl std::fmt::Display for Stop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        std::fmt::Debug::fmt(self, f)
    }
}

impl PlanFile {
    /// The policy that executes this plan on the scenario it was made from.
    pub fn policy(&self, setup: &Setup) -> Result<Policy, PlanError> {
        let steps = setup.u_init.len();
        let (nx, nu) = (setup.dynamics.nx(), setup.dynamics.nu());
        if self.u.len() != steps || self.x.len() != steps + 1 {
            return Err(PlanError::StepsMismatch {
                plan: self.u.len(),
                scenario: steps,
            });
        }
        if self.u.iter().any(|u| u.len() != nu) || self.x.iter().any(|x| x.len() != nx) {
            return Err(PlanError::DimensionMismatch { nu, nx });
        }
        let d = self.summary.delay_steps;
        let hold = setup.u_init[0].clone();
        let acting = (0..steps)
            .map(|k| {
                if k < d {
                    hold.clone()
                } else {
                    DVector::from_column_slice(&self.u[k - d])
                }
            })
            .collect();
        let gains = self
            .gains
            .iter()
            .map(|g| {
                let rows = g.len();
                let cols = g.first().map_or(0, |r| r.len());
                DMatrix::from_fn(rows, cols, |r, c| g[r][c])
            })
            .collect::<Vec<_>>();
        let gains = if gains.len() == steps && gains.iter().all(|g| g.shape() == (nu, nx)) {
            gains
        } else {
            vec![DMatrix::zeros(nu, nx); steps]
        };
        Ok(Policy {
            acting,
            nominal: self
                .x
                .iter()
                .map(|x| DVector::from_column_slice(x))
                .collect(),
            gains,
            plan_delay: d,
            bounds: setup.bounds.clone(),
        })
    }
}

pub(crate) fn plan_file(
    s: &Scenario,
    setup: &Setup,
    sol: &Solution,
    d: usize,
    nu: usize,
    method: Method,
    open_loop: &OpenLoopPrediction,
) -> PlanFile {
    let model = &s.model;
    let dof = model.dof();
    let dt = s.task.dt;
    let steps = s.task.steps;
    let (max_stiffness, mean_stiffness) = stiffness_figures(model, sol);
    let last = &sol.x[steps];
    let target = &setup.reference[steps];
    let unit = Unit::for_model(model);
    let final_error = unit.scale()
        * if dof == 1 {
            (last[0] - target.q_d[0]).abs()
        } else {
            let p = model.plant.hand_position(&last.as_slice()[..2]);
            let t = model.plant.hand_position(&target.q_d);
            ((p[0] - t[0]).powi(2) + (p[1] - t[1]).powi(2)).sqrt()
        };
    let (position_cov, open_loop_final_std) =
        final_position_covariance(model, &open_loop.mean[steps], &open_loop.final_covariance);
    PlanFile {
        version: PLAN_VERSION,
        scenario: s.source.display().to_string(),
        config: serde_json::to_value(&s.resolved).unwrap_or(serde_json::Value::Null),
        dt,
        time: (0..=steps).map(|k| k as f64 * dt).collect(),
        state_names: state_names(model),
        control_names: control_names(dof, nu),
        x: sol.x.iter().map(|v| v.iter().copied().collect()).collect(),
        u: sol.u.iter().map(|v| v.iter().copied().collect()).collect(),
        gains: sol
            .gains
            .iter()
            .map(|g| g.row_iter().map(|r| r.iter().copied().collect()).collect())
            .collect(),
        reference: setup.reference.clone(),
        open_loop_final_covariance: rows(&open_loop.final_covariance),
        open_loop_final_position_covariance: rows(&position_cov),
        summary: PlanSummary {
            method,
            converged: sol.stop.converged(),
            stop: sol.stop.into(),
            iterations: sol.iterations,
            cost: sol.cost,
            expected_cost: sol.expected_cost,
            solve_ms: sol.solve_time.as_secs_f64() * 1000.0,
            max_stiffness,
            mean_stiffness,
            delay_steps: d,
            delay_ms: Latency::from_knots(d, dt).ms(),
            final_error,
            final_error_unit: unit,
            open_loop_expected_cost: open_loop.expected_cost,
            open_loop_final_std,
            optimality: None,
            convergence: sol.convergence,
            total_variation: total_variation(&sol.u),
            clamped_feedback_knots: None,
        },
    }
}

/// Largest and time-averaged planned stiffness over all joints [N m/rad] (0 without a stiffness
/// control).
fn stiffness_figures(model: &ArmModel, sol: &Solution) -> (f64, f64) {
    commanded_stiffness(model, &sol.u)
}

/// Largest and mean stiffness of the commands `u` over all joints and knots [N m/rad]: of a plan,
/// or of what trials executed (a replanner's new plans, a feedback law's stiffness). 0 without a
/// stiffness control; commands that are not finite (a diverged trial's) are left out.
pub fn commanded_stiffness<'a>(
    model: &ArmModel,
    u: impl IntoIterator<Item = &'a DVector<f64>>,
) -> (f64, f64) {
    let dof = model.dof();
    let Some(off) = model.actuator.stiffness_offset(dof) else {
        return (0.0, 0.0);
    };
    let (mut max, mut sum, mut n) = (0.0f64, 0.0, 0usize);
    for k in u
        .into_iter()
        .flat_map(|u| u.rows(off, dof).iter().copied().collect::<Vec<_>>())
    {
        if k.is_finite() {
            (max, sum, n) = (max.max(k), sum + k, n + 1);
        }
    }
    (max, if n == 0 { 0.0 } else { sum / n as f64 })
}

/// Names of the plant state's components: `q`, `q_dot` (single joint) or `q1`, `q2`, `q1_dot`,
/// … (arm), then the VSA's motor angles and speeds or a lagged stiffness's realised values.
fn state_names(model: &ArmModel) -> Vec<String> {
    let dof = model.dof();
    let joints: Vec<String> = (1..=dof)
        .map(|i| {
            if dof == 1 {
                "q".to_string()
            } else {
                format!("q{i}")
            }
        })
        .collect();
    let mut state_names: Vec<String> = joints.clone();
    state_names.extend(joints.iter().map(|j| format!("{j}_dot")));
    if matches!(model.actuator, Actuator::Vsa { .. }) {
        let motors: Vec<String> = (1..=dof).map(|i| format!("theta{i}")).collect();
        state_names.extend(motors.clone());
        state_names.extend(motors.iter().map(|m| format!("{m}_dot")));
    }
    if model.actuator.stiffness_state_offset(dof).is_some() {
        // The realised stiffness; the controls k1… are its commands.
        state_names.extend((1..=dof).map(|i| format!("k{i}_realised")));
    }
    state_names
}

/// Names of the controls: torques `tau1…`, then stiffnesses `k1…` when the actuator has them.
fn control_names(dof: usize, nu: usize) -> Vec<String> {
    let mut control_names: Vec<String> = (1..=dof).map(|i| format!("tau{i}")).collect();
    if nu > dof {
        control_names.extend((1..=dof).map(|i| format!("k{i}")));
    }
    control_names
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

/// The covariance of the final position (hand for the arm, `J P_qq Jᵀ`; joint angle for a single
/// joint) and its largest standard deviation in the model's [`Unit`].
pub fn final_position_covariance(
    model: &ArmModel,
    mean: &DVector<f64>,
    cov: &DMatrix<f64>,
) -> (DMatrix<f64>, f64) {
    if model.dof() == 1 {
        let c = DMatrix::from_element(1, 1, cov[(0, 0)]);
        (c, cov[(0, 0)].max(0.0).sqrt() * Unit::Degree.scale())
    } else {
        let j = model.plant.jacobian(&mean.as_slice()[..2]);
        let jm = DMatrix::from_row_slice(2, 2, &[j[0][0], j[0][1], j[1][0], j[1][1]]);
        let pq = cov.view((0, 0), (2, 2));
        let c = &jm * pq * jm.transpose();
        let (tr, det) = (
            c[(0, 0)] + c[(1, 1)],
            c[(0, 0)] * c[(1, 1)] - c[(0, 1)] * c[(1, 0)],
        );
        let largest = 0.5 * (tr + (tr * tr - 4.0 * det).max(0.0).sqrt());
        (c, largest.max(0.0).sqrt() * Unit::Millimetre.scale())
    }
}

#[cfg(test)]
mod tests {
    use super::total_variation;
    use nalgebra::DVector;

    #[test]
    fn total_variation_sums_absolute_changes_per_channel() {
        let u: Vec<DVector<f64>> = [[0.0, 5.0], [2.0, 5.0], [-1.0, 6.0], [-1.0, 4.0]]
            .iter()
            .map(|r| DVector::from_column_slice(r))
            .collect();
        // Channel 0: 2 + 3 + 0; channel 1: 0 + 1 + 2.
        assert_eq!(total_variation(&u), vec![5.0, 3.0]);
        assert!(total_variation(&u[..1]).iter().all(|&v| v == 0.0));
        assert!(total_variation(&[]).is_empty());
    }
}
