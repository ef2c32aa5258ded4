//! The scalar type the models are written in.
//!
//! Every model equation is written once, generic over [`Scalar`], and evaluated with `f64` for
//! simulation, with [`num_dual::Dual64`] for exact first derivatives and with
//! [`num_dual::HyperDual64`] for exact second derivatives (forward-mode automatic differentiation).
//! No derivative is ever written by hand, so none can drift from the equation it differentiates.

use num_dual::DualNum;

/// A real number or a dual number over `f64`.
pub trait Scalar: DualNum<Primitive = f64> + Copy {}

impl<T: DualNum<Primitive = f64> + Copy> Scalar for T {}

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
