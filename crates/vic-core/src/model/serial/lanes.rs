//! First derivatives along `K` directions that share one real part: the dual numbers of
//! `num-dual`'s `DualSVec64<K>` as a plain array (no optional derivative to test at every
//! operation), which the compiler keeps in vector registers. For the chain's derivatives
//! (`SerialChain::forward_dynamics_derivatives`).

use crate::scalar::Scalar;
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// `x` and its derivatives `d[l]` along `K` directions.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Lanes<const K: usize> {
    pub re: f64,
    pub d: [f64; K],
}

impl<const K: usize> Lanes<K> {
    /// The variable `index` of `K` (derivative 1 along direction `index`), or a constant when
    /// `index` is `None`.
    pub fn variable(re: f64, index: Option<usize>) -> Self {
        let mut d = [0.0; K];
        if let Some(i) = index {
            d[i] = 1.0;
        }
        Lanes { re, d }
    }

    #[inline(always)]
    fn map(self, f: impl Fn(f64) -> f64) -> Self {
        Lanes {
            re: self.re,
            d: self.d.map(f),
        }
    }
}

impl<const K: usize> From<f64> for Lanes<K> {
    #[inline(always)]
    fn from(re: f64) -> Self {
        Lanes { re, d: [0.0; K] }
    }
}

impl<const K: usize> Add for Lanes<K> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Lanes {
            re: self.re + o.re,
            d: std::array::from_fn(|l| self.d[l] + o.d[l]),
        }
    }
}

impl<const K: usize> Sub for Lanes<K> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Lanes {
            re: self.re - o.re,
            d: std::array::from_fn(|l| self.d[l] - o.d[l]),
        }
    }
}

impl<const K: usize> Mul for Lanes<K> {
    type Output = Self;
    #[inline(always)]
    #[allow(clippy::suspicious_arithmetic_impl)] // the product rule
    fn mul(self, o: Self) -> Self {
        Lanes {
            re: self.re * o.re,
            d: std::array::from_fn(|l| self.d[l] * o.re + self.re * o.d[l]),
        }
    }
}

impl<const K: usize> Div for Lanes<K> {
    type Output = Self;
    #[inline(always)]
    #[allow(clippy::suspicious_arithmetic_impl)] // the quotient rule
    fn div(self, o: Self) -> Self {
        let inv = 1.0 / o.re;
        let re = self.re * inv;
        Lanes {
            re,
            d: std::array::from_fn(|l| (self.d[l] - re * o.d[l]) * inv),
        }
    }
}

impl<const K: usize> Neg for Lanes<K> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Lanes {
            re: -self.re,
            d: self.d.map(|v| -v),
        }
    }
}

impl<const K: usize> Add<f64> for Lanes<K> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: f64) -> Self {
        Lanes {
            re: self.re + o,
            d: self.d,
        }
    }
}

impl<const K: usize> Sub<f64> for Lanes<K> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: f64) -> Self {
        Lanes {
            re: self.re - o,
            d: self.d,
        }
    }
}

impl<const K: usize> Mul<f64> for Lanes<K> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: f64) -> Self {
        Lanes {
            re: self.re * o,
            ..self.map(|v| v * o)
        }
    }
}

impl<const K: usize> Div<f64> for Lanes<K> {
    type Output = Self;
    #[inline(always)]
    #[allow(clippy::suspicious_arithmetic_impl)] // a / b = a · (1/b)
    fn div(self, o: f64) -> Self {
        let inv = 1.0 / o;
        self * inv
    }
}

impl<const K: usize> AddAssign for Lanes<K> {
    #[inline(always)]
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}

impl<const K: usize> SubAssign for Lanes<K> {
    #[inline(always)]
    fn sub_assign(&mut self, o: Self) {
        *self = *self - o;
    }
}

impl<const K: usize> MulAssign for Lanes<K> {
    #[inline(always)]
    fn mul_assign(&mut self, o: Self) {
        *self = *self * o;
    }
}

impl<const K: usize> Scalar for Lanes<K> {
    #[inline(always)]
    fn zero() -> Self {
        Self::from(0.0)
    }
    #[inline(always)]
    fn one() -> Self {
        Self::from(1.0)
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        let (s, c) = self.re.sin_cos();
        (
            Lanes {
                re: s,
                ..self.map(|v| v * c)
            },
            Lanes {
                re: c,
                ..self.map(|v| -v * s)
            },
        )
    }
}
