//! Rigid-body dynamics of the limb (paper Eq. 1 and Eq. 15): `M(q) q'' + C(q, q') + B_v q' + g(q) =
//! τ + Jᵀ(q) D`. Angles in rad, torques in N m, lengths in m.

use crate::core::scalar::{Scalar, c};
use serde::{Deserialize, Serialize};

/// One joint rotating in the vertical plane (paper Eq. 15, the iCub forearm):
/// `J q'' + m g l_c cos q + b q' = τ`, with `q` measured from the horizontal.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct SingleJoint {
    /// Moment of inertia about the joint axis `J` [kg m²].
    pub inertia: f64,
    /// Mass of the forearm `m` [kg].
    pub mass: f64,
    /// Distance from the joint to the centre of mass `l_c` [m].
    pub com: f64,
    /// Length of the forearm `l` [m] (for the tip position only).
    pub length: f64,
    /// Gravity `g` [m/s²]; 0 for a joint moving in the horizontal plane.
    pub gravity: f64,
    /// Joint viscosity `b` [N m s/rad].
    pub viscosity: f64,
}

/// Two-link planar arm in the horizontal plane (paper Eq. 1, Li & Todorov's arm model), inertias
/// about the joint axes: `M11 = I1 + I2 + m2 l1² + 2 m2 l1 s2 cos q2`, `M12 = I2 + m2 l1 s2 cos q2`,
/// `M22 = I2`.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct TwoLink {
    /// Upper-arm length `l1` [m].
    pub l1: f64,
    /// Forearm length `l2` [m].
    pub l2: f64,
    /// Distance from the elbow to the forearm's centre of mass `s2` [m].
    pub s2: f64,
    /// Forearm mass `m2` [kg].
    pub m2: f64,
    /// Shoulder-side inertia `I1` about the shoulder axis [kg m²].
    pub i1: f64,
    /// Forearm inertia `I2` about the elbow axis [kg m²].
    pub i2: f64,
    /// Joint viscosity matrix `B_v` [N m s/rad].
    pub viscosity: [[f64; 2]; 2],
}

/// The limb: which rigid-body model moves.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub enum Plant {
    SingleJoint(SingleJoint),
    TwoLink(TwoLink),
}

impl Plant {
    /// Degrees of freedom (number of joints).
    pub fn dof(&self) -> usize {
        match self {
            Plant::SingleJoint(_) => 1,
            Plant::TwoLink(_) => 2,
        }
    }

    /// Mass matrix `M(q)`, row-major 2×2 (only `[0][0]` used for a single joint).
    pub fn mass_matrix<S: Scalar>(&self, q: &[S]) -> [[S; 2]; 2] {
        match self {
            Plant::SingleJoint(p) => [[c(p.inertia), S::zero()], [S::zero(), S::one()]],
            Plant::TwoLink(p) => {
                let h = c::<S>(p.m2 * p.l1 * p.s2) * q[1].cos();
                let m11 = c::<S>(p.i1 + p.i2 + p.m2 * p.l1 * p.l1) + h * 2.0;
                let m12 = c::<S>(p.i2) + h;
                [[m11, m12], [m12, c(p.i2)]]
            }
        }
    }

    /// Velocity- and gravity-dependent torques `C(q, q') + B_v q' + g(q)` (the bias torques).
    pub fn bias_torque<S: Scalar>(&self, q: &[S], qd: &[S], out: &mut [S]) {
        match self {
            Plant::SingleJoint(p) => {
                out[0] = c::<S>(p.mass * p.gravity * p.com) * q[0].cos() + qd[0] * p.viscosity;
            }
            Plant::TwoLink(p) => {
                let h = c::<S>(p.m2 * p.l1 * p.s2) * q[1].sin();
                let b = &p.viscosity;
                out[0] = -h * qd[1] * (qd[0] * 2.0 + qd[1]) + qd[0] * b[0][0] + qd[1] * b[0][1];
                out[1] = h * qd[0] * qd[0] + qd[0] * b[1][0] + qd[1] * b[1][1];
            }
        }
    }

    /// Position of the hand (two-link) or of the forearm tip (single joint) [m], shoulder at the
    /// origin: `x = l1 cos q1 + l2 cos(q1 + q2)`, `y = l1 sin q1 + l2 sin(q1 + q2)`.
    pub fn hand_position<S: Scalar>(&self, q: &[S]) -> [S; 2] {
        match self {
            Plant::SingleJoint(p) => [q[0].cos() * p.length, q[0].sin() * p.length],
            Plant::TwoLink(p) => {
                let q12 = q[0] + q[1];
                [
                    q[0].cos() * p.l1 + q12.cos() * p.l2,
                    q[0].sin() * p.l1 + q12.sin() * p.l2,
                ]
            }
        }
    }

