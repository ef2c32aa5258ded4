//! The delay wrapper `vic_core::delay::Delayed` (paper Eq. 11–13, 19).
//!
//! * With 0 steps it is the plain model: step, noise gain and linearisation identical.
//! * With `d > 0` steps a rollout of the augmented model from `initial_state(x0, pending)` is a
//!   direct simulation of the plain model in which the control acting at step `k` is `u_{k−d}`
//!   (and `pending` for `k < d`), with and without noise.
//! * Its linearisation agrees with central finite differences of its step and noise gain.

use crate::common;

use nalgebra::DMatrix;
use rand::rngs::StdRng;
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use vic_core::delay::{Delayed, NoiseFree};
use vic_core::dynamics::{Column, DiscreteDynamics, Dynamics, Linearization};
use vic_core::model::{Actuator, ArmModel, Damping, Exogenous, Field, Noise, Plant};

const DT: f64 = 0.01;
const HORIZON: usize = 15;

fn single_joint() -> Plant {
    Plant::SingleJoint(common::icub_forearm())
}

fn two_link() -> Plant {
    Plant::TwoLink(common::two_link())
}

/// Models covering both plants, every actuator and every noise kind.
fn models() -> Vec<ArmModel> {
    let impedance = Actuator::Impedance {
        damping: Damping::Proportional { alpha: 0.2 },
    };
    [
        (single_joint(), impedance.clone(), Field::None, Noise::None),
        (
            single_joint(),
            impedance.clone(),
            Field::None,
            Noise::StateProportional {
                sigma: 0.03,
                component: 1,
            },
        ),
        (
            single_joint(),
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
                sample_time: 0.004,
            },
        ),
        (
            two_link(),
            Actuator::Torque,
            Field::Divergent { beta: 50.0 },
            Noise::StateProportional {
                sigma: 0.05,
                component: 2,
            },
        ),
        (
            two_link(),
            impedance,
            Field::Curl {
                matrix: [[0.0, 13.0], [-13.0, 0.0]],
            },
            Noise::Torque {
                a: 0.15,
                b: 0.37,
                sample_time: 0.004,
            },
        ),
        (
            two_link(),
            Actuator::Vsa {
                motor_inertia: vec![2.0, 0.2],
            },
            Field::Divergent { beta: 50.0 },
            Noise::StateProportional {
                sigma: 0.05,
                component: 2,
            },
        ),
    ]
    .into_iter()
    .map(|(p, a, f, n)| ArmModel::new(p, a, f, n).expect("valid model"))
    .collect()
}

fn random_exogenous(rng: &mut StdRng) -> Exogenous {
    Exogenous {
        q_d: [rng.random_range(-1.0..1.5), rng.random_range(0.2..2.0)],
        qd_d: [rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0)],
        tau_ext: [rng.random_range(-0.2..0.2), rng.random_range(-0.2..0.2)],
    }
}

/// A discrete model with a different reference at every knot.
fn discrete(model: &ArmModel, rng: &mut StdRng) -> DiscreteDynamics {
    let exogenous = (0..=HORIZON).map(|_| random_exogenous(rng)).collect();
    DiscreteDynamics::euler(model.clone(), DT, exogenous)
}

fn random_state(model: &ArmModel, rng: &mut StdRng) -> Vec<f64> {
    let dof = model.dof();
    let mut x: Vec<f64> = (0..model.nx())
        .map(|i| {
            if i % (2 * dof) < dof {
                rng.random_range(-1.0..1.5)
            } else {
                rng.random_range(-1.0..1.0)
            }
        })
        .collect();
    if model.nx() > 2 * dof {
        // Motor angles near the joint angles.
        for i in 0..dof {
            x[2 * dof + i] = x[i] + rng.random_range(-0.2..0.2);
        }
    }
    x
}

fn random_control(model: &ArmModel, rng: &mut StdRng) -> Vec<f64> {
    let dof = model.dof();
    (0..model.nu())
        .map(|j| {
            if j < dof {
                rng.random_range(-1.0..1.0)
            } else {
                rng.random_range(1.0..30.0)
            }
        })
        .collect()
}

fn step<D: Dynamics>(d: &D, k: usize, x: &[f64], u: &[f64]) -> Vec<f64> {
    let mut next = vec![f64::NAN; d.nx()];
    d.step(k, x, u, &mut next);
    next
}

