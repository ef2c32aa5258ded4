//! The derivatives of the moment step `z⁺ = F(z, u)` by forward-mode automatic differentiation
//! through the discretised flow: first derivatives (`expand`, every iteration) and the
//! costate-contracted second derivatives that the Newton model adds (`second_order`).

use super::{MomentDynamics, MomentExpansion, costate_matrix, lift, unpack};
use crate::core::dense::zero;
use crate::core::dynamics::{DiscreteDynamics, Dynamics, NoiseKind};
#[cfg(test)]
use crate::core::model::Plant;
use crate::core::scalar::{MAX_NU, MAX_NW, MAX_NX};
use crate::core::taylor::Taylor3;
use nalgebra::DMatrix;
use num_dual::{Dual, Dual64};

/// The largest number of variables `v = (x, u)` of one knot.
const MAX_NV: usize = MAX_NX + MAX_NU;

impl MomentDynamics<'_> {
    /// The first derivatives of the moment step at knot `k` into `e.a`, `e.b`, and what
    /// [`MomentExpansion::curvature`] needs of them besides (`dA_j`, `dc_j`, `dCx_j`).
    ///
    /// `∂P⁺/∂(m, u)` needs the second derivatives of the flow (`∂A/∂v_j`): one nested-dual flow
    /// evaluation per pair `(v_j, x_i)`, the state–state pairs once by symmetry.
    pub fn expand(&self, k: usize, z: &[f64], u: &[f64], e: &mut MomentExpansion) {
        let base = self.base();
        let (n, m) = (base.nx(), base.nu());
        base.linearize(k, &z[..n], u, &mut e.base);
        unpack(n, &z[n..], &mut e.p);
        zero(&mut e.a);
        zero(&mut e.b);
        e.a.view_mut((0, 0), (n, n)).copy_from(&e.base.a);
        e.b.view_mut((0, 0), (n, m)).copy_from(&e.base.b);
        covariance_transition(e);
        let at = At::new(base, k, z, u);
        flow_hessian(at, e);
        covariance_sensitivity(at, e);
    }

    /// What the Newton model needs beyond [`MomentDynamics::expand`] (which must have run at the
    /// same `(z, u)`), contracted with the costate `lam_next` of the next knot:
    ///
    /// * the third derivatives of the flow, only as `h3 = 2 Σ_{r,c} (Λ A P)_{rc}
    ///   ∂³Φ_r/∂x_c∂v_a∂v_b` (the one place [`MomentExpansion::curvature`] uses them),
    ///   contracted as each distinct triple is evaluated: no `n (n + m)²` tensor is stored or
    ///   copied, and the backward pass's retries at higher μ reuse the `(n + m)²` contraction;
    /// * `∂²Φ/∂u_a∂u_b` (the pairs that `expand`'s `dA_j` do not cover);
    /// * for a noise gain nonlinear in the state, its second and third derivatives.
    ///
    /// With `third` false the flow's third derivatives are left out (`h3 = 0`): the cheaper,
    /// inexact model of [`crate::core::solver::sooc_newton::SoocOptions::flow_third_derivatives`].
    pub fn second_order(
        &self,
        k: usize,
        z: &[f64],
        u: &[f64],
        lam_next: &[f64],
        third: bool,
        s: &mut MomentExpansion,
    ) {
        let base = self.base();
        let n = base.nx();
        s.h3_costate.copy_from_slice(lam_next);
        // T = Λ A P, the weight of ∂A/∂v_a∂v_b in 2 tr(Λ ∂²A P Aᵀ) = 2 Σ ∂²A ∘ (Λ A P).
        costate_matrix(n, &lam_next[n..], &mut s.lam);
        s.t1.gemm(1.0, &s.lam, &s.base.a, 0.0);
        s.t2.gemm(1.0, &s.t1, &s.p, 0.0);
        let at = At::new(base, k, z, u);
        flow_control_hessian(at, s);
        if third {
            flow_third_contracted(at, s);
        } else {
            zero(&mut s.h3);
        }
        if s.curved_model && base.nw() > 0 {
            noise_gain_second_order(at, s);
        }
    }
}

