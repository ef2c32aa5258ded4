//! The drift's first derivatives written out: `[∂f/∂x | ∂f/∂u]` of paper Eq. 2 for every
//! plant, actuator and field.
//!
//! Every other derivative of the crate comes from forward-mode automatic differentiation of
//! [`ArmModel::f`]. This one is the exception because ILQG linearises every knot of every
//! iteration, and there a vector dual number pays for all `n + m` directions in every operation
//! of `f`, most of them structurally zero (the accelerations depend on `q2`, `q'`, the spring and
//! the controls, and the mass matrix only on `q2`), a large part of a solve of the two-link
//! reach. Written out, the Jacobian reuses the angles and the mass matrix of the evaluation of `f`
//! it comes with and touches only the entries that can be non-zero. `tests/derivatives.rs`
//! checks it against the dual numbers and against finite differences on every model, so it
//! cannot drift from the equation it differentiates.

use super::{Actuator, ArmModel, Exogenous, Plant};
use crate::scalar::{MAX_NU, MAX_NX};

/// Columns of a drift Jacobian: `n` states then `m` controls.
const MAX_COLS: usize = MAX_NX + MAX_NU;

impl ArmModel {
    /// The drift `xdot = f(x, u)`, bit for bit as [`ArmModel::f`] computes it, and its Jacobian
    /// `jac = [∂f/∂x | ∂f/∂u]` (n × (n + m), column-major: column `j` is
    /// `jac[j*n .. (j+1)*n]`).
    pub fn f_jacobian(
        &self,
        x: &[f64],
        u: &[f64],
        ex: &Exogenous,
        xdot: &mut [f64],
        jac: &mut [f64],
    ) {
        macro_rules! by_size {
            ($(($n:literal, $c:literal))*) => {
                match (self.nx(), self.nx() + self.nu()) {
                    $(($n, $c) => {
                        let mut fixed = [[0.0; $n]; $c];
                        self.f_jacobian_fixed(x, u, ex, xdot, &mut fixed);
                        for (col, column) in fixed.iter().enumerate() {
                            jac[col * $n..(col + 1) * $n].copy_from_slice(column);
                        }
                    })*
                    (nx, cols) => unreachable!("a model with {nx} states and {cols} columns"),
                }
            };
        }
        by_size!((2, 3)(2, 4)(3, 5)(4, 6)(4, 8)(6, 10)(8, 12));
    }

