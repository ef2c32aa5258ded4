//! Monte Carlo execution of a plan on the stochastic plant (Euler–Maruyama, paper Eq. 10), with
//! the policies the paper compares: open loop, full feedback, and feedback that arrives late.
//!
//! Every trial has its own random stream derived from `(seed, trial)`, so the results do not
//! depend on how many threads run the trials or in which order.

use crate::dynamics::{Dynamics, EulerModel};
use crate::model::ArmModel;
use crate::plan::{PlanFile, Setup};
use crate::solver::Bounds;
use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, StandardNormal};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// How the plan's commands are executed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Policy {
    /// The commands as planned, no feedback at all (the paper's feedforward execution).
    OpenLoop,
    /// `u = ū + L (x − x̄)` with the current state.
    Feedback,
    /// `u_j = ū_j + L_{j−D} (x_{j−D} − x̄_{j−D})`: the feedback of a controller that sees the state
    /// `D` steps late (paper Eq. 13 with a plan made for that delay; a naive delayed controller
    /// with a plan made without).
    DelayedFeedback { latency_steps: usize },
}

/// A plan ready to execute: the commands that act at each step, the nominal states, the gains.
#[derive(Debug, Clone)]
pub struct Executable {
    /// Command acting at each step `0..N` (with a plan delay `d`, command `k − d`; the hold
    /// command before).
    pub acting: Vec<DVector<f64>>,
    /// Nominal states `x̄_0 ..= x̄_N`.
    pub nominal: Vec<DVector<f64>>,
    /// Gains `L_k` per issue step (m×n).
    pub gains: Vec<DMatrix<f64>>,
    /// Delay the plan was made for [steps].
    pub plan_delay: usize,
}

impl Executable {
    /// From a plan file and the set-up of the scenario it runs on.
    pub fn from_plan(plan: &PlanFile, setup: &Setup) -> Result<Self, String> {
        let steps = setup.u_init.len();
        let (nx, nu) = (setup.dynamics.nx(), setup.dynamics.nu());
        if plan.u.len() != steps || plan.x.len() != steps + 1 {
            return Err(format!(
                "the plan has {} steps, the scenario {steps}: plan and scenario do not match",
                plan.u.len()
            ));
        }
        if plan.u.iter().any(|u| u.len() != nu) || plan.x.iter().any(|x| x.len() != nx) {
            return Err(format!(
                "the plan's controls/states are not {nu}/{nx}-dimensional like the scenario's"
            ));
        }
        let d = plan.summary.delay_steps;
        let hold = setup.u_init[0].clone();
        let acting = (0..steps)
            .map(|k| {
                if k < d {
                    hold.clone()
                } else {
                    DVector::from_column_slice(&plan.u[k - d])
                }
            })
            .collect();
        let gains = plan
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
        Ok(Executable {
            acting,
            nominal: plan
                .x
                .iter()
                .map(|x| DVector::from_column_slice(x))
                .collect(),
            gains,
            plan_delay: d,
        })
    }
}

/// One simulated movement.
#[derive(Debug, Clone)]
pub struct Trial {
    pub x: Vec<DVector<f64>>,
    pub u: Vec<DVector<f64>>,
    /// Realised cost (Eq. 14 on this trajectory).
    pub cost: f64,
}

/// The random stream of one trial: SplitMix64 of the seed and the trial index.
pub fn trial_rng(seed: u64, trial: u64) -> Xoshiro256PlusPlus {
    let mut z = seed ^ trial.wrapping_mul(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    Xoshiro256PlusPlus::seed_from_u64(z ^ (z >> 31))
}

/// Simulates one trial of `exe` under `policy` on the stochastic plant.
#[allow(clippy::too_many_arguments)]
pub fn run_trial(
    dynamics: &EulerModel,
    cost: &dyn crate::cost::Cost,
    bounds: &Bounds,
    x0: &[f64],
    exe: &Executable,
    policy: Policy,
    seed: u64,
    trial: u64,
) -> Trial {
    let (nx, nw) = (dynamics.nx(), dynamics.nw());
    let steps = exe.acting.len();
    let mut rng = trial_rng(seed, trial);
    let mut x = vec![DVector::from_column_slice(x0)];
    let mut us = Vec::with_capacity(steps);
    let mut g = DMatrix::zeros(nx, nw);
    let mut eps = DVector::zeros(nw);
    let mut total = 0.0;
    for k in 0..steps {
        let mut u = exe.acting[k].clone();
        // The state the controller sees (now, or D steps ago) and the gain issued with it.
        let seen = match policy {
            Policy::OpenLoop => None,
            Policy::Feedback => Some(k),
            Policy::DelayedFeedback { latency_steps } => k.checked_sub(latency_steps),
        };
        if let Some(j) = seen.filter(|&j| j < exe.gains.len()) {
            let dx = &x[j] - &exe.nominal[j];
            u += &exe.gains[j] * dx;
        }
        bounds.clamp(u.as_mut_slice());
        let mut next = DVector::zeros(nx);
        dynamics.step(k, x[k].as_slice(), u.as_slice(), next.as_mut_slice());
        if nw > 0 {
            dynamics.noise_gain(k, x[k].as_slice(), u.as_slice(), &mut g);
            for e in eps.iter_mut() {
                *e = StandardNormal.sample(&mut rng);
            }
            next.gemv(1.0, &g, &eps, 1.0);
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
    exe: &Executable,
    policy: Policy,
    trials: usize,
    seed: u64,
) -> Vec<Trial> {
    (0..trials as u64)
        .into_par_iter()
        .map(|t| {
            run_trial(
                &setup.dynamics,
                &setup.cost,
                &setup.bounds,
                &setup.x0,
                exe,
                policy,
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
pub fn position(model: &ArmModel, x: &DVector<f64>) -> Vec<f64> {
    if model.dof() == 1 {
        vec![x[0]]
    } else {
        model.plant.hand_position(&x.as_slice()[..2]).to_vec()
    }
}