/// The point the moment step is differentiated at: knot `k`, the mean state `x` (the first `n`
/// entries of the moment state `z`) and the control `u`. Every derivative below lifts `(x, u)`
/// into dual numbers and evaluates the flow of `base` there.
#[derive(Clone, Copy)]
struct At<'a> {
    base: &'a DiscreteDynamics,
    k: usize,
    x: &'a [f64],
    u: &'a [f64],
}

impl<'a> At<'a> {
    fn new(base: &'a DiscreteDynamics, k: usize, z: &'a [f64], u: &'a [f64]) -> Self {
        At {
            base,
            k,
            x: &z[..base.nx()],
            u,
        }
    }
}

/// `∂P⁺/∂P` along each symmetric basis matrix `E_ab = e_a e_bᵀ + e_b e_aᵀ` (`E_aa = e_a e_aᵀ`
/// counted once as in `vech`): `A E Aᵀ = A_a A_bᵀ + A_b A_aᵀ` with `A_a` the a-th column, and
/// the same for every `Cx_i`. `O(n²)` per entry instead of the sandwich's `O(n³)`.
fn covariance_transition(s: &mut MomentExpansion) {
    let (n, nw) = (s.n, s.nw);
    let dependent = s.base.noise == NoiseKind::Dependent;
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
                    let mut v = pair(&s.base.a);
                    if dependent {
                        for i in 0..nw {
                            v += pair(&s.base.cx[i]);
                        }
                    }
                    s.a[(n + e, n + f)] = v;
                    e += 1;
                }
            }
            f += 1;
        }
    }
}

/// `dA_j = ∂A/∂(m,u)_j` from the second derivatives of the flow: column i of `dA_j` is
/// `∂²Φ/∂v_j ∂x_i`, one nested-dual flow evaluation per pair. The pairs with both indices in the
/// state are symmetric, so only `i ≤ j` is evaluated.
fn flow_hessian(at: At, s: &mut MomentExpansion) {
    let At { base, k, x, u } = at;
    let (n, m) = (base.nx(), base.nu());
    let (mut xdd, mut udd) = lift::<Dual<Dual64>>(x, u);
    let mut out = [Dual::from_re(Dual64::from(0.0)); MAX_NX];
    for j in 0..n + m {
        for i in 0..n {
            if j < n && i < j {
                for r in 0..n {
                    let v = s.da[i][(r, j)];
                    s.da[j][(r, i)] = v;
                }
                continue;
            }
            // Inner seed on v_j, outer seed on x_i: out.eps.eps = ∂²Φ/∂x_i ∂v_j.
            seed_inner(&mut xdd, &mut udd, n, j, 1.0);
            xdd[i].eps.re = 1.0;
            base.flow(k, &xdd[..n], &udd[..m], &mut out[..n]);
            xdd[i].eps.re = 0.0;
            seed_inner(&mut xdd, &mut udd, n, j, 0.0);
            for r in 0..n {
                s.da[j][(r, i)] = out[r].eps.eps;
            }
        }
    }
}

/// Sets the inner derivative seed of entry `j` of `v = (x, u)` of nested duals.
fn seed_inner(x: &mut [Dual<Dual64>], u: &mut [Dual<Dual64>], n: usize, j: usize, value: f64) {
    if j < n {
        x[j].re.eps = value;
    } else {
        u[j - n].re.eps = value;
    }
}

