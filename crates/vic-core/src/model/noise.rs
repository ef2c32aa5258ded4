//! Noise models: the diffusion `F(x, u)` of `dx = f dt + F dw` (paper Eq. 8).

use serde::{Deserialize, Serialize};

/// Which noise drives the plant.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub enum Noise {
    /// Deterministic plant.
    None,
    /// `F = σ x_v I_n`: every state component is disturbed in proportion to one velocity
    /// component `x_v` (the paper's `σ q1' I` for the arm, `σ q' I` for the elbow).
    StateProportional { sigma: f64, component: usize },
    /// Torque noise `e_i = (a + b q'_i) η_i` on every joint (the iCub's identified model, Eq. 16),
    /// acting through `M⁻¹` on the joint accelerations. `e` is what the identification measures:
    /// one independent torque error [N m] per sample of length `sample_time` [s]. Its white-noise
    /// equivalent has intensity `e² T_s`, so `F = √T_s M⁻¹ (a + b q')`. (Taking `a`, `b` as a
    /// diffusion in N m √s instead makes the second moments of the iCub elbow explode: the
    /// velocity-proportional part alone multiplies the variance by about 50 per 10 ms step.)
    Torque { a: f64, b: f64, sample_time: f64 },
}

impl Noise {
    /// Number of independent noise channels `p` (columns of `F`).
    pub fn nw(&self, nx: usize, dof: usize) -> usize {
        match self {
            Noise::None => 0,
            Noise::StateProportional { .. } => nx,
            Noise::Torque { .. } => dof,
        }
    }
}

impl Noise {
    /// The same noise model with its intensity multiplied by `factor` (standard deviations scale).
    pub fn scaled(self, factor: f64) -> Noise {
        match self {
            Noise::None => Noise::None,
            Noise::StateProportional { sigma, component } => Noise::StateProportional {
                sigma: sigma * factor,
                component,
            },
            Noise::Torque { a, b, sample_time } => Noise::Torque {
                a: a * factor,
                b: b * factor,
                sample_time,
            },
        }
    }
}
