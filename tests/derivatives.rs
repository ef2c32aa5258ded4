//! Derivatives of every model × actuator × field × noise combination.
//!
//! * [`ArmModel::f`] and [`ArmModel::diffusion`] against an independent transcription of the
//!   equations of motion of paper Eq. 1–8, 15 and 16 (written here with nalgebra, not with the
//!   crate's code).
//! * The forward-mode Jacobians of `f` and `diffusion` (`f_x`, `f_u`, `∂F/∂x`, `∂F/∂u`) against
//!   central finite differences, and [`ArmModel::f_jacobian`], written out, against them.
//! * [`DiscreteDynamics::linearize`] (`A = I + Δ f_x`, `B = Δ f_u`, `c = √Δ F`, `Cx`, `Cu`) against
//!   central finite differences of [`DiscreteDynamics::step`] and [`DiscreteDynamics::noise_gain`].

use crate::common;

use nalgebra::{DMatrix, DVector, Matrix2, Vector2};
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use vic_core::dynamics::{DiscreteDynamics, Dynamics, Integrator, Linearization, NoiseKind};
use vic_core::model::{
    Actuator, ArmModel, Damping, Exogenous, Field, Noise, Plant, SingleJoint, TwoLink,
};
use vic_core::scalar::{MAX_NU, MAX_NW, MAX_NX};

/// Random points per model.
const POINTS: usize = 6;

fn single_joint() -> SingleJoint {
    // A little viscosity, so that its term is differentiated too.
    SingleJoint {
        viscosity: 0.02,
        ..common::icub_forearm()
    }
}

fn two_link() -> TwoLink {
    common::two_link()
}

/// Every valid combination of plant, actuator, field and noise.
fn all_models() -> Vec<ArmModel> {
    let mut models = Vec::new();
    for plant in [
        Plant::SingleJoint(single_joint()),
        Plant::TwoLink(two_link()),
    ] {
        let dof = plant.dof();
        let actuators = [
            Actuator::Torque,
            Actuator::Impedance {
                damping: Damping::Proportional { alpha: 0.1 },
            },
            Actuator::Impedance {
                damping: Damping::Affine {
                    slope: 0.075,
                    offset: -0.0015,
                },
            },
            Actuator::Vsa {
                motor_inertia: [2.0, 0.2][..dof].to_vec(),
            },
        ];
        let fields = if dof == 1 {
            vec![Field::None]
        } else {
            vec![
                Field::None,
                Field::Divergent { beta: 50.0 },
                // Not antisymmetric, so that every entry of B_c matters.
                Field::Curl {
                    matrix: [[1.5, 13.0], [-11.0, 2.0]],
                },
            ]
        };
        for actuator in &actuators {
            let nx = actuator.nx(dof);
            let noises = [
                Noise::None,
                // The first joint velocity (the paper's σ q1' I) and the last state component.
                Noise::StateProportional {
                    sigma: 0.05,
                    component: dof,
                },
                Noise::StateProportional {
                    sigma: 0.3,
                    component: nx - 1,
                },
                Noise::Torque {
                    a: 0.15,
                    b: 0.37,
                    sample_time: 0.004,
                },
            ];
            for field in &fields {
                for noise in noises {
                    models.push(
                        ArmModel::new(plant.clone(), actuator.clone(), *field, noise)
                            .expect("valid model"),
                    );
                }
            }
        }
    }
    // 4 actuators × 4 noises × (1 + 3 fields).
    assert_eq!(models.len(), 4 * 4 * 4);
    models
}

fn random_exogenous(rng: &mut StdRng) -> Exogenous {
    Exogenous {
        q_d: [rng.random_range(-1.0..1.5), rng.random_range(0.2..2.0)],
        qd_d: [rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)],
        tau_ext: [rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5)],
    }
}

/// A random state (angles, velocities and, with a VSA, motor angles near the joint angles and motor
/// velocities) and a random control (torques, non-negative stiffnesses).
fn random_point(model: &ArmModel, rng: &mut StdRng) -> (Vec<f64>, Vec<f64>) {
    let dof = model.dof();
    let mut x = vec![0.0; model.nx()];
    for i in 0..dof {
        x[i] = rng.random_range(-1.0..1.5);
        x[dof + i] = rng.random_range(-2.0..2.0);
    }
    if model.nx() > 2 * dof {
        for i in 0..dof {
            x[2 * dof + i] = x[i] + rng.random_range(-0.3..0.3);
            x[3 * dof + i] = rng.random_range(-2.0..2.0);
        }
    }
    let mut u = vec![0.0; model.nu()];
    for (j, v) in u.iter_mut().enumerate() {
        *v = if j < dof {
            rng.random_range(-3.0..3.0)
        } else {
            rng.random_range(0.5..40.0)
        };
    }
    (x, u)
}

fn describe(model: &ArmModel) -> String {
    format!(
        "{}-dof {:?} / {:?} / {:?}",
        model.dof(),
        model.actuator,
        model.field,
        model.noise
    )
}

/// Drift through the crate's `f`.
fn drift(model: &ArmModel, x: &[f64], u: &[f64], ex: &Exogenous) -> Vec<f64> {
    let mut out = vec![0.0; model.nx()];
    model.f(x, u, ex, &mut out);
    out
}

/// Diffusion through the crate's `diffusion`, as an n×p matrix.
fn diffusion(model: &ArmModel, x: &[f64], u: &[f64]) -> DMatrix<f64> {
    let (nx, nw) = (model.nx(), model.nw());
    let mut out = vec![0.0; nx * nw.max(1)];
    model.diffusion(x, u, &mut out);
    DMatrix::from_column_slice(nx, nw, &out[..nx * nw])
}

