//! Plans for the delayed plant (paper Eq. 13) through the undelayed one, cold and warm.
//!
//! With `d` steps of delay the first `d` commands that act are the ones already in flight: the
//! plant runs open loop to `x_d`, and a command issued at `k` acts at `k + d`. For a cost that
//! adds a control term to a state term (Eq. 14 does), the deterministic delayed problem is
//! therefore the undelayed problem from `x_d` over knots `d..N`, whose command `j` is issued at
//! `j`; the last `d` issued commands act after the horizon and only pay their control cost.
//! Solving that `n`-state problem instead of the `n + m d`-state one is much cheaper, and ILQG on
//! the delayed problem then starts at its optimum: without noise it only needs one backward pass,
//! for the delayed gains of Eq. 13. A replan after the plan advanced `s` knots is the same
//! construction from the new augmented state, with the undelayed problem warm-started from its
//! previous solution shifted by `s` (the receding horizon of the central controller).
//!
//! Without noise even that one pass is not needed. A command issued at `k` acts at `k + d`, so
//! the best one depends on the augmented state `z_k = (x_k, u_1 … u_d)` (the commands in flight,
//! `u_i` acting at `k + i − 1`) only through the state it will act on, `x_{k+d} = φ_k(z_k)`:
//! the delayed policy is the undelayed one applied to the *predicted* state. Linearised along
//! the plan, the gain of Eq. 13 is therefore `L̃_k = L_{k+d} ∂φ_k/∂z_k`, the undelayed gain of
//! the knot where the command acts times the prediction's Jacobian,
//! `∂x_{k+d}/∂x_k = A_{k+d−1} ⋯ A_k` and `∂x_{k+d}/∂u_i = A_{k+d−1} ⋯ A_{k+i} B_{k+i−1}`: the
//! shift register of commands in flight enters through products of the plant's `n × n` and
//! `n × m` blocks, never through the `(n + m d)`-dimensional value function. The commands
//! issued in the last `d` knots act after the horizon: their gain is zero. This is exactly the
//! backward pass of the augmented plant at μ = 0 (the linearised problems are the same LQ
//! problem; `tests/delayed_planner.rs` compares the two), at a fraction of its cost.

use super::{NoiseFree, Offset};
use crate::cost::{Cost, CostDerivatives};
use crate::dynamics::{Dynamics, Linearization};
use crate::solver::ilqg::IlqgError;
use crate::solver::{Bounds, Ilqg, IlqgOptions, Problem, Solution};
use nalgebra::{DMatrix, DVector};
use std::time::Instant;

/// A first guess for the delayed problem from the undelayed plant, exact without noise (see the
/// module's documentation); with noise (in `options` and the plant) the tail problem holds the
/// impedance's stiffness at its lower limit (`tail_bounds`). `plain` is the undelayed problem (plant, cost, start state, horizon,
/// limits), `pending` the command in flight in every slot, `u_init` a guess for the undelayed
/// plant (its knots `d..N` are used). The last `d` commands minimise their control cost.
pub fn undelayed_guess(
    plain: &Problem,
    pending: &[f64],
    delay: usize,
    options: &IlqgOptions,
    u_init: &[DVector<f64>],
) -> Result<Vec<DVector<f64>>, IlqgError> {
    let steps = plain.horizon;
    if delay == 0 {
        return Ok(plain_solver(plain, options).try_solve(plain, u_init)?.u);
    }
    if delay >= steps {
        return Ok(vec![DVector::from_column_slice(pending); steps]);
    }
    let in_flight = std::iter::repeat_n(pending, delay);
    let x_d = state_after(plain.dynamics, &plain.x0, in_flight);
    let (dynamics, cost) = tail_of(plain, delay);
    let hold = options.stochastic && plain.dynamics.nw() > 0;
    let bounds = tail_bounds(&plain.bounds, options, hold);
    let tail = tail_problem(&dynamics, &cost, x_d, steps - delay, bounds);
    let sol = plain_solver(&tail, options).try_solve(&tail, &u_init[delay..])?;
    let mut u = vec![DVector::zeros(plain.dynamics.nu()); steps];
    let mut d = CostDerivatives::new(plain.dynamics.nx(), plain.dynamics.nu());
    complete_guess(plain, &sol, &mut d, &mut u);
    Ok(u)
}

