//! Discrete-time stochastic dynamics, the only thing the solvers see:
//! `x[k+1] = step(k, x[k], u[k]) + G(k, x[k], u[k]) ε[k]`, `ε ~ N(0, I)` (paper Eq. 10), and its
//! linearisation `δx' = A δx + B δu + Σ_i (c_i + Cx_i δx + Cu_i δu) ε_i`.

use crate::model::{ArmModel, Exogenous};
use crate::scalar::{MAX_NU, MAX_NW, MAX_NX, Scalar};
use nalgebra::DMatrix;
use num_dual::{Dual, DualNum};
use std::ops::Range;

mod integrator;
mod noise;

use integrator::flow_body;
pub use integrator::{Integrator, flow};

/// What kind of noise a linearisation carries; the backward pass skips what is absent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NoiseKind {
    /// Deterministic.
    None,
    /// `c_i` only (`Cx_i = Cu_i = 0`).
    Additive,
    /// State- and/or control-dependent.
    Dependent,
}

/// The linearisation of one discrete step around (x̄, ū).
#[derive(Debug, Clone)]
pub struct Linearization {
    /// `A = ∂x'/∂x` (n×n).
    pub a: DMatrix<f64>,
    /// `B = ∂x'/∂u` (n×m).
    pub b: DMatrix<f64>,
    /// Noise columns `c_i` (n×p).
    pub c: DMatrix<f64>,
    /// `Cx_i = ∂c_i/∂x` (p matrices n×n).
    pub cx: Vec<DMatrix<f64>>,
    /// `Cu_i = ∂c_i/∂u` (p matrices n×m).
    pub cu: Vec<DMatrix<f64>>,
    pub noise: NoiseKind,
}

impl Linearization {
    /// A zeroed linearisation of the right sizes.
    pub fn new(nx: usize, nu: usize, nw: usize) -> Self {
        Linearization {
            a: DMatrix::zeros(nx, nx),
            b: DMatrix::zeros(nx, nu),
            c: DMatrix::zeros(nx, nw),
            cx: (0..nw).map(|_| DMatrix::zeros(nx, nx)).collect(),
            cu: (0..nw).map(|_| DMatrix::zeros(nx, nu)).collect(),
            noise: if nw == 0 {
                NoiseKind::None
            } else {
                NoiseKind::Dependent
            },
        }
    }
}

/// Where one column of a Jacobian can be nonzero, at any knot, state and control.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Column {
    /// In these rows only: the entries outside are exactly zero.
    Rows(Range<usize>),
    /// Exactly `1` in this row and zero elsewhere, always: a shift register's column, whose
    /// entry a reader need not look up (on the delayed plant that lookup would cost a cache line
    /// of a 42×42 Jacobian per column).
    Unit(usize),
}

impl Column {
    /// Whether row `i` can hold a nonzero.
    pub fn contains(&self, i: usize) -> bool {
        match self {
            Column::Rows(r) => r.contains(&i),
            Column::Unit(r) => *r == i,
        }
    }

    /// Whether the column lies within `nrows` rows.
    pub fn fits(&self, nrows: usize) -> bool {
        match self {
            Column::Rows(r) => r.start <= r.end && r.end <= nrows,
            Column::Unit(r) => *r < nrows,
        }
    }
}

/// Where each column of `A`, `B` and of every `Cx_i`, `Cu_i` can hold a nonzero, at any knot,
/// state and control. The delay-augmented plant's columns of `A` hold the plant's rows or a
/// single one of the shift register (3 of 42 rows at most for the single joint with 200 ms of
/// delay), its `B` is the register's input (a unit column per control) and its `Cu_i` are zero,
/// so that reading its Jacobians' nonzeros by the support touches 8 entries of `A` instead of 42²
/// and takes the 38 ones of the shift as known.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StateSupport {
    /// Column `j` of `A`.
    pub a: Vec<Column>,
    /// Column `j` of `B`.
    pub b: Vec<Column>,
    /// Column `j` of every `Cx_i` can be nonzero in rows `cx[j]` only.
    pub cx: Vec<Range<usize>>,
    /// Column `j` of every `Cu_i` can be nonzero in rows `cu[j]` only.
    pub cu: Vec<Range<usize>>,
    /// The noise columns `c_i` can be nonzero in these rows only (the plant's, on the delayed
    /// plant): the stochastic merit reads the value Hessians there only, and the solver keeps
    /// only those rows and columns of them per knot.
    pub c: Range<usize>,
}

