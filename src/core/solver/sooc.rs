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
//! from nested dual numbers through [`DiscreteDynamics::flow_jacobian`].

use crate::core::cost::{Cost, CostDerivatives, TrackingCost};
use crate::core::dynamics::{DiscreteDynamics, Dynamics, Linearization, NoiseKind};
use crate::core::model::Noise;
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
/// [`DiscreteDynamics`]'s `linearize` computes them, so the values are the same.
fn state_linearization(
    base: &DiscreteDynamics,
    k: usize,
    x: &[f64],
    u: &[f64],
    lin: &mut Linearization,
) {
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
        // Own expansion per call: knots are linearised in parallel.
        let mut e = MomentExpansion::new(self.base.nx(), self.base.nu(), self.base.nw());
        self.expand(k, z, u, false, &mut e);
        lin.noise = NoiseKind::None;
        lin.a.copy_from(&e.a);
        lin.b.copy_from(&e.b);
    }
}

/// Everything the moment step's derivatives are built from at one knot, kept so that the
/// stagewise Newton solver can contract the second derivatives of `z⁺ = F(z, u)` with the costate
/// of the next knot without evaluating the flow again ([`MomentExpansion::curvature`]).
///
/// Notation: `v = (m, u)` stacks the mean and the controls (`n + m` entries); `A = ∂Φ/∂x`,
/// `dA_j = ∂A/∂v_j`, `c_i` the noise columns, `Cx_i = ∂c_i/∂x`.
#[derive(Debug, Clone)]
pub struct MomentExpansion {
    n: usize,
    m: usize,
    nw: usize,
    /// `∂z⁺/∂z` (nz×nz).
    pub a: DMatrix<f64>,
    /// `∂z⁺/∂u` (nz×m).
    pub b: DMatrix<f64>,
    /// The plant's linearisation at (m, u): `A`, `B`, `c_i`, `Cx_i`.
    base: Linearization,
    /// `P` at the knot.
    p: DMatrix<f64>,
    /// `dA_j = ∂A/∂v_j` (n×n each, `n + m` of them): the second derivatives of the flow.
    da: Vec<DMatrix<f64>>,
    /// `∂²Φ/∂u_a ∂u_b` (the pairs of `da` cover every pair with a state index), `[a][b][r]`.
    phi_uu: [[[f64; MAX_NX]; MAX_NU]; MAX_NU],
    /// `∂²A/∂v_a∂v_b` (n×n each, index `a (n + m) + b`): the third derivatives of the flow.
    d2a: Vec<DMatrix<f64>>,
    /// Whether the noise gain is nonlinear in the state (torque noise through `M⁻¹(q)`): then
    /// `d2c`, `d2cx` hold its second and third derivatives.
    curved_model: bool,
    /// `∂²c_i/∂v_a∂v_b` (n×p each, index `a (n + m) + b`).
    d2c: Vec<DMatrix<f64>>,
    /// `∂²Cx_i/∂v_a∂v_b`, `[a (n + m) + b][i]` (n×n each).
    d2cx: Vec<Vec<DMatrix<f64>>>,
    /// `∂c_i/∂v_j` (n×p each).
    dc: Vec<DMatrix<f64>>,
    /// `∂Cx_i/∂v_j`, `[j][i]` (n×n each); zero unless the noise gain is nonlinear in the state.
    dcx: Vec<Vec<DMatrix<f64>>>,
    /// Whether the noise gain's state Jacobian varies with `v` (some `dcx` nonzero).
    curved_noise: bool,
    // Scratch of `curvature`.
    lam: DMatrix<f64>,
    atl: DMatrix<f64>,
    t1: DMatrix<f64>,
    t2: DMatrix<f64>,
    t3: DMatrix<f64>,
    next: DMatrix<f64>,
    y: Vec<DMatrix<f64>>,
    hvv: DMatrix<f64>,
    hpv: DMatrix<f64>,
}

