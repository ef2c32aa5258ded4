//! Stochastic optimal open-loop control (after Berret & Jean 2020): the plan is executed
//! without any feedback, so its quality is the expected cost of the *open-loop* stochastic plant.
//! Propagate the mean and covariance,
//!
//! `m[k+1] = Φ(m[k], u[k])`,
//! `P[k+1] = A P Aᵀ + E[G Gᵀ] = A P Aᵀ + Σ_i (c_i c_iᵀ + Cx_i P Cx_iᵀ)`, `A = ∂Φ/∂x (m, u)`,
//!
//! (exact for noise affine in the state, e.g. `F = σ q' I`: `E[F Fᵀ] = σ² (m_v² + P_vv) I`), and
//! minimise `Σ ℓ(m, u) + ½ tr(ℓ_xx P) + g(m_N) + ½ tr(g_xx P_N)` over `u` on the deterministic
//! state `z = (m, vech P)`. Stiffness enters the cost through `A`, so the optimum raises it where
//! the plant is unstable or noisy — what plain ILQG cannot see.
//!
//! The module by domain: [`MomentDynamics`] (the step of `z`), [`MomentExpansion`] (its first and
//! second derivatives at one knot and their contraction with a costate), [`MomentCost`] (the
//! expected cost in moment form), and the `vech` helpers here.

mod cost;
mod derivatives;
mod directional;
mod expansion;
mod moment_dynamics;

pub use cost::MomentCost;
pub use expansion::{FlowSensitivity, MomentExpansion};
pub use moment_dynamics::MomentDynamics;

use crate::scalar::{MAX_NU, MAX_NX, Scalar};
use nalgebra::DMatrix;

/// Number of entries of `vech P` for an n×n symmetric matrix.
pub fn vech_len(n: usize) -> usize {
    n * (n + 1) / 2
}

/// Index pairs `(a, b)`, `a ≤ b`, in the order of `vech` (row by row of the upper triangle).
pub fn vech_pairs(n: usize) -> Vec<(usize, usize)> {
    (0..n).flat_map(|a| (a..n).map(move |b| (a, b))).collect()
}

/// Unpacks `vech P` into a full symmetric matrix.
pub fn unpack(n: usize, v: &[f64], p: &mut DMatrix<f64>) {
    let mut e = 0;
    for a in 0..n {
        for b in a..n {
            p[(a, b)] = v[e];
            p[(b, a)] = v[e];
            e += 1;
        }
    }
}

/// Packs the upper triangle of `p` into `vech`.
pub fn pack(n: usize, p: &DMatrix<f64>, v: &mut [f64]) {
    let mut e = 0;
    for a in 0..n {
        for b in a..n {
            v[e] = p[(a, b)];
            e += 1;
        }
    }
}

/// `Λ` with `tr(Λ δP) = λ_P · δvech P` from the covariance part `lam_p` of a costate (the
/// off-diagonal entries of `vech` count twice in the trace, so they are halved).
pub(crate) fn costate_matrix(n: usize, lam_p: &[f64], lam: &mut DMatrix<f64>) {
    let mut e = 0;
    for a in 0..n {
        for b in a..n {
            let v = lam_p[e];
            if a == b {
                lam[(a, a)] = v;
            } else {
                lam[(a, b)] = 0.5 * v;
                lam[(b, a)] = 0.5 * v;
            }
            e += 1;
        }
    }
}

/// The plant state `x` and controls `u` lifted into the scalar type `S` (no derivative seeded).
pub(crate) fn lift<S: Scalar>(x: &[f64], u: &[f64]) -> ([S; MAX_NX], [S; MAX_NU]) {
    let mut xs = [S::from(0.0); MAX_NX];
    let mut us = [S::from(0.0); MAX_NU];
    for (d, v) in xs.iter_mut().zip(x) {
        *d = S::from(*v);
    }
    for (d, v) in us.iter_mut().zip(u) {
        *d = S::from(*v);
    }
    (xs, us)
}
