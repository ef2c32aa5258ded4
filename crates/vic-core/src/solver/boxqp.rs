//! Small box-constrained quadratic programs `min ½ xᵀ H x + gᵀ x, lower ≤ x ≤ upper`, solved by
//! projected Newton (Tassa, Mansard & Todorov 2014, "Control-limited differential dynamic
//! programming", Alg. 3). Sized for control vectors (at most [`MAX_QP`] entries), on the stack.

/// Largest QP handled.
pub const MAX_QP: usize = 8;

/// A dense Cholesky factor `H = R Rᵀ` (lower triangular, row-major) of the free block, for at
/// most `M` variables. A plant whose control count is known at compile time sizes it exactly
/// (the ILQG backward pass on the stack), so that the compiler unrolls the factorisation and the
/// substitutions; the operations, and so the numbers, do not depend on `M`.
#[derive(Debug, Clone, Copy)]
pub struct SmallCholesky<const M: usize = MAX_QP> {
    n: usize,
    l: [[f64; M]; M],
}

impl<const M: usize> SmallCholesky<M> {
    /// A factor of nothing, to be written by [`SmallCholesky::factorize`] (or by
    /// [`solve_box_qp`]) in place: the factor is 0.5 KiB, and moving it through return values
    /// would cost the two-link reach a sizeable part of its solve time in copies.
    pub const EMPTY: Self = SmallCholesky {
        n: 0,
        l: [[0.0; M]; M],
    };

    /// Factorises the symmetric `h` restricted to the indices `idx`; `None` if not positive definite.
    #[cfg(test)]
    pub(crate) fn new(h: impl Fn(usize, usize) -> f64, idx: &[usize]) -> Option<Self> {
        let mut c = Self::EMPTY;
        c.factorize(h, idx).then_some(c)
    }

    /// Factorises the symmetric `h` restricted to the indices `idx` in place; false (and the factor unusable) if `h` restricted to
    /// `idx` is not positive definite. Only the lower triangle of the leading `idx.len()` rows
    /// is written, and only it is read.
    pub fn factorize(&mut self, h: impl Fn(usize, usize) -> f64, idx: &[usize]) -> bool {
        let n = idx.len();
        let l = &mut self.l;
        for i in 0..n {
            for j in 0..=i {
                let mut s = h(idx[i], idx[j]);
                for k in 0..j {
                    s -= l[i][k] * l[j][k];
                }
                if i == j {
                    if s.is_nan() || s <= 0.0 || !s.is_finite() {
                        return false;
                    }
                    l[i][i] = s.sqrt();
                } else {
                    l[i][j] = s / l[j][j];
                }
            }
        }
        self.n = n;
        true
    }

    /// Solves `H x = b_c` in place for `N` right-hand sides at once: the same operations per
    /// column as [`SmallCholesky::solve`] (so the same numbers), interleaved across the columns,
    /// whose substitutions are independent of one another. The ILQG policy solves all the state
    /// columns of its gains this way, from slices, rather than one checked-index gather and
    /// solve per column (a noticeably faster reach).
    #[inline(always)]
    pub fn solve_many<const N: usize>(&self, b: &mut [[f64; M]; N]) {
        let n = self.n;
        for i in 0..n {
            let d = self.l[i][i];
            for col in b.iter_mut() {
                let mut s = col[i];
                for k in 0..i {
                    s -= self.l[i][k] * col[k];
                }
                col[i] = s / d;
            }
        }
        for i in (0..n).rev() {
            let d = self.l[i][i];
            for col in b.iter_mut() {
                let mut s = col[i];
                for k in i + 1..n {
                    s -= self.l[k][i] * col[k];
                }
                col[i] = s / d;
            }
        }
    }

    /// Solves `H x = b` in place.
    pub fn solve(&self, b: &mut [f64]) {
        let n = self.n;
        for i in 0..n {
            let mut s = b[i];
            for k in 0..i {
                s -= self.l[i][k] * b[k];
            }
            b[i] = s / self.l[i][i];
        }
        for i in (0..n).rev() {
            let mut s = b[i];
            for k in i + 1..n {
                s -= self.l[k][i] * b[k];
            }
            b[i] = s / self.l[i][i];
        }
    }
}

/// Why the QP stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum QpStatus {
    /// The Hessian's free block is not positive definite.
    NotPositiveDefinite,
    /// Converged (small projected gradient or no descent left).
    Converged,
    /// Every variable is at a bound.
    AllClamped,
    /// Iteration limit.
    MaxIterations,
}

