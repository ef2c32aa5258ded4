//! The simulated plant the board drives: the arm model under the impedance law (Eq. 4), the
//! external torques and fields that disturbances put on it, and its noise.

use super::BoardConfig;
use crate::transport::{Disturbance, DisturbanceKind, Knot, MAX_JOINTS};
use rand::rngs::Xoshiro256PlusPlus;
use vic_core::dynamics::flow;
use vic_core::model::{ArmModel, Exogenous, Field, Noise};
use vic_core::rng::{add_diffusion, trial_rng};
use vic_core::scalar::{MAX_NW, MAX_NX};

/// The plant state and what acts on it.
pub(super) struct SimulatedPlant {
    pub model: ArmModel,
    /// The configured noise and field, restored when disturbances are cleared.
    base_noise: Noise,
    pub dof: usize,
    pub nx: usize,
    /// `(q, q')` and the actuator's states.
    pub x: [f64; MAX_NX],
    /// Joint torque and stiffness of the last period [N m], [N m/rad].
    pub tau: [f64; MAX_JOINTS],
    pub stiffness: [f64; MAX_JOINTS],
    /// The trial's random stream: the Monte Carlo's, so that live and offline trials with the
    /// same seed draw the same noise.
    rng: Xoshiro256PlusPlus,
    pulse: [f64; MAX_JOINTS],
    pulse_until_ns: u64,
    load: [f64; MAX_JOINTS],
    pub noise_factor: f64,
}

impl SimulatedPlant {
    /// The plant at rest at `q0` (`q0` holds one angle per joint).
    pub fn new(model: ArmModel, q0: &[f64]) -> Self {
        let dof = model.dof();
        let mut x = [0.0; MAX_NX];
        x[..dof].copy_from_slice(&q0[..dof]);
        SimulatedPlant {
            base_noise: model.noise,
            dof,
            nx: model.nx(),
            model,
            x,
            tau: [0.0; MAX_JOINTS],
            stiffness: [0.0; MAX_JOINTS],
            rng: trial_rng(0, 0),
            pulse: [0.0; MAX_JOINTS],
            pulse_until_ns: 0,
            load: [0.0; MAX_JOINTS],
            noise_factor: 1.0,
        }
    }

    /// Puts the plant at `(q0, q0')` with the noise stream of `(seed, trial)`.
    pub fn reset(
        &mut self,
        q0: &[f64; MAX_JOINTS],
        qd0: &[f64; MAX_JOINTS],
        seed: u64,
        trial: u32,
    ) {
        let dof = self.dof;
        self.x = [0.0; MAX_NX];
        self.x[..dof].copy_from_slice(&q0[..dof]);
        self.x[dof..2 * dof].copy_from_slice(&qd0[..dof]);
        self.rng = trial_rng(seed, trial as u64);
        self.tau = [0.0; MAX_JOINTS];
        self.stiffness = [0.0; MAX_JOINTS];
    }

    /// External torque in force at `now_ns` [N m]: the load plus a running pulse.
    pub fn tau_ext(&self, now_ns: u64) -> [f64; MAX_JOINTS] {
        let mut t = self.load;
        if now_ns < self.pulse_until_ns {
            for i in 0..MAX_JOINTS {
                t[i] += self.pulse[i];
            }
        }
        t
    }

    /// Puts a validated disturbance of `kind` in force from `now_ns`.
    pub fn apply(&mut self, kind: DisturbanceKind, d: &Disturbance, now_ns: u64) {
        let mut torque = [0.0; MAX_JOINTS];
        torque[..self.dof].copy_from_slice(&d.torque[..self.dof]);
        match kind {
            DisturbanceKind::Pulse => {
                self.pulse = torque;
                self.pulse_until_ns = now_ns + d.duration_ns;
            }
            DisturbanceKind::Load => self.load = torque,
            DisturbanceKind::Field => {
                self.model.field = if d.value == 0.0 {
                    Field::None
                } else {
                    Field::Divergent { beta: d.value }
                };
            }
            DisturbanceKind::Noise => {
                self.noise_factor = d.value;
                self.model.noise = self.base_noise.scaled(d.value);
            }
        }
    }

    /// The safe hold at the present position: the hold stiffness, no velocity, the torque that
    /// balances gravity and the field there (clamped to the actuator's range, like any command).
    pub(crate) fn hold_target(&self, cfg: &BoardConfig) -> Knot {
        let dof = self.dof;
        let mut k = Knot::default();
        k.q_d[..dof].copy_from_slice(&self.x[..dof]);
        k.stiffness[..dof]
            .iter_mut()
            .for_each(|v| *v = cfg.hold_stiffness);
        let zero = [0.0; MAX_JOINTS];
        let g = self
            .model
            .inverse_dynamics(&self.x[..dof], &zero[..dof], &zero[..dof]);
        for i in 0..dof {
            k.tau_ff[i] = g[i].clamp(-cfg.torque_max, cfg.torque_max);
        }
        k
    }

    /// One period under knot `k`: the impedance law (Eq. 4) through the model's joint torque,
    /// the shared integrator [`flow`], then the noise `√Δ F(x) ε` (Euler–Maruyama, Eq. 10, once
    /// per period, as the Monte Carlo does per plan step).
    pub fn step(&mut self, k: &Knot, now_ns: u64, cfg: &BoardConfig) {
        let (dof, nx) = (self.dof, self.nx);
        let mut u = [0.0; 2 * MAX_JOINTS];
        u[..dof].copy_from_slice(&k.tau_ff[..dof]);
        u[dof..2 * dof].copy_from_slice(&k.stiffness[..dof]);
        let ex = Exogenous {
            q_d: k.q_d,
            qd_d: k.qd_d,
            tau_ext: self.tau_ext(now_ns),
        };
        let mut tau = [0.0; MAX_JOINTS];
        self.model
            .joint_torque(&self.x[..nx], &u[..2 * dof], &ex, &mut tau);
        self.tau = tau;
        self.stiffness = k.stiffness;
        let dt = cfg.period_ns as f64 * 1e-9;
        let mut next = [0.0; MAX_NX];
        let x = &self.x[..nx];
        flow(
            &self.model,
            &ex,
            dt,
            cfg.substeps,
            cfg.integrator,
            x,
            &u[..2 * dof],
            &mut next[..nx],
        );
        let nw = self.model.nw();
        if nw > 0 {
            let mut f = [0.0; MAX_NX * MAX_NW];
            self.model.diffusion(&self.x[..nx], &u[..2 * dof], &mut f);
            let s = dt.sqrt();
            f[..nx * nw].iter_mut().for_each(|v| *v *= s);
            add_diffusion(&mut next[..nx], &f[..nx * nw], nx, nw, &mut self.rng);
        }
        self.x = next;
    }
}
