//! Rigid-body dynamics of the limb (paper Eq. 1 and Eq. 15): `M(q) q'' + C(q, q') + B_v q' + g(q) =
//! τ + Jᵀ(q) D`. Angles in rad, torques in N m, lengths in m.

use crate::scalar::{Scalar, c};
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

/// `sin` and `cos` of the joint angles and of their sum (`s12 = sin(q1 + q2)`); for a single
/// joint `q2 = 0`.
#[derive(Debug, Clone, Copy)]
pub struct Angles<S> {
    pub(crate) s1: S,
    pub c1: S,
    pub s2: S,
    pub c2: S,
    pub(crate) s12: S,
    pub(crate) c12: S,
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

    /// The sines and cosines of a configuration, each computed once: one evaluation of the
    /// dynamics needs them in the mass matrix, the bias torques, the hand position and the
    /// Jacobian, and with nested dual numbers (the solver's derivatives) the trigonometry is most
    /// of the cost of an evaluation.
    #[inline(always)]
    pub fn angles<S: Scalar>(&self, q: &[S]) -> Angles<S> {
        let (s1, c1) = q[0].sin_cos();
        match self {
            Plant::SingleJoint(_) => Angles {
                s1,
                c1,
                s2: S::zero(),
                c2: S::one(),
                s12: s1,
                c12: c1,
            },
            Plant::TwoLink(_) => {
                let (s2, c2) = q[1].sin_cos();
                let (s12, c12) = (q[0] + q[1]).sin_cos();
                Angles {
                    s1,
                    c1,
                    s2,
                    c2,
                    s12,
                    c12,
                }
            }
        }
    }

    /// The [`Angles`] that [`Plant::mass_matrix_at`] and [`Plant::bias_torque_at`] read, and no
    /// more: for the two-link arm only the elbow's (`s2`, `c2`; the mass matrix and the Coriolis
    /// torques depend on `q2` alone), one `sin_cos` instead of three. Without a force field the
    /// dynamics needs nothing else, and the trigonometry is a large part of a rollout. The hand's
    /// entries (`s1`, `c1`, `s12`, `c12`) are NaN, so that a kinematic use of them shows at once.
    #[inline(always)]
    pub(crate) fn dynamics_angles<S: Scalar>(&self, q: &[S]) -> Angles<S> {
        match self {
            Plant::SingleJoint(_) => self.angles(q),
            Plant::TwoLink(_) => {
                let (s2, c2) = q[1].sin_cos();
                let nan = c::<S>(f64::NAN);
                Angles {
                    s1: nan,
                    c1: nan,
                    s2,
                    c2,
                    s12: nan,
                    c12: nan,
                }
            }
        }
    }

    /// Mass matrix `M(q)`, row-major 2×2 (only `[0][0]` used for a single joint).
    pub fn mass_matrix<S: Scalar>(&self, q: &[S]) -> [[S; 2]; 2] {
        self.mass_matrix_at(&self.angles(q))
    }

    /// [`Plant::mass_matrix`] from the configuration's [`Angles`].
    /// Inlined: see [`crate::model::ArmModel::f`].
    #[inline(always)]
    pub(crate) fn mass_matrix_at<S: Scalar>(&self, a: &Angles<S>) -> [[S; 2]; 2] {
        match self {
            Plant::SingleJoint(p) => [[c(p.inertia), S::zero()], [S::zero(), S::one()]],
            Plant::TwoLink(p) => {
                let h = c::<S>(p.m2 * p.l1 * p.s2) * a.c2;
                let m11 = c::<S>(p.i1 + p.i2 + p.m2 * p.l1 * p.l1) + h * 2.0;
                let m12 = c::<S>(p.i2) + h;
                [[m11, m12], [m12, c(p.i2)]]
            }
        }
    }

    /// Velocity- and gravity-dependent torques `C(q, q') + B_v q' + g(q)` (the bias torques).
    #[cfg(test)]
    pub(crate) fn bias_torque<S: Scalar>(&self, q: &[S], qd: &[S], out: &mut [S]) {
        self.bias_torque_at(&self.angles(q), qd, out)
    }

