//! Moment propagation of the linearised stochastic plant under a policy `u = ū + L (x − x̄)`:
//! the covariance of the state about the nominal and the expected cost to second order.
//!
//! `Σ[k+1] = (A + B L) Σ (A + B L)ᵀ + Σ_i (c_i c_iᵀ + (Cx_i + Cu_i L) Σ (Cx_i + Cu_i L)ᵀ)`,
//! `E[C] ≈ C(x̄, ū) + Σ_k ½ tr((ℓ_xx + Lᵀ ℓ_uu L + Lᵀ ℓ_ux + ℓ_uxᵀ L) Σ[k]) + ½ tr(g_xx Σ[N])`.
//!
//! With `L = 0` this is the open-loop plan's spread (SOOC). For a linear plant with quadratic
//! cost it is exact, and at an ILQG optimum it equals the backward pass's `s_0`.

use crate::cost::CostDerivatives;
use crate::dense::zero;
use crate::dynamics::{Linearization, NoiseKind};
use nalgebra::DMatrix;

/// Scratch space for [`expected_cost`], allocated once per problem size.
#[derive(Debug, Clone)]
pub struct MomentWorkspace {
    sigma: DMatrix<f64>,
    next: DMatrix<f64>,
    acl: DMatrix<f64>,
    transposed: DMatrix<f64>,
    cl: DMatrix<f64>,
    tmp: DMatrix<f64>,
    q: DMatrix<f64>,
    qu: DMatrix<f64>,
}

impl MomentWorkspace {
    pub fn new(nx: usize, nu: usize) -> Self {
        MomentWorkspace {
            sigma: DMatrix::zeros(nx, nx),
            next: DMatrix::zeros(nx, nx),
            acl: DMatrix::zeros(nx, nx),
            transposed: DMatrix::zeros(nx, nx),
            cl: DMatrix::zeros(nx, nx),
            tmp: DMatrix::zeros(nx, nx),
            q: DMatrix::zeros(nx, nx),
            qu: DMatrix::zeros(nu, nx),
        }
    }

    /// The covariance after the last call to [`expected_cost`].
    pub fn final_covariance(&self) -> &DMatrix<f64> {
        &self.sigma
    }
}

/// `trace(a b)` for square matrices of equal size, without forming the product.
fn trace_of_product(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    let n = a.nrows();
    let mut t = 0.0;
    for i in 0..n {
        for j in 0..n {
            t += a[(i, j)] * b[(j, i)];
        }
    }
    t
}

/// Expected cost, to second order, of the policy `ū + L (x − x̄)` (`gains = None`: open loop)
/// given the linearisations and cost derivatives along the nominal (whose own cost is
/// `nominal_cost`). `derivs[N]` holds the final cost's. Calls `visit(k, Σ_k)` at every knot.
pub fn expected_cost(
    nominal_cost: f64,
    lin: &[Linearization],
    derivs: &[CostDerivatives],
    gains: Option<&[DMatrix<f64>]>,
    ws: &mut MomentWorkspace,
    mut visit: impl FnMut(usize, &DMatrix<f64>),
) -> f64 {
    let horizon = lin.len();
    zero(&mut ws.sigma);
    let mut total = nominal_cost;
    for k in 0..horizon {
        visit(k, &ws.sigma);
        let (l, d) = (&lin[k], &derivs[k]);
        ws.acl.copy_from(&l.a);
        ws.q.copy_from(&d.lxx);
        if let Some(gains) = gains {
            let g = &gains[k];
            ws.acl.gemm(1.0, &l.b, g, 1.0);
            // Lᵀ ℓ_uu L + Lᵀ ℓ_ux + ℓ_uxᵀ L = Lᵀ (ℓ_uu L + ℓ_ux) + ℓ_uxᵀ L
            ws.qu.copy_from(&d.lux);
            ws.qu.gemm(1.0, &d.luu, g, 1.0);
            ws.q.gemm_tr(1.0, g, &ws.qu, 1.0);
            ws.q.gemm_tr(1.0, &d.lux, g, 1.0);
        }
        total += 0.5 * trace_of_product(&ws.q, &ws.sigma);
        ws.tmp.gemm(1.0, &ws.acl, &ws.sigma, 0.0);
        ws.acl.transpose_to(&mut ws.transposed);
        ws.next.gemm(1.0, &ws.tmp, &ws.transposed, 0.0);
        if l.noise != NoiseKind::None {
            for i in 0..l.c.ncols() {
                ws.next.ger(1.0, &l.c.column(i), &l.c.column(i), 1.0);
            }
        }
        if l.noise == NoiseKind::Dependent {
            for i in 0..l.cx.len() {
                ws.cl.copy_from(&l.cx[i]);
                if let Some(gains) = gains {
                    ws.cl.gemm(1.0, &l.cu[i], &gains[k], 1.0);
                }
                ws.tmp.gemm(1.0, &ws.cl, &ws.sigma, 0.0);
                ws.cl.transpose_to(&mut ws.transposed);
                ws.next.gemm(1.0, &ws.tmp, &ws.transposed, 1.0);
            }
        }
        std::mem::swap(&mut ws.sigma, &mut ws.next);
        // Keep Σ symmetric against round-off.
        let n = ws.sigma.nrows();
        for i in 0..n {
            for j in 0..i {
                let m = 0.5 * (ws.sigma[(i, j)] + ws.sigma[(j, i)]);
                ws.sigma[(i, j)] = m;
                ws.sigma[(j, i)] = m;
            }
        }
    }
    visit(horizon, &ws.sigma);
    total + 0.5 * trace_of_product(&derivs[horizon].lxx, &ws.sigma)
}