fn noise_gain<D: Dynamics>(d: &D, k: usize, x: &[f64], u: &[f64]) -> DMatrix<f64> {
    let mut g = DMatrix::from_element(d.nx(), d.nw(), f64::NAN);
    d.noise_gain(k, x, u, &mut g);
    g
}

fn step_bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn linearize<D: Dynamics>(d: &D, k: usize, x: &[f64], u: &[f64]) -> Linearization {
    let mut lin = Linearization::new(d.nx(), d.nu(), d.nw());
    // Poison the buffers: the wrapper must write every entry.
    lin.a.fill(f64::NAN);
    lin.b.fill(f64::NAN);
    lin.c.fill(f64::NAN);
    for m in lin.cx.iter_mut().chain(lin.cu.iter_mut()) {
        m.fill(f64::NAN);
    }
    d.linearize(k, x, u, &mut lin);
    lin
}

fn assert_vec_close(what: &str, actual: &[f64], expected: &[f64]) {
    assert_eq!(actual.len(), expected.len(), "{what}: length");
    for (i, (a, e)) in actual.iter().zip(expected).enumerate() {
        assert!(
            (a - e).abs() <= 1e-13 * (1.0 + e.abs()),
            "{what}: component {i} is {a:e}, expected {e:e}\nactual {actual:?}\nexpected {expected:?}"
        );
    }
}

#[test]
fn zero_delay_is_the_plain_model() {
    let mut rng = StdRng::seed_from_u64(5);
    for model in models() {
        let base = discrete(&model, &mut rng);
        let delayed = Delayed::new(base.clone(), 0);
        let name = format!("{:?} / {:?}", model.actuator, model.noise);
        assert_eq!(delayed.steps(), 0);
        assert_eq!(
            (delayed.nx(), delayed.nu(), delayed.nw()),
            (base.nx(), base.nu(), base.nw()),
            "{name}: sizes"
        );
        let x0 = random_state(&model, &mut rng);
        let pending = random_control(&model, &mut rng);
        assert_eq!(delayed.initial_state(&x0, &pending), x0, "{name}: x̃_0");
        for k in [0, 4, HORIZON - 1] {
            let x = random_state(&model, &mut rng);
            let u = random_control(&model, &mut rng);
            assert_eq!(
                step(&delayed, k, &x, &u),
                step(&base, k, &x, &u),
                "{name}: step"
            );
            assert_eq!(
                noise_gain(&delayed, k, &x, &u),
                noise_gain(&base, k, &x, &u),
                "{name}: noise gain"
            );
            let (l1, l2) = (linearize(&delayed, k, &x, &u), linearize(&base, k, &x, &u));
            assert_eq!(l1.a, l2.a, "{name}: A");
            assert_eq!(l1.b, l2.b, "{name}: B");
            assert_eq!(l1.noise, l2.noise, "{name}: noise kind");
            if model.nw() > 0 {
                assert_eq!(l1.c, l2.c, "{name}: c");
                assert_eq!(l1.cx, l2.cx, "{name}: Cx");
                assert_eq!(l1.cu, l2.cu, "{name}: Cu");
            }
        }
    }
}

