//! Continuous-time stochastic plant models `dx = f(x, u) dt + F(x, u) dw` (paper Eq. 8): a limb
//! ([`Plant`]), an [`Actuator`], a force [`Field`] on the hand and a [`Noise`] model.
//!
//! [`ArmModel::f`] and [`ArmModel::diffusion`] are the only places the equations of motion are
//! written. They are generic over [`Scalar`], so the same code simulates (with `f64`), gives exact
//! Jacobians (with dual numbers) and runs inside the board's 1 kHz loop. The drift's first
//! derivatives are also written out ([`ArmModel::f_jacobian`], checked against the dual numbers
//! by the tests) because ILQG needs them at every knot of every iteration.

pub(crate) mod actuator;
pub(crate) mod field;
mod jacobian;
pub mod noise;
pub mod plant;
pub mod serial;

pub use actuator::{Actuator, Damping};
pub use field::Field;
pub use noise::Noise;
pub(crate) use plant::Angles;
pub use plant::{Plant, SingleJoint, TwoLink};
pub use serial::{SerialChain, UrdfError};

use crate::scalar::{Scalar, c};
use serde::{Deserialize, Serialize};

/// Inputs to the plant that are not controls: the impedance law's equilibrium trajectory and any
/// external joint torque (the board's injected disturbances). Not differentiated.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Exogenous {
    /// Desired joint angles `q_d` [rad].
    pub q_d: [f64; 2],
    /// Desired joint velocities `q_d'` [rad/s].
    pub qd_d: [f64; 2],
    /// External joint torque [N m] added to the actuator's.
    pub tau_ext: [f64; 2],
}

/// A complete continuous-time model: limb, actuator, field and noise.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ArmModel {
    pub plant: Plant,
    pub actuator: Actuator,
    pub field: Field,
    pub noise: Noise,
}

/// Why the parts of an [`ArmModel`] do not fit together; each names the key of the scenario file
/// that is wrong (`[section] key`), so that the planning layer can report the right line.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    #[error("motor_inertia has {entries} entries, the plant has {dof} joints")]
    MotorInertiaCount { entries: usize, dof: usize },
    #[error("motor_inertia must be positive")]
    MotorInertiaNotPositive,
    #[error(
        "force fields act on the hand of the two-link arm; a single joint takes field kind = \"none\""
    )]
    FieldOnSingleJoint,
    #[error("noise component {component} is out of range for a {nx}-dimensional state")]
    NoiseComponent { component: usize, nx: usize },
    #[error("the stiffness time constant must be positive and finite, got {0} s")]
    StiffnessTimeConstant(f64),
}

impl ModelError {
    /// The `(section, key)` of the scenario file that holds the value in error.
    pub fn key(&self) -> (&'static str, &'static str) {
        match self {
            Self::MotorInertiaCount { .. } | Self::MotorInertiaNotPositive => {
                ("actuator", "motor_inertia")
            }
            Self::FieldOnSingleJoint => ("field", "kind"),
            Self::NoiseComponent { .. } => ("noise", "component"),
            Self::StiffnessTimeConstant(_) => ("actuator", "stiffness_time_constant"),
        }
    }
}

impl ArmModel {
    /// Builds a model, checking that its parts fit together.
    pub fn new(
        plant: Plant,
        actuator: Actuator,
        field: Field,
        noise: Noise,
    ) -> Result<Self, ModelError> {
        let dof = plant.dof();
        if let Actuator::Vsa { motor_inertia } = &actuator {
            if motor_inertia.len() != dof {
                return Err(ModelError::MotorInertiaCount {
                    entries: motor_inertia.len(),
                    dof,
                });
            }
            if motor_inertia.iter().any(|b| b.is_nan() || *b <= 0.0) {
                return Err(ModelError::MotorInertiaNotPositive);
            }
        }
        if let Actuator::ImpedanceLag { time_constant, .. } = &actuator
            && !(time_constant.is_finite() && *time_constant > 0.0)
        {
            return Err(ModelError::StiffnessTimeConstant(*time_constant));
        }
        if dof == 1 && !matches!(field, Field::None) {
            return Err(ModelError::FieldOnSingleJoint);
        }
        let model = ArmModel {
            plant,
            actuator,
            field,
            noise,
        };
        if let Noise::StateProportional { component, .. } = noise
            && component >= model.nx()
        {
            return Err(ModelError::NoiseComponent {
                component,
                nx: model.nx(),
            });
        }
        Ok(model)
    }