/// Checks that `actual` equals `expected` entry by entry: within `rel` of the entry and `rel` of
/// the largest entry of its row (derivatives of one output share a scale; different outputs do
/// not: a joint acceleration moves 10⁴ times more than an angle), plus `abs` for round-off.
fn assert_close(what: &str, actual: &DMatrix<f64>, expected: &DMatrix<f64>, rel: f64, abs: f64) {
    assert_close_with(what, actual, expected, rel, |_, _| abs);
}

/// [`assert_close`] with an absolute allowance per entry.
fn assert_close_with(
    what: &str,
    actual: &DMatrix<f64>,
    expected: &DMatrix<f64>,
    rel: f64,
    abs: impl Fn(usize, usize) -> f64,
) {
    assert_eq!(actual.shape(), expected.shape(), "{what}: shape");
    for i in 0..expected.nrows() {
        let row_scale = expected.row(i).amax();
        for j in 0..expected.ncols() {
            let (a, e) = (actual[(i, j)], expected[(i, j)]);
            let tol = rel * (e.abs() + row_scale) + abs(i, j);
            assert!(
                (a - e).abs() <= tol,
                "{what}: entry ({i}, {j}) is {a:e}, expected {e:e} (tolerance {tol:e})\n\
                 actual {actual:.6e}\nexpected {expected:.6e}"
            );
        }
    }
}

/// Checks a derivative against its finite-difference estimate, allowing [`FD_REL`] relative
/// (truncation) and the estimate's own round-off.
fn assert_matches_fd(what: &str, actual: &DMatrix<f64>, fd: &Fd) {
    assert_close_with(what, actual, &fd.value, FD_REL, |i, j| fd.roundoff[(i, j)]);
}

/// Central-difference step for a variable of size `v`.
fn step_size(v: f64) -> f64 {
    1e-6 * (1.0 + v.abs())
}

// ---------------------------------------------------------------------------------------------
// An independent transcription of paper Eq. 1–8, 15 and 16.
// ---------------------------------------------------------------------------------------------

/// Mass matrix, bias torques `C + B_v q' + g`, hand Jacobian and hand position of the limb.
struct Limb {
    mass: Matrix2<f64>,
    bias: Vector2<f64>,
    jacobian: Matrix2<f64>,
    hand: Vector2<f64>,
}

fn limb(plant: &Plant, q: &[f64], qd: &[f64]) -> Limb {
    match plant {
        Plant::SingleJoint(p) => Limb {
            // The unused second joint gets unit inertia so that M stays invertible.
            mass: Matrix2::new(p.inertia, 0.0, 0.0, 1.0),
            bias: Vector2::new(
                p.mass * p.gravity * p.com * q[0].cos() + p.viscosity * qd[0],
                0.0,
            ),
            jacobian: Matrix2::new(-p.length * q[0].sin(), 0.0, p.length * q[0].cos(), 0.0),
            hand: Vector2::new(p.length * q[0].cos(), p.length * q[0].sin()),
        },
        Plant::TwoLink(p) => {
            let (c2, s2) = (q[1].cos(), q[1].sin());
            let a1 = p.i1 + p.i2 + p.m2 * p.l1 * p.l1;
            let a2 = p.m2 * p.l1 * p.s2;
            let m = Matrix2::new(a1 + 2.0 * a2 * c2, p.i2 + a2 * c2, p.i2 + a2 * c2, p.i2);
            let coriolis = a2 * s2 * Vector2::new(-qd[1] * (2.0 * qd[0] + qd[1]), qd[0] * qd[0]);
            let bv = Matrix2::new(
                p.viscosity[0][0],
                p.viscosity[0][1],
                p.viscosity[1][0],
                p.viscosity[1][1],
            );
            let (t1, t12) = (q[0], q[0] + q[1]);
            Limb {
                mass: m,
                bias: coriolis + bv * Vector2::new(qd[0], qd[1]),
                jacobian: Matrix2::new(
                    -p.l1 * t1.sin() - p.l2 * t12.sin(),
                    -p.l2 * t12.sin(),
                    p.l1 * t1.cos() + p.l2 * t12.cos(),
                    p.l2 * t12.cos(),
                ),
                hand: Vector2::new(
                    p.l1 * t1.cos() + p.l2 * t12.cos(),
                    p.l1 * t1.sin() + p.l2 * t12.sin(),
                ),
            }
        }
    }
}

/// `x' = f(x, u)` from paper Eq. 1–8, 15 and 16.
fn reference_drift(model: &ArmModel, x: &[f64], u: &[f64], ex: &Exogenous) -> Vec<f64> {
    let n = model.dof();
    let mut q = [0.0; 2];
    let mut qd = [0.0; 2];
    q[..n].copy_from_slice(&x[..n]);
    qd[..n].copy_from_slice(&x[n..2 * n]);
    let limb = limb(&model.plant, &q, &qd);
    let mut tau = Vector2::from(ex.tau_ext);
    for i in 0..n {
        tau[i] += match &model.actuator {
            Actuator::Torque => u[i],
            Actuator::Impedance { damping } => {
                let kp = u[n + i];
                let kd = match *damping {
                    Damping::Proportional { alpha } => alpha * kp,
                    Damping::Affine { slope, offset } => slope * kp + offset,
                };
                u[i] - kp * (q[i] - ex.q_d[i]) - kd * (qd[i] - ex.qd_d[i])
            }
            Actuator::Vsa { .. } => u[n + i] * (x[2 * n + i] - q[i]),
            // Checked in tests/stiffness_lag.rs against the ideal law at the realised stiffness.
            Actuator::ImpedanceLag { .. } => unreachable!("not among all_models"),
        };
    }
    let hand_velocity = limb.jacobian * Vector2::from(qd);
    let force = match model.field {
        Field::None => Vector2::zeros(),
        Field::Divergent { beta } => Vector2::new(beta * limb.hand[0], 0.0),
        Field::Curl { matrix: b } => {
            Matrix2::new(b[0][0], b[0][1], b[1][0], b[1][1]) * hand_velocity
        }
    };
    let rhs = tau - limb.bias + limb.jacobian.transpose() * force;
    let qdd = limb.mass.try_inverse().expect("M invertible") * rhs;
    let mut xdot = vec![0.0; model.nx()];
    for i in 0..n {
        xdot[i] = qd[i];
        xdot[n + i] = qdd[i];
    }
    if let Actuator::Vsa { motor_inertia } = &model.actuator {
        for i in 0..n {
            let theta = x[2 * n + i];
            xdot[2 * n + i] = x[3 * n + i];
            xdot[3 * n + i] = (u[i] - u[n + i] * (theta - q[i])) / motor_inertia[i];
        }
    }
    xdot
}