impl StateSupport {
    /// Empty, with room for an `nx`-state, `nu`-control model's columns (refilled without
    /// allocating).
    pub fn with_capacity(nx: usize, nu: usize) -> Self {
        StateSupport {
            a: Vec::with_capacity(nx),
            b: Vec::with_capacity(nu),
            cx: Vec::with_capacity(nx),
            cu: Vec::with_capacity(nu),
            c: 0..0,
        }
    }

    /// Whether every column is there and lies within an `nx`-state, `nu`-control model's
    /// Jacobians (a model's support that does not is ignored).
    pub fn fits(&self, nx: usize, nu: usize) -> bool {
        let ranges = |r: &[Range<usize>], cols: usize| {
            r.len() == cols && r.iter().all(|r| Column::Rows(r.clone()).fits(nx))
        };
        self.a.len() == nx
            && self.b.len() == nu
            && self.a.iter().chain(&self.b).all(|c| c.fits(nx))
            && ranges(&self.cx, nx)
            && ranges(&self.cu, nu)
            && Column::Rows(self.c.clone()).fits(nx)
    }
}

/// What a plant tells the solvers about its linearisations beyond their values
/// ([`Dynamics::structure`]): performance hints only, never a change of the result.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Structure {
    /// One linearisation costs enough (microseconds or more) that the solvers linearise the
    /// knots of a trajectory in parallel. Cheap models (a few states, first derivatives only) say
    /// false and are linearised in order, without allocating.
    pub parallel_linearization: bool,
    /// The plant declares where its Jacobians can be nonzero ([`StateSupport`]), and filled the
    /// support it was given.
    pub supported: bool,
}

impl Default for Structure {
    /// Every entry may be nonzero; linearised in parallel.
    fn default() -> Self {
        Structure {
            parallel_linearization: true,
            supported: false,
        }
    }
}

/// A discrete-time stochastic plant with exact first derivatives: six methods every plant gives
/// (its sizes, the step, the noise gain, the linearisation), and two optional capabilities with
/// defaults that a plant with more structure overrides ([`Dynamics::linearize_with`],
/// [`Dynamics::structure`]).
pub trait Dynamics: Send + Sync {
    /// State dimension.
    fn nx(&self) -> usize;
    /// Control dimension.
    fn nu(&self) -> usize;
    /// Number of noise channels.
    fn nw(&self) -> usize;
    /// Deterministic part of the step.
    fn step(&self, k: usize, x: &[f64], u: &[f64], next: &mut [f64]);
    /// Noise gain `G = √Δ F` (n×p) of the step.
    fn noise_gain(&self, k: usize, x: &[f64], u: &[f64], out: &mut DMatrix<f64>);
    /// Linearisation of the step around (x, u). A `lin` made without noise channels
    /// (`Linearization::new(nx, nu, 0)`, as the delay planner's noise-free tail problem asks for)
    /// receives the deterministic part only, and its noise kind is [`NoiseKind::None`].
    fn linearize(&self, k: usize, x: &[f64], u: &[f64], lin: &mut Linearization);
    /// Optional capability: [`Dynamics::linearize`] (the same `lin`, bit for bit) with what the
    /// caller offers a plant that can use it.
    ///
    /// - `next`: the step is wanted too, into `next` as [`Dynamics::step`] gives it, bit for
    ///   bit. A rollout that will be linearised anyway asks for it, and a plant whose Jacobian
    ///   computes the step on the way (the chain rule runs through the same sub-step states)
    ///   saves a second evaluation of its drift.
    /// - `refill`: `lin` holds this model's linearisation at knot `k` from an earlier call (at
    ///   another state and control) or, for a plant that declares a support
    ///   ([`Dynamics::structure`]), a linearisation of *any* model with the same support. A
    ///   plant whose Jacobians are zero outside fixed blocks (the delay-augmented plant: 46 of
    ///   42² entries of `A` can be nonzero) then writes only those blocks instead of clearing
    ///   and refilling every entry. The solvers pass it for the second and later linearisations
    ///   of a knot, and keep such buffers from one solve to the next when the support is the
    ///   same.
    ///
    /// Default: the step if asked, then [`Dynamics::linearize`].
    fn linearize_with(
        &self,
        k: usize,
        x: &[f64],
        u: &[f64],
        next: Option<&mut [f64]>,
        refill: bool,
        lin: &mut Linearization,
    ) {
        let _ = refill;
        if let Some(next) = next {
            self.step(k, x, u, next);
        }
        self.linearize(k, x, u, lin);
    }
    /// Optional capability: what the solvers may exploit ([`Structure`]). With `support` given
    /// and a plant that knows where `A`, `B` and the noise Jacobians can be nonzero, fills it
    /// ([`StateSupport`]) and says `supported`; the solvers then read a linearisation's nonzeros
    /// only there and take its unit columns without reading them. `None` asks for the flags
    /// only. Default: [`Structure::default`] (every entry may be nonzero, linearised in
    /// parallel).
    fn structure(&self, support: Option<&mut StateSupport>) -> Structure {
        let _ = support;
        Structure::default()
    }
}