/// The solution of a box QP.
#[derive(Debug, Clone, Copy)]
pub struct QpSolution {
    pub x: [f64; MAX_QP],
    /// `free[i]` is false when `x[i]` sits at a bound that the gradient pushes against.
    pub free: [bool; MAX_QP],
    /// Whether the caller's factor (the last argument of [`solve_box_qp`]) holds the Cholesky
    /// factor of `H` over the free indices (in increasing order).
    pub factored: bool,
    pub status: QpStatus,
}

/// Solves the box QP from the starting point `x0` (clamped into the box first): projected
/// Newton on the free variables with a projected Armijo line search (Bertsekas 1982, as in
/// Tassa, Mansard & Todorov 2014). The factor of the final free block is written into
/// `factor` ([`QpSolution::factored`] says whether it was).
pub fn solve_box_qp<const M: usize>(
    h: impl Fn(usize, usize) -> f64 + Copy,
    g: &[f64],
    lower: &[f64],
    upper: &[f64],
    x0: &[f64],
    factor: &mut SmallCholesky<M>,
) -> QpSolution {
    let n = g.len();
    assert!(n <= M, "box QP of size {n} exceeds {M}");
    let qp = BoxQp {
        h,
        g,
        lower,
        upper,
        n,
    };
    let mut x = [0.0; MAX_QP];
    for i in 0..n {
        x[i] = x0[i].clamp(lower[i], upper[i]);
    }
    let mut free = [true; MAX_QP];
    let mut old_free = [false; MAX_QP];
    let mut factored = false;
    let mut idx = [0usize; MAX_QP];
    let mut status = QpStatus::MaxIterations;
    let mut f = qp.value(&x);
    for iter in 0..100 {
        let grad = qp.gradient(&x);
        let (nfree, _) = qp.classify(&x, &grad, &mut free, &mut idx);
        if nfree == 0 {
            // No free block: a factor from an earlier iteration would describe the wrong set.
            factored = false;
            status = QpStatus::AllClamped;
            break;
        }
        if iter == 0 || free[..n] != old_free[..n] {
            factored = factor.factorize(h, &idx[..nfree]);
            if !factored {
                return QpSolution {
                    x,
                    free,
                    factored,
                    status: QpStatus::NotPositiveDefinite,
                };
            }
        }
        old_free = free;
        let gnorm: f64 = idx[..nfree]
            .iter()
            .map(|&i| grad[i] * grad[i])
            .sum::<f64>()
            .sqrt();
        if gnorm < 1e-10 {
            status = QpStatus::Converged;
            break;
        }
        debug_assert!(
            factored,
            "the free block is factored before its Newton step"
        );
        let dir = qp.newton_direction(&x, &free, &idx[..nfree], factor);
        let sdotg: f64 = (0..n).map(|i| dir[i] * grad[i]).sum();
        if sdotg >= -1e-14 * (1.0 + f.abs()) {
            status = QpStatus::Converged;
            break;
        }
        match qp.line_search(&x, &dir, f, sdotg) {
            Some((xc, fc)) => {
                x = xc;
                f = fc;
            }
            None => {
                status = QpStatus::Converged;
                break;
            }
        }
    }
    qp.finish(x, free, (factor, factored), status)
}

/// The problem `min ½ xᵀ H x + gᵀ x` over `lower ≤ x ≤ upper` (`n` variables).
struct BoxQp<'a, H> {
    h: H,
    g: &'a [f64],
    lower: &'a [f64],
    upper: &'a [f64],
    n: usize,
}

