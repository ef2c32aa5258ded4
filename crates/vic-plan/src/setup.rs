//! Everything needed to solve a scenario with any method: the Eq. 10 discrete model, the Eq. 14
//! cost, the start state and a warm start from inverse dynamics.

use crate::reference::{self, PathError};
use crate::scenario::{Scenario, Task, TaskPath};
use nalgebra::DVector;
use vic_core::cost::TrackingCost;
use vic_core::delay::Delayed;
use vic_core::dynamics::DiscreteDynamics;
use vic_core::model::{Actuator, ArmModel, Exogenous};
use vic_core::solver::{Bounds, Problem};

/// Why a scenario cannot be planned, or a plan not executed on it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// The hand path of the task cannot be followed.
    #[error("{0}")]
    Path(#[from] PathError),
    /// A VSA's warm start puts the spring at the motor angle that delivers the torque: it needs a
    /// spring.
    #[error("a VSA plan needs [actuator] initial_stiffness > 0")]
    VsaWithoutStiffness,
    /// A plan file read back for a scenario it was not made from.
    #[error("the plan has {plan} steps, the scenario {scenario}: plan and scenario do not match")]
    StepsMismatch { plan: usize, scenario: usize },
    #[error("the plan's controls/states are not {nu}/{nx}-dimensional like the scenario's")]
    DimensionMismatch { nu: usize, nx: usize },
    /// ILQG could not start or failed in one of its phases (`deterministic`, `stochastic`,
    /// `ilqg`: see `plan::solve_in_phases`).
    #[error("ILQG ({phase} phase): {source}")]
    Ilqg {
        phase: &'static str,
        source: vic_core::solver::IlqgError,
    },
    /// SOOC was given no stage of noise continuation (the scenario's validation refuses this).
    #[error("SOOC needs at least one noise continuation stage")]
    NoContinuationStage,
    /// SOOC could not start or failed at one stage of the noise continuation.
    #[error("SOOC at noise fraction {fraction}: {source}")]
    Sooc {
        fraction: f64,
        source: vic_core::solver::sooc_newton::SoocError,
    },
}

/// Everything needed to solve a scenario with any method.
#[derive(Debug, Clone)]
pub struct Setup {
    pub dynamics: DiscreteDynamics,
    pub cost: TrackingCost,
    /// Initial state x₀ (start posture at rest; a lagged stiffness settled at the initial
    /// stiffness).
    pub x0: Vec<f64>,
    /// Initial guess: inverse dynamics along the reference with the configured initial stiffness.
    pub u_init: Vec<DVector<f64>>,
    pub bounds: Bounds,
    pub reference: Vec<Exogenous>,
}

impl Setup {
    /// The undelayed planning problem of `horizon` steps from x₀.
    pub fn problem(&self, horizon: usize) -> Problem<'_> {
        Problem {
            dynamics: &self.dynamics,
            cost: &self.cost,
            x0: self.x0.clone(),
            horizon,
            bounds: self.bounds.clone(),
        }
    }

    /// The same movement `shift` knots later, for a receding horizon of the same length: from
    /// `x0` (the state reached at knot `shift`), the reference, the exogenous inputs and the warm
    /// start advanced by `shift` knots and held at their last value past the end.
    pub fn shifted(&self, shift: usize, x0: &[f64]) -> Setup {
        fn advance<T: Clone>(v: &mut Vec<T>, shift: usize) {
            let Some(last) = v.last().cloned() else {
                return;
            };
            let s = shift.min(v.len());
            v.drain(..s);
            v.extend(std::iter::repeat_n(last, s));
        }
        let mut next = self.clone();
        advance(&mut next.reference, shift);
        advance(&mut next.dynamics.exogenous, shift);
        advance(&mut next.cost.reference, shift);
        advance(&mut next.u_init, shift);
        next.x0 = x0.to_vec();
        next
    }

    /// The rest of the movement from knot `k0` on (`k0` knots fewer), from `x0`: what the
    /// central controller's replanner re-solves (`vic_core::replan`), with the warm start's tail.
    pub fn remaining(&self, k0: usize, x0: &[f64]) -> Setup {
        let mut rest = self.clone();
        let keep_last = |len: usize| k0.min(len.saturating_sub(1));
        rest.reference.drain(..keep_last(rest.reference.len()));
        rest.dynamics
            .exogenous
            .drain(..keep_last(rest.dynamics.exogenous.len()));
        rest.cost
            .reference
            .drain(..keep_last(rest.cost.reference.len()));
        rest.u_init.drain(..k0.min(rest.u_init.len()));
        rest.x0 = x0.to_vec();
        rest
    }

    /// The plant augmented with `d` steps of commands in flight (Eq. 11–13) and its cost, the
    /// commands in flight at the start all equal to the warm start's first.
    pub fn delayed(&self, d: usize) -> DelayedPlant<'_> {
        let dynamics = Delayed::new(self.dynamics.clone(), d);
        let x0 = dynamics.initial_state(&self.x0, self.u_init[0].as_slice());
        DelayedPlant {
            dynamics,
            cost: DelayedCost::new(&self.cost, self.x0.len()),
            x0,
            bounds: self.bounds.clone(),
        }
    }
}

