//! Small box-constrained quadratic programs `min ½ xᵀ H x + gᵀ x, lower ≤ x ≤ upper`, solved by
//! projected Newton (Tassa, Mansard & Todorov 2014, "Control-limited differential dynamic
//! programming", Alg. 3). Sized for control vectors (at most [`MAX_QP`] entries), on the stack.

/// Largest QP handled.
pub const MAX_QP: usize = 8;

/// A dense Cholesky factor `H = R Rᵀ` (lower triangular, row-major) of the free block.
#[derive(Debug, Clone, Copy)]
pub struct SmallCholesky {
    n: usize,
    l: [[f64; MAX_QP]; MAX_QP],
}

impl SmallCholesky {
    /// Factorises the symmetric `h` restricted to the indices `idx`; `None` if not positive definite.
    pub fn new(h: impl Fn(usize, usize) -> f64, idx: &[usize]) -> Option<Self> {
        let n = idx.len();
        let mut l = [[0.0; MAX_QP]; MAX_QP];
        for i in 0..n {
            for j in 0..=i {
                let mut s = h(idx[i], idx[j]);
                for k in 0..j {
                    s -= l[i][k] * l[j][k];
                }
                if i == j {
                    if s.is_nan() || s <= 0.0 || !s.is_finite() {
                        return None;
                    }
                    l[i][i] = s.sqrt();
                } else {
                    l[i][j] = s / l[j][j];
                }
            }
        }
        Some(SmallCholesky { n, l })
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
    /// Cholesky factor of `H` over the free indices (in increasing order).
    pub factor: Option<SmallCholesky>,
    pub status: QpStatus,
}

/// Solves the box QP from the starting point `x0` (clamped into the box first).
pub fn solve_box_qp(
    h: impl Fn(usize, usize) -> f64 + Copy,
    g: &[f64],
    lower: &[f64],
    upper: &[f64],
    x0: &[f64],
) -> QpSolution {
    let n = g.len();
    assert!(n <= MAX_QP, "box QP of size {n} exceeds {MAX_QP}");
    let mut x = [0.0; MAX_QP];
    for i in 0..n {
        x[i] = x0[i].clamp(lower[i], upper[i]);
    }
    let value = |x: &[f64; MAX_QP]| {
        let mut v = 0.0;
        for i in 0..n {
            v += g[i] * x[i];
            for j in 0..n {
                v += 0.5 * x[i] * h(i, j) * x[j];
            }
        }
        v
    };
    let mut free = [true; MAX_QP];
    let mut old_free = [false; MAX_QP];
    let mut factor: Option<SmallCholesky> = None;
    let mut idx = [0usize; MAX_QP];
    let mut nfree = 0;
    let mut status = QpStatus::MaxIterations;
    let mut f = value(&x);
    for iter in 0..100 {
        let mut grad = [0.0; MAX_QP];
        for i in 0..n {
            grad[i] = g[i] + (0..n).map(|j| h(i, j) * x[j]).sum::<f64>();
        }
        nfree = 0;
        for i in 0..n {
            let clamped =
                (x[i] <= lower[i] && grad[i] > 0.0) || (x[i] >= upper[i] && grad[i] < 0.0);
            free[i] = !clamped;
            if free[i] {
                idx[nfree] = i;
                nfree += 1;
            }
        }
        if nfree == 0 {
            // No free block: a factor from an earlier iteration would describe the wrong set.
            factor = None;
            status = QpStatus::AllClamped;
            break;
        }
        if iter == 0 || free[..n] != old_free[..n] {
            match SmallCholesky::new(h, &idx[..nfree]) {
                Some(c) => factor = Some(c),
                None => {
                    return QpSolution {
                        x,
                        free,
                        factor: None,
                        status: QpStatus::NotPositiveDefinite,
                    };
                }
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
        // Newton step on the free variables with the clamped ones fixed.
        let mut rhs = [0.0; MAX_QP];
        for (a, &i) in idx[..nfree].iter().enumerate() {
            rhs[a] = g[i]
                + (0..n)
                    .filter(|&j| !free[j])
                    .map(|j| h(i, j) * x[j])
                    .sum::<f64>();
        }
        factor
            .as_ref()
            .expect("factor computed")
            .solve(&mut rhs[..nfree]);
        let mut dir = [0.0; MAX_QP];
        for (a, &i) in idx[..nfree].iter().enumerate() {
            dir[i] = -rhs[a] - x[i];
        }
        let sdotg: f64 = (0..n).map(|i| dir[i] * grad[i]).sum();
        if sdotg >= -1e-14 * (1.0 + f.abs()) {
            status = QpStatus::Converged;
            break;
        }
        // Projected Armijo line search.
        let mut step = 1.0;
        let mut accepted = false;
        while step > 1e-12 {
            let mut xc = [0.0; MAX_QP];
            for i in 0..n {
                xc[i] = (x[i] + step * dir[i]).clamp(lower[i], upper[i]);
            }
            let fc = value(&xc);
            if (fc - f) / (step * sdotg) > 0.1 {
                x = xc;
                f = fc;
                accepted = true;
                break;
            }
            step *= 0.6;
        }
        if !accepted {
            status = QpStatus::Converged;
            break;
        }
    }
    // The final free set and its factor must describe the returned point.
    let mut grad = [0.0; MAX_QP];
    for i in 0..n {
        grad[i] = g[i] + (0..n).map(|j| h(i, j) * x[j]).sum::<f64>();
    }
    let mut changed = false;
    let mut k = 0;
    for i in 0..n {
        let clamped = (x[i] <= lower[i] && grad[i] > 0.0) || (x[i] >= upper[i] && grad[i] < 0.0);
        changed |= free[i] == clamped;
        free[i] = !clamped;
        if free[i] {
            idx[k] = i;
            k += 1;
        }
    }
    if changed || factor.is_none() {
        factor = if k == 0 {
            None
        } else {
            SmallCholesky::new(h, &idx[..k])
        };
        if k > 0 && factor.is_none() {
            status = QpStatus::NotPositiveDefinite;
        }
    }
    let _ = nfree;
    QpSolution {
        x,
        free,
        factor,
        status,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
                let Some(c) = SmallCholesky::new(hf, &free) else {
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
            let sol = solve_box_qp(|i, j| h[i][j], &g, &lo, &hi, &[0.0; 3]);
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
}