/// Rolls the augmented model and the plain model with the delayed controls side by side, with
/// the same noise samples (`noisy`), and compares them at every step.
fn compare_rollouts(model: &ArmModel, d: usize, noisy: bool, rng: &mut StdRng) {
    let base = discrete(model, rng);
    let delayed = Delayed::new(base.clone(), d);
    let (n, m, p) = (base.nx(), base.nu(), base.nw());
    let name = format!("{:?} / {:?}, d = {d}", model.actuator, model.noise);
    assert_eq!(delayed.steps(), d);
    assert_eq!(delayed.nx(), n + m * d, "{name}: augmented size");
    assert_eq!((delayed.nu(), delayed.nw()), (m, p), "{name}: sizes");

    let x0 = random_state(model, rng);
    let pending = random_control(model, rng);
    let commands: Vec<Vec<f64>> = (0..HORIZON).map(|_| random_control(model, rng)).collect();
    // The control that acts on the plant at step k.
    let acting = |k: usize| -> &[f64] { if k < d { &pending } else { &commands[k - d] } };

    let mut aug = delayed.initial_state(&x0, &pending);
    let mut expected_x0 = x0.clone();
    for _ in 0..d {
        expected_x0.extend_from_slice(&pending);
    }
    assert_eq!(aug, expected_x0, "{name}: x̃_0");
    let mut plain = x0;
    for (k, command) in commands.iter().enumerate() {
        // x̃_k = (x_k, v_k, …, v_{k+d−1}): the plant state and the commands in flight, oldest
        // first, where v_j is the control acting at step j.
        assert_vec_close(&format!("{name}: x_{k}"), &aug[..n], &plain);
        for i in 0..d {
            assert_eq!(
                &aug[n + m * i..n + m * (i + 1)],
                acting(k + i),
                "{name}: command in flight {i} at step {k}"
            );
        }
        let eps: Vec<f64> = (0..p)
            .map(|_| {
                if noisy {
                    rng.sample(StandardNormal)
                } else {
                    0.0
                }
            })
            .collect();
        let eps = nalgebra::DVector::from_vec(eps);
        let mut next_aug = step(&delayed, k, &aug, command);
        let mut next_plain = step(&base, k, &plain, acting(k));
        if noisy && p > 0 {
            let g_aug = noise_gain(&delayed, k, &aug, command);
            let g_plain = noise_gain(&base, k, &plain, acting(k));
            // The noise drives the plant block only.
            assert_eq!(
                g_aug.rows(n, m * d).amax(),
                0.0,
                "{name}: noise on the commands in flight"
            );
            let (da, dp) = (&g_aug * &eps, &g_plain * &eps);
            for (v, e) in next_aug.iter_mut().zip(da.iter()) {
                *v += e;
            }
            for (v, e) in next_plain.iter_mut().zip(dp.iter()) {
                *v += e;
            }
        }
        aug = next_aug;
        plain = next_plain;
    }
    assert_vec_close(&format!("{name}: x_N"), &aug[..n], &plain);
    // After N steps the last d commands are still in flight.
    for i in 0..d {
        assert_eq!(
            &aug[n + m * i..n + m * (i + 1)],
            &commands[HORIZON - d + i][..],
            "{name}: final command in flight {i}"
        );
    }
}

#[test]
fn delayed_rollout_applies_each_command_d_steps_late() {
    let mut rng = StdRng::seed_from_u64(6);
    for model in models() {
        for d in [1, 3, 7] {
            compare_rollouts(&model, d, false, &mut rng);
        }
    }
}

#[test]
fn delayed_stochastic_rollout_matches_the_plain_model() {
    let mut rng = StdRng::seed_from_u64(7);
    for model in models() {
        for d in [1, 4] {
            compare_rollouts(&model, d, true, &mut rng);
        }
    }
}

/// Central differences of `g` (columns: one per component of `x`) and a round-off bound.
fn fd_jacobian(
    x: &[f64],
    rows: usize,
    mut g: impl FnMut(&[f64]) -> Vec<f64>,
) -> (DMatrix<f64>, DMatrix<f64>) {
    let mut jac = DMatrix::zeros(rows, x.len());
    let mut roundoff = DMatrix::zeros(rows, x.len());
    let mut xp = x.to_vec();
    for j in 0..x.len() {
        let h = 1e-6 * (1.0 + x[j].abs());
        xp[j] = x[j] + h;
        let plus = g(&xp);
        xp[j] = x[j] - h;
        let minus = g(&xp);
        xp[j] = x[j];
        for i in 0..rows {
            jac[(i, j)] = (plus[i] - minus[i]) / (2.0 * h);
            roundoff[(i, j)] = 64.0 * f64::EPSILON * plus[i].abs().max(minus[i].abs()) / h;
        }
    }
    (jac, roundoff)
}

/// `actual` against a finite-difference estimate: 1e-7 of the entry and of its row's largest
/// entry, plus the estimate's round-off.
fn assert_matches_fd(what: &str, actual: &DMatrix<f64>, fd: &(DMatrix<f64>, DMatrix<f64>)) {
    let (expected, roundoff) = fd;
    assert_eq!(actual.shape(), expected.shape(), "{what}: shape");
    for i in 0..expected.nrows() {
        let row = expected.row(i).amax();
        for j in 0..expected.ncols() {
            let (a, e) = (actual[(i, j)], expected[(i, j)]);
            let tol = 1e-7 * (e.abs() + row) + roundoff[(i, j)];
            assert!(
                (a - e).abs() <= tol,
                "{what}: entry ({i}, {j}) is {a:e}, expected {e:e} (tolerance {tol:e})"
            );
        }
    }
}

