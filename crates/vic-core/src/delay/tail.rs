//! The tail of a horizon as a problem of its own: a model or cost read some knots later
//! ([`Offset`]), and a model without its noise ([`NoiseFree`]), for the undelayed first guess of
//! the delayed planner and for replanning from a later knot.

use crate::cost::{Cost, CostDerivatives};
use crate::dynamics::{Dynamics, Linearization, StateSupport, Structure};
use nalgebra::DMatrix;

/// A model or cost read `offset` knots later: knot `k` of the wrapper is knot `k + offset` of
/// the inner one (its reference and exogenous inputs). The tail of a horizon as a problem of its
/// own, for [`undelayed_guess`](super::undelayed_guess) and for replanning from a later knot.
pub struct Offset<'a, T: ?Sized> {
    inner: &'a T,
    offset: usize,
}

impl<'a, T: ?Sized> Offset<'a, T> {
    /// Knot `k` of the result is knot `k + offset` of `inner`.
    pub fn new(inner: &'a T, offset: usize) -> Self {
        Offset { inner, offset }
    }
}

impl<T: Dynamics + ?Sized> Dynamics for Offset<'_, T> {
    fn nx(&self) -> usize {
        self.inner.nx()
    }
    fn nu(&self) -> usize {
        self.inner.nu()
    }
    fn nw(&self) -> usize {
        self.inner.nw()
    }
    fn step(&self, k: usize, x: &[f64], u: &[f64], next: &mut [f64]) {
        self.inner.step(k + self.offset, x, u, next);
    }
    fn noise_gain(&self, k: usize, x: &[f64], u: &[f64], out: &mut DMatrix<f64>) {
        self.inner.noise_gain(k + self.offset, x, u, out);
    }
    fn linearize(&self, k: usize, x: &[f64], u: &[f64], lin: &mut Linearization) {
        self.inner.linearize(k + self.offset, x, u, lin);
    }
    fn linearize_with(
        &self,
        k: usize,
        x: &[f64],
        u: &[f64],
        next: Option<&mut [f64]>,
        refill: bool,
        lin: &mut Linearization,
    ) {
        self.inner
            .linearize_with(k + self.offset, x, u, next, refill, lin);
    }
    fn structure(&self, support: Option<&mut StateSupport>) -> Structure {
        self.inner.structure(support)
    }
}

impl<T: Cost + ?Sized> Cost for Offset<'_, T> {
    fn running(&self, k: usize, x: &[f64], u: &[f64]) -> f64 {
        self.inner.running(k + self.offset, x, u)
    }
    fn terminal(&self, x: &[f64]) -> f64 {
        self.inner.terminal(x)
    }
    fn running_derivatives(&self, k: usize, x: &[f64], u: &[f64], d: &mut CostDerivatives) {
        self.inner.running_derivatives(k + self.offset, x, u, d);
    }
    fn running_derivatives_again(&self, k: usize, x: &[f64], u: &[f64], d: &mut CostDerivatives) {
        self.inner
            .running_derivatives_again(k + self.offset, x, u, d);
    }
    fn terminal_derivatives(&self, x: &[f64], d: &mut CostDerivatives) {
        self.inner.terminal_derivatives(x, d);
    }
    fn hessian_support(&self) -> Option<std::ops::Range<usize>> {
        self.inner.hessian_support()
    }
    fn nonnegative(&self) -> bool {
        self.inner.nonnegative()
    }
}

/// A model without its noise: the deterministic problem of the same plant (`nw() = 0`), whose
/// solves neither read nor compute the noise's linearisation. The undelayed first guess of the
/// delayed planner is such a solve; computing the noise Jacobians it never reads would be a
/// sizeable share of its time.
pub struct NoiseFree<D>(pub D);

impl<D: Dynamics> Dynamics for NoiseFree<D> {
    fn nx(&self) -> usize {
        self.0.nx()
    }
    fn nu(&self) -> usize {
        self.0.nu()
    }
    fn nw(&self) -> usize {
        0
    }
    fn step(&self, k: usize, x: &[f64], u: &[f64], next: &mut [f64]) {
        self.0.step(k, x, u, next);
    }
    fn noise_gain(&self, _k: usize, _x: &[f64], _u: &[f64], out: &mut DMatrix<f64>) {
        debug_assert_eq!(out.ncols(), 0, "a noise-free model has no noise channels");
    }
    // The linearisations go to `lin`s without noise channels (the solvers size them by `nw()`),
    // which the inner model fills with its deterministic part only (see `Dynamics::linearize`).
    fn linearize(&self, k: usize, x: &[f64], u: &[f64], lin: &mut Linearization) {
        self.0.linearize(k, x, u, lin);
    }
    fn linearize_with(
        &self,
        k: usize,
        x: &[f64],
        u: &[f64],
        next: Option<&mut [f64]>,
        refill: bool,
        lin: &mut Linearization,
    ) {
        self.0.linearize_with(k, x, u, next, refill, lin);
    }
    fn structure(&self, support: Option<&mut StateSupport>) -> Structure {
        self.0.structure(support)
    }
}