    /// Hand Jacobian `J(q) = ∂(x, y)/∂q`, row-major 2×dof (column 1 unused for a single joint).
    pub fn jacobian<S: Scalar>(&self, q: &[S]) -> [[S; 2]; 2] {
        match self {
            Plant::SingleJoint(p) => [
                [-q[0].sin() * p.length, S::zero()],
                [q[0].cos() * p.length, S::zero()],
            ],
            Plant::TwoLink(p) => {
                let q12 = q[0] + q[1];
                let (s1, c1) = (q[0].sin(), q[0].cos());
                let (s12, c12) = (q12.sin(), q12.cos());
                [
                    [-s1 * p.l1 - s12 * p.l2, -s12 * p.l2],
                    [c1 * p.l1 + c12 * p.l2, c12 * p.l2],
                ]
            }
        }
    }

    /// Solves `M(q) a = rhs` for the joint accelerations `a`.
    pub fn solve_mass<S: Scalar>(&self, q: &[S], rhs: &[S], out: &mut [S]) {
        let m = self.mass_matrix(q);
        match self {
            Plant::SingleJoint(_) => out[0] = rhs[0] / m[0][0],
            Plant::TwoLink(_) => {
                let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
                out[0] = (m[1][1] * rhs[0] - m[0][1] * rhs[1]) / det;
                out[1] = (m[0][0] * rhs[1] - m[1][0] * rhs[0]) / det;
            }
        }
    }

    /// Inverse kinematics of the two-link arm for a hand position, elbow flexed (q2 > 0).
    /// Returns `None` when the point is out of reach. For a single joint, the angle of the tip.
    pub fn inverse_kinematics(&self, hand: [f64; 2]) -> Option<[f64; 2]> {
        match self {
            Plant::SingleJoint(_) => Some([hand[1].atan2(hand[0]), 0.0]),
            Plant::TwoLink(p) => {
                let r2 = hand[0] * hand[0] + hand[1] * hand[1];
                let cos_q2 = (r2 - p.l1 * p.l1 - p.l2 * p.l2) / (2.0 * p.l1 * p.l2);
                if !(-1.0..=1.0).contains(&cos_q2) {
                    return None;
                }
                let q2 = cos_q2.acos();
                let q1 = hand[1].atan2(hand[0]) - (p.l2 * q2.sin()).atan2(p.l1 + p.l2 * cos_q2);
                Some([q1, q2])
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn arm() -> Plant {
        Plant::TwoLink(TwoLink {
            l1: 0.30,
            l2: 0.33,
            s2: 0.16,
            m2: 1.0,
            i1: 0.025,
            i2: 0.045,
            viscosity: [[0.05, 0.025], [0.025, 0.05]],
        })
    }

    #[test]
    fn inverse_kinematics_inverts_forward_kinematics() {
        let p = arm();
        for hand in [[0.0, 0.31], [0.0, 0.56], [0.1, 0.4], [-0.2, 0.3]] {
            let q = p.inverse_kinematics(hand).unwrap();
            let back = p.hand_position(&q);
            assert!((back[0] - hand[0]).abs() < 1e-12 && (back[1] - hand[1]).abs() < 1e-12);
            assert!(q[1] > 0.0);
        }
        assert!(p.inverse_kinematics([0.0, 0.7]).is_none());
    }

    #[test]
    fn coriolis_matches_christoffel_symbols_of_mass_matrix() {
        // C_i = Σ_jk (∂M_ij/∂q_k − ½ ∂M_jk/∂q_i) q'_j q'_k, from finite differences of M.
        let p = arm();
        let Plant::TwoLink(params) = &p else {
            unreachable!()
        };
        let q = [0.3, 1.1];
        let qd = [0.7, -1.3];
        let eps = 1e-6;
        let dm = |k: usize| {
            let mut qp = q;
            let mut qm = q;
            qp[k] += eps;
            qm[k] -= eps;
            let (a, b) = (p.mass_matrix(&qp), p.mass_matrix(&qm));
            [
                [
                    (a[0][0] - b[0][0]) / (2.0 * eps),
                    (a[0][1] - b[0][1]) / (2.0 * eps),
                ],
                [
                    (a[1][0] - b[1][0]) / (2.0 * eps),
                    (a[1][1] - b[1][1]) / (2.0 * eps),
                ],
            ]
        };
        let dms = [dm(0), dm(1)];
        let mut expected = [0.0; 2];
        for (i, e) in expected.iter_mut().enumerate() {
            for j in 0..2 {
                for k in 0..2 {
                    *e += (dms[k][i][j] - 0.5 * dms[i][j][k]) * qd[j] * qd[k];
                }
            }
        }
        let mut bias = [0.0; 2];
        p.bias_torque(&q, &qd, &mut bias);
        let b = params.viscosity;
        let coriolis = [
            bias[0] - b[0][0] * qd[0] - b[0][1] * qd[1],
            bias[1] - b[1][0] * qd[0] - b[1][1] * qd[1],
        ];
        for i in 0..2 {
            assert!(
                (coriolis[i] - expected[i]).abs() < 1e-7,
                "{coriolis:?} vs {expected:?}"
            );
        }
    }
}