#[test]
fn delayed_linearization_matches_finite_differences() {
    let mut rng = StdRng::seed_from_u64(8);
    for model in models() {
        let base = discrete(&model, &mut rng);
        for d in [1, 2, 5] {
            let delayed = Delayed::new(base.clone(), d);
            let (nx, nw) = (delayed.nx(), delayed.nw());
            for k in [0, 6, HORIZON - 1] {
                let name = format!("{:?} / {:?}, d = {d}, k = {k}", model.actuator, model.noise);
                let mut x = random_state(&model, &mut rng);
                for _ in 0..d {
                    x.extend(random_control(&model, &mut rng));
                }
                let u = random_control(&model, &mut rng);
                let lin = linearize(&delayed, k, &x, &u);
                let fd_a = fd_jacobian(&x, nx, |xp| step(&delayed, k, xp, &u));
                let fd_b = fd_jacobian(&u, nx, |up| step(&delayed, k, &x, up));
                assert_matches_fd(&format!("{name}: A"), &lin.a, &fd_a);
                assert_matches_fd(&format!("{name}: B"), &lin.b, &fd_b);
                // The noise kind is the base model's at the acting (oldest in-flight) command.
                let n = base.nx();
                let m = base.nu();
                let base_lin = linearize(&base, k, &x[..n], &x[n..n + m]);
                assert_eq!(lin.noise, base_lin.noise, "{name}: noise kind");
                if nw == 0 {
                    continue;
                }
                let g = noise_gain(&delayed, k, &x, &u);
                assert_vec_close(&format!("{name}: c"), lin.c.as_slice(), g.as_slice());
                for i in 0..nw {
                    let column = |g: DMatrix<f64>| g.column(i).iter().copied().collect::<Vec<_>>();
                    let fd_cx = fd_jacobian(&x, nx, |xp| column(noise_gain(&delayed, k, xp, &u)));
                    let fd_cu = fd_jacobian(&u, nx, |up| column(noise_gain(&delayed, k, &x, up)));
                    assert_matches_fd(&format!("{name}: Cx[{i}]"), &lin.cx[i], &fd_cx);
                    assert_matches_fd(&format!("{name}: Cu[{i}]"), &lin.cu[i], &fd_cu);
                }
            }
        }
    }
}

