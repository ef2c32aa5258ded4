//! Taylor polynomials of second or third order along `K` directions that share one real part.
//!
//! [`Taylor`] carries `x` and, for each direction `w_l`, the first `ORDER` derivatives of
//! `t ↦ x(t w_l)` at `t = 0` (the `Dual2` / `Dual3` arithmetic of `num-dual`, lane by lane). A
//! model evaluated on it gives the directional derivatives `DᵏΦ[w_l]` of `K` directions in one
//! pass: the real part, and with it every sine, cosine and reciprocal of the model, is computed
//! once instead of once per direction, and the lanes are plain arrays the compiler vectorises.
//! The SOOC model recovers second and third partial derivatives from such directions
//! (the `solver::sooc` module).

use crate::scalar::Scalar;
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// `x` and the first `ORDER` derivatives (`ORDER` 2 or 3) of `x(t w_l)` at `t = 0` along `K`
/// directions `w_l`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Taylor<const K: usize, const ORDER: usize> {
    /// The value.
    pub re: f64,
    /// `v[i][l]`: the derivative of order `i + 1` along direction `l`.
    pub v: [[f64; K]; ORDER],
}

impl<const K: usize, const ORDER: usize> Taylor<K, ORDER> {
    /// Rejects, at compile time, an order the formulas below do not cover.
    const SUPPORTED: () = assert!(ORDER == 2 || ORDER == 3, "Taylor: ORDER must be 2 or 3");

    /// A constant: every derivative 0.
    #[inline(always)]
    pub fn constant(re: f64) -> Self {
        let () = Self::SUPPORTED;
        Taylor {
            re,
            v: [[0.0; K]; ORDER],
        }
    }

