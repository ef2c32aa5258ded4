//! Monte Carlo execution of a plan on the stochastic plant (Euler–Maruyama, paper Eq. 10), with
//! the policies the paper compares: open loop, full feedback, and feedback that arrives late.
//!
//! Every trial has its own random stream derived from `(seed, trial)`, so the results do not
//! depend on how many threads run the trials or in which order.

use crate::plan::Setup;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use vic_core::dynamics::{DiscreteDynamics, Dynamics};
use vic_core::policy::{Feedback, Policy};
use vic_core::replan::{Executor, ReplanOptions, Replanner};
use vic_core::rng::{add_diffusion, trial_rng};

/// One simulated movement.
#[derive(Debug, Clone)]
pub struct Trial {
    pub x: Vec<DVector<f64>>,
    pub u: Vec<DVector<f64>>,
    /// Realised cost (Eq. 14 on this trajectory).
    pub cost: f64,
}

/// A torque pulse on the plant that the controller does not know of: `torque` [N m per joint]
/// from `start` for `duration` [s] (the sweep's disturbance-rejection variant; the same pulse
/// for every strategy).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Pulse {
    pub torque: [f64; 2],
    pub start: f64,
    pub duration: f64,
}

impl Pulse {
    /// The plant of `dynamics` with the pulse added to the external torque of the knots whose
    /// step starts inside it (a step acts over `[kΔ, (k+1)Δ)`).
    pub fn apply(&self, dynamics: &DiscreteDynamics) -> DiscreteDynamics {
        let mut plant = dynamics.clone();
        let dt = plant.dt;
        for (k, e) in plant.exogenous.iter_mut().enumerate() {
            let t = k as f64 * dt;
            if t + 1e-9 >= self.start && t + 1e-9 < self.start + self.duration {
                for (tau, p) in e.tau_ext.iter_mut().zip(self.torque) {
                    *tau += p;
                }
            }
        }
        plant
    }
}

/// What a trial executes: `policy` with `feedback`, or for [`Feedback::Replan`] a replanner of
/// the policy on the controller's model (the plan's, `setup.dynamics`).
pub(crate) fn executor<'a>(setup: &Setup, policy: &'a Policy, feedback: Feedback) -> Executor<'a> {
    match feedback {
        Feedback::Replan { .. } => Executor::Replan(Box::new(Replanner::new(
            policy,
            &setup.dynamics,
            &setup.cost,
            ReplanOptions::at_50_hz(setup.dynamics.dt),
        ))),
        _ => Executor::Plan { policy, feedback },
    }
}

/// Simulates one trial of `exec` on the stochastic `plant` (Euler–Maruyama, Eq. 10); the
/// controller predicts with its own `model` (the plant without the disturbances it cannot know).
#[allow(clippy::too_many_arguments)]
pub fn run_trial_on(
    plant: &DiscreteDynamics,
    model: &DiscreteDynamics,
    cost: &dyn vic_core::cost::Cost,
    x0: &[f64],
    exec: &mut Executor<'_>,
    feedback: Feedback,
    seed: u64,
    trial: u64,
) -> Trial {
    let (nx, nw) = (plant.nx(), plant.nw());
    let steps = model.exogenous.len() - 1;
    let mut rng = trial_rng(seed, trial);
    let mut x = vec![DVector::from_column_slice(x0)];
    let mut us = Vec::with_capacity(steps);
    let mut g = DMatrix::zeros(nx, nw);
    let mut predicted = DVector::zeros(nx);
    let mut total = 0.0;
    for k in 0..steps {
        let mut u = DVector::zeros(plant.nu());
        let seen = feedback.seen_knot(k);
        exec.command_into(
            model,
            k,
            seen.map(|j| (j, x[j].as_slice())),
            us[seen.unwrap_or(k)..k]
                .iter()
                .map(|u: &DVector<f64>| u.as_slice()),
            predicted.as_mut_slice(),
            u.as_mut_slice(),
        );
        let mut next = DVector::zeros(nx);
        plant.step(k, x[k].as_slice(), u.as_slice(), next.as_mut_slice());
        if nw > 0 {
            plant.noise_gain(k, x[k].as_slice(), u.as_slice(), &mut g);
            add_diffusion(next.as_mut_slice(), g.as_slice(), nx, nw, &mut rng);
        }
        total += cost.running(k, x[k].as_slice(), u.as_slice());
        x.push(next);
        us.push(u);
    }
    total += cost.terminal(x[steps].as_slice());
    Trial {
        x,
        u: us,
        cost: total,
    }
}

/// Runs `trials` trials in parallel (results independent of the thread count).
pub fn run_trials(
    setup: &Setup,
    policy: &Policy,
    feedback: Feedback,
    trials: usize,
    seed: u64,
) -> Vec<Trial> {
    run_trials_disturbed(setup, policy, feedback, None, trials, seed)
}

/// [`run_trials`] with an optional torque `pulse` on the plant, unknown to the controller.
pub fn run_trials_disturbed(
    setup: &Setup,
    policy: &Policy,
    feedback: Feedback,
    pulse: Option<&Pulse>,
    trials: usize,
    seed: u64,
) -> Vec<Trial> {
    let plant = pulse.map_or_else(|| setup.dynamics.clone(), |p| p.apply(&setup.dynamics));
    (0..trials as u64)
        .into_par_iter()
        .map(|t| {
            let mut exec = executor(setup, policy, feedback);
            run_trial_on(
                &plant,
                &setup.dynamics,
                &setup.cost,
                &setup.x0,
                &mut exec,
                feedback,
                seed,
                t,
            )
        })
        .collect()
}

/// Sample mean and covariance of the final state over trials (n×n, unbiased).
pub fn final_state_statistics(trials: &[Trial]) -> (DVector<f64>, DMatrix<f64>) {
    let n = trials[0].x.last().map_or(0, |x| x.len());
    let count = trials.len() as f64;
    let mut mean = DVector::zeros(n);
    for t in trials {
        mean += t.x.last().expect("non-empty");
    }
    mean /= count;
    let mut cov = DMatrix::zeros(n, n);
    for t in trials {
        let d = t.x.last().expect("non-empty") - &mean;
        cov.ger(1.0, &d, &d, 1.0);
    }
    cov /= (count - 1.0).max(1.0);
    (mean, cov)
}

/// Position of the "end effector" in the units reports use: the hand [m] for the arm, the joint
/// angle [rad] (as a 1-vector) for a single joint.
pub fn position(model: &vic_core::model::ArmModel, x: &DVector<f64>) -> Vec<f64> {
    if model.dof() == 1 {
        vec![x[0]]
    } else {
        model.plant.hand_position(&x.as_slice()[..2]).to_vec()
    }
}
