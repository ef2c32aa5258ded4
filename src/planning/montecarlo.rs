//! Monte Carlo execution of a plan on the stochastic plant (Euler–Maruyama, paper Eq. 10), with
//! the policies the paper compares: open loop, full feedback, and feedback that arrives late.
//!
//! Every trial has its own random stream derived from `(seed, trial)`, so the results do not
//! depend on how many threads run the trials or in which order.

use crate::core::dynamics::{DiscreteDynamics, Dynamics};
use crate::core::policy::{Feedback, Policy};
use crate::core::rng::{add_diffusion, trial_rng};
use crate::planning::plan::Setup;
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// One simulated movement.
#[derive(Debug, Clone)]
pub struct Trial {
    pub x: Vec<DVector<f64>>,
    pub u: Vec<DVector<f64>>,
    /// Realised cost (Eq. 14 on this trajectory).
    pub cost: f64,
}

/// Simulates one trial of `policy` with `feedback` on the stochastic plant (Euler–Maruyama,
/// Eq. 10).
pub fn run_trial(
    dynamics: &DiscreteDynamics,
    cost: &dyn crate::core::cost::Cost,
    x0: &[f64],
    policy: &Policy,
    feedback: Feedback,
    seed: u64,
    trial: u64,
) -> Trial {
    let (nx, nw) = (dynamics.nx(), dynamics.nw());
    let steps = policy.steps();
    let mut rng = trial_rng(seed, trial);
    let mut x = vec![DVector::from_column_slice(x0)];
    let mut us = Vec::with_capacity(steps);
    let mut g = DMatrix::zeros(nx, nw);
    let mut predicted = DVector::zeros(nx);
    let mut total = 0.0;
    for k in 0..steps {
        let mut u = DVector::zeros(policy.nu());
        let seen = feedback.seen_knot(k);
        policy.command_into(
            dynamics,
            k,
            feedback,
            seen.map(|j| (j, x[j].as_slice())),
            us[seen.unwrap_or(k)..k]
                .iter()
                .map(|u: &DVector<f64>| u.as_slice()),
            predicted.as_mut_slice(),
            u.as_mut_slice(),
        );
        let mut next = DVector::zeros(nx);
        dynamics.step(k, x[k].as_slice(), u.as_slice(), next.as_mut_slice());
        if nw > 0 {
            dynamics.noise_gain(k, x[k].as_slice(), u.as_slice(), &mut g);
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
    (0..trials as u64)
        .into_par_iter()
        .map(|t| {
            run_trial(
                &setup.dynamics,
                &setup.cost,
                &setup.x0,
                policy,
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
pub fn position(model: &crate::core::model::ArmModel, x: &DVector<f64>) -> Vec<f64> {
    if model.dof() == 1 {
        vec![x[0]]
    } else {
        model.plant.hand_position(&x.as_slice()[..2]).to_vec()
    }
}