/// Cold and warm plans for a delayed plant: the undelayed tail problem, then the delayed gains
/// from the prediction (without noise) or ILQG on the augmented plant from the tail's solution
/// (with noise). The workspaces are kept, so a replan reuses them.
pub struct DelayedPlanner {
    delay: usize,
    /// ILQG on the undelayed plant over knots `d..N` (deterministic).
    tail: Ilqg,
    /// ILQG on the augmented plant (made on the first plan that needs it: a stochastic one, or
    /// one whose undelayed gains do not exist without regularisation).
    full: Option<Ilqg>,
    /// The augmented solve's options.
    options: IlqgOptions,
    guess: Vec<DVector<f64>>,
    derivs: CostDerivatives,
    /// The plant linearised at the first `d` knots of the plan, under the commands in flight
    /// (for the prediction's Jacobians; the later knots are the tail solve's).
    lin: Vec<Linearization>,
    /// At most this many ILQG iterations in a replan with noise (`None`, the default: the
    /// options' `max_iterations`, a converged replan). A real-time iteration scheme for the
    /// central controller (Diehl, Bock & Schlöder 2005): the first replans after a cold plan
    /// move it for many iterations before a sequence settles at one or two a replan, and a cap
    /// spreads that over the next periods. On the single joint, 30 replans at 50 Hz capped at
    /// 2 end next to the converged sequence's expected cost (`tests/delayed_planner.rs`;
    /// `docs/BENCHMARKS.md`, "Why targets are missed"); a capped replan reports
    /// `MaxIterations`, not converged.
    pub replan_iterations: Option<usize>,
}

/// A delayed plan and what it took.
#[derive(Debug, Clone)]
pub struct DelayedSolution {
    /// The plan on the augmented plant (without noise: `iterations` 0 and the tail's stop
    /// reason, since the tail's optimum is the delayed one); its `solve_time` covers the whole
    /// plan.
    pub solution: Solution,
    /// Iterations on the undelayed tail problem.
    pub guess_iterations: usize,
}

/// How a plan starts: cold from controls for the undelayed tail problem, or warm from the last
/// plan shifted by some knots.
#[derive(Clone, Copy)]
enum Start<'a> {
    Cold(&'a [DVector<f64>]),
    Shifted(usize),
}

impl DelayedPlanner {
    /// A planner for `delayed` (an augmented plant of `plain`'s model, see
    /// [`super::Delayed`]) with 0 < d < N steps of delay. `options` are the augmented solve's;
    /// the tail problem is solved deterministically with the same limits.
    pub fn new(
        plain: &Problem,
        delayed: &Problem,
        options: &IlqgOptions,
    ) -> Result<Self, IlqgError> {
        let delay = delay_of(plain, delayed)?;
        let (dynamics, cost) = tail_of(plain, delay);
        let tail = tail_problem(
            &dynamics,
            &cost,
            plain.x0.clone(),
            plain.horizon - delay,
            plain.bounds.clone(),
        );
        let (n, m, w) = (
            plain.dynamics.nx(),
            plain.dynamics.nu(),
            plain.dynamics.nw(),
        );
        Ok(DelayedPlanner {
            delay,
            tail: plain_solver(&tail, options),
            full: None,
            options: options.clone(),
            guess: vec![DVector::zeros(m); plain.horizon],
            derivs: CostDerivatives::new(n, m),
            lin: (0..delay).map(|_| Linearization::new(n, m, w)).collect(),
            replan_iterations: None,
        })
    }

    /// Delay in steps `d`.
    pub fn delay(&self) -> usize {
        self.delay
    }

    /// The last plan's guess for the augmented plant, from the undelayed tail problem: command
    /// `k` is the tail's control at knot `k + d`, the last `d` minimise their control cost.
    pub fn guess(&self) -> &[DVector<f64>] {
        &self.guess
    }

