//! The stagewise Newton solver of the open-loop moment problem (SOOC): its second derivatives,
//! its optimum (KKT conditions by finite differences, agreement from several starts, Monte Carlo)
//! and its receding-horizon warm start.

mod common;

use nalgebra::DMatrix;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use vic::dynamics::{EulerModel, Integrator};
use vic::model::{Actuator, ArmModel, Damping, Exogenous, Field, Noise, Plant};
use vic::solver::sooc::{MomentDynamics, MomentExpansion, pack, vech_len};

struct Case {
    name: &'static str,
    model: ArmModel,
    substeps: usize,
}

fn cases() -> Vec<Case> {
    let state_noise = Noise::StateProportional {
        sigma: 0.05,
        component: 2,
    };
    vec![
        Case {
            name: "two-link impedance, divergent field, state noise",
            model: ArmModel::new(
                Plant::TwoLink(common::two_link()),
                Actuator::Impedance {
                    damping: Damping::Proportional { alpha: 0.1 },
                },
                Field::Divergent { beta: 50.0 },
                state_noise,
            )
            .expect("valid"),
            substeps: 10,
        },
        Case {
            name: "two-link VSA, divergent field, state noise",
            model: ArmModel::new(
                Plant::TwoLink(common::two_link()),
                Actuator::Vsa {
                    motor_inertia: vec![2.0, 0.2],
                },
                Field::Divergent { beta: 50.0 },
                state_noise,
            )
            .expect("valid"),
            substeps: 5,
        },
        Case {
            name: "single joint impedance (affine damping), torque noise",
            model: ArmModel::new(
                Plant::SingleJoint(common::icub_forearm()),
                Actuator::Impedance {
                    damping: Damping::Affine {
                        slope: 0.075,
                        offset: -0.0015,
                    },
                },
                Field::None,
                Noise::Torque {
                    a: 0.15,
                    b: 0.37,
                    sample_time: 0.01,
                },
            )
            .expect("valid"),
            substeps: 10,
        },
    ]
}

/// A posture in motion, a positive stiffness, a positive-definite covariance; a costate with a
/// positive-definite covariance part (as the expected cost's is).
fn point(model: &ArmModel, rng: &mut StdRng) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (n, dof) = (model.nx(), model.dof());
    let nz = n + vech_len(n);
    let mut z = vec![0.0; nz];
    for i in 0..dof {
        z[i] = rng.random_range(0.2..1.6);
        z[dof + i] = rng.random_range(-1.5..1.5);
    }
    if n > 2 * dof {
        for i in 0..dof {
            z[2 * dof + i] = z[i] + rng.random_range(-0.1..0.1);
            z[3 * dof + i] = rng.random_range(-1.0..1.0);
        }
    }
    let spd = |rng: &mut StdRng, s: f64| {
        let l = DMatrix::from_fn(n, n, |i, j| {
            if j <= i {
                rng.random_range(-s..s)
            } else {
                0.0
            }
        });
        &l * l.transpose() + DMatrix::identity(n, n) * (s * s * 0.1)
    };
    let p = spd(rng, 0.05);
    pack(n, &p, &mut z[n..]);
    let mut u = vec![0.0; model.nu()];
    for (j, v) in u.iter_mut().enumerate() {
        *v = if j < dof {
            rng.random_range(-1.5..1.5)
        } else {
            rng.random_range(2.0..60.0)
        };
    }
    let mut lam = vec![0.0; nz];
    for v in lam.iter_mut().take(n) {
        *v = rng.random_range(-100.0..100.0);
    }
    let big = spd(rng, 30.0);
    // vech costate of tr(Λ P): λ_e = Λ_aa on the diagonal, 2 Λ_ab off it.
    let mut e = 0;
    for a in 0..n {
        for b in a..n {
            lam[n + e] = if a == b { big[(a, a)] } else { 2.0 * big[(a, b)] };
            e += 1;
        }
    }
    (z, u, lam)
}