/// `F(x, u)` from paper Eq. 8 and 16: `σ x_c I`, or the torque noise `(a + b q'_i) √T_s` on
/// joint `i` through `M⁻¹`.
fn reference_diffusion(model: &ArmModel, x: &[f64]) -> DMatrix<f64> {
    let (n, nx) = (model.dof(), model.nx());
    match model.noise {
        Noise::None => DMatrix::zeros(nx, 0),
        Noise::StateProportional { sigma, component } => {
            DMatrix::identity(nx, nx) * (sigma * x[component])
        }
        // A torque error of standard deviation (a + b q'_i) per sample of length T_s is a white
        // noise of intensity (a + b q'_i)² T_s.
        Noise::Torque { a, b, sample_time } => {
            let mut q = [0.0; 2];
            q[..n].copy_from_slice(&x[..n]);
            let minv = limb(&model.plant, &q, &[0.0; 2])
                .mass
                .try_inverse()
                .expect("M invertible");
            let mut f = DMatrix::zeros(nx, n);
            for i in 0..n {
                let e = (a + b * x[n + i]) * sample_time.sqrt();
                for j in 0..n {
                    f[(n + j, i)] = minv[(j, i)] * e;
                }
            }
            f
        }
    }
}

#[test]
fn drift_and_diffusion_match_the_equations_of_motion() {
    let mut rng = StdRng::seed_from_u64(11);
    for model in all_models() {
        let name = describe(&model);
        for _ in 0..POINTS {
            let (x, u) = random_point(&model, &mut rng);
            let ex = random_exogenous(&mut rng);
            let f = DMatrix::from_column_slice(model.nx(), 1, &drift(&model, &x, &u, &ex));
            let f_ref =
                DMatrix::from_column_slice(model.nx(), 1, &reference_drift(&model, &x, &u, &ex));
            assert_close(&format!("{name}: f"), &f, &f_ref, 1e-12, 1e-12);
            let big_f = diffusion(&model, &x, &u);
            assert_close(
                &format!("{name}: F"),
                &big_f,
                &reference_diffusion(&model, &x),
                1e-12,
                1e-15,
            );
            assert_eq!(big_f.ncols(), model.nw(), "{name}: noise channels");
        }
    }
}

/// A central-difference Jacobian and a bound on its round-off error.
struct Fd {
    value: DMatrix<f64>,
    roundoff: DMatrix<f64>,
}

/// Central differences of a vector function of `x` (columns: one per component of `x`). The
/// round-off bound allows 64 ulps of error in each evaluated value, divided by the step.
fn fd_jacobian(x: &[f64], rows: usize, mut g: impl FnMut(&[f64]) -> Vec<f64>) -> Fd {
    let mut value = DMatrix::zeros(rows, x.len());
    let mut roundoff = DMatrix::zeros(rows, x.len());
    let mut xp = x.to_vec();
    for j in 0..x.len() {
        let h = step_size(x[j]);
        xp[j] = x[j] + h;
        let plus = g(&xp);
        xp[j] = x[j] - h;
        let minus = g(&xp);
        xp[j] = x[j];
        for i in 0..rows {
            value[(i, j)] = (plus[i] - minus[i]) / (2.0 * h);
            roundoff[(i, j)] = 64.0 * f64::EPSILON * plus[i].abs().max(minus[i].abs()) / h;
        }
    }
    Fd { value, roundoff }
}

/// Relative tolerance of the finite-difference comparisons: the truncation error of a central
/// difference with h ≈ 1e-6 is ~1e-12 relative and its round-off ~1e-10 relative; a wrong
/// derivative is off by O(1).
const FD_REL: f64 = 1e-7;