/// `∂P⁺/∂m_j` and `∂P⁺/∂u_j` into the covariance rows of `e.a`, `e.b`: `d(A P Aᵀ) = X + Xᵀ` with
/// `X = dA (P Aᵀ)`, the same for each `Cx_i`, and `d(c cᵀ) = dc cᵀ + c dcᵀ` (`P Aᵀ` and
/// `P Cx_iᵀ` do not depend on j).
fn covariance_sensitivity(at: At, s: &mut MomentExpansion) {
    let At { base, x, u, .. } = at;
    let (n, m, nw) = (base.nx(), base.nu(), base.nw());
    let noisy = s.base.noise != NoiseKind::None;
    // P Aᵀ = (A P)ᵀ, P being symmetric.
    s.t1.gemm(1.0, &s.base.a, &s.p, 0.0);
    s.t1.transpose_to(&mut s.atl);
    let (mut xd, mut ud) = lift::<Dual64>(x, u);
    let zero = Dual64::from(0.0);
    let mut g = [zero; MAX_NX * MAX_NW];
    let mut dgx = [zero; MAX_NX * MAX_NX * MAX_NW];
    let mut dgu = [zero; MAX_NU * MAX_NX * MAX_NW];
    s.curved_noise = false;
    for j in 0..n + m {
        s.t1.gemm(1.0, &s.da[j], &s.atl, 0.0);
        crate::core::dense::zero(&mut s.next);
        if noisy {
            let v = if j < n { &mut xd[j] } else { &mut ud[j - n] };
            v.eps = 1.0;
            base.noise_jacobian(&xd[..n], &ud[..m], &mut g, &mut dgx, &mut dgu);
            let v = if j < n { &mut xd[j] } else { &mut ud[j - n] };
            v.eps = 0.0;
            for i in 0..nw {
                noise_sensitivity(s, j, i, &g, &dgx);
            }
        }
        let mut e = 0;
        for r in 0..n {
            for c in r..n {
                let v = s.next[(r, c)] + s.t1[(r, c)] + s.t1[(c, r)];
                if j < n {
                    s.a[(n + e, j)] = v;
                } else {
                    s.b[(n + e, j - n)] = v;
                }
                e += 1;
            }
        }
    }
}

/// Noise channel `i`'s part of `∂P⁺/∂v_j` (`g`, `dgx`: the noise gain and its state Jacobian
/// with `v_j` seeded): `dc cᵀ + c dcᵀ` into `s.next`, and `dCx P Cxᵀ` into `s.t1` when the
/// gain's state Jacobian varies (then `s.curved_noise`).
fn noise_sensitivity(s: &mut MomentExpansion, j: usize, i: usize, g: &[Dual64], dgx: &[Dual64]) {
    let (n, block) = (s.n, s.n * s.nw);
    for r in 0..n {
        s.dc[j][(r, i)] = g[i * n + r].eps;
    }
    for r in 0..n {
        for c in 0..n {
            s.next[(r, c)] +=
                s.dc[j][(r, i)] * s.base.c[(c, i)] + s.base.c[(r, i)] * s.dc[j][(c, i)];
        }
    }
    if s.base.noise != NoiseKind::Dependent {
        return;
    }
    let mut any = false;
    for c in 0..n {
        for r in 0..n {
            let v = dgx[c * block + i * n + r].eps;
            any |= v != 0.0;
            s.dcx[j][i][(r, c)] = v;
        }
    }
    if any {
        s.curved_noise = true;
        // P Cx_iᵀ = (Cx_i P)ᵀ
        s.t2.gemm(1.0, &s.base.cx[i], &s.p, 0.0);
        s.t2.transpose_to(&mut s.t3);
        s.t1.gemm(1.0, &s.dcx[j][i], &s.t3, 1.0);
    }
}