    /// [`ArmModel::f_jacobian`] into a fixed-size array of `C = n + m` columns of `N = n` rows
    /// (the sizes must be the model's), so that the solvers' linearisation keeps it on the stack
    /// without a call to clear or copy it.
    ///
    /// With `r = τ − C(q, q') − B_v q' − g(q) + Jᵀ D` and `M(q) q'' = r` (Eq. 1), the
    /// accelerations' derivatives are `∂q''/∂z = M⁻¹ (∂r/∂z − (∂M/∂z) q'')`.
    #[inline(always)]
    pub(crate) fn f_jacobian_fixed<const N: usize, const C: usize>(
        &self,
        x: &[f64],
        u: &[f64],
        ex: &Exogenous,
        xdot: &mut [f64],
        jac: &mut [[f64; N]; C],
    ) {
        let (n, nx) = (self.dof(), N);
        debug_assert_eq!((self.nx(), self.nx() + self.nu()), (N, C));
        let (angles, m) = self.drift(x, u, ex, xdot);
        let (q, qd) = (&x[..n], &x[n..2 * n]);
        *jac = [[0.0; N]; C];

        // ∂r/∂(x, u), a row per joint.
        let mut dr = [[0.0; MAX_COLS]; 2];
        for (i, row) in dr.iter_mut().enumerate().take(n) {
            match &self.actuator {
                Actuator::Torque => row[nx + i] = 1.0,
                // Eq. 4: τ = τ_ff − K (q − q_d) − K_D(K) (q' − q_d').
                Actuator::Impedance { damping } => {
                    let k = u[n + i];
                    row[i] = -k;
                    row[n + i] = -damping.gain(k);
                    row[nx + i] = 1.0;
                    row[nx + n + i] = -(q[i] - ex.q_d[i]) - damping.slope() * (qd[i] - ex.qd_d[i]);
                }
                // The same law with the realised stiffness, a state.
                Actuator::ImpedanceLag { damping, .. } => {
                    let k = x[2 * n + i];
                    row[i] = -k;
                    row[n + i] = -damping.gain(k);
                    row[nx + i] = 1.0;
                    row[2 * n + i] = -(q[i] - ex.q_d[i]) - damping.slope() * (qd[i] - ex.qd_d[i]);
                }
                // Eq. 6: τ = K (θ − q).
                Actuator::Vsa { .. } => {
                    let k = u[n + i];
                    row[i] = -k;
                    row[2 * n + i] = k;
                    row[nx + n + i] = x[2 * n + i] - q[i];
                }
            }
        }
        let (bias_q, bias_qd) = self.plant.bias_torque_jacobian_at(&angles, qd);
        for i in 0..n {
            for j in 0..n {
                dr[i][j] -= bias_q[i][j];
                dr[i][n + j] -= bias_qd[i][j];
            }
        }
        if !self.field.is_none() {
            let (field_q, field_qd) = self.field_torque_jacobian(&angles, qd);
            for i in 0..n {
                for j in 0..n {
                    dr[i][j] += field_q[i][j];
                    dr[i][n + j] += field_qd[i][j];
                }
            }
        }
        let dm = self.plant.mass_matrix_gradient_at(&angles);
        let qdd = [xdot[n], xdot[(2 * n - 1).max(n)]];
        for (j, dm_j) in dm.iter().enumerate().take(n) {
            for i in 0..n {
                for l in 0..n {
                    dr[i][j] -= dm_j[i][l] * qdd[l];
                }
            }
        }

        // q' rows: ∂q'/∂q' = I. q'' rows: M⁻¹ ∂r, column by column.
        for i in 0..n {
            jac[n + i][i] = 1.0;
        }
        for (col, column) in jac.iter_mut().enumerate() {
            let rhs = [dr[0][col], dr[1][col]];
            let mut acc = [0.0; 2];
            Plant::solve_with(&m, n, &rhs[..n], &mut acc[..n]);
            // Not `copy_from_slice`: a slice copy of one or two numbers is a call to memcpy.
            #[allow(clippy::manual_memcpy)]
            for i in 0..n {
                column[n + i] = acc[i];
            }
        }

        // The motor of a VSA (Eq. 6): θ'' = (τ_m − K (θ − q)) / B.
        if let Actuator::Vsa { motor_inertia } = &self.actuator {
            for i in 0..n {
                let (b, k) = (motor_inertia[i], u[n + i]);
                let row = 3 * n + i;
                jac[3 * n + i][2 * n + i] = 1.0;
                jac[i][row] = k / b;
                jac[2 * n + i][row] = -k / b;
                jac[nx + i][row] = 1.0 / b;
                jac[nx + n + i][row] = -(x[2 * n + i] - q[i]) / b;
            }
        }

        // The stiffness lag: K' = (K_c − K) / τ_K.
        if let Actuator::ImpedanceLag { time_constant, .. } = self.actuator {
            for i in 0..n {
                let row = 2 * n + i;
                jac[row][row] = -1.0 / time_constant;
                jac[nx + n + i][row] = 1.0 / time_constant;
            }
        }
    }

    /// `(∂/∂q, ∂/∂q')` of the field's joint torques `Jᵀ(q) D(p(q), J(q) q')` (row `i`: torque
    /// `i`, column `j`: joint `j`). Both fields are linear in the hand's position and velocity.
    fn field_torque_jacobian(
        &self,
        angles: &super::Angles<f64>,
        qd: &[f64],
    ) -> ([[f64; 2]; 2], [[f64; 2]; 2]) {
        let jac = self.plant.jacobian_at(angles);
        let djac = self.plant.jacobian_gradient_at(angles);
        let v = [
            jac[0][0] * qd[0] + jac[0][1] * qd[1],
            jac[1][0] * qd[0] + jac[1][1] * qd[1],
        ];
        let force = self.field.force(self.plant.hand_position_at(angles), v);
        let (dp, dv) = self.field.gradients();
        let (mut by_q, mut by_qd) = ([[0.0; 2]; 2], [[0.0; 2]; 2]);
        for j in 0..2 {
            // The force's change with q_j: through the hand position (∂p/∂q_j = J e_j) and
            // through its velocity ((∂J/∂q_j) q').
            let dv_j = [
                djac[j][0][0] * qd[0] + djac[j][0][1] * qd[1],
                djac[j][1][0] * qd[0] + djac[j][1][1] * qd[1],
            ];
            let mut dforce = [0.0; 2];
            for (r, d) in dforce.iter_mut().enumerate() {
                *d = dp[r][0] * jac[0][j]
                    + dp[r][1] * jac[1][j]
                    + dv[r][0] * dv_j[0]
                    + dv[r][1] * dv_j[1];
            }
            // ... and with q'_j through the hand velocity (∂v/∂q'_j = J e_j).
            let mut dforce_qd = [0.0; 2];
            for (r, d) in dforce_qd.iter_mut().enumerate() {
                *d = dv[r][0] * jac[0][j] + dv[r][1] * jac[1][j];
            }
            for i in 0..2 {
                by_q[i][j] = djac[j][0][i] * force[0]
                    + djac[j][1][i] * force[1]
                    + jac[0][i] * dforce[0]
                    + jac[1][i] * dforce[1];
                by_qd[i][j] = jac[0][i] * dforce_qd[0] + jac[1][i] * dforce_qd[1];
            }
        }
        (by_q, by_qd)
    }
}
