//! Serial arms from URDF files: the chain of revolute joints from a base link to a tip link, and
//! its rigid-body dynamics `M(q) q'' + C(q, q') + g(q) + B q' = τ` generic over [`Scalar`].
//!
//! - Revolute and continuous joints move; fixed joints merge their links into the body before
//!   them; joints off the chain are held at their zero position (their links ride on the chain
//!   link they hang from, as in Pinocchio's reduced model); what hangs off the base is ignored.
//!   A prismatic, floating, planar, spherical or mimic joint on the chain is refused.
//! - A link that a joint moves needs a positive mass; inertias must be positive semidefinite (a
//!   point mass is allowed) and the mass matrix positive definite. Visuals, collisions and
//!   materials are dropped unread: no mesh file is opened.
//! - Gravity is a parameter: −9.81 m/s² along the base link's z axis unless set.
//! - `B` is the diagonal of the joints' `<dynamics damping>`; friction is kept in
//!   [`JointLimits`] but is not part of the dynamics.
//! - Nothing in the dynamics allocates: at most [`MAX_DOF`] joints, results in fixed arrays
//!   whose first [`SerialChain::dof`] entries are used.

mod chain;
mod dynamics;
mod lanes;
mod urdf;

#[cfg(test)]
mod fuzz;
#[cfg(test)]
mod tests;

pub use chain::JointLimits;
pub use urdf::{UrdfError, UrdfReason};

use crate::scalar::Scalar;
use chain::Chain;

/// The most joints a chain may move.
pub const MAX_DOF: usize = 7;

/// Gravity unless set [m/s²]: 9.81 down the base link's z axis.
pub const DEFAULT_GRAVITY: [f64; 3] = [0.0, 0.0, -9.81];

/// The forward dynamics and its first derivatives at one state (row `i`: `q''_i`, column `j`:
/// the variable `j`; the first [`SerialChain::dof`] rows and columns used).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForwardDerivatives {
    /// `q''` [rad/s²].
    pub qdd: [f64; MAX_DOF],
    /// `∂q''/∂q`.
    pub d_q: [[f64; MAX_DOF]; MAX_DOF],
    /// `∂q''/∂q'`.
    pub d_qd: [[f64; MAX_DOF]; MAX_DOF],
    /// `∂q''/∂τ = M⁻¹`.
    pub d_tau: [[f64; MAX_DOF]; MAX_DOF],
}

/// A serial chain of a URDF file with its dynamics.
#[derive(Debug, Clone, PartialEq)]
pub struct SerialChain {
    chain: Chain,
    gravity: [f64; 3],
}

impl SerialChain {
    /// The chain from `base_link` to `tip_link` of a URDF document given as text.
    pub fn from_urdf_str(text: &str, base_link: &str, tip_link: &str) -> Result<Self, UrdfError> {
        Self::parse(text, "<string>", base_link, tip_link)
    }

    /// The chain from `base_link` to `tip_link` of a URDF document read from `source` (a file
    /// name, for the errors). Reading the file is the caller's: this crate does no I/O (the
    /// scenario layer reads files with its size limits). Meshes are never read.
    pub fn from_urdf(
        text: &str,
        source: &str,
        base_link: &str,
        tip_link: &str,
    ) -> Result<Self, UrdfError> {
        Self::parse(text, source, base_link, tip_link)
    }

    fn parse(text: &str, file: &str, base: &str, tip: &str) -> Result<Self, UrdfError> {
        let tree = urdf::Tree::parse(text, file)?;
        Ok(SerialChain {
            chain: Chain::new(&tree, base, tip)?,
            gravity: DEFAULT_GRAVITY,
        })
    }

    /// The same chain in gravity `g` [m/s²], a vector in the base link's frame.
    pub fn with_gravity(mut self, g: [f64; 3]) -> Self {
        self.gravity = g;
        self
    }

    /// Gravity [m/s²] in the base link's frame.
    pub fn gravity(&self) -> [f64; 3] {
        self.gravity
    }

    /// The number of moving joints.
    pub fn dof(&self) -> usize {
        self.chain.joints.len()
    }

    /// The moving joints' names, from the base.
    pub fn joint_names(&self) -> impl Iterator<Item = &str> {
        self.chain.joints.iter().map(|j| j.name.as_str())
    }

    /// Joint `i`'s limits, damping and friction.
    pub fn limits(&self, i: usize) -> &JointLimits {
        &self.chain.joints[i].limits
    }

    /// The mass matrix `M(q)` [kg m²] (composite rigid body algorithm).
    pub fn mass_matrix<S: Scalar>(&self, q: &[S]) -> [[S; MAX_DOF]; MAX_DOF] {
        dynamics::crba(&self.chain, &dynamics::rotations(&self.chain, q))
    }