/// `s.h3 = 2 Σ_{r,c} T_{rc} ∂³Φ_r/∂x_c∂v_a∂v_b` with `T = s.t2`, from third derivatives of the
/// flow along single directions (univariate Taylor polynomials; Griewank, Utke & Walther, Math.
/// Comp. 2000). Along `w` the flow gives `D³Φ[w] = Σ_{ijk} ∂³Φ/∂v_i∂v_j∂v_k w_i w_j w_k`, so
///
/// * `w = e_a` gives `∂_aaa`;
/// * `w = e_a ± e_b` give `∂_aaa ± 3 ∂_aab + 3 ∂_abb ± ∂_bbb`, hence `∂_aab` and `∂_abb`;
/// * `w = e_a + e_b + e_c` gives `6 ∂_abc` plus entries already known.
///
/// The directions go through the flow [`LANES`] at a time on one [`Taylor3`], which computes
/// the real part (and every sine, cosine and reciprocal of the model) once for all of them:
/// where a triple-nested dual (`Dual<Dual<Dual64>>`, one flow per entry) carries eight numbers
/// and multiplies with 27 products, a lane carries three derivatives and 11 products. The
/// entries are combinations of a few directions, so their rounding is that of the largest
/// term combined (relative 1e-15 of it), not the nested duals' bits.
fn flow_third_contracted(at: At, s: &mut MomentExpansion) {
    let At { base, k, x, u } = at;
    let (n, m) = (base.nx(), base.nu());
    let nv = n + m;
    let mut dirs = [Direction::default(); MAX_DIRECTIONS];
    let count = directions(n, nv, &mut dirs);
    let mut d3 = [[0.0; MAX_NX]; MAX_DIRECTIONS];
    let (mut xt, mut ut) = lift::<Taylor3<LANES>>(x, u);
    let mut out = [Taylor3::<LANES>::constant(0.0); MAX_NX];
    for first in (0..count).step_by(LANES) {
        let chunk = &dirs[first..count.min(first + LANES)];
        for (l, d) in chunk.iter().enumerate() {
            for j in 0..d.len {
                lane(&mut xt, &mut ut, n, d.index[j])[l] = d.weight[j];
            }
        }
        base.flow(k, &xt[..n], &ut[..m], &mut out[..n]);
        for (l, d) in chunk.iter().enumerate() {
            for j in 0..d.len {
                lane(&mut xt, &mut ut, n, d.index[j])[l] = 0.0;
            }
            for (r, o) in out[..n].iter().enumerate() {
                d3[first + l][r] = o.v3[l];
            }
        }
    }
    // Back from the directions to the entries, in the order `directions` lists them.
    zero(&mut s.h3);
    let mut next = d3.iter();
    // cube[a] = ∂_aaa; pair[a][b] = ∂_aab (a ≠ b), each a row per state.
    let mut cube = [[0.0; MAX_NX]; MAX_NV];
    let mut pair = [[[0.0; MAX_NX]; MAX_NV]; MAX_NV];
    for a in 0..nv {
        cube[a] = *next.next().expect("one direction per cube");
        if a < n {
            contract_triple(s, n, [a, a, a], &cube[a][..n]);
        }
    }
    for a in 0..nv {
        for b in a + 1..nv {
            let plus = next.next().expect("e_a + e_b");
            let minus = next.next().expect("e_a - e_b");
            for r in 0..n {
                pair[a][b][r] = (plus[r] - minus[r] - 2.0 * cube[b][r]) / 6.0;
                pair[b][a][r] = (plus[r] + minus[r] - 2.0 * cube[a][r]) / 6.0;
            }
            // The states come first in v: a multiset has a state index iff its smallest does.
            if a < n {
                contract_triple(s, n, [a, a, b], &pair[a][b][..n]);
                contract_triple(s, n, [a, b, b], &pair[b][a][..n]);
            }
        }
    }
    let mut d = [0.0; MAX_NX];
    for a in 0..n.min(nv) {
        for b in a + 1..nv {
            for c in b + 1..nv {
                let sum = next.next().expect("e_a + e_b + e_c");
                for r in 0..n {
                    let known = cube[a][r]
                        + cube[b][r]
                        + cube[c][r]
                        + 3.0
                            * (pair[a][b][r]
                                + pair[b][a][r]
                                + pair[a][c][r]
                                + pair[c][a][r]
                                + pair[b][c][r]
                                + pair[c][b][r]);
                    d[r] = (sum[r] - known) / 6.0;
                }
                contract_triple(s, n, [a, b, c], &d[..n]);
            }
        }
    }
}

