//! Stochastic optimal open-loop control (DESIGN §5, after Berret & Jean 2020): the plan is executed
//! without any feedback, so its quality is the expected cost of the *open-loop* stochastic plant.
//! Propagate the mean and covariance,
//!
//! `m[k+1] = Φ(m[k], u[k])`,
//! `P[k+1] = A P Aᵀ + E[G Gᵀ] = A P Aᵀ + Σ_i (c_i c_iᵀ + Cx_i P Cx_iᵀ)`, `A = ∂Φ/∂x (m, u)`,
//!
//! (exact for noise affine in the state, e.g. `F = σ q' I`: `E[F Fᵀ] = σ² (m_v² + P_vv) I`), and
//! minimise `Σ ℓ(m, u) + ½ tr(ℓ_xx P) + g(m_N) + ½ tr(g_xx P_N)` over `u` with the same DDP machinery,
//! on the deterministic state `z = (m, vech P)`. Stiffness enters the cost through `A`, so the optimum
//! raises it where the plant is unstable or noisy — what plain ILQG cannot see (DESIGN §4).
//!
//! The derivatives of `z[k+1]` need the second derivatives of the flow (`∂A/∂m`, `∂A/∂u`): they come
//! from nested dual numbers through [`EulerModel::flow_jacobian`].

use crate::core::cost::{Cost, CostDerivatives, TrackingCost};
use crate::core::dynamics::{Dynamics, EulerModel, Linearization, NoiseKind};
use crate::core::scalar::{MAX_NU, MAX_NW, MAX_NX};
use nalgebra::DMatrix;
use num_dual::{Dual, Dual64};
use std::sync::Mutex;

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

/// Scratch matrices for one evaluation of the moment dynamics.
struct Scratch {
    lin: Linearization,
    p: DMatrix<f64>,
    next: DMatrix<f64>,
    t1: DMatrix<f64>,
    da: DMatrix<f64>,
    dcx: DMatrix<f64>,
    dc: Vec<f64>,
    /// `P Aᵀ` and `P Cx_iᵀ` at the knot being linearised.
    pat: DMatrix<f64>,
    pcx: Vec<DMatrix<f64>>,
}

impl Scratch {
    fn new(n: usize, m: usize, p: usize) -> Self {
        let z = |r, c| DMatrix::zeros(r, c);
        Scratch {
            lin: Linearization::new(n, m, p),
            p: z(n, n),
            next: z(n, n),
            t1: z(n, n),
            da: z(n, n),
            dcx: z(n, n),
            dc: vec![0.0; n],
            pat: z(n, n),
            pcx: (0..p).map(|_| z(n, n)).collect(),
        }
    }
}

/// The mean-and-covariance dynamics of an [`EulerModel`] executed open loop: a deterministic
/// [`Dynamics`] on `z = (m, vech P)` of dimension `n + n(n+1)/2`.
pub struct MomentDynamics<'a> {
    base: &'a EulerModel,
    scratch: Mutex<Scratch>,
}