impl<H: Fn(usize, usize) -> f64 + Copy> BoxQp<'_, H> {
    fn value(&self, x: &[f64; MAX_QP]) -> f64 {
        let mut v = 0.0;
        for i in 0..self.n {
            v += self.g[i] * x[i];
            for j in 0..self.n {
                v += 0.5 * x[i] * (self.h)(i, j) * x[j];
            }
        }
        v
    }

    fn gradient(&self, x: &[f64; MAX_QP]) -> [f64; MAX_QP] {
        let mut grad = [0.0; MAX_QP];
        for (i, gi) in grad.iter_mut().enumerate().take(self.n) {
            *gi = self.g[i] + (0..self.n).map(|j| (self.h)(i, j) * x[j]).sum::<f64>();
        }
        grad
    }

    /// The free set at `x`: a variable is clamped when it sits at a bound its gradient pushes
    /// against. Writes `free` and the free indices into `idx`; their number, and whether `free`
    /// changed.
    fn classify(
        &self,
        x: &[f64; MAX_QP],
        grad: &[f64; MAX_QP],
        free: &mut [bool; MAX_QP],
        idx: &mut [usize; MAX_QP],
    ) -> (usize, bool) {
        let mut changed = false;
        let mut k = 0;
        for i in 0..self.n {
            let clamped = (x[i] <= self.lower[i] && grad[i] > 0.0)
                || (x[i] >= self.upper[i] && grad[i] < 0.0);
            changed |= free[i] == clamped;
            free[i] = !clamped;
            if free[i] {
                idx[k] = i;
                k += 1;
            }
        }
        (k, changed)
    }

    /// The Newton step on the free variables `idx` with the clamped ones fixed (`chol`: the
    /// factor of the free block of `H`), as a direction from `x`.
    fn newton_direction<const M: usize>(
        &self,
        x: &[f64; MAX_QP],
        free: &[bool; MAX_QP],
        idx: &[usize],
        chol: &SmallCholesky<M>,
    ) -> [f64; MAX_QP] {
        let n = self.n;
        let mut rhs = [0.0; MAX_QP];
        for (a, &i) in idx.iter().enumerate() {
            rhs[a] = self.g[i]
                + (0..n)
                    .filter(|&j| !free[j])
                    .map(|j| (self.h)(i, j) * x[j])
                    .sum::<f64>();
        }
        chol.solve(&mut rhs[..idx.len()]);
        let mut dir = [0.0; MAX_QP];
        for (a, &i) in idx.iter().enumerate() {
            dir[i] = -rhs[a] - x[i];
        }
        dir
    }

    /// The solution at `x`: the final free set and its factor must describe the returned point,
    /// so both are recomputed when the free set changed at the last step.
    fn finish<const M: usize>(
        &self,
        x: [f64; MAX_QP],
        mut free: [bool; MAX_QP],
        (factor, mut factored): (&mut SmallCholesky<M>, bool),
        mut status: QpStatus,
    ) -> QpSolution {
        let grad = self.gradient(&x);
        let mut idx = [0usize; MAX_QP];
        let (k, changed) = self.classify(&x, &grad, &mut free, &mut idx);
        if changed || !factored {
            factored = k > 0 && factor.factorize(self.h, &idx[..k]);
            if k > 0 && !factored {
                status = QpStatus::NotPositiveDefinite;
            }
        }
        QpSolution {
            x,
            free,
            factored,
            status,
        }
    }

    /// Projected Armijo line search along `dir` from `x` (value `f`, slope `sdotg`): the first
    /// accepted point and its value.
    fn line_search(
        &self,
        x: &[f64; MAX_QP],
        dir: &[f64; MAX_QP],
        f: f64,
        sdotg: f64,
    ) -> Option<([f64; MAX_QP], f64)> {
        let mut step = 1.0;
        while step > 1e-12 {
            let mut xc = [0.0; MAX_QP];
            for i in 0..self.n {
                xc[i] = (x[i] + step * dir[i]).clamp(self.lower[i], self.upper[i]);
            }
            let fc = self.value(&xc);
            if (fc - f) / (step * sdotg) > 0.1 {
                return Some((xc, fc));
            }
            step *= 0.6;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solving_many_columns_at_once_gives_each_column_s_numbers() {
        let mut seed = 11u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for n in 1..=MAX_QP {
            for _ in 0..50 {
                // H = M Mᵀ + n I: positive definite, entries of mixed sign.
                let m: Vec<f64> = (0..n * n).map(|_| next()).collect();
                let h = |i: usize, j: usize| {
                    (0..n).map(|k| m[i * n + k] * m[j * n + k]).sum::<f64>()
                        + if i == j { n as f64 } else { 0.0 }
                };
                let idx: Vec<usize> = (0..n).collect();
                let c = SmallCholesky::<MAX_QP>::new(h, &idx).expect("positive definite");
                let mut many = [[0.0; MAX_QP]; 4];
                for col in &mut many {
                    for v in &mut col[..n] {
                        *v = next() * 1e3;
                    }
                }
                let mut one = many;
                c.solve_many(&mut many);
                for col in &mut one {
                    c.solve(&mut col[..n]);
                }
                let bits = |a: &[[f64; MAX_QP]; 4]| a.map(|c| c.map(f64::to_bits));
                assert_eq!(bits(&many), bits(&one), "n = {n}");
                // And it solves: H x = b to round-off for the first column.
                let mut b = [0.0; MAX_QP];
                for (i, bi) in b[..n].iter_mut().enumerate() {
                    *bi = (0..n).map(|j| h(i, j) * many[0][j]).sum::<f64>();
                }
                let mut again = b;
                c.solve(&mut again[..n]);
                for i in 0..n {
                    assert!((again[i] - many[0][i]).abs() <= 1e-9 * (1.0 + many[0][i].abs()));
                }
            }
        }
    }

    /// Brute force: enumerate every active set and keep the best feasible KKT point.
    fn brute(h: &[[f64; 3]; 3], g: &[f64; 3], lo: &[f64; 3], hi: &[f64; 3]) -> f64 {
        let mut best = f64::INFINITY;
        for mask in 0..27u32 {
            // 0: free, 1: at lower, 2: at upper
            let mut state = [0u32; 3];
            let mut m = mask;
            for s in &mut state {
                *s = m % 3;
                m /= 3;
            }
            let mut x = [0.0; 3];
            let free: Vec<usize> = (0..3).filter(|&i| state[i] == 0).collect();
            for i in 0..3 {
                x[i] = match state[i] {
                    1 => lo[i],
                    2 => hi[i],
                    _ => 0.0,
                };
            }
            if !free.is_empty() {
                let hf = |a: usize, b: usize| h[a][b];
                let Some(c) = SmallCholesky::<MAX_QP>::new(hf, &free) else {
                    continue;
                };
                let mut rhs: Vec<f64> = free
                    .iter()
                    .map(|&i| {
                        g[i] + (0..3)
                            .filter(|j| state[*j] != 0)
                            .map(|j| h[i][j] * x[j])
                            .sum::<f64>()
                    })
                    .collect();
                c.solve(&mut rhs);
                for (a, &i) in free.iter().enumerate() {
                    x[i] = -rhs[a];
                }
            }
            if (0..3).any(|i| x[i] < lo[i] - 1e-12 || x[i] > hi[i] + 1e-12) {
                continue;
            }
            let v: f64 = (0..3)
                .map(|i| g[i] * x[i] + 0.5 * x[i] * (0..3).map(|j| h[i][j] * x[j]).sum::<f64>())
                .sum();
            best = best.min(v);
        }
        best
    }

    #[test]
    fn matches_brute_force_on_random_problems() {
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for _ in 0..500 {
            let a: [[f64; 3]; 3] = [
                [rnd(), rnd(), rnd()],
                [rnd(), rnd(), rnd()],
                [rnd(), rnd(), rnd()],
            ];
            let mut h = [[0.0; 3]; 3];
            for i in 0..3 {
                for j in 0..3 {
                    h[i][j] = (0..3).map(|k| a[i][k] * a[j][k]).sum::<f64>()
                        + if i == j { 0.1 } else { 0.0 };
                }
            }
            let g = [rnd() * 3.0, rnd() * 3.0, rnd() * 3.0];
            let lo = [rnd() - 0.5, rnd() - 0.5, -1.0];
            let hi = [
                lo[0] + rnd().abs(),
                lo[1] + rnd().abs() + 0.01,
                f64::INFINITY,
            ];
            let mut factor = SmallCholesky::<MAX_QP>::EMPTY;
            let sol = solve_box_qp(|i, j| h[i][j], &g, &lo, &hi, &[0.0; 3], &mut factor);
            let v: f64 = (0..3)
                .map(|i| {
                    g[i] * sol.x[i]
                        + 0.5 * sol.x[i] * (0..3).map(|j| h[i][j] * sol.x[j]).sum::<f64>()
                })
                .sum();
            let best = brute(&h, &g, &lo, &hi);
            assert!(
                v <= best + 1e-8 * (1.0 + best.abs()),
                "qp {v} vs brute {best}"
            );
            for i in 0..3 {
                assert!(sol.x[i] >= lo[i] && sol.x[i] <= hi[i]);
            }
        }
    }

    /// The factor is written in place and reused across knots: whatever an earlier, larger
    /// factorisation left behind (here NaN everywhere) must never be read.
    #[test]
    fn a_reused_factor_reads_nothing_stale() {
        let h = [[4.0, 1.0, 0.5], [1.0, 3.0, 0.2], [0.5, 0.2, 2.0]];
        let g = [1.0, -2.0, 0.5];
        let (lo, hi) = ([-0.1, -1.0, -1.0], [1.0, 0.3, 1.0]);
        let mut stale = SmallCholesky {
            n: MAX_QP,
            l: [[f64::NAN; MAX_QP]; MAX_QP],
        };
        let mut fresh = SmallCholesky::<MAX_QP>::EMPTY;
        let a = solve_box_qp(|i, j| h[i][j], &g, &lo, &hi, &[0.0; 3], &mut stale);
        let b = solve_box_qp(|i, j| h[i][j], &g, &lo, &hi, &[0.0; 3], &mut fresh);
        assert!(a.factored && b.factored);
        assert_eq!(a.free, b.free);
        assert_eq!(a.x.map(f64::to_bits), b.x.map(f64::to_bits));
        let nfree = a.free[..3].iter().filter(|&&f| f).count();
        assert!(
            nfree > 0 && nfree < 3,
            "the test wants a partly clamped solution"
        );
        let (mut x, mut y) = ([1.0, 2.0, 3.0], [1.0, 2.0, 3.0]);
        stale.solve(&mut x[..nfree]);
        fresh.solve(&mut y[..nfree]);
        assert_eq!(x.map(f64::to_bits), y.map(f64::to_bits));
    }
}