impl MomentExpansion {
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
            d2a: (0..nv * nv).map(|_| z(n, n)).collect(),
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
            da: (0..n + m).map(|_| z(n, n)).collect(),
            phi_uu: [[[0.0; MAX_NX]; MAX_NU]; MAX_NU],
            dc: (0..n + m).map(|_| z(n, p)).collect(),
            dcx: (0..n + m)
                .map(|_| (0..p).map(|_| z(n, n)).collect())
                .collect(),
            curved_noise: false,
            lam: z(n, n),
            atl: z(n, n),
            t1: z(n, n),
            t2: z(n, n),
            t3: z(n, n),
            next: z(n, n),
            y: (0..n + m).map(|_| z(n, n)).collect(),
            hvv: z(n + m, n + m),
            hpv: z(vech_len(n), n + m),
        }
    }

    /// The costate-weighted second derivatives of the moment step,
    /// `H = Σ_e λ⁺_e ∂²z⁺_e / ∂(z, u)²`, the term that turns the Gauss–Newton model of the
    /// moment dynamics into Newton's (Pantoja's stagewise Newton; `λ⁺` is the costate of the
    /// next knot). Written into `hzz` (nz×nz), `huz` (m×nz) and `huu` (m×m).
    ///
    /// With `Λ` the symmetric matrix of the covariance part of `λ⁺` (`tr(Λ δP) = λ⁺_P · δvech P`):
    ///
    /// * mean: `Σ_r λ⁺_m[r] ∂²Φ_r/∂v_a ∂v_b`;
    /// * covariance, `v`–`v`: `2 tr(Λ dA_a P dA_bᵀ) + Σ_i 2 dc_{i,a}ᵀ Λ dc_{i,b} +
    ///   2 tr(Λ dCx_{i,a} P dCx_{i,b}ᵀ)` — the bilinear part of `A P Aᵀ` that makes stiffness
    ///   worth buying, and that a Gauss–Newton model drops;
    ///   and the third derivatives of the flow, `2 tr(Λ ∂²A/∂v_a∂v_b P Aᵀ)`, of the same size
    ///   (measured: leaving them out changes this block by half and stalls Newton);
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
        let (n, m, nw) = (self.n, self.m, self.nw);
        let nv = n + m;
        // Λ from the vech part of the costate: δJ = Σ_e λ_e δP_e = tr(Λ δP).
        let mut e = 0;
        for a in 0..n {
            for b in a..n {
                let v = lam_next[n + e];
                if a == b {
                    self.lam[(a, a)] = v;
                } else {
                    self.lam[(a, b)] = 0.5 * v;
                    self.lam[(b, a)] = 0.5 * v;
                }
                e += 1;
            }
        }
        let lm = &lam_next[..n];
        self.hvv.fill(0.0);
        // Mean: Σ_r λ_m[r] ∂²Φ_r/∂v_a∂v_b.
        for a in 0..nv {
            for b in 0..nv {
                let mut s = 0.0;
                for r in 0..n {
                    let d2 = if b < n {
                        self.da[a][(r, b)]
                    } else if a < n {
                        self.da[b][(r, a)]
                    } else {
                        self.phi_uu[a - n][b - n][r]
                    };
                    s += lm[r] * d2;
                }
                self.hvv[(a, b)] = s;
            }
        }
        // Covariance, bilinear: 2 tr(Λ dA_a P dA_bᵀ) = 2 Σ (Λ dA_a P) ∘ dA_b.
        for a in 0..nv {
            self.t1.gemm(1.0, &self.lam, &self.da[a], 0.0);
            self.y[a].gemm(1.0, &self.t1, &self.p, 0.0);
        }
        for a in 0..nv {
            for b in a..nv {
                let s = 2.0 * self.y[a].dot(&self.da[b]);
                self.hvv[(a, b)] += s;
                if b != a {
                    self.hvv[(b, a)] += s;
                }
            }
        }
        // Covariance, third derivatives of the flow: 2 tr(Λ ∂²A/∂v_a∂v_b P Aᵀ)
        // = 2 Σ (∂²A/∂v_a∂v_b) ∘ (Λ A P).
        self.t1.gemm(1.0, &self.lam, &self.base.a, 0.0);
        self.t2.gemm(1.0, &self.t1, &self.p, 0.0);
        for a in 0..nv {
            for b in 0..nv {
                self.hvv[(a, b)] += 2.0 * self.d2a[a * nv + b].dot(&self.t2);
            }
        }
        let noisy = self.base.noise != NoiseKind::None;
        if noisy && self.curved_model {
            // 2 c_iᵀ Λ ∂²c_i + 2 tr(Λ ∂²Cx_i P Cx_iᵀ) = 2 Σ ∂²Cx_i ∘ (Λ Cx_i P).
            for i in 0..nw {
                self.t1.gemm(1.0, &self.lam, &self.base.cx[i], 0.0);
                self.t2.gemm(1.0, &self.t1, &self.p, 0.0);
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
        if noisy {
            // 2 Σ_i dc_{i,a}ᵀ Λ dc_{i,b}
            for a in 0..nv {
                for b in a..nv {
                    let mut s = 0.0;
                    for i in 0..nw {
                        for r in 0..n {
                            let mut t = 0.0;
                            for c in 0..n {
                                t += self.lam[(r, c)] * self.dc[b][(c, i)];
                            }
                            s += self.dc[a][(r, i)] * t;
                        }
                    }
                    self.hvv[(a, b)] += 2.0 * s;
                    if b != a {
                        self.hvv[(b, a)] += 2.0 * s;
                    }
                }
            }
            if self.curved_noise {
                for i in 0..nw {
                    for a in 0..nv {
                        self.t1.gemm(1.0, &self.lam, &self.dcx[a][i], 0.0);
                        self.y[a].gemm(1.0, &self.t1, &self.p, 0.0);
                    }
                    for a in 0..nv {
                        for b in a..nv {
                            let s = 2.0 * self.y[a].dot(&self.dcx[b][i]);
                            self.hvv[(a, b)] += s;
                            if b != a {
                                self.hvv[(b, a)] += s;
                            }
                        }
                    }
                }
            }
        }
        // P–v: tr((T_a + T_aᵀ) E_e), T_a = Aᵀ Λ dA_a + Σ_i Cx_iᵀ Λ dCx_{i,a}.
        self.atl.gemm_tr(1.0, &self.base.a, &self.lam, 0.0);
        for a in 0..nv {
            self.t1.gemm(1.0, &self.atl, &self.da[a], 0.0);
            if self.curved_noise {
                for i in 0..nw {
                    self.t2.gemm_tr(1.0, &self.base.cx[i], &self.lam, 0.0);
                    self.t1.gemm(1.0, &self.t2, &self.dcx[a][i], 1.0);
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
        // Scatter into the (z, u) blocks; z = (m, vech P).
        let np = vech_len(n);
        hzz.fill(0.0);
        huz.fill(0.0);
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

impl MomentDynamics<'_> {
    /// `∂²A/∂v_a∂v_b`, i.e. `∂³Φ/∂x_c∂v_a∂v_b`, by triple-nested dual numbers (seeds: `x_c`
    /// outermost, `v_a`, `v_b`), each distinct triple once (the derivative is symmetric in its
    /// state indices and in `a, b`); and, for a noise gain nonlinear in the state, its second and
    /// third derivatives.
    ///
    /// Also `∂²Φ/∂u_a∂u_b` (the pairs that [`MomentDynamics::expand`]'s first derivatives do not
    /// cover). Everything [`MomentExpansion::curvature`] needs beyond `expand(.., false, ..)`:
    /// the expensive part (`O(n (n + m)²)` triple-dual flow evaluations), done only when the
    /// Newton model is used.
    pub fn second_order(&self, k: usize, z: &[f64], u: &[f64], s: &mut MomentExpansion) {
        type D3 = Dual<Dual<Dual64>>;
        let base = self.base;
        let (n, m, nw) = (base.nx(), base.nu(), base.nw());
        let nv = n + m;
        {
            type D2 = Dual<Dual64>;
            let lift2 = |v: f64| D2::from_re(Dual64::from(v));
            let mut x2 = [lift2(0.0); MAX_NX];
            let mut u2 = [lift2(0.0); MAX_NU];
            for (d, v) in x2.iter_mut().zip(&z[..n]) {
                *d = lift2(*v);
            }
            for (d, v) in u2.iter_mut().zip(u) {
                *d = lift2(*v);
            }
            let mut out = [lift2(0.0); MAX_NX];
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
        let lift = |v: f64| D3::from_re(Dual::from_re(Dual64::from(v)));
        let mut x3 = [lift(0.0); MAX_NX];
        let mut u3 = [lift(0.0); MAX_NU];
        for (d, v) in x3.iter_mut().zip(&z[..n]) {
            *d = lift(*v);
        }
        for (d, v) in u3.iter_mut().zip(u) {
            *d = lift(*v);
        }
        let mut out = [lift(0.0); MAX_NX];
        // Canonical triples: state indices in increasing order.
        let canonical = |c: usize, a: usize| a >= n || c <= a;
        for a in 0..nv {
            for b in a..nv {
                for c in 0..n {
                    if !canonical(c, a) {
                        continue;
                    }
                    x3[c].eps = Dual::from_re(Dual64::from(1.0));
                    if a < n {
                        x3[a].re.eps = Dual64::from(1.0);
                    } else {
                        u3[a - n].re.eps = Dual64::from(1.0);
                    }
                    if b < n {
                        x3[b].re.re.eps = 1.0;
                    } else {
                        u3[b - n].re.re.eps = 1.0;
                    }
                    base.flow(k, &x3[..n], &u3[..m], &mut out[..n]);
                    x3[c].eps = Dual::from_re(Dual64::from(0.0));
                    if a < n {
                        x3[a].re.eps = Dual64::from(0.0);
                    } else {
                        u3[a - n].re.eps = Dual64::from(0.0);
                    }
                    if b < n {
                        x3[b].re.re.eps = 0.0;
                    } else {
                        u3[b - n].re.re.eps = 0.0;
                    }
                    for r in 0..n {
                        s.d2a[a * nv + b][(r, c)] = out[r].eps.eps.eps;
                    }
                }
            }
        }
        // The other triples from their canonical order, then the mirror pairs (b, a).
        for a in 0..nv {
            for b in a..nv {
                for c in 0..n {
                    if canonical(c, a) {
                        continue;
                    }
                    // c > a, both states: swap them; if b is a state too, sort all three.
                    let (c2, a2, b2) = if b < n {
                        let mut t = [c, a, b];
                        t.sort_unstable();
                        (t[0], t[1], t[2])
                    } else {
                        (a, c, b)
                    };
                    for r in 0..n {
                        let v = s.d2a[a2 * nv + b2][(r, c2)];
                        s.d2a[a * nv + b][(r, c)] = v;
                    }
                }
                if b != a {
                    // a < b, so a·nv + b < b·nv + a.
                    let (head, tail) = s.d2a.split_at_mut(b * nv + a);
                    tail[0].copy_from(&head[a * nv + b]);
                }
            }
        }
        if s.curved_model && nw > 0 {
            type D2 = Dual<Dual64>;
            let lift2 = |v: f64| D2::from_re(Dual64::from(v));
            let mut x2 = [lift2(0.0); MAX_NX];
            let mut u2 = [lift2(0.0); MAX_NU];
            for (d, v) in x2.iter_mut().zip(&z[..n]) {
                *d = lift2(*v);
            }
            for (d, v) in u2.iter_mut().zip(u) {
                *d = lift2(*v);
            }
            let zero = lift2(0.0);
            let mut g = [zero; MAX_NX * MAX_NW];
            let mut dgx = [zero; MAX_NX * MAX_NX * MAX_NW];
            let mut dgu = [zero; MAX_NU * MAX_NX * MAX_NW];
            let block = n * nw;
            for a in 0..nv {
                for b in a..nv {
                    if a < n {
                        x2[a].re.eps = 1.0;
                    } else {
                        u2[a - n].re.eps = 1.0;
                    }
                    if b < n {
                        x2[b].eps.re = 1.0;
                    } else {
                        u2[b - n].eps.re = 1.0;
                    }
                    base.noise_jacobian(&x2[..n], &u2[..m], &mut g, &mut dgx, &mut dgu);
                    if a < n {
                        x2[a].re.eps = 0.0;
                    } else {
                        u2[a - n].re.eps = 0.0;
                    }
                    if b < n {
                        x2[b].eps.re = 0.0;
                    } else {
                        u2[b - n].eps.re = 0.0;
                    }
                    for (ab, pair) in [(a * nv + b), (b * nv + a)].into_iter().enumerate() {
                        if ab == 1 && a == b {
                            break;
                        }
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
    }

    /// The first derivatives of the moment step at knot `k` into `e.a`, `e.b`, and (with
    /// `curvature`) what [`MomentExpansion::curvature`] needs besides.
    ///
    /// `∂P⁺/∂(m, u)` needs the second derivatives of the flow (`∂A/∂v_j`): one nested-dual flow
    /// evaluation per pair `(v_j, x_i)`, the state–state pairs once by symmetry; with `curvature`
    /// also the control–control pairs `∂²Φ/∂u_a∂u_b`.
    pub fn expand(&self, k: usize, z: &[f64], u: &[f64], curvature: bool, e: &mut MomentExpansion) {
        let base = self.base;
        let (n, m, nw) = (base.nx(), base.nu(), base.nw());
        let s = e;
        base.linearize(k, &z[..n], u, &mut s.base);
        unpack(n, &z[n..], &mut s.p);
        s.a.fill(0.0);
        s.b.fill(0.0);
        s.a.view_mut((0, 0), (n, n)).copy_from(&s.base.a);
        s.b.view_mut((0, 0), (n, m)).copy_from(&s.base.b);
        let noisy = s.base.noise != NoiseKind::None;
        let dependent = s.base.noise == NoiseKind::Dependent;

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

        // ∂A/∂(m,u)_j from the second derivatives of the flow: column i of ∂A/∂z_j is
        // ∂²Φ/∂z_j ∂x_i, one nested-dual flow evaluation per pair. The pairs with both indices
        // in the state are symmetric, so only i ≤ j is evaluated.
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
                        for r in 0..n {
                            let v = s.da[i][(r, j)];
                            s.da[j][(r, i)] = v;
                        }
                        continue;
                    }
                    // Inner seed on v_j, outer seed on x_i: out.eps.eps = ∂²Φ/∂x_i ∂v_j.
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
                        s.da[j][(r, i)] = out[r].eps.eps;
                    }
                }
            }
        }
        if curvature {
            self.second_order(k, z, u, s);
        }

        // ∂P⁺/∂m_j and ∂P⁺/∂u_j: d(A P Aᵀ) = X + Xᵀ with X = dA (P Aᵀ), and the same for each
        // Cx_i; P Aᵀ and P Cx_iᵀ do not depend on j.
        // P Aᵀ = (A P)ᵀ, P being symmetric.
        s.t1.gemm(1.0, &s.base.a, &s.p, 0.0);
        s.t1.transpose_to(&mut s.atl);
        let pat = &s.atl;
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
        s.curved_noise = false;
        for j in 0..n + m {
            s.t1.gemm(1.0, &s.da[j], pat, 0.0);
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
                        s.dc[j][(r, i)] = g[i * n + r].eps;
                    }
                    for r in 0..n {
                        for c in 0..n {
                            s.next[(r, c)] += s.dc[j][(r, i)] * s.base.c[(c, i)]
                                + s.base.c[(r, i)] * s.dc[j][(c, i)];
                        }
                    }
                    if dependent {
                        // dCx from the second derivatives of the noise gain.
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