impl<'a> MomentDynamics<'a> {
    pub fn new(base: &'a EulerModel) -> Self {
        let (n, m, p) = (base.nx(), base.nu(), base.nw());
        MomentDynamics {
            base,
            scratch: Mutex::new(Scratch::new(n, m, p)),
        }
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
    tmp.gemm(1.0, l, mid, 0.0);
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

/// The parts of the plant's linearisation that the covariance step needs: `A`, `c_i`, `Cx_i`
/// (not `B`: m fewer dual flow evaluations per step of every line-search rollout). Computed as
/// [`EulerModel`]'s `linearize` computes them, so the values are the same.
fn state_linearization(base: &EulerModel, k: usize, x: &[f64], u: &[f64], lin: &mut Linearization) {
    let (n, m) = (base.nx(), base.nu());
    let mut xd = [Dual64::from(0.0); MAX_NX];
    let mut ud = [Dual64::from(0.0); MAX_NU];
    for (d, v) in xd.iter_mut().zip(x) {
        *d = Dual64::from(*v);
    }
    for (d, v) in ud.iter_mut().zip(u) {
        *d = Dual64::from(*v);
    }
    let mut out = [Dual64::from(0.0); MAX_NX];
    for j in 0..n {
        xd[j].eps = 1.0;
        base.flow(k, &xd[..n], &ud[..m], &mut out[..n]);
        xd[j].eps = 0.0;
        for r in 0..n {
            lin.a[(r, j)] = out[r].eps;
        }
    }
    base.noise_linearization(x, u, lin, false);
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
        self.base.step(k, &z[..n], u, &mut next[..n]);
        state_linearization(self.base, k, &z[..n], u, &mut s.lin);
        unpack(n, &z[n..], &mut s.p);
        s.next.fill(0.0);
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
        let base = self.base;
        let (n, m, nw) = (base.nx(), base.nu(), base.nw());
        let pairs_len = vech_len(n);
        // Own scratch per call: knots are linearised in parallel.
        let mut own = Scratch::new(n, m, nw);
        let s = &mut own;
        base.linearize(k, &z[..n], u, &mut s.lin);
        unpack(n, &z[n..], &mut s.p);
        lin.noise = NoiseKind::None;
        lin.a.fill(0.0);
        lin.b.fill(0.0);
        lin.a.view_mut((0, 0), (n, n)).copy_from(&s.lin.a);
        lin.b.view_mut((0, 0), (n, m)).copy_from(&s.lin.b);
        let noisy = s.lin.noise != NoiseKind::None;
        let dependent = s.lin.noise == NoiseKind::Dependent;

        // ∂P⁺/∂P along each symmetric basis matrix E_ab = e_a e_bᵀ + e_b e_aᵀ (E_aa = e_a e_aᵀ
        // counted once as in `vech`): A E Aᵀ = A_a A_bᵀ + A_b A_aᵀ with A_a the a-th column, and
        // the same for every Cx_i. O(n²) per entry instead of the sandwich's O(n³).
        let mut f = 0;
        for a in 0..n {
            for b in a..n {
                let mut e = 0;
                for r in 0..n {
                    for c in r..n {
                        let pair = |m: &DMatrix<f64>| {
                            if a == b {
                                m[(r, a)] * m[(c, a)]
                            } else {
                                m[(r, a)] * m[(c, b)] + m[(r, b)] * m[(c, a)]
                            }
                        };
                        let mut v = pair(&s.lin.a);
                        if dependent {
                            for i in 0..nw {
                                v += pair(&s.lin.cx[i]);
                            }
                        }
                        lin.a[(n + e, n + f)] = v;
                        e += 1;
                    }
                }
                f += 1;
            }
        }
        debug_assert_eq!(f, pairs_len);

        // ∂A/∂(m,u)_j from the second derivatives of the flow: column i of ∂A/∂z_j is
        // ∂²Φ/∂z_j ∂x_i, one nested-dual flow evaluation per pair. The pairs with both indices
        // in the state are symmetric, so only i ≤ j is evaluated, and B's second derivatives
        // (not needed) are never formed.
        let mut d2 = [[[0.0; MAX_NX]; MAX_NX]; MAX_NX + MAX_NU];
        {
            let zero = Dual::from_re(Dual64::from(0.0));
            let mut xdd = [zero; MAX_NX];
            let mut udd = [zero; MAX_NU];
            for (d, v) in xdd.iter_mut().zip(&z[..n]) {
                *d = Dual::from_re(Dual64::from(*v));
            }
            for (d, v) in udd.iter_mut().zip(u) {
                *d = Dual::from_re(Dual64::from(*v));
            }
            let mut out = [zero; MAX_NX];
            for j in 0..n + m {
                for i in 0..n {
                    if j < n && i < j {
                        d2[j][i] = d2[i][j];
                        continue;
                    }
                    // Inner seed on z_j, outer seed on x_i: out.eps.eps = ∂²Φ/∂x_i ∂z_j.
                    if j < n {
                        xdd[j].re.eps = 1.0;
                    } else {
                        udd[j - n].re.eps = 1.0;
                    }
                    xdd[i].eps.re = 1.0;
                    base.flow(k, &xdd[..n], &udd[..m], &mut out[..n]);
                    xdd[i].eps.re = 0.0;
                    if j < n {
                        xdd[j].re.eps = 0.0;
                    } else {
                        udd[j - n].re.eps = 0.0;
                    }
                    for r in 0..n {
                        d2[j][i][r] = out[r].eps.eps;
                    }
                }
            }
        }

        // ∂P⁺/∂m_j and ∂P⁺/∂u_j: d(A P Aᵀ) = X + Xᵀ with X = dA (P Aᵀ), and the same for each
        // Cx_i; P Aᵀ and P Cx_iᵀ do not depend on j.
        // P Aᵀ = (A P)ᵀ, P being symmetric.
        s.t1.gemm(1.0, &s.lin.a, &s.p, 0.0);
        s.t1.transpose_to(&mut s.pat);
        if dependent {
            for i in 0..nw {
                s.t1.gemm(1.0, &s.lin.cx[i], &s.p, 0.0);
                s.t1.transpose_to(&mut s.pcx[i]);
            }
        }
        let mut xd = [Dual64::from(0.0); MAX_NX];
        let mut ud = [Dual64::from(0.0); MAX_NU];
        for (d, v) in xd.iter_mut().zip(&z[..n]) {
            *d = Dual64::from(*v);
        }
        for (d, v) in ud.iter_mut().zip(u) {
            *d = Dual64::from(*v);
        }
        let mut g = [Dual64::from(0.0); MAX_NX * MAX_NW];
        let mut dgx = [Dual64::from(0.0); MAX_NX * MAX_NX * MAX_NW];
        let mut dgu = [Dual64::from(0.0); MAX_NU * MAX_NX * MAX_NW];
        let block = n * nw;
        for j in 0..n + m {
            for c in 0..n {
                for r in 0..n {
                    s.da[(r, c)] = d2[j][c][r];
                }
            }
            s.t1.gemm(1.0, &s.da, &s.pat, 0.0);
            if noisy {
                if j < n {
                    xd[j].eps = 1.0;
                } else {
                    ud[j - n].eps = 1.0;
                }
                base.noise_jacobian(&xd[..n], &ud[..m], &mut g, &mut dgx, &mut dgu);
                if j < n {
                    xd[j].eps = 0.0;
                } else {
                    ud[j - n].eps = 0.0;
                }
            }
            s.next.fill(0.0);
            if noisy {
                for i in 0..nw {
                    // dc_i = ∂c_i/∂(m,u)_j; d(c cᵀ) = dc cᵀ + c dcᵀ
                    for r in 0..n {
                        s.dc[r] = g[i * n + r].eps;
                    }
                    for r in 0..n {
                        for c in 0..n {
                            s.next[(r, c)] += s.dc[r] * s.lin.c[(c, i)] + s.lin.c[(r, i)] * s.dc[c];
                        }
                    }
                    if dependent {
                        // dCx from the second derivatives of the noise gain.
                        for c in 0..n {
                            for r in 0..n {
                                s.dcx[(r, c)] = dgx[c * block + i * n + r].eps;
                            }
                        }
                        s.t1.gemm(1.0, &s.dcx, &s.pcx[i], 1.0);
                    }
                }
            }
            let mut e = 0;
            for r in 0..n {
                for c in r..n {
                    let v = s.next[(r, c)] + s.t1[(r, c)] + s.t1[(c, r)];
                    if j < n {
                        lin.a[(n + e, j)] = v;
                    } else {
                        lin.b[(n + e, j - n)] = v;
                    }
                    e += 1;
                }
            }
        }
    }
}

/// The expected cost of the open-loop plant in moment form: `ℓ(m, u) + ½ tr(ℓ_xx P)` per step and
/// `g(m_N) + ½ tr(g_xx P_N)` at the end, exact for the quadratic tracking cost of Eq. 14.
pub struct MomentCost<'a> {
    inner: &'a TrackingCost,
    n: usize,
    /// `vech` weights of `½ tr(ℓ_xx P)` (running) and `½ tr(g_xx P)` (final), per knot.
    running_weights: Vec<Vec<f64>>,
    terminal_weights: Vec<f64>,
}