#[test]
fn arm_model_jacobians_match_finite_differences() {
    let mut rng = StdRng::seed_from_u64(1);
    for model in all_models() {
        let name = describe(&model);
        let (nx, nu, nw) = (model.nx(), model.nu(), model.nw());
        for _ in 0..POINTS {
            let (x, u) = random_point(&model, &mut rng);
            let ex = random_exogenous(&mut rng);
            let mut fx = vec![f64::NAN; nx * nx];
            let mut fu = vec![f64::NAN; nx * nu];
            let mut dfx = vec![f64::NAN; nx * nx * nw];
            let mut dfu = vec![f64::NAN; nu * nx * nw];
            jacobians(
                &model,
                &x,
                &u,
                &ex,
                &mut fx,
                &mut fu,
                Some((&mut dfx[..], &mut dfu[..])),
            );
            let fx = DMatrix::from_column_slice(nx, nx, &fx);
            let fu = DMatrix::from_column_slice(nx, nu, &fu);
            let fd_fx = fd_jacobian(&x, nx, |xp| drift(&model, xp, &u, &ex));
            let fd_fu = fd_jacobian(&u, nx, |up| drift(&model, &x, up, &ex));
            assert_matches_fd(&format!("{name}: f_x"), &fx, &fd_fx);
            assert_matches_fd(&format!("{name}: f_u"), &fu, &fd_fu);

            // ∂F/∂x_j and ∂F/∂u_j, each an n×p block in the layout of `diffusion`.
            let block = nx * nw;
            let flat = |m: DMatrix<f64>| m.as_slice().to_vec();
            let fd_dfx = fd_jacobian(&x, block, |xp| flat(diffusion(&model, xp, &u)));
            let fd_dfu = fd_jacobian(&u, block, |up| flat(diffusion(&model, &x, up)));
            assert_matches_fd(
                &format!("{name}: dF/dx"),
                &DMatrix::from_column_slice(block, nx, &dfx),
                &fd_dfx,
            );
            assert_matches_fd(
                &format!("{name}: dF/du"),
                &DMatrix::from_column_slice(block, nu, &dfu),
                &fd_dfu,
            );

            // Without the noise request the drift Jacobians are the same.
            let mut fx2 = vec![f64::NAN; nx * nx];
            let mut fu2 = vec![f64::NAN; nx * nu];
            jacobians(&model, &x, &u, &ex, &mut fx2, &mut fu2, None);
            assert_eq!(fx.as_slice(), &fx2[..], "{name}: f_x without noise request");
            assert_eq!(fu.as_slice(), &fu2[..], "{name}: f_u without noise request");
        }
    }
}

/// The drift's written-out Jacobian ([`ArmModel::f_jacobian`]) is the dual numbers' to
/// round-off, and the drift that comes with it is `f`'s bit for bit; through the sub-steps, the
/// chain rule over it ([`DiscreteDynamics::flow_jacobian_f64`]) is the dual numbers carried
/// through the whole flow ([`DiscreteDynamics::flow_jacobian`]).
#[test]
fn written_out_jacobians_match_the_dual_numbers() {
    let mut rng = StdRng::seed_from_u64(3);
    for model in all_models() {
        let name = describe(&model);
        let (nx, nu) = (model.nx(), model.nu());
        for _ in 0..POINTS {
            let (x, u) = random_point(&model, &mut rng);
            let ex = random_exogenous(&mut rng);
            let mut fx = vec![f64::NAN; nx * nx];
            let mut fu = vec![f64::NAN; nx * nu];
            jacobians(&model, &x, &u, &ex, &mut fx, &mut fu, None);
            let mut jac = vec![f64::NAN; nx * (nx + nu)];
            let mut xdot = vec![f64::NAN; nx];
            model.f_jacobian(&x, &u, &ex, &mut xdot, &mut jac);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&xdot), bits(&drift(&model, &x, &u, &ex)), "{name}: f");
            let dual = DMatrix::from_iterator(nx, nx + nu, fx.into_iter().chain(fu));
            let written = DMatrix::from_column_slice(nx, nx + nu, &jac);
            assert_close(&format!("{name}: [f_x | f_u]"), &written, &dual, 1e-13, 0.0);

            for (integrator, substeps) in DISCRETISATIONS {
                let mut d = DiscreteDynamics::euler(model.clone(), 0.01, vec![ex]);
                d.integrator = integrator;
                d.substeps = substeps;
                let (mut a, mut b) = (vec![f64::NAN; nx * nx], vec![f64::NAN; nx * nu]);
                let (mut a_dual, mut b_dual) = (a.clone(), b.clone());
                d.flow_jacobian_f64(0, &x, &u, &mut a, &mut b);
                d.flow_jacobian(0, &x, &u, &mut a_dual, &mut b_dual);
                let what = format!("{name}, {integrator:?} × {substeps}");
                let m = |v: &[f64], cols| DMatrix::from_column_slice(nx, cols, v);
                assert_close(
                    &format!("{what}: A"),
                    &m(&a, nx),
                    &m(&a_dual, nx),
                    1e-13,
                    0.0,
                );
                assert_close(
                    &format!("{what}: B"),
                    &m(&b, nu),
                    &m(&b_dual, nu),
                    1e-13,
                    0.0,
                );
            }
        }
    }
}

/// The fused step ([`Dynamics::linearize_with`] with the step, what a rollout that will be linearised calls)
/// is the step and its linearisation computed apart, to the bit: the end state is the chain
/// rule's last sub-step state, and the solver's plans must not depend on which path a knot took.
#[test]
fn the_fused_step_is_the_step_and_its_linearisation_bit_for_bit() {
    let mut rng = StdRng::seed_from_u64(11);
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    for model in all_models() {
        let name = describe(&model);
        let (nx, nu, nw) = (model.nx(), model.nu(), model.nw());
        for _ in 0..POINTS {
            let (x, u) = random_point(&model, &mut rng);
            let ex = random_exogenous(&mut rng);
            for (integrator, substeps) in DISCRETISATIONS {
                let mut d = DiscreteDynamics::euler(model.clone(), 0.01, vec![ex]);
                d.integrator = integrator;
                d.substeps = substeps;
                let what = format!("{name}, {integrator:?} × {substeps}");
                let (mut apart, mut fused) = (
                    Linearization::new(nx, nu, nw),
                    Linearization::new(nx, nu, nw),
                );
                d.linearize(0, &x, &u, &mut apart);
                let mut next = vec![f64::NAN; nx];
                d.linearize_with(0, &x, &u, Some(&mut next), false, &mut fused);
                assert_eq!(
                    bits(&next),
                    bits(&euler_step(&d, 0, &x, &u)),
                    "{what}: step"
                );
                assert_eq!(
                    bits(fused.a.as_slice()),
                    bits(apart.a.as_slice()),
                    "{what}: A"
                );
                assert_eq!(
                    bits(fused.b.as_slice()),
                    bits(apart.b.as_slice()),
                    "{what}: B"
                );
                assert_eq!(
                    bits(fused.c.as_slice()),
                    bits(apart.c.as_slice()),
                    "{what}: C"
                );
                assert_eq!(fused.noise, apart.noise, "{what}: noise kind");
                for i in 0..nw {
                    assert_eq!(
                        bits(fused.cx[i].as_slice()),
                        bits(apart.cx[i].as_slice()),
                        "{what}: Cx"
                    );
                    assert_eq!(
                        bits(fused.cu[i].as_slice()),
                        bits(apart.cu[i].as_slice()),
                        "{what}: Cu"
                    );
                }
            }
        }
    }
}