    /// Plans from `delayed.x0` (the plant's state and the commands in flight), the undelayed
    /// plant started from `u_init` (its knots `d..N`).
    pub fn solve(
        &mut self,
        plain: &Problem,
        delayed: &Problem,
        u_init: &[DVector<f64>],
    ) -> Result<DelayedSolution, IlqgError> {
        if u_init.len() != plain.horizon {
            return Err(IlqgError::InitialGuessLength {
                got: u_init.len(),
                want: plain.horizon,
            });
        }
        self.plan(plain, delayed, Start::Cold(&u_init[self.delay..]))
    }

    /// Replans after the plan advanced `shift` knots: `plain` and `delayed` are the problems from
    /// there (their reference read `shift` knots later, `delayed.x0` the state and the commands
    /// in flight now). The undelayed tail problem restarts from its previous solution shifted
    /// ([`Ilqg::resolve_shifted`]); with noise, so does ILQG on the augmented plant, from its
    /// previous plan (the first plan on the augmented plant starts from the tail's solution),
    /// whose commands from knot `N − d − shift` on start from the new undelayed guess
    /// ([`Ilqg::resolve_shifted_with_tail`]: the last plan left them unplanned).
    pub fn resolve_shifted(
        &mut self,
        plain: &Problem,
        delayed: &Problem,
        shift: usize,
    ) -> Result<DelayedSolution, IlqgError> {
        self.plan(plain, delayed, Start::Shifted(shift))
    }

    fn plan(
        &mut self,
        plain: &Problem,
        delayed: &Problem,
        start: Start,
    ) -> Result<DelayedSolution, IlqgError> {
        let started = Instant::now();
        let d = delay_of(plain, delayed)?;
        if d != self.delay || plain.horizon != self.guess.len() {
            return Err(IlqgError::SizeMismatch {
                got: dims(delayed),
                want: (
                    plain.dynamics.nx() + plain.dynamics.nu() * self.delay,
                    plain.dynamics.nu(),
                    plain.dynamics.nw(),
                    self.guess.len(),
                ),
            });
        }
        let (n, m) = (plain.dynamics.nx(), plain.dynamics.nu());
        let in_flight = delayed.x0[n..].chunks_exact(m);
        let x_d = state_after(plain.dynamics, &delayed.x0[..n], in_flight);
        let (dynamics, cost) = tail_of(plain, d);
        let deterministic = !self.options.stochastic || delayed.dynamics.nw() == 0;
        let bounds = tail_bounds(&plain.bounds, &self.options, !deterministic);
        let tail = tail_problem(&dynamics, &cost, x_d, plain.horizon - d, bounds);
        let sol = match start {
            Start::Cold(u) => self.tail.try_solve(&tail, u)?,
            Start::Shifted(s) => self.tail.resolve_shifted(&tail, s)?,
        };
        complete_guess(plain, &sol, &mut self.derivs, &mut self.guess);
        let predicted = if deterministic {
            self.predicted_policy(plain, delayed, &tail, &sol)
        } else {
            None
        };
        let mut solution = match predicted {
            Some(solution) => solution,
            None => {
                let options = &self.options;
                let full = self
                    .full
                    .get_or_insert_with(|| Ilqg::new(delayed, options.clone()));
                match start {
                    // With noise, the augmented plan of the last solve shifted (its gains hold
                    // the plant near it from the new state) starts closer than the undelayed
                    // guess, which knows nothing of the noise: fewer stochastic iterations and
                    // less time a replan (`examples/delay_replans` compares the two starts).
                    // The last plan's last `d` commands act after its horizon, so it left
                    // them at their control cost's minimum; shifted by `s`, the first `s` of
                    // them act within this one (on the single joint at 200 ms, 20 ms without
                    // torque before the end: a terminal cost orders of magnitude above the
                    // plan's expected one). They, and the knots after them, start from the
                    // undelayed guess instead: fewer iterations a replan, and replans at 50 Hz
                    // settle at one or two iterations each.
                    Start::Shifted(s) if !deterministic && full.has_solution() => {
                        let from = self.guess.len().saturating_sub(d + s);
                        let cap = self.replan_iterations.unwrap_or(options.max_iterations);
                        let limit = std::mem::replace(&mut full.options.max_iterations, cap);
                        let replan =
                            full.resolve_shifted_with_tail(delayed, s, &self.guess[from..]);
                        full.options.max_iterations = limit;
                        replan?
                    }
                    _ => full.try_solve(delayed, &self.guess)?,
                }
            }
        };
        solution.solve_time = started.elapsed();
        Ok(DelayedSolution {
            solution,
            guess_iterations: sol.iterations,
        })
    }