/// A continuous model discretised on a fixed grid (paper Eq. 10):
/// `x[k+1] = Φ_Δ(x[k], u[k]) + √Δ F(x[k], u[k]) ε[k]`, where `Φ_Δ` integrates the drift over Δ in
/// `substeps` steps of the chosen [`Integrator`] with the control and reference of knot `k` held.
///
/// The noise enters once per control step as in Eq. 10; sub-steps only keep a stiff impedance
/// (large `K_D / J`) numerically stable, which explicit Euler at Δ = 10 ms is not. The Rosenbrock
/// step is stable with one step per knot, but a SOOC plan made on it costs 0.35–3 % more on the
/// 1 ms plant than the optimum made there (`docs/BENCHMARKS.md`, "SOOC cost against the state").
#[derive(Debug, Clone)]
pub struct DiscreteDynamics {
    pub model: ArmModel,
    /// Time step Δ [s].
    pub dt: f64,
    /// Integration sub-steps per control step (1: the paper's single Euler step).
    pub substeps: usize,
    pub integrator: Integrator,
    /// Exogenous inputs (reference, external torque) at each knot.
    pub exogenous: Vec<Exogenous>,
}

impl DiscreteDynamics {
    /// The paper's discretisation: one explicit Euler step per control step.
    pub fn euler(model: ArmModel, dt: f64, exogenous: Vec<Exogenous>) -> Self {
        DiscreteDynamics {
            model,
            dt,
            substeps: 1,
            integrator: Integrator::Euler,
            exogenous,
        }
    }

    pub(crate) fn exo(&self, k: usize) -> &Exogenous {
        &self.exogenous[k.min(self.exogenous.len() - 1)]
    }

    /// The deterministic step `Φ_Δ(x, u)` in any scalar type (so it can be differentiated), in
    /// AVX2's 256-bit registers where [`crate::wide`] allows it (the same numbers to the
    /// bit; SOOC's Taylor-polynomial flows, most of its time, gain the most).
    pub fn flow<S: Scalar>(&self, k: usize, x: &[S], u: &[S], next: &mut [S]) {
        #[cfg(target_arch = "x86_64")]
        if crate::wide::enabled() {
            // SAFETY: `enabled` is true only where the CPU reported AVX2.
            return unsafe { self.flow_avx2(k, x, u, next) };
        }
        self.flow_inlined(k, x, u, next);
    }

