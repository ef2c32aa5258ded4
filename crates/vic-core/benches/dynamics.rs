//! Rigid-body dynamics of a URDF chain: `cargo bench -p vic-core --bench dynamics`.
//!
//! The 7-joint Franka Panda of `config/panda.urdf` at one state: RNEA (inverse dynamics), CRBA
//! (the mass matrix) and forward dynamics (CRBA, RNEA for the bias, `L D Lᵀ`) in `f64`, and the
//! forward dynamics' first derivatives with respect to the state `(q, q')` with dual numbers:
//! fourteen passes with `Dual64` (one direction each) and one pass with `DualSVec64<14>` (every
//! direction at once), and `forward_dynamics_derivatives` (`−M⁻¹ ∂τ_ID/∂x`: only the inverse
//! dynamics in dual numbers). Issue 62's targets: 2 µs in `f64`, 20 µs with first derivatives.

use criterion::{Criterion, criterion_group, criterion_main};
use num_dual::{Dual64, DualSVec64};
use std::hint::black_box;
use vic_core::model::serial::SerialChain;

const Q: [f64; 7] = [0.1, -0.4, 0.2, -1.8, 0.3, 1.5, 0.6];
const QD: [f64; 7] = [0.5, -0.3, 0.8, 0.2, -1.0, 0.6, 1.2];
const QDD: [f64; 7] = [1.0, -2.0, 0.5, 3.0, -1.5, 2.5, -0.7];
const TAU: [f64; 7] = [2.0, -5.0, 1.0, 8.0, -0.5, 0.7, 0.1];

fn panda() -> SerialChain {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/panda.urdf");
    let text = std::fs::read_to_string(path).expect("config/panda.urdf");
    SerialChain::from_urdf(&text, path, "panda_link0", "panda_hand").expect("the Panda loads")
}

fn serial_dynamics(c: &mut Criterion) {
    let chain = panda();
    let mut group = c.benchmark_group("serial_dynamics");
    group.bench_function("panda_rnea_f64", |b| {
        b.iter(|| chain.inverse_dynamics(black_box(&Q), black_box(&QD), black_box(&QDD)))
    });
    group.bench_function("panda_crba_f64", |b| {
        b.iter(|| chain.mass_matrix(black_box(&Q)))
    });
    group.bench_function("panda_forward_f64", |b| {
        b.iter(|| chain.forward_dynamics(black_box(&Q), black_box(&QD), black_box(&TAU)))
    });
    group.bench_function("panda_rnea_crba_forward_f64", |b| {
        b.iter(|| {
            let (q, qd) = (black_box(&Q), black_box(&QD));
            let tau = chain.inverse_dynamics(q, qd, black_box(&QDD));
            let m = chain.mass_matrix(q);
            let qdd = chain.forward_dynamics(q, qd, black_box(&TAU));
            (tau, m, qdd)
        })
    });
    group.bench_function("panda_forward_jacobian_dual64_x14", |b| {
        b.iter(|| {
            let mut jac = [[0.0; 7]; 14];
            for (k, column) in jac.iter_mut().enumerate() {
                let seed = |i: usize, v: f64| Dual64::new(v, if i == k { 1.0 } else { 0.0 });
                let q: [Dual64; 7] = std::array::from_fn(|i| seed(i, black_box(Q)[i]));
                let qd: [Dual64; 7] = std::array::from_fn(|i| seed(7 + i, black_box(QD)[i]));
                let tau = TAU.map(Dual64::from);
                let a = chain.forward_dynamics(&q, &qd, &tau);
                *column = a.map(|v| v.eps);
            }
            jac
        })
    });
    group.bench_function("panda_forward_jacobian_dualsvec14", |b| {
        b.iter(|| {
            type D = DualSVec64<14>;
            let q: [D; 7] = std::array::from_fn(|i| D::from_re(black_box(Q)[i]).derivative(i));
            let qd: [D; 7] =
                std::array::from_fn(|i| D::from_re(black_box(QD)[i]).derivative(7 + i));
            let tau = TAU.map(D::from);
            chain.forward_dynamics(&q, &qd, &tau)
        })
    });
    group.bench_function("panda_forward_derivatives_via_inverse", |b| {
        b.iter(|| {
            chain.forward_dynamics_derivatives(black_box(&Q), black_box(&QD), black_box(&TAU))
        })
    });
    group.finish();
}

criterion_group!(benches, serial_dynamics);
criterion_main!(benches);