    /// [`Plant::bias_torque`] from the configuration's [`Angles`].
    /// Inlined: see [`crate::model::ArmModel::f`].
    #[inline(always)]
    pub(crate) fn bias_torque_at<S: Scalar>(&self, a: &Angles<S>, qd: &[S], out: &mut [S]) {
        match self {
            Plant::SingleJoint(p) => {
                out[0] = c::<S>(p.mass * p.gravity * p.com) * a.c1 + qd[0] * p.viscosity;
            }
            Plant::TwoLink(p) => {
                let h = c::<S>(p.m2 * p.l1 * p.s2) * a.s2;
                let b = &p.viscosity;
                out[0] = -h * qd[1] * (qd[0] * 2.0 + qd[1]) + qd[0] * b[0][0] + qd[1] * b[0][1];
                out[1] = h * qd[0] * qd[0] + qd[0] * b[1][0] + qd[1] * b[1][1];
            }
        }
    }

    /// `∂M/∂q_j` for each joint `j` (entry `j`), from the configuration's [`Angles`]: the
    /// two-link arm's mass matrix depends on `q2` alone, a single joint's is constant. For the
    /// drift's Jacobian ([`crate::model::ArmModel::f_jacobian`]).
    pub(crate) fn mass_matrix_gradient_at(&self, a: &Angles<f64>) -> [[[f64; 2]; 2]; 2] {
        match self {
            Plant::SingleJoint(_) => [[[0.0; 2]; 2]; 2],
            Plant::TwoLink(p) => {
                let dh = -(p.m2 * p.l1 * p.s2) * a.s2;
                [[[0.0; 2]; 2], [[dh * 2.0, dh], [dh, 0.0]]]
            }
        }
    }

    /// The bias torques' Jacobians `(∂/∂q, ∂/∂q')` (row `i`: torque `i`, column `j`: joint `j`),
    /// from the configuration's [`Angles`]: [`Plant::bias_torque_at`] differentiated.
    pub(crate) fn bias_torque_jacobian_at(
        &self,
        a: &Angles<f64>,
        qd: &[f64],
    ) -> ([[f64; 2]; 2], [[f64; 2]; 2]) {
        match self {
            Plant::SingleJoint(p) => (
                [[-(p.mass * p.gravity * p.com) * a.s1, 0.0], [0.0; 2]],
                [[p.viscosity, 0.0], [0.0; 2]],
            ),
            Plant::TwoLink(p) => {
                let k = p.m2 * p.l1 * p.s2;
                let (h, dh) = (k * a.s2, k * a.c2);
                let b = &p.viscosity;
                (
                    [
                        [0.0, -dh * qd[1] * (qd[0] * 2.0 + qd[1])],
                        [0.0, dh * qd[0] * qd[0]],
                    ],
                    [
                        [
                            -h * qd[1] * 2.0 + b[0][0],
                            -h * (qd[0] + qd[1]) * 2.0 + b[0][1],
                        ],
                        [h * qd[0] * 2.0 + b[1][0], b[1][1]],
                    ],
                )
            }
        }
    }

    /// Position of the hand (two-link) or of the forearm tip (single joint) [m], shoulder at the
    /// origin: `x = l1 cos q1 + l2 cos(q1 + q2)`, `y = l1 sin q1 + l2 sin(q1 + q2)`.
    pub fn hand_position<S: Scalar>(&self, q: &[S]) -> [S; 2] {
        self.hand_position_at(&self.angles(q))
    }

    /// [`Plant::hand_position`] from the configuration's [`Angles`].
    /// Inlined: see [`crate::model::ArmModel::f`].
    #[inline(always)]
    pub(crate) fn hand_position_at<S: Scalar>(&self, a: &Angles<S>) -> [S; 2] {
        match self {
            Plant::SingleJoint(p) => [a.c1 * p.length, a.s1 * p.length],
            Plant::TwoLink(p) => [a.c1 * p.l1 + a.c12 * p.l2, a.s1 * p.l1 + a.s12 * p.l2],
        }
    }

    /// Hand Jacobian `J(q) = ∂(x, y)/∂q`, row-major 2×dof (column 1 unused for a single joint).
    pub fn jacobian<S: Scalar>(&self, q: &[S]) -> [[S; 2]; 2] {
        self.jacobian_at(&self.angles(q))
    }

    /// [`Plant::jacobian`] from the configuration's [`Angles`].
    /// Inlined: see [`crate::model::ArmModel::f`].
    #[inline(always)]
    pub(crate) fn jacobian_at<S: Scalar>(&self, a: &Angles<S>) -> [[S; 2]; 2] {
        match self {
            Plant::SingleJoint(p) => [[-a.s1 * p.length, S::zero()], [a.c1 * p.length, S::zero()]],
            Plant::TwoLink(p) => [
                [-a.s1 * p.l1 - a.s12 * p.l2, -a.s12 * p.l2],
                [a.c1 * p.l1 + a.c12 * p.l2, a.c12 * p.l2],
            ],
        }
    }

