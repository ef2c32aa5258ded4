//! How a plan is made: the method chosen in `[solver] method` or on the command line.

use serde::{Deserialize, Serialize};

/// How a plan is made.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// ILQG: a nominal plan with locally optimal feedback gains (the feedback law of Eq. 9, or
    /// Eq. 13 with a delay), made for the scenario's feedback delay.
    #[default]
    Ilqg,
    /// Stochastic optimal open-loop control: torque and stiffness for execution without feedback,
    /// optimal for the open-loop plant's mean and covariance (the Eq. 14 cost in expectation).
    /// Delay-free by nature: nothing is fed back.
    Sooc,
    /// The same open-loop problem solved by [`vic_core::solver::sooc_fast`]: an exact gradient
    /// by the covariance adjoint, `O(n³)` per knot instead of the exact Newton step's `O(n⁶)`,
    /// and projected Newton–CG steps (Hessian-vector products by differences of that gradient,
    /// preconditioned by a Riccati solve of a mean-only model); its optimum is a stationary
    /// point of the same cost.
    SoocFast,
}

impl Method {
    /// The name used in scenario files, plan files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::Ilqg => "ilqg",
            Method::Sooc => "sooc",
            Method::SoocFast => "sooc_fast",
        }
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