    /// `f(self)` from `f` and its first derivatives at the real part (Faà di Bruno): `f1 v1`,
    /// `f2 v1² + f1 v2`, `f3 v1³ + 3 f2 v1 v2 + f1 v3` (`f3` unused at order 2).
    #[inline(always)]
    fn chain(&self, f0: f64, f1: f64, f2: f64, f3: f64) -> Self {
        let mut out = Taylor::constant(f0);
        for l in 0..K {
            let (a1, a2) = (self.v[0][l], self.v[1][l]);
            out.v[0][l] = f1 * a1;
            out.v[1][l] = f2 * a1 * a1 + f1 * a2;
            if ORDER == 3 {
                let a3 = self.v[2][l];
                out.v[2][l] = f3 * a1 * a1 * a1 + 3.0 * f2 * a1 * a2 + f1 * a3;
            }
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

impl<const K: usize, const ORDER: usize> From<f64> for Taylor<K, ORDER> {
    #[inline(always)]
    fn from(re: f64) -> Self {
        Taylor::constant(re)
    }
}

impl<const K: usize, const ORDER: usize> Add for Taylor<K, ORDER> {
    type Output = Self;
    #[inline(always)]
    fn add(mut self, rhs: Self) -> Self {
        self += rhs;
        self
    }
}

impl<const K: usize, const ORDER: usize> AddAssign for Taylor<K, ORDER> {
    #[inline(always)]
    fn add_assign(&mut self, rhs: Self) {
        self.re += rhs.re;
        for (v, r) in self.v.iter_mut().zip(&rhs.v) {
            for l in 0..K {
                v[l] += r[l];
            }
        }
    }
}

impl<const K: usize, const ORDER: usize> Sub for Taylor<K, ORDER> {
    type Output = Self;
    #[inline(always)]
    fn sub(mut self, rhs: Self) -> Self {
        self -= rhs;
        self
    }
}

impl<const K: usize, const ORDER: usize> SubAssign for Taylor<K, ORDER> {
    #[inline(always)]
    fn sub_assign(&mut self, rhs: Self) {
        self.re -= rhs.re;
        for (v, r) in self.v.iter_mut().zip(&rhs.v) {
            for l in 0..K {
                v[l] -= r[l];
            }
        }
    }
}

impl<const K: usize, const ORDER: usize> Neg for Taylor<K, ORDER> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self * -1.0
    }
}

impl<const K: usize, const ORDER: usize> Mul for Taylor<K, ORDER> {
    type Output = Self;
    /// Leibniz's rule, lane by lane.
    #[inline(always)]
    fn mul(self, b: Self) -> Self {
        let a = self;
        let mut out = Taylor::constant(a.re * b.re);
        for l in 0..K {
            out.v[0][l] = a.v[0][l] * b.re + a.re * b.v[0][l];
            out.v[1][l] = a.v[1][l] * b.re + 2.0 * a.v[0][l] * b.v[0][l] + a.re * b.v[1][l];
            if ORDER == 3 {
                out.v[2][l] = a.v[2][l] * b.re
                    + 3.0 * (a.v[1][l] * b.v[0][l] + a.v[0][l] * b.v[1][l])
                    + a.re * b.v[2][l];
            }
        }
        out
    }
}

impl<const K: usize, const ORDER: usize> MulAssign for Taylor<K, ORDER> {
    #[inline(always)]
    fn mul_assign(&mut self, rhs: Self) {
        *self = *self * rhs;
    }
}

impl<const K: usize, const ORDER: usize> Div for Taylor<K, ORDER> {
    type Output = Self;
    #[inline(always)]
    #[allow(clippy::suspicious_arithmetic_impl)] // a / b = a · (1/b), the reciprocal by the chain rule
    fn div(self, rhs: Self) -> Self {
        self * rhs.recip()
    }
}

impl<const K: usize, const ORDER: usize> Add<f64> for Taylor<K, ORDER> {
    type Output = Self;
    #[inline(always)]
    fn add(mut self, rhs: f64) -> Self {
        self.re += rhs;
        self
    }
}

impl<const K: usize, const ORDER: usize> Sub<f64> for Taylor<K, ORDER> {
    type Output = Self;
    #[inline(always)]
    fn sub(mut self, rhs: f64) -> Self {
        self.re -= rhs;
        self
    }
}

impl<const K: usize, const ORDER: usize> Mul<f64> for Taylor<K, ORDER> {
    type Output = Self;
    #[inline(always)]
    fn mul(mut self, rhs: f64) -> Self {
        self.re *= rhs;
        for v in &mut self.v {
            for x in v.iter_mut() {
                *x *= rhs;
            }
        }
        self
    }
}

impl<const K: usize, const ORDER: usize> Div<f64> for Taylor<K, ORDER> {
    type Output = Self;
    #[inline(always)]
    fn div(mut self, rhs: f64) -> Self {
        self.re /= rhs;
        for v in &mut self.v {
            for x in v.iter_mut() {
                *x /= rhs;
            }
        }
        self
    }
}

impl<const K: usize, const ORDER: usize> Scalar for Taylor<K, ORDER> {
    #[inline(always)]
    fn zero() -> Self {
        Taylor::constant(0.0)
    }
    #[inline(always)]
    fn one() -> Self {
        Taylor::constant(1.0)
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        let (s, c) = memo::sin_cos(self.re);
        (self.chain(s, c, -s, -c), self.chain(c, -s, -c, s))
    }
}

/// The sine and cosine of the real parts, remembered per thread.
///
/// The SOOC model takes a knot's flow along its directions in several passes (15 third-order
/// flows of eight lanes per knot on the two-link arm), and every pass computes the same real
/// part bit for bit: the same angles at every sub-step, hence the same `sin_cos` calls. libm's
/// `sincos` (which also saves and restores the rounding mode at each call) is a noticeable share
/// of a SOOC plan, almost all of it recomputing what the first pass already had. A small
/// direct-mapped table keyed by the angle's bits returns the same two numbers `f64::sin_cos`
/// would (it is what computed them), so the derivatives are unchanged to the bit; a collision
/// only costs the call it would have cost anyway. Per thread, so no lock and no sharing between
/// rayon's workers.
mod memo {
    use std::cell::RefCell;

    /// Entries of the table: a knot of the two-link arm needs 30 angles (three per sub-step).
    const SLOTS: usize = 64;

    #[derive(Clone, Copy)]
    struct Entry {
        bits: u64,
        sin: f64,
        cos: f64,
    }

    thread_local! {
        /// Empty slots hold a NaN's bits with NaN values: the lookup of that very NaN returns NaNs,
        /// as `f64::sin_cos` does.
        static TABLE: RefCell<[Entry; SLOTS]> = const {
            RefCell::new([Entry { bits: 0x7ff8_0000_0000_0000, sin: f64::NAN, cos: f64::NAN }; SLOTS])
        };
    }

