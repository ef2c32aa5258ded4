//! How the drift is integrated over one control step: the one integrator of the project (the
//! planner, the Monte Carlo and the board step the plant through [`flow`]).

use crate::model::{ArmModel, Exogenous};
use crate::scalar::{MAX_NX, Scalar};

/// How the drift is integrated over one control step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Integrator {
    /// Explicit Euler (the paper's): `x += h f(x, u)`.
    Euler,
    /// Semi-implicit (symplectic) Euler: velocities first, then positions with the new
    /// velocities. Stable for undamped springs (the VSA) where explicit Euler gains energy.
    SemiImplicit,
    /// The classical fourth-order Runge–Kutta step, control and exogenous input held: error
    /// O(h⁴) per unit time against Euler's O(h), so one step per knot can stand in for ten
    /// Euler sub-steps where the sub-steps were there for accuracy rather than stability
    /// (four drift evaluations per step instead of ten; the step's derivatives take one
    /// differentiated step per knot).
    Rk4,
}

/// Integrates the drift of `model` over `dt` in `substeps` steps, control and exogenous input
/// held. The one integrator of the project: the planner, the Monte Carlo and the board use it.
#[allow(clippy::too_many_arguments)]
pub fn flow<S: Scalar>(
    model: &ArmModel,
    ex: &Exogenous,
    dt: f64,
    substeps: usize,
    integrator: Integrator,
    x: &[S],
    u: &[S],
    next: &mut [S],
) {
    flow_body(model, ex, dt, substeps, integrator, x, u, next);
}

/// [`flow`]'s body, inlined where it is compiled for a particular instruction set.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(super) fn flow_body<S: Scalar>(
    model: &ArmModel,
    ex: &Exogenous,
    dt: f64,
    substeps: usize,
    integrator: Integrator,
    x: &[S],
    u: &[S],
    next: &mut [S],
) {
    let nx = model.nx();
    let h = dt / substeps as f64;
    let mut cur = [<S as Scalar>::zero(); MAX_NX];
    cur[..nx].copy_from_slice(&x[..nx]);
    let mut xdot = [<S as Scalar>::zero(); MAX_NX];
    for _ in 0..substeps {
        model.f(&cur[..nx], u, ex, &mut xdot[..nx]);
        match integrator {
            Integrator::Euler => {
                for i in 0..nx {
                    cur[i] += xdot[i] * h;
                }
            }
            Integrator::SemiImplicit => {
                let dof = model.dof();
                let blocks = model.second_order_states();
                // Velocities are the second half of each (position, velocity) block.
                for block in (0..blocks).step_by(2 * dof) {
                    for i in 0..dof {
                        cur[block + dof + i] += xdot[block + dof + i] * h;
                        cur[block + i] += cur[block + dof + i] * h;
                    }
                }
                // First-order states (a lagged stiffness) have no velocity: explicit Euler.
                for i in blocks..nx {
                    cur[i] += xdot[i] * h;
                }
            }
            Integrator::Rk4 => {
                // k₁ = xdot; x += h/6 (k₁ + 2k₂ + 2k₃ + k₄), kᵢ at x + cᵢ h kᵢ₋₁.
                let mut sum = xdot;
                let mut stage = [<S as Scalar>::zero(); MAX_NX];
                let mut slope = xdot;
                for (c, w) in [(0.5, 2.0), (0.5, 2.0), (1.0, 1.0)] {
                    for i in 0..nx {
                        stage[i] = cur[i] + slope[i] * (c * h);
                    }
                    model.f(&stage[..nx], u, ex, &mut slope[..nx]);
                    for i in 0..nx {
                        sum[i] += slope[i] * w;
                    }
                }
                for i in 0..nx {
                    cur[i] += sum[i] * (h / 6.0);
                }
            }
        }
    }
    next[..nx].copy_from_slice(&cur[..nx]);
}
