//! The scalar type the models are written in.
//!
//! Every model equation is written once, generic over [`Scalar`], and evaluated with `f64` for
//! simulation, with [`num_dual::Dual64`] for exact first derivatives, with nested dual numbers
//! for exact second derivatives one pair at a time, and with the Taylor polynomials of
//! the `taylor` module for second and third derivatives along many directions at once (forward-mode
//! automatic differentiation). One derivative is written by hand, the drift's first
//! (`ArmModel::f_jacobian` of the model module, for ILQG's linearisations, where the dual
//! numbers cost much of a solve); the tests check it against the dual numbers on every model,
//! so it cannot drift from the equation it differentiates.
//!
//! The trait asks only for what the models use: field arithmetic, arithmetic with `f64`
//! constants, and the sine and cosine of an angle. Every `num-dual` number is a `Scalar`; a
//! type of this crate can be one without implementing `num-dual`'s much wider interface.

use num_dual::DualNum;
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// A real number, or a number carrying derivatives along with its real part.
pub trait Scalar:
    Copy
    + From<f64>
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + Div<f64, Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
{
    /// `0` (every derivative 0).
    fn zero() -> Self;
    /// `1` (every derivative 0).
    fn one() -> Self;
    /// `(sin x, cos x)`, the trigonometry computed once for both.
    fn sin_cos(self) -> (Self, Self);
}

impl<T: DualNum<Primitive = f64> + Copy> Scalar for T {
    #[inline(always)]
    fn zero() -> Self {
        T::from(0.0)
    }
    #[inline(always)]
    fn one() -> Self {
        T::from(1.0)
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        DualNum::sin_cos(&self)
    }
}

/// A constant lifted into any scalar type.
#[inline(always)]
pub fn c<S: Scalar>(value: f64) -> S {
    S::from(value)
}

/// The largest state dimension of a continuous model (two-link arm with a VSA actuator: 8).
pub const MAX_NX: usize = 8;
/// The largest control dimension of a continuous model (two-link arm, torque + stiffness: 4).
pub const MAX_NU: usize = 4;
/// The largest number of noise channels of a continuous model.
pub const MAX_NW: usize = MAX_NX;
