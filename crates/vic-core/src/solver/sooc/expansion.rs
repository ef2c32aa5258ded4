//! The derivatives of the moment step at one knot and their contraction with the costate of the
//! next knot: the curvature term that turns the Gauss–Newton model into Newton's.

use super::directional::third_order_direction_count;
use super::{MomentDynamics, costate_matrix, vech_len};
use crate::dense::{multiply, zero};
use crate::dynamics::{DiscreteDynamics, Dynamics, Linearization, NoiseKind};
use crate::model::Noise;
use crate::scalar::{MAX_NU, MAX_NX};
use nalgebra::DMatrix;

/// Everything the moment step's derivatives are built from at one knot, kept so that the
/// stagewise Newton solver can contract the second derivatives of `z⁺ = F(z, u)` with the costate
/// of the next knot without evaluating the flow again ([`MomentExpansion::curvature`]).
///
/// Notation: `v = (m, u)` stacks the mean and the controls (`n + m` entries); `A = ∂Φ/∂x`,
/// `dA_j = ∂A/∂v_j`, `c_i` the noise columns, `Cx_i = ∂c_i/∂x`.
#[derive(Debug, Clone)]
pub struct MomentExpansion {
    pub(super) n: usize,
    pub(super) m: usize,
    pub(super) nw: usize,
    /// `∂z⁺/∂z` (nz×nz).
    pub a: DMatrix<f64>,
    /// `∂z⁺/∂u` (nz×m).
    pub b: DMatrix<f64>,
    /// The plant's linearisation at (m, u): `A`, `B`, `c_i`, `Cx_i`.
    pub(super) base: Linearization,
    /// `P` at the knot.
    pub(super) p: DMatrix<f64>,
    /// `dA_j = ∂A/∂v_j` (n×n each, `n + m` of them): the second derivatives of the flow.
    pub(super) da: Vec<DMatrix<f64>>,
    /// `∂²Φ/∂u_a ∂u_b` (the pairs of `da` cover every pair with a state index), `[a][b][r]`.
    pub(super) phi_uu: [[[f64; MAX_NX]; MAX_NU]; MAX_NU],
    /// The third derivatives of the flow contracted with the costate:
    /// `2 Σ_{r,c} (Λ A P)_{rc} ∂³Φ_r/∂x_c∂v_a∂v_b` (nv×nv), from
    /// [`MomentDynamics::second_order`].
    pub(super) h3: DMatrix<f64>,
    /// The costate `h3` was contracted with (checked by [`MomentExpansion::curvature`]).
    pub(super) h3_costate: Vec<f64>,
    /// The flow's third derivatives along the directions `h3` is recovered from (one row per
    /// direction), valid at the expansion's point when `d3_ready`: computed by
    /// [`MomentDynamics::expand_with_third`] or by the first contraction, reused by the next.
    pub(super) d3: Vec<[f64; MAX_NX]>,
    pub(super) d3_ready: bool,
    /// Where `d3` was taken, bit for bit ([`FlowPoint`]): what lets a re-solve over the
    /// remaining movement reuse it ([`MomentDynamics::expand_reusing_third`]).
    pub(super) d3_at: FlowPoint,
    /// Where the flow's first and second derivatives (`base`, `da`, `phi_uu`) were taken.
    pub(super) flow_at: FlowPoint,
    /// Whether the noise gain is nonlinear in the state (torque noise through `M⁻¹(q)`): then
    /// `d2c`, `d2cx` hold its second and third derivatives.
    pub(super) curved_model: bool,
    /// `∂²c_i/∂v_a∂v_b` (n×p each, index `a (n + m) + b`).
    pub(super) d2c: Vec<DMatrix<f64>>,
    /// `∂²Cx_i/∂v_a∂v_b`, `[a (n + m) + b][i]` (n×n each).
    pub(super) d2cx: Vec<Vec<DMatrix<f64>>>,
    /// `∂c_i/∂v_j` (n×p each).
    pub(super) dc: Vec<DMatrix<f64>>,
    /// `∂Cx_i/∂v_j`, `[j][i]` (n×n each); zero unless the noise gain is nonlinear in the state.
    pub(super) dcx: Vec<Vec<DMatrix<f64>>>,
    /// Whether the noise gain's state Jacobian varies with `v` (some `dcx` nonzero).
    pub(super) curved_noise: bool,
    // Scratch of `curvature` and `expand`.
    pub(super) lam: DMatrix<f64>,
    pub(super) atl: DMatrix<f64>,
    pub(super) t1: DMatrix<f64>,
    pub(super) t2: DMatrix<f64>,
    pub(super) t3: DMatrix<f64>,
    pub(super) next: DMatrix<f64>,
    y: Vec<DMatrix<f64>>,
    /// `Λ dc_j` (n×p each), scratch of `noise_bilinear`.
    lam_dc: Vec<DMatrix<f64>>,
    hvv: DMatrix<f64>,
    hpv: DMatrix<f64>,
}