    /// `∂J/∂q_j` for each joint `j` (entry `j`, row-major like [`Plant::jacobian_at`]), from the
    /// configuration's [`Angles`].
    pub(crate) fn jacobian_gradient_at(&self, a: &Angles<f64>) -> [[[f64; 2]; 2]; 2] {
        match self {
            Plant::SingleJoint(p) => [
                [[-a.c1 * p.length, 0.0], [-a.s1 * p.length, 0.0]],
                [[0.0; 2]; 2],
            ],
            Plant::TwoLink(p) => {
                let (c12, s12) = (a.c12 * p.l2, a.s12 * p.l2);
                [
                    [[-a.c1 * p.l1 - c12, -c12], [-a.s1 * p.l1 - s12, -s12]],
                    [[-c12, -c12], [-s12, -s12]],
                ]
            }
        }
    }

    /// Solves `m a = rhs` for a mass matrix `m` of a plant with `dof` joints.
    /// Inlined: see [`crate::model::ArmModel::f`].
    #[inline(always)]
    pub fn solve_with<S: Scalar>(m: &[[S; 2]; 2], dof: usize, rhs: &[S], out: &mut [S]) {
        if dof == 1 {
            out[0] = rhs[0] / m[0][0];
        } else {
            let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
            out[0] = (m[1][1] * rhs[0] - m[0][1] * rhs[1]) / det;
            out[1] = (m[0][0] * rhs[1] - m[1][0] * rhs[0]) / det;
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
pub(crate) mod tests {
    use super::*;

    /// A two-link arm for the tests of this module and of the solvers'.
    pub(crate) fn arm() -> Plant {
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

    /// A single joint for the tests of this module and of the model's.
    pub(crate) fn joint() -> Plant {
        Plant::SingleJoint(SingleJoint {
            inertia: 0.1,
            mass: 1.0,
            com: 0.1,
            length: 0.3,
            gravity: 9.81,
            viscosity: 0.05,
        })
    }

    #[test]
    fn the_dynamics_angles_give_the_same_dynamics_and_no_hand() {
        for (p, q) in [
            (arm(), [0.3_f64, 1.1]),
            (arm(), [-2.0, 2.9]),
            (joint(), [0.7, 0.0]),
        ] {
            let (all, few) = (p.angles(&q), p.dynamics_angles(&q));
            let qd = [0.4, -1.3];
            let (mut b_all, mut b_few) = ([0.0; 2], [0.0; 2]);
            p.bias_torque_at(&all, &qd, &mut b_all);
            p.bias_torque_at(&few, &qd, &mut b_few);
            assert_eq!(b_all.map(f64::to_bits), b_few.map(f64::to_bits));
            let (m_all, m_few) = (p.mass_matrix_at(&all), p.mass_matrix_at(&few));
            assert_eq!(m_all, m_few);
            if matches!(p, Plant::TwoLink(_)) {
                assert!(p.hand_position_at(&few).iter().all(|v| v.is_nan()));
            }
        }
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
    fn jacobian_matches_finite_differences_of_the_hand_position() {
        // The cached angles feed both: each is checked against the other and against the
        // forward kinematics written out with plain sin and cos.
        for (p, q) in [
            (arm(), [0.3_f64, 1.1]),
            (arm(), [-2.0, 2.9]),
            (joint(), [0.7, 0.0]),
        ] {
            let dof = p.dof();
            let hand = p.hand_position(&q);
            let direct = match &p {
                Plant::TwoLink(a) => [
                    a.l1 * q[0].cos() + a.l2 * (q[0] + q[1]).cos(),
                    a.l1 * q[0].sin() + a.l2 * (q[0] + q[1]).sin(),
                ],
                Plant::SingleJoint(j) => [j.length * q[0].cos(), j.length * q[0].sin()],
            };
            assert_eq!(hand, direct);
            let jac = p.jacobian(&q);
            let eps = 1e-6;
            for k in 0..dof {
                let (mut qp, mut qm) = (q, q);
                qp[k] += eps;
                qm[k] -= eps;
                let (a, b) = (p.hand_position(&qp), p.hand_position(&qm));
                for r in 0..2 {
                    let fd = (a[r] - b[r]) / (2.0 * eps);
                    assert!(
                        (jac[r][k] - fd).abs() < 1e-8,
                        "J[{r}][{k}] {} vs {fd}",
                        jac[r][k]
                    );
                }
            }
        }
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