impl<'a> MomentCost<'a> {
    pub fn new(inner: &'a TrackingCost, horizon: usize) -> Self {
        let n = inner.nx;
        let nu = inner.control_weights.len();
        let mut d = CostDerivatives::new(n, nu);
        let x = vec![0.0; n];
        let u = vec![0.0; nu];
        let weights = |lxx: &DMatrix<f64>| -> Vec<f64> {
            vech_pairs(n)
                .into_iter()
                .map(|(a, b)| {
                    if a == b {
                        0.5 * lxx[(a, a)]
                    } else {
                        lxx[(a, b)]
                    }
                })
                .collect()
        };
        let running_weights = (0..horizon)
            .map(|k| {
                inner.running_derivatives(k, &x, &u, &mut d);
                weights(&d.lxx)
            })
            .collect();
        inner.terminal_derivatives(&x, &mut d);
        let terminal_weights = weights(&d.lxx);
        MomentCost {
            inner,
            n,
            running_weights,
            terminal_weights,
        }
    }

    fn trace_term(w: &[f64], vech: &[f64]) -> f64 {
        w.iter().zip(vech).map(|(a, b)| a * b).sum()
    }
}

impl Cost for MomentCost<'_> {
    fn running(&self, k: usize, z: &[f64], u: &[f64]) -> f64 {
        let n = self.n;
        self.inner.running(k, &z[..n], u) + Self::trace_term(&self.running_weights[k], &z[n..])
    }

    fn terminal(&self, z: &[f64]) -> f64 {
        let n = self.n;
        self.inner.terminal(&z[..n]) + Self::trace_term(&self.terminal_weights, &z[n..])
    }

    fn running_derivatives(&self, k: usize, z: &[f64], u: &[f64], d: &mut CostDerivatives) {
        let n = self.n;
        let mut inner = CostDerivatives::new(n, u.len());
        self.inner.running_derivatives(k, &z[..n], u, &mut inner);
        d.lx.fill(0.0);
        d.lxx.fill(0.0);
        d.lux.fill(0.0);
        d.lx.rows_mut(0, n).copy_from(&inner.lx);
        d.lx.rows_mut(n, z.len() - n)
            .copy_from_slice(&self.running_weights[k]);
        d.lxx.view_mut((0, 0), (n, n)).copy_from(&inner.lxx);
        d.lux.view_mut((0, 0), (u.len(), n)).copy_from(&inner.lux);
        d.lu.copy_from(&inner.lu);
        d.luu.copy_from(&inner.luu);
    }

    fn terminal_derivatives(&self, z: &[f64], d: &mut CostDerivatives) {
        let n = self.n;
        let mut inner = CostDerivatives::new(n, d.lu.len());
        self.inner.terminal_derivatives(&z[..n], &mut inner);
        d.lx.fill(0.0);
        d.lxx.fill(0.0);
        d.lx.rows_mut(0, n).copy_from(&inner.lx);
        d.lx.rows_mut(n, z.len() - n)
            .copy_from_slice(&self.terminal_weights);
        d.lxx.view_mut((0, 0), (n, n)).copy_from(&inner.lxx);
    }
}