/// The inputs of one knot's flow, bit for bit: the mean state, the controls, the exogenous
/// input of the knot (reference and external torque), the time step and the sub-steps. Equal
/// points give equal directional derivatives, to the bit, for the same plant model.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) struct FlowPoint([u64; FLOW_POINT_LEN]);

/// Entries of a [`FlowPoint`]: state, controls, the six exogenous values, `dt`, sub-steps.
const FLOW_POINT_LEN: usize = MAX_NX + MAX_NU + 8;

impl FlowPoint {
    /// No point (NaN bits, which no flow is taken at).
    pub(super) const NONE: FlowPoint = FlowPoint([u64::MAX; FLOW_POINT_LEN]);

    /// The point `(x, u)` of knot `k` of `base`.
    pub(super) fn of(base: &DiscreteDynamics, k: usize, x: &[f64], u: &[f64]) -> Self {
        let mut bits = [0u64; FLOW_POINT_LEN];
        let ex = base.exo(k);
        let exogenous = ex.q_d.iter().chain(&ex.qd_d).chain(&ex.tau_ext);
        let values = x[..base.nx()]
            .iter()
            .chain(&u[..base.nu()])
            .chain(exogenous);
        for (b, v) in bits.iter_mut().zip(values) {
            *b = v.to_bits();
        }
        // Past the state and controls the slots of absent entries stay 0 in both points, so
        // the tail can hold dt and the sub-steps (with the integrator in the top bits) at fixed
        // places.
        bits[FLOW_POINT_LEN - 2] = base.dt.to_bits();
        bits[FLOW_POINT_LEN - 1] = base.substeps as u64 | (base.integrator as u64) << 48;
        FlowPoint(bits)
    }
}

impl MomentExpansion {
    /// Drops third derivatives kept from an earlier point: the next
    /// [`MomentDynamics::second_order`](super::MomentDynamics::second_order) takes them anew.
    pub fn forget_third(&mut self) {
        self.d3_ready = false;
    }

    /// An expansion for a plant of `n` states, `m` controls and `p` noise channels whose noise
    /// gain is linear in the state (the second derivatives of the noise gain are not stored).
    pub fn new(n: usize, m: usize, p: usize) -> Self {
        Self::with_noise_curvature(n, m, p, false)
    }

    /// An expansion sized for `dynamics`.
    pub fn for_dynamics(dynamics: &MomentDynamics) -> Self {
        let base = dynamics.base();
        let curved = !matches!(
            base.model.noise,
            Noise::None | Noise::StateProportional { .. }
        );
        Self::with_noise_curvature(base.nx(), base.nu(), base.nw(), curved)
    }

    fn with_noise_curvature(n: usize, m: usize, p: usize, curved: bool) -> Self {
        let z = |r, c| DMatrix::zeros(r, c);
        let nz = n + vech_len(n);
        let nv = n + m;
        let pairs = if curved { nv * nv } else { 0 };
        MomentExpansion {
            h3: z(nv, nv),
            h3_costate: vec![0.0; nz],
            d3: vec![[0.0; MAX_NX]; third_order_direction_count(n, nv)],
            d3_ready: false,
            d3_at: FlowPoint::NONE,
            flow_at: FlowPoint::NONE,
            curved_model: curved,
            d2c: (0..pairs).map(|_| z(n, p)).collect(),
            d2cx: (0..pairs)
                .map(|_| (0..p).map(|_| z(n, n)).collect())
                .collect(),
            n,
            m,
            nw: p,
            a: z(nz, nz),
            b: z(nz, m),
            base: Linearization::new(n, m, p),
            p: z(n, n),
            da: (0..nv).map(|_| z(n, n)).collect(),
            phi_uu: [[[0.0; MAX_NX]; MAX_NU]; MAX_NU],
            dc: (0..nv).map(|_| z(n, p)).collect(),
            dcx: (0..nv).map(|_| (0..p).map(|_| z(n, n)).collect()).collect(),
            curved_noise: false,
            lam: z(n, n),
            atl: z(n, n),
            t1: z(n, n),
            t2: z(n, n),
            t3: z(n, n),
            next: z(n, n),
            y: (0..nv).map(|_| z(n, n)).collect(),
            lam_dc: (0..nv).map(|_| z(n, p)).collect(),
            hvv: z(nv, nv),
            hpv: z(vech_len(n), nv),
        }
    }

