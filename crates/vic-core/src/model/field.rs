//! External force fields acting on the hand (the `D` of paper Eq. 1).

use crate::scalar::Scalar;
use serde::{Deserialize, Serialize};

/// A force field on the hand, in N.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub enum Field {
    /// No external force.
    None,
    /// Divergent field `D = (β x, 0)`: pushes the hand away from the line `x = 0`, harder the
    /// further it is (β in N/m). Unpredictable: which side the hand falls to depends on noise.
    Divergent { beta: f64 },
    /// Velocity-dependent curl field `D = B_c v` (B_c in N s/m, row-major): predictable, and so
    /// compensable by the feedforward plan alone.
    Curl { matrix: [[f64; 2]; 2] },
}

impl Field {
    /// Force on the hand at position `hand` moving with velocity `hand_velocity`.
    /// Inlined: see [`crate::model::ArmModel::f`].
    #[inline(always)]
    pub fn force<S: Scalar>(&self, hand: [S; 2], hand_velocity: [S; 2]) -> [S; 2] {
        match *self {
            Field::None => [S::zero(), S::zero()],
            Field::Divergent { beta } => [hand[0] * beta, S::zero()],
            Field::Curl { matrix: b } => [
                hand_velocity[0] * b[0][0] + hand_velocity[1] * b[0][1],
                hand_velocity[0] * b[1][0] + hand_velocity[1] * b[1][1],
            ],
        }
    }

    /// `(∂D/∂p, ∂D/∂v)`, row-major: both fields are linear in the hand's position and velocity,
    /// so these are constants (the drift's Jacobian uses them).
    pub fn gradients(&self) -> ([[f64; 2]; 2], [[f64; 2]; 2]) {
        match *self {
            Field::None => ([[0.0; 2]; 2], [[0.0; 2]; 2]),
            Field::Divergent { beta } => ([[beta, 0.0], [0.0; 2]], [[0.0; 2]; 2]),
            Field::Curl { matrix } => ([[0.0; 2]; 2], matrix),
        }
    }

    /// True when there is no field (the joint torques need no Jacobian).
    pub fn is_none(&self) -> bool {
        matches!(self, Field::None) || matches!(self, Field::Divergent { beta } if *beta == 0.0)
    }
}
