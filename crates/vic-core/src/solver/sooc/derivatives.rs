//! The derivatives of the moment step `z⁺ = F(z, u)` by forward-mode automatic differentiation
//! through the discretised flow: first derivatives (`expand`, every iteration) and the
//! costate-contracted second derivatives that the Newton model adds (`second_order`).

use super::directional::{flow_second_and_third, flow_second_derivatives, flow_third_contracted};
use super::expansion::FlowPoint;
use super::{MomentDynamics, MomentExpansion, costate_matrix, lift, unpack};
use crate::dense::{multiply, zero};
use crate::dynamics::{DiscreteDynamics, Dynamics, NoiseKind};
use crate::scalar::{MAX_NU, MAX_NW, MAX_NX};
use nalgebra::DMatrix;
use num_dual::{Dual, Dual64};

impl MomentDynamics<'_> {
    /// The first derivatives of the moment step at knot `k` into `e.a`, `e.b`, and what
    /// [`MomentExpansion::curvature`] needs of them besides (`dA_j`, `dc_j`, `dCx_j`).
    ///
    /// `∂P⁺/∂(m, u)` needs the second derivatives of the flow (`∂A/∂v_j`); they come from
    /// second-order directions with `∂²Φ/∂u_a∂u_b`, which the Newton model adds
    /// ([`flow_second_derivatives`]).
    pub fn expand(&self, k: usize, z: &[f64], u: &[f64], e: &mut MomentExpansion) {
        self.expand_at(k, z, u, false, e);
    }

    /// [`MomentDynamics::expand`], for a [`MomentDynamics::second_order`] with the third
    /// derivatives at the same point next: the flow's third derivatives are taken along their
    /// directions now, and the second derivatives come from the same flows
    /// ([`flow_second_and_third`]: bit for bit those of [`MomentDynamics::expand`], without its
    /// own second-order flows; a sixth of the Newton iteration's flows on the arm).
    pub fn expand_with_third(&self, k: usize, z: &[f64], u: &[f64], e: &mut MomentExpansion) {
        self.expand_at(k, z, u, true, e);
    }

    /// [`MomentDynamics::expand`] at a new point, keeping the flow's third derivatives that
    /// [`MomentDynamics::expand_with_third`] took at the previous one for the next
    /// [`MomentDynamics::second_order`] (see
    /// [`crate::solver::sooc_newton::SoocOptions::keep_third_derivatives`]): the second
    /// derivatives are those of the new point, by their own order-2 flows.
    pub fn expand_keeping_third(&self, k: usize, z: &[f64], u: &[f64], e: &mut MomentExpansion) {
        let kept = e.d3_ready;
        self.expand_at(k, z, u, false, e);
        e.d3_ready = kept;
    }

    /// [`MomentDynamics::expand`] (with `third`, [`MomentDynamics::expand_with_third`]) where
    /// `e` may hold the flow's third derivatives of the very same point from an earlier solve:
    /// a re-solve over the remaining movement
    /// ([`crate::solver::sooc_newton::SoocSolver::resolve_remaining`]) from the plan's own
    /// mean meets, at every knot, the point its previous solve ended at. Those are kept, and so
    /// are the flow's first and second derivatives if `e` took them there too (then only what
    /// the covariance at the knot changes is computed); whatever was taken elsewhere is taken
    /// anew, a point differing in any bit (the mean state, the controls, the knot's exogenous
    /// input, the time step). The same numbers to the bit either way. Whether the third
    /// derivatives were kept.
    pub fn expand_reusing_third(
        &self,
        k: usize,
        z: &[f64],
        u: &[f64],
        third: bool,
        e: &mut MomentExpansion,
    ) -> bool {
        let here = At::new(self.base(), k, z, u).point();
        let same_third = e.d3_ready && e.d3_at == here;
        if e.flow_at == here {
            // The flow's first and second derivatives are this point's as well: only what the
            // covariance at the knot changes is computed (`P` is not part of the point).
            self.expand_with(k, z, u, None, e);
            e.d3_ready = same_third;
        } else {
            self.expand_at(k, z, u, third && !same_third, e);
            e.d3_ready |= same_third;
        }
        same_third
    }

    /// The plant's step at knot `k` and its derivatives as n×n matrices only
    /// ([`MomentExpansion::flow_sensitivity`]: `A`, `B`, `c_i`, `Cx_i`, `P`, `dA_j`, `dc_j`,
    /// `dCx_j`), for a solver that keeps the covariance as a matrix: the `vech` Jacobians `e.a`,
    /// `e.b` of [`MomentDynamics::expand`] (the Kronecker blocks of `P⁺ = A P Aᵀ + W`) are left
    /// untouched.
    pub fn expand_matrices(&self, k: usize, z: &[f64], u: &[f64], e: &mut MomentExpansion) {
        let base = self.base();
        let (n, m) = (base.nx(), base.nu());
        let at = At::new(base, k, z, u);
        base.linearize(k, &z[..n], u, &mut e.base);
        unpack(n, &z[n..], &mut e.p);
        flow_second_derivatives(at, e);
        e.flow_at = at.point();
        e.curved_noise = false;
        if e.base.noise == NoiseKind::None {
            return;
        }
        let (mut xd, mut ud) = lift::<Dual64>(&z[..n], u);
        let d0 = Dual64::from(0.0);
        let mut g = [d0; MAX_NX * MAX_NW];
        let mut dgx = [d0; MAX_NX * MAX_NX * MAX_NW];
        let mut dgu = [d0; MAX_NU * MAX_NX * MAX_NW];
        for j in 0..n + m {
            let v = if j < n { &mut xd[j] } else { &mut ud[j - n] };
            v.eps = 1.0;
            base.noise_jacobian(&xd[..n], &ud[..m], &mut g, &mut dgx, &mut dgu);
            let v = if j < n { &mut xd[j] } else { &mut ud[j - n] };
            v.eps = 0.0;
            // `next` and `t1` are the scratch `noise_sensitivity` adds the vech rows' parts to.
            zero(&mut e.next);
            for i in 0..base.nw() {
                noise_sensitivity(e, j, i, &g, &dgx);
            }
        }
    }

    fn expand_at(&self, k: usize, z: &[f64], u: &[f64], third: bool, e: &mut MomentExpansion) {
        self.expand_with(k, z, u, Some(third), e);
    }

    /// The expansion at `(z, u)`; `flow`: the flow's derivatives are taken (with the third ones
    /// if `Some(true)`), or with `None` are those `e` holds, taken at this very point.
    fn expand_with(
        &self,
        k: usize,
        z: &[f64],
        u: &[f64],
        flow: Option<bool>,
        e: &mut MomentExpansion,
    ) {
        let base = self.base();
        let (n, m) = (base.nx(), base.nu());
        let at = At::new(base, k, z, u);
        if flow.is_some() {
            base.linearize(k, &z[..n], u, &mut e.base);
        }
        unpack(n, &z[n..], &mut e.p);
        zero(&mut e.a);
        zero(&mut e.b);
        e.a.view_mut((0, 0), (n, n)).copy_from(&e.base.a);
        e.b.view_mut((0, 0), (n, m)).copy_from(&e.base.b);
        covariance_transition(e);
        match flow {
            Some(true) => flow_second_and_third(at, e),
            Some(false) => flow_second_derivatives(at, e),
            None => {}
        }
        if flow.is_some() {
            e.flow_at = at.point();
        }
        covariance_sensitivity(at, e);
    }

    /// What the Newton model needs beyond [`MomentDynamics::expand`] (which must have run at the
    /// same `(z, u)`), contracted with the costate `lam_next` of the next knot:
    ///
    /// * the third derivatives of the flow, only as `h3 = 2 Σ_{r,c} (Λ A P)_{rc}
    ///   ∂³Φ_r/∂x_c∂v_a∂v_b` (the one place [`MomentExpansion::curvature`] uses them),
    ///   contracted as each distinct triple is evaluated: no `n (n + m)²` tensor is stored or
    ///   copied, and the backward pass's retries at higher μ reuse the `(n + m)²` contraction;
    /// * for a noise gain nonlinear in the state, its second and third derivatives.
    ///
    /// With `third` false the flow's third derivatives are left out (`h3 = 0`): the cheaper,
    /// inexact model of [`crate::solver::sooc_newton::SoocOptions::flow_third_derivatives`].
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
        multiply(&mut s.t1, &s.lam, &s.base.a, false);
        multiply(&mut s.t2, &s.t1, &s.p, false);
        let at = At::new(base, k, z, u);
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
pub(super) struct At<'a> {
    pub(super) base: &'a DiscreteDynamics,
    pub(super) k: usize,
    pub(super) x: &'a [f64],
    pub(super) u: &'a [f64],
}