    /// [`DiscreteDynamics::flow`] compiled for AVX2 (see [`crate::wide`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn flow_avx2<S: Scalar>(&self, k: usize, x: &[S], u: &[S], next: &mut [S]) {
        self.flow_inlined(k, x, u, next);
    }

    /// The step, inlined into both callers so that each compiles the drift for its own
    /// instruction set.
    #[inline(always)]
    fn flow_inlined<S: Scalar>(&self, k: usize, x: &[S], u: &[S], next: &mut [S]) {
        flow_body(
            &self.model,
            self.exo(k),
            self.dt,
            self.substeps,
            self.integrator,
            x,
            u,
            next,
        );
    }
}

impl Dynamics for DiscreteDynamics {
    fn nx(&self) -> usize {
        self.model.nx()
    }
    fn nu(&self) -> usize {
        self.model.nu()
    }
    fn nw(&self) -> usize {
        self.model.nw()
    }

    fn step(&self, k: usize, x: &[f64], u: &[f64], next: &mut [f64]) {
        self.flow(k, x, u, next);
    }

    fn noise_gain(&self, _k: usize, x: &[f64], u: &[f64], out: &mut DMatrix<f64>) {
        let (nx, nw) = (self.nx(), self.nw());
        let mut f = [0.0; MAX_NX * MAX_NW];
        self.model.diffusion(x, u, &mut f);
        let s = self.dt.sqrt();
        for i in 0..nw {
            for r in 0..nx {
                out[(r, i)] = s * f[i * nx + r];
            }
        }
    }

    fn linearize(&self, k: usize, x: &[f64], u: &[f64], lin: &mut Linearization) {
        // DMatrix is column-major: its slices have flow_jacobian's layout.
        self.flow_jacobian_f64(k, x, u, lin.a.as_mut_slice(), lin.b.as_mut_slice());
        self.noise_linearization(x, u, lin);
    }

    fn linearize_with(
        &self,
        k: usize,
        x: &[f64],
        u: &[f64],
        next: Option<&mut [f64]>,
        _refill: bool,
        lin: &mut Linearization,
    ) {
        // Every entry is written anyway: a relinearisation is a linearisation.
        let Some(next) = next else {
            return self.linearize(k, x, u, lin);
        };
        let (a, b) = (lin.a.as_mut_slice(), lin.b.as_mut_slice());
        if !self.flow_jacobian_by_size(k, x, u, a, b, Some(&mut *next)) {
            self.flow(k, x, u, next);
            self.flow_jacobian(k, x, u, a, b);
        }
        self.noise_linearization(x, u, lin);
    }

    fn structure(&self, _support: Option<&mut StateSupport>) -> Structure {
        // One flow with a vector dual number: well under a microsecond for the paper's limbs.
        Structure {
            parallel_linearization: false,
            supported: false,
        }
    }
}

impl DiscreteDynamics {
    /// `A = ∂Φ/∂x` and `B = ∂Φ/∂u` of the step (column-major n×n and n×m) by forward-mode AD
    /// through every sub-step, in any scalar type: with dual numbers in, the result carries the
    /// second derivatives of the flow (what the moment dynamics of SOOC need).
    pub fn flow_jacobian<S: Scalar + DualNum<Primitive = f64>>(
        &self,
        k: usize,
        x: &[S],
        u: &[S],
        a: &mut [S],
        b: &mut [S],
    ) {
        let (nx, nu) = (self.nx(), self.nu());
        let mut xd = [Dual::from_re(<S as Scalar>::zero()); MAX_NX];
        let mut ud = [Dual::from_re(<S as Scalar>::zero()); MAX_NU];
        for (d, v) in xd.iter_mut().zip(x) {
            *d = Dual::from_re(*v);
        }
        for (d, v) in ud.iter_mut().zip(u) {
            *d = Dual::from_re(*v);
        }
        let mut out = [Dual::from_re(<S as Scalar>::zero()); MAX_NX];
        for j in 0..nx + nu {
            seed(&mut xd, &mut ud, nx, j, <S as Scalar>::one());
            self.flow(k, &xd[..nx], &ud[..nu], &mut out[..nx]);
            seed(&mut xd, &mut ud, nx, j, <S as Scalar>::zero());
            let col = if j < nx {
                &mut a[j * nx..(j + 1) * nx]
            } else {
                &mut b[(j - nx) * nx..(j - nx + 1) * nx]
            };
            for (c, o) in col.iter_mut().zip(&out[..nx]) {
                *c = o.eps;
            }
        }
    }