/// A relinearisation (`Dynamics::linearize_with`, `refill`) into a buffer that holds the model's
/// linearisation at another state and control is the fresh linearisation there, bit for bit:
/// the entries it leaves alone are the ones every linearisation writes the same. Also when the
/// last call was noise-free and left the noise Jacobians as they were (emulated by junk in
/// them). And every nonzero of `A`, `B`, the noise columns and their Jacobians lies where
/// the support of `Dynamics::structure` says, and its unit columns hold their one, so reading the
/// nonzeros there (and taking the unit columns' ones unread) finds them all. The fused calls
/// (`linearize_with` and the step into a poisoned buffer, and refilling one that holds another
/// point's) give the same
/// linearisation and the step to the bit, and the model without its noise (`NoiseFree`) the
/// same `A` and `B` into a buffer without noise channels, marked noise-free.
#[test]
fn relinearization_is_a_fresh_linearization_and_the_support_holds_every_nonzero() {
    let mut rng = StdRng::seed_from_u64(9);
    let bits = |lin: &Linearization| {
        let mut all = vec![lin.a.as_slice(), lin.b.as_slice(), lin.c.as_slice()];
        all.extend(lin.cx.iter().chain(&lin.cu).map(|m| m.as_slice()));
        let all: Vec<u64> = all.concat().iter().map(|v| v.to_bits()).collect();
        (all, lin.noise)
    };
    for model in models() {
        let base = discrete(&model, &mut rng);
        for d in [0, 1, 2, 5] {
            let delayed = Delayed::new(base.clone(), d);
            let mut support = vic_core::dynamics::StateSupport::default();
            assert!(delayed.structure(Some(&mut support)).supported);
            let point = |rng: &mut StdRng| {
                let mut x = random_state(&model, rng);
                for _ in 0..d {
                    x.extend(random_control(&model, rng));
                }
                (x, random_control(&model, rng))
            };
            for k in [0, 6, HORIZON - 1] {
                let name = format!("{:?} / {:?}, d = {d}, k = {k}", model.actuator, model.noise);
                let ((x1, u1), (x2, u2)) = (point(&mut rng), point(&mut rng));
                let fresh = linearize(&delayed, k, &x2, &u2);
                let mut lin = linearize(&delayed, k, &x1, &u1);
                delayed.linearize_with(k, &x2, &u2, None, true, &mut lin);
                assert_eq!(bits(&lin), bits(&fresh), "{name}");
                if delayed.nw() > 0 {
                    let mut lin = linearize(&delayed, k, &x1, &u1);
                    lin.noise = vic_core::dynamics::NoiseKind::None;
                    lin.c.fill(f64::NAN);
                    for m in lin.cx.iter_mut().chain(lin.cu.iter_mut()) {
                        m.fill(f64::NAN);
                    }
                    delayed.linearize_with(k, &x2, &u2, None, true, &mut lin);
                    assert_eq!(bits(&lin), bits(&fresh), "{name}: after a noise-free call");
                }
                let mut step = vec![f64::NAN; delayed.nx()];
                delayed.step(k, &x2, &u2, &mut step);
                let step = step_bits(&step);
                let mut next = vec![f64::NAN; delayed.nx()];
                let mut lin = linearize(&delayed, k, &x1, &u1);
                delayed.linearize_with(k, &x2, &u2, Some(&mut next), true, &mut lin);
                assert_eq!(bits(&lin), bits(&fresh), "{name}: fused relinearisation");
                assert_eq!(
                    step_bits(&next),
                    step,
                    "{name}: fused relinearisation's step"
                );
                let mut lin = linearize(&delayed, k, &x1, &u1);
                for m in [&mut lin.a, &mut lin.b, &mut lin.c] {
                    m.fill(f64::NAN);
                }
                next.fill(f64::NAN);
                delayed.linearize_with(k, &x2, &u2, Some(&mut next), false, &mut lin);
                assert_eq!(bits(&lin), bits(&fresh), "{name}: fused linearisation");
                assert_eq!(step_bits(&next), step, "{name}: fused linearisation's step");
                let quiet = NoiseFree(Delayed::new(base.clone(), d));
                assert_eq!(quiet.nw(), 0);
                let mut lin = Linearization::new(delayed.nx(), delayed.nu(), 0);
                lin.a.fill(f64::NAN);
                lin.b.fill(f64::NAN);
                quiet.linearize(k, &x2, &u2, &mut lin);
                let plain =
                    |l: &Linearization| step_bits(&[l.a.as_slice(), l.b.as_slice()].concat());
                assert_eq!(plain(&lin), plain(&fresh), "{name}: without the noise");
                assert_eq!(lin.noise, vic_core::dynamics::NoiseKind::None, "{name}");
                next.fill(f64::NAN);
                quiet.linearize_with(k, &x1, &u1, Some(&mut next), true, &mut lin);
                let other = linearize(&delayed, k, &x1, &u1);
                assert_eq!(
                    plain(&lin),
                    plain(&other),
                    "{name}: without the noise, fused"
                );
                let ranges = |r: &[std::ops::Range<usize>]| -> Vec<Column> {
                    r.iter().cloned().map(Column::Rows).collect()
                };
                let (cx, cu) = (ranges(&support.cx), ranges(&support.cu));
                let c = vec![Column::Rows(support.c.clone()); fresh.c.ncols()];
                let jacobians = [("A", &fresh.a, &support.a), ("B", &fresh.b, &support.b)]
                    .into_iter()
                    .chain(std::iter::once(("c", &fresh.c, &c)))
                    .chain(fresh.cx.iter().map(|m| ("Cx", m, &cx)))
                    .chain(fresh.cu.iter().map(|m| ("Cu", m, &cu)));
                for (what, m, columns) in jacobians {
                    assert_eq!(columns.len(), m.ncols(), "{name}: {what}");
                    for ((i, j), v) in m
                        .iter()
                        .enumerate()
                        .map(|(e, v)| ((e % m.nrows(), e / m.nrows()), v))
                    {
                        assert!(
                            *v == 0.0 || columns[j].contains(i),
                            "{name}: {what} ({i}, {j}) = {v} outside {:?}",
                            columns[j]
                        );
                        if columns[j] == Column::Unit(i) {
                            assert_eq!(*v, 1.0, "{name}: {what} ({i}, {j}) of a unit column");
                        }
                    }
                }
            }
        }
    }
}
