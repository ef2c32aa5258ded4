//! Actuators: how the control vector becomes joint torque (paper Eq. 3–7).
//!
//! | type | law | extra state | control |
//! |---|---|---|---|
//! | 1 torque | τ = τ_ff | none | τ_ff |
//! | 2 impedance | τ = τ_ff − K_P (q − q_d) − K_D (q' − q_d') | none | (τ_ff, diag K_P) |
//! | 3 VSA | τ = K (θ − q), B θ'' = τ_m − K (θ − q) | (θ, θ') | (τ_m, diag K) |

use crate::scalar::Scalar;
use serde::{Deserialize, Serialize};

/// How the impedance actuator's damping follows its stiffness.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub enum Damping {
    /// `K_D = α K_P` (the paper's simulations; α = 0.1 for the arm, 0.2 for the iCub elbow).
    Proportional { alpha: f64 },
    /// `K_D = slope K_P + offset` (the iCub's identified stability boundary: 0.075 K_P − 0.0015).
    Affine { slope: f64, offset: f64 },
}

impl Damping {
    /// Damping gain [N m s/rad] for a stiffness [N m/rad].
    #[inline]
    pub fn gain<S: Scalar>(&self, stiffness: S) -> S {
        match *self {
            Damping::Proportional { alpha } => stiffness * alpha,
            Damping::Affine { slope, offset } => stiffness * slope + offset,
        }
    }
}

impl Damping {
    /// `∂K_D/∂K_P`.
    pub fn slope(&self) -> f64 {
        match *self {
            Damping::Proportional { alpha } => alpha,
            Damping::Affine { slope, .. } => slope,
        }
    }
}

/// The actuator type.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub enum Actuator {
    /// Type 1: rigid joint driven by a feedforward torque.
    Torque,
    /// Type 2: feedforward torque plus a PD impedance law around the reference (Eq. 4).
    Impedance { damping: Damping },
    /// Type 3: flexible joint with controllable spring stiffness and motor inertia `B` [kg m²] per
    /// joint (Eq. 6).
    Vsa { motor_inertia: Vec<f64> },
}

impl Actuator {
    /// Number of controls for `dof` joints.
    pub fn nu(&self, dof: usize) -> usize {
        match self {
            Actuator::Torque => dof,
            Actuator::Impedance { .. } | Actuator::Vsa { .. } => 2 * dof,
        }
    }

    /// Number of states for `dof` joints.
    pub fn nx(&self, dof: usize) -> usize {
        match self {
            Actuator::Vsa { .. } => 4 * dof,
            _ => 2 * dof,
        }
    }

    /// Index of the first stiffness control, if the actuator has stiffness.
    pub fn stiffness_offset(&self, dof: usize) -> Option<usize> {
        match self {
            Actuator::Torque => None,
            _ => Some(dof),
        }
    }

    /// Short name used in config files and reports.
    pub fn name(&self) -> &'static str {
        match self {
            Actuator::Torque => "torque",
            Actuator::Impedance { .. } => "impedance",
            Actuator::Vsa { .. } => "vsa",
        }
    }
}
