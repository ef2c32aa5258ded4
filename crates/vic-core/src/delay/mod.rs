//! Feedback delay by state augmentation (paper Eq. 11–13 and 19).
//!
//! A central controller `d` steps away sees the state `d` steps late, and what it sends acts at
//! once. Relabelled in the controller's time, a command computed from `x_k` acts `d` steps later:
//! `x_{k+1} = x_k + Δ f(x_k, u_{k−d}) + …` — the first line of paper Eq. 19 with `h = d + 1`. The
//! plant stays Markov once the state carries the commands still in flight:
//! `x̃_k = (x_k, u_{k−d}, …, u_{k−1})`, of dimension `n + m d`.
//!
//! Why the commands and not the past states (the paper's `(x_k, …, x_{k−h+1})`): with a Markov
//! plant the value function depends on `x_k` alone, so ILQG on a history of *states* puts no gain at
//! all on the older blocks and Eq. 13 would reduce to open loop. With the commands in flight, the
//! gain block on `x_k` is the feedback that a controller acting `d` steps late should apply to the
//! state it sees; keeping only that block and ignoring the in-flight commands (no predictor) is
//! the paper's Eq. 13. For `d = 0` the wrapper is the plain model.

use crate::dense::zero;
use crate::dynamics::{Column, Dynamics, Linearization, NoiseKind, StateSupport, Structure};
use nalgebra::DMatrix;
use std::sync::Mutex;

mod planner;
mod tail;

pub use planner::{DelayedPlanner, undelayed_guess};
pub use tail::{NoiseFree, Offset};

/// A discrete model whose commands act `steps` steps after they are issued.
pub struct Delayed<D: Dynamics> {
    base: D,
    steps: usize,
    scratch: Mutex<(Linearization, DMatrix<f64>)>,
}

impl<D: Dynamics> Delayed<D> {
    /// Wraps `base` with a delay of `steps` control steps.
    pub fn new(base: D, steps: usize) -> Self {
        let (nx, nu, nw) = (base.nx(), base.nu(), base.nw());
        Delayed {
            base,
            steps,
            scratch: Mutex::new((Linearization::new(nx, nu, nw), DMatrix::zeros(nx, nw))),
        }
    }

    /// The wrapped model.
    pub fn base(&self) -> &D {
        &self.base
    }

    /// Delay in steps `d`.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// The augmented initial state: `x0` with the commands `pending` already in flight (the same
    /// command in every slot, typically the one that holds the start posture).
    pub fn initial_state(&self, x0: &[f64], pending: &[f64]) -> Vec<f64> {
        let mut x = x0.to_vec();
        for _ in 0..self.steps {
            x.extend_from_slice(pending);
        }
        x
    }

    /// The commands in flight of `next`: those of `x` shifted by one, the new command `u` at
    /// the back.
    fn shift(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        if self.steps > 0 {
            let (n, m, total) = (self.base.nx(), self.base.nu(), self.nx());
            next[n..total - m].copy_from_slice(&x[n + m..total]);
            next[total - m..].copy_from_slice(u);
        }
    }

    /// The control that acts on the plant in augmented state `x` given the new command `u`.
    fn acting<'a>(&self, x: &'a [f64], u: &'a [f64]) -> &'a [f64] {
        if self.steps == 0 {
            u
        } else {
            let n = self.base.nx();
            &x[n..n + self.base.nu()]
        }
    }
}

impl<D: Dynamics> Dynamics for Delayed<D> {
    fn nx(&self) -> usize {
        self.base.nx() + self.base.nu() * self.steps
    }
    fn nu(&self) -> usize {
        self.base.nu()
    }
    fn nw(&self) -> usize {
        self.base.nw()
    }

    fn step(&self, k: usize, x: &[f64], u: &[f64], next: &mut [f64]) {
        let n = self.base.nx();
        self.base
            .step(k, &x[..n], self.acting(x, u), &mut next[..n]);
        self.shift(x, u, next);
    }

    fn noise_gain(&self, k: usize, x: &[f64], u: &[f64], out: &mut DMatrix<f64>) {
        let n = self.base.nx();
        let mut guard = self.scratch.lock().expect("scratch lock");
        let g = &mut guard.1;
        self.base.noise_gain(k, &x[..n], self.acting(x, u), g);
        zero(out);
        out.view_mut((0, 0), (n, g.ncols())).copy_from(g);
    }

    fn linearize(&self, k: usize, x: &[f64], u: &[f64], lin: &mut Linearization) {
        self.write_linearization(k, x, u, lin, true, None);
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
        self.write_linearization(k, x, u, lin, !refill, next);
    }

    fn structure(&self, support: Option<&mut StateSupport>) -> Structure {
        // The augmented part is a fixed shift: the cost of a linearisation is the base model's.
        let parallel_linearization = self.base.structure(None).parallel_linearization;
        if let Some(support) = support {
            self.fill_support(support);
        }
        Structure {
            parallel_linearization,
            supported: true,
        }
    }
}