/// Directions a [`Taylor3`] carries through one flow: enough to fill SIMD registers several
/// times over, few enough that the lanes of a partly filled last flow cost little.
const LANES: usize = 8;

/// The most directions [`directions`] lists: `nv + nv (nv − 1) + C(nv, 3)` at `nv = 12`.
const MAX_DIRECTIONS: usize =
    MAX_NV + MAX_NV * (MAX_NV - 1) + MAX_NV * (MAX_NV - 1) * (MAX_NV - 2) / 6;

/// A direction `w = Σ_j weight_j e_{index_j}` over `v = (x, u)` with at most three terms.
#[derive(Clone, Copy, Default)]
struct Direction {
    index: [usize; 3],
    weight: [f64; 3],
    len: usize,
}

/// Lists into `out` the directions [`flow_third_contracted`] needs, in the order it reads them
/// back: `e_a` for every `a`; `e_a + e_b`, `e_a − e_b` for every `a < b`; `e_a + e_b + e_c` for
/// every `a < b < c` with `a` a state. Returns how many.
fn directions(n: usize, nv: usize, out: &mut [Direction; MAX_DIRECTIONS]) -> usize {
    let mut count = 0;
    let mut push = |index: [usize; 3], weight: [f64; 3], len: usize| {
        out[count] = Direction { index, weight, len };
        count += 1;
    };
    for a in 0..nv {
        push([a, 0, 0], [1.0, 0.0, 0.0], 1);
    }
    for a in 0..nv {
        for b in a + 1..nv {
            push([a, b, 0], [1.0, 1.0, 0.0], 2);
            push([a, b, 0], [1.0, -1.0, 0.0], 2);
        }
    }
    for a in 0..n.min(nv) {
        for b in a + 1..nv {
            for c in b + 1..nv {
                push([a, b, c], [1.0, 1.0, 1.0], 3);
            }
        }
    }
    count
}

/// The first-derivative lanes of entry `j` of `v = (x, u)`.
fn lane<'a>(
    x: &'a mut [Taylor3<LANES>],
    u: &'a mut [Taylor3<LANES>],
    n: usize,
    j: usize,
) -> &'a mut [f64; LANES] {
    if j < n {
        &mut x[j].v1
    } else {
        &mut u[j - n].v1
    }
}

/// The same contraction as [`flow_third_contracted`] by triple-nested dual numbers (seeds: `x_c`
/// outermost, `v_a`, `v_b`), one flow per distinct triple: the independent reference its tests
/// compare against.
#[cfg(test)]
fn flow_third_contracted_nested(at: At, s: &mut MomentExpansion) {
    let At { base, k, x, u } = at;
    let (n, m) = (base.nx(), base.nu());
    let nv = n + m;
    let (mut x3, mut u3) = lift::<Dual<Dual<Dual64>>>(x, u);
    let mut out = [Dual::from_re(Dual::from_re(Dual64::from(0.0))); MAX_NX];
    zero(&mut s.h3);
    let mut d = [0.0; MAX_NX];
    for a in 0..nv {
        for b in a..nv {
            for c in 0..n.min(a + 1) {
                seed3(&mut x3, &mut u3, n, [c, a, b], 1.0);
                base.flow(k, &x3[..n], &u3[..m], &mut out[..n]);
                seed3(&mut x3, &mut u3, n, [c, a, b], 0.0);
                for (dr, o) in d.iter_mut().zip(&out[..n]) {
                    *dr = o.eps.eps.eps;
                }
                contract_triple(s, n, [c, a, b], &d[..n]);
            }
        }
    }
}

#[cfg(test)]
/// Seeds (or clears) the three levels of a triple-nested dual: `x_c` outermost, then `v_a`, `v_b`.
fn seed3(
    x: &mut [Dual<Dual<Dual64>>],
    u: &mut [Dual<Dual<Dual64>>],
    n: usize,
    [c, a, b]: [usize; 3],
    value: f64,
) {
    x[c].eps = Dual::from_re(Dual64::from(value));
    if a < n {
        x[a].re.eps = Dual64::from(value);
    } else {
        u[a - n].re.eps = Dual64::from(value);
    }
    if b < n {
        x[b].re.re.eps = value;
    } else {
        u[b - n].re.re.eps = value;
    }
}