    /// `A = ∂Φ/∂x` and `B = ∂Φ/∂u` in `f64` (layout of [`DiscreteDynamics::flow_jacobian`]), by
    /// the chain rule through the sub-steps with the drift's written-out Jacobian
    /// ([`ArmModel::f_jacobian`]): `J ← J + h (f_x J + [0 | f_u])` per explicit Euler sub-step
    /// (`J` = `[∂x/∂x₀ | ∂x/∂u]`, from `[I | 0]`); the semi-implicit step updates the velocity
    /// rows so, then adds `h` times the new velocity rows to the position rows. The states of the
    /// sub-steps are [`flow`]'s, bit for bit.
    pub fn flow_jacobian_f64(&self, k: usize, x: &[f64], u: &[f64], a: &mut [f64], b: &mut [f64]) {
        if !self.flow_jacobian_by_size(k, x, u, a, b, None) {
            self.flow_jacobian(k, x, u, a, b);
        }
    }

    /// [`DiscreteDynamics::flow_jacobian_fixed`] for the paper's plant sizes, and the step's
    /// end state into `next` if asked; false (nothing written) for any other size.
    fn flow_jacobian_by_size(
        &self,
        k: usize,
        x: &[f64],
        u: &[f64],
        a: &mut [f64],
        b: &mut [f64],
        next: Option<&mut [f64]>,
    ) -> bool {
        macro_rules! by_size {
            ($(($n:literal, $c:literal))*) => {
                match (self.nx(), self.nx() + self.nu()) {
                    $(($n, $c) => self.flow_jacobian_sized::<$n, $c>(k, x, u, a, b, next),)*
                    _ => return false,
                }
            };
        }
        // The written-out chain rule covers the two Euler steps; a Runge–Kutta or Rosenbrock
        // step is differentiated by dual numbers.
        if matches!(self.integrator, Integrator::Rk4 | Integrator::Rosenbrock) {
            return false;
        }
        by_size!((2, 3)(2, 4)(3, 5)(4, 6)(4, 8)(6, 10)(8, 12));
        true
    }

    /// [`DiscreteDynamics::flow_jacobian_fixed`] in AVX2's 256-bit registers where
    /// [`crate::wide`] allows it (the same numbers to the bit), else portably.
    fn flow_jacobian_sized<const N: usize, const C: usize>(
        &self,
        k: usize,
        x: &[f64],
        u: &[f64],
        a: &mut [f64],
        b: &mut [f64],
        next: Option<&mut [f64]>,
    ) {
        #[cfg(target_arch = "x86_64")]
        if crate::wide::enabled() {
            // SAFETY: `enabled` is true only where the CPU reported AVX2.
            return unsafe { self.flow_jacobian_avx2::<N, C>(k, x, u, a, b, next) };
        }
        self.flow_jacobian_fixed::<N, C>(k, x, u, a, b, next)
    }