    /// The costate-weighted second derivatives of the moment step,
    /// `H = Σ_e λ⁺_e ∂²z⁺_e / ∂(z, u)²`, the term that turns the Gauss–Newton model of the
    /// moment dynamics into Newton's (Pantoja's stagewise Newton; `λ⁺` is the costate of the
    /// next knot). Written into `hzz` (nz×nz), `huz` (m×nz) and `huu` (m×m). Needs
    /// [`MomentDynamics::second_order`] with the same `λ⁺` first.
    ///
    /// With `Λ` the symmetric matrix of the covariance part of `λ⁺` (`tr(Λ δP) = λ⁺_P · δvech P`):
    ///
    /// * mean: `Σ_r λ⁺_m[r] ∂²Φ_r/∂v_a ∂v_b`;
    /// * covariance, `v`–`v`: `2 tr(Λ dA_a P dA_bᵀ) + Σ_i 2 dc_{i,a}ᵀ Λ dc_{i,b} +
    ///   2 tr(Λ dCx_{i,a} P dCx_{i,b}ᵀ)` — the bilinear part of `A P Aᵀ` that makes stiffness
    ///   worth buying, and that a Gauss–Newton model drops;
    ///   and the third derivatives of the flow, `2 tr(Λ ∂²A/∂v_a∂v_b P Aᵀ)`, of the same size
    ///   (leaving them out stalls Newton near the optimum);
    /// * noise gain nonlinear in the state: `2 c_iᵀ Λ ∂²c_i + 2 tr(Λ ∂²Cx_i P Cx_iᵀ)`;
    /// * covariance, `P`–`v`: `tr((T_a + T_aᵀ) E_e)` with `T_a = Aᵀ Λ dA_a + Σ_i Cx_iᵀ Λ dCx_{i,a}`
    ///   (`P⁺` is linear in `P`, so `P`–`P` is zero).
    pub fn curvature(
        &mut self,
        lam_next: &[f64],
        hzz: &mut DMatrix<f64>,
        huz: &mut DMatrix<f64>,
        huu: &mut DMatrix<f64>,
    ) {
        debug_assert_eq!(
            lam_next,
            &self.h3_costate[..],
            "second_order was contracted with another costate"
        );
        let n = self.n;
        costate_matrix(n, &lam_next[n..], &mut self.lam);
        self.mean_curvature(&lam_next[..n]);
        self.covariance_bilinear();
        // Covariance, third derivatives of the flow: 2 tr(Λ ∂²A/∂v_a∂v_b P Aᵀ), contracted
        // when they were computed.
        self.hvv += &self.h3;
        if self.base.noise != NoiseKind::None {
            if self.curved_model {
                self.noise_gain_curvature();
            }
            self.noise_bilinear();
        }
        self.covariance_mean_cross();
        self.scatter(hzz, huz, huu);
    }

    /// `hvv = Σ_r λ_m[r] ∂²Φ_r/∂v_a∂v_b`.
    fn mean_curvature(&mut self, lm: &[f64]) {
        let (n, nv) = (self.n, self.n + self.m);
        for a in 0..nv {
            for b in 0..nv {
                let mut s = 0.0;
                for (r, l) in lm.iter().enumerate() {
                    let d2 = if b < n {
                        self.da[a][(r, b)]
                    } else if a < n {
                        self.da[b][(r, a)]
                    } else {
                        self.phi_uu[a - n][b - n][r]
                    };
                    s += l * d2;
                }
                self.hvv[(a, b)] = s;
            }
        }
    }

    /// `hvv += 2 tr(Λ dA_a P dA_bᵀ) = 2 Σ (Λ dA_a P) ∘ dA_b`.
    fn covariance_bilinear(&mut self) {
        let nv = self.n + self.m;
        for a in 0..nv {
            multiply(&mut self.t1, &self.lam, &self.da[a], false);
            multiply(&mut self.y[a], &self.t1, &self.p, false);
        }
        for a in 0..nv {
            for b in a..nv {
                let s = 2.0 * self.y[a].dot(&self.da[b]);
                self.add_symmetric(a, b, s);
            }
        }
    }

    /// `hvv[a, b] += s` and, off the diagonal, `hvv[b, a] += s`.
    fn add_symmetric(&mut self, a: usize, b: usize, s: f64) {
        self.hvv[(a, b)] += s;
        if b != a {
            self.hvv[(b, a)] += s;
        }
    }