/// Adds `2 Σ_r T_{r c'} d_r` to `h3[a', b']` for every distinct ordering `(c', a', b')` of the
/// triple whose `c'` is a state index (`d_r = ∂³Φ_r` along the triple, `T = s.t2`).
fn contract_triple(s: &mut MomentExpansion, n: usize, [c, a, b]: [usize; 3], d: &[f64]) {
    let orders = [
        [c, a, b],
        [c, b, a],
        [a, c, b],
        [a, b, c],
        [b, c, a],
        [b, a, c],
    ];
    for (i, o) in orders.iter().enumerate() {
        if o[0] >= n || orders[..i].contains(o) {
            continue;
        }
        let w: f64 = d
            .iter()
            .enumerate()
            .map(|(r, dr)| s.t2[(r, o[0])] * dr)
            .sum();
        s.h3[(o[1], o[2])] += 2.0 * w;
    }
}

/// `∂²Φ/∂u_a∂u_b` into `s.phi_uu` by nested duals, each unordered pair once.
fn flow_control_hessian(at: At, s: &mut MomentExpansion) {
    let At { base, k, x, u } = at;
    let (n, m) = (base.nx(), base.nu());
    let (x2, mut u2) = lift::<Dual<Dual64>>(x, u);
    let mut out = [Dual::from_re(Dual64::from(0.0)); MAX_NX];
    for a in 0..m {
        for b in a..m {
            u2[a].re.eps = 1.0;
            u2[b].eps.re = 1.0;
            base.flow(k, &x2[..n], &u2[..m], &mut out[..n]);
            u2[a].re.eps = 0.0;
            u2[b].eps.re = 0.0;
            for r in 0..n {
                s.phi_uu[a][b][r] = out[r].eps.eps;
                s.phi_uu[b][a][r] = out[r].eps.eps;
            }
        }
    }
}

/// The second derivatives of the noise gain `c_i` and of its state Jacobian `Cx_i` over
/// `v = (m, u)` (a gain nonlinear in the state: torque noise through `M⁻¹(q)`), by nested duals,
/// each unordered pair once.
fn noise_gain_second_order(at: At, s: &mut MomentExpansion) {
    let At { base, x, u, .. } = at;
    let (n, m, nw) = (base.nx(), base.nu(), base.nw());
    let nv = n + m;
    let (mut x2, mut u2) = lift::<Dual<Dual64>>(x, u);
    let zero = Dual::from_re(Dual64::from(0.0));
    let mut g = [zero; MAX_NX * MAX_NW];
    let mut dgx = [zero; MAX_NX * MAX_NX * MAX_NW];
    let mut dgu = [zero; MAX_NU * MAX_NX * MAX_NW];
    let block = n * nw;
    for a in 0..nv {
        for b in a..nv {
            seed_inner(&mut x2, &mut u2, n, a, 1.0);
            seed_outer(&mut x2, &mut u2, n, b, 1.0);
            base.noise_jacobian(&x2[..n], &u2[..m], &mut g, &mut dgx, &mut dgu);
            seed_inner(&mut x2, &mut u2, n, a, 0.0);
            seed_outer(&mut x2, &mut u2, n, b, 0.0);
            for pair in [a * nv + b, b * nv + a] {
                for i in 0..nw {
                    for r in 0..n {
                        s.d2c[pair][(r, i)] = g[i * n + r].eps.eps;
                        for j in 0..n {
                            s.d2cx[pair][i][(r, j)] = dgx[j * block + i * n + r].eps.eps;
                        }
                    }
                }
            }
        }
    }
}