    /// `x.sin_cos()`, from the table when `x` was looked up last in its slot.
    #[inline(always)]
    pub(super) fn sin_cos(x: f64) -> (f64, f64) {
        let bits = x.to_bits();
        // Fibonacci hashing of the bits (angles along a trajectory differ in their low bits).
        let slot = ((bits ^ (bits >> 32)).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 58) as usize;
        TABLE.with(|table| {
            let mut table = table.borrow_mut();
            let e = &mut table[slot % SLOTS];
            if e.bits != bits {
                let (sin, cos) = x.sin_cos();
                *e = Entry { bits, sin, cos };
            }
            (e.sin, e.cos)
        })
    }

    #[cfg(test)]
    mod tests {
        /// The table returns `f64::sin_cos`'s bits, on a hit, a miss and a collision alike.
        #[test]
        fn remembered_values_are_the_computed_ones() {
            let angles: Vec<f64> = (0..500).map(|i| -7.0 + 0.0287 * i as f64).collect();
            for _ in 0..3 {
                for &x in &angles {
                    let (s, c) = super::sin_cos(x);
                    let (s0, c0) = x.sin_cos();
                    assert_eq!(
                        (s.to_bits(), c.to_bits()),
                        (s0.to_bits(), c0.to_bits()),
                        "{x}"
                    );
                }
            }
            let (s, c) = super::sin_cos(f64::NAN);
            assert!(s.is_nan() && c.is_nan());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use num_dual::{Dual2_64, Dual3_64};

    fn expr<S: Scalar>(x: S, y: S) -> S {
        let (s, c) = (x * y).sin_cos();
        let q = (s * 2.5 - c / y + 0.3) / (x * x + 1.0);
        -(q * q) * 0.5 + (x - y) / 3.0 - (c - 0.1)
    }

    const X: f64 = 0.7;
    const Y: f64 = -1.3;
    const DIRS: [(f64, f64); 4] = [(1.0, 0.0), (0.0, 1.0), (1.0, -1.0), (0.4, 2.0)];

    fn seeded<const ORDER: usize>(re: f64, w: [f64; 4]) -> Taylor<4, ORDER> {
        let mut t = Taylor::constant(re);
        t.v[0] = w;
        t
    }

    fn close(ours: f64, theirs: f64, what: &str) {
        assert!(
            (ours - theirs).abs() <= 1e-13 * (1.0 + theirs.abs()),
            "{what}: {ours} against {theirs}"
        );
    }

    /// A lane of `Taylor<K, 3>` along `w` against `num-dual`'s `Dual3` seeded with `w`, on an
    /// expression that uses every operation (both carry the same derivatives; the sums may
    /// round differently).
    #[test]
    fn each_lane_is_a_univariate_taylor_polynomial() {
        let t = expr(
            seeded::<3>(X, DIRS.map(|d| d.0)),
            seeded::<3>(Y, DIRS.map(|d| d.1)),
        );
        for (l, (wx, wy)) in DIRS.iter().enumerate() {
            let d = expr(
                Dual3_64::new(X, *wx, 0.0, 0.0),
                Dual3_64::new(Y, *wy, 0.0, 0.0),
            );
            close(t.re, d.re, "value");
            close(t.v[0][l], d.v1, "first");
            close(t.v[1][l], d.v2, "second");
            close(t.v[2][l], d.v3, "third");
        }
        // And the third derivative is not trivially zero.
        assert!(t.v[2].iter().all(|v| v.abs() > 1e-3), "{:?}", t.v[2]);
    }

    /// The same for `Taylor<K, 2>` against `Dual2`: the second-order lanes drop the third
    /// derivative without changing the first two.
    #[test]
    fn second_order_lanes_match_dual2() {
        let t = expr(
            seeded::<2>(X, DIRS.map(|d| d.0)),
            seeded::<2>(Y, DIRS.map(|d| d.1)),
        );
        for (l, (wx, wy)) in DIRS.iter().enumerate() {
            let d = expr(Dual2_64::new(X, *wx, 0.0), Dual2_64::new(Y, *wy, 0.0));
            close(t.re, d.re, "value");
            close(t.v[0][l], d.v1, "first");
            close(t.v[1][l], d.v2, "second");
        }
        assert!(t.v[1].iter().all(|v| v.abs() > 1e-3), "{:?}", t.v[1]);
    }
}
