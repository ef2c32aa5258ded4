//! The policy of one knot of the backward pass: the feedforward step from the box QP on the
//! regularised `Q_uu` and the feedback gains on its free controls (Tassa, Mansard & Todorov
//! 2014), shared by the dynamic path ([`super::backward`]) and the stack path ([`super::knot`]).

use super::Bounds;
use crate::solver::boxqp::{MAX_QP, QpStatus, SmallCholesky, solve_box_qp};

/// The policy `δu = l + L δx` of a knot from its regularised `Q_uu` (`quu_reg`, m×m), `Q_u` and
/// regularised `Q_ux` (`qux_reg`, m×n), all column-major: the feedforward step `l` from the box
/// QP `min ½ lᵀ Q_uu l + Q_uᵀ l` over `lower − ū ≤ l ≤ upper − ū` (projected Newton, Tassa,
/// Mansard & Todorov 2014), warm-started at the previous `l`; the gains `L = −Q_uu⁻¹ Q_ux`
/// (`gain`, m×n) on its free components, zero on the clamped ones. Without limits the QP is one
/// Newton step and is not run. (Skipping it also whenever the Newton step happens to land inside
/// a finite box would be the same mathematics, but the QP reaches that point along another
/// sequence of roundings; the stochastic single joint, whose optimum is flat in the stiffness,
/// then settles at another stop, percents away in expected cost.) False when `Q_uu` is not
/// positive definite.
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
    if unbounded && matches!(nx, 2 | 4 | 8) {
        let all = [0, 1, 2, 3, 4, 5, 6, 7];
        if !factor.factorize(h, &all[..nu]) {
            return false;
        }
        match nx {
            2 => newton_and_gains::<2, 3, M>(&factor, qu, qux_reg, l, gain),
            4 => newton_and_gains::<4, 5, M>(&factor, qu, qux_reg, l, gain),
            _ => newton_and_gains::<8, 9, M>(&factor, qu, qux_reg, l, gain),
        }
        return true;
    }
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

/// Without limits, for the paper's state sizes: the Newton step `l = −Q_uu⁻¹ Q_u` and the gains
/// `L = −Q_uu⁻¹ Q_ux` (`N` columns) from one substitution of `C` = `N` + 1 right-hand sides
/// ([`SmallCholesky::solve_many`]: per column the operations of [`newton_step`] and
/// [`free_gains`], so the same numbers).
#[inline(always)]
fn newton_and_gains<const N: usize, const C: usize, const M: usize>(
    factor: &SmallCholesky<M>,
    qu: &[f64],
    qux: &[f64],
    l: &mut [f64],
    gain: &mut [f64],
) {
    debug_assert_eq!(C, N + 1);
    let nu = qu.len();
    let mut cols = [[0.0; M]; C];
    for (a, &g) in qu.iter().enumerate() {
        cols[0][a] = -g;
    }
    // Element loops, not slice copies: a copy of one or two numbers is a call to memcpy.
    for (col, q) in cols[1..].iter_mut().zip(qux.chunks_exact(nu)) {
        for (v, q) in col.iter_mut().zip(q) {
            *v = *q;
        }
    }
    factor.solve_many(&mut cols);
    for (l, v) in l.iter_mut().zip(&cols[0]) {
        *l = *v;
    }
    for (c, col) in cols[1..].iter().enumerate() {
        for (g, v) in gain[c * nu..(c + 1) * nu].iter_mut().zip(&col[..nu]) {
            *g = -v;
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{RngExt, SeedableRng};

    /// The Newton step and the gains from one substitution are those of the separate
    /// substitutions ([`newton_step`], then [`free_gains`]) to the bit, for every control count
    /// and the paper's state sizes, from well and badly scaled `Q_uu`.
    #[test]
    fn one_substitution_gives_the_separate_ones_bit_for_bit() {
        fn check<const N: usize, const C: usize>(rng: &mut StdRng) {
            for nu in 1..=MAX_QP {
                let scale = 10f64.powi(rng.random_range(-6..7));
                let f: Vec<f64> = (0..nu * nu).map(|_| rng.random_range(-1.0..1.0)).collect();
                // Q_uu = F Fᵀ + I/10, scaled: positive definite.
                let mut quu = vec![0.0; nu * nu];
                for i in 0..nu {
                    for j in 0..nu {
                        let dot: f64 = (0..nu).map(|k| f[i * nu + k] * f[j * nu + k]).sum();
                        quu[j * nu + i] = scale * (dot + if i == j { 0.1 } else { 0.0 });
                    }
                }
                let qu: Vec<f64> = (0..nu).map(|_| rng.random_range(-5.0..5.0)).collect();
                let qux: Vec<f64> = (0..nu * N).map(|_| rng.random_range(-5.0..5.0)).collect();
                let h = |i: usize, j: usize| quu[j * nu + i];
                let all = [0, 1, 2, 3, 4, 5, 6, 7];
                let mut factor = SmallCholesky::<MAX_QP>::EMPTY;
                let step = newton_step(h, &qu, &all[..nu], &mut factor).expect("definite");
                let mut gains = vec![f64::NAN; nu * N];
                free_gains::<N, MAX_QP>(&factor, &all[..nu], &qux, &mut gains);
                let (mut l, mut gains_once) = (vec![f64::NAN; nu], vec![f64::NAN; nu * N]);
                newton_and_gains::<N, C, MAX_QP>(&factor, &qu, &qux, &mut l, &mut gains_once);
                let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&l), bits(&step[..nu]), "l, {nu} controls, {N} states");
                assert_eq!(
                    bits(&gains_once),
                    bits(&gains),
                    "L, {nu} controls, {N} states"
                );
            }
        }
        let mut rng = StdRng::seed_from_u64(5);
        for _ in 0..50 {
            check::<2, 3>(&mut rng);
            check::<4, 5>(&mut rng);
            check::<8, 9>(&mut rng);
        }
    }
}
