//! The policy of one knot of the backward pass: the feedforward step from the box QP on the
//! regularised `Q_uu` and the feedback gains on its free controls (Tassa, Mansard & Todorov
//! 2014), shared by the dynamic path ([`super::backward`]) and the stack path ([`super::knot`]).

use super::Bounds;
use crate::core::solver::boxqp::{MAX_QP, QpStatus, SmallCholesky, solve_box_qp};

/// The policy `δu = l + L δx` of a knot from its regularised `Q_uu` (`quu_reg`, m×m), `Q_u` and
/// regularised `Q_ux` (`qux_reg`, m×n), all column-major: the feedforward step `l` from the box
/// QP `min ½ lᵀ Q_uu l + Q_uᵀ l` over `lower − ū ≤ l ≤ upper − ū` (projected Newton, Tassa,
/// Mansard & Todorov 2014), warm-started at the previous `l`; the gains `L = −Q_uu⁻¹ Q_ux`
/// (`gain`, m×n) on its free components, zero on the clamped ones. Without limits the QP is one
/// Newton step and is not run. (Skipping it also whenever the Newton step happens to land inside
/// a finite box would be the same mathematics, but the QP reaches that point along another
/// sequence of roundings; the stochastic single joint, whose optimum is flat in the stiffness,
/// then settles 3 % away in expected cost.) False when `Q_uu` is not positive definite.
///
/// Inlined, so that on the stack path ([`super::knot`]) the sizes, read off the slices of its
/// arrays, are constants.
#[inline(always)]
pub(super) fn policy<const M: usize>(
    quu_reg: &[f64],
    qu: &[f64],
    qux_reg: &[f64],
    bounds: &Bounds,
    u: &[f64],
    l: &mut [f64],
    gain: &mut [f64],
) -> bool {
    let nu = qu.len();
    let nx = qux_reg.len() / nu;
    let h = |i: usize, j: usize| quu_reg[j * nu + i];
    let mut lower = [0.0; MAX_QP];
    let mut upper = [0.0; MAX_QP];
    for j in 0..nu {
        lower[j] = bounds.lower[j] - u[j];
        upper[j] = bounds.upper[j] - u[j];
    }
    let unbounded = (0..nu).all(|j| lower[j] == f64::NEG_INFINITY && upper[j] == f64::INFINITY);
    // Written in place, never moved (see `SmallCholesky::EMPTY`).
    let mut factor = SmallCholesky::<M>::EMPTY;
    let (x, free, factored) = if unbounded {
        let all = [0, 1, 2, 3, 4, 5, 6, 7];
        match newton_step(h, qu, &all[..nu], &mut factor) {
            None => return false,
            Some(x) => (x, [true; MAX_QP], true),
        }
    } else {
        let qp = solve_box_qp(h, qu, &lower[..nu], &upper[..nu], l, &mut factor);
        if qp.status == QpStatus::NotPositiveDefinite {
            return false;
        }
        (qp.x, qp.free, qp.factored)
    };
    l.copy_from_slice(&x[..nu]);
    gain.fill(0.0);
    if factored {
        let mut idx = [0usize; MAX_QP];
        let mut nfree = 0;
        for j in (0..nu).filter(|&j| free[j]) {
            idx[nfree] = j;
            nfree += 1;
        }
        let idx = &idx[..nfree];
        match nx {
            2 => free_gains::<2, M>(&factor, idx, qux_reg, gain),
            4 => free_gains::<4, M>(&factor, idx, qux_reg, gain),
            8 => free_gains::<8, M>(&factor, idx, qux_reg, gain),
            _ => {
                let mut col = [0.0; MAX_QP];
                for c in 0..nx {
                    for (a, &j) in idx.iter().enumerate() {
                        col[a] = qux_reg[c * nu + j];
                    }
                    factor.solve(&mut col[..nfree]);
                    for (a, &j) in idx.iter().enumerate() {
                        gain[c * nu + j] = -col[a];
                    }
                }
            }
        }
    }
    true
}

/// The gains `L = −Q_uu⁻¹ Q_ux` on the free controls `idx` for the paper's state sizes: all `N`
/// columns solved at once ([`SmallCholesky::solve_many`], the same numbers as one column at a
/// time).
fn free_gains<const N: usize, const M: usize>(
    factor: &SmallCholesky<M>,
    idx: &[usize],
    qux: &[f64],
    gain: &mut [f64],
) {
    let nu = qux.len() / N;
    let mut cols = [[0.0; M]; N];
    for (c, col) in cols.iter_mut().enumerate() {
        for (a, &j) in idx.iter().enumerate() {
            col[a] = qux[c * nu + j];
        }
    }
    factor.solve_many(&mut cols);
    for (c, col) in cols.iter().enumerate() {
        for (a, &j) in idx.iter().enumerate() {
            gain[c * nu + j] = -col[a];
        }
    }
}

/// The unconstrained Newton step `x = −H⁻¹ g`, with the Cholesky factor of `H` over the indices
/// `idx` (all of them) written into `factor`; `None` when `H` is not positive definite.
fn newton_step<const M: usize>(
    h: impl Fn(usize, usize) -> f64 + Copy,
    g: &[f64],
    idx: &[usize],
    factor: &mut SmallCholesky<M>,
) -> Option<[f64; MAX_QP]> {
    if !factor.factorize(h, idx) {
        return None;
    }
    let mut x = [0.0; MAX_QP];
    for (a, &i) in idx.iter().enumerate() {
        x[a] = -g[i];
    }
    factor.solve(&mut x[..idx.len()]);
    Some(x)
}