/// Sets the outer derivative seed of entry `j` of `v = (x, u)` of nested duals.
fn seed_outer(x: &mut [Dual<Dual64>], u: &mut [Dual<Dual64>], n: usize, j: usize, value: f64) {
    if j < n {
        x[j].eps.re = value;
    } else {
        u[j - n].eps.re = value;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::dynamics::Integrator;
    use crate::core::model::plant::tests::{arm, joint};
    use crate::core::model::{Actuator, ArmModel, Damping, Exogenous, Field, Noise};

    fn discretised(plant: Plant, actuator: Actuator, field: Field) -> DiscreteDynamics {
        let exo = Exogenous {
            q_d: [0.4, 1.2],
            qd_d: [0.3, -0.2],
            tau_ext: [0.1, -0.05],
        };
        // The first joint's velocity drives the noise (the paper's σ q1' I).
        let component = plant.dof();
        DiscreteDynamics {
            model: ArmModel {
                plant,
                actuator,
                field,
                noise: Noise::StateProportional {
                    sigma: 0.3,
                    component,
                },
            },
            dt: 0.01,
            substeps: 10,
            integrator: Integrator::SemiImplicit,
            exogenous: vec![exo; 3],
        }
    }

    /// The contracted third derivatives from univariate Taylor polynomials agree with the
    /// triple-nested duals (one flow per entry, every entry its own derivative arithmetic) on
    /// the three actuators of the two-link arm in the divergent field and on the single joint,
    /// to the rounding of the combinations (relative 1e-9 of the largest entry).
    #[test]
    fn taylor_third_derivatives_match_nested_duals() {
        let impedance = Actuator::Impedance {
            damping: Damping::Proportional { alpha: 0.1 },
        };
        let vsa = Actuator::Vsa {
            motor_inertia: vec![0.05, 0.05],
        };
        let divergent = Field::Divergent { beta: 200.0 };
        let cases = [
            ("two-link torque", arm(), Actuator::Torque, divergent),
            ("two-link impedance", arm(), impedance.clone(), divergent),
            ("two-link VSA", arm(), vsa, divergent),
            ("single-joint impedance", joint(), impedance, Field::None),
        ];
        for (what, plant, actuator, field) in cases {
            let base = discretised(plant, actuator, field);
            let (n, m) = (base.nx(), base.nu());
            let moments = MomentDynamics::new(&base);
            // A state and control away from any symmetry; stiffness positive.
            let x: Vec<f64> = (0..n).map(|i| 0.3 + 0.17 * i as f64).collect();
            let u: Vec<f64> = (0..m).map(|i| 2.0 + 3.0 * i as f64).collect();
            let nz = n + n * (n + 1) / 2;
            let mut z = vec![0.0; nz];
            z[..n].copy_from_slice(&x);
            // Covariance: a diagonal-dominant vech; costate: arbitrary signs.
            let mut e = n;
            for a in 0..n {
                for b in a..n {
                    z[e] = if a == b {
                        1e-2
                    } else {
                        1e-3 * (a + 2 * b) as f64
                    };
                    e += 1;
                }
            }
            let lam: Vec<f64> = (0..nz).map(|i| ((i * 7 % 5) as f64 - 2.0) * 1e3).collect();
            let mut s = MomentExpansion::for_dynamics(&moments);
            moments.expand(1, &z, &u, &mut s);
            moments.second_order(1, &z, &u, &lam, true, &mut s);
            let taylor = s.h3.clone();
            flow_third_contracted_nested(At::new(&base, 1, &z, &u), &mut s);
            let nested = s.h3.clone();
            let scale = nested.abs().max();
            assert!(
                scale > 0.0,
                "{what}: no third derivatives: the test is vacuous"
            );
            let diff = (&taylor - &nested).abs().max();
            eprintln!("{what}: largest difference {diff:e}, entries up to {scale:e}");
            assert!(
                diff <= 1e-9 * scale,
                "{what}: largest difference {diff:e} against entries up to {scale:e}"
            );
        }
    }
}