    /// The bias torques `C(q, q') + g(q) + B q'` [N m]: what the joints need at `q'' = 0`.
    pub fn bias<S: Scalar>(&self, q: &[S], qd: &[S]) -> [S; MAX_DOF] {
        let rot = dynamics::rotations(&self.chain, q);
        let qdd = [S::zero(); MAX_DOF];
        dynamics::rnea(&self.chain, &self.gravity, &rot, qd, &qdd, true)
    }

    /// The joint torques `τ = M(q) q'' + C(q, q') + g(q) + B q'` [N m] (recursive Newton–Euler).
    pub fn inverse_dynamics<S: Scalar>(&self, q: &[S], qd: &[S], qdd: &[S]) -> [S; MAX_DOF] {
        let rot = dynamics::rotations(&self.chain, q);
        dynamics::rnea(&self.chain, &self.gravity, &rot, qd, qdd, true)
    }

    /// The joint accelerations `q'' = M(q)⁻¹ (τ − C(q, q') − g(q) − B q')` [rad/s²].
    pub fn forward_dynamics<S: Scalar>(&self, q: &[S], qd: &[S], tau: &[S]) -> [S; MAX_DOF] {
        let n = self.dof();
        let rot = dynamics::rotations(&self.chain, q);
        let m = dynamics::crba(&self.chain, &rot);
        let zero = [S::zero(); MAX_DOF];
        let b = dynamics::rnea(&self.chain, &self.gravity, &rot, qd, &zero, true);
        let mut rhs = [S::zero(); MAX_DOF];
        for i in 0..n {
            rhs[i] = tau[i] - b[i];
        }
        dynamics::solve(&m, n, &rhs)
    }

    /// The forward dynamics and its first derivatives at one state, in `f64`: `q''` from
    /// [`SerialChain::forward_dynamics`], and `∂q''/∂x = −M⁻¹ ∂τ_ID/∂x` for `x = q, q'` (the
    /// inverse dynamics differentiated at the state's own `q''`, by dual numbers over the
    /// 14 directions at once, in plain arrays), `∂q''/∂τ = M⁻¹`. Cheaper than the forward dynamics in dual numbers:
    /// only the inverse dynamics carries derivatives, and the factorisation is reused.
    pub fn forward_dynamics_derivatives(
        &self,
        q: &[f64],
        qd: &[f64],
        tau: &[f64],
    ) -> ForwardDerivatives {
        type D = lanes::Lanes<{ 2 * MAX_DOF }>;
        let n = self.dof();
        let rot = dynamics::rotations(&self.chain, q);
        let m = dynamics::crba(&self.chain, &rot);
        let b = dynamics::rnea(&self.chain, &self.gravity, &rot, qd, &[0.0; MAX_DOF], true);
        let (l, d) = dynamics::ldl(&m, n);
        let mut rhs = [0.0; MAX_DOF];
        for i in 0..n {
            rhs[i] = tau[i] - b[i];
        }
        let qdd = dynamics::solve_factored(&l, &d, n, &rhs);
        let seed = |v: &[f64], offset: usize| -> [D; MAX_DOF] {
            std::array::from_fn(|i| match v.get(i) {
                Some(&x) if i < n => D::variable(x, Some(offset + i)),
                _ => D::from(0.0),
            })
        };
        let (qx, qdx) = (seed(q, 0), seed(qd, MAX_DOF));
        let rotx = dynamics::rotations(&self.chain, &qx);
        let id = dynamics::rnea(
            &self.chain,
            &self.gravity,
            &rotx,
            &qdx,
            &qdd.map(D::from),
            true,
        );
        let grads = id.map(|t| t.d);
        let mut out = ForwardDerivatives {
            qdd,
            d_q: [[0.0; MAX_DOF]; MAX_DOF],
            d_qd: [[0.0; MAX_DOF]; MAX_DOF],
            d_tau: [[0.0; MAX_DOF]; MAX_DOF],
        };
        for j in 0..n {
            let column =
                |offset: usize| std::array::from_fn::<f64, MAX_DOF, _>(|i| -grads[i][offset + j]);
            let (dq, dqd) = (column(0), column(MAX_DOF));
            let mut unit = [0.0; MAX_DOF];
            unit[j] = 1.0;
            let cols = [
                dynamics::solve_factored(&l, &d, n, &dq),
                dynamics::solve_factored(&l, &d, n, &dqd),
                dynamics::solve_factored(&l, &d, n, &unit),
            ];
            for i in 0..n {
                out.d_q[i][j] = cols[0][i];
                out.d_qd[i][j] = cols[1][i];
                out.d_tau[i][j] = cols[2][i];
            }
        }
        out
    }

    /// The tip link's origin in the base link's frame [m].
    pub fn tip_position<S: Scalar>(&self, q: &[S]) -> [S; 3] {
        dynamics::tip_position(&self.chain, q)
    }

    /// The potential energy in gravity [J] (zero with every mass at the base's origin).
    pub fn potential_energy<S: Scalar>(&self, q: &[S]) -> S {
        dynamics::potential_energy(&self.chain, &self.gravity, q)
    }
}
