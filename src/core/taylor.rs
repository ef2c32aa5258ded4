//! Third-order Taylor polynomials along `K` directions that share one real part.
//!
//! [`Taylor3`] carries `x` and, for each direction `w_l`, the first three derivatives of
//! `t ↦ x(t w_l)` at `t = 0` (the `Dual3` arithmetic of `num-dual`, lane by lane). A model
//! evaluated on it gives the third directional derivatives `D³Φ[w_l]` of `K` directions in one
//! pass: the real part, and with it every sine, cosine and reciprocal of the model, is computed
//! once instead of once per direction, and the lanes are plain arrays the compiler vectorises.
//! The SOOC Newton model recovers third partial derivatives from such directions
//! (`core::solver::sooc`).

use crate::core::scalar::Scalar;
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// `x` and the first three derivatives of `x(t w_l)` at `t = 0` along `K` directions `w_l`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Taylor3<const K: usize> {
    /// The value.
    pub re: f64,
    /// First derivatives, one per direction.
    pub v1: [f64; K],
    /// Second derivatives.
    pub v2: [f64; K],
    /// Third derivatives.
    pub v3: [f64; K],
}

impl<const K: usize> Taylor3<K> {
    /// A constant: every derivative 0.
    #[inline(always)]
    pub fn constant(re: f64) -> Self {
        Taylor3 {
            re,
            v1: [0.0; K],
            v2: [0.0; K],
            v3: [0.0; K],
        }
    }

    /// `f(self)` from `f` and its first three derivatives at the real part (Faà di Bruno to
    /// third order): `f1 v1`, `f2 v1² + f1 v2`, `f3 v1³ + 3 f2 v1 v2 + f1 v3`.
    #[inline(always)]
    fn chain(&self, f0: f64, f1: f64, f2: f64, f3: f64) -> Self {
        let mut out = Taylor3::constant(f0);
        for l in 0..K {
            let (a1, a2, a3) = (self.v1[l], self.v2[l], self.v3[l]);
            out.v1[l] = f1 * a1;
            out.v2[l] = f2 * a1 * a1 + f1 * a2;
            out.v3[l] = f3 * a1 * a1 * a1 + 3.0 * f2 * a1 * a2 + f1 * a3;
        }
        out
    }

    /// `1 / self`.
    #[inline(always)]
    fn recip(&self) -> Self {
        let f0 = 1.0 / self.re;
        let f1 = -f0 * f0;
        let f2 = -2.0 * f1 * f0;
        let f3 = -3.0 * f2 * f0;
        self.chain(f0, f1, f2, f3)
    }
}

impl<const K: usize> From<f64> for Taylor3<K> {
    #[inline(always)]
    fn from(re: f64) -> Self {
        Taylor3::constant(re)
    }
}

impl<const K: usize> Add for Taylor3<K> {
    type Output = Self;
    #[inline(always)]
    fn add(mut self, rhs: Self) -> Self {
        self += rhs;
        self
    }
}

impl<const K: usize> AddAssign for Taylor3<K> {
    #[inline(always)]
    fn add_assign(&mut self, rhs: Self) {
        self.re += rhs.re;
        for l in 0..K {
            self.v1[l] += rhs.v1[l];
            self.v2[l] += rhs.v2[l];
            self.v3[l] += rhs.v3[l];
        }
    }
}

impl<const K: usize> Sub for Taylor3<K> {
    type Output = Self;
    #[inline(always)]
    fn sub(mut self, rhs: Self) -> Self {
        self -= rhs;
        self
    }
}

impl<const K: usize> SubAssign for Taylor3<K> {
    #[inline(always)]
    fn sub_assign(&mut self, rhs: Self) {
        self.re -= rhs.re;
        for l in 0..K {
            self.v1[l] -= rhs.v1[l];
            self.v2[l] -= rhs.v2[l];
            self.v3[l] -= rhs.v3[l];
        }
    }
}

impl<const K: usize> Neg for Taylor3<K> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self * -1.0
    }
}

impl<const K: usize> Mul for Taylor3<K> {
    type Output = Self;
    /// Leibniz's rule to third order, lane by lane.
    #[inline(always)]
    fn mul(self, b: Self) -> Self {
        let a = self;
        let mut out = Taylor3::constant(a.re * b.re);
        for l in 0..K {
            out.v1[l] = a.v1[l] * b.re + a.re * b.v1[l];
            out.v2[l] = a.v2[l] * b.re + 2.0 * a.v1[l] * b.v1[l] + a.re * b.v2[l];
            out.v3[l] =
                a.v3[l] * b.re + 3.0 * (a.v2[l] * b.v1[l] + a.v1[l] * b.v2[l]) + a.re * b.v3[l];
        }
        out
    }
}