    /// Number of joints.
    pub fn dof(&self) -> usize {
        self.plant.dof()
    }
    /// State dimension `n`: `(q, q')`, `(q, q', θ, θ')` with a VSA, `(q, q', K)` with a lagged
    /// stiffness.
    pub fn nx(&self) -> usize {
        self.actuator.nx(self.dof())
    }
    /// The leading states that come in (position, velocity) blocks of `dof` each (the
    /// semi-implicit step updates their velocities first); the states after them are of first
    /// order (a lagged stiffness).
    pub fn second_order_states(&self) -> usize {
        match self.actuator {
            Actuator::ImpedanceLag { .. } => 2 * self.dof(),
            _ => self.nx(),
        }
    }
    /// The states the noise drives: all of them, except a lagged stiffness (a mechanism's
    /// position, not disturbed by the limb's noise), so that `τ_K → 0` leaves the paper's noise
    /// model of the limb unchanged.
    fn noisy_states(&self) -> usize {
        self.second_order_states()
    }
    /// Control dimension `m`.
    pub fn nu(&self) -> usize {
        self.actuator.nu(self.dof())
    }
    /// Number of noise channels `p`.
    pub fn nw(&self) -> usize {
        self.noise.nw(self.noisy_states(), self.dof())
    }

    /// Joint torque produced by the actuator and the exogenous torque (Eq. 3, 4, 6).
    /// Inlined: see [`ArmModel::f`].
    #[inline(always)]
    pub fn joint_torque<S: Scalar>(&self, x: &[S], u: &[S], ex: &Exogenous, tau: &mut [S]) {
        let n = self.dof();
        for i in 0..n {
            let (q, qd) = (x[i], x[n + i]);
            tau[i] = c::<S>(ex.tau_ext[i])
                + match &self.actuator {
                    Actuator::Torque => u[i],
                    Actuator::Impedance { damping } => {
                        let k = u[n + i];
                        u[i] - k * (q - ex.q_d[i]) - damping.gain(k) * (qd - ex.qd_d[i])
                    }
                    // Eq. 4 with the stiffness the mechanism has reached, not the one commanded.
                    Actuator::ImpedanceLag { damping, .. } => {
                        let k = x[2 * n + i];
                        u[i] - k * (q - ex.q_d[i]) - damping.gain(k) * (qd - ex.qd_d[i])
                    }
                    // The spring between motor and link: τ = K (θ − q).
                    Actuator::Vsa { .. } => u[n + i] * (x[2 * n + i] - q),
                };
        }
    }

    /// The drift `x' = f(x, u)` (paper Eq. 2).
    ///
    /// Inlined into its callers, with the plant's pieces it calls (marked so as well): the step
    /// (`DiscreteDynamics::flow`) is compiled twice, portably and for
    /// AVX2, and left to itself the compiler keeps these as calls to their portable copies, which
    /// pass SOOC's Taylor polynomials through memory; inlined into the AVX2 step they stay in
    /// registers (faster than building the whole program for AVX2).
    #[inline(always)]
    pub fn f<S: Scalar>(&self, x: &[S], u: &[S], ex: &Exogenous, xdot: &mut [S]) {
        self.drift(x, u, ex, xdot);
    }

    /// [`ArmModel::f`], returning the mass matrix `M(q)` it solved with (the Rosenbrock step of
    /// the integrator takes the impedance law's spring and damper implicitly through it).
    #[inline(always)]
    pub(crate) fn f_and_mass<S: Scalar>(
        &self,
        x: &[S],
        u: &[S],
        ex: &Exogenous,
        xdot: &mut [S],
    ) -> [[S; 2]; 2] {
        self.drift(x, u, ex, xdot).1
    }

    /// [`ArmModel::f`], returning what [`ArmModel::f_jacobian`] reuses: the configuration's
    /// angles and the mass matrix.
    #[inline(always)]
    fn drift<S: Scalar>(
        &self,
        x: &[S],
        u: &[S],
        ex: &Exogenous,
        xdot: &mut [S],
    ) -> (Angles<S>, [[S; 2]; 2]) {
        let n = self.dof();
        let (q, qd) = (&x[..n], &x[n..2 * n]);
        // The hand's kinematics only for the field's force.
        let angles = if self.field.is_none() {
            self.plant.dynamics_angles(q)
        } else {
            self.plant.angles(q)
        };
        let mut tau = [S::zero(); 2];
        self.joint_torque(x, u, ex, &mut tau);
        let mut bias = [S::zero(); 2];
        self.plant.bias_torque_at(&angles, qd, &mut bias);
        let mut rhs = [S::zero(); 2];
        for i in 0..n {
            rhs[i] = tau[i] - bias[i];
        }
        if !self.field.is_none() {
            let field = self.field_torque(&angles, qd);
            for (r, t) in rhs.iter_mut().zip(field).take(n) {
                *r += t;
            }
        }
        let mut qdd = [S::zero(); 2];
        let m = self.plant.mass_matrix_at(&angles);
        Plant::solve_with(&m, n, &rhs[..n], &mut qdd[..n]);
        // Element by element: a slice copy of one or two numbers is a call to memcpy.
        #[allow(clippy::manual_memcpy)]
        for i in 0..n {
            xdot[i] = qd[i];
            xdot[n + i] = qdd[i];
        }
        if let Actuator::Vsa { motor_inertia } = &self.actuator {
            for i in 0..n {
                let theta = x[2 * n + i];
                xdot[2 * n + i] = x[3 * n + i];
                xdot[3 * n + i] = (u[i] - u[n + i] * (theta - q[i])) / motor_inertia[i];
            }
        }
        if let Actuator::ImpedanceLag { time_constant, .. } = self.actuator {
            // K' = (K_c − K) / τ_K: the realised stiffness follows its command.
            for i in 0..n {
                xdot[2 * n + i] = (u[n + i] - x[2 * n + i]) / time_constant;
            }
        }
        (angles, m)
    }