impl<'a> At<'a> {
    /// The flow's inputs at this point, bit for bit.
    pub(super) fn point(&self) -> FlowPoint {
        FlowPoint::of(self.base, self.k, self.x, self.u)
    }

    pub(super) fn new(base: &'a DiscreteDynamics, k: usize, z: &'a [f64], u: &'a [f64]) -> Self {
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

/// Sets the inner derivative seed of entry `j` of `v = (x, u)` of nested duals.
pub(super) fn seed_inner(
    x: &mut [Dual<Dual64>],
    u: &mut [Dual<Dual64>],
    n: usize,
    j: usize,
    value: f64,
) {
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
    multiply(&mut s.t1, &s.base.a, &s.p, false);
    s.t1.transpose_to(&mut s.atl);
    let (mut xd, mut ud) = lift::<Dual64>(x, u);
    let zero = Dual64::from(0.0);
    let mut g = [zero; MAX_NX * MAX_NW];
    let mut dgx = [zero; MAX_NX * MAX_NX * MAX_NW];
    let mut dgu = [zero; MAX_NU * MAX_NX * MAX_NW];
    s.curved_noise = false;
    for j in 0..n + m {
        multiply(&mut s.t1, &s.da[j], &s.atl, false);
        crate::dense::zero(&mut s.next);
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
    let mut moved = false;
    for r in 0..n {
        s.dc[j][(r, i)] = g[i * n + r].eps;
        moved |= s.dc[j][(r, i)] != 0.0;
    }
    // A channel that `v_j` does not move adds only zeros to `next`, which starts at +0 and so
    // can never be −0: skipping it changes no bit (with state noise, every channel but one).
    if moved {
        for r in 0..n {
            for c in 0..n {
                s.next[(r, c)] +=
                    s.dc[j][(r, i)] * s.base.c[(c, i)] + s.base.c[(r, i)] * s.dc[j][(c, i)];
            }
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
        multiply(&mut s.t2, &s.base.cx[i], &s.p, false);
        s.t2.transpose_to(&mut s.t3);
        multiply(&mut s.t1, &s.dcx[j][i], &s.t3, true);
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
pub(super) fn seed_outer(
    x: &mut [Dual<Dual64>],
    u: &mut [Dual<Dual64>],
    n: usize,
    j: usize,
    value: f64,
) {
    if j < n {
        x[j].eps.re = value;
    } else {
        u[j - n].eps.re = value;
    }
}