    /// Noise gain nonlinear in the state:
    /// `hvv += 2 c_iᵀ Λ ∂²c_i + 2 tr(Λ ∂²Cx_i P Cx_iᵀ) = 2 Σ ∂²Cx_i ∘ (Λ Cx_i P) + …`.
    fn noise_gain_curvature(&mut self) {
        let (n, nw, nv) = (self.n, self.nw, self.n + self.m);
        for i in 0..nw {
            multiply(&mut self.t1, &self.lam, &self.base.cx[i], false);
            multiply(&mut self.t2, &self.t1, &self.p, false);
            for r in 0..n {
                let mut s = 0.0;
                for c in 0..n {
                    s += self.lam[(r, c)] * self.base.c[(c, i)];
                }
                self.t3[(r, 0)] = s;
            }
            for a in 0..nv {
                for b in 0..nv {
                    let ab = a * nv + b;
                    let mut s = self.d2cx[ab][i].dot(&self.t2);
                    for r in 0..n {
                        s += self.t3[(r, 0)] * self.d2c[ab][(r, i)];
                    }
                    self.hvv[(a, b)] += 2.0 * s;
                }
            }
        }
    }

    /// `hvv += 2 Σ_i dc_{i,a}ᵀ Λ dc_{i,b}` and, for a curved noise gain,
    /// `2 tr(Λ dCx_{i,a} P dCx_{i,b}ᵀ)`.
    fn noise_bilinear(&mut self) {
        let (n, nw, nv) = (self.n, self.nw, self.n + self.m);
        // `Λ dc_b` once per b, not once per pair (the same sums in the same order).
        // A zero column of `dc_b` gives +0 here where the sums gave ±0, which the sums below
        // (starting at +0) add without a change.
        for b in 0..nv {
            for i in 0..nw {
                if (0..n).all(|c| self.dc[b][(c, i)] == 0.0) {
                    self.lam_dc[b].column_mut(i).fill(0.0);
                    continue;
                }
                for r in 0..n {
                    let mut t = 0.0;
                    for c in 0..n {
                        t += self.lam[(r, c)] * self.dc[b][(c, i)];
                    }
                    self.lam_dc[b][(r, i)] = t;
                }
            }
        }
        for a in 0..nv {
            for b in a..nv {
                let mut s = 0.0;
                for i in 0..nw {
                    for r in 0..n {
                        s += self.dc[a][(r, i)] * self.lam_dc[b][(r, i)];
                    }
                }
                self.add_symmetric(a, b, 2.0 * s);
            }
        }
        if !self.curved_noise {
            return;
        }
        for i in 0..nw {
            for a in 0..nv {
                multiply(&mut self.t1, &self.lam, &self.dcx[a][i], false);
                multiply(&mut self.y[a], &self.t1, &self.p, false);
            }
            for a in 0..nv {
                for b in a..nv {
                    let s = 2.0 * self.y[a].dot(&self.dcx[b][i]);
                    self.add_symmetric(a, b, s);
                }
            }
        }
    }

    /// `P`–`v`: `hpv[e, a] = tr((T_a + T_aᵀ) E_e)`, `T_a = Aᵀ Λ dA_a + Σ_i Cx_iᵀ Λ dCx_{i,a}`.
    fn covariance_mean_cross(&mut self) {
        let (n, nw, nv) = (self.n, self.nw, self.n + self.m);
        self.atl.gemm_tr(1.0, &self.base.a, &self.lam, 0.0);
        for a in 0..nv {
            multiply(&mut self.t1, &self.atl, &self.da[a], false);
            if self.curved_noise {
                for i in 0..nw {
                    self.t2.gemm_tr(1.0, &self.base.cx[i], &self.lam, 0.0);
                    multiply(&mut self.t1, &self.t2, &self.dcx[a][i], true);
                }
            }
            let mut e = 0;
            for r in 0..n {
                for c in r..n {
                    self.hpv[(e, a)] = if r == c {
                        2.0 * self.t1[(r, r)]
                    } else {
                        2.0 * (self.t1[(r, c)] + self.t1[(c, r)])
                    };
                    e += 1;
                }
            }
        }
    }

    /// Scatters `hvv` and `hpv` into the `(z, u)` blocks; `z = (m, vech P)`.
    fn scatter(&self, hzz: &mut DMatrix<f64>, huz: &mut DMatrix<f64>, huu: &mut DMatrix<f64>) {
        let (n, m) = (self.n, self.m);
        let np = vech_len(n);
        zero(hzz);
        zero(huz);
        for i in 0..n {
            for j in 0..n {
                hzz[(i, j)] = self.hvv[(i, j)];
            }
            for e in 0..np {
                hzz[(n + e, i)] = self.hpv[(e, i)];
                hzz[(i, n + e)] = self.hpv[(e, i)];
            }
        }
        for a in 0..m {
            for j in 0..n {
                huz[(a, j)] = self.hvv[(n + a, j)];
            }
            for e in 0..np {
                huz[(a, n + e)] = self.hpv[(e, n + a)];
            }
            for b in 0..m {
                huu[(a, b)] = self.hvv[(n + a, n + b)];
            }
        }
    }
}