    /// The deterministic delayed plan from the tail's solution (see the module's documentation):
    /// the guess rolled out on the augmented plant, and the gains `L̃_k = L_{k+d} ∂φ_k/∂z_k`.
    /// `None` when the rollout leaves the finite numbers or the tail's gains need
    /// regularisation; the augmented solve then decides.
    fn predicted_policy(
        &mut self,
        plain: &Problem,
        delayed: &Problem,
        tail: &Problem,
        tail_solution: &Solution,
    ) -> Option<Solution> {
        let (d, horizon) = (self.delay, self.guess.len());
        let (n, m) = (plain.dynamics.nx(), plain.dynamics.nu());
        let total = n + m * d;
        let mut x = Vec::with_capacity(horizon + 1);
        x.push(DVector::from_column_slice(&delayed.x0));
        let mut cost = 0.0;
        for (k, u) in self.guess.iter().enumerate() {
            let (xk, u) = (x[k].as_slice(), u.as_slice());
            let mut next = DVector::zeros(total);
            delayed.dynamics.step(k, xk, u, next.as_mut_slice());
            cost += delayed.cost.running(k, xk, u);
            if k < d {
                // The plant under a command in flight (the front of the register); from knot d
                // on, the plant runs the tail's nominal, which the tail solve linearised.
                plain
                    .dynamics
                    .linearize(k, &xk[..n], &xk[n..n + m], &mut self.lin[k]);
            }
            x.push(next);
        }
        cost += delayed.cost.terminal(x[horizon].as_slice());
        if !cost.is_finite() || x.iter().any(|v| v.iter().any(|e| !e.is_finite())) {
            return None;
        }
        self.tail.unregularized_gains(tail)?;
        let (tail_gains, tail_lin) = (self.tail.gains(), self.tail.linearizations());
        let lin_at = |j: usize| {
            if j < d {
                &self.lin[j]
            } else {
                &tail_lin[j - d]
            }
        };
        let mut gains = vec![DMatrix::zeros(m, total); horizon];
        let mut jac = DMatrix::zeros(n, total);
        let (mut p, mut scratch) = (DMatrix::identity(n, n), DMatrix::zeros(n, n));
        for (k, gain) in gains.iter_mut().enumerate().take(horizon - d) {
            // ∂x_{k+d}/∂z_k from the last command in flight back to x_k: P = A_{k+d−1} ⋯ A_j.
            p.fill_with_identity();
            for i in (1..=d).rev() {
                let lin = lin_at(k + i - 1);
                let mut block = jac.columns_mut(n + (i - 1) * m, m);
                block.gemm(1.0, &p, &lin.b, 0.0);
                scratch.gemm(1.0, &p, &lin.a, 0.0);
                std::mem::swap(&mut p, &mut scratch);
            }
            jac.columns_mut(0, n).copy_from(&p);
            gain.gemm(1.0, &tail_gains[k], &jac, 0.0);
        }
        Some(Solution {
            x,
            u: self.guess.clone(),
            gains,
            cost,
            expected_cost: cost,
            iterations: 0,
            stop: tail_solution.stop,
            solve_time: Default::default(),
            history: Vec::new(),
            convergence: tail_solution.convergence,
        })
    }
}

/// `d` from the two problems' dimensions, when `delayed` is `plain`'s model with `d` commands in
/// flight (0 < d < N) and the same horizon.
fn delay_of(plain: &Problem, delayed: &Problem) -> Result<usize, IlqgError> {
    let (n, m) = (plain.dynamics.nx(), plain.dynamics.nu());
    let extra = delayed.dynamics.nx().saturating_sub(n);
    let d = extra / m.max(1);
    let fits = delayed.dynamics.nu() == m
        && extra == d * m
        && delayed.x0.len() == n + d * m
        && plain.x0.len() == n
        && d > 0
        && d < plain.horizon
        && delayed.horizon == plain.horizon;
    if fits {
        Ok(d)
    } else {
        Err(IlqgError::SizeMismatch {
            got: dims(delayed),
            want: dims(plain),
        })
    }
}