/// A scenario's delay-augmented plant, its cost and start state ([`Setup::delayed`]), owned so
/// that its [`Problem`] can borrow them.
pub struct DelayedPlant<'a> {
    pub dynamics: Delayed<DiscreteDynamics>,
    pub cost: DelayedCost<'a>,
    pub x0: Vec<f64>,
    bounds: Bounds,
}

impl DelayedPlant<'_> {
    /// The delayed planning problem of `horizon` steps.
    pub fn problem(&self, horizon: usize) -> Problem<'_> {
        Problem {
            dynamics: &self.dynamics,
            cost: &self.cost,
            x0: self.x0.clone(),
            horizon,
            bounds: self.bounds.clone(),
        }
    }
}

/// The cost of the plain plant applied to the plant block of a delay-augmented state.
pub struct DelayedCost<'a> {
    inner: &'a TrackingCost,
    nx: usize,
}

impl<'a> DelayedCost<'a> {
    /// Wraps `inner`, a cost on the first `nx` components of the state.
    pub fn new(inner: &'a TrackingCost, nx: usize) -> Self {
        DelayedCost { inner, nx }
    }
}

impl vic_core::cost::Cost for DelayedCost<'_> {
    fn running(&self, k: usize, x: &[f64], u: &[f64]) -> f64 {
        self.inner.running(k, &x[..self.nx], u)
    }
    fn terminal(&self, x: &[f64]) -> f64 {
        self.inner.terminal(&x[..self.nx])
    }
    fn running_derivatives(
        &self,
        k: usize,
        x: &[f64],
        u: &[f64],
        d: &mut vic_core::cost::CostDerivatives,
    ) {
        // The augmented derivatives are zero outside the plant block. The tracking cost clears
        // every entry it is given and writes only the joint angles and velocities (the first
        // 2·dof components), so it fills the augmented derivatives in place, without a copy
        // (and without allocating in the solver's iterations).
        debug_assert!(self.inner.nx <= x.len());
        self.inner.running_derivatives(k, x, u, d);
    }
    fn running_derivatives_again(
        &self,
        k: usize,
        x: &[f64],
        u: &[f64],
        d: &mut vic_core::cost::CostDerivatives,
    ) {
        self.inner.running_derivatives_again(k, x, u, d);
    }
    fn terminal_derivatives(&self, x: &[f64], d: &mut vic_core::cost::CostDerivatives) {
        self.inner.terminal_derivatives(x, d);
    }
    fn hessian_support(&self) -> Option<std::ops::Range<usize>> {
        // The plant's components: the commands in flight cost nothing.
        self.inner.hessian_support()
    }
    fn nonnegative(&self) -> bool {
        self.inner.nonnegative()
    }
}

/// Builds the discrete model, the cost, the start state and the warm start of a scenario.
pub fn setup(s: &Scenario) -> Result<Setup, PlanError> {
    let model = &s.model;
    let (dof, nx, nu) = (model.dof(), model.nx(), model.nu());
    let task = &s.task;
    let reference = reference_of(task, model)?;
    let tau = inverse_dynamics(model, task, &reference);
    let mut x0 = vec![0.0; nx];
    x0[..dof].copy_from_slice(&reference[0].q_d[..dof]);
    let u_init = warm_start(s, &reference, &tau, &mut x0)?;
    let mut control_weights = vec![s.weights.w_torque; dof];
    control_weights.extend(std::iter::repeat_n(s.weights.w_stiffness, nu - dof));
    let cost = TrackingCost {
        dof,
        nx,
        control_weights,
        w_p: s.weights.w_p,
        w_v: s.weights.w_v,
        dt: task.dt,
        reference: reference.clone(),
    };
    let dynamics = DiscreteDynamics {
        model: model.clone(),
        dt: task.dt,
        substeps: task.substeps,
        integrator: task.integrator,
        exogenous: reference.clone(),
    };
    Ok(Setup {
        dynamics,
        cost,
        x0,
        u_init,
        bounds: s.bounds.clone(),
        reference,
    })
}

/// The reference `q_d`, `q_d'` at the knots `0..=N`.
fn reference_of(task: &Task, model: &ArmModel) -> Result<Vec<Exogenous>, PathError> {
    let steps = task.steps;
    Ok(match &task.path {
        TaskPath::Joint { start, target } => {
            reference::joint_minimum_jerk(start, target, task.duration, task.dt, steps)
        }
        TaskPath::Hand { start, target } => reference::hand_straight_line(
            &model.plant,
            *start,
            *target,
            task.duration,
            task.dt,
            steps,
        )?,
    })
}