impl<D: Dynamics> Delayed<D> {
    /// The support [`Dynamics::structure`] declares.
    fn fill_support(&self, support: &mut StateSupport) {
        // What `write_linearization` writes: the plant's Jacobians in the plant's rows of the
        // first n + m columns (its own state and the command acting now), then column
        // n + m + i holds the shift's one in row n + i, and B the new command's ones in the
        // last m rows; the noise acts in the plant's rows, through the plant's columns.
        let (n, m) = (self.base.nx(), self.base.nu());
        let total = self.nx();
        let plant = if self.steps == 0 { n } else { n + m };
        support.a.clear();
        support.b.clear();
        support.cx.clear();
        support.cu.clear();
        for j in 0..total {
            if j < plant {
                support.a.push(Column::Rows(0..n));
                support.cx.push(0..n);
            } else {
                support.a.push(Column::Unit(j - m));
                support.cx.push(0..0);
            }
        }
        support.c = 0..n;
        for j in 0..m {
            if self.steps == 0 {
                support.b.push(Column::Rows(0..n));
                support.cu.push(0..n);
            } else {
                support.b.push(Column::Unit(total - m + j));
                support.cu.push(0..0);
            }
        }
    }

    /// The augmented linearisation: the plant's Jacobians in the plant's rows, the shift of the
    /// commands in flight below. With `clear` every entry is written; without, `lin` holds this
    /// model's linearisation from an earlier call (`refill` of [`Dynamics::linearize_with`]), whose entries
    /// outside the plant's blocks are the zeros and ones a clearing call wrote, so only the
    /// blocks are written (clearing 42² entries of `A` and of each noise Jacobian at every knot is
    /// a sizeable part of a stochastic solve of the delayed single joint). The noise Jacobians are
    /// cleared when the noise kind changed: a noise-free call leaves them as they were. With
    /// `next` the step is taken on the way ([`Dynamics::linearize_with`]): the plant's step
    /// comes from its own fused call, bit for bit its [`Dynamics::step`].
    fn write_linearization(
        &self,
        k: usize,
        x: &[f64],
        u: &[f64],
        lin: &mut Linearization,
        clear: bool,
        next: Option<&mut [f64]>,
    ) {
        let (n, m) = (self.base.nx(), self.base.nu());
        let total = self.nx();
        // The shared scratch when free (the solvers linearise a cheap model's knots in order, and
        // then nothing is allocated); an own one when another thread holds it.
        let mut guard = self.scratch.try_lock();
        let mut own = None;
        let base = match guard.as_mut() {
            Ok(g) => &mut g.0,
            Err(_) => own.insert(Linearization::new(n, m, self.base.nw())),
        };
        match next {
            Some(next) => {
                let acting = self.acting(x, u);
                self.base
                    .linearize_with(k, &x[..n], acting, Some(&mut next[..n]), false, base);
                self.shift(x, u, next);
            }
            None => self.base.linearize(k, &x[..n], self.acting(x, u), base),
        }
        if clear && self.steps > 0 {
            // The shift register's ones (its unit columns in the declared support), written once:
            // a relinearisation finds them in place, and touching them again would cost a cache
            // line per column of a 42×42 `A` at every knot.
            zero(&mut lin.a);
            zero(&mut lin.b);
            for i in 0..total - n - m {
                lin.a[(n + i, n + m + i)] = 1.0;
            }
            for j in 0..m {
                lin.b[(total - m + j, j)] = 1.0;
            }
        }
        let clear_noise = clear || lin.noise != base.noise;
        lin.noise = base.noise;
        lin.a.view_mut((0, 0), (n, n)).copy_from(&base.a);
        if self.steps == 0 {
            lin.b.copy_from(&base.b);
        } else {
            lin.a.view_mut((0, n), (n, m)).copy_from(&base.b);
        }
        if base.noise == NoiseKind::None || lin.c.ncols() == 0 {
            // A noise-free `lin` (see `Dynamics::linearize`) takes the deterministic part only.
            if lin.c.ncols() == 0 {
                lin.noise = NoiseKind::None;
            }
            return;
        }
        if clear_noise {
            zero(&mut lin.c);
        }
        lin.c
            .view_mut((0, 0), (n, base.c.ncols()))
            .copy_from(&base.c);
        for i in 0..base.cx.len() {
            if clear_noise {
                zero(&mut lin.cx[i]);
                zero(&mut lin.cu[i]);
            }
            lin.cx[i].view_mut((0, 0), (n, n)).copy_from(&base.cx[i]);
            if self.steps == 0 {
                lin.cu[i].copy_from(&base.cu[i]);
            } else {
                lin.cx[i].view_mut((0, n), (n, m)).copy_from(&base.cu[i]);
            }
        }
    }
}