    /// The diffusion `F(x, u)` (n × p, column-major: column `i` is `out[i*n .. (i+1)*n]`).
    pub fn diffusion<S: Scalar>(&self, x: &[S], _u: &[S], out: &mut [S]) {
        let nx = self.nx();
        let nw = self.nw();
        out[..nx * nw].iter_mut().for_each(|v| *v = S::zero());
        match self.noise {
            Noise::None => {}
            Noise::StateProportional { sigma, component } => {
                let scale = x[component] * sigma;
                for i in 0..nw {
                    out[i * nx + i] = scale;
                }
            }
            Noise::Torque { a, b, sample_time } => {
                let scale = sample_time.sqrt();
                let n = self.dof();
                let m = self.plant.mass_matrix(&x[..n]);
                for i in 0..n {
                    let mut e = [S::zero(); 2];
                    e[i] = (x[n + i] * b + a) * scale;
                    let mut acc = [S::zero(); 2];
                    Plant::solve_with(&m, n, &e[..n], &mut acc[..n]);
                    for j in 0..n {
                        out[i * nx + n + j] = acc[j];
                    }
                }
            }
        }
    }

    /// Joint torque needed to move along `(q, q', q'')`, the inverse dynamics
    /// `M(q) q'' + C(q, q') + B_v q' + g(q) − Jᵀ D` (used to warm-start the planner).
    pub fn inverse_dynamics(&self, q: &[f64], qd: &[f64], qdd: &[f64]) -> [f64; 2] {
        let n = self.dof();
        let angles = self.plant.angles(q);
        let m = self.plant.mass_matrix_at(&angles);
        let mut tau = [0.0; 2];
        self.plant.bias_torque_at(&angles, qd, &mut tau);
        for i in 0..n {
            for j in 0..n {
                tau[i] += m[i][j] * qdd[j];
            }
        }
        if !self.field.is_none() {
            for (t, f) in tau.iter_mut().zip(self.field_torque(&angles, qd)).take(n) {
                *t -= f;
            }
        }
        tau
    }

    /// `Jᵀ(q) D(x, v)`: the field's hand force mapped to joint torques (Eq. 2's external term),
    /// with the hand velocity `v = J(q) q'`.
    /// Inlined: see [`ArmModel::f`].
    #[inline(always)]
    fn field_torque<S: Scalar>(&self, angles: &Angles<S>, qd: &[S]) -> [S; 2] {
        let jac = self.plant.jacobian_at(angles);
        let v = [
            jac[0][0] * qd[0] + jac[0][1] * qd[1],
            jac[1][0] * qd[0] + jac[1][1] * qd[1],
        ];
        let force = self.field.force(self.plant.hand_position_at(angles), v);
        [
            jac[0][0] * force[0] + jac[1][0] * force[1],
            jac[0][1] * force[0] + jac[1][1] * force[1],
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::plant::tests::joint;
    use super::*;

    #[test]
    fn parts_that_do_not_fit_name_the_key_at_fault() {
        let vsa = |b: Vec<f64>| Actuator::Vsa { motor_inertia: b };
        let noise = Noise::None;
        let e = ArmModel::new(joint(), vsa(vec![1.0, 2.0]), Field::None, noise).unwrap_err();
        assert_eq!(e, ModelError::MotorInertiaCount { entries: 2, dof: 1 });
        assert_eq!(e.key(), ("actuator", "motor_inertia"));
        let e = ArmModel::new(joint(), vsa(vec![0.0]), Field::None, noise).unwrap_err();
        assert_eq!(e, ModelError::MotorInertiaNotPositive);
        let divergent = Field::Divergent { beta: 40.0 };
        let e = ArmModel::new(joint(), Actuator::Torque, divergent, noise).unwrap_err();
        assert_eq!(e.key(), ("field", "kind"));
        // A torque-driven joint has the state (q, q'): component 2 does not exist.
        let state = |component| Noise::StateProportional {
            sigma: 0.1,
            component,
        };
        let e = ArmModel::new(joint(), Actuator::Torque, Field::None, state(2)).unwrap_err();
        assert_eq!(
            e,
            ModelError::NoiseComponent {
                component: 2,
                nx: 2
            }
        );
        assert_eq!(e.key(), ("noise", "component"));
        assert!(ArmModel::new(joint(), Actuator::Torque, Field::None, state(1)).is_ok());
    }
}