/// `∇_{(z,u)} (λ · F(z, u))` from the exact first derivatives.
fn gradient(dynamics: &MomentDynamics, k: usize, z: &[f64], u: &[f64], lam: &[f64]) -> Vec<f64> {
    let base = dynamics.base();
    let mut e = MomentExpansion::new(base.model.nx(), base.model.nu(), base.model.nw());
    dynamics.expand(k, z, u, false, &mut e);
    let l = nalgebra::DVector::from_column_slice(lam);
    let gz = e.a.transpose() * &l;
    let gu = e.b.transpose() * &l;
    gz.iter().chain(gu.iter()).copied().collect()
}

/// [`MomentExpansion::curvature`] (costate-weighted second derivatives of the moment step,
/// including the third derivatives of the flow and the noise gain's second and third) against
/// central differences of the exact gradient `∇(λ · F)`, block by block.
#[test]
fn moment_curvature_matches_finite_differences() {
    let mut rng = StdRng::seed_from_u64(17);
    for case in cases() {
        let (n, m) = (case.model.nx(), case.model.nu());
        let nz = n + vech_len(n);
        let exogenous = vec![
            Exogenous {
                q_d: [0.7, 1.1],
                qd_d: [0.3, -0.2],
                tau_ext: [0.0; 2],
            };
            4
        ];
        let base = EulerModel {
            model: case.model.clone(),
            dt: 0.01,
            substeps: case.substeps,
            integrator: Integrator::SemiImplicit,
            exogenous,
        };
        let dynamics = MomentDynamics::new(&base);
        let (z, u, lam) = point(&case.model, &mut rng);
        let k = 1;
        let mut e = MomentExpansion::for_dynamics(&dynamics);
        dynamics.expand(k, &z, &u, true, &mut e);
        let (mut hzz, mut huz, mut huu) = (
            DMatrix::zeros(nz, nz),
            DMatrix::zeros(m, nz),
            DMatrix::zeros(m, m),
        );
        e.curvature(&lam, &mut hzz, &mut huz, &mut huu);
        let mut h = DMatrix::zeros(nz + m, nz + m);
        h.view_mut((0, 0), (nz, nz)).copy_from(&hzz);
        h.view_mut((nz, 0), (m, nz)).copy_from(&huz);
        h.view_mut((0, nz), (nz, m)).copy_from(&huz.transpose());
        h.view_mut((nz, nz), (m, m)).copy_from(&huu);
        let mut fd = DMatrix::zeros(nz + m, nz + m);
        let mut pt: Vec<f64> = z.iter().chain(&u).copied().collect();
        for j in 0..nz + m {
            let v = pt[j];
            let step = 1e-5 * (1.0 + v.abs());
            pt[j] = v + step;
            let gp = gradient(&dynamics, k, &pt[..nz], &pt[nz..], &lam);
            pt[j] = v - step;
            let gm = gradient(&dynamics, k, &pt[..nz], &pt[nz..], &lam);
            pt[j] = v;
            for i in 0..nz + m {
                fd[(i, j)] = (gp[i] - gm[i]) / (2.0 * step);
            }
        }
        // Blocks: mean, covariance, control.
        let blocks = [("m", 0, n), ("P", n, nz), ("u", nz, nz + m)];
        for &(rn, r0, r1) in &blocks {
            for &(cn, c0, c1) in &blocks {
                let a = h.view((r0, c0), (r1 - r0, c1 - c0));
                let b = fd.view((r0, c0), (r1 - r0, c1 - c0));
                let err = (a - b).amax();
                eprintln!(
                    "{}: block {rn}{cn}: max |H| {:.3e}, max |FD| {:.3e}, max error {:.3e}",
                    case.name,
                    a.amax(),
                    b.amax(),
                    err
                );
                // Central differences of exact gradients: error ~1e-10 of the block's scale.
                assert!(
                    err <= 1e-6 * b.amax().max(1e-300) || (a.amax() == 0.0 && b.amax() == 0.0),
                    "{}: block {rn}{cn} off by {err:e} (scale {:e})",
                    case.name,
                    b.amax()
                );
            }
        }
    }
}