fn noise_gain(model: &DiscreteDynamics, k: usize, x: &[f64], u: &[f64]) -> DMatrix<f64> {
    let mut g = DMatrix::from_element(model.nx(), model.nw(), f64::NAN);
    model.noise_gain(k, x, u, &mut g);
    g
}

fn euler_step(model: &DiscreteDynamics, k: usize, x: &[f64], u: &[f64]) -> Vec<f64> {
    let mut next = vec![f64::NAN; model.nx()];
    model.step(k, x, u, &mut next);
    next
}

/// The discrete step from the drift, written out here: `substeps` explicit Euler steps,
/// semi-implicit Euler (velocities first, then positions with the new velocities) on each
/// (position, velocity) block, or classical RK4 steps.
fn reference_step(
    model: &ArmModel,
    ex: &Exogenous,
    dt: f64,
    substeps: usize,
    integrator: Integrator,
    x: &[f64],
    u: &[f64],
) -> Vec<f64> {
    let (dof, nx) = (model.dof(), model.nx());
    let h = dt / substeps as f64;
    let mut cur = x.to_vec();
    for _ in 0..substeps {
        let xdot = reference_drift(model, &cur, u, ex);
        match integrator {
            Integrator::Euler => {
                for i in 0..nx {
                    cur[i] += h * xdot[i];
                }
            }
            Integrator::SemiImplicit => {
                // Blocks (q, q') and, with a VSA, (θ, θ').
                for block in 0..nx / (2 * dof) {
                    let (p, v) = (2 * dof * block, 2 * dof * block + dof);
                    for i in 0..dof {
                        cur[v + i] += h * xdot[v + i];
                        cur[p + i] += h * cur[v + i];
                    }
                }
            }
            Integrator::Rk4 => {
                let at = |x: &[f64], k: &[f64], c: f64| -> Vec<f64> {
                    let stage: Vec<f64> = x.iter().zip(k).map(|(x, k)| x + c * h * k).collect();
                    reference_drift(model, &stage, u, ex)
                };
                let k2 = at(&cur, &xdot, 0.5);
                let k3 = at(&cur, &k2, 0.5);
                let k4 = at(&cur, &k3, 1.0);
                for i in 0..nx {
                    cur[i] += h / 6.0 * (xdot[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
                }
            }
            Integrator::Rosenbrock => {
                // ROS2 with W = I − γ h J formed densely and solved by LU: J holds the
                // impedance law's −M⁻¹K, −M⁻¹K_D (the VSA's spring ±M⁻¹K, ±K/B) at the
                // sub-step's start.
                let gamma = 1.0 - std::f64::consts::FRAC_1_SQRT_2;
                let w = DMatrix::identity(nx, nx) - stiff_jacobian(model, &cur, u) * (gamma * h);
                let lu = w.lu();
                let solve = |r: Vec<f64>| -> Vec<f64> {
                    lu.solve(&DVector::from_vec(r))
                        .expect("W invertible")
                        .iter()
                        .copied()
                        .collect()
                };
                let k1 = solve(xdot);
                let stage: Vec<f64> = cur.iter().zip(&k1).map(|(x, k)| x + h * k).collect();
                let f2 = reference_drift(model, &stage, u, ex);
                let k2 = solve(f2.iter().zip(&k1).map(|(f, k)| f - 2.0 * k).collect());
                for i in 0..nx {
                    cur[i] += h * (1.5 * k1[i] + 0.5 * k2[i]);
                }
            }
        }
    }
    cur
}

/// The Jacobian of the actuator's stiff linear part (n×n): what the Rosenbrock step takes
/// implicitly, with the mass matrix at `x`.
fn stiff_jacobian(model: &ArmModel, x: &[f64], u: &[f64]) -> DMatrix<f64> {
    let (dof, nx) = (model.dof(), model.nx());
    let mut j = DMatrix::zeros(nx, nx);
    let m = model.plant.mass_matrix(&x[..dof]);
    let m_inv = DMatrix::from_fn(dof, dof, |r, c| m[r][c])
        .try_inverse()
        .expect("M invertible");
    // The stiffness controls (none for the torque actuator).
    let k = || DMatrix::from_fn(dof, dof, |r, c| if r == c { u[dof + r] } else { 0.0 });
    match &model.actuator {
        // A lagged stiffness is a state: the step takes it explicitly (and scenarios refuse it).
        Actuator::Torque | Actuator::ImpedanceLag { .. } => {}
        Actuator::Impedance { damping } => {
            let kd = DMatrix::from_fn(dof, dof, |r, c| {
                if r == c {
                    damping.gain(u[dof + r])
                } else {
                    0.0
                }
            });
            for i in 0..dof {
                j[(i, dof + i)] = 1.0;
            }
            j.view_mut((dof, 0), (dof, dof)).copy_from(&(-&m_inv * k()));
            j.view_mut((dof, dof), (dof, dof))
                .copy_from(&(-&m_inv * kd));
        }
        Actuator::Vsa { motor_inertia } => {
            for i in 0..dof {
                j[(i, dof + i)] = 1.0;
                j[(2 * dof + i, 3 * dof + i)] = 1.0;
                let kb = u[dof + i] / motor_inertia[i];
                j[(3 * dof + i, i)] = kb;
                j[(3 * dof + i, 2 * dof + i)] = -kb;
            }
            let mk = &m_inv * k();
            j.view_mut((dof, 0), (dof, dof)).copy_from(&(-&mk));
            j.view_mut((dof, 2 * dof), (dof, dof)).copy_from(&mk);
        }
    }
    j
}

/// The discretisations checked: the paper's single Euler step and the sub-stepped ones.
const DISCRETISATIONS: [(Integrator, usize); 8] = [
    (Integrator::Euler, 1),
    (Integrator::Euler, 3),
    (Integrator::SemiImplicit, 1),
    (Integrator::SemiImplicit, 4),
    (Integrator::Rk4, 1),
    (Integrator::Rk4, 2),
    (Integrator::Rosenbrock, 1),
    (Integrator::Rosenbrock, 2),
];

#[test]
fn discrete_step_matches_the_integrator_applied_to_the_drift() {
    let mut rng = StdRng::seed_from_u64(3);
    let dt = 0.01;
    for model in all_models() {
        let name = describe(&model);
        let exogenous: Vec<Exogenous> = (0..4).map(|_| random_exogenous(&mut rng)).collect();
        for (integrator, substeps) in DISCRETISATIONS {
            let mut euler = DiscreteDynamics::euler(model.clone(), dt, exogenous.clone());
            euler.integrator = integrator;
            euler.substeps = substeps;
            for k in [0, 3, 9] {
                let what = format!("{name}, {integrator:?} × {substeps}, knot {k}");
                let (x, u) = random_point(&model, &mut rng);
                let ex = &exogenous[k.min(exogenous.len() - 1)];
                let next = euler_step(&euler, k, &x, &u);
                let expected = reference_step(&model, ex, dt, substeps, integrator, &x, &u);
                assert_close(
                    &format!("{what}: step"),
                    &DMatrix::from_column_slice(x.len(), 1, &next),
                    &DMatrix::from_column_slice(x.len(), 1, &expected),
                    1e-12,
                    1e-12,
                );
            }
        }
    }
}

#[test]
fn euler_linearization_matches_finite_differences() {
    let mut rng = StdRng::seed_from_u64(2);
    let dt = 0.01;
    for model in all_models() {
        let name = describe(&model);
        let exogenous: Vec<Exogenous> = (0..4).map(|_| random_exogenous(&mut rng)).collect();
        for (integrator, substeps) in DISCRETISATIONS {
            let mut euler = DiscreteDynamics::euler(model.clone(), dt, exogenous.clone());
            euler.integrator = integrator;
            euler.substeps = substeps;
            let (nx, nu, nw) = (euler.nx(), euler.nu(), euler.nw());
            assert_eq!((nx, nu, nw), (model.nx(), model.nu(), model.nw()));
            // Knot 7 is past the reference and must use its last entry.
            for (point, k) in [0, 2, 3, 7].into_iter().enumerate() {
                let what = format!("{name}, {integrator:?} × {substeps}, point {point}, knot {k}");
                let (x, u) = random_point(&model, &mut rng);
                let ex = exogenous[k.min(exogenous.len() - 1)];
                let mut lin = Linearization::new(nx, nu, nw);
                euler.linearize(k, &x, &u, &mut lin);
                let fd_a = fd_jacobian(&x, nx, |xp| euler_step(&euler, k, xp, &u));
                let fd_b = fd_jacobian(&u, nx, |up| euler_step(&euler, k, &x, up));
                // The identity part of A is exact; compare A − I.
                let eye = DMatrix::<f64>::identity(nx, nx);
                let fd_a_minus_i = Fd {
                    value: &fd_a.value - &eye,
                    roundoff: fd_a.roundoff.clone(),
                };
                assert_matches_fd(&format!("{what}: A - I"), &(&lin.a - &eye), &fd_a_minus_i);
                assert_matches_fd(&format!("{what}: B"), &lin.b, &fd_b);
                if (integrator, substeps) == (Integrator::Euler, 1) {
                    // The paper's discretisation: A = I + Δ f_x, B = Δ f_u exactly.
                    let mut fx = vec![0.0; nx * nx];
                    let mut fu = vec![0.0; nx * nu];
                    jacobians(&model, &x, &u, &ex, &mut fx, &mut fu, None);
                    let a = eye.clone() + DMatrix::from_column_slice(nx, nx, &fx) * dt;
                    let b = DMatrix::from_column_slice(nx, nu, &fu) * dt;
                    assert_close(&format!("{what}: A = I + Δ f_x"), &lin.a, &a, 1e-13, 0.0);
                    assert_close(&format!("{what}: B = Δ f_u"), &lin.b, &b, 1e-13, 0.0);
                }

                if nw == 0 {
                    assert_eq!(lin.noise, NoiseKind::None, "{what}: noise kind");
                    continue;
                }
                // c = √Δ F at the start of the step, once per control step.
                let expected_c = diffusion(&model, &x, &u) * dt.sqrt();
                assert_close(&format!("{what}: c"), &lin.c, &expected_c, 1e-14, 0.0);
                assert_close(
                    &format!("{what}: noise_gain"),
                    &noise_gain(&euler, k, &x, &u),
                    &expected_c,
                    1e-14,
                    0.0,
                );
                // Cx_i, Cu_i: derivatives of column i of the noise gain.
                let mut all_zero = true;
                for i in 0..nw {
                    let column = |m: DMatrix<f64>| m.column(i).iter().copied().collect::<Vec<_>>();
                    let fd_cx = fd_jacobian(&x, nx, |xp| column(noise_gain(&euler, k, xp, &u)));
                    let fd_cu = fd_jacobian(&u, nx, |up| column(noise_gain(&euler, k, &x, up)));
                    assert_matches_fd(&format!("{what}: Cx[{i}]"), &lin.cx[i], &fd_cx);
                    assert_matches_fd(&format!("{what}: Cu[{i}]"), &lin.cu[i], &fd_cu);
                    all_zero &= fd_cx.value.amax() == 0.0 && fd_cu.value.amax() == 0.0;
                }
                // The kind tells the backward pass which terms it may skip.
                let expected_kind = if all_zero {
                    NoiseKind::Additive
                } else {
                    NoiseKind::Dependent
                };
                assert_eq!(lin.noise, expected_kind, "{what}: noise kind");
            }
        }
    }
}

/// The finite-difference reference itself: exact (to round-off) on an affine map.
#[test]
fn finite_differences_are_exact_on_affine_maps() {
    let a = DMatrix::from_fn(3, 4, |i, j| (i as f64 + 1.0) * 0.5 - j as f64);
    let x0 = [0.3, -1.0, 2.0, 0.1];
    let fd = fd_jacobian(&x0, 3, |x| {
        (&a * DVector::from_column_slice(x))
            .iter()
            .copied()
            .collect()
    });
    assert_close("affine map", &fd.value, &a, 1e-9, 1e-9);
}

/// The continuous model's Jacobians by forward-mode AD, column by column: the reference the
/// discrete linearisations are checked against.
/// Exact Jacobians of `f` and of `F` at (x, u) by forward-mode automatic differentiation.
///
/// `fx` (n×n) and `fu` (n×m) are column-major; `dfx[j]` / `dfu[j]` hold `∂F/∂x_j` / `∂F/∂u_j`
/// in the layout of `ArmModel::diffusion`. Pass `None` for the noise derivatives when the
/// model is noise-free or they are not needed.
fn jacobians(
    model: &ArmModel,
    x: &[f64],
    u: &[f64],
    ex: &Exogenous,
    fx: &mut [f64],
    fu: &mut [f64],
    mut noise: Option<(&mut [f64], &mut [f64])>,
) {
    use num_dual::Dual64;
    let (nx, nu, nw) = (model.nx(), model.nu(), model.nw());
    let mut xd = [Dual64::from(0.0); MAX_NX];
    let mut ud = [Dual64::from(0.0); MAX_NU];
    for (d, v) in xd.iter_mut().zip(x) {
        *d = Dual64::from(*v);
    }
    for (d, v) in ud.iter_mut().zip(u) {
        *d = Dual64::from(*v);
    }
    let mut out = [Dual64::from(0.0); MAX_NX];
    let mut big_f = [Dual64::from(0.0); MAX_NX * MAX_NW];
    for j in 0..nx + nu {
        if j < nx {
            xd[j].eps = 1.0;
        } else {
            ud[j - nx].eps = 1.0;
        }
        model.f(&xd[..nx], &ud[..nu], ex, &mut out[..nx]);
        let col = if j < nx {
            &mut fx[j * nx..(j + 1) * nx]
        } else {
            &mut fu[(j - nx) * nx..(j - nx + 1) * nx]
        };
        for (dst, o) in col.iter_mut().zip(&out[..nx]) {
            *dst = o.eps;
        }
        if let Some((dfx, dfu)) = noise.as_mut() {
            model.diffusion(&xd[..nx], &ud[..nu], &mut big_f);
            let block = nx * nw;
            let dst = if j < nx {
                &mut dfx[j * block..(j + 1) * block]
            } else {
                &mut dfu[(j - nx) * block..(j - nx + 1) * block]
            };
            for (d, v) in dst.iter_mut().zip(&big_f[..block]) {
                *d = v.eps;
            }
        }
        if j < nx {
            xd[j].eps = 0.0;
        } else {
            ud[j - nx].eps = 0.0;
        }
    }
}

/// RK4 is fourth order: on every plant, halving its step divides the one-step error against a
/// fine reference (the written-out RK4 with 4000 sub-steps) by about 2⁴ = 16, and one RK4 step
/// is closer to the flow than ten semi-implicit Euler sub-steps. At 1 ms, inside every plant's
/// stability region: at the planner's 10 ms a stiff impedance's damping rate leaves it
/// (`h K_D / I` past 2.78), which is what the scenarios' sub-steps are for.
#[test]
fn rk4_is_fourth_order_and_one_step_beats_ten_euler_sub_steps() {
    let mut rng = StdRng::seed_from_u64(5);
    let dt = 0.001;
    for model in all_models() {
        let name = describe(&model);
        let ex = random_exogenous(&mut rng);
        let (x, u) = random_point(&model, &mut rng);
        let exact = reference_step(&model, &ex, dt, 4000, Integrator::Rk4, &x, &u);
        let error = |integrator, substeps| {
            let mut d = DiscreteDynamics::euler(model.clone(), dt, vec![ex]);
            d.integrator = integrator;
            d.substeps = substeps;
            let next = euler_step(&d, 0, &x, &u);
            next.iter()
                .zip(&exact)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let (one, two) = (error(Integrator::Rk4, 1), error(Integrator::Rk4, 2));
        let ratio = one / two;
        assert!(
            (10.0..26.0).contains(&ratio),
            "{name}: RK4 error {one:.3e} with one step, {two:.3e} with two: ratio {ratio:.1}"
        );
        let semi = error(Integrator::SemiImplicit, 10);
        assert!(
            one < semi,
            "{name}: RK4 ×1 error {one:.3e} vs semi-implicit ×10 {semi:.3e}"
        );
    }
}

/// The Rosenbrock step (ROS2) is second order: on every plant, halving its step (two steps over
/// the same interval) divides the error against a fine reference (RK4 with 4000 sub-steps) by
/// about 2² = 4 (at 0.2 ms,
/// where even the stiffest impedance is in the asymptotic range; at the planner's 10 ms the
/// damping rate is far outside it and the next test takes over).
#[test]
fn rosenbrock_is_second_order() {
    let mut rng = StdRng::seed_from_u64(6);
    let dt = 2e-4;
    for model in all_models() {
        let name = describe(&model);
        let ex = random_exogenous(&mut rng);
        let (x, u) = random_point(&model, &mut rng);
        let exact = reference_step(&model, &ex, dt, 4000, Integrator::Rk4, &x, &u);
        let error = |substeps| {
            let mut d = DiscreteDynamics::euler(model.clone(), dt, vec![ex]);
            d.integrator = Integrator::Rosenbrock;
            d.substeps = substeps;
            let next = euler_step(&d, 0, &x, &u);
            next.iter()
                .zip(&exact)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        let (one, two) = (error(1), error(2));
        let ratio = one / two;
        assert!(
            (3.0..5.5).contains(&ratio),
            "{name}: ROS2 error {one:.3e} with one step, {two:.3e} with two: ratio {ratio:.1}"
        );
    }
}

/// One Rosenbrock step per 10 ms knot on the stiffest linear spring-damper of the scenarios (the
/// iCub forearm at `stiffness_max` = 40 N m/rad, K_D = 0.2 K: a damping rate of 1575 /s, no
/// gravity, so that the flow is the matrix exponential of the augmented system): over 1 s the
/// Rosenbrock ×1 path stays within 0.2 % of the largest excursion of the exact solution
/// (8.3e-4 measured) and at most a quarter of the error of today's ten semi-implicit sub-steps
/// (6.9e-3), where RK4 ×1 diverges.
#[test]
fn one_rosenbrock_step_per_knot_follows_a_stiff_spring_damper() {
    let joint = SingleJoint {
        gravity: 0.0,
        viscosity: 0.0,
        ..common::icub_forearm()
    };
    let (k, alpha, dt, knots) = (40.0, 0.2, 0.01, 100);
    let model = ArmModel::new(
        Plant::SingleJoint(joint.clone()),
        Actuator::Impedance {
            damping: Damping::Proportional { alpha },
        },
        Field::None,
        Noise::None,
    )
    .expect("valid");
    let rate = alpha * k / joint.inertia;
    assert!((rate - 1575.0).abs() < 10.0, "rate {rate}");
    // A reference stepping away from the start, and a torque pulse.
    let ex = |i: usize| Exogenous {
        q_d: [if i < 50 { 0.6 } else { -0.2 }, 0.0],
        qd_d: [0.0; 2],
        tau_ext: [0.0; 2],
    };
    let u = |i: usize| [if (20..30).contains(&i) { 0.5 } else { 0.0 }, k];
    // Exact: x' = L x + c, c from the reference and the torque, held over the knot.
    let exact_step = |x: Vector2<f64>, i: usize| -> Vector2<f64> {
        let (e, ui) = (ex(i), u(i));
        let kd = alpha * k;
        let c0 = (ui[0] + k * e.q_d[0]) / joint.inertia;
        let mut aug = DMatrix::zeros(3, 3);
        aug[(0, 1)] = 1.0;
        aug[(1, 0)] = -k / joint.inertia;
        aug[(1, 1)] = -kd / joint.inertia;
        aug[(1, 2)] = c0;
        let phi = (aug * dt).exp();
        let y = &phi * DVector::from_vec(vec![x[0], x[1], 1.0]);
        Vector2::new(y[0], y[1])
    };
    let path = |integrator: Integrator, substeps: usize| -> f64 {
        let exogenous: Vec<Exogenous> = (0..knots).map(ex).collect();
        let mut d = DiscreteDynamics::euler(model.clone(), dt, exogenous);
        d.integrator = integrator;
        d.substeps = substeps;
        let (mut x, mut y) = (vec![0.0, 0.0], Vector2::new(0.0, 0.0));
        let (mut worst, mut scale) = (0.0_f64, 0.0_f64);
        for i in 0..knots {
            let next = euler_step(&d, i, &x, &u(i));
            y = exact_step(y, i);
            x = next;
            worst = worst.max((x[0] - y[0]).abs());
            scale = scale.max(y[0].abs());
        }
        worst / scale
    };
    let (ros, semi, rk4) = (
        path(Integrator::Rosenbrock, 1),
        path(Integrator::SemiImplicit, 10),
        path(Integrator::Rk4, 1),
    );
    eprintln!(
        "relative position error: ROS2 ×1 {ros:.2e}, semi-implicit ×10 {semi:.2e}, RK4 ×1 {rk4:.2e}"
    );
    assert!(ros < 2e-3, "ROS2 ×1: {ros:.3e}");
    assert!(
        ros < 0.25 * semi,
        "ROS2 ×1 {ros:.3e} vs semi-implicit ×10 {semi:.3e}"
    );
    assert!(
        rk4.is_nan() || rk4 >= 1.0,
        "RK4 ×1 should diverge here: {rk4:.3e}"
    );
}