/// Joint torques along the reference by inverse dynamics (`q''` by central differences of `q_d'`).
fn inverse_dynamics(model: &ArmModel, task: &Task, reference: &[Exogenous]) -> Vec<[f64; 2]> {
    let (dof, steps) = (model.dof(), task.steps);
    let qdd = |k: usize, i: usize| {
        let (a, b) = (k.saturating_sub(1), (k + 1).min(steps));
        (reference[b].qd_d[i] - reference[a].qd_d[i]) / ((b - a) as f64 * task.dt)
    };
    (0..=steps)
        .map(|k| {
            let r = &reference[k];
            let acc = [qdd(k, 0), if dof > 1 { qdd(k, 1) } else { 0.0 }];
            model.inverse_dynamics(&r.q_d[..dof], &r.qd_d[..dof], &acc[..dof])
        })
        .collect()
}

/// The solver's initial guess: the torques `tau` with the configured initial stiffness; for a VSA
/// the motor torques that move the motors to where the springs deliver `tau` (which also sets the
/// motor angles of `x0`).
fn warm_start(
    s: &Scenario,
    reference: &[Exogenous],
    tau: &[[f64; 2]],
    x0: &mut [f64],
) -> Result<Vec<DVector<f64>>, PlanError> {
    let model = &s.model;
    let (dof, nu, steps, dt) = (model.dof(), model.nu(), s.task.steps, s.task.dt);
    let k0 = s.initial_stiffness;
    if let Some(off) = model.actuator.stiffness_state_offset(dof) {
        // The mechanism has settled at the stiffness the plan starts from.
        x0[off..off + dof].fill(k0);
    }
    Ok(match &model.actuator {
        Actuator::Torque => (0..steps)
            .map(|k| DVector::from_column_slice(&tau[k][..dof]))
            .collect(),
        Actuator::Impedance { .. } | Actuator::ImpedanceLag { .. } => (0..steps)
            .map(|k| {
                let mut u = DVector::from_element(nu, k0);
                u.rows_mut(0, dof).copy_from_slice(&tau[k][..dof]);
                u
            })
            .collect(),
        Actuator::Vsa { motor_inertia } => {
            if k0 <= 0.0 {
                return Err(PlanError::VsaWithoutStiffness);
            }
            let theta: Vec<[f64; 2]> = (0..=steps)
                .map(|k| {
                    let mut t = [0.0; 2];
                    for i in 0..dof {
                        t[i] = reference[k].q_d[i] + tau[k][i] / k0;
                    }
                    t
                })
                .collect();
            for i in 0..dof {
                x0[2 * dof + i] = theta[0][i];
            }
            (0..steps)
                .map(|k| {
                    let mut u = DVector::from_element(nu, k0);
                    for i in 0..dof {
                        let (a, b) = (k.saturating_sub(1), (k + 1).min(steps));
                        let acc = if b - a == 2 {
                            (theta[b][i] - 2.0 * theta[k][i] + theta[a][i]) / (dt * dt)
                        } else {
                            0.0
                        };
                        u[i] = motor_inertia[i] * acc + tau[k][i];
                    }
                    u
                })
                .collect()
        }
    })
}

#[cfg(test)]
mod tests {
    use super::setup;
    use crate::scenario::Scenario;
    use std::path::Path;

    /// Every knot-indexed input of the shifted setup is the original's `shift` knots later, the
    /// last one held past the end, and the start is the given state; the remaining movement is
    /// the original's tail.
    #[test]
    fn shifted_and_remaining_setups_read_the_original_later() {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/two_link_divergent.toml");
        let s = Scenario::load(&path, &[]).expect("scenario loads");
        let original = setup(&s).expect("scenario sets up");
        let x0 = [0.1, 0.2, 0.3, 0.4];
        for shift in [0, 2, 7] {
            let next = original.shifted(shift, &x0);
            assert_eq!(next.x0, x0);
            let at = |k: usize, len: usize| (k + shift).min(len - 1);
            for k in 0..original.u_init.len() {
                let n = original.u_init.len();
                assert_eq!(next.u_init[k], original.u_init[at(k, n)], "u_init[{k}]");
            }
            for (name, got, want) in [
                ("reference", &next.reference, &original.reference),
                (
                    "exogenous",
                    &next.dynamics.exogenous,
                    &original.dynamics.exogenous,
                ),
                (
                    "cost reference",
                    &next.cost.reference,
                    &original.cost.reference,
                ),
            ] {
                assert_eq!(got.len(), want.len(), "{name}");
                for k in 0..got.len() {
                    assert_eq!(
                        got[k],
                        want[at(k, want.len())],
                        "{name}[{k}], shift {shift}"
                    );
                }
            }
        }
        assert_ne!(
            original.reference[0], original.reference[7],
            "a reference that moves"
        );
    }
}
