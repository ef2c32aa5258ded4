//! The mean-and-covariance step of the open-loop plant (the covariance propagation
//! `P⁺ = A P Aᵀ + Σ_i (c_i c_iᵀ + Cx_i P Cx_iᵀ)` of the module documentation).

use super::{MomentExpansion, pack, unpack, vech_len};
use crate::dense::{multiply, zero};
use crate::dynamics::{DiscreteDynamics, Dynamics, Linearization, NoiseKind};
use nalgebra::DMatrix;
use std::sync::Mutex;

/// Scratch matrices for one evaluation of the moment dynamics.
struct Scratch {
    lin: Linearization,
    p: DMatrix<f64>,
    next: DMatrix<f64>,
    t1: DMatrix<f64>,
}

impl Scratch {
    fn new(n: usize, m: usize, p: usize) -> Self {
        let z = |r, c| DMatrix::zeros(r, c);
        Scratch {
            lin: Linearization::new(n, m, p),
            p: z(n, n),
            next: z(n, n),
            t1: z(n, n),
        }
    }
}

/// The mean-and-covariance dynamics of an [`DiscreteDynamics`] executed open loop: a deterministic
/// [`Dynamics`] on `z = (m, vech P)` of dimension `n + n(n+1)/2`.
pub struct MomentDynamics<'a> {
    base: &'a DiscreteDynamics,
    scratch: Mutex<Scratch>,
}

impl<'a> MomentDynamics<'a> {
    pub fn new(base: &'a DiscreteDynamics) -> Self {
        let (n, m, p) = (base.nx(), base.nu(), base.nw());
        MomentDynamics {
            base,
            scratch: Mutex::new(Scratch::new(n, m, p)),
        }
    }

    /// The plant model whose moments these are.
    pub fn base(&self) -> &DiscreteDynamics {
        self.base
    }

    /// The plant's state dimension n.
    pub fn n(&self) -> usize {
        self.base.nx()
    }

    /// The initial moment state: a known start (`P = 0`).
    pub fn initial_state(&self, x0: &[f64]) -> Vec<f64> {
        let mut z = x0.to_vec();
        z.resize(self.nx(), 0.0);
        z
    }
}

/// `out += a · l · mid · rᵀ`, with `tmp` for `l · mid`.
fn add_sandwich(
    out: &mut DMatrix<f64>,
    a: f64,
    l: &DMatrix<f64>,
    mid: &DMatrix<f64>,
    r: &DMatrix<f64>,
    tmp: &mut DMatrix<f64>,
) {
    multiply(tmp, l, mid, false);
    // out += a · tmp · rᵀ
    let n = out.nrows();
    for i in 0..n {
        for j in 0..n {
            let mut s = 0.0;
            for k in 0..n {
                s += tmp[(i, k)] * r[(j, k)];
            }
            out[(i, j)] += a * s;
        }
    }
}

impl Dynamics for MomentDynamics<'_> {
    fn nx(&self) -> usize {
        let n = self.base.nx();
        n + vech_len(n)
    }
    fn nu(&self) -> usize {
        self.base.nu()
    }
    fn nw(&self) -> usize {
        0
    }

    fn step(&self, k: usize, z: &[f64], u: &[f64], next: &mut [f64]) {
        let n = self.base.nx();
        let mut guard = self.scratch.lock().expect("scratch lock");
        let s = &mut *guard;
        // The mean's step and `A` from one pass through the sub-steps (the chain rule runs
        // through the step's own states), `A` being the one the expansion at this point uses.
        self.base
            .linearize_with(k, &z[..n], u, Some(&mut next[..n]), false, &mut s.lin);
        unpack(n, &z[n..], &mut s.p);
        zero(&mut s.next);
        add_sandwich(&mut s.next, 1.0, &s.lin.a, &s.p, &s.lin.a, &mut s.t1);
        if s.lin.noise != NoiseKind::None {
            for i in 0..s.lin.c.ncols() {
                s.next.ger(1.0, &s.lin.c.column(i), &s.lin.c.column(i), 1.0);
                if s.lin.noise == NoiseKind::Dependent {
                    add_sandwich(
                        &mut s.next,
                        1.0,
                        &s.lin.cx[i],
                        &s.p,
                        &s.lin.cx[i],
                        &mut s.t1,
                    );
                }
            }
        }
        pack(n, &s.next, &mut next[n..]);
    }

    fn noise_gain(&self, _k: usize, _z: &[f64], _u: &[f64], _out: &mut DMatrix<f64>) {}

    fn linearize(&self, k: usize, z: &[f64], u: &[f64], lin: &mut Linearization) {
        // Own expansion per call: knots are linearised in parallel.
        let mut e = MomentExpansion::new(self.base.nx(), self.base.nu(), self.base.nw());
        self.expand(k, z, u, &mut e);
        lin.noise = NoiseKind::None;
        lin.a.copy_from(&e.a);
        lin.b.copy_from(&e.b);
    }
}
