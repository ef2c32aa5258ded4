//! Actuators: how the control vector becomes joint torque (paper Eq. 3–7).
//!
//! | type | law | extra state | control |
//! |---|---|---|---|
//! | 1 torque | τ = τ_ff | none | τ_ff |
//! | 2 impedance | τ = τ_ff − K_P (q − q_d) − K_D (q' − q_d') | none | (τ_ff, diag K_P) |
//! | 3 VSA | τ = K (θ − q), B θ'' = τ_m − K (θ − q) | (θ, θ') | (τ_m, diag K) |
//! | 2 with a stiffness lag | τ as type 2 with the realised `K`, `K' = (K_c − K) / τ_K` | `K` | (τ_ff, diag K_c) |
//!
//! Types 2 and 3 treat the stiffness as a control that acts at once. A variable-stiffness
//! mechanism cannot: it moves a pretensioner or a lever with a motor of its own, and a
//! MACCEPA-like design needs 0.3–0.5 s to cross its stiffness range, fast VSAs 0.1–0.3 s (Braun,
//! Howard & Vijayakumar 2012 make the stiffness a state of the motor dynamics). The lagged type 2
//! ([`Actuator::ImpedanceLag`]) does the same: the realised stiffness `K` is a state that follows
//! the command `K_c` (the control the planner optimises) through a first-order lag, so that a
//! plan can only ask for what the mechanism delivers.

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
    /// Type 2 whose stiffness is a state: the law of Eq. 4 with the realised stiffness `K`
    /// (states `2·dof..3·dof`), which follows the commanded `K_c` (the stiffness controls) by
    /// `K' = (K_c − K) / τ_K`. Its limit `τ_K → 0` is [`Actuator::Impedance`].
    ImpedanceLag {
        damping: Damping,
        /// Time constant `τ_K` [s] of the stiffness mechanism, the same for every joint.
        time_constant: f64,
    },
}

impl Actuator {
    /// Number of controls for `dof` joints.
    pub fn nu(&self, dof: usize) -> usize {
        match self {
            Actuator::Torque => dof,
            Actuator::Impedance { .. } | Actuator::ImpedanceLag { .. } | Actuator::Vsa { .. } => {
                2 * dof
            }
        }
    }

    /// Number of states for `dof` joints.
    pub fn nx(&self, dof: usize) -> usize {
        match self {
            Actuator::Vsa { .. } => 4 * dof,
            Actuator::ImpedanceLag { .. } => 3 * dof,
            Actuator::Torque | Actuator::Impedance { .. } => 2 * dof,
        }
    }

    /// Index of the first stiffness control, if the actuator has stiffness.
    pub fn stiffness_offset(&self, dof: usize) -> Option<usize> {
        match self {
            Actuator::Torque => None,
            _ => Some(dof),
        }
    }

    /// The damping law of an impedance law (Eq. 4), with or without a stiffness lag.
    pub fn impedance_damping(&self) -> Option<&Damping> {
        match self {
            Actuator::Impedance { damping } | Actuator::ImpedanceLag { damping, .. } => {
                Some(damping)
            }
            Actuator::Torque | Actuator::Vsa { .. } => None,
        }
    }

    /// Index of the first realised-stiffness state, if the stiffness is a state that lags its
    /// command ([`Actuator::ImpedanceLag`]).
    pub fn stiffness_state_offset(&self, dof: usize) -> Option<usize> {
        match self {
            Actuator::ImpedanceLag { .. } => Some(2 * dof),
            _ => None,
        }
    }

    /// Short name used in config files and reports.
    pub fn name(&self) -> &'static str {
        match self {
            Actuator::Torque => "torque",
            Actuator::Impedance { .. } => "impedance",
            Actuator::ImpedanceLag { .. } => "impedance_lag",
            Actuator::Vsa { .. } => "vsa",
        }
    }
}