fn dims(p: &Problem) -> (usize, usize, usize, usize) {
    (p.dynamics.nx(), p.dynamics.nu(), p.dynamics.nw(), p.horizon)
}

/// The state the commands in flight lead to: `x0` stepped open loop under each of them in turn.
fn state_after<'a>(
    base: &dyn Dynamics,
    x0: &[f64],
    in_flight: impl Iterator<Item = &'a [f64]>,
) -> Vec<f64> {
    let mut x = x0.to_vec();
    let mut next = x.clone();
    for (k, u) in in_flight.enumerate() {
        base.step(k, &x, u, &mut next);
        std::mem::swap(&mut x, &mut next);
    }
    x
}

/// The plant and cost of `plain` from knot `delay` on, the plant without its noise: the tail
/// problem is solved deterministically.
fn tail_of<'a>(
    plain: &Problem<'a>,
    delay: usize,
) -> (
    NoiseFree<Offset<'a, dyn Dynamics + 'a>>,
    Offset<'a, dyn Cost + 'a>,
) {
    (
        NoiseFree(Offset::new(plain.dynamics, delay)),
        Offset::new(plain.cost, delay),
    )
}

/// The undelayed problem over knots `d..N` from `x_d`.
fn tail_problem<'a>(
    dynamics: &'a dyn Dynamics,
    cost: &'a dyn Cost,
    x_d: Vec<f64>,
    horizon: usize,
    bounds: Bounds,
) -> Problem<'a> {
    Problem {
        dynamics,
        cost,
        x0: x_d,
        horizon,
        bounds,
    }
}

/// The limits the tail problem is solved with: the plan's, or for a plan with noise (`hold`)
/// with the controls that act only through the deviation from the reference
/// ([`IlqgOptions::held_first`]: an impedance's stiffness) held at their finite lower limits.
/// With noise the tail's solution is only the augmented solve's first guess, and that solve
/// re-plans the stiffness under the noise; without noise a stiffness buys almost nothing, and
/// freeing it is most of a free tail solve's iterations (a Gauss–Newton crawl, see
/// [`crate::solver::Ilqg::try_solve_held_first`]), where the torque-only problem takes one or
/// two; the stochastic solve from the held guess takes about as many iterations and ends at
/// about the same expected cost. Without noise the tail's optimum is the plan: nothing is held.
fn tail_bounds(bounds: &Bounds, options: &IlqgOptions, hold: bool) -> Bounds {
    let held = hold.then(|| bounds.holding(&options.held_first)).flatten();
    held.unwrap_or_else(|| bounds.clone())
}

/// Deterministic ILQG for the tail problem (the noise-free plan is the guess).
fn plain_solver(problem: &Problem, options: &IlqgOptions) -> Ilqg {
    let mut solver = Ilqg::new(problem, options.clone());
    solver.options.stochastic = false;
    solver
}

/// The delayed problem's commands from the tail's solution: the tail's `N − d` commands, then
/// the last `d`, which act after the horizon and only pay their control cost: one Newton step on
/// it (exact for a quadratic control cost), clamped into the limits.
fn complete_guess(
    plain: &Problem,
    tail: &Solution,
    d: &mut CostDerivatives,
    u: &mut [DVector<f64>],
) {
    let x_end = tail.x[tail.x.len() - 1].as_slice();
    let last = &tail.u[tail.u.len() - 1];
    for (k, uk) in u.iter_mut().enumerate() {
        uk.copy_from(tail.u.get(k).unwrap_or(last));
        if k >= tail.u.len() {
            plain.cost.running_derivatives(k, x_end, uk.as_slice(), d);
            if let Some(step) = d.luu.clone().cholesky().map(|c| c.solve(&d.lu)) {
                *uk -= step;
                plain.bounds.clamp(uk.as_mut_slice());
            }
        }
    }
}