impl<const K: usize> MulAssign for Taylor3<K> {
    #[inline(always)]
    fn mul_assign(&mut self, rhs: Self) {
        *self = *self * rhs;
    }
}

impl<const K: usize> Div for Taylor3<K> {
    type Output = Self;
    #[inline(always)]
    #[allow(clippy::suspicious_arithmetic_impl)] // a / b = a · (1/b), the reciprocal by the chain rule
    fn div(self, rhs: Self) -> Self {
        self * rhs.recip()
    }
}

impl<const K: usize> Add<f64> for Taylor3<K> {
    type Output = Self;
    #[inline(always)]
    fn add(mut self, rhs: f64) -> Self {
        self.re += rhs;
        self
    }
}

impl<const K: usize> Sub<f64> for Taylor3<K> {
    type Output = Self;
    #[inline(always)]
    fn sub(mut self, rhs: f64) -> Self {
        self.re -= rhs;
        self
    }
}

impl<const K: usize> Mul<f64> for Taylor3<K> {
    type Output = Self;
    #[inline(always)]
    fn mul(mut self, rhs: f64) -> Self {
        self.re *= rhs;
        for l in 0..K {
            self.v1[l] *= rhs;
            self.v2[l] *= rhs;
            self.v3[l] *= rhs;
        }
        self
    }
}

impl<const K: usize> Div<f64> for Taylor3<K> {
    type Output = Self;
    #[inline(always)]
    fn div(mut self, rhs: f64) -> Self {
        self.re /= rhs;
        for l in 0..K {
            self.v1[l] /= rhs;
            self.v2[l] /= rhs;
            self.v3[l] /= rhs;
        }
        self
    }
}

impl<const K: usize> Scalar for Taylor3<K> {
    #[inline(always)]
    fn zero() -> Self {
        Taylor3::constant(0.0)
    }
    #[inline(always)]
    fn one() -> Self {
        Taylor3::constant(1.0)
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        let (s, c) = self.re.sin_cos();
        (self.chain(s, c, -s, -c), self.chain(c, -s, -c, s))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_dual::Dual3_64;

    /// A lane of [`Taylor3`] along `w` against `num-dual`'s `Dual3` seeded with `w`, on an
    /// expression that uses every operation (both carry the same derivatives; the sums may
    /// round differently).
    #[test]
    fn each_lane_is_a_univariate_taylor_polynomial() {
        fn expr<S: Scalar>(x: S, y: S) -> S {
            let (s, c) = (x * y).sin_cos();
            let q = (s * 2.5 - c / y + 0.3) / (x * x + 1.0);
            -(q * q) * 0.5 + (x - y) / 3.0 - (c - 0.1)
        }
        let (x, y) = (0.7, -1.3);
        let dirs = [(1.0, 0.0), (0.0, 1.0), (1.0, -1.0), (0.4, 2.0)];
        let tx = Taylor3::<4> {
            re: x,
            v1: dirs.map(|d| d.0),
            v2: [0.0; 4],
            v3: [0.0; 4],
        };
        let ty = Taylor3::<4> {
            re: y,
            v1: dirs.map(|d| d.1),
            v2: [0.0; 4],
            v3: [0.0; 4],
        };
        let t = expr(tx, ty);
        for (l, (wx, wy)) in dirs.iter().enumerate() {
            let d = expr(
                Dual3_64::new(x, *wx, 0.0, 0.0),
                Dual3_64::new(y, *wy, 0.0, 0.0),
            );
            for (ours, theirs) in [
                (t.re, d.re),
                (t.v1[l], d.v1),
                (t.v2[l], d.v2),
                (t.v3[l], d.v3),
            ] {
                assert!(
                    (ours - theirs).abs() <= 1e-13 * (1.0 + theirs.abs()),
                    "lane {l}: {ours} against {theirs}"
                );
            }
        }
        // And the third derivative is not trivially zero.
        assert!(t.v3.iter().all(|v| v.abs() > 1e-3), "{:?}", t.v3);
    }
}
