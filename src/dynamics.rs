//! Discrete-time stochastic dynamics, the only thing the solvers see:
//! `x[k+1] = step(k, x[k], u[k]) + G(k, x[k], u[k]) ε[k]`, `ε ~ N(0, I)` (paper Eq. 10), and its
//! linearisation `δx' = A δx + B δu + Σ_i (c_i + Cx_i δx + Cu_i δu) ε_i` (DESIGN §4).

use crate::model::{ArmModel, Exogenous};
use crate::scalar::{MAX_NU, MAX_NW, MAX_NX};
use nalgebra::DMatrix;

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

/// A discrete-time stochastic plant with exact first derivatives.
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
    /// Linearisation of the step around (x, u).
    fn linearize(&self, k: usize, x: &[f64], u: &[f64], lin: &mut Linearization);
}

/// A continuous model discretised by Euler–Maruyama on a fixed grid (paper Eq. 10):
/// `x[k+1] = x[k] + Δ f(x[k], u[k]) + √Δ F(x[k], u[k]) ε[k]`, with the reference of knot `k`.
#[derive(Debug, Clone)]
pub struct EulerModel {
    pub model: ArmModel,
    /// Time step Δ [s].
    pub dt: f64,
    /// Exogenous inputs (reference, external torque) at each knot.
    pub exogenous: Vec<Exogenous>,
}

impl EulerModel {
    fn exo(&self, k: usize) -> &Exogenous {
        &self.exogenous[k.min(self.exogenous.len() - 1)]
    }
}

impl Dynamics for EulerModel {
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
        let nx = self.nx();
        let mut xdot = [0.0; MAX_NX];
        self.model.f(x, u, self.exo(k), &mut xdot[..nx]);
        for i in 0..nx {
            next[i] = x[i] + self.dt * xdot[i];
        }
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
        let (nx, nu, nw) = (self.nx(), self.nu(), self.nw());
        let mut fx = [0.0; MAX_NX * MAX_NX];
        let mut fu = [0.0; MAX_NX * MAX_NU];
        let mut dfx = [0.0; MAX_NX * MAX_NX * MAX_NW];
        let mut dfu = [0.0; MAX_NU * MAX_NX * MAX_NW];
        let noise = (nw > 0).then_some((&mut dfx[..], &mut dfu[..]));
        self.model
            .jacobians(x, u, self.exo(k), &mut fx, &mut fu, noise);
        let dt = self.dt;
        for j in 0..nx {
            for i in 0..nx {
                lin.a[(i, j)] = dt * fx[j * nx + i] + if i == j { 1.0 } else { 0.0 };
            }
        }
        for j in 0..nu {
            for i in 0..nx {
                lin.b[(i, j)] = dt * fu[j * nx + i];
            }
        }
        if nw == 0 {
            lin.noise = NoiseKind::None;
            return;
        }
        self.noise_gain(k, x, u, &mut lin.c);
        let s = dt.sqrt();
        let block = nx * nw;
        let mut dependent = false;
        for ch in 0..nw {
            for j in 0..nx {
                for r in 0..nx {
                    let v = s * dfx[j * block + ch * nx + r];
                    dependent |= v != 0.0;
                    lin.cx[ch][(r, j)] = v;
                }
            }
            for j in 0..nu {
                for r in 0..nx {
                    let v = s * dfu[j * block + ch * nx + r];
                    dependent |= v != 0.0;
                    lin.cu[ch][(r, j)] = v;
                }
            }
        }
        lin.noise = if dependent {
            NoiseKind::Dependent
        } else {
            NoiseKind::Additive
        };
    }
}