    /// [`DiscreteDynamics::flow_jacobian_fixed`] compiled for AVX2 (see [`crate::wide`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn flow_jacobian_avx2<const N: usize, const C: usize>(
        &self,
        k: usize,
        x: &[f64],
        u: &[f64],
        a: &mut [f64],
        b: &mut [f64],
        next: Option<&mut [f64]>,
    ) {
        self.flow_jacobian_fixed::<N, C>(k, x, u, a, b, next)
    }

    /// [`DiscreteDynamics::flow_jacobian_f64`] for `N` states and `C` = `N` + controls columns,
    /// on the stack; with `next`, also the step's end state (the sub-steps are [`flow`]'s).
    /// Inlined into its two callers, so that each compiles it (and the drift's Jacobian) for
    /// its own instruction set.
    #[inline(always)]
    fn flow_jacobian_fixed<const N: usize, const C: usize>(
        &self,
        k: usize,
        x: &[f64],
        u: &[f64],
        a: &mut [f64],
        b: &mut [f64],
        next: Option<&mut [f64]>,
    ) {
        let ex = self.exo(k);
        let h = self.dt / self.substeps as f64;
        let mut cur = [0.0; N];
        cur.copy_from_slice(&x[..N]);
        let mut xdot = [0.0; N];
        // The drift's Jacobian at the sub-step, its product with J (the total derivative of the
        // drift with respect to (x₀, u)), and J, column by column.
        let mut f = [[0.0; N]; C];
        let mut df = [[0.0; N]; C];
        let mut jac = [[0.0; N]; C];
        for (i, column) in jac.iter_mut().enumerate().take(N) {
            column[i] = 1.0;
        }
        for sub in 0..self.substeps {
            self.model.f_jacobian_fixed(&cur, u, ex, &mut xdot, &mut f);
            let total = if sub == 0 {
                // J = [I | 0]: the product is f's Jacobian itself.
                &f
            } else {
                for (col, (out, j_col)) in df.iter_mut().zip(&jac).enumerate() {
                    *out = if col < N { [0.0; N] } else { f[col] };
                    for (l, &j_l) in j_col.iter().enumerate() {
                        if j_l != 0.0 {
                            for (o, fv) in out.iter_mut().zip(&f[l]) {
                                *o += fv * j_l;
                            }
                        }
                    }
                }
                &df
            };
            match self.integrator {
                Integrator::Euler => {
                    for (j_col, t_col) in jac.iter_mut().zip(total) {
                        for (jv, t) in j_col.iter_mut().zip(t_col) {
                            *jv += t * h;
                        }
                    }
                    for i in 0..N {
                        cur[i] += xdot[i] * h;
                    }
                }
                Integrator::SemiImplicit => {
                    let dof = self.model.dof();
                    let blocks = self.model.second_order_states();
                    for block in (0..blocks).step_by(2 * dof) {
                        for i in 0..dof {
                            let (p, v) = (block + i, block + dof + i);
                            for (j_col, t_col) in jac.iter_mut().zip(total) {
                                j_col[v] += t_col[v] * h;
                                j_col[p] += j_col[v] * h;
                            }
                            cur[v] += xdot[v] * h;
                            cur[p] += cur[v] * h;
                        }
                    }
                    // First-order states (a lagged stiffness): explicit Euler, as in `flow`.
                    for i in blocks..N {
                        for (j_col, t_col) in jac.iter_mut().zip(total) {
                            j_col[i] += t_col[i] * h;
                        }
                        cur[i] += xdot[i] * h;
                    }
                }
                Integrator::Rk4 | Integrator::Rosenbrock => {
                    unreachable!("flow_jacobian_by_size leaves RK4 and ROS2 to dual numbers")
                }
            }
        }
        for (col, column) in jac.iter().enumerate() {
            let dst = if col < N {
                &mut a[col * N..(col + 1) * N]
            } else {
                &mut b[(col - N) * N..(col - N + 1) * N]
            };
            for (d, v) in dst.iter_mut().zip(column) {
                *d = *v;
            }
        }
        if let Some(next) = next {
            next[..N].copy_from_slice(&cur);
        }
    }
}

/// Sets the derivative seed of variable `j` of the stacked vector `(x, u)`.
fn seed<S: Scalar + DualNum<Primitive = f64>>(
    x: &mut [Dual<S>],
    u: &mut [Dual<S>],
    nx: usize,
    j: usize,
    value: S,
) {
    if j < nx {
        x[j].eps = value;
    } else {
        u[j - nx].eps = value;
    }
}
